"""Two bores meeting at a junction (main bore and a lateral at 45 degrees): contacts on both
walls near their intersection, tip and link, small noise -> two cylinders, radii and angle."""

import numpy as np
from fit_synth import contacts, merge

from wholearm_tools.fit import FitData
from wholearm_tools.fit.segment import segment

MAIN = {"point": np.zeros(3), "axis": np.array([0.0, 0.0, 1.0]), "radius": 0.16}
LATERAL = {"point": np.zeros(3), "axis": np.array([np.sqrt(0.5), 0.0, np.sqrt(0.5)]),
           "radius": 0.11}


def _radial(p: dict, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance from the axis, axial coordinate) of points ``x (N, 3)``."""
    q = x - p["point"]
    h = q @ p["axis"]
    return np.linalg.norm(q - h[:, None] * p["axis"], axis=1), h


def _keep(d: FitData, ok_tip: np.ndarray, ok_link: np.ndarray) -> FitData:
    return FitData.create(d.tip_points[ok_tip], d.tip_radius[ok_tip], 1.0, d.link_a[ok_link],
                          d.link_b[ok_link], d.link_radius[ok_link], 1.0, d.free_points,
                          dim=3)


def _junction(rng: np.random.Generator, noise: float) -> tuple[FitData, np.ndarray]:
    """Contacts inside both bores (free side inside), the main bore's wall without the
    lateral's window, the lateral's wall outside the main bore, all within 0.45 m of the
    junction; returns the data and each contact's bore (0 main, 1 lateral)."""
    main = contacts("cylinder", MAIN, 60, 24, -1, rng, noise=noise)
    lat = contacts("cylinder", LATERAL, 60, 24, -1, rng, noise=noise)

    def on_main(x: np.ndarray) -> np.ndarray:  # not in the lateral's window, near the junction
        r, h = _radial(LATERAL, x)
        return ~((r < LATERAL["radius"] + 0.03) & (h > 0)) & (np.abs(x[:, 2]) < 0.45)

    def on_lateral(x: np.ndarray) -> np.ndarray:  # beyond the main bore's wall
        r, h = _radial(MAIN, x)
        return (r > MAIN["radius"] + 0.03) & (h < 0.6) & (_radial(LATERAL, x)[1] > 0)

    main = _keep(main, on_main(main.tip_points),
                 on_main(main.link_a) & on_main(main.link_b))
    lat = _keep(lat, on_lateral(lat.tip_points),
                on_lateral(lat.link_a) & on_lateral(lat.link_b))
    # the robot right behind each tip (towards its bore's axis) was in free space, as the
    # pipeline's hints from each contact's own link say
    hints = []
    for d, p in ((main, MAIN), (lat, LATERAL)):
        q = d.tip_points - p["point"]
        foot = p["point"] + (q @ p["axis"])[:, None] * p["axis"]
        inward = (foot - d.tip_points) / np.linalg.norm(foot - d.tip_points, axis=1)[:, None]
        hints.append(d.tip_points + 0.03 * inward)
    main = FitData.create(main.tip_points, main.tip_radius, 1.0, main.link_a, main.link_b,
                          main.link_radius, 1.0, np.vstack(hints), dim=3)
    data = merge(main, lat)
    label = np.concatenate([np.zeros(main.n_tip, int), np.ones(lat.n_tip, int),
                            np.zeros(main.n_link, int), np.ones(lat.n_link, int)])
    return data, label


def test_two_bores_at_a_junction_are_two_cylinders():
    data, label = _junction(np.random.default_rng(5), 2e-4)
    assert data.n_link >= 8
    seg = segment(data, kinds=("plane", "sphere", "cylinder"), noise_floor=1e-4, rng=0)
    kinds = sorted(f.kind for f in seg.primitives)
    assert kinds == ["cylinder", "cylinder"], seg.primitives
    radii = sorted(float(f.params["radius"]) for f in seg.primitives)
    assert abs(radii[0] - LATERAL["radius"]) < 0.02 * LATERAL["radius"]
    assert abs(radii[1] - MAIN["radius"]) < 0.02 * MAIN["radius"]
    a, b = (np.asarray(f.params["axis"], dtype=float) for f in seg.primitives)
    angle = np.degrees(np.arccos(min(1.0, abs(float(a @ b)))))
    assert abs(angle - 45.0) < 1.0
    # each cylinder's contacts come from one bore
    for k in range(2):
        members = seg.members(k)
        assert np.mean(label[members] == np.bincount(label[members]).argmax()) > 0.95
    assert len(seg.unexplained) <= 0.1 * data.n_contacts
