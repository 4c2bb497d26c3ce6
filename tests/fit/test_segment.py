"""Fit-and-grow segmentation on synthetic scenes."""

import numpy as np
import pytest
from fit_synth import contacts, merge, param_error, planar_scene, spatial_scene

from wholearm_tools.errors import InputError
from wholearm_tools.fit import FitData
from wholearm_tools.fit.segment import seed_pool, segment


def _check_scene(seg, prims, labels, data, tol):
    assert sorted(p.kind for p in seg.primitives) == sorted(k for k, _ in prims)
    for k, res in enumerate(seg.primitives):
        members = seg.members(k)
        true_i = np.bincount(labels[members]).argmax()
        # almost all members come from one true primitive, and it is recovered
        assert np.mean(labels[members] == true_i) > 0.95
        kind, p = prims[true_i]
        assert res.kind == kind
        expected = dict(p, normal=p["normal"]) if kind == "plane" else p
        assert param_error(kind, res.params, expected) < tol
    assert len(seg.unexplained) <= 0.05 * data.n_contacts


@pytest.mark.parametrize("noise", [0.0, 0.002])
def test_planar_scene_two_lines_and_a_circle(noise):
    data, prims, labels = planar_scene(np.random.default_rng(0), noise)
    seg = segment(data, rng=0)
    _check_scene(seg, prims, labels, data, 1e-6 if noise == 0 else 0.02)


@pytest.mark.parametrize("noise", [0.0, 0.002])
def test_spatial_scene_plane_and_cylinder(noise):
    data, prims, labels = spatial_scene(np.random.default_rng(1), noise)
    seg = segment(data, rng=0)
    _check_scene(seg, prims, labels, data, 1e-6 if noise == 0 else 0.02)


def test_plane_is_not_reported_as_a_huge_sphere_and_not_split():
    rng = np.random.default_rng(4)
    p = {"point": np.zeros(3), "normal": np.array([0.0, 0.0, 1.0])}
    data = contacts("plane", p, 40, 10, 1, rng, noise=0.001)
    seg = segment(data, kinds=("plane", "sphere", "cylinder"), rng=0)
    assert [r.kind for r in seg.primitives] == ["plane"]


def test_far_contacts_are_unexplained_and_result_is_deterministic():
    rng = np.random.default_rng(2)
    p = {"center": np.array([0.0, 0.0]), "radius": 0.5}
    circ = contacts("circle", p, 25, 5, 1, rng)
    junk = FitData.create(rng.uniform(2.0, 3.0, (3, 2)), 0.02, dim=2)
    data = merge(circ, junk)
    a = segment(data, rng=3)
    b = segment(data, rng=3)
    np.testing.assert_array_equal(a.assignment, b.assignment)
    assert [r.kind for r in a.primitives] == ["circle"]
    # the three junk tips are contacts 25..27 (tips first)
    assert set(a.unexplained) >= {25, 26, 27}


def test_seed_fits_in_worker_processes_give_the_same_segmentation():
    """The seed fits run in a process pool give exactly the map fitted in one process: each
    seed draws from its own generator, whichever process fits it."""
    data, prims, labels = spatial_scene(np.random.default_rng(5), 0.002)
    here = segment(data, rng=0)
    with seed_pool(2) as pool:
        assert pool is not None
        there = segment(data, rng=0, executor=pool)
    _check_scene(there, prims, labels, data, 0.02)
    np.testing.assert_array_equal(there.assignment, here.assignment)
    assert there.noise == here.noise
    for a, b in zip(there.primitives, here.primitives, strict=True):
        assert a.kind == b.kind
        for name, v in a.params.items():
            np.testing.assert_array_equal(v, b.params[name])


def test_seed_pool_of_one_worker_fits_here_and_rejects_zero():
    with seed_pool(1) as pool:
        assert pool is None
    with pytest.raises(InputError, match="workers must be at least 1"), seed_pool(0):
        pass


def test_too_few_contacts_gives_an_empty_segmentation():
    seg = segment(FitData.create(np.eye(3)[:2]))
    assert seg.primitives == ()
    assert np.all(seg.assignment == -1)


def test_segment_input_errors():
    with pytest.raises(InputError, match="cannot be fitted to 2-D"):
        segment(FitData.create(np.zeros((5, 2))), kinds=("plane",))
    with pytest.raises(InputError, match="noise"):
        segment(FitData.create(np.zeros((5, 2))), noise=-1.0)


def test_sweep_violation_counts_cuts_next_to_the_support_only():
    from wholearm_tools.fit.core import sweep_violation
    from wholearm_tools.fit.data import Sweep
    from wholearm_tools.geometry import Plane

    floor = Plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    support = np.array([[x, y, 0.0] for x in (-0.1, 0.0, 0.1) for y in (-0.1, 0.0, 0.1)])
    above = ([-0.1, 0.0, 0.05], [0.1, 0.0, 0.05], 0.02)    # 3 cm clear of the floor
    cuts = ([-0.1, 0.05, -0.03], [0.1, 0.05, 0.03], 0.01)  # through it, next to the support
    far = ([5.0, 0.0, -0.1], [5.0, 0.0, 0.1], 0.01)        # through it, 5 m away
    sweep = Sweep(*[np.array(v, dtype=float) for v in zip(above, cuts, far, strict=True)])
    check = sweep_violation(floor, 1.0, support, sweep, near=0.05, tol=1e-3)
    assert (check.cuts, check.checked) == (1, 2)
    # its deepest point is at x = -0.1, y = 0.05: within 5 cm of two support points, at the
    # edge of the support (none at x < -0.1)
    assert check.contradicted == pytest.approx(2 / 9)
    assert check.interior == 0


def test_cuts_past_the_edge_of_the_support_do_not_rule_a_surface_out():
    """A bore wall with a window: the arm reaches through the window right past the last
    contacts, many times.  Cuts next to 1 of 80 contacts and outside the region they cover
    leave the surface admissible; the same cuts between the contacts rule it out."""
    from wholearm_tools.fit.core import sweep_violation
    from wholearm_tools.fit.data import Sweep
    from wholearm_tools.geometry import Plane

    wall = Plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    support = np.array([[x, y, 0.0] for x in np.linspace(-0.3, 0.0, 16)
                        for y in (-0.04, -0.02, 0.0, 0.02, 0.04)])          # 2 cm apart
    n = 40
    through_window = Sweep(np.tile([0.012, 0.0, -0.05], (n, 1)), np.tile([0.012, 0.0, 0.05],
                                                                         (n, 1)), np.full(n, 0.005))
    clear = Sweep(np.tile([-0.15, 0.0, 0.02], (1000, 1)), np.tile([-0.1, 0.0, 0.03], (1000, 1)),
                  np.full(1000, 0.005))
    edge = Sweep(np.vstack([through_window.a, clear.a]), np.vstack([through_window.b, clear.b]),
                 np.concatenate([through_window.radius, clear.radius]))
    check = sweep_violation(wall, 1.0, support, edge, near=0.015, tol=1e-3)
    assert check.cuts == n
    assert check.contradicted == pytest.approx(1 / 80)
    assert check.interior == 0
    assert not check.rules_out()
    inside = Sweep(edge.a - [0.15, 0.0, 0.0], edge.b - [0.15, 0.0, 0.0], edge.radius)
    check = sweep_violation(wall, 1.0, support, inside, near=0.015, tol=1e-3)
    assert check.interior > 0
    assert check.rules_out()


def test_a_circle_the_robot_swept_through_is_not_a_primitive():
    """Contacts that fit a circle exactly, but the robot's own capsules passed through its
    inside: no surface can be there, so segmentation reports none."""
    from wholearm_tools.fit.data import Sweep

    ang = np.linspace(0.0, np.pi, 12)
    pts = 0.1 * np.stack([np.cos(ang), np.sin(ang)], 1)
    data = FitData.create(tip_points=pts, tip_radius=0.0, free_points=[[0.0, 0.5]])
    assert [p.kind for p in segment(data, kinds=("circle",), rng=0).primitives] == ["circle"]
    xs = np.linspace(-0.08, 0.08, 9)
    through = Sweep(np.stack([xs, np.full(9, 0.02)], 1), np.stack([xs, np.full(9, 0.06)], 1),
                    np.full(9, 0.005))
    assert segment(data, kinds=("circle",), rng=0, sweep=through).primitives == ()


def test_an_enclosure_must_hold_the_robot_base():
    """Contacts on the inside of a circle (free space inside) are an enclosure around the arm
    only if the arm's base is inside it too: an arm based outside reached them through walls."""
    ang = np.linspace(0.0, 1.5 * np.pi, 14)
    pts = np.array([1.0, 0.0]) + 0.08 * np.stack([np.cos(ang), np.sin(ang)], 1)
    data = FitData.create(tip_points=pts, tip_radius=0.0, free_points=[[1.0, 0.0]])
    inside = segment(data, kinds=("circle",), rng=0, base=[1.0, 0.02])
    assert [p.kind for p in inside.primitives] == ["circle"]
    assert inside.primitives[0].free_side == -1
    assert segment(data, kinds=("circle",), rng=0, base=[0.0, 0.0]).primitives == ()


def test_determined_at_a_noise_level():
    """A circle on a short arc is determined at micrometre noise but not at centimetres: the
    pipeline reports a primitive only when it is determined at a realistic noise level."""
    ang = np.linspace(0.0, 0.6, 10)
    pts = 0.2 * np.stack([np.cos(ang), np.sin(ang)], 1)
    data = FitData.create(tip_points=pts, tip_radius=0.0, free_points=[[0.0, 0.0]])
    seg = segment(data, kinds=("circle",), rng=0)
    assert len(seg.primitives) == 1
    fit = seg.primitives[0]
    assert seg.determined(fit, 1e-6)
    assert not seg.determined(fit, 1e-1)


def test_an_undetermined_post_is_completed_by_contacts_on_its_other_side():
    """Link bodies touching a post along one side leave its radius and the centre's distance
    free (a bigger post further away touches them too); tips on the post's other side fix
    them, but a fit a few millimetres off never reaches them by growth.  complete_support
    takes them one by one while one refit explains all, and leaves out a contact 5 mm off the
    post and the contacts of another surface."""
    from wholearm_tools.fit import fit_primitive
    from wholearm_tools.fit.segment import complete_support

    r, w_tip, w_link = 0.06, 0.02, 0.03
    phi = np.radians(np.linspace(-10.0, 10.0, 8))
    z = np.linspace(0.1, 0.5, 8)
    centre = np.stack([(r + w_link) * np.cos(phi), (r + w_link) * np.sin(phi), z], axis=1)
    along = np.stack([-np.sin(phi), np.cos(phi), np.zeros(8)], axis=1)  # tangent, horizontal
    far = np.radians([150.0, 170.0, 190.0, 210.0])
    tips = np.stack([(r + w_tip) * np.cos(far), (r + w_tip) * np.sin(far),
                     [0.2, 0.3, 0.4, 0.25]], axis=1)
    off = np.array([[-(r + w_tip + 0.005), 0.0, 0.35]])  # 5 mm off the post
    floor = np.array([[0.3, 0.3, -0.08 + w_tip], [0.4, -0.2, -0.08 + w_tip]])
    all_tips = np.vstack([tips, off, floor])
    data = FitData.create(all_tips, w_tip, 1.0, centre - 0.1 * along, centre + 0.1 * along,
                          w_link, 1.0, free_points=np.array([[0.5, 0.0, 0.3]]), dim=3)
    links = np.arange(len(all_tips), data.n_contacts)  # FitData orders tips, then links
    true = {"point": np.zeros(3), "axis": np.array([0.0, 0.0, 1.0]), "radius": r}
    # the one-sided support, fitted from a start 3 mm further out with a 3 mm bigger radius
    start = {"point": np.array([0.003, 0.0, 0.0]), "axis": true["axis"], "radius": r - 0.003}
    one_sided = fit_primitive("cylinder", data.take(links), initial=start, free_side=1.0)
    assert one_sided
    fit, members = complete_support(one_sided, links, data,
                                    np.arange(len(all_tips)), sigma=1e-5)
    assert members.tolist() == [0, 1, 2, 3, *links.tolist()]  # the far tips joined, no other
    assert param_error("cylinder", fit.params, true) < 1e-6
    assert fit.sensitivity < 0.1 * one_sided.sensitivity


def _one_sided_post(far_tips: np.ndarray):
    """Link bodies touching a post r 0.06 m (axis z) along one side, and tips elsewhere."""
    r, w_tip, w_link = 0.06, 0.02, 0.03
    phi = np.radians(np.linspace(-10.0, 10.0, 8))
    z = np.linspace(0.1, 0.5, 8)
    centre = np.stack([(r + w_link) * np.cos(phi), (r + w_link) * np.sin(phi), z], axis=1)
    along = np.stack([-np.sin(phi), np.cos(phi), np.zeros(8)], axis=1)
    data = FitData.create(far_tips, w_tip, 1.0, centre - 0.1 * along, centre + 0.1 * along,
                          w_link, 1.0, free_points=np.array([[0.5, 0.0, 0.3]]), dim=3)
    true = {"point": np.zeros(3), "axis": np.array([0.0, 0.0, 1.0]), "radius": r}
    return data, true


def test_a_contact_that_bends_a_barely_determined_post_is_dropped_and_one_that_pins_it_kept():
    """Link bodies along one side of a post leave a family of cylinders; a single contact on
    the other side picks one.  A wrong one (1.3 mm off the post: a body contact taken as a
    tip) bends the fit through it; the fit without it explains the three true tips there far
    better and leaves it 1.3 mm off, so it goes.  The only tip on the far side has a large
    deletion residual too (without it the fit drifts along the family), but the others fit no
    better without it: it stays."""
    from fit_synth import param_error

    from wholearm_tools.fit import fit_primitive
    from wholearm_tools.fit.segment import drop_bending

    r, w_tip = 0.06, 0.02
    far = np.radians([160.0, 180.0, 200.0])
    tips = np.stack([(r + w_tip) * np.cos(far), (r + w_tip) * np.sin(far), [0.2, 0.3, 0.4]],
                    axis=1)
    wrong = np.array([[-(r + w_tip + 0.0013) * np.cos(np.radians(10.0)),
                       -(r + w_tip + 0.0013) * np.sin(np.radians(10.0)), 0.35]])
    data, true = _one_sided_post(np.vstack([tips, wrong]))
    every = np.arange(data.n_contacts)
    bent = fit_primitive("cylinder", data, free_side=1.0, initial=true)
    assert bent
    assert param_error("cylinder", bent.params, true) > 1e-4
    fit, members = drop_bending(bent, every, data, tol=5e-4)
    assert members.tolist() == [0, 1, 2, *range(4, data.n_contacts)]  # the wrong tip (3) gone
    assert param_error("cylinder", fit.params, true) < 1e-6

    data, true = _one_sided_post(tips[1:2])  # one far tip pins the post
    every = np.arange(data.n_contacts)
    pinned = fit_primitive("cylinder", data, free_side=1.0, initial=true)
    fit, members = drop_bending(pinned, every, data, tol=5e-4)
    assert members.tolist() == every.tolist()
    assert param_error("cylinder", fit.params, true) < 1e-6


def test_a_seed_of_link_contacts_from_one_sweep_plane_is_extended_until_determined():
    """Link bodies swept in one vertical plane are all tangent to a vertical post at the same
    distance from their plane, so the seven nearest (mostly one plane) fit a whole family of
    cylinders.  The extended seed takes further nearest contacts one at a time, refitted from
    the last solution while the fit stays good; contacts from another plane pin the post."""
    import math

    from fit_synth import param_error

    from wholearm_tools.fit.segment import _fit_seed, _seed_job, _SeedConfig

    r, w = 0.06, 0.03
    foot = np.array([0.36, 0.2, 0.0])
    a, b = [], []
    for ang in np.radians([0.0, 55.0, 120.0]):  # three sweep planes, 9 link contacts each
        n = np.array([np.cos(ang), np.sin(ang), 0.0])
        t = np.array([-n[1], n[0], 0.0])
        for j, (pitch, z) in enumerate(zip(np.linspace(-0.5, 0.5, 9), np.linspace(0.15, 0.45, 9),
                                           strict=True)):
            c = foot + (r + w) * n + [0.0, 0.0, z]  # the link's closest point to the axis
            d = np.cos(pitch) * t + np.sin(pitch) * np.array([0.0, 0.0, 1.0])
            s = 0.05 * ((7 * j) % 5 - 2)  # not always at the link's middle
            a.append(c - (0.15 + s) * d)
            b.append(c + (0.15 - s) * d)
    rng = np.random.default_rng(0)
    a = np.array(a) + rng.normal(0.0, 2e-5, (27, 3))
    b = np.array(b) + rng.normal(0.0, 2e-5, (27, 3))
    data = FitData.create(np.zeros((0, 3)), 0.02, 1.0, a, b, w, 1.0,
                          free_points=np.array([[0.0, 0.0, 0.3]]), dim=3)
    true = {"point": foot, "axis": np.array([0.0, 0.0, 1.0]), "radius": r}
    x = data.contact_points()
    order = np.argsort(np.linalg.norm(x[:, None] - x[None], axis=2), axis=1)
    sigma, max_sens = 3e-5, 2000.0
    out = {}
    for extend in (0, 12):
        cfg = _SeedConfig({"cylinder": 7}, ("cylinder",), (), True, sigma, 2.5, 30, 1e-3, 0,
                          extend, max_sens if extend else math.inf)
        ((_kind, members, fit),) = _fit_seed(cfg, _seed_job(4, 7, order, data, cfg))
        out[extend] = members, fit
    members, fit = out[0]
    assert len(members) == 7
    assert fit.sensitivity > 10 * max_sens  # a family: not determined
    members, fit = out[12]
    assert len(members) > 7
    assert fit.sensitivity < max_sens
    assert param_error("cylinder", fit.params, true) < 1e-3


def test_a_post_only_one_tip_determines_is_pinned_by_it_and_one_three_tips_determine_is_not():
    """Link bodies along one side of a post leave a family of cylinders.  With one tip on the
    far side, that tip alone picks the post: were it a body contact taken as a tip, nothing
    would show it, so it is the pinning contact.  With three far tips, dropping any one
    contact leaves the post determined."""
    from wholearm_tools.fit import fit_primitive
    from wholearm_tools.fit.segment import pinning_contact

    r, w_tip = 0.06, 0.02
    far = np.radians([160.0, 180.0, 200.0])
    tips = np.stack([(r + w_tip) * np.cos(far), (r + w_tip) * np.sin(far), [0.2, 0.3, 0.4]],
                    axis=1)

    def determined(fit):  # worst parameter std below 0.2 support spreads at 10 um noise
        return fit.sensitivity * 1e-5 <= 0.2

    for far_tips, pin in [(tips[1:2], 0), (tips, None)]:
        data, true = _one_sided_post(far_tips)
        every = np.arange(data.n_contacts)
        fit = fit_primitive("cylinder", data, free_side=1.0, initial=true)
        assert fit
        assert determined(fit)
        assert pinning_contact(fit, every, data, determined) == pin
