"""Contact detection and link identification from joint velocities and commanded torques.

Only the robot's own signals are used (never ground truth).  The principle (Kaneko & Tanie 1994,
the paper's section 2): when link ``n`` touches, joints ``0..n`` stop while their commanded torque
persists; joints beyond ``n`` keep moving as long as torque drives them, and stop with (almost)
zero torque when they reach their target.  Hence the link in contact is the outermost joint of
the stopped prefix ``0..n`` that is *blocked* (stopped **and** loaded).

Thresholds come from the log's own noise level (see :func:`estimate_noise`), so the same code
runs on a 500 Hz simulated log and on a noisier 50 Hz real one:

* velocity noise ``sigma_v[j]``: zero-centred, sigma-clipped MAD of the (lightly smoothed)
  velocity over the samples where it is compatible with rest, started from the white-noise
  estimate ``MAD(diff qd) / sqrt(2)`` and floored by the encoder quantum / sample period;
* torque noise ``sigma_tau[j]``: the same estimator applied to ``tau_cmd`` on the samples where
  the whole arm is at rest (targets reached and contacts both qualify; the contact torques are the
  outliers the clipping removes), floored by half the torque resolution (5th percentile of the
  non-zero sample-to-sample torque steps: a quantised encoder moves the torque in steps of
  ``K * quantum``).

``stopped = |qd_smooth| < k_velocity * sigma_v``, ``loaded = |tau_cmd| > k_torque * sigma_tau``,
and a state must last ``max(min_stop_time, min_stop_samples / rate)`` to count.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError
from wholearm_tools.logs.records import JointLog
from wholearm_tools.robot.model import RobotModel

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_MAD = 1.4826  # MAD -> standard deviation for Gaussian noise


def _frozen(arr: Any, dtype: Any = float) -> NDArray[Any]:
    out = np.array(arr, dtype=dtype)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, slots=True)
class DetectionParams:
    """Tuning of :func:`detect_contacts`; the defaults are noise-relative, not absolute.

    Parameters
    ----------
    k_velocity : float
        A joint is *stopped* when its smoothed speed is below ``k_velocity * sigma_v``.
    k_torque : float
        A joint is *loaded* when ``|tau_cmd|`` exceeds ``k_torque * sigma_tau``.
    min_stop_time : float
        Seconds a contact state must persist (the simulator dwells >= 50 ms).
    min_stop_samples : int
        ... and at least this many samples (guards slow logs).
    smooth_time : float
        Width in seconds of the centred moving average applied to ``qd`` before thresholding
        (at least one sample, so a 50 Hz log is not smoothed).
    before_time : float
        Window in seconds before the stop over which ``qd_before`` is averaged.
    motion_torque_fraction : float
        A joint is loaded only when ``|tau_cmd|`` also exceeds this fraction of its median
        ``|tau_cmd|`` while it moves freely: a contact torque builds up beyond the motion
        torque, while a joint creeping near its target carries a torque that is far above the
        (tiny) noise yet far below the motion level.  A *held* joint (at rest and unloaded
        before the stop) is not creeping: its load counts once it stands ``k_torque`` standard
        errors clear of zero (:func:`_raise_to_loaded_held`).
    rigid_outer : bool
        When the joints beyond the stopped link were at rest and unloaded (a single-joint
        move), links ``n..m`` moved as one rigid body and the joint signals cannot tell which
        touched.  True (default): choose within that group (see ``rigid_choice``); False: keep
        the innermost link ``n``.
    rigid_choice : str
        ``"map"`` (default; needs ``robot``): the link of the group whose dilated boundary
        sweeps the most admissible space, eq. (2)'s integral over each candidate link with the
        whole run's swept map (see :func:`_choose_rigid`); ``"outer"``: the outermost link
        (the map-free prior; also used when no robot is given).
    rigid_dilation : float
        Dilation [m] used by the ``"map"`` choice (the map is cached, so classifying at the same
        B reuses it).
    velocity_threshold, torque_threshold : float or (n,) float, optional
        Absolute overrides of the noise-derived thresholds.
    """

    k_velocity: float = 5.0
    k_torque: float = 6.0
    min_stop_time: float = 0.03
    min_stop_samples: int = 2
    smooth_time: float = 0.01
    before_time: float = 0.02
    motion_torque_fraction: float = 0.2
    rigid_outer: bool = True
    rigid_choice: str = "map"
    rigid_dilation: float = 0.02
    velocity_threshold: Any = None
    torque_threshold: Any = None

    def __post_init__(self) -> None:
        for name in ("k_velocity", "k_torque", "min_stop_time", "smooth_time", "before_time",
                     "motion_torque_fraction"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise InputError(f"{name} must be a finite non-negative number, got {value!r}")
        if self.rigid_choice not in ("map", "outer"):
            raise InputError("rigid_choice must be 'map' or 'outer', got "
                             f"{self.rigid_choice!r}")
        if not (np.isfinite(self.rigid_dilation) and self.rigid_dilation > 0):
            raise InputError("rigid_dilation must be a positive length, got "
                             f"{self.rigid_dilation!r}")
        if self.min_stop_samples < 1:
            raise InputError(f"min_stop_samples must be >= 1, got {self.min_stop_samples}")


@dataclass(frozen=True, slots=True, eq=False)
class Contacts:
    """Detected contacts, columnar and read-only (``M`` contacts, ``n`` joints).

    Parameters
    ----------
    t : (M,) float
        Contact time (first sample of the stop), seconds on the log clock.
    link : (M,) int
        0-based index of the link in contact.
    index : (M,) int
        Index of that sample in the log.
    q : (M, n) float
        Joint positions at contact (joints ``0..link`` averaged over the first samples of the stop).
    qd_before : (M, n) float
        Joint velocities just before the stop (joints that were already at rest set to 0); the
        motion direction that eq. (2) integrates against.
    t_end : (M,) float
        End of the blocked state (the retreat), seconds.
    velocity_threshold, torque_threshold : (n,) float
        The thresholds that were used (noise-derived unless overridden).
    tau_peak : (M, n) float
        The contact force's torque signature: the commanded torques at the height of the stop
        where none of the joints involved is clipped (the sample with the largest driving
        torques while the driving and the held joints are at rest below their effort limits —
        a clipped torque no longer grows with the force), each held joint's entry replaced by
        its load (change from its rest level), fitted over the whole stop in proportion to the
        driving torques.  Zeros when unknown.
    held : (M, n) bool
        Joints at rest and unloaded just before the stop (not driven by this move): their
        torque at the stop is the contact force's moment alone.  All False when unknown.
    link_prior : (M, n) float
        Probability of each link having made the contact, from the signals and the swept map
        alone: one-hot at ``link`` unless the joints could not tell the links of a rigid group
        apart (then each one's share of eq. (2)'s admissible mass, see ``_choose_rigid``).
        The fitted map refines it (:func:`wholearm_tools.pipeline.reconstruct`, column
        ``link_by_map`` of contacts.csv).  One-hot at ``link`` when not given.
    """

    t: FloatArray
    link: IntArray
    index: IntArray
    q: FloatArray
    qd_before: FloatArray
    t_end: FloatArray
    velocity_threshold: FloatArray
    torque_threshold: FloatArray
    meta: dict[str, Any] = field(default_factory=dict)
    tau_peak: FloatArray | None = None
    held: NDArray[np.bool_] | None = None
    link_prior: FloatArray | None = None

    def __post_init__(self) -> None:
        n = np.asarray(self.velocity_threshold).shape[0]
        m = np.asarray(self.t).reshape(-1).shape[0]
        object.__setattr__(self, "t", _frozen(self.t).reshape(m))
        object.__setattr__(self, "link", _frozen(self.link, np.int64).reshape(m))
        object.__setattr__(self, "index", _frozen(self.index, np.int64).reshape(m))
        object.__setattr__(self, "t_end", _frozen(self.t_end).reshape(m))
        for name, dtype in (("q", float), ("qd_before", float), ("tau_peak", float),
                            ("held", bool)):
            value = getattr(self, name)
            arr = _frozen(np.zeros((m, n)) if value is None else value, dtype)
            if arr.size == 0:
                arr = _frozen(np.zeros((m, n)), dtype)
            if arr.shape != (m, n):
                raise InputError(f"expected {name} of shape ({m}, {n}), got {arr.shape}")
            object.__setattr__(self, name, arr)
        for name in ("velocity_threshold", "torque_threshold"):
            arr = _frozen(getattr(self, name)).reshape(-1)
            if arr.shape != (n,):
                raise InputError(f"expected {name} of shape ({n},), got {arr.shape}")
            object.__setattr__(self, name, arr)
        if np.any((self.link < 0) | (self.link >= n)):
            raise InputError(f"contact links must be in 0..{n - 1}, got {self.link.tolist()}")
        if self.link_prior is None:
            object.__setattr__(self, "link_prior", _frozen(np.eye(n)[self.link] if m
                                                           else np.zeros((0, n))))
        else:
            prior = _frozen(self.link_prior) if m else _frozen(np.zeros((0, n)))
            if prior.shape != (m, n):
                raise InputError(f"expected link_prior of shape ({m}, {n}), got {prior.shape}")
            if m and not (np.all(prior >= 0) and np.allclose(prior.sum(axis=1), 1.0)):
                raise InputError("link_prior rows must be probabilities summing to 1")
            object.__setattr__(self, "link_prior", prior)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def n_joints(self) -> int:
        return int(self.velocity_threshold.shape[0])

    def select(self, mask: Any) -> Contacts:
        """A new record with the contacts where ``mask`` (bool or index array) selects."""
        sel = np.arange(len(self))[mask]
        return Contacts(self.t[sel], self.link[sel], self.index[sel], self.q[sel],
                        self.qd_before[sel], self.t_end[sel], self.velocity_threshold,
                        self.torque_threshold, dict(self.meta),
                        tau_peak=self.tau_peak[sel], held=self.held[sel],
                        link_prior=self.link_prior[sel])


# --------------------------------------------------------------------------- noise estimation
def _clipped_scale(x: FloatArray, start: FloatArray, iters: int = 8, k: float = 4.0,
                   mask: NDArray[np.bool_] | None = None) -> FloatArray:
    """Zero-centred sigma-clipped robust scale of each column of ``x`` (N, n).

    Iterates ``s <- 1.4826 * median(|x|  where |x| < k s)`` from ``start``; the rest cluster of a
    signal is what survives, motion and contact torques are clipped away.
    """
    a = np.abs(x)
    if mask is not None:
        a = a[mask]
    s = np.array(start, dtype=float)
    if a.shape[0] == 0:
        return s
    for _ in range(iters):
        new = s.copy()
        for j in range(a.shape[1]):
            inside = a[:, j][a[:, j] < k * s[j]]
            if inside.shape[0] >= max(5, 0.02 * a.shape[0]):
                new[j] = max(_MAD * float(np.median(inside)), 1e-12)
        if np.allclose(new, s, rtol=1e-3):
            break
        s = new
    return s


def _white_scale(x: FloatArray) -> FloatArray:
    """Per-column white-noise scale from first differences: 1.4826 MAD(diff x) / sqrt 2."""
    if x.shape[0] < 3:
        return np.full(x.shape[1], 1e-12)
    d = np.diff(x, axis=0)
    return np.maximum(_MAD * np.median(np.abs(d - np.median(d, axis=0)), axis=0) / np.sqrt(2),
                      1e-12)


def _second_diff_scale(x: FloatArray, mask: NDArray[np.bool_]) -> FloatArray:
    """White-noise scale of each column from second differences: 1.4826 MAD(d2 x) / sqrt 6.

    Only differences whose three samples all lie in ``mask`` are used (all of them if fewer than
    10 do).  Linear ramps and plateaus have zero second difference, so they do not inflate it.
    """
    if x.shape[0] < 4:
        return np.full(x.shape[1], 1e-12)
    d2 = x[2:] - 2 * x[1:-1] + x[:-2]
    ok = mask[2:] & mask[1:-1] & mask[:-2]
    if np.count_nonzero(ok) >= 10:
        d2 = d2[ok]
    return np.maximum(_MAD * np.median(np.abs(d2), axis=0) / np.sqrt(6), 1e-12)


def _smooth(x: FloatArray, width: int) -> FloatArray:
    """Centred moving average over ``width`` samples (edges use a shrinking window)."""
    if width <= 1:
        return x
    c = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x]), axis=0)
    n = x.shape[0]
    half = width // 2
    lo = np.clip(np.arange(n) - half, 0, n)
    hi = np.clip(np.arange(n) - half + width, 0, n)
    return (c[hi] - c[lo]) / (hi - lo)[:, None]


def estimate_noise(log: JointLog, params: DetectionParams | None = None
                   ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Velocity noise, torque noise and the smoothed velocity of a log.

    Returns
    -------
    sigma_v : (n,) float, noise of the smoothed velocity [rad/s]
    sigma_tau : (n,) float, commanded-torque noise at rest [N m]
    qd_smooth : (N, n) float
    """
    params = params or DetectionParams()
    _check_log(log)
    dt = 1.0 / log.rate
    width = max(1, round(params.smooth_time / dt))
    qd = _smooth(np.asarray(log.qd), width)
    # floor: one encoder quantum per sample period, spread over the smoothing window
    dq = np.abs(np.diff(np.asarray(log.q), axis=0))
    quantum = np.array([np.min(c[c > 1e-12]) if np.any(c > 1e-12) else 0.0 for c in dq.T])
    floor = np.maximum(0.5 * quantum / dt / width, 1e-9)
    sigma_v = np.maximum(_clipped_scale(qd, np.maximum(_white_scale(qd), floor)), floor)
    # torque noise from second differences on the samples where the arm is at rest: a contact
    # torque ramps linearly (impedance spring against a moving set point) or saturates, so its
    # second difference vanishes; the level of the contact torques never enters the estimate
    # (a clipped MAD of the torque itself is dominated by them when a joint spends most of its
    # rest time blocked)
    rest = np.all(np.abs(qd) < 4.0 * sigma_v, axis=1)
    tau = np.asarray(log.tau_cmd)
    sigma_tau = _second_diff_scale(tau, rest)
    # floor: half the torque resolution (a quantised encoder makes tau move in steps; with a
    # perfectly quiet arm the scale above collapses to zero)
    dtau = np.abs(np.diff(tau, axis=0))
    big = 1e-6 * np.maximum(np.abs(tau).max(axis=0), 1e-12)
    tau_floor = np.array([0.5 * np.percentile(c[c > b], 5) if np.any(c > b) else 1e-9
                          for c, b in zip(dtau.T, big, strict=True)])
    sigma_tau = np.maximum(sigma_tau, tau_floor)
    return sigma_v, sigma_tau, qd


# --------------------------------------------------------------------------- detection
def _check_log(log: JointLog) -> None:
    if log.tau_cmd is None:
        raise InputError("the log has no commanded torques (tau_cmd): contact detection needs "
                         "them; record the command topic or pass it to the reader")
    if log.n_samples < 3:
        raise InputError(f"the log has {log.n_samples} samples; contact detection needs >= 3")
    for name in ("t", "q", "qd", "tau_cmd"):
        arr = np.asarray(getattr(log, name))
        if not np.all(np.isfinite(arr)):
            bad = int(np.count_nonzero(~np.isfinite(arr)))
            raise InputError(f"log field {name} contains {bad} NaN or infinite values")
    if np.any(np.diff(log.t) <= 0):
        raise InputError("log times must be strictly increasing")


def _debounce(labels: IntArray, min_len: int) -> IntArray:
    """Absorb runs shorter than ``min_len`` samples into the preceding run."""
    out = labels.copy()
    if out.shape[0] == 0:
        return out
    change = np.flatnonzero(np.diff(out)) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [out.shape[0]]])
    prev = int(out[0]) if ends[0] - starts[0] >= min_len else -1
    for s, e in zip(starts, ends, strict=True):
        if e - s < min_len:
            out[s:e] = prev
        else:
            prev = int(out[s])
    return out


def contact_link_per_sample(stopped: NDArray[np.bool_], loaded: NDArray[np.bool_]) -> IntArray:
    """Link in contact at each sample, -1 for none.

    The outermost joint ``n`` of the stopped prefix (joints ``0..n`` all stopped) that is also
    loaded.  ``stopped, loaded : (N, n) bool`` → ``(N,) int``.
    """
    n = stopped.shape[1]
    prefix = np.cumprod(stopped, axis=1).astype(bool)  # joints 0..j all stopped
    blocked = prefix & loaded
    idx = np.where(blocked, np.arange(n), -1)
    return idx.max(axis=1).astype(np.int64)


def _extend_rigid(rows: list[tuple[int, int, int]], stopped: NDArray[np.bool_],
                  loaded: NDArray[np.bool_], nb: int) -> list[tuple[int, int, int]]:
    """Move a contact to the outermost link of the rigid group that was moving.

    When joints ``n+1..m`` were at rest and unloaded before and at the stop (a single-joint
    move of an inner joint), links ``n..m`` moved as one rigid body and the joint signals cannot
    tell which of them touched.  The outer link sweeps by far the most space per unit of motion
    (eq. 1: the probability of touching is the swept share), so the contact is assigned to
    link ``m``; the tip probability then decides between its tip and its body.
    """
    n = stopped.shape[1]
    out = []
    for s, e, link in rows:
        lo = max(0, s - nb)
        m = link
        while (m + 1 < n and np.all(stopped[lo:s + 1, m + 1])
               and not np.any(loaded[lo:s + 1, m + 1])):
            m += 1
        out.append((s, e, m))
    return out


def _choose_rigid(robot: RobotModel, q_all: FloatArray, q: FloatArray, qd: FloatArray,
                  tau: FloatArray, held: NDArray[np.bool_], tau_tol: FloatArray,
                  groups: list[tuple[int, int]], B: float, force_angle: float = 20.0,
                  ) -> tuple[list[int], FloatArray]:
    """Link of each rigid group ``lo..hi`` that most likely touched, from geometry, the map and
    the loads on the held joints.

    Eq. (2)'s reasoning applied across links: the chance that link ``k`` made the contact is
    proportional to ``∫ (n·v)+ P_C`` over its dilated boundary (side and outer sphere, exposed
    part only) at the contact pose, with ``P_C`` from the whole run's swept map — space the arm
    swept at any time (before or after) cannot hold the surface that stopped it.

    Only boundary points consistent with the joint torques count
    (:func:`torque_consistent`): joints ``lo+1..hi`` were held and carry no load, so a point of
    link ``k > lo`` counts only where the force predicted there leaves them (nearly) unloaded —
    it passes through those axes (a roll joint along its link, a push along the link) — and
    predicts the loads the other held joints show.

    ``q, qd, tau, held`` are ``(G, n)`` (one row per group: configuration, joint velocity before
    the stop, commanded torque at the height of the stop, held joints).  Returns the argmax of
    each group (the torque-identified link ``lo`` when no candidate keeps any admissible
    boundary) and ``(G, n)`` each link's share of the group's admissible mass (one-hot at the
    chosen link when none has any): the prior the fitted map later weighs the links with
    (:func:`wholearm_tools.classify.refine.link_evidence`).
    """
    from wholearm_tools.classify.swept import swept_map
    from wholearm_tools.classify.tip import ClassifyParams, _boundary

    grid = swept_map(robot, q_all, B=B)
    rows = np.concatenate([np.full(hi - lo + 1, g) for g, (lo, hi) in enumerate(groups)])
    cand = np.concatenate([np.arange(lo, hi + 1) for lo, hi in groups])
    bd = _boundary(robot, q[rows], qd[rows], cand, B, ClassifyParams())
    tmin = grid.first_within(bd.x, B - 0.25 * grid.resolution)
    consistent = torque_consistent(robot, q[rows], bd.x, bd.normal, qd[rows] != 0, held[rows],
                                   tau[rows], tau_tol, cand, B, np.radians(force_angle),
                                   one_force=True)
    mass = (bd.flux * (tmin >= grid.n_samples) * consistent).sum(1)
    out = []
    share = np.zeros((len(groups), q.shape[1]))
    for g, (lo, _hi) in enumerate(groups):
        sel = rows == g
        if np.any(mass[sel] > 0):
            out.append(int(cand[sel][np.argmax(mass[sel])]))
            share[g, cand[sel]] = mass[sel] / mass[sel].sum()
        else:
            out.append(lo)
            share[g, lo] = 1.0
    return out, share


def torque_consistent(robot: RobotModel, q: FloatArray, x_bd: FloatArray, nu: FloatArray,
                      moving: NDArray[np.bool_], held: NDArray[np.bool_], tau: FloatArray,
                      tau_tol: FloatArray, cand: IntArray, B: float, angle: float,
                      one_force: bool = False) -> NDArray[np.bool_]:
    """Which dilated-boundary points of link ``cand[r]`` could have made the contact, judged by
    the torques of the held joints.

    A frictionless contact at robot point ``r`` (boundary point ``x`` minus ``B`` along its
    outward normal ``nu``) pushes along ``-nu``; its moment about joint ``i <= cand`` is
    ``f g_i``, ``g_i = (a_i x (r - o_i)) . (-nu)``, zero beyond ``cand``.  ``f`` is fitted to the
    torques of the ``moving`` joints (least squares, ``f >= 0``).  The force may lean from the
    normal by up to ``angle`` (friction, quadrature spacing):

    * ``one_force=False``: a point is consistent when every ``held`` joint's observed torque
      lies within ``tau_tol`` of its prediction ``-f g_i``, widened by the change of the moment
      when the force leans by ``angle`` (``sin(angle) f |a_i x (r - o_i)|``) — each joint
      judged on its own, as if each could have a lean of its own;
    * ``one_force=True``: consistent when **one** lean ``t`` (tangent to the boundary,
      ``|t| <= tan(angle)``, force ``f (-nu + t)``) brings every held joint's prediction within
      ``tau_tol`` of the observed torque at once — one contact has one force.  Stricter where
      several held joints constrain the lean: an unloaded wrist and the loads of two other held
      joints cannot each take the lean that suits it.

    Parameters
    ----------
    q, moving, held, tau : (R, n) configuration, joints driven into the stop, held joints,
        torques at the height of the stop
    x_bd : (R, Q, d) boundary points; nu : (R, Q, 3) their outward unit normals
    tau_tol : (n,) or (R, n) torque tolerance; cand : (R,) candidate link; B : dilation [m]
    angle : float [rad]

    Returns
    -------
    (R, Q) bool (all True for a row without held joints)
    """
    R, Qn = x_bd.shape[:2]
    n = robot.dof
    tol = np.broadcast_to(np.asarray(tau_tol, dtype=float), (R, n))
    pts = robot.joint_positions(q)                    # (R, n+1, 3)
    axes = robot.joint_axes(q)                        # (R, n, 3)
    x = np.zeros((R, Qn, 3))
    x[..., : robot.dim] = x_bd
    r_pt = x - B * nu                                 # the robot's own surface point
    lever = np.cross(axes[:, None], r_pt[:, :, None, :] - pts[:, None, :n, :])  # (R, Q, n, 3)
    g = -np.einsum("rqjk,rqk->rqj", lever, nu)        # moment per unit force, (R, Q, n)
    on_chain = np.arange(n)[None, None, :] <= cand[:, None, None]   # joints that move the link
    g = np.where(on_chain, g, 0.0)
    mv = moving[:, None, :]
    gb = np.where(mv, g, 0.0)
    f = np.maximum(-np.einsum("rqj,rj->rq", gb, np.where(moving, tau, 0.0))
                   / np.maximum(np.einsum("rqj,rqj->rq", gb, gb), 1e-300), 0.0)
    if not one_force:
        pred = -f[..., None] * g                      # (R, Q, n)
        slack = np.sin(angle) * f[..., None] * np.linalg.norm(lever, axis=-1)
        slack = np.where(on_chain, slack, 0.0)
        ok = np.abs(pred - tau[:, None, :]) <= tol[:, None, :] + slack
        return np.all(~held[:, None, :] | ok, axis=-1)
    # moment change per unit lean along two tangent directions e1, e2 of the boundary
    e1 = np.cross(nu, np.where(np.abs(nu[..., :1]) < 0.9, [1.0, 0, 0], [0, 1.0, 0]))
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(nu, e1)
    L = np.stack([np.einsum("rqjk,rqk->rqj", lever, e1),
                  np.einsum("rqjk,rqk->rqj", lever, e2)], -1)              # (R, Q, n, 2)
    L = np.where(on_chain[..., None], L, 0.0)
    # held joint i: observed tau_i = -f (g_i + L_i . t)  =>  | f L_i . t - b_i | <= tol_i
    b = -(f[..., None] * g + tau[:, None, :])
    return _lean_feasible(f[..., None, None] * L, b, np.broadcast_to(tol[:, None, :], b.shape),
                          np.broadcast_to(held[:, None, :], b.shape), float(np.tan(angle)))


def _lean_feasible(A: FloatArray, b: FloatArray, c: FloatArray, use: NDArray[np.bool_],
                   radius: float, chunk: int = 20000) -> NDArray[np.bool_]:
    """Whether some ``t`` with ``|t| <= radius`` meets ``|A_i . t - b_i| <= c_i`` for every
    ``i`` where ``use`` (``A (..., H, 2)``, ``b, c, use (..., H)``) → ``(...) bool``.

    The slabs cut a convex polygon out of the plane; it meets the disc exactly when its point
    nearest the origin does, and that point is the origin, the foot of the origin on one of the
    polygon's edge lines, or a vertex (two edge lines crossing).  Every such candidate is
    tested.
    """
    shape = b.shape[:-1]
    H = b.shape[-1]
    A = A.reshape(-1, H, 2)
    b = b.reshape(-1, H)
    c = c.reshape(-1, H)
    use = use.reshape(-1, H)
    out = np.zeros(A.shape[0], dtype=bool)
    # half-planes p . t <= h: A t <= b + c and -A t <= c - b; unused ones never bind
    for lo in range(0, A.shape[0], chunk):
        sl = slice(lo, lo + chunk)
        a_, b_, c_, u_ = A[sl], b[sl], c[sl], use[sl]
        p = np.concatenate([a_, -a_], 1)                                # (P, 2H, 2)
        h = np.concatenate([b_ + c_, c_ - b_], 1)
        uu = np.concatenate([u_, u_], 1)
        p = np.where(uu[..., None], p, 0.0)
        h = np.where(uu, h, np.inf)
        pn2 = np.einsum("pjk,pjk->pj", p, p)
        scale = np.sqrt(pn2) * radius + np.abs(np.where(np.isfinite(h), h, 0.0)) + 1e-12
        # candidates: origin, feet of the origin on each line, crossings of pairs of lines
        foot = np.where((pn2 > 1e-300)[..., None],
                        np.where(np.isfinite(h), h, 0.0)[..., None] * p
                        / np.maximum(pn2, 1e-300)[..., None], 0.0)
        i1, i2 = np.triu_indices(2 * H, 1)
        p1, p2 = p[:, i1], p[:, i2]
        det = p1[..., 0] * p2[..., 1] - p1[..., 1] * p2[..., 0]
        h1 = np.where(np.isfinite(h[:, i1]), h[:, i1], 0.0)
        h2 = np.where(np.isfinite(h[:, i2]), h[:, i2], 0.0)
        ok_det = np.abs(det) > 1e-12 * np.sqrt(pn2[:, i1] * pn2[:, i2]) + 1e-300
        dd = np.where(ok_det, det, 1.0)
        vert = np.stack([(h1 * p2[..., 1] - h2 * p1[..., 1]) / dd,
                         (p1[..., 0] * h2 - p2[..., 0] * h1) / dd], -1)
        vert = np.where(ok_det[..., None], vert, 0.0)
        cands = np.concatenate([np.zeros((p.shape[0], 1, 2)), foot, vert], 1)  # (P, C, 2)
        inside = np.einsum("pck,pck->pc", cands, cands) <= radius**2 * (1 + 1e-9) + 1e-300
        slack = h[:, None, :] - np.einsum("pck,pjk->pcj", cands, p)
        meets = np.all(slack >= -1e-9 * scale[:, None, :], axis=-1)
        out[sl] = np.any(inside & meets, axis=1)
    return out.reshape(shape)


def _clip_levels(tau: FloatArray, robot: RobotModel | None) -> FloatArray:
    """Torque level at which each joint's command is clipped (inf when unknown).

    The URDF's effort limits, where the log never exceeds them: a commanded torque at its limit
    is clipped and no longer measures the contact force.
    """
    n = tau.shape[1]
    if robot is None:
        return np.full(n, np.inf)
    lim = np.asarray(robot.effort_limits, dtype=float)
    peak = np.abs(tau).max(axis=0) if tau.shape[0] else np.zeros(n)
    ok = np.isfinite(lim) & (lim > 0) & (peak <= lim * (1 + 1e-6))
    return np.where(ok, lim, np.inf)


def _stop_torques(tau: FloatArray, stopped: NDArray[np.bool_], saturated: NDArray[np.bool_],
                  s: int, e: int, moving: NDArray[np.bool_], held: NDArray[np.bool_],
                  base_end: int, base_max: int, sigma_tau: FloatArray,
                  ) -> tuple[FloatArray, FloatArray]:
    """The contact's torque signature over a stop ``s..e``, and the held joints' uncertainty.

    Returns ``(tau_ref (n,), se (n,))``.  ``tau_ref`` holds the commanded torques at the
    reference sample — the sample of the stop, with the joints that drove into it and the held
    joints at rest and none of them clipped, where the driving torques are largest (a clipped
    torque no longer grows with the force) — and, for each held joint, its *load*: the change
    from its level at rest before the stop, fitted over the whole stop as proportional to the
    driving torques (the force and with it every held joint's moment grow together) and
    evaluated at the reference sample.  ``se`` is that load's standard error (residual scale,
    at least the torque noise, through the fit and the rest level); ``inf`` for joints that
    are not held.  Without such a sample (a stop clipped at once or too short) the largest
    sample of the stop is used and the error is a single sample's.
    """
    n = tau.shape[1]
    se = np.full(n, np.inf)
    use = moving & stopped[s]          # the joints that drove into the stop and were blocked
    part = use | held
    ks = np.arange(s, e)
    valid = np.all(stopped[s:e][:, part], axis=1) & ~np.any(saturated[s:e][:, part], axis=1)
    base = np.zeros(n)
    n_base = np.ones(n)
    for j in np.flatnonzero(held):
        k0 = base_end
        while k0 > max(0, base_end - base_max) and stopped[k0 - 1, j]:
            k0 -= 1
        if k0 < base_end:
            base[j] = float(tau[k0:base_end, j].mean())
            n_base[j] = base_end - k0
    if not np.any(valid):
        seg = tau[s:e]
        out = seg[int(np.argmax(np.abs(seg).sum(axis=1)))].copy()
        out[held] -= base[held]
        se[held] = sigma_tau[held] * np.sqrt(1 + 1 / n_base[held])
        return out, se
    ks = ks[valid]
    if np.any(use):
        drive = tau[ks][:, use]
        r = int(np.argmax(np.abs(drive).sum(axis=1)))
        u = drive[r] / max(float(np.linalg.norm(drive[r])), 1e-300)
        rho = drive @ u
    else:
        r = ks.shape[0] - 1
        rho = np.ones(ks.shape[0])
    out = tau[ks[r]].copy()
    ss = max(float(rho @ rho), 1e-300)
    for j in np.flatnonzero(held):
        d = tau[ks, j] - base[j]
        beta = float(d @ rho) / ss
        out[j] = beta * rho[r]
        res = d - beta * rho
        sig = max(float(sigma_tau[j]), float(np.sqrt(res @ res / max(ks.shape[0] - 1, 1))))
        se[j] = sig * np.sqrt(rho[r] ** 2 / ss + 1 / n_base[j])
    return out, se


def _raise_to_loaded_held(rows: list[tuple[int, int, int]], inner: dict[int, int],
                          held: NDArray[np.bool_], load: FloatArray, se: FloatArray,
                          stopped: NDArray[np.bool_], loaded: NDArray[np.bool_],
                          sigma_tau: FloatArray, k: float, nb: int, rigid_outer: bool,
                          ) -> list[tuple[int, int, int]]:
    """A held joint beyond the contact link that carries a load moves the contact outward.

    A held joint (at rest and unloaded before the stop, not driven by the move) feels the
    contact force only through a contact on its own link or beyond: joints beyond the link in
    contact carry nothing.  Its load can stay under the *motion* threshold of ``loaded`` (a
    fraction of the joint's torque while it moves) — a tip pushed nearly along the last link
    loads the wrist by a small moment — yet stand clear of the noise.  When held joint ``m``
    beyond the innermost link of a contact's group carries a load of more than ``k`` standard
    errors (and more than one noise sigma), and joints ``0..m`` are stopped, the contact is on
    link ``m`` or beyond: the group becomes ``m..hi`` (extended past ``m`` over joints at rest
    and unloaded, as in :func:`_extend_rigid`).  ``inner`` is updated in place.
    """
    n = held.shape[1]
    out = []
    for i, (s, e, link) in enumerate(rows):
        lo = inner.get(s, link)
        sig = held[i] & (np.abs(load[i]) > k * se[i]) & (np.abs(load[i]) > sigma_tau)
        cand = [j for j in np.flatnonzero(sig) if j > lo and np.all(stopped[s, :j + 1])]
        if not cand:
            out.append((s, e, link))
            continue
        m = int(max(cand))
        hi = max(link, m) if rigid_outer else m
        if rigid_outer and m > link:
            b0 = max(0, s - nb)
            while (hi + 1 < n and np.all(stopped[b0:s + 1, hi + 1])
                   and not np.any(loaded[b0:s + 1, hi + 1]) and not sig[hi + 1]):
                hi += 1
        inner[s] = m
        out.append((s, e, hi))
    return out


def _split_two_stage(rows: list[tuple[int, int, int]], labels: IntArray,
                     blocked: NDArray[np.bool_], stopped: NDArray[np.bool_], gap: int,
                     qd_s: FloatArray, v_th: FloatArray, window: int,
                     ) -> list[tuple[int, int, int]]:
    """Recover the inner contact of a quick two-stage event.

    When link ``j`` touches and an outer link ``n`` stops on its own obstacle less than the
    minimum duration later, the debounced label jumps straight to ``n``.  Joint ``j`` then
    shows a stop that began distinctly earlier (``gap`` samples, more than the smoothing can
    shift a stop) than joint ``n``'s, after clear motion (3 velocity thresholds), and lasted up
    to the rise, where it is blocked (loaded):
    that earlier stop is a contact on link ``j`` (the outermost such joint).  The earlier stop
    must lie within ``window`` samples (the minimum duration plus the gap) of joint ``n``'s:
    a joint that stopped long before — it reached its target and was then held, loaded by the
    outer contact's force — was not blocked by a contact of its own (the debounced label would
    have risen to it).
    """
    out: list[tuple[int, int, int]] = []
    prev_label = -1
    # joints 0..j all stopped: the prefix stop starts when the last of them stopped (their
    # smoothed velocities cross the threshold a sample or two apart)
    prefix = np.cumprod(stopped, axis=1).astype(bool)
    for s, e, link in rows:
        prev_label = int(labels[s - 1]) if s > 0 else -1

        def onset(j: int, arr: NDArray[np.bool_], s: int = s) -> int:
            k = s
            while k > 0 and arr[k - 1, j]:
                k -= 1
            return k

        on_n = onset(link, stopped)
        extra = None
        for j in range(link - 1, prev_label, -1):
            if not blocked[s, j]:
                continue
            on_j = onset(j, prefix)
            # ... and it was a real stop: the joint was moving clearly (not creeping) before it
            own = onset(j, stopped)
            approach = np.abs(qd_s[max(0, own - 2 * gap):own + 1, j])
            if (on_n - window <= on_j <= on_n - gap
                    and approach.size and approach.max() > 3 * v_th[j]):
                extra = (on_j, s, j)
                break
        if extra is not None and (not out or extra[0] > out[-1][0]):
            out.append(extra)
        out.append((s, e, link))
    return out


def detect_contacts(log: JointLog, robot: RobotModel | None = None, *,
                    params: DetectionParams | None = None) -> Contacts:
    """Detect contacts and identify the link in contact from ``qd`` and ``tau_cmd`` only.

    Parameters
    ----------
    log : JointLog with ``tau_cmd`` (N, n)
    robot : RobotModel, optional; when given its joint names must match the log's
    params : DetectionParams, optional

    Returns
    -------
    Contacts
        One row per contact event, in time order.  A two-stage contact (link ``n`` stops, then an
        outer link ``m`` stops on its own obstacle while ``0..n`` stay blocked) gives two rows.

    Raises
    ------
    InputError
        No commanded torques, NaNs, too few samples, or joint names that do not match ``robot``.
    """
    params = params or DetectionParams()
    _check_log(log)
    if robot is not None and tuple(robot.joint_names) != tuple(log.joint_names):
        raise InputError(f"log joints {log.joint_names} do not match robot joints "
                         f"{robot.joint_names}")
    n = len(log.joint_names)
    sigma_v, sigma_tau, qd_s = estimate_noise(log, params)
    v_th = (np.broadcast_to(np.asarray(params.velocity_threshold, float), (n,)).copy()
            if params.velocity_threshold is not None else params.k_velocity * sigma_v)
    tau = np.asarray(log.tau_cmd)
    if params.torque_threshold is not None:
        tau_th = np.broadcast_to(np.asarray(params.torque_threshold, float), (n,)).copy()
    else:
        moving = np.abs(qd_s) > v_th
        tau_motion = np.array([float(np.median(np.abs(tau[moving[:, j], j])))
                               if np.count_nonzero(moving[:, j]) >= 10 else 0.0
                               for j in range(n)])
        tau_th = np.maximum(params.k_torque * sigma_tau,
                            params.motion_torque_fraction * tau_motion)
    stopped = np.abs(qd_s) < v_th
    loaded = np.abs(tau) > tau_th
    dt = 1.0 / log.rate
    min_len = max(params.min_stop_samples, int(np.ceil(params.min_stop_time / dt - 1e-9)))
    labels = _debounce(contact_link_per_sample(stopped, loaded), min_len)

    change = np.flatnonzero(np.diff(labels)) + 1
    starts = np.concatenate([[0], change])
    ends = np.concatenate([change, [labels.shape[0]]])
    prev = -1
    rows: list[tuple[int, int, int]] = []
    nb = max(2, round(params.before_time / dt))
    for s, e in zip(starts, ends, strict=True):
        cur = int(labels[s])
        if cur > prev and cur >= 0 and s > 0:
            s0 = rows[-1][0] if rows else 0
            if (prev >= 0 and rows and rows[-1][2] == prev
                    and np.all(stopped[max(0, s0 - nb):s + 1, prev + 1:cur + 1])):
                # joints prev+1..cur were held still all along: no new stop, the same
                # contact's force building up until their load crossed the threshold
                rows[-1] = (s0, int(e), cur)
            else:
                rows.append((int(s), int(e), cur))
        prev = cur
    inner: dict[int, int] = {}  # start sample -> innermost link of its rigid group
    if params.rigid_outer:
        ext = _extend_rigid(rows, stopped, loaded, nb)
        inner = {r[0]: r[2] for r in rows}
        rows = ext
    gap = max(2, round(params.smooth_time / dt)) + 1
    rows = _split_two_stage(rows, labels, stopped & loaded, stopped, gap, qd_s, v_th,
                            min_len + gap)
    meta = {"sigma_velocity": sigma_v.tolist(), "sigma_torque": sigma_tau.tolist(),
            "min_stop_samples": min_len, "rate": log.rate}
    if not rows:
        return Contacts(np.zeros(0), np.zeros(0, int), np.zeros(0, int), np.zeros((0, n)),
                        np.zeros((0, n)), np.zeros(0), v_th, tau_th, meta)

    q = np.asarray(log.q)
    qd = np.asarray(log.qd)
    lag = max(1, round(params.smooth_time / dt) // 2)
    limit = _clip_levels(tau, robot)
    saturated = np.abs(tau) >= limit * (1 - 1e-9)
    M = len(rows)
    out_qd = np.zeros((M, n))
    t_end = np.empty(M)
    peak = np.zeros((M, n))
    load_se = np.full((M, n), np.inf)
    held = np.zeros((M, n), dtype=bool)
    for i, (s, e, link) in enumerate(rows):
        # the segment may end when an outer link stops too; the blocked state lasts until the
        # label drops below this link
        k = e
        while k < labels.shape[0] and labels[k] >= link:
            k += 1
        t_end[i] = log.t[min(k, labels.shape[0] - 1)]
        lo, hi = max(0, s - lag - nb), max(1, s - lag)
        out_qd[i] = qd[lo:hi].mean(axis=0)
        at_rest = np.all(stopped[lo:hi], axis=0)  # already stopped before this contact
        out_qd[i, at_rest] = 0.0
        # held: at rest and unloaded over the window before that (the contact's own load can
        # show on a held joint a few samples before the smoothed velocities call the stop)
        h0, h1 = max(0, lo - nb), max(1, lo)
        held[i] = (at_rest & np.all(stopped[h0:h1], axis=0)
                   & ~np.any(loaded[h0:h1], axis=0))
        peak[i], load_se[i] = _stop_torques(tau, stopped, saturated, s, max(e, s + 1),
                                            out_qd[i] != 0, held[i], h1, 5 * nb, sigma_tau)
    rows = _raise_to_loaded_held(rows, inner, held, peak, load_se, stopped, loaded, sigma_tau,
                                 params.k_torque, nb, params.rigid_outer)
    idx = np.array([r[0] for r in rows])
    out_q = q[idx].copy()
    for i, (s, e, link) in enumerate(rows):
        settle = q[s:min(s + min_len, e)]
        out_q[i, :link + 1] = np.median(settle[:, :link + 1], axis=0)
    links = np.array([r[2] for r in rows])
    prior = np.eye(n)[links]
    if params.rigid_outer and params.rigid_choice == "map" and robot is not None:
        which = [i for i, r in enumerate(rows) if inner.get(r[0], r[2]) < r[2]]
        if which:
            groups = [(inner[rows[i][0]], rows[i][2]) for i in which]
            links[which], prior[which] = _choose_rigid(
                robot, q, out_q[which], out_qd[which], peak[which], held[which], tau_th,
                groups, params.rigid_dilation)
    return Contacts(log.t[idx], links, idx, out_q, out_qd, t_end, v_th, tau_th, meta,
                    tau_peak=peak, held=held, link_prior=prior)
