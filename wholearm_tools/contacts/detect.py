"""Contact detection and link identification from the joint signals: one row per contact event.

Only the robot's own signals are used (never ground truth).  The principle (Kaneko & Tanie 1994,
the paper's section 2): when link ``n`` touches, joints ``0..n`` are obstructed — at rest while
the controller pushes — and joints beyond ``n`` carry no part of the contact force.  What the
controller does without contact (friction and bias at rest, inertia, gravity, arrival at a free
target, unloading on retreat) is learned from the run itself, and a contact is an event from the
first obstruction until the arm is released, measured where it settles
(:mod:`wholearm_tools.contacts.events`).

The joints beyond the outermost obstructed one carry no load, but that does not place the
contact inward of them: a joint at rest moved its links as one body with the obstructed one,
and a joint that kept moving freely may have moved the contact point along the surface (a push
across a yaw-pitch arm's plane has no moment about its pitch joints; a tip slides).  Every
link from the obstructed one outward is a candidate; the candidates share a prior from eq.
(2)'s admissible boundary mass, counting only boundary points that the held joints' torques
and the moving joints' motion allow (:func:`_choose_rigid`), and the fitted map later weighs
them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError
from wholearm_tools.logs.records import JointLog
from wholearm_tools.robot.model import RobotModel

if TYPE_CHECKING:
    from wholearm_tools.contacts.events import Event

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
        A joint is at rest when its smoothed speed is below ``k_velocity * sigma_v``.
    k_torque : float
        A joint at rest is *loaded* when its torque departs from the learned free-motion model
        by more than the Coulomb friction it can hold there plus ``k_torque`` sigmas of the
        model's error: its robust residual scale in free motion, or the torque noise at rest
        where that is larger (:mod:`wholearm_tools.contacts.events`).  A load the model could
        be wrong by in free motion is no evidence of contact at rest.
    min_stop_time : float
        Seconds of obstruction an event needs (and a joint's obstruction, to count).
    min_stop_samples : int
        ... and at least this many samples (guards slow logs).
    release_time : float
        Seconds without obstruction that end an event: shorter gaps (a rebound that comes
        back, a joint unloading for a moment while the tip slides) are bridged.
    smooth_time : float
        Width in seconds of the centred moving average applied to ``qd`` (at least one sample,
        so a 50 Hz log is not smoothed).
    before_time : float
        Window in seconds before the impact (the end of the obstructed joints' free motion,
        at most ``release_time`` before the first obstruction) over which ``qd_before`` is
        averaged.
    rigid_outer : bool
        The joints beyond the outermost obstructed joint ``n`` carry no load, so links beyond
        ``n`` may have touched.  True (default): choose among them (see ``rigid_choice``);
        False: keep the innermost link ``n``.
    rigid_choice : str
        ``"map"`` (default; needs ``robot``): every link from ``n`` outward is a candidate; the
        one whose dilated boundary sweeps the most admissible space, eq. (2)'s integral over
        each candidate link with the whole run's swept map, counting only points the joints
        beyond ``n`` allow (see :func:`_choose_rigid`); ``"outer"``: the
        outermost link of the rigid group — joints beyond ``n`` that moved the arm by less
        than the contact resolution over the event (the map-free prior; also used when no
        robot is given).
    rigid_dilation : float
        Dilation [m] used by the ``"map"`` choice.
    gravity : bool or None
        Whether the free-motion model has gravity terms (needs ``robot``); None: when a robot
        is given (they cost nothing where the log's torques hold no gravity: their weights
        come out zero).
    velocity_threshold, torque_threshold : float or (n,) float, optional
        Absolute overrides of the noise-derived thresholds.
    """

    k_velocity: float = 5.0
    k_torque: float = 6.0
    min_stop_time: float = 0.05
    min_stop_samples: int = 2
    release_time: float = 0.1
    smooth_time: float = 0.01
    before_time: float = 0.02
    rigid_outer: bool = True
    rigid_choice: str = "map"
    rigid_dilation: float = 0.02
    gravity: bool | None = None
    velocity_threshold: Any = None
    torque_threshold: Any = None

    def __post_init__(self) -> None:
        for name in ("k_velocity", "k_torque", "min_stop_time", "release_time", "smooth_time",
                     "before_time"):
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
        Index in the log of the sample where the contact settled, where ``q`` is measured.
    q : (M, n) float
        Joint positions where the contact settled (median over the first samples from there),
        at the links' angles where the robot's drives are compliant
        (``RobotModel.link_angles``).
    qd_before : (M, n) float
        Joint velocities just before the impact (joints that were already at rest set to 0):
        the motion that led into the contact, which eq. (2) integrates against, not the bounce
        between impact and rest.
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
    t_settle : (M,) float
        When the contact settled (the time of ``index``), seconds; ``t`` when not given.
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
    t_settle: FloatArray | None = None

    def __post_init__(self) -> None:
        n = np.asarray(self.velocity_threshold).shape[0]
        m = np.asarray(self.t).reshape(-1).shape[0]
        object.__setattr__(self, "t", _frozen(self.t).reshape(m))
        object.__setattr__(self, "t_settle", _frozen(self.t if self.t_settle is None
                                                     else self.t_settle).reshape(m))
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

    @property
    def p_link(self) -> FloatArray:
        """``(M,)`` probability of each contact's named link (its ``link_prior`` entry): 1
        where the joint signals name one link, its share where a rigid group left several."""
        return self.link_prior[np.arange(len(self)), self.link]

    def select(self, mask: Any) -> Contacts:
        """A new record with the contacts where ``mask`` (bool or index array) selects."""
        sel = np.arange(len(self))[mask]
        return Contacts(self.t[sel], self.link[sel], self.index[sel], self.q[sel],
                        self.qd_before[sel], self.t_end[sel], self.velocity_threshold,
                        self.torque_threshold, dict(self.meta),
                        tau_peak=self.tau_peak[sel], held=self.held[sel],
                        link_prior=self.link_prior[sel], t_settle=self.t_settle[sel])


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


def _choose_rigid(robot: RobotModel, q_all: FloatArray, q: FloatArray, qd: FloatArray,
                  tau: FloatArray, held: NDArray[np.bool_], tau_tol: FloatArray,
                  groups: list[tuple[int, int]], B: float, force_angle: float = 20.0,
                  moved: NDArray[np.bool_] | None = None,
                  ) -> tuple[list[int], FloatArray]:
    """Link of each rigid group ``lo..hi`` that most likely touched, from geometry, the map and
    the loads on the held joints.

    Eq. (2)'s reasoning applied across links: the chance that link ``k`` made the contact is
    proportional to ``∫ (n·v)+ P_C`` over its dilated boundary (side and outer sphere, exposed
    part only) at the contact pose, with ``P_C`` from the whole run's swept map — space the arm
    swept at any time (before or after) cannot hold the surface that stopped it.

    Only boundary points consistent with the joints beyond ``lo`` count.  A held joint (at
    rest, unloaded) is judged by its torque (:func:`torque_consistent`): a point of link
    ``k > lo`` counts only where the force predicted there leaves it (nearly) unloaded — it
    passes through its axis (a roll joint along its link, a push along the link) — and
    predicts the loads the held joints show.  A joint that kept moving freely (``moved``) is
    judged by its motion, which the contact did not stop: it moved the point along the
    surface, so its velocity there is tangent to the boundary within ``force_angle`` (a push
    across the plane of pitch joints).  Its torque is not used: while it moves, what the
    free-motion model misses of the motion is as large as a small contact moment.

    ``q, qd, tau, held, moved`` are ``(G, n)`` (one row per group: configuration, joint
    velocity before the stop, commanded torque at the height of the stop, held joints, joints
    beyond ``lo`` that kept moving).  Returns the argmax of
    each group (the torque-identified link ``lo`` when no candidate keeps any admissible
    boundary) and ``(G, n)`` each link's share of the group's admissible mass (one-hot at the
    chosen link when none has any): the prior the fitted map later weighs the links with
    (the readings of every candidate link, :mod:`wholearm_tools.fit.readings`).
    """
    from wholearm_tools.classify.swept import swept_map
    from wholearm_tools.classify.tip import ClassifyParams, _boundary

    grid = swept_map(robot, q_all, B=B)
    rows = np.concatenate([np.full(hi - lo + 1, g) for g, (lo, hi) in enumerate(groups)])
    cand = np.concatenate([np.arange(lo, hi + 1) for lo, hi in groups])
    prm = ClassifyParams()
    bd = _boundary(robot, q[rows], qd[rows], cand, B, prm)
    tmin = grid.first_within(bd.x, B - prm.swept_tol(grid.resolution))
    weight = bd.flux * (tmin >= grid.n_samples)
    consistent = torque_consistent(robot, q[rows], bd.x, bd.normal, qd[rows] != 0, held[rows],
                                   tau[rows], tau_tol, cand, B, np.radians(force_angle),
                                   one_force=True, where=weight > 0)
    if moved is not None and np.any(moved):
        consistent &= moves_along(robot, q[rows], bd.x, bd.normal, moved[rows], cand, B,
                                  np.radians(force_angle))
    mass = (weight * consistent).sum(1)
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


def _point_velocities(robot: RobotModel, q: FloatArray, x_bd: FloatArray, nu: FloatArray,
                      B: float) -> FloatArray:
    """``a_j x (r - o_j)`` for every joint ``j``: the velocity per unit joint rate of the
    robot's own surface point ``r = x - B nu`` under each boundary point (and, dotted with a
    force, its moment about the joint).  ``q (R, n)``, ``x_bd (R, Q, d)``, ``nu (R, Q, 3)``
    → ``(R, Q, n, 3)``."""
    x = np.zeros(nu.shape)
    x[..., : robot.dim] = x_bd
    r_pt = x - B * nu
    pts, axes = robot.joint_positions_and_axes(q)
    return np.cross(axes[:, None], r_pt[:, :, None, :] - pts[:, None, :robot.dof, :])


def moves_along(robot: RobotModel, q: FloatArray, x_bd: FloatArray, nu: FloatArray,
                moved: NDArray[np.bool_], cand: IntArray, B: float, angle: float
                ) -> NDArray[np.bool_]:
    """Which dilated-boundary points of link ``cand[r]`` the ``moved`` joints (inward of or at
    the link) move along the boundary: the point's velocity per unit rate of joint ``j``,
    ``a_j x (r - o_j)`` at the robot's surface point ``r = x - B nu``, has a normal component
    within ``sin(angle)`` of its length.  A joint the contact did not stop moved its contact
    point along the surface.

    ``q, moved : (R, n)``; ``x_bd : (R, Q, d)``; ``nu : (R, Q, 3)``; ``cand : (R,)`` →
    ``(R, Q) bool``."""
    n = robot.dof
    lever = _point_velocities(robot, q, x_bd, nu, B)
    normal_part = np.abs(np.einsum("rqjk,rqk->rqj", lever, nu))
    along = normal_part <= np.sin(angle) * np.linalg.norm(lever, axis=-1)
    check = moved[:, None, :] & (np.arange(n)[None, None, :] <= cand[:, None, None])
    return np.all(along | ~check, axis=-1)


def _fitted_force(robot: RobotModel, q: FloatArray, x_bd: FloatArray, nu: FloatArray,
                  moving: NDArray[np.bool_], tau: FloatArray, cand: IntArray, B: float,
                  ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], FloatArray]:
    """The normal force at each boundary point that best explains the ``moving`` joints'
    torques: ``(lever (R, Q, n, 3), g (R, Q, n), on_chain (R, 1, n), f (R, Q))``
    (see :func:`torque_consistent`)."""
    n = robot.dof
    lever = _point_velocities(robot, q, x_bd, nu, B)  # (R, Q, n, 3)
    g = -np.einsum("rqjk,rqk->rqj", lever, nu)        # moment per unit force, (R, Q, n)
    on_chain = np.arange(n)[None, None, :] <= cand[:, None, None]   # joints that move the link
    g = np.where(on_chain, g, 0.0)
    gb = np.where(moving[:, None, :], g, 0.0)
    f = np.maximum(-np.einsum("rqj,rj->rq", gb, np.where(moving, tau, 0.0))
                   / np.maximum(np.einsum("rqj,rqj->rq", gb, gb), 1e-300), 0.0)
    return lever, g, on_chain, f


def lean_needed(robot: RobotModel, q: FloatArray, x_bd: FloatArray, nu: FloatArray,
                moving: NDArray[np.bool_], tau: FloatArray, tau_tol: FloatArray,
                cand: IntArray, B: float) -> FloatArray:
    """Sine of the least lean from the normal the force at each boundary point needs to bring
    each joint's moment within ``tau_tol`` of its torque, each joint judged on its own (the
    ``one_force=False`` test of :func:`torque_consistent`): ``(R, Q, n)``, 0 where the normal
    force already does, ``inf`` where no lean does (a joint off the chain that is loaded, no
    force).  Arguments as for :func:`torque_consistent`."""
    R = x_bd.shape[0]
    tol = np.broadcast_to(np.asarray(tau_tol, dtype=float), (R, robot.dof))
    lever, g, on_chain, f = _fitted_force(robot, q, x_bd, nu, moving, tau, cand, B)
    excess = np.abs(f[..., None] * g + tau[:, None, :]) - tol[:, None, :]
    per_lean = np.where(on_chain, f[..., None] * np.linalg.norm(lever, axis=-1), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        need = np.where(per_lean > 0, excess / np.where(per_lean > 0, per_lean, 1.0), np.inf)
    return np.where(excess <= 0, 0.0, need)


def torque_consistent(robot: RobotModel, q: FloatArray, x_bd: FloatArray, nu: FloatArray,
                      moving: NDArray[np.bool_], held: NDArray[np.bool_], tau: FloatArray,
                      tau_tol: FloatArray, cand: IntArray, B: float, angle: float,
                      one_force: bool = False, where: NDArray[np.bool_] | None = None,
                      ) -> NDArray[np.bool_]:
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
      judged on its own, as if each could have a lean of its own (:func:`lean_needed`);
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
    where : (R, Q) bool, optional; with ``one_force``, the points to test (the others come out
        False): the lean test is the costly part, and points no prior weighs need none

    Returns
    -------
    (R, Q) bool (all True for a row without held joints)
    """
    if not one_force:
        need = lean_needed(robot, q, x_bd, nu, moving, tau, tau_tol, cand, B)
        return np.all(~held[:, None, :] | (need <= np.sin(angle)), axis=-1)
    R, Qn = x_bd.shape[:2]
    tol = np.broadcast_to(np.asarray(tau_tol, dtype=float), (R, robot.dof))
    lever, g, on_chain, f = _fitted_force(robot, q, x_bd, nu, moving, tau, cand, B)
    # moment change per unit lean along two tangent directions e1, e2 of the boundary
    e1 = np.cross(nu, np.where(np.abs(nu[..., :1]) < 0.9, [1.0, 0, 0], [0, 1.0, 0]))
    e1 /= np.linalg.norm(e1, axis=-1, keepdims=True)
    e2 = np.cross(nu, e1)
    L = np.stack([np.einsum("rqjk,rqk->rqj", lever, e1),
                  np.einsum("rqjk,rqk->rqj", lever, e2)], -1)              # (R, Q, n, 2)
    L = np.where(on_chain[..., None], L, 0.0)
    # held joint i: observed tau_i = -f (g_i + L_i . t)  =>  | f L_i . t - b_i | <= tol_i
    b = -(f[..., None] * g + tau[:, None, :])
    test = np.ones((R, Qn), dtype=bool) if where is None else np.asarray(where, dtype=bool)
    out = np.zeros((R, Qn), dtype=bool)
    out[test] = _lean_feasible((f[..., None, None] * L)[test], b[test],
                               np.broadcast_to(tol[:, None, :], b.shape)[test],
                               np.broadcast_to(held[:, None, :], b.shape)[test],
                               float(np.tan(angle)))
    return out


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


def _changed_motion_link(e: Event, loaded_moving: NDArray[np.bool_], qd_s: FloatArray,
                         qd_before: FloatArray, v_th: FloatArray, min_len: int,
                         held_back: NDArray[np.bool_]) -> int:
    """The link of event ``e``, or the outermost joint the contact loads without it counting as
    obstructed, if that lies outward.  Such a joint is not held at rest under load for a whole
    stop (friction in the joint or at the contact, a compliant contact, a slide), and from the
    moment the event settles either

    * moves, loaded beyond the free-motion model most of that time, at a velocity that differs
      from the one that led into the contact (``qd_before``) by more than half of it and more
      than its threshold ``v_th``: held back, slowed or reversed by the impact, or, at rest
      before, pushed into motion against its controller; or
    * is still held back where the stop ends (``held_back``: loaded beyond its friction and
      not moving along the load, at rest or driven against it, for a stop's length at
      least).  A load that does negative work, or none while it exceeds the joint's
      friction, comes from outside: in free motion only inertia could, and by the end of the
      stop the inner joints have long been at rest and the joint's own transient is over (a
      joint braked to rest by its controller is at rest unloaded by then).  The contact
      holds or back-drives the joint (a tip creeping along a wall against a wrist that pushes
      it on, at speeds about its velocity threshold, in and out of rest), so it lies on the
      joint's link or beyond.  This needs no ``qd_before``: a creep that began before the
      obstruction was confirmed has already changed the motion that led into it.

    A joint that runs on at its own speed and is brought to rest by its controller afterwards
    (its torque beyond the model as the inner joints stop: its coupled inertia changed) was not
    moved by the contact, and the contact is inward of it."""
    k, end = e.settle, e.end
    held_for = max(end - k, 1)
    loaded = np.count_nonzero(loaded_moving[k:end], axis=0) >= max(min_len, 0.5 * held_for)
    after = np.median(qd_s[k:min(k + min_len, end)], axis=0)
    changed = np.abs(after - qd_before) > np.maximum(0.5 * np.abs(qd_before), v_th)
    last = max(k, end - min_len)   # the stop's last samples
    back = np.count_nonzero(held_back[last:end], axis=0) >= max(1.0, 0.5 * (end - last))
    return max([int(e.link), *np.flatnonzero((loaded & changed) | back).tolist()])


def _rigid_group(link: int, travel: FloatArray, resolution: FloatArray,
                 obstructed: tuple[int, ...]) -> int:
    """Outermost link of the rigid group of ``link``: joints beyond it that were not obstructed
    and whose travel over the event moved the arm beyond them by less than ``resolution``
    (per joint) moved as one body with it.  The contact force may be on any of their links with
    no moment about them (a force along a joint's axis, or through it), so the joint signals
    cannot tell those links apart; a joint beyond that moved, moved freely, so the contact is
    inward of it."""
    n = len(travel)
    m = link
    while m + 1 < n and m + 1 not in obstructed and travel[m + 1] < resolution[m + 1]:
        m += 1
    return m


def settled_window(index: int, length: int, end: int) -> slice:
    """The samples a contact's configuration is taken from: ``length`` from ``index``, where
    it settled, and none past ``end``, its release (at least the first)."""
    return slice(index, max(index + 1, min(index + length, end)))


def detect_contacts(log: JointLog, robot: RobotModel | None = None, *,
                    params: DetectionParams | None = None) -> Contacts:
    """Detect contact events and identify the link in contact from ``qd`` and ``tau_cmd`` only.

    Parameters
    ----------
    log : JointLog with ``tau_cmd`` (N, n)
    robot : RobotModel, optional; when given its joint names must match the log's (it adds
        gravity to the free-motion model and the map-based choice within rigid groups)
    params : DetectionParams, optional

    Returns
    -------
    Contacts
        One row per contact event, in time order (see :mod:`wholearm_tools.contacts.events`):
        ``t`` its first obstruction, ``t_end`` its release, ``q`` the configuration where it
        settled, ``qd_before`` the motion that led into it.

    Raises
    ------
    InputError
        No commanded torques, NaNs, too few samples, or joint names that do not match ``robot``.
    """
    from wholearm_tools.contacts import events as ev

    params = params or DetectionParams()
    _check_log(log)
    if robot is not None and tuple(robot.joint_names) != tuple(log.joint_names):
        raise InputError(f"log joints {log.joint_names} do not match robot joints "
                         f"{robot.joint_names}")
    n = len(log.joint_names)
    dt = float(np.median(np.diff(log.t)))
    width = max(1, round(params.smooth_time / dt))
    q = np.asarray(log.q)
    qd = np.asarray(log.qd)
    tau = np.asarray(log.tau_cmd)
    # the geometry of a contact (where it settled, what the arm swept) is the links'; the
    # signals (rest, load) are the drives'
    q_link = robot.link_angles(q, tau) if robot is not None else q
    qd_s = ev.smooth(qd, width)
    sigma_v = ev.velocity_noise(q, qd, dt, width)
    v_th = (np.broadcast_to(np.asarray(params.velocity_threshold, float), (n,)).copy()
            if params.velocity_threshold is not None else params.k_velocity * sigma_v)
    stopped = np.abs(qd_s) < v_th
    qdd = ev.smooth(np.gradient(qd_s, dt, axis=0), max(width, 3))
    use_gravity = robot is not None if params.gravity is None else bool(params.gravity)
    if use_gravity and robot is None:
        raise InputError("a free-motion model with gravity needs the robot")
    kin = robot.joint_positions_and_axes(q) if robot is not None else None
    grav = ev.gravity_features(robot, q, kin) if use_gravity and robot is not None else None
    inertia = ev.inertia_features(robot, q, qd_s, qdd, dt, width, kin) if kin is not None else None
    fm = ev.free_motion(tau, qd_s, qdd, ~stopped, grav, inertia=inertia)
    resid = tau - fm.predicted
    if params.torque_threshold is not None:
        tau_th = np.broadcast_to(np.asarray(params.torque_threshold, float), (n,)).copy()
    else:
        tau_th = fm.coulomb + params.k_torque * np.maximum(fm.rest_scale, fm.scale)
    loaded = np.abs(resid) > tau_th
    if robot is not None:
        # a joint at its mechanical stop also takes the stop's reaction, which pushes it away
        # from the stop by an unknown amount: a residual in that sense is explained by the
        # stop alone (tau_cmd - tau_free = -(tau_stop + tau_contact)); only one against it,
        # the controller pushing the joint away from the stop beyond the free motion's need,
        # proves a contact pressing it in
        tol = params.k_velocity * ev.second_difference_scale(q)
        loaded &= ~((q <= np.asarray(robot.lower) + tol) & (resid < 0))
        loaded &= ~((q >= np.asarray(robot.upper) - tol) & (resid > 0))
    min_len = max(params.min_stop_samples, int(np.ceil(params.min_stop_time / dt - 1e-9)))
    release = max(1, round(params.release_time / dt))
    obstructed = ev.drop_short(stopped & loaded, min_len)
    free_moving = ~stopped & (np.abs(resid) <= params.k_torque * fm.scale)
    dragging = ev.drop_short(~stopped & (resid * np.sign(qd_s) > params.k_torque * fm.scale),
                             min_len)
    # moving with a torque beyond the free-motion model, either way (driving a slide, or held
    # back): a joint the contact loads without stopping it (:func:`_changed_motion_link`)
    loaded_moving = ev.drop_short(~stopped & ~free_moving, min_len)
    # held back: loaded beyond its friction and not moving along the load (at rest, or driven
    # against it), for a stop's length at least (:func:`_changed_motion_link`)
    held_back = ev.drop_short(loaded & (stopped | (resid * qd_s < 0.0)), min_len)
    events = ev.segment_events(obstructed, ~stopped, free_moving, min_len, release, dragging)
    meta = {"sigma_velocity": sigma_v.tolist(), "sigma_torque": fm.rest_scale.tolist(),
            "sigma_torque_motion": fm.scale.tolist(),
            "coulomb": fm.coulomb.tolist(), "min_stop_samples": min_len,
            "release_samples": release, "rate": 1.0 / dt, "gravity_model": grav is not None}
    if not events:
        return Contacts(np.zeros(0), np.zeros(0, int), np.zeros(0, int), np.zeros((0, n)),
                        np.zeros((0, n)), np.zeros(0), v_th, tau_th, meta)

    nb = max(2, round(params.before_time / dt))
    lag = max(1, width // 2)
    limit = _clip_levels(tau, robot)
    saturated = np.abs(tau) >= limit * (1 - 1e-9)
    M = len(events)
    out_q = np.empty((M, n))
    out_qd = np.zeros((M, n))
    peak = np.zeros((M, n))
    held = np.zeros((M, n), dtype=bool)
    links = np.empty(M, dtype=np.int64)
    groups: list[tuple[int, int, int]] = []   # (row, innermost link, outermost link)
    by_map = params.rigid_choice == "map" and robot is not None
    # the motion that led into a contact is measured before its impact: the obstruction is
    # confirmed only once the joints have come to rest, and in between the impact (a bounce,
    # the outer joints flung on) is no approach.  The impact begins where the free motion of
    # the joints it obstructed ends (moving, as the free-motion model predicts, for longer
    # than the velocity's smoothing window: a bounce passes through free motion only for
    # moments the smoothed velocity does not resolve); looking back at most one release time
    for i, e in enumerate(events):
        s_, k_ = e.start, e.settle
        settled = q_link[settled_window(k_, min_len, e.end)]
        out_q[i] = np.median(settled, axis=0)
        back = max(0, s_ - lag - release)
        obs = list(e.obstructed)
        free = ev.drop_short(np.any(free_moving[back:max(back, s_ - lag), obs], axis=1),
                             width + 1)
        onset = np.flatnonzero(free)
        on = back + int(onset[-1]) + 1 if len(onset) else max(0, s_ - lag)
        lo, hi = max(0, on - nb), max(1, on)
        out_qd[i] = qd[lo:hi].mean(axis=0)
        at_rest = np.all(stopped[lo:hi], axis=0)  # already at rest before this contact
        out_qd[i, at_rest] = 0.0
        h0, h1 = max(0, lo - nb), max(1, lo)
        held[i] = (at_rest & np.all(stopped[h0:h1], axis=0) & ~np.any(loaded[h0:h1], axis=0))
        peak[i], _ = _stop_torques(resid, stopped, saturated, k_, max(e.end, k_ + 1),
                                   out_qd[i] != 0, held[i], h1, 5 * nb, fm.scale)
        e = replace(e, link=_changed_motion_link(e, loaded_moving, qd_s, out_qd[i], v_th, min_len,
                                                   held_back))
        links[i] = e.link
        if params.rigid_outer:
            if by_map:
                m = n - 1      # every link outward; _choose_rigid weighs them
            else:
                # a joint's travel over the event and the motion that led into it (one release
                # time before), as rotation: it counts as at rest while the arm beyond it moved
                # by less than the contact-location resolution (the dilation), or, without a
                # robot, by less than its velocity noise over that time
                w0 = max(0, s_ - release)
                travel = np.sum(np.abs(qd_s[w0:e.end]), axis=0) * dt
                if robot is not None:
                    arm = np.linalg.norm(robot.joint_positions(out_q[i])[-1]
                                         - robot.joint_positions(out_q[i])[:-1], axis=1)
                    resolution = params.rigid_dilation / np.maximum(arm, 1e-9)
                else:
                    resolution = v_th * (e.end - w0) * dt
                m = _rigid_group(e.link, travel, resolution, e.obstructed)
            if m > e.link:
                groups.append((i, e.link, m))
    prior = np.eye(n)[links]
    if groups:
        rows = [g[0] for g in groups]
        if by_map:
            beyond = np.arange(n)[None, :] > links[rows][:, None]
            chosen, share = _choose_rigid(robot, q_link, out_q[rows], out_qd[rows], peak[rows],
                                          held[rows], tau_th,
                                          [(g[1], g[2]) for g in groups],
                                          params.rigid_dilation,
                                          moved=beyond & ~held[rows] & (out_qd[rows] != 0))
            links[rows] = chosen
            prior[rows] = share
        else:
            links[rows] = [g[2] for g in groups]
            prior[rows] = np.eye(n)[links[rows]]
    idx = np.array([e.settle for e in events])
    return Contacts(log.t[[e.start for e in events]], links, idx, out_q, out_qd,
                    log.t[[min(e.end, log.n_samples - 1) for e in events]], v_th, tau_th, meta,
                    tau_peak=peak, held=held, link_prior=prior, t_settle=log.t[idx])
