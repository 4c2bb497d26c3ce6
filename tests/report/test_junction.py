"""Junction summary on synthetic two-cylinder maps with known geometry."""

from __future__ import annotations

import json

import numpy as np
import pytest
from report_inputs import cylinder, fake_rec, junction_surfaces, make_truth

from wholearm_tools.errors import InputError
from wholearm_tools.report.junction import junction_quantities, junction_summary

C = np.array([0.0, 0.0, 0.35])
V45 = np.array([np.sqrt(0.5), 0.0, np.sqrt(0.5)])


def _map(main_axis=(0, 0, 1), lat_axis=V45, lat_point=None, lat_s=(0.2, 0.7), main_cov=None,
         lat_support=(3, 0)):
    lat_axis = np.asarray(lat_axis, float)
    lat_point = C + 0.2 * V45 if lat_point is None else lat_point
    return [cylinder(0, C + 0.1 * np.asarray(main_axis), main_axis, 0.18, (-0.5, 0.1),
                     support=(20, 4), cov=main_cov),
            cylinder(1, lat_point, lat_axis, 0.12, lat_s, support=lat_support)]


def test_exact_values_for_a_45_degree_lateral():
    j = junction_summary(fake_rec(_map()))
    assert (j.main_id, j.lateral_id) == (0, 1)
    assert j.main_diameter.value == pytest.approx(0.36)
    assert j.lateral_diameter.value == pytest.approx(0.24)
    assert j.angle_deg.value == pytest.approx(45.0, abs=1e-9)
    assert j.window_position.value == pytest.approx(0.35, abs=1e-12)
    assert j.window_azimuth_deg.value == pytest.approx(0.0, abs=1e-9)
    assert j.axis_offset.value == pytest.approx(0.0, abs=1e-12)
    assert j.reference == pytest.approx((1.0, 0.0, 0.0))
    assert j.main_diameter.truth is None
    assert j.main_diameter.error is None
    assert np.isnan(j.angle_deg.half95)            # no covariance, no uncertainty


def test_axis_signs_do_not_matter():
    """Main axis pointing down and lateral axis pointing back into the bore: the conventions
    orient them (base → window; window → branch support) and nothing changes."""
    flipped = _map(main_axis=(0, 0, -1), lat_axis=-V45, lat_s=(-0.7, -0.2))
    j = junction_summary(fake_rec(flipped))
    assert j.angle_deg.value == pytest.approx(45.0, abs=1e-9)
    assert j.window_position.value == pytest.approx(0.35, abs=1e-12)
    assert j.window_azimuth_deg.value == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("az", [90.0, -120.0, 180.0])
def test_azimuth_and_angle_of_a_rotated_lateral(az):
    a, tilt = np.radians(az), np.radians(60.0)
    v = np.array([np.sin(tilt) * np.cos(a), np.sin(tilt) * np.sin(a), np.cos(tilt)])
    j = junction_summary(fake_rec(_map(lat_axis=v, lat_point=C + 0.3 * v)))
    assert j.angle_deg.value == pytest.approx(60.0, abs=1e-9)
    assert abs((j.window_azimuth_deg.value - az + 180) % 360 - 180) < 1e-9


def test_offset_window_position_and_axis_offset():
    # lateral axis passes 0.02 m beside the main axis, crossing its height at z = 0.5
    q = np.array([0.0, 0.02, 0.5])
    j = junction_summary(fake_rec(_map(lat_point=q + 0.3 * V45, lat_s=(-0.1, 0.4))))
    assert j.window_position.value == pytest.approx(0.5, abs=1e-12)
    assert j.axis_offset.value == pytest.approx(0.02, abs=1e-12)


def test_truth_values_and_errors():
    truth = make_truth(junction_surfaces(), t=[], link=[], kind=[], point=np.zeros((0, 3)),
                       surface=[])
    prims = _map()
    prims[1] = cylinder(1, C + 0.2 * V45, V45, 0.123, (0.2, 0.7))
    j = junction_summary(fake_rec(prims, truth))
    assert j.main_diameter.truth == pytest.approx(0.36)
    assert j.main_diameter.error == \
        pytest.approx(0.0, abs=1e-12)
    assert j.lateral_diameter.error == pytest.approx(0.006)
    assert j.angle_deg.truth == pytest.approx(45.0)
    assert j.window_position.truth == \
        pytest.approx(0.35)
    assert j.window_azimuth_deg.truth == pytest.approx(0.0, abs=1e-9)
    d = json.loads(json.dumps(j.to_dict()))
    assert d["lateral_diameter"]["error"] == pytest.approx(0.006)


def test_uncertainty_from_the_covariance_is_propagated_and_seeded():
    sigma = 1e-3
    cov = np.zeros((7, 7))            # point[3], axis[3], radius
    cov[6, 6] = sigma ** 2
    rec = fake_rec(_map(main_cov=cov))
    # the lateral has no covariance → no sampled uncertainty at all
    assert np.isnan(junction_summary(rec).main_diameter.half95)
    prims = _map(main_cov=cov)
    prims[1] = cylinder(1, C + 0.2 * V45, V45, 0.12, (0.2, 0.7), cov=np.zeros((7, 7)))
    rec = fake_rec(prims)
    j = junction_summary(rec, samples=20000)
    assert j.main_diameter.half95 == pytest.approx(1.96 * 2 * sigma, rel=0.03)
    assert j.lateral_diameter.half95 == 0.0
    assert j.angle_deg.half95 == pytest.approx(0.0)
    # an axis tilt variance shows up in the angle, not in the diameters
    tilt = np.zeros((7, 7))
    tilt[3, 3] = np.radians(0.5) ** 2
    prims[0] = cylinder(0, C, (0, 0, 1), 0.18, (-0.5, 0.1), cov=tilt)
    j1 = junction_summary(fake_rec(prims), samples=4000, seed=3)
    j2 = junction_summary(fake_rec(prims), samples=4000, seed=3)
    assert j1.angle_deg.half95 == pytest.approx(1.96 * 0.5, rel=0.08)
    assert j1.main_diameter.half95 == 0.0
    assert j1 == j2


def test_main_bore_is_the_cylinder_holding_the_base():
    prims = _map(lat_support=(50, 0))       # the lateral has more support, still not the main
    j = junction_summary(fake_rec(prims))
    assert (j.main_id, j.lateral_id) == (0, 1)


def test_not_a_junction():
    assert junction_summary(fake_rec(_map()[:1])) is None
    posts = [cylinder(0, (0.5, 0.0, 0.0), (0, 0, 1), 0.05, (0, 0.2)),   # base outside both
             cylinder(1, (0.0, 0.5, 0.0), (1, 0, 0), 0.05, (0, 0.2))]
    assert junction_summary(fake_rec(posts)) is None
    far = _map()
    far[1] = cylinder(1, (0.6, 0.0, 0.0), (0, 1, 0), 0.05, (0, 0.2))   # axis outside the bore
    assert junction_summary(fake_rec(far)) is None
    assert junction_summary(fake_rec([], planar=True)) is None
    with pytest.raises(InputError, match="samples must be >= 2"):
        junction_summary(fake_rec(_map()), samples=1)


def test_quantities_are_batched():
    u = np.tile([0.0, 0.0, 1.0], (4, 1))
    out = junction_quantities(np.tile(C, (4, 1)), u, np.full(4, 0.18), np.tile(C, (4, 1)),
                              np.tile(V45, (4, 1)), np.full(4, 0.12))
    np.testing.assert_allclose(out["angle_deg"], 45.0)
    assert out["window_position"].shape == (4,)
