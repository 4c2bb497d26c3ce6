"""Robust fits with no start (fit/robust.py): consensus start, inlier noise, capped loss."""

import numpy as np
import pytest
from fit_synth import contacts, param_error, truth

from wholearm_tools.fit import FitData, core, fit_primitive
from wholearm_tools.fit.models import MODELS
from wholearm_tools.fit.robust import consensus_start, robust_fit


def _arc(rng, n=150, share=0.1, radius=0.1, arc_deg=60.0, noise=1e-4):
    """Sharp-tip points on an ``arc_deg`` arc of a cylinder (random axis), a ``share`` of them
    outliers uniform over the arc's bounding box grown by 5 cm.  Returns the data, the inlier
    mask and the true cylinder."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    u = np.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    centre = rng.uniform(-0.5, 0.5, 3)
    n_out = round(share * n)
    az = rng.uniform(0.0, np.radians(arc_deg), n - n_out) + rng.uniform(0.0, 2 * np.pi)
    h = rng.uniform(0.0, 0.4, n - n_out)
    on = centre + h[:, None] * axis + radius * (np.cos(az)[:, None] * u
                                                + np.sin(az)[:, None] * v)
    on += noise * rng.normal(size=on.shape)
    out = rng.uniform(on.min(axis=0) - 0.05, on.max(axis=0) + 0.05, (n_out, 3))
    inlier = np.arange(n) < n - n_out
    return (FitData.create(np.vstack([on, out]), 0.0, 1.0), inlier,
            {"point": centre, "axis": axis, "radius": radius})


def test_no_start_huber_cylinder_on_a_partial_arc_with_outliers():
    """The consensus finds the axis of a 60-degree arc among 10 % outliers and the outliers
    do not pull on the radius (plain pseudo-Huber over all points is millimetres off here)."""
    for draw in range(3):
        data, _, p = _arc(np.random.default_rng([41, draw]))
        res = fit_primitive("cylinder", data, loss="huber")
        assert res, (draw, res.message)
        assert abs(res.params["radius"] - p["radius"]) <= 5e-4, draw
        assert param_error("cylinder", res.params, p) < 2e-3, draw
        assert "contacts read as outliers" in res.message


def test_contacts_read_as_outliers_do_not_pull():
    """The no-start fit on all contacts is the pseudo-Huber fit of its inliers alone."""
    data, _, _ = _arc(np.random.default_rng(43))
    m = MODELS["cylinder"]
    nd = core._normalise(data)
    rf = robust_fit(m, nd, 1.0, "huber", 2.0, None, np.random.default_rng(0))
    assert rf is not None
    assert rf.success
    every = fit_primitive("cylinder", data, loss="huber")
    assert f"{np.count_nonzero(~rf.inliers)} of 150 contacts read as outliers" in every.message
    alone = fit_primitive("cylinder", data.take(np.flatnonzero(rf.inliers)), loss="huber",
                          noise=rf.sigma * nd.scale, initial=every.params, free_side=1)
    assert alone
    assert every.params["radius"] == pytest.approx(alone.params["radius"], abs=1e-7)
    assert param_error("cylinder", every.params, alone.params) < 1e-6


@pytest.mark.parametrize("noise", [5e-5, 5e-4])
def test_inliers_and_noise_come_from_the_data(noise):
    """No tolerance in metres: the inliers and the noise estimate follow the data's noise."""
    data, inlier, _ = _arc(np.random.default_rng(44), n=200, noise=noise)
    nd = core._normalise(data)
    cs = consensus_start(MODELS["cylinder"], nd, 1.0, np.random.default_rng(0))
    assert cs is not None
    assert cs.sigma * nd.scale == pytest.approx(noise, rel=0.25)
    assert np.count_nonzero(cs.inliers & ~inlier) <= 2  # outliers within 2.5 sigma by chance
    assert np.count_nonzero(~cs.inliers & inlier) <= 0.03 * np.count_nonzero(inlier)


def test_covariance_leaves_the_outliers_out():
    data, inlier, p = _arc(np.random.default_rng(45))
    res = fit_primitive("cylinder", data, loss="huber")
    clean = fit_primitive("cylinder", data.take(np.flatnonzero(inlier)), free_side=1,
                          initial=p)
    lo, hi = res.ci95["radius"]
    assert lo <= p["radius"] <= hi
    width, clean_width = hi - lo, clean.ci95["radius"][1] - clean.ci95["radius"][0]
    assert 0.67 * clean_width <= width <= 1.5 * clean_width


@pytest.mark.parametrize(("kind", "loss"), [("sphere", "huber"), ("plane", "cauchy"),
                                            ("circle", "huber")])
def test_no_start_robust_fit_with_link_contacts_and_outliers(kind, loss):
    rng = np.random.default_rng(46)
    p = truth(kind, rng)
    data = contacts(kind, p, 40, 20, 1, rng, noise=3e-4)
    tips = np.array(data.tip_points)
    off = rng.uniform(0.02, 0.08, 6)[:, None] * rng.choice([-1.0, 1.0], (6, 1))
    tips[:6] += off * rng.normal(size=(6, tips.shape[1]))  # six tips far off the surface
    bad = FitData.create(tips, data.tip_radius, 1.0, data.link_a, data.link_b,
                         data.link_radius, 1.0, data.free_points)
    res = fit_primitive(kind, bad, loss=loss)
    assert res, res.message
    expected = dict(p, normal=res.free_side * p["normal"]) if kind == "plane" else p
    assert param_error(kind, res.params, expected) < 2e-3
    assert "contacts read as outliers" in res.message


def test_too_few_contacts_for_a_consensus_fall_back_to_the_algebraic_start():
    rng = np.random.default_rng(47)
    p = truth("cylinder", rng)
    data = contacts("cylinder", p, 6, 0, 1, rng)
    assert robust_fit(MODELS["cylinder"], core._normalise(data), 1.0, "huber", 2.0, None,
                      np.random.default_rng(0)) is None
    res = fit_primitive("cylinder", data, loss="huber")
    assert res, res.message
    assert param_error("cylinder", res.params, p) < 1e-6


def test_no_start_robust_fit_is_a_function_of_its_data():
    data, _, _ = _arc(np.random.default_rng(48))
    a = fit_primitive("cylinder", data, loss="huber")
    b = fit_primitive("cylinder", data, loss="huber")
    for key in a.params:
        assert np.array_equal(a.params[key], b.params[key])


def test_few_contacts_every_set_is_tried():
    """Eight contacts of a post, one of them off: a quarter of the 28 six-contact sets miss
    the outlier, and each set is tried, so one of them is found."""
    rng = np.random.default_rng(49)
    p = truth("cylinder", rng)
    data = contacts("cylinder", p, 8, 0, 1, rng)
    tips = np.array(data.tip_points)
    q = tips[3] - p["point"]
    radial = q - (q @ p["axis"]) * p["axis"]
    tips[3] += 0.05 * radial / np.linalg.norm(radial)  # 5 cm off the surface
    bad = FitData.create(tips, data.tip_radius, 1.0, free_points=data.free_points)
    nd = core._normalise(bad)
    cs = consensus_start(MODELS["cylinder"], nd, 1.0, np.random.default_rng(0))
    assert cs is not None
    assert cs.trials <= 28
    assert np.array_equal(np.flatnonzero(~cs.inliers), [3])
    res = fit_primitive("cylinder", bad, loss="huber")
    assert param_error("cylinder", res.params, p) < 1e-6
