"""Tip probability on hand-built planar motions with known answers; swept map; bad input."""

from __future__ import annotations

import numpy as np
import pytest

from wholearm_tools.classify import (
    NEVER,
    ClassifyParams,
    swept_map,
    tip_probability,
    tip_probability_history,
)
from wholearm_tools.contacts import Contacts
from wholearm_tools.errors import InputError
from wholearm_tools.logs.records import JointLog, Run
from wholearm_tools.robot import RobotModel


def two_link(l1=0.6, l2=0.15, r=0.015):
    return RobotModel.from_spec({
        "joints": [{"origin": [0, 0, 0], "radius": r}, {"origin": [l1, 0, 0], "radius": r}],
        "tip": {"offset": [l2, 0, 0], "radius": r}}, name="two_link")


def log_from(robot, qs, rate=500.0):
    qs = np.asarray(qs, float)
    t = np.arange(qs.shape[0]) / rate
    qd = np.gradient(qs, t, axis=0)
    return JointLog(robot.joint_names, t, qs, qd, np.zeros_like(qs))


def contact_at(log, idx, link):
    n = log.q.shape[1]
    return Contacts([log.t[idx]], [link], [idx], [log.q[idx]], [log.qd[idx - 3]], [log.t[-1]],
                    np.ones(n), np.ones(n))


def ramp(a, b, k=200):
    return np.linspace(a, b, k)


def tip_push_run(explore_after: bool):
    """Link 2 perpendicular to link 1; joint 0 turns so the tip moves along link 2's axis."""
    robot = two_link()
    approach = np.stack([ramp(-0.3, 0.0), np.full(200, np.pi / 2)], 1)
    dwell = np.repeat(approach[-1:], 30, 0)
    parts = [approach, dwell, approach[::-1]]
    if explore_after:
        # retreat further, then swing link 2 through the space beside its contact pose
        q = approach[0]
        parts.append(np.stack([np.full(200, q[0]), ramp(np.pi / 2, np.pi / 2 + 0.9)], 1))
        parts.append(np.stack([ramp(q[0], 0.1), np.full(200, np.pi / 2 + 0.9)], 1))
    return robot, log_from(robot, np.vstack(parts)), 199


def side_swipe_run(explore_after: bool):
    """Straight arm turning about joint 0: link 1's side leads, into a post at mid-link."""
    robot = two_link(0.5, 0.3)
    approach = np.stack([ramp(0.0, 0.5), np.zeros(200)], 1)
    parts = [approach, np.repeat(approach[-1:], 30, 0), approach[::-1]]
    if explore_after:
        # back off a little, then bend the forearm forward: the tip passes just ahead of its
        # contact position while the middle of the link stays clear of the post
        parts = [approach, np.repeat(approach[-1:], 30, 0),
                 np.stack([ramp(0.5, 0.4, 50), np.zeros(50)], 1),
                 np.stack([np.full(100, 0.4), ramp(0.0, 0.35, 100)], 1),
                 np.stack([np.full(100, 0.4), ramp(0.35, 0.0, 100)], 1),
                 np.stack([ramp(0.4, 0.0, 100), np.zeros(100)], 1)]
    return robot, log_from(robot, np.vstack(parts)), 199


def test_tip_pushed_into_a_wall_is_a_tip_contact():
    robot, log, idx = tip_push_run(False)
    cl = tip_probability(Run(robot, log), contact_at(log, idx, 1), 0.02)
    assert cl.p_tip[0] > 0.5
    assert 0.0 <= cl.p_tip_swept[0] <= 1.0
    assert cl.p_tip_swept[0] > 0.5


def test_link_swept_sideways_into_a_post_is_a_link_contact():
    robot, log, idx = side_swipe_run(False)
    cl = tip_probability(Run(robot, log), contact_at(log, idx, 1), 0.02)
    assert cl.p_tip[0] < 0.5
    assert cl.label[0] == "link"
    assert cl.p_tip_swept[0] < 0.5


@pytest.mark.parametrize("make", [tip_push_run, side_swipe_run])
def test_offline_map_moves_p_tip_toward_the_truth(make):
    robot, log, idx = make(True)
    c = contact_at(log, idx, 1)
    causal = tip_probability(Run(robot, log), c, 0.02, causal=True)
    offline = tip_probability(Run(robot, log), c, 0.02)
    assert np.all((offline.p_tip >= 0) & (offline.p_tip <= 1))
    truth = 1.0 if make is tip_push_run else 0.0
    assert abs(offline.p_tip[0] - truth) < abs(causal.p_tip[0] - truth) - 0.02
    # causal = the map-free answer here: nothing was explored before the first contact
    assert causal.p_tip[0] == pytest.approx(causal.p_tip_nomap[0])
    # weights: the surer contact gets the smaller variance
    assert offline.variance[0] < causal.variance[0]
    # replay: P_T is the causal value at the contact and the offline value at the end
    hist = tip_probability_history(Run(robot, log), c, 0.02, [0.0, log.t[idx], log.t[-1]])
    assert np.isnan(hist[0, 0])
    assert hist[0, 1] == pytest.approx(causal.p_tip[0])
    assert hist[0, 2] == pytest.approx(offline.p_tip[0])


def test_a_map_that_rules_out_all_but_a_sliver_gives_no_certainty():
    """The whole run's map sweeps every dilated-boundary point of the tip push but one on the
    link's side (an edge the arm later passed: the curvature assumption fails there).  Eq. (2)
    with a hard P_C would call it a certain link contact on that one point; the doubt on swept
    points keeps P_T near the ratio over the swept boundary instead."""
    from wholearm_tools.classify.tip import TipEvaluator, labels_from_p_tip

    robot, log, idx = tip_push_run(False)
    c = contact_at(log, idx, 1)
    p = {}
    for doubt in (0.0, ClassifyParams().swept_doubt):
        ev = TipEvaluator(robot, log, c, 0.02, params=ClassifyParams(swept_doubt=doubt))
        flux = ev.flux[0]
        side = np.flatnonzero((flux > 0) & ~ev.tip)
        keep = side[np.argmin(flux[side])]
        tmin = np.zeros_like(ev.tmin)
        tmin[0, keep] = NEVER
        ev.tmin = tmin
        p[doubt], ok = ev.p_tip()
        assert ok[0]
    assert p[0.0][0] == 0.0
    soft = p[ClassifyParams().swept_doubt][0]
    assert 0.2 < soft < ev.p_nomap[0]
    assert labels_from_p_tip(np.array([soft]))[0] != "link"


def test_swept_map_marks_the_capsules_and_first_times():
    robot = two_link(0.5, 0.3, r=0.02)
    qs = np.stack([ramp(0.0, np.pi / 2), np.zeros(200)], 1)
    smap = swept_map(robot, qs, resolution=0.01)
    # the quarter annulus swept by the arm is free, the opposite quadrant is not
    assert smap.first_at([[0.4, 0.4]])[0] != NEVER
    assert smap.first_at([[-0.4, -0.4]])[0] == NEVER
    # first time grows with the angle of the swept point
    f = smap.first_at([[0.6, 0.05], [0.05, 0.6]])
    assert f[0] < f[1]
    # a point 3 cm outside the arm's reach is not swept, but is within 4 cm of swept cells
    far = [[0.0, 0.83]]
    assert smap.first_at(far)[0] == NEVER
    assert smap.first_within(far, 0.04)[0] != NEVER


def test_swept_map_covers_the_swept_volume_to_a_quarter_of_a_cell():
    """Rasterising subsampled poses: every cell whose centre the robot's capsules swept over by
    more than a quarter of a cell (at any logged sample) is marked, and no cell they never
    came within reach of.  Brute force over every sample and cell."""
    robot = two_link(0.5, 0.3, r=0.02)
    k = 800  # 1.6 s at 500 Hz: both joints sweep, the samples finer than the poses kept
    qs = np.stack([np.linspace(0.0, 2.0, k), np.linspace(0.0, 1.5, k)], 1)
    res = 0.01
    smap = swept_map(robot, qs, resolution=res)
    pts = robot.joint_positions(qs)[..., :2]                       # (k, 3, 2)
    shape = smap.first.shape
    centres = smap.origin + np.stack(np.meshgrid(*[np.arange(n) for n in shape],
                                                 indexing="ij"), -1).reshape(-1, 2) * res
    clear = np.full(len(centres), np.inf)
    for j, r in enumerate((0.02, 0.02)):
        a, b = pts[:, j], pts[:, j + 1]
        for i in range(0, k, 50):
            aa, ab = a[i:i + 50], b[i:i + 50] - a[i:i + 50]
            rel = centres[:, None] - aa[None]
            u = np.clip(np.sum(rel * ab, -1) / np.sum(ab * ab, -1), 0.0, 1.0)
            d = np.linalg.norm(rel - u[..., None] * ab, axis=-1).min(axis=1)
            clear = np.minimum(clear, d - r)
    marked = smap.first.reshape(-1) != NEVER
    assert np.all(marked[clear <= -0.25 * res])
    assert not np.any(marked[clear > 0])


def test_bad_inputs_raise():
    robot, log, idx = side_swipe_run(False)
    c = contact_at(log, idx, 1)
    with pytest.raises(InputError, match="B must be a positive"):
        tip_probability(Run(robot, log), c, 0.0)
    with pytest.raises(InputError, match="needs robot"):
        tip_probability(log, c, 0.02)
    q = np.array(log.q)
    q[5, 0] = np.nan
    bad = JointLog(log.joint_names, log.t, q, log.qd, log.tau_cmd)
    with pytest.raises(InputError, match="NaN"):
        tip_probability(bad, c, 0.02, robot=robot)
    with pytest.raises(InputError, match="link_threshold"):
        ClassifyParams(tip_threshold=0.2, link_threshold=0.6)


def test_no_contacts_classify_to_empty_records():
    robot, log, _ = side_swipe_run(False)
    empty = Contacts([], [], [], np.zeros((0, 2)), np.zeros((0, 2)), [], np.ones(2), np.ones(2))
    cl = tip_probability(Run(robot, log), empty, 0.02)
    assert len(cl) == 0
    assert cl.label.shape == (0,)


def test_held_joint_torque_narrows_where_the_contact_can_be():
    """Only joint 0 moves and link 1's tip hits the wall (simulated).  With the map alone the
    tip and the leading side of link 1 are both open (low P_T); the load on held joint 1 fixes
    the moment-arm ratio, which only the tip explains."""
    from tests.sim.conftest import pocket, two_link
    from tests.sim.test_simulator import FixedTargets
    from wholearm_tools.contacts import detect_contacts
    from wholearm_tools.sim import simulate

    robot, env = two_link(), pocket()
    res = simulate(robot, env, strategy=FixedTargets(robot, env, [[1.8, -0.9]]), duration=3.0,
                   seed=0, home=[1.0, -0.9])
    assert res.truth.contact_kind.tolist() == ["tip"]
    c = detect_contacts(res.run.log, robot)
    assert c.held.tolist() == [[False, True]]
    plain = tip_probability(res.run, c, 0.02, params=ClassifyParams(use_torques=False))
    informed = tip_probability(res.run, c, 0.02)
    assert plain.p_tip[0] < 0.3
    assert informed.p_tip[0] > 0.9
    assert informed.meta["torque_informed"] == 1


@pytest.mark.parametrize("dim", [2, 3])
def test_first_within_is_the_earliest_swept_cell_in_the_ball(dim):
    """Against brute force over every cell, for points inside, at the edge of and outside the
    grid and radii of a fraction of a cell to several cells."""
    from wholearm_tools.classify.swept import SweptMap

    rng = np.random.default_rng(dim)
    shape = (23, 19, 17)[:dim]
    first = rng.integers(0, 500, size=shape).astype(np.int32)
    first[rng.random(shape) < 0.7] = NEVER
    res = 0.01
    origin = np.array([-0.1, 0.05, 0.2][:dim])
    smap = SweptMap(origin=origin, resolution=res, first=first, n_samples=500)
    lo, hi = origin - 3 * res, origin + (np.array(shape) + 2) * res
    points = rng.uniform(lo, hi, size=(400, dim))
    centres = origin + np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"),
                                -1).reshape(-1, dim) * res
    values = first.reshape(-1).astype(np.int64)
    for radius in (0.004, 0.013, 0.035):
        got = smap.first_within(points, radius)
        d = np.linalg.norm(points[:, None] - centres[None], axis=-1)
        expect = np.where(d <= radius, values[None], NEVER).min(axis=1)
        np.testing.assert_array_equal(got, expect)


def test_driving_joints_torques_count_only_where_the_runs_stops_balance():
    """Three joints drive the tip of a planar arm into a wall.  At rest the joints that drove
    balance the contact force, so torques of a push at the tip restrict where the contact can
    be and raise P_T.  A run whose stops no push explains (torques that pull against the
    motion that led in: no balance with a contact) says its stops are no static balances, and
    then the driving joints restrict nothing."""
    r = 0.015
    robot = RobotModel.from_spec({
        "joints": [{"origin": [0, 0, 0], "radius": r}, {"origin": [0.4, 0, 0], "radius": r},
                   {"origin": [0.3, 0, 0], "radius": r}],
        "tip": {"offset": [0.15, 0, 0], "radius": r}}, name="three_link")
    end, start = np.array([0.3, 0.6, 0.2]), np.array([0.0, 0.5, 0.1])
    approach = np.stack([ramp(start[j], end[j]) for j in range(3)], 1)
    log = log_from(robot, np.vstack([approach, np.repeat(approach[-1:], 30, 0), approach[::-1]]))
    idx = 199
    q, qd = log.q[idx], log.qd[idx - 3]
    pts, axes = robot.joint_positions_and_axes(q[None])
    pts, axes = pts[0], axes[0]
    v = sum(qd[j] * np.cross(axes[j], pts[-1] - pts[j]) for j in range(3))
    u = v / np.linalg.norm(v)
    at_tip = pts[-1] + robot.tip_radius * u           # the tip's point ahead, pushed along -u
    push = 20.0 * np.array([np.cross(axes[j], at_tip - pts[j]) @ u for j in range(3)])
    pull = -5.0 * qd

    def stops(torques):
        m = len(torques)
        return Contacts([log.t[idx]] * m, [2] * m, [idx] * m, [q] * m, [qd] * m,
                        [log.t[-1]] * m, np.full(3, 0.01), np.full(3, 0.05),
                        tau_peak=torques, held=[[False] * 3] * m)

    run = Run(robot, log)
    plain = tip_probability(run, stops([push]), 0.02, params=ClassifyParams(use_torques=False))
    balanced = tip_probability(run, stops([push]), 0.02)
    unbalanced = tip_probability(run, stops([push, pull, pull, pull]), 0.02)
    assert plain.p_tip[0] < 0.35
    assert balanced.p_tip[0] > plain.p_tip[0] + 0.1
    assert balanced.meta["driving_lean"] == pytest.approx(20.0)
    assert unbalanced.meta["driving_lean"] == 90.0
    assert unbalanced.p_tip[0] == pytest.approx(plain.p_tip[0])
    # a lean measured over the whole run carries to a few of its contacts evaluated again
    given = tip_probability(run, stops([push]), 0.02,
                            params=ClassifyParams(driving_lean=unbalanced.meta["driving_lean"]))
    assert given.p_tip[0] == pytest.approx(plain.p_tip[0])
