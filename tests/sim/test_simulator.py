"""Simulator invariants on short runs: no penetration, exact stops, consistent ground truth."""

from __future__ import annotations

import numpy as np
import pytest

from tests.sim.conftest import dense_penetration, pocket, two_link
from wholearm_tools.errors import InputError
from wholearm_tools.geometry import Plane, Sphere, Surface
from wholearm_tools.robot.model import RobotModel
from wholearm_tools.sim import simulate
from wholearm_tools.sim.collision import Collider
from wholearm_tools.sim.occupancy import SweptGrid
from wholearm_tools.sim.strategies import Strategy

HOME = [1.2, -0.8]


@pytest.fixture(scope="module")
def run():
    return simulate(two_link(), pocket(), strategy="random", duration=12.0, rate=500.0, seed=3,
                    home=HOME)


def test_no_penetration_at_any_logged_sample(run) -> None:
    assert run.truth.n_contacts >= 5
    assert dense_penetration(run.run.robot, list(run.obstacles), run.q_true) <= 1e-6


def test_contact_configurations_touch_within_tolerance(run) -> None:
    robot = run.run.robot
    collider = Collider(robot, run.obstacles)
    for q, link in zip(run.contact_q, run.truth.contact_link, strict=True):
        c = collider.clearance(q[None], np.array([link])).value[0, 0]
        assert -1e-6 <= c <= 1e-6


def test_truth_point_is_at_radius_from_the_named_feature_and_on_the_surface(run) -> None:
    robot, truth = run.run.robot, run.truth
    rows = {s["id"]: s for s in truth.surfaces}
    from wholearm_tools.geometry import primitive_from_dict

    for i in range(truth.n_contacts):
        q, link, kind = run.contact_q[i], truth.contact_link[i], truth.contact_kind[i]
        pts = robot.joint_positions(q)
        a, b = pts[link], pts[link + 1]
        centre = a + truth.contact_s[i] * (b - a)
        w = robot.contact_radius(int(link), kind != "body")
        if kind == "tip":
            assert link == robot.dof - 1
        if kind == "joint":
            assert link < robot.dof - 1
        if kind == "body":
            assert 0.0 < truth.contact_s[i] < 1.0
        p = truth.contact_point[i]
        assert np.linalg.norm(p - centre) == pytest.approx(w, abs=1e-5)
        surf = primitive_from_dict(rows[int(truth.contact_surface[i])])
        assert abs(float(surf.signed_distance(p[: robot.dim][None])[0])) < 1e-5


def test_contact_times_are_exact_first_contacts(run) -> None:
    """Just before each truth contact the link is free; q_true matches the contact pose."""
    robot = run.run.robot
    collider = Collider(robot, run.obstacles)
    for t, _q in zip(run.truth.contact_t, run.contact_q, strict=True):
        k = int(np.floor(t * 500.0 + 1e-9))
        assert collider.min_clearance(run.q_true[k][None])[0] >= -1e-6
    assert np.all(np.diff(run.truth.contact_t) >= 0)


class FixedTargets(Strategy):
    """Test strategy: the given targets, in order, then nothing."""

    name = "fixed"

    def __init__(self, robot, obstacles, targets) -> None:
        super().__init__(robot, Collider(robot, obstacles), SweptGrid(robot), rng=0)
        self.targets = [np.asarray(t, dtype=float) for t in targets]

    def next_target(self, q):
        return self.targets.pop(0) if self.targets else None


def test_inner_joints_freeze_while_outer_joints_move() -> None:
    """Link 0 hits the post; joint 0 stops for good while joint 1 keeps moving, and the log
    shows it (joint 0 still with torque, joint 1 moving)."""
    robot, env = two_link(), pocket()
    strat = FixedTargets(robot, env, [[1.5, -0.6]])
    res = simulate(robot, env, strategy=strat, duration=4.0, seed=0, home=[0.0, -1.2])
    truth = res.truth
    assert truth.contact_link[0] == 0
    assert truth.contact_surface[0] == 0
    tc = truth.contact_t[0]
    t_next = truth.contact_t[1] if truth.n_contacts > 1 else res.moves[0].t_stop
    ks = np.arange(int(np.ceil(tc * 500)) + 1, int(t_next * 500))
    assert len(ks) > 50
    q = res.q_true[ks]
    assert np.ptp(q[:, 0]) < 1e-12  # joint 0 frozen
    assert np.ptp(q[:, 1]) > 0.1  # joint 1 still moving
    log = res.run.log
    late = ks[10:]
    free = np.abs(log.tau_cmd[ks[0] - 20, 0])
    assert np.all(np.abs(log.tau_cmd[late, 0]) > 3 * free)
    assert np.abs(log.tau_cmd[late[-1], 0]) > 20 * free
    assert np.max(np.abs(log.qd[late, 0])) < 0.05
    assert np.median(np.abs(log.qd[late, 1])) > 0.2


def test_dwell_then_retreat_along_the_swept_path(run) -> None:
    for move in run.moves:
        if not move.contacts or move.t_end > 11.9:
            continue
        k0, k1 = int(np.ceil(move.t_stop * 500)) + 1, int(move.t_retreat * 500)
        assert (k1 - k0) / 500 >= 0.05 - 0.004
        assert np.ptp(run.q_true[k0:k1 + 1], axis=0).max() < 1e-12


def test_same_seed_same_run_different_seed_different_run() -> None:
    a = simulate(two_link(), pocket(), duration=3.0, seed=11, home=HOME)
    b = simulate(two_link(), pocket(), duration=3.0, seed=11, home=HOME)
    c = simulate(two_link(), pocket(), duration=3.0, seed=12, home=HOME)
    np.testing.assert_array_equal(a.run.log.q, b.run.log.q)
    np.testing.assert_array_equal(a.run.log.tau_cmd, b.run.log.tau_cmd)
    assert not np.array_equal(a.run.log.q, c.run.log.q)


def test_sensor_model_quantises_positions_and_estimates_velocity(run) -> None:
    log = run.run.log
    quantum = 2 * np.pi / 2**17
    counts = log.q / quantum
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    assert np.max(np.abs(log.q - run.q_true)) < 1e-3
    moving = np.abs(run.qd_true) > 0.3
    rel = np.abs(log.qd[moving] - run.qd_true[moving]) / np.abs(run.qd_true[moving])
    assert np.median(rel) < 0.1
    assert np.all(np.abs(log.tau_cmd) <= run.run.robot.effort_limits + 1e-12)


def test_no_tunnelling_at_high_speed() -> None:
    """A thin wall crossed in far less than one log period is still hit, not passed through."""
    robot = RobotModel.from_spec({
        "joints": [{"name": "j", "origin": [0, 0, 0], "radius": 0.01, "limits": [-3, 3],
                    "velocity": 50.0, "effort": 5.0}],
        "tip": {"offset": [0.5, 0, 0], "radius": 0.0}}, name="fast")
    from wholearm_tools.geometry import Segment2D

    wall = Segment2D([0.2, 0.0], [1.0, 0.0], (0.0, 0.25), free_side=1, thickness=0.002)
    res = simulate(robot, [wall], strategy="sweep", duration=1.0, rate=50.0, seed=0,
                   home=[1.0], strategy_params={"counts": 2, "lower": [-1.0],
                                                "upper": [1.0]})
    assert res.truth.n_contacts >= 1
    assert dense_penetration(robot, [wall], res.q_true) <= 1e-6


def test_spatial_tip_sphere_and_plane() -> None:
    robot = RobotModel.from_spec({
        "joints": [
            {"name": "yaw", "origin": [0, 0, 0], "axis": [0, 0, 1], "radius": 0.03},
            {"name": "pitch", "origin": [0, 0, 0.2], "axis": [0, 1, 0], "radius": 0.02,
             "limits": [-1.5, 1.5]},
        ],
        "tip": {"offset": [0.4, 0, 0], "radius": 0.03}}, name="yp")
    env = [Surface(Plane([0, 0, -0.05], [0, 0, 1]), 1, 0),
           Surface(Sphere([0.0, 0.35, 0.2], 0.06), 1, 1)]
    strat = FixedTargets(robot, env, [[0.3, 1.4], [1.6, 0.0], [1.6, 0.0]])
    res = simulate(robot, env, strategy=strat, duration=8.0, seed=2, home=[0.0, -0.8])
    assert res.truth.n_contacts >= 2
    assert dense_penetration(robot, env, res.q_true) <= 1e-6
    assert res.truth.contact_surface.tolist()[:2] == [0, 1]
    assert res.truth.contact_kind[0] == "tip"


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"duration": 0.0}, "duration"),
    ({"rate": -5.0}, "rate"),
    ({"home": [0.0, 0.0]}, "in collision"),
    ({"home": [0.1]}, "shape"),
    ({"strategy": "bogus"}, "unknown strategy"),
])
def test_bad_inputs(kwargs, match) -> None:
    with pytest.raises(InputError, match=match):
        simulate(two_link(), pocket(), **{"home": HOME, **kwargs})


def test_radii_must_decrease_outward() -> None:
    robot = RobotModel.from_spec({
        "joints": [{"origin": [0, 0, 0], "radius": 0.01}, {"origin": [0.3, 0, 0],
                                                          "radius": 0.02}],
        "tip": {"offset": [0.2, 0, 0], "radius": 0.0}})
    with pytest.raises(InputError, match="decrease outward"):
        simulate(robot, pocket(), duration=1.0)


def _single_joint_move(home, target):
    robot, env = two_link(), pocket()
    strat = FixedTargets(robot, env, [target])
    return simulate(robot, env, strategy=strat, duration=3.0, seed=0, home=home)


def test_held_joint_resists_the_contact_force_of_its_own_link() -> None:
    """Only joint 0 moves; the tip (link 1) hits the wall.  Joint 1, held in place, carries the
    contact force's moment: tau_1 / tau_0 = g_1 / g_0 with g_i = (z x (p - o_i)) . n."""
    res = _single_joint_move([1.0, -0.9], [1.8, -0.9])
    truth = res.truth
    assert truth.n_contacts >= 1
    assert (truth.contact_link[0], truth.contact_kind[0], truth.contact_surface[0]) == (1, "tip", 1)
    q = res.contact_q[0]
    o = res.run.robot.joint_positions(q)[:2]
    p = truth.contact_point[0]
    n = np.array([0.0, -1.0, 0.0])  # the wall y = 0.52, free below: its normal towards the arm
    g = np.cross([0.0, 0.0, 1.0], p - o) @ n
    k0 = int(np.ceil(truth.contact_t[0] * 500))
    tau = res.run.log.tau_cmd[k0 + 20:k0 + 45]
    assert np.all(np.abs(tau[:, 1]) > 0.05)  # well above the noise (~1e-3 N m)
    np.testing.assert_allclose(tau[:, 1] / tau[:, 0], g[1] / g[0], rtol=0.02)


def test_contact_on_an_inner_link_leaves_outer_held_joints_unloaded() -> None:
    """Only joint 0 moves; link 0 hits the post: joint 1 is held but carries no load."""
    res = _single_joint_move([0.0, -0.9], [1.0, -0.9])
    truth = res.truth
    assert truth.contact_link[0] == 0
    assert truth.contact_surface[0] == 0
    k0 = int(np.ceil(truth.contact_t[0] * 500))
    tau = res.run.log.tau_cmd[k0 + 20:k0 + 45]
    assert np.all(np.abs(tau[:, 0]) > 0.5)
    assert np.all(np.abs(tau[:, 1]) < 0.01)
