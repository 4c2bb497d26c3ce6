"""Contact events from joint signals: what the controller does in free motion, and what it does not.

A joint is **obstructed** when it is at rest while its torque stands clear of what the
controller needs there without a contact.  What it needs without contact is learned from the
run itself, per joint, by a robust linear model over every sample (contacts are a minority of
the samples and its outliers)::

    tau_j ~ b_j + v_j qd_j + c_j sign(qd_j) [moving] + sum_k a_jk qdd_k
            + sum_k m_jk g_jk(q) + sum_k u_jk h_jk(q, qd, qdd)

a bias, viscous and Coulomb joint friction, inertia as constants (the joint's own, mostly the
drive's reflected inertia, and a constant part of the coupling), the coupled inertia of the arm
in its pose, and, where the log's torques hold gravity (measured effort, or a controller's
gravity compensation), gravity.  ``g_jk(q)`` is the moment about joint ``j``'s axis of a unit
downward force at joint ``k > j`` (or the tip), ``h_jk`` the moment of the inertial force of a
unit mass there as the other joints move it (:func:`inertia_features`), so ``m_jk`` and ``u_jk``
are effective masses: a joint held still while the others accelerate carries their coupled
inertia, which changes size and sign with the pose.  At rest Coulomb friction holds any
torque up to ``|c_j|``: a joint at rest is loaded when its torque departs from the model by
more than ``|c_j|`` and ``k_torque`` noise sigmas.  A joint resting on its mechanical stop
also takes the stop's reaction (:func:`wholearm_tools.contacts.detect.detect_contacts`).

An **event** runs from the first obstruction until the arm is released: obstruction in any
joint, with gaps shorter than ``release_time`` bridged (a rebound that comes back, a joint that
unloads for a moment while the tip slides), and at least ``min_stop_time`` of it in all.  Its
link is the outermost joint obstructed during it — the paper's "last one to stop": joints
outward of the link in contact carry no part of the force — unless that joint, while still
moving, moved freely (its torque within the free-motion model) before it stopped against a
second obstacle: the two are then two contacts, the second starting there.  A joint outward
of it that slides on while the obstructed ones are held, pushing along its motion beyond the
free-motion model for most of that time (a tip sliding on under the load, slowed but not
stopped), is the last one to stop: the link is then at least its link.  The event is
measured where it settles: once every joint it obstructs has stopped.

Noise levels come from second differences, which a smooth motion does not reach, so they do
not depend on how much of the run the arm is at rest.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.robot.model import RobotModel

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

_MAD = 1.4826  # MAD -> standard deviation for Gaussian noise


def smooth(x: FloatArray, width: int) -> FloatArray:
    """Centred moving average over ``width`` samples (edges use a shrinking window)."""
    if width <= 1:
        return x
    c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x]), axis=0)
    n = x.shape[0]
    half = width // 2
    lo = np.clip(np.arange(n) - half, 0, n)
    hi = np.clip(np.arange(n) - half + width, 0, n)
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def second_difference_scale(x: FloatArray) -> FloatArray:
    """White-noise scale of each column from second differences: 1.4826 MAD(d2 x) / sqrt 6.
    Linear ramps and plateaus have zero second difference, so motion does not inflate it."""
    if x.shape[0] < 4:
        return np.full(x.shape[1], 1e-12)
    d2 = x[2:] - 2 * x[1:-1] + x[:-2]
    return np.maximum(_MAD * np.median(np.abs(d2), axis=0) / np.sqrt(6), 1e-12)


def velocity_noise(q: FloatArray, qd: FloatArray, dt: float, width: int) -> FloatArray:
    """Noise of the ``width``-sample moving average of the logged velocity, per joint.

    From the second differences of ``qd`` (motion does not reach them), divided by
    ``sqrt(width)``; floored by one encoder quantum per sample period spread over the window
    (a quantised encoder at rest reads no noise at all)."""
    dq = np.abs(np.diff(q, axis=0))
    quantum = np.array([np.min(c[c > 1e-12]) if np.any(c > 1e-12) else 0.0 for c in dq.T])
    floor = np.maximum(0.5 * quantum / dt / width, 1e-9)
    return np.maximum(second_difference_scale(qd) / np.sqrt(width), floor)


def gravity_features(robot: RobotModel, q: FloatArray,
                     kinematics: tuple[FloatArray, FloatArray] | None = None) -> FloatArray:
    """``(N, n, n)``: moment about joint ``j``'s axis of a unit downward force at joint ``k + 1``
    (the tip for the last), for ``k >= j`` (zero below): gravity torques are a linear
    combination of these, weighted by the masses each outer point carries.  ``kinematics``:
    ``robot.joint_positions_and_axes(q)`` when the caller has it."""
    pts, axes = robot.joint_positions_and_axes(q) if kinematics is None else kinematics
    n = robot.dof
    down = np.array([0.0, 0.0, -1.0])
    out = np.zeros((q.shape[0], n, n))
    for j in range(n):
        lever = pts[:, j + 1:, :] - pts[:, j:j + 1, :]             # (N, n-j, 3)
        moment = np.cross(lever, down)
        out[:, j, j:] = np.einsum("nkc,nc->nk", moment, axes[:, j, :])
    return out


def inertia_features(robot: RobotModel, q: FloatArray, qd: FloatArray, qdd: FloatArray,
                     dt: float, width: int,
                     kinematics: tuple[FloatArray, FloatArray] | None = None) -> FloatArray:
    """``(N, n, n)``: moment about joint ``j``'s axis of the inertial (d'Alembert) force of a
    unit mass at joint ``k + 1`` (the tip for the last), for ``k >= j`` (zero below), less the
    part of joint ``j``'s own acceleration (the constant ``qdd_j`` term carries the joint's own
    inertia).  The torques the other joints' motion asks of joint ``j`` are a linear
    combination of these, weighted by the masses each outer point carries, in any pose.  The
    points' accelerations are differentiated from their velocities ``sum_i a_i x (p - o_i)
    qd_i`` (``qd`` smoothed) and smoothed as the joint accelerations are, so they include the
    centripetal and Coriolis parts.  Zero while the arm is at rest: they cannot take up a
    contact's static load.  ``kinematics``: ``robot.joint_positions_and_axes(q)`` when the
    caller has it."""
    pts, axes = robot.joint_positions_and_axes(q) if kinematics is None else kinematics
    n = robot.dof
    N = q.shape[0]
    p, o = pts[:, 1:, :], pts[:, :n, :]          # point k + 1, origin of joint i
    ao = np.cross(axes, o)
    # point k + 1's velocity sum_{i<=k} qd_i a_i x (p - o_i), from running sums over i
    vel = (np.cross(np.cumsum(axes * qd[:, :, None], axis=1), p)
           - np.cumsum(ao * qd[:, :, None], axis=1))
    acc = smooth(np.gradient(vel, dt, axis=0).reshape(N, -1), max(width, 3)).reshape(N, n, 3)
    # the lever a_i x (p - o_i) is never formed (an (N, n, n, 3) array): its moment
    # (a_i x (p - o_i)) . f = a_i . (p x f) - f . (a_i x o_i), and its square norm
    # |p - o_i|^2 - (a_i . (p - o_i))^2, are sums of 3-vector dot products per pair i <= k
    pxf = np.cross(p, acc)
    oo = np.square(o).sum(-1)
    aox = (axes * o).sum(-1)
    out = np.zeros((N, n, n))
    for k in range(n):
        a_i, o_i, ao_i = axes[:, :k + 1], o[:, :k + 1], ao[:, :k + 1]
        pk, fk = p[:, k, None, :], acc[:, k, None, :]
        moment = (a_i * pxf[:, k, None, :]).sum(-1) - (ao_i * fk).sum(-1)
        arm2 = ((pk * pk).sum(-1) - 2.0 * (o_i * pk).sum(-1) + oo[:, :k + 1]
                - np.square((a_i * pk).sum(-1) - aox[:, :k + 1]))
        out[:, :k + 1, k] = moment - arm2 * qdd[:, :k + 1]
    return out


@dataclass(frozen=True, slots=True)
class FreeMotion:
    """The learned free-motion torque of every joint.

    ``predicted (N, n)``: the model's torque at every sample; ``coulomb (n,)``: ``|c_j|``, the
    torque Coulomb friction can hold at rest; ``scale (n,)``: the robust scale of the model's
    residual while the arm moves (noise plus what the model does not capture of the motion);
    ``rest_scale (n,)``: the torque noise at rest; ``coef``: per joint, the fitted coefficients
    (for the record)."""

    predicted: FloatArray
    coulomb: FloatArray
    scale: FloatArray
    rest_scale: FloatArray
    coef: tuple[FloatArray, ...]


def _resolution(x: FloatArray) -> float:
    """Half the resolution of a signal: half the 5th percentile of its non-zero steps (a torque
    computed from a quantised encoder moves in steps of stiffness times the quantum; at rest
    its second differences are mostly zero, and a noise estimate from them collapses)."""
    d = np.abs(np.diff(x))
    big = 1e-6 * max(float(np.abs(x).max(initial=0.0)), 1e-12)
    d = d[d > big]
    return 0.5 * float(np.percentile(d, 5)) if d.size else 1e-9


def _lsq(X: FloatArray, y: FloatArray) -> FloatArray:
    """Least squares ``y ~ X`` for tall ``X (N, k)``, ``k`` small: the normal equations with the
    columns scaled to unit norm, solved by a pseudo-inverse (rank-safe).  A tenth of an SVD of
    ``X`` on a run's hundred thousand samples, and the model's columns (bias, velocity,
    friction sign, accelerations, gravity moments) are far from collinear once scaled."""
    G = X.T @ X
    d = np.sqrt(np.maximum(np.diag(G), 1e-300))
    z, *_ = np.linalg.lstsq(G / np.outer(d, d), (X.T @ y) / d, rcond=1e-12)
    return z / d


def _trimmed_fit(X: FloatArray, y: FloatArray, rows: BoolArray, keep: float = 0.5,
                 steps: int = 8, clip: float = 4.0) -> tuple[FloatArray, float]:
    """Robust least squares of ``y ~ X`` over ``rows``: concentration steps of least trimmed
    squares (refit on the ``keep`` share of the rows with the smallest residuals; high
    breakdown: contact samples may be nearly half of them), then one reweighting at ``clip``
    robust sigmas for efficiency.  Returns the coefficients and the residual scale."""
    Xi, yi = X[rows], y[rows]
    n = len(yi)
    if n <= X.shape[1]:
        return (_lsq(Xi, yi) if n else np.zeros(X.shape[1])), 1.0
    h = max(int(keep * n), X.shape[1] + 1)
    use = np.ones(n, dtype=bool)
    beta = np.zeros(X.shape[1])
    for _ in range(steps):
        beta = _lsq(Xi[use], yi[use])
        r = np.abs(yi - Xi @ beta)
        nxt = np.zeros(n, dtype=bool)
        nxt[np.argpartition(r, h - 1)[:h]] = True
        if np.array_equal(nxt, use):
            break
        use = nxt
    r = yi - Xi @ beta
    # scale of the kept half, corrected to a normal's sigma (the h smallest of |r|)
    q = float(np.partition(np.abs(r), h - 1)[h - 1])
    s = max(q / NormalDist().inv_cdf(0.5 + 0.5 * h / n), 1e-12)
    good = np.abs(r) <= clip * s
    if np.count_nonzero(good) > X.shape[1]:
        beta = _lsq(Xi[good], yi[good])
        r = yi[good] - Xi[good] @ beta
        s = max(_MAD * float(np.median(np.abs(r - np.median(r)))), 1e-12)
    return beta, s


def free_motion(tau: FloatArray, qd: FloatArray, qdd: FloatArray, moving: BoolArray,
                gravity: FloatArray | None, gain: float = 0.7,
                inertia: FloatArray | None = None) -> FreeMotion:
    """Fit the free-motion torque model of the module docstring, per joint, robustly
    (:func:`_trimmed_fit`) on the samples where some joint moves.

    Contacts are obstructions: most of their samples find the arm at rest, pressing (they do
    not enter the fit at all), and those that do not (impacts, a tip sliding) are a minority of
    the motion, which the trimming removes.  The arm at rest is then predicted from the same
    bias and gravity terms.  Gravity terms enter a joint's model only where they shrink its
    residual scale below ``gain`` of the model without them (where the torques hold gravity;
    elsewhere they would only fit what contacts do).  The coupled-inertia terms ``inertia``
    (:func:`inertia_features`) always enter: they vanish at rest, so they cannot take up a
    contact's static load, and where the torques do not carry the arm's inertia (a kinematic
    log) their weights come out near zero.  The torque noise at rest comes from second
    differences over the samples where the joint is at rest: a contact torque ramps or
    saturates there, so it does not reach them.

    ``tau, qd, qdd, moving : (N, n)``; ``gravity, inertia : (N, n, n)`` or None."""
    N, n = tau.shape
    arm_moves = moving.any(axis=1)
    pred = np.zeros((N, n))
    coul = np.zeros(n)
    scale = np.zeros(n)
    rest = np.zeros(n)
    coefs = []
    for j in range(n):
        base = [np.ones(N), qd[:, j], np.sign(qd[:, j]) * moving[:, j]]
        base += [qdd[:, k] for k in range(n)]
        fit_rows = arm_moves if np.count_nonzero(arm_moves) > 4 * (len(base) + n) else (
            np.ones(N, dtype=bool))
        coupled = [inertia[:, j, k] for k in range(j, n)] if inertia is not None else []
        best = None
        for grav in ([False, True] if gravity is not None else [False]):
            cols = base + ([gravity[:, j, k] for k in range(j, n)] if grav else []) + coupled
            X = np.stack(cols, axis=1)
            keep_cols = np.std(X[fit_rows], axis=0) > 1e-12
            keep_cols[0] = True
            beta, s = _trimmed_fit(X[:, keep_cols], tau[:, j], fit_rows)
            full = np.zeros(len(keep_cols))
            full[keep_cols] = beta
            if best is None or s < gain * best[1]:
                best = (full, s, X @ full)
        full, s, p = best
        coefs.append(full)
        pred[:, j] = p
        coul[j] = abs(float(full[2]))
        scale[j] = s
        at_rest = ~moving[:, j]
        rest[j] = max(second_difference_scale(tau[at_rest, j:j + 1])[0]
                      if np.count_nonzero(at_rest) > 10 else s, _resolution(tau[:, j]))
    return FreeMotion(pred, coul, scale, rest, tuple(coefs))


def runs(mask: BoolArray) -> tuple[IntArray, IntArray]:
    """Start and end (exclusive) indices of the runs of True in ``mask (N,)``."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def drop_short(mask: BoolArray, min_len: int) -> BoolArray:
    """``mask`` without its runs of True shorter than ``min_len`` samples; an ``(N, n)`` mask
    column by column (each joint's runs)."""
    if mask.ndim == 2:
        return np.stack([drop_short(mask[:, j], min_len) for j in range(mask.shape[1])], axis=1)
    out = mask.copy()
    s, e = runs(mask)
    for a, b in zip(s, e, strict=True):
        if b - a < min_len:
            out[a:b] = False
    return out


def bridge(mask: BoolArray, max_gap: int) -> BoolArray:
    """``mask`` with its gaps of False no longer than ``max_gap`` samples filled."""
    out = mask.copy()
    s, e = runs(mask)
    for a, b in zip(e[:-1], s[1:], strict=True):
        if b - a <= max_gap:
            out[a:b] = True
    return out


@dataclass(frozen=True, slots=True)
class Event:
    """One contact event: samples ``start..end`` (exclusive), its link, the sample where it
    settles, and the joints it obstructed."""

    start: int
    end: int
    link: int
    settle: int
    obstructed: tuple[int, ...]


def segment_events(obstructed: BoolArray, moving: BoolArray, free_moving: BoolArray,
                   min_len: int, release: int, dragging: BoolArray | None = None
                   ) -> list[Event]:
    """Contact events from the per-joint obstruction mask (see the module docstring).

    ``obstructed (N, n)``: joint at rest and loaded (short runs already dropped);
    ``moving (N, n)``: joint moving; ``free_moving (N, n)``: moving with its torque within
    the free-motion model; ``dragging (N, n)``: moving while pushing along its motion beyond
    the free-motion model (a tip sliding along a surface: one contact with the stop it ends
    in, so it keeps an event going).  A contact obstructs a *motion*: an event needs a joint
    that moved (within ``release`` samples) before it became obstructed; loads on joints that
    were held while the others moved freely (inertia the model does not capture) are not
    one."""
    N, n = obstructed.shape
    active = bridge(obstructed.any(axis=1), release)
    if dragging is not None:
        # a slide is part of the obstruction it ends in (the arm dragged along the surface
        # until it held), and joins two obstructions it connects (a rebound that comes back)
        drag = dragging.any(axis=1)
        for a in runs(active)[0]:
            b = a
            while b > 0 and drag[b - 1]:
                b -= 1
            active[b:a] = True
    out: list[Event] = []
    starts, ends = runs(active)
    for s, e in zip(starts, ends, strict=True):
        if np.count_nonzero(obstructed[s:e].any(axis=1)) < min_len:
            continue
        stopped_motion = False
        for j in range(n):
            a_, _ = runs(obstructed[s:e, j])
            for o in s + a_:
                if np.any(moving[max(0, o - release):o, j]):
                    stopped_motion = True
                    break
            if stopped_motion:
                break
        if not stopped_motion:
            continue
        onset = np.full(n, -1)
        for j in range(n):
            hit = np.flatnonzero(obstructed[s:e, j])
            if hit.size:
                onset[j] = s + int(hit[0])
        # second contacts are told from the first obstruction on (a slide before it moved
        # every joint, freely or not)
        pieces = [s + int(np.flatnonzero(obstructed[s:e].any(axis=1))[0])]
        # a joint obstructed later than the joints inward of it, which moved freely until it
        # stopped, stopped against an obstacle of its own: a second contact from its onset
        link_so_far = -1
        for j in np.argsort(np.where(onset >= 0, onset, N)):
            if onset[j] < 0:
                break
            if j > link_so_far >= 0 and onset[j] - pieces[-1] >= min_len:
                before = slice(pieces[-1], onset[j])
                was_free = free_moving[before, j]
                if was_free.size and np.count_nonzero(was_free) >= 0.5 * was_free.size:
                    pieces.append(int(onset[j]))
            link_so_far = max(link_so_far, int(j))
        pieces[0] = s
        bounds = [*pieces, e]
        for a, b in itertools.pairwise(bounds):
            joints = tuple(int(j) for j in np.flatnonzero(obstructed[a:b].any(axis=0)))
            if not joints:
                continue
            # settles once every joint it obstructs has been obstructed
            first = [a + int(np.flatnonzero(obstructed[a:b, j])[0]) for j in joints]
            settle = min(max(first), b - 1)
            # the link in contact is the last one to stop: a joint outward of the obstructed
            # ones that slides on while they are held, pushing along its motion beyond the
            # free-motion model for most of that time (a tip sliding on under the load), is
            # loaded by the contact too, which lies on its link or beyond.  A joint that only
            # catches up with its reference as the others stop (its coupled inertia changed)
            # does so for moments
            link = max(joints)
            if dragging is not None:
                held_for = b - settle
                slid = (np.count_nonzero(dragging[settle:b], axis=0)
                        >= max(min_len, 0.5 * held_for))
                link = max([link, *np.flatnonzero(slid).tolist()])
            out.append(Event(a, b, link, settle, joints))
    return out
