"""Contact detection on tiny hand-built joint logs: one-stage, two-stage, noisy 50 Hz, errors."""

from __future__ import annotations

import numpy as np
import pytest

from wholearm_tools.contacts import Contacts, DetectionParams, detect_contacts
from wholearm_tools.errors import InputError
from wholearm_tools.logs.records import JointLog


def impedance_log(moves, *, n=3, rate=500.0, q_noise=2e-5, quantum=1e-4, qd_noise=0.003,
                  differentiate=False, seed=0, K=20.0, D=1.0, speed=0.8, fling=None,
                  creep=None, push=None, slide=None):
    """A guarded-move impedance log: ``moves`` = list of (target (n,), {joint: block_time}).

    Each move drives the commanded position toward ``target`` at ``speed`` rad/s per joint; a
    joint listed in the block mapping freezes at that time (contact) while its command goes on;
    after the move has settled for 0.1 s the command returns to the start (retreat) and the
    blocks are released.  ``fling`` ``(n,)`` rad/s: the impact of each block throws the arm at
    that velocity for 30 ms (a rebound of the blocked joints, the outer ones flung on) before
    the blocked joints come to rest and the others' controllers pull them back.  ``creep``
    rad/s: the joint of the link in contact is not stopped but held back, creeping on at that
    speed towards its command (negative: pushed back, away from it).  ``push`` rad/s: the
    joint of the link in contact, at rest before, is pushed into motion at that speed.
    ``slide`` ``(seconds, (n,) rad/s)``: on touching, the arm slides on at that velocity for
    that long (a tip dragged along the surface, the link pivoting about it) before it stops.
    """
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    q = np.zeros(n)
    qc = np.zeros(n)
    rows_q, rows_qd, _rows_tau, rows_qc = [], [], [], []
    t = 0.0
    ts = []

    kick = np.zeros(n)
    kick_until = -1.0

    creeping = np.zeros(n, bool)
    sliding_until = -1.0

    def step(target, blocked):
        nonlocal t, q, qc
        qc = qc + np.clip(target - qc, -speed * dt, speed * dt)
        new = q + (qc - q) * (1 - np.exp(-dt / 0.02))
        new[blocked] = q[blocked]
        if creeping.any():
            new[creeping] = (q[creeping] + push * dt if push is not None else
                             q[creeping] + creep * dt * np.sign(qc - q)[creeping])
        if t < kick_until:
            new += kick * dt
        if t < sliding_until:
            new = q + np.asarray(slide[1], float) * dt
        qd_true = (new - q) / dt
        q = new
        ts.append(t)
        t += dt
        rows_q.append(q.copy())
        rows_qd.append(qd_true)
        rows_qc.append(qc.copy())

    for _ in range(round(0.2 * rate)):  # rest at start
        step(np.zeros(n), np.zeros(n, bool))
    for target, blocks in moves:
        target = np.asarray(target, float)
        start = q.copy()
        t0 = t
        blocked = np.zeros(n, bool)
        settled = 0
        while settled < round(0.1 * rate):
            for j, tb in blocks.items():
                if (slide is not None and t - t0 >= tb and sliding_until < t0
                        and not blocked[j]):
                    sliding_until = t + slide[0]
                if slide is not None and t - t0 >= tb and t < sliding_until:
                    continue
                if t - t0 >= tb and not blocked[j] and not creeping[j]:
                    blocked[: j + 1] = True  # joints 0..j stop when link j touches
                    if creep is not None or push is not None:
                        blocked[j], creeping[j] = False, True
                    if fling is not None:
                        kick = np.asarray(fling, float)
                        kick_until = t + 0.03
            step(target, blocked)
            if np.all(blocked | creeping | (np.abs(rows_qd[-1]) < 1e-3)) and (
                    np.any(blocked) or np.allclose(q, target, atol=1e-3)):
                settled += 1
        creeping[:] = False
        while not np.allclose(q, start, atol=1e-3):
            step(start, np.zeros(n, bool))
        for _ in range(round(0.1 * rate)):
            step(start, np.zeros(n, bool))
    q_true = np.array(rows_q)
    qd_true = np.array(rows_qd)
    q_meas = np.round((q_true + rng.normal(0, q_noise, q_true.shape)) / quantum) * quantum
    if differentiate:
        qd_meas = np.vstack([np.zeros((1, n)), np.diff(q_meas, axis=0) * rate])
    else:
        qd_meas = qd_true + rng.normal(0, qd_noise, qd_true.shape)
    qc_arr = np.array(rows_qc)
    tau = K * (qc_arr - q_meas) - D * qd_meas
    names = tuple(f"j{i}" for i in range(n))
    return JointLog(names, np.array(ts), q_meas, qd_meas, tau, qc_arr)


def test_single_contacts_identify_the_link():
    moves = [([0.6, 0.5, 0.4], {1: 0.3}),   # link 1 touches; joint 2 goes on to its target
             ([0.6, 0.5, 0.4], {2: 0.35}),  # tip link
             ([0.6, 0.5, 0.4], {0: 0.2})]   # link 0
    log = impedance_log(moves)
    c = detect_contacts(log)
    assert isinstance(c, Contacts)
    assert c.link.tolist() == [1, 2, 0]
    assert c.q.shape == (3, 3)
    assert c.qd_before.shape == (3, 3)
    # contact times: within 40 ms after the block instants
    assert np.all(np.diff(c.t) > 0)
    assert np.all(c.t_end > c.t)
    # motion just before the stop is positive on the joints that moved
    assert np.all(c.qd_before[0, :2] > 0.3)


def test_the_approach_is_measured_before_the_impact_not_during_it():
    """Only joint 0 drives into the contact; the impact bounces it back and flings joints 1
    and 2 on at 1 rad/s for 30 ms before the arm comes to rest.  The motion that led into the
    contact (eq. 2's velocity, the rigid-group choice's levers) is joint 0's alone."""
    log = impedance_log([([0.6, 0.0, 0.0], {0: 0.4})], fling=[-0.5, 1.0, 1.0])
    c = detect_contacts(log)
    assert c.link.tolist() == [0]
    assert c.qd_before[0, 0] > 0.5
    assert np.all(np.abs(c.qd_before[0, 1:]) < 0.05)


@pytest.mark.xfail(strict=True, reason="known limitation (issue 18): the approach is measured "
                   "inside the slide; moving it before the slide (docs/method.md, open "
                   "issues) made labels better but maps no better")
def test_the_approach_of_a_contact_that_slid_is_the_motion_before_the_slide():
    """Shoulder and elbow drive the arm into a surface at 0.8 rad/s; the tip touches and the
    link pivots about it for 0.3 s: the surface pushes shoulder and elbow back against their
    commands and swings the wrist, every joint loaded beyond the free motion and none pushing
    along its motion, then the arm stops.  The motion that led into the contact, which
    eq. (2) reads, is the approach (shoulder and elbow forward), not the slide's pivot."""
    for seed in range(3):
        log = impedance_log([([0.6, 0.5, 0.0], {2: 0.35})], slide=(0.3, [-0.1, -0.05, 0.4]),
                            seed=seed)
        c = detect_contacts(log)
        assert len(c) == 1
        assert np.all(c.qd_before[0, :2] > 0.5)
        assert abs(c.qd_before[0, 2]) < 0.05


def test_a_joint_the_contact_holds_back_without_stopping_it_names_the_link():
    """The tip touches: shoulder and elbow stop, and the wrist, its torque against the load
    growing, is pushed back at 0.1 rad/s (an eighth of its speed) by the tip sliding on the
    surface.  It never comes to rest and never pushes along its motion, yet its link is the one
    in contact.  (A wrist that runs on at its own speed when the elbow's link touches is not
    held back: the first move of ``test_single_contacts_identify_the_link``, link 1.)"""
    for seed in range(3):
        log = impedance_log([([0.6, 0.5, 0.4], {2: 0.35})], creep=-0.1, seed=seed)
        c = detect_contacts(log)
        assert c.link.tolist() == [2]
        assert c.qd_before[0, 2] > 0.3


@pytest.mark.parametrize("creep", [-0.1, -0.025])
def test_a_joint_the_contact_back_drives_names_the_link_whatever_the_approach_read(creep):
    """The tip touches and the arm slides for 0.3 s, the wrist already pushed back, before
    shoulder and elbow stop; the wrist creeps on, pushed back at the same speed: 0.1 rad/s, or
    about its velocity threshold, so that it is at rest for moments too short to count as a
    stop.  The approach is read inside the slide, so the wrist's motion did not change from
    it, yet it never moves along its load: the contact drives it, and its link is the one in
    contact."""
    for seed in range(3):
        log = impedance_log([([0.6, 0.5, 0.4], {2: 0.35})], slide=(0.3, [0.1, 0.1, creep]),
                            creep=creep, seed=seed)
        c = detect_contacts(log)
        assert c.link.tolist() == [2]
        assert c.qd_before[0, 2] < 0  # the approach read is the slide's, wrist pushed back
        if creep > -0.05:
            assert abs(c.velocity_threshold[2] - abs(creep)) < 0.2 * abs(creep)


def test_a_joint_at_rest_the_contact_sets_moving_names_the_link():
    """Shoulder and elbow move, the wrist holds still; the tip touches, the inner joints
    stop, and the contact pushes the wrist into motion at 0.3 rad/s against its controller.
    The wrist never comes to rest under load and had no speed to be slowed from, yet the
    contact changed its motion: its link is the one in contact."""
    for seed in range(3):
        log = impedance_log([([0.6, 0.5, 0.0], {2: 0.35})], push=0.3, seed=seed)
        c = detect_contacts(log)
        assert c.link.tolist() == [2]
        assert c.qd_before[0, 2] == 0.0


def test_reaching_the_target_is_not_a_contact():
    log = impedance_log([([0.3, 0.2, 0.1], {}), ([0.2, -0.2, 0.3], {})])
    assert len(detect_contacts(log)) == 0


@pytest.mark.xfail(strict=True, reason="known limitation (issue 18): the retreat's arrival at "
                   "its start 0.09 s before the log ends is taken for a third obstruction")
def test_two_stage_contact_gives_two_contacts_inner_then_outer():
    log = impedance_log([([0.6, 0.5, 0.8], {0: 0.25, 2: 0.6})])
    c = detect_contacts(log)
    assert c.link.tolist() == [0, 2]
    # second contact: joint 0 already at rest → its velocity before is 0; joints 1, 2 moving
    assert c.qd_before[1, 0] == 0.0
    assert np.all(c.qd_before[1, 1:] > 0.3)
    assert c.index[1] > c.index[0]


def test_noisy_50hz_log_with_differentiated_velocity():
    moves = [([0.6, 0.5, 0.4], {1: 0.3}), ([0.6, 0.5, 0.4], {2: 0.4}),
             ([0.6, 0.5, 0.9], {0: 0.2, 2: 0.7}), ([0.3, 0.2, 0.1], {})]
    log = impedance_log(moves, rate=50.0, q_noise=3e-4, quantum=2e-4, differentiate=True, seed=3)
    c = detect_contacts(log)
    assert c.link.tolist() == [1, 2, 0, 2]
    # thresholds follow the noise: the 50 Hz differentiated velocity is much noisier
    quiet = detect_contacts(impedance_log(moves, seed=3))
    assert np.all(c.velocity_threshold > quiet.velocity_threshold)


def test_empty_contacts_are_well_formed():
    log = impedance_log([([0.3, 0.2, 0.1], {})])
    c = detect_contacts(log)
    assert len(c) == 0
    assert c.q.shape == (0, 3)
    assert c.qd_before.shape == (0, 3)
    assert c.select(np.zeros(0, bool)).link.shape == (0,)


def test_missing_torques_and_nans_are_clear_errors():
    log = impedance_log([([0.3, 0.2, 0.1], {1: 0.1})])
    no_tau = JointLog(log.joint_names, log.t, log.q, log.qd)
    with pytest.raises(InputError, match="no commanded torques"):
        detect_contacts(no_tau)
    qd = np.array(log.qd)
    qd[10, 1] = np.nan
    bad = JointLog(log.joint_names, log.t, log.q, qd, log.tau_cmd)
    with pytest.raises(InputError, match="qd contains 1 NaN"):
        detect_contacts(bad)
    with pytest.raises(InputError, match="min_stop_samples"):
        DetectionParams(min_stop_samples=0)


def test_single_joint_move_link_from_the_held_joints_load():
    """Only joint 0 moves and link 1's tip hits the wall (simulated).  Joint 1 is held, so
    velocities alone cannot tell link 0 from link 1; the load it carries does — with no robot
    model and no swept map (rigid_choice="outer" would say 1 for any rigid move, "map" needs a
    robot, so use the innermost link of the group to show the torque alone decides)."""
    from tests.sim.conftest import pocket, two_link
    from tests.sim.test_simulator import FixedTargets
    from wholearm_tools.sim import simulate

    robot, env = two_link(), pocket()
    for home, target, link in (([1.0, -0.9], [1.8, -0.9], 1), ([0.0, -0.9], [1.0, -0.9], 0)):
        res = simulate(robot, env, strategy=FixedTargets(robot, env, [target]), duration=3.0,
                       seed=0, home=home)
        c = detect_contacts(res.run.log, params=DetectionParams(rigid_outer=False))
        assert len(c) == res.truth.n_contacts >= 1
        assert c.link[0] == res.truth.contact_link[0] == link


def _planar_pair(upper: float = 2.5):
    """A two-link planar arm named like :func:`impedance_log`'s joints."""
    from wholearm_tools.robot.model import RobotModel

    return RobotModel.from_spec({
        "joints": [
            {"name": "j0", "origin": [0, 0, 0], "radius": 0.02, "limits": [-2.5, 2.5],
             "velocity": 1.5, "effort": 6.0},
            {"name": "j1", "origin": [0.35, 0, 0], "radius": 0.012, "limits": [-2.5, upper],
             "velocity": 1.5, "effort": 6.0},
        ],
        "tip": {"offset": [0.30, 0, 0], "radius": 0.015},
    }, name="pair")


def test_a_joint_held_while_another_accelerates_carries_its_coupled_inertia_not_a_contact():
    """The elbow holds still while the shoulder swings, at three elbow angles: its torque is
    the coupled inertia of a mass at the tip, which changes sign and size with the pose (no
    constant per-joint coefficient fits it).  The free-motion model learns it from the run:
    no contact is reported, and the elbow's threshold stays near its noise instead of growing
    with what a pose-blind model would miss."""
    robot = _planar_pair()
    rate, rng = 500.0, np.random.default_rng(3)
    dt = 1.0 / rate

    def min_jerk(a, b, T):
        s = np.linspace(0.0, 1.0, round(T * rate), endpoint=False)
        return a + (b - a) * (10 * s**3 - 15 * s**4 + 6 * s**5)

    q0, q1 = [0.0], [0.0]
    for elbow in (-2.0, 0.0, 1.0, -1.0):
        q1 += list(min_jerk(q1[-1], elbow, 1.0)) + [elbow] * round(0.3 * rate)
        q0 += [q0[-1]] * (len(q1) - len(q0))
        for swing in (0.8, 0.0, -0.6, 0.0):
            q0 += list(min_jerk(q0[-1], swing, 0.6)) + [swing] * round(0.3 * rate)
            q1 += [q1[-1]] * (len(q0) - len(q1))
    q = np.stack([q0, q1], axis=1)
    qd = np.gradient(q, dt, axis=0)
    pts = robot.joint_positions(q)                        # (N, 3, 3): joints and tip
    acc = np.gradient(np.gradient(pts, dt, axis=0), dt, axis=0)
    masses = np.array([0.0, 0.8, 0.5])                    # at the elbow and at the tip
    tau = np.zeros_like(q)
    for j in range(2):                                    # moments of m * acceleration
        lever = pts[:, j + 1:, :2] - pts[:, j:j + 1, :2]
        cross = lever[..., 0] * acc[:, j + 1:, 1] - lever[..., 1] * acc[:, j + 1:, 0]
        tau[:, j] = cross @ masses[j + 1:]
    held = np.abs(qd[:, 1]) < 1e-9
    load = np.abs(tau[held, 1]).max()                     # the elbow's coupled load
    assert load > 0.5
    t = np.arange(len(q)) * dt
    log = JointLog(("j0", "j1"), t, q + rng.normal(0, 2e-5, q.shape),
                   qd + rng.normal(0, 0.003, q.shape), tau + rng.normal(0, 0.002, q.shape))
    c = detect_contacts(log, robot)
    assert len(c) == 0
    # and the elbow stays sensitive: a contact loading it by a tenth of that is seen
    assert c.torque_threshold[1] < 0.1 * load


def test_a_joint_driven_against_its_own_stop_is_no_contact():
    """The elbow's command runs past its upper limit: the joint rests on its stop while its
    controller pushes on, a torque the stop explains.  With the limit out of the way the same
    signals are a contact on link 1 (a joint at rest pushing against something)."""
    log = impedance_log([([0.5, 0.2], {}), ([-0.4, -0.3], {}), ([0.3, 0.25], {}),
                         ([-0.2, 0.1], {}), ([0.5, 0.45], {})], n=2)
    q, qd, tau, qc = (np.array(a) for a in (log.q, log.qd, log.tau_cmd, log.q_cmd))
    stop = 0.3
    on = q[:, 1] >= stop
    q[on, 1] = stop + np.random.default_rng(1).normal(0, 2e-5, on.sum())
    qd[on, 1] = np.random.default_rng(2).normal(0, 0.003, on.sum())
    tau[:, 1] = 20.0 * (qc[:, 1] - q[:, 1]) - 1.0 * qd[:, 1]
    pushed = JointLog(log.joint_names, log.t, q, qd, tau, qc)
    assert detect_contacts(pushed, _planar_pair(upper=stop)).link.tolist() == []
    assert detect_contacts(pushed, _planar_pair(upper=2.5)).link.tolist() == [1]
