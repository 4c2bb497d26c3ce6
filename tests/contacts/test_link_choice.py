"""Link identification where velocities and the motion threshold cannot decide: contacts of the
bundled spatial scenarios replayed one guarded move at a time (the scenario's robot, obstacles,
controller and sensors; a fixed target through the contact configuration of a benchmark run)."""

from __future__ import annotations

import numpy as np
import pytest

from wholearm_tools.contacts import detect_contacts


def replay(name, q_contact, direction, *, before=0.25, beyond=0.1, warm_up=None, duration=2.5):
    """Simulate one guarded move from ``q_contact - before * d`` toward ``q_contact +
    beyond * d`` (``d`` = ``direction`` scaled to a largest component of 1 rad), after an
    optional free move by ``warm_up`` and back."""
    from tests.sim.test_simulator import FixedTargets
    from wholearm_tools.sim import simulate
    from wholearm_tools.sim.scenarios import load_scenario

    sc = load_scenario(name)
    qc = np.asarray(q_contact, float)
    d = np.asarray(direction, float)
    d = d / np.abs(d).max()
    home = qc - before * d
    targets = ([home + np.asarray(warm_up, float), home] if warm_up is not None else [])
    targets.append(qc + beyond * d)
    res = simulate(sc.robot, list(sc.obstacles),
                   strategy=FixedTargets(sc.robot, sc.obstacles, targets), duration=duration,
                   seed=0, home=home, controller=sc.controller, sensors=sc.sensors)
    return sc.robot, res.run


def test_lean_feasibility_matches_brute_force():
    """One lean for all slabs: the exact test against a dense grid of leans in the disc."""
    from wholearm_tools.contacts.detect import _lean_feasible

    rng = np.random.default_rng(1)
    N, H, R = 400, 3, 0.7
    A = rng.normal(size=(N, H, 2))
    A[:20, 0] = 0.0                  # a constraint no lean changes (a joint beyond the link)
    b = rng.normal(size=(N, H))
    c = np.abs(rng.normal(size=(N, H))) * 0.5
    use = rng.random((N, H)) < 0.8
    got = _lean_feasible(A, b, c, use, R)
    g = np.linspace(-R, R, 121)
    T = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    T = T[(T**2).sum(1) <= R * R]
    viol = np.abs(np.einsum("nhk,tk->nth", A, T) - b[:, None, :]) - c[:, None, :]
    worst = np.where(use[:, None, :], viol, -np.inf).max(-1).min(1)   # best lean on the grid
    assert np.all(got[worst <= 0])            # feasible on the grid: found
    # infeasible on the grid but found: only within the grid's spacing of feasible
    spacing = g[1] - g[0]
    assert np.all(worst[got] <= spacing * np.abs(A).sum(-1).max(-1)[got])
    assert 0.2 < got.mean() < 0.8


@pytest.mark.parametrize("one_force", [False, True])
def test_rows_without_held_joints_are_all_consistent(one_force):
    from wholearm_tools.contacts.detect import torque_consistent
    from wholearm_tools.sim.scenarios import load_scenario

    robot = load_scenario("paper_spatial").robot
    q = np.zeros((1, 5))
    x = np.array([[[0.3, 0.0, 0.2], [0.5, 0.1, 0.1]]])
    nu = np.array([[[0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]])
    ok = torque_consistent(robot, q, x, nu, np.ones((1, 5), bool), np.zeros((1, 5), bool),
                           np.ones((1, 5)), np.full(5, 0.1), np.array([4]), 0.02,
                           np.radians(20), one_force=one_force)
    assert ok.tolist() == [[True, True]]


def test_signature_from_the_unclipped_part_of_the_stop():
    """lab_circle seed 1, t = 38 s: joint 0 turns, link 1's body presses on the post and the
    held elbow reaches its 3 N m effort limit before the shoulder does.  The clipped torques
    (-4.7, -3.0) said the force ran through the tip; the signature is the held joint's load
    relative to the driving torque while neither is clipped, and with it eq. (2)'s
    torque-consistent boundary is the link's side."""
    from wholearm_tools.classify import tip_probability

    robot, run = replay("lab_circle", [0.0523, 1.7095], [-1.1361, 0.0], beyond=0.3)
    assert run.truth.contact_kind.tolist() == ["body"]
    c = detect_contacts(run.log, robot)
    assert c.link.tolist() == [1]
    assert c.held[0].tolist() == [False, True]
    limit = np.asarray(robot.effort_limits)
    assert np.all(np.abs(c.tau_peak[0]) < limit)
    # the load ratio of the log's unclipped stop samples
    tau = np.asarray(run.log.tau_cmd)
    k = c.index[0] + np.arange(5, 40)
    free = np.all(np.abs(tau[k]) < limit * (1 - 1e-9), axis=1)
    ratio = np.median(tau[k[free], 1] / tau[k[free], 0])
    assert c.tau_peak[0, 1] / c.tau_peak[0, 0] == pytest.approx(ratio, rel=0.02)
    assert tip_probability(run, c, 0.02).label.tolist() == ["link"]




def test_pitch_joints_that_kept_moving_admit_a_side_contact_across_the_arms_plane():
    """Yaw-pitch arm stretched along x: a post beside link 2 blocks the yaw joint, while the
    pitch joints keep moving (their motion is tangent to a contact across the arm's vertical
    plane).  The side point of link 2 is one they move along the surface; a point half-way to
    the link's top is not (pitching would have pushed it into the surface), nor is a side
    point when the yaw joint is the one that kept moving."""
    from wholearm_tools.contacts.detect import moves_along
    from wholearm_tools.sim.scenarios import load_scenario

    robot = load_scenario("paper_spatial").robot
    B = 0.02
    r2 = robot.link_radii[2]
    nu = np.array([[[0.0, -1.0, 0.0], [0.0, -np.sqrt(0.5), np.sqrt(0.5)]]])
    x = np.array([0.45, 0.0, 0.12]) + (r2 + B) * nu
    q = np.zeros((1, 5))
    pitch_moved = np.array([[False, True, True, False, False]])
    ok = moves_along(robot, q, x, nu, pitch_moved, np.array([2]), B, np.radians(20))
    assert ok.tolist() == [[True, False]]
    yaw_moved = np.array([[True, False, False, False, False]])
    ok = moves_along(robot, q, x[:, :1], nu[:, :1], yaw_moved, np.array([2]), B, np.radians(20))
    assert ok.tolist() == [[False]]
