"""Accuracy metrics on hand-built cases with known answers."""

from __future__ import annotations

import dataclasses
import json
from types import SimpleNamespace

import numpy as np
import pytest
from report_inputs import cylinder, fake_rec, junction_surfaces, make_truth

from wholearm_tools.errors import InputError
from wholearm_tools.mapfile import MappedPrimitive
from wholearm_tools.report.metrics import (
    TrueSurface,
    classification_metrics,
    evaluate,
    primitive_accuracy,
    true_surfaces,
    truth_contact_surfaces,
)


def _truth_6():
    return make_truth(
        surfaces=[{"id": 0, "type": "line", "params": {"point": [0, 0.5], "direction": [1, 0]},
                   "free_side": -1}],
        t=[1, 2, 3, 4, 5, 6], link=[2, 1, 0, 2, 2, 1],
        kind=["tip", "joint", "body", "body", "tip", "body"],
        point=np.zeros((6, 3)), surface=[0] * 6)


def test_confusion_link_accuracy_and_calibration_counts():
    truth = _truth_6()
    t = [1.02, 2.02, 3.02, 4.02, 5.02, 10.0]            # contact 6 missed, one false detection
    link = [2, 1, 0, 1, 2, 0]
    label = ["tip", "link", "link", "ambiguous", "tip", "tip"]
    p = [0.9, 0.1, 0.05, 0.5, 0.95, 0.8]
    m = classification_metrics(t, link, p, label, truth)
    assert (m.n_detected, m.n_truth, m.n_matched, m.n_false, m.n_missed) == (6, 6, 5, 1, 1)
    assert m.truth_index.tolist() == [0, 1, 2, 3, 4, -1]
    np.testing.assert_array_equal(m.confusion, [[2, 1, 0], [0, 1, 1]])
    assert m.link_correct == 4
    assert m.link_accuracy == pytest.approx(0.8)
    assert m.class_accuracy == pytest.approx(3 / 4)
    assert m.ambiguous_fraction == pytest.approx(1 / 5)
    np.testing.assert_array_equal(m.bin_count, [2, 0, 1, 0, 2])
    assert m.bin_mean_p[0] == pytest.approx(0.075)
    assert m.bin_tip_fraction[0] == pytest.approx(0.5)       # one joint, one body
    assert m.bin_tip_fraction[2] == 0.0
    assert m.bin_tip_fraction[4] == 1.0
    brier = np.mean(np.square([0.9 - 1, 0.1 - 1, 0.05, 0.5, 0.95 - 1]))
    assert m.brier == pytest.approx(brier)
    d = json.loads(json.dumps(m.to_dict()))
    assert d["confusion"]["counts"] == [[2, 1, 0], [0, 1, 1]]
    assert d["calibration"]["tip_fraction"][1] is None        # empty bin → null, not NaN


def test_recall_of_the_arms_stops_against_contact():
    """A physics run records touches that only slowed or deflected the arm, and stops held by
    two contacts at once; joint positions show each stop once, and the detection recall is
    of those."""
    q = np.array([[0.1, 0.2], [0.3, 0.4], [0.5, 0.6], [0.3, 0.4], [0.7, 0.8], [0.9, 1.0]])
    truth = dataclasses.replace(_truth_6(), contact_q=q,
                                contact_stopped=np.array([1, 1, 0, 1, 0, 1], dtype=bool))
    t = [1.02, 3.02, 4.02, 5.02, 10.0]          # contact 2 missed but its stop held by 4 too
    m = classification_metrics(t, [2, 0, 2, 2, 0], [0.9, 0.05, 0.5, 0.95, 0.8],
                               ["tip", "link", "ambiguous", "tip", "tip"], truth)
    assert (m.n_stopped, m.n_stops, m.n_stops_found) == (4, 3, 2)   # contact 6's stop missed
    assert m.stop_recall == pytest.approx(2 / 3)
    assert json.loads(json.dumps(m.to_dict()))["stop_recall"] == pytest.approx(2 / 3)


def test_classification_metrics_rejects_bad_input():
    truth = _truth_6()
    with pytest.raises(InputError, match="unknown contact labels"):
        classification_metrics([1.0], [0], [0.5], ["edge"], truth)
    with pytest.raises(InputError, match=r"expected p_tip of shape \(1,\)"):
        classification_metrics([1.0], [0], [0.5, 0.2], ["tip"], truth)


def _circle(r, center=(0.3, 0.25)):
    return MappedPrimitive(id=3, kind="circle",
                           params={"center": np.array(center), "radius": r},
                           extent={"angle": {"reference": [1.0, 0.0], "start": 0.0,
                                             "sweep": np.pi, "full": False}})


def _true(kind, params, sid=4):
    from wholearm_tools.geometry.base import primitive_type

    return TrueSurface(sid, kind, primitive_type(kind).from_params(params), sid, {})


def test_perfect_fit_has_zero_error():
    truth = _true("circle", {"center": [0.3, 0.25], "radius": 0.07})
    a = primitive_accuracy(_circle(0.07), truth, matched_by="contacts")
    assert a.type_correct
    assert a.truth_id == 4
    assert a.size_error == 0.0
    assert a.size_error_pct == 0.0
    assert a.position_error == 0.0
    assert a.surface_rms < 1e-12
    assert a.surface_max < 1e-12


def test_radius_offset_gives_percent_error_and_surface_deviation():
    truth = _true("circle", {"center": [0.3, 0.25], "radius": 0.07})
    a = primitive_accuracy(_circle(0.0735), truth, matched_by="contacts")
    assert a.size_error == pytest.approx(0.0035)
    assert a.size_error_pct == pytest.approx(5.0)
    assert a.surface_rms == pytest.approx(0.0035)
    assert a.surface_max == pytest.approx(0.0035)


def test_axis_angle_position_and_wrong_type():
    tilt = np.radians(2.0)
    truth = _true("cylinder", {"point": [0, 0, 0], "axis": [0, 0, 1], "radius": 0.1})
    fit = cylinder(0, (0.004, 0.0, 0.0), (np.sin(tilt), 0.0, np.cos(tilt)), 0.1, (-0.1, 0.1))
    a = primitive_accuracy(fit, truth, matched_by="contacts")
    assert a.axis_angle_deg == pytest.approx(2.0, abs=1e-9)
    assert a.position_error == pytest.approx(0.004, rel=1e-6)   # axes cross at the data centre
    plane_truth = _true("plane", {"point": [0, 0, 1], "normal": [0, 0, 1]})
    flipped = MappedPrimitive(id=1, kind="plane",
                              params={"point": np.array([0, 0, 1.01]),
                                      "normal": np.array([0, 0, -1.0])},
                              extent={"u": [1, 0, 0], "v": [0, -1, 0],
                                      "polygon": [[0, 0], [0.1, 0], [0.1, 0.1], [0, 0.1]]})
    b = primitive_accuracy(flipped, plane_truth, matched_by="distance")
    assert b.axis_angle_deg == pytest.approx(0.0, abs=1e-6)    # a normal's sign is free
    assert b.position_error == pytest.approx(0.01)
    assert b.surface_rms == pytest.approx(0.01)
    c = primitive_accuracy(fit, plane_truth, matched_by="contacts")
    assert not c.type_correct
    assert c.size_error is None
    assert c.axis_angle_deg is None


def _junction_case():
    """Truth: junction (one obstacle, two cylinders); contacts on both walls; a map holding
    the exact main bore (#0), a lateral 5 % too wide (#1) and a plane nobody touched (#2)."""
    surfaces = junction_surfaces()
    c = np.array([0.0, 0.0, 0.35])
    v = np.array([np.sqrt(0.5), 0.0, np.sqrt(0.5)])
    phi = np.linspace(0.0, 2 * np.pi, 6, endpoint=False)
    main_pts = np.stack([0.18 * np.cos(phi), 0.18 * np.sin(phi), np.full(6, 0.05)], axis=1)
    radial = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [-np.sqrt(0.5), 0.0, np.sqrt(0.5)]])
    lat_pts = c + 0.6 * v + 0.12 * radial
    pts = np.concatenate([main_pts, lat_pts])
    t = np.arange(1.0, len(pts) + 1)
    truth = make_truth(surfaces, t=t, link=[5] * len(pts), kind=["tip"] * len(pts), point=pts,
                       surface=[0] * len(pts))
    table = SimpleNamespace(t=t + 0.01, link=np.full(len(pts), 5), p_tip=np.full(len(pts), 0.9),
                            label=np.array(["tip"] * len(pts)),
                            primitive=np.array([0] * 6 + [1] * 3),
                            t_settle=t + 0.02, t_end=t + 0.3)
    prims = [cylinder(0, c, (0, 0, 1), 0.18, (-0.4, 0.2), support=(6, 0)),
             cylinder(1, c, v, 0.126, (0.3, 0.7), support=(3, 0)),
             MappedPrimitive(id=2, kind="plane", params={"point": np.array([0, 0, 2.0]),
                                                         "normal": np.array([0, 0, 1.0])},
                             extent={"u": [1, 0, 0], "v": [0, 1, 0],
                                     "polygon": [[0, 0], [0.1, 0], [0.1, 0.1], [0, 0.1]]})]
    return fake_rec(prims, truth, table=table), truth


def test_junction_contacts_resolve_to_the_nearest_of_the_obstacle_surfaces():
    _, truth = _junction_case()
    assert truth_contact_surfaces(truth).tolist() == [0] * 6 + [1] * 3


def test_evaluate_matches_primitives_and_reports_found_and_missed():
    rec, _ = _junction_case()
    acc = evaluate(rec)
    p0, p1, p2 = acc.primitives
    assert (p0.truth_id, p0.matched_by, p0.votes) == (0, "contacts", {0: 6})
    assert p0.size_error == pytest.approx(0.0, abs=1e-12)
    assert p0.axis_angle_deg == pytest.approx(0.0, abs=1e-6)
    assert (p1.truth_id, p1.matched_by) == (1, "contacts")
    assert p1.size_error_pct == pytest.approx(5.0)
    assert p2.matched_by == "distance"
    assert not p2.type_correct
    assert [s.found_by for s in acc.surfaces] == [(0,), (1,)]
    assert acc.n_found == 2
    assert acc.n_touched == 2
    assert acc.missed == ()
    assert acc.classification.n_matched == 9
    json.dumps(acc.to_dict())


def test_surface_touched_but_not_found_is_missed():
    rec, _truth = _junction_case()
    rec.surface_map = type(rec.surface_map)(planar=False, B=0.02,
                                            primitives=rec.surface_map.primitives[:1])
    rec.table.primitive = np.array([0] * 6 + [-1] * 3)
    acc = evaluate(rec)
    assert [s.truth_id for s in acc.missed] == [1]


def test_no_truth_no_accuracy():
    rec, _ = _junction_case()
    rec.run.truth = None
    assert evaluate(rec) is None


def test_true_surfaces_rejects_malformed_truth():
    bad = make_truth([{"id": 0, "type": "circle"}], t=[], link=[], kind=[],
                     point=np.zeros((0, 3)), surface=[])
    with pytest.raises(InputError, match="malformed"):
        true_surfaces(bad)


def test_a_contact_in_a_corner_votes_for_both_walls():
    """A tip in the corner of a floor and a wall touches both, whichever the simulator
    recorded (here the floor): the plane fitted on the wall and its corner contacts is the
    wall, not the floor it ties with on the recorded surfaces."""
    floor = {"id": 0, "type": "plane", "params": {"point": [0, 0, 0], "normal": [0, 0, 1.0]},
             "free_side": 1}
    wall = {"id": 1, "type": "plane", "params": {"point": [0, 0, 0], "normal": [1.0, 0, 0]},
            "free_side": 1}
    y = np.linspace(-0.2, 0.2, 3)
    on_wall = np.stack([np.zeros(3), y, np.full(3, 0.3)], axis=1)
    in_corner = np.stack([np.full(3, 0.004), y, np.full(3, 0.004)], axis=1)
    truth = make_truth([floor, wall], t=np.arange(1.0, 7.0), link=[2] * 6, kind=["tip"] * 6,
                       point=np.vstack([on_wall, in_corner]), surface=[1, 1, 1, 0, 0, 0])
    t = np.arange(1.0, 7.0)
    table = SimpleNamespace(t=t + 0.01, link=np.full(6, 2), p_tip=np.full(6, 0.9),
                            label=np.array(["tip"] * 6), primitive=np.zeros(6, int),
                            t_settle=t + 0.02, t_end=t + 0.3)
    plane = MappedPrimitive(id=0, kind="plane", params={"point": np.zeros(3),
                                                        "normal": np.array([1.0, 0, 0])},
                            extent={"u": [0, 1, 0], "v": [0, 0, 1],
                                    "polygon": [[-0.2, 0], [0.2, 0], [0.2, 0.3], [-0.2, 0.3]]})
    acc = evaluate(fake_rec([plane], truth, table=table))
    (p,) = acc.primitives
    assert (p.truth_id, p.votes) == (1, {0: 3, 1: 6})
    assert p.type_correct
