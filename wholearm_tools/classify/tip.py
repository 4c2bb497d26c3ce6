"""Tip probability P_T of every contact (the paper's eqs. 1 and 2), labels and fit variances.

Eq. (2), the main estimate::

    P_T = ∫_{∂(tip ⊕ B)} (n·v)+ P_C dA  /  ∫_{∂(link ⊕ B) ∪ ∂(tip ⊕ B)} (n·v)+ P_C dA

* The integration surface is the boundary of link ``n`` (the cylinder side) and of its outer
  sphere (the tip sphere for the last link, the joint sphere at joint ``n + 1`` otherwise), both
  dilated by ``B``; only the part exposed on the boundary of the whole dilated robot at the
  contact pose counts (points inside another dilated link are not where a surface can be).
* ``v`` is the velocity of the boundary point as a point of link ``n``, from the joint velocity
  just before the stop (``Contacts.qd_before``); only boundary moving into space counts
  (``(n·v)+ = max(n·v, 0)``).
* ``P_C(x)``: a surface whose curvature radius is at least ``B`` and that touches the robot at
  ``g(x)`` holds a ball of radius ``B`` centred at ``x`` on its far side.  That ball cannot
  overlap space the robot has swept, so where any swept cell centre lies within ``B - tol`` of
  ``x`` (``x`` lies in the region swept by the *dilated* robot) only a failure of that
  assumption (an edge or the end of a finite surface, a surface curved more sharply than
  ``B``) leaves a surface possible: ``P_C(x)`` is the prior (1) times ``swept_doubt``
  (0.001; the fit's reading prior keeps the same doubt, ``fit.readings.P_TIP_CLIP``), otherwise
  the prior.  Where the map leaves admissible boundary the doubt changes P_T by about its
  size; where it rules out nearly all of it, P_T follows the swept boundary rather than the
  sliver the map still allows.  The robot's own cells at the contact pose are at distance
  >= ``B`` from every ``x`` by construction, so the cells the contact itself swept into never
  count against it; what decides is what lies *beyond* the contact.  ``tol`` (default a
  quarter cell) absorbs encoder noise.
* causal: map of the samples up to the contact sample; offline: the whole run's map.
* If the map leaves no admissible boundary (the map says everything ahead is free, an
  assumption violated) ``consistent`` is False, and P_T is the map-free value (every point
  carries the same doubt).

Eq. (1), reported as ``p_tip_swept``: the area (2-D) or volume (3-D) newly swept by the tip
sphere over the last displacement (the motion of the last ``B`` before the contact, at most
0.5 s) divided by the one newly swept by link ``n`` plus tip, on a local grid.

Labels: ``tip`` if P_T >= ``tip_threshold`` (0.6), ``link`` if P_T <= ``link_threshold`` (0.2),
otherwise ``ambiguous``.  The band comes from calibration on the bundled simulated scenarios
(simulator at 73a671c, 3 seeds each, contacts with the right link, fraction that were tip/joint per
offline P_T bin): below 0.2 at most 13 % (B = 0.02) / 6 % (B = 0.04); 0.6 and above at least 88 %
/ 93 %; in between 44-88 % / 26-72 %, i.e. genuinely uncertain.  Eq. (2) with the binary swept map
*under*-states the tip share (unexplored space counts as possibly occupied, which favours the
long body), hence the band sits below 0.5.

Fit variance (a two-point mixture: correct with probability
``1 - p_wrong``, off by ``Δ`` otherwise)::

    σ² = σ0² + p_wrong Δ²,   p_wrong = P_T if labelled/used as link else 1 - P_T
       = σ0² + min(P_T, 1 - P_T) Δ²

with ``σ0`` the contact-position noise (default 1 mm) and ``Δ`` half the length of link ``n``
(the typical distance between its tip and a body contact point).  Weights ``1/σ²`` run from
``1/σ0²`` for a certain contact down to ``~ 2/Δ²`` at P_T = 0.5.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.classify.swept import NEVER, SweptMap, _fingerprint, swept_map
from wholearm_tools.contacts.detect import Contacts
from wholearm_tools.errors import InputError
from wholearm_tools.logs.records import JointLog, Run
from wholearm_tools.robot.model import RobotModel

FloatArray = NDArray[np.float64]

LABELS = ("tip", "link", "ambiguous")


@dataclass(frozen=True, slots=True)
class ClassifyParams:
    """Tuning of :func:`tip_probability` (see the module docstring for the meaning)."""

    tip_threshold: float = 0.6
    link_threshold: float = 0.2
    prior: float = 1.0
    swept_doubt: float = 0.001
    sigma0: float = 1e-3
    tol: float | None = None
    n_axial: int = 0
    n_around: int = 0
    n_sphere: int = 0
    use_torques: bool = True
    torque_angle: float = 20.0
    statics_quantile: float = 0.95
    driving_lean: float | None = None

    def swept_tol(self, resolution: float) -> float:
        """How far inside ``B`` of a boundary point a swept cell centre must lie to rule the
        point out: ``tol``, by default a quarter of the map's cell (encoder noise)."""
        return self.tol if self.tol is not None else 0.25 * resolution

    def __post_init__(self) -> None:
        if not 0.0 <= self.link_threshold <= self.tip_threshold <= 1.0:
            raise InputError("expected 0 <= link_threshold <= tip_threshold <= 1, got "
                             f"{self.link_threshold}, {self.tip_threshold}")
        if not 0.0 < self.prior <= 1.0:
            raise InputError(f"prior must be in (0, 1], got {self.prior}")
        if self.driving_lean is not None and not 0.0 <= self.driving_lean <= 90.0:
            raise InputError(f"driving_lean must be in [0, 90] degrees, got {self.driving_lean}")
        if not 0.0 < self.statics_quantile <= 1.0:
            raise InputError(f"statics_quantile must be in (0, 1], got {self.statics_quantile}")
        if not 0.0 <= self.swept_doubt <= 1.0:
            raise InputError(f"swept_doubt must be in [0, 1], got {self.swept_doubt}")
        if not self.sigma0 > 0:
            raise InputError(f"sigma0 must be > 0, got {self.sigma0}")


@dataclass(frozen=True, slots=True, eq=False)
class Classification:
    """Tip/link classification of ``M`` contacts, columnar and read-only.

    Parameters
    ----------
    p_tip : (M,) float in [0, 1], eq. (2) with the swept map
    label : (M,) str, ``tip`` / ``link`` / ``ambiguous``
    variance : (M,) float, σ² for fit weights [m²]
    p_tip_nomap : (M,) float, eq. (2) without map information (P_C = 1)
    p_tip_swept : (M,) float, eq. (1) over the last displacement
    consistent : (M,) bool, False where the map left no admissible boundary (fallback used)
    B : float, causal : bool
    """

    p_tip: FloatArray
    label: NDArray[np.str_]
    variance: FloatArray
    p_tip_nomap: FloatArray
    p_tip_swept: FloatArray
    consistent: NDArray[np.bool_]
    B: float
    causal: bool
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        m = np.asarray(self.p_tip).shape[0]
        for name, dtype in (("p_tip", float), ("label", np.str_), ("variance", float),
                            ("p_tip_nomap", float), ("p_tip_swept", float),
                            ("consistent", bool)):
            arr = np.array(getattr(self, name), dtype=dtype).reshape(-1)
            if arr.shape != (m,):
                raise InputError(f"expected {name} of shape ({m},), got {arr.shape}")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    def __len__(self) -> int:
        return int(self.p_tip.shape[0])

    @property
    def is_tip(self) -> NDArray[np.bool_]:
        return self.label == "tip"

    @property
    def weight(self) -> FloatArray:
        """Fit weights ``1 / σ²``."""
        return 1.0 / self.variance


def labels_from_p_tip(p_tip: FloatArray, params: ClassifyParams | None = None
                      ) -> NDArray[np.str_]:
    """``tip`` where ``p_tip >= tip_threshold``, ``link`` where ``<= link_threshold``, else
    ``ambiguous`` (the band of :class:`ClassifyParams`)."""
    prm = params or ClassifyParams()
    p = np.asarray(p_tip, dtype=float)
    return np.where(p >= prm.tip_threshold, "tip",
                    np.where(p <= prm.link_threshold, "link", "ambiguous"))


# --------------------------------------------------------------------------- quadrature
def _fibonacci_sphere(n: int) -> FloatArray:
    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5**0.5) * k
    rho = np.sqrt(1 - z * z)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], -1)


def _perp_frames(u: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Two unit vectors perpendicular to each unit ``u (M, 3)`` and to each other."""
    helper = np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(u, e1)


@dataclass(frozen=True, slots=True)
class _Boundary:
    """Quadrature of the dilated boundary of each contact's link (M contacts × Q points)."""

    x: FloatArray        # (M, Q, d) points
    flux: FloatArray     # (M, Q) w (n·v)+ (0 where not exposed)
    tip: NDArray[np.bool_]  # (Q,) point on the outer sphere
    normal: FloatArray   # (M, Q, 3) outward unit normal of the dilated robot at each point


def _segment_dist(x: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Distance of points ``x (M, Q, d)`` to segments ``a, b (M, K, d)`` → ``(M, Q, K)``."""
    ab = b - a
    rel = x[:, :, None, :] - a[:, None, :, :]
    denom = np.maximum(np.sum(ab * ab, -1), 1e-300)[:, None, :]
    u = np.clip(np.sum(rel * ab[:, None], -1) / denom, 0, 1)
    return np.linalg.norm(rel - u[..., None] * ab[:, None], axis=-1)


def _boundary(robot: RobotModel, q: FloatArray, qd: FloatArray, link: NDArray[np.int64],
              B: float, params: ClassifyParams) -> _Boundary:
    M = q.shape[0]
    dim = robot.dim
    n = robot.dof
    pts, axes = robot.joint_positions_and_axes(q)
    ar = np.arange(M)
    a = pts[ar, link]
    b = pts[ar, link + 1]
    r_link = robot.link_radii[link]
    last = link == n - 1
    nxt = np.minimum(link + 1, n - 1)
    r_end = np.where(last, np.maximum(robot.tip_radius, r_link),
                     np.maximum(r_link, robot.link_radii[nxt]))
    Rc = r_link + B
    Re = r_end + B
    L = np.linalg.norm(b - a, axis=1)
    u = (b - a) / np.maximum(L, 1e-12)[:, None]
    if dim == 2:
        n_ax = params.n_axial or 64
        n_c = params.n_sphere or 96
        s = (np.arange(n_ax) + 0.5) / n_ax
        perp = np.stack([-u[:, 1], u[:, 0], np.zeros(M)], -1)
        side_n = np.concatenate([np.repeat(perp[:, None], n_ax, 1),
                                 np.repeat(-perp[:, None], n_ax, 1)], 1)       # (M, 2A, 3)
        ss = np.concatenate([s, s])
        side_x = a[:, None] + ss[None, :, None] * (b - a)[:, None] + Rc[:, None, None] * side_n
        side_w = np.repeat((L / n_ax)[:, None], 2 * n_ax, 1)
        th = 2 * np.pi * (np.arange(n_c) + 0.5) / n_c
        dirs = np.stack([np.cos(th), np.sin(th), np.zeros(n_c)], -1)
        end_n = np.broadcast_to(dirs, (M, n_c, 3))
        end_w = np.repeat((2 * np.pi * Re / n_c)[:, None], n_c, 1)
    else:
        n_ax = params.n_axial or 32
        n_ar = params.n_around or 24
        n_s = params.n_sphere or 400
        s = (np.arange(n_ax) + 0.5) / n_ax
        phi = 2 * np.pi * (np.arange(n_ar) + 0.5) / n_ar
        e1, e2 = _perp_frames(u)
        radial = (np.cos(phi)[None, :, None] * e1[:, None] + np.sin(phi)[None, :, None]
                  * e2[:, None])                                                # (M, P, 3)
        side_n = np.repeat(radial[:, None], n_ax, 1).reshape(M, -1, 3)
        ss = np.repeat(s, n_ar)
        side_x = a[:, None] + ss[None, :, None] * (b - a)[:, None] + Rc[:, None, None] * side_n
        side_w = np.repeat((L * 2 * np.pi * Rc / (n_ax * n_ar))[:, None], n_ax * n_ar, 1)
        dirs = _fibonacci_sphere(n_s)
        end_n = np.broadcast_to(dirs, (M, n_s, 3))
        end_w = np.repeat((4 * np.pi * Re**2 / n_s)[:, None], n_s, 1)
    end_x = b[:, None] + Re[:, None, None] * end_n
    x = np.concatenate([side_x, end_x], 1)
    nrm = np.concatenate([side_n, end_n], 1)
    w = np.concatenate([side_w, end_w], 1)
    tip = np.concatenate([np.zeros(side_x.shape[1], bool), np.ones(end_x.shape[1], bool)])

    # exposure: outside every other dilated capsule of the robot at the contact pose
    dist = _segment_dist(x, pts[:, :-1], pts[:, 1:])                 # (M, Q, n)
    clear = dist >= (robot.link_radii + B)[None, None] - 1e-9 * (1 + B)
    exposed = np.all(clear | (np.arange(n)[None, None] == link[:, None, None]), axis=-1)
    # own link: only the end sphere may cut into the side (bigger tip or joint sphere)
    own = dist[ar, :, link]
    exposed &= own >= Rc[:, None] - 1e-9 * (1 + B)
    dend = np.linalg.norm(x - b[:, None], axis=-1)
    exposed &= tip[None] | (dend >= Re[:, None] - 1e-9 * (1 + B))
    if robot.tip_radius > robot.link_radii[-1]:
        dtip = np.linalg.norm(x - pts[:, None, -1], axis=-1)
        exposed &= (dtip >= robot.tip_radius + B - 1e-9 * (1 + B)) | (last[:, None] & tip[None])

    # velocity of x as a point of link n: sum_{j<=n} qd_j a_j x (x - o_j)
    lever = x[:, :, None, :] - pts[:, None, :-1, :]                  # (M, Q, n, 3)
    mask = (np.arange(n)[None] <= link[:, None]) * qd                 # (M, n)
    v = np.einsum("mqjk,mj->mqk", np.cross(axes[:, None], lever), mask)
    flux = w * np.maximum(np.sum(nrm * v, -1), 0.0) * exposed
    return _Boundary(x[..., :dim], flux, tip, nrm)


# --------------------------------------------------------------------------- eq. (1)
def _swept_ratio(robot: RobotModel, q_path: FloatArray, link: int, cells_max: int) -> float:
    """Eq. (1): newly swept tip area / newly swept link+tip area over a short pose sequence."""
    dim = robot.dim
    pts = robot.joint_positions(q_path)[..., :dim]                 # (P, n+1, d)
    a, b = pts[:, link], pts[:, link + 1]
    r = float(robot.link_radii[link])
    r_end = float(max(robot.tip_radius, r) if link == robot.dof - 1
                  else max(r, robot.link_radii[link + 1]))
    allp = np.concatenate([a, b])
    lo = allp.min(0) - r_end
    hi = allp.max(0) + r_end
    res = max(float(np.prod(hi - lo) / cells_max) ** (1 / dim), 1e-9)
    axes = [np.arange(lo[k], hi[k] + res, res) for k in range(dim)]
    g = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, dim)

    g2 = np.einsum("ij,ij->i", g, g)

    def inside(k: int) -> tuple[NDArray[np.bool_], NDArray[np.bool_]]:
        # squared distances from expanded dot products (no (G, d) temporaries per pose)
        ab = b[k] - a[k]
        ga = g @ a[k]
        gab = g @ ab
        aa = float(a[k] @ a[k])
        abab = max(float(ab @ ab), 1e-300)
        t = np.clip((gab - float(a[k] @ ab)) / abab, 0, 1)
        # |g - a - t ab|² = |g - a|² - 2 t (g - a)·ab + t² |ab|²
        d2_a = g2 - 2 * ga + aa
        body = d2_a - 2 * t * (gab - float(a[k] @ ab)) + t * t * abab <= r * r
        tip = g2 - 2 * (g @ b[k]) + float(b[k] @ b[k]) <= r_end * r_end
        return body, tip

    body0, tip0 = inside(0)
    start = body0 | tip0
    any_tip = np.zeros(g.shape[0], bool)
    any_all = np.zeros(g.shape[0], bool)
    for k in range(1, pts.shape[0]):
        body, tip = inside(k)
        any_tip |= tip
        any_all |= body | tip
    new_all = np.count_nonzero(any_all & ~start)
    if new_all == 0:
        return float("nan")
    return float(np.count_nonzero(any_tip & ~start) / new_all)


def _last_displacement(robot: RobotModel, q: FloatArray, t: FloatArray, index: int, link: int,
                       B: float, n_poses: int = 8) -> FloatArray:
    """Poses over the last ``B`` of motion of link ``link`` before sample ``index``."""
    lo = int(np.searchsorted(t, t[index] - 0.5))
    window = q[lo:index + 1]
    pts = robot.joint_positions(window)[:, : link + 2]
    disp = np.max(np.linalg.norm(pts - pts[-1], axis=-1), axis=1)
    far = np.flatnonzero(disp >= B)
    k0 = int(far[-1]) if far.size else 0
    sel = np.unique(np.linspace(k0, window.shape[0] - 1, n_poses).round().astype(int))
    return window[sel]


#: last eq.-(1) result: the offline and the causal classification of the same contacts share it
_EQ1_MEMO: list[tuple[RobotModel, tuple[object, ...], FloatArray]] = []


def _eq1_all(robot: RobotModel, log: JointLog, c: Contacts, B: float) -> FloatArray:
    """Eq. (1) for every contact (memoised on robot, trajectory, contacts and B)."""
    M = len(c)
    if M == 0:
        return np.zeros(0)
    q = robot.link_angles(log.q, log.tau_cmd)
    t = np.asarray(log.t)
    key = (_fingerprint(q), np.asarray(c.index).tobytes(),
           np.asarray(c.link).tobytes(), np.asarray(c.q).tobytes(), B)
    for r, k, val in _EQ1_MEMO:
        if r is robot and k == key:
            return val
    out = np.array([
        _swept_ratio(robot, _last_displacement(robot, q, t, int(c.index[k]), int(c.link[k]), B),
                     int(c.link[k]), 20_000 if robot.dim == 2 else 40_000)
        for k in range(M)])
    _EQ1_MEMO[:] = [(robot, key, out)]
    return out


# --------------------------------------------------------------------------- public API
def _resolve(run_or_log: Run | JointLog, robot: RobotModel | None
             ) -> tuple[JointLog, RobotModel]:
    if isinstance(run_or_log, Run):
        return run_or_log.log, robot or run_or_log.robot
    if isinstance(run_or_log, JointLog):
        if robot is None:
            raise InputError("tip_probability on a JointLog needs robot=RobotModel")
        if tuple(robot.joint_names) != tuple(run_or_log.joint_names):
            raise InputError(f"log joints {run_or_log.joint_names} do not match robot joints "
                             f"{robot.joint_names}")
        return run_or_log, robot
    raise InputError(f"expected a Run or a JointLog, got {type(run_or_log).__name__}")


def _check_b(B: float) -> float:
    B = float(B)
    if not np.isfinite(B) or B <= 0:
        raise InputError(f"B must be a positive length in metres, got {B}")
    return B


class TipEvaluator:
    """Per-contact boundary quadrature and swept-map look-ups, evaluated at any map time.

    Build once, then :meth:`p_tip` for the causal (``until = contact sample``), offline
    (``until = None``) or any replay time — the Figure 4 curves cost one comparison each.
    """

    def __init__(self, robot: RobotModel, log: JointLog, contacts: Contacts, B: float, *,
                 grid: SweptMap | None = None, params: ClassifyParams | None = None) -> None:
        self.params = params or ClassifyParams()
        self.B = _check_b(B)
        self.robot = robot
        if contacts.n_joints != robot.dof:
            raise InputError(f"contacts have {contacts.n_joints} joints, robot {robot.dof}")
        q = robot.link_angles(log.q, log.tau_cmd)
        if not np.all(np.isfinite(q)):
            raise InputError("log field q contains NaN or infinite values")
        self.grid = grid if grid is not None else swept_map(robot, q, B=self.B)
        if self.grid.dim != robot.dim:
            raise InputError(f"grid is {self.grid.dim}-D, robot workspace {robot.dim}-D")
        self.contacts = contacts
        self.index = np.asarray(contacts.index)
        self.tol = self.params.swept_tol(self.grid.resolution)
        M = len(contacts)
        self.torque_informed = np.zeros(M, dtype=bool)
        self.driving_lean = 90.0   # the lean the driving joints are judged with [deg]
        if M:
            bd = _boundary(robot, np.asarray(contacts.q), np.asarray(contacts.qd_before),
                           np.asarray(contacts.link), self.B, self.params)
            self.flux = bd.flux
            self.tip = bd.tip
            self.tmin = self.grid.first_within(bd.x, self.B - self.tol)
            if self.params.use_torques:
                self._condition_on_torques(contacts, bd)
        else:
            self.flux = np.zeros((0, 1))
            self.tip = np.zeros(1, bool)
            self.tmin = np.zeros((0, 1), np.int64)
        num0 = (self.flux * self.tip).sum(1)
        self._flux_total = den0 = self.flux.sum(1)
        with np.errstate(invalid="ignore", divide="ignore"):
            self.p_nomap = np.where(den0 > 0, num0 / np.where(den0 > 0, den0, 1), 0.5)

    def _condition_on_torques(self, contacts: Contacts, bd: _Boundary) -> None:
        """Keep only the boundary that explains the torques at the height of the stop.

        A joint held still during the move carries the contact force's moment alone.  The
        joints that drove into the stop are at rest there too, so they balance the same force
        against their controller, and their torques are its moments as well — where the stop
        is a static balance with the environment, the force within a friction cone of the
        normal.  Where the contact could lie is restricted to the dilated-boundary points whose
        force predicts all those torques (:func:`wholearm_tools.contacts.detect.lean_needed`);
        eq. (2) is then the same ratio over that part: the map decides within what the torques
        allow.

        How far the force may lean is the held joints' ``torque_angle``.  For the driving
        joints it is measured from the run: of every stop two or more joints drove into, the
        lean its best admissible point needs, at the ``statics_quantile`` of those stops (at
        least ``torque_angle``), unless ``driving_lean`` gives it (the run's, measured once,
        when a few of its contacts are evaluated again as if on other links).  A run whose
        stops balance like a rig's needs a friction cone's lean; one whose stops do not (a
        rigid stop that holds the arm whatever the controller pushes, friction idealised away)
        needs leans no cone allows, and its driving joints then restrict nothing.  Contacts
        without judged joints, or whose torques no admissible point explains (an assumption
        violated), keep the whole boundary.
        """
        from wholearm_tools.contacts.detect import lean_needed

        link = np.asarray(contacts.link)
        moving = np.asarray(contacts.qd_before) != 0
        driving = moving & (np.arange(contacts.n_joints)[None, :] <= link[:, None])
        held = np.asarray(contacts.held)
        rows = np.flatnonzero((held | driving).any(axis=1))
        if rows.size == 0:
            return
        need = lean_needed(self.robot, np.asarray(contacts.q)[rows], bd.x[rows],
                           bd.normal[rows], moving[rows], np.asarray(contacts.tau_peak)[rows],
                           np.asarray(contacts.torque_threshold), link[rows], self.B)
        free = self.tmin[rows] >= NEVER  # admissible with the whole run's map
        admissible = free & (self.flux[rows] > 0)
        drive_need = np.max(np.where(driving[rows][:, None, :], need, 0.0), axis=-1)
        s_held = np.sin(np.radians(self.params.torque_angle))
        s_drive = s_held
        several = (driving[rows].sum(axis=1) >= 2) & admissible.any(axis=1)
        if self.params.driving_lean is not None:
            s_drive = max(s_held, float(np.sin(np.radians(self.params.driving_lean))))
        elif np.any(several):
            best = np.min(np.where(admissible[several], drive_need[several], np.inf), axis=1)
            # a stop no lean explains counts as needing more than any (sin > 1)
            s_drive = max(s_held, float(np.quantile(np.minimum(best, 2.0),
                                                    self.params.statics_quantile)))
        judging = s_drive < 1.0
        ok = (np.all(~held[rows][:, None, :] | (need <= s_held), axis=-1)
              & ((drive_need <= s_drive) | (not judging)))
        informed = held[rows].any(axis=1) | (judging & driving[rows].any(axis=1))
        kept = informed & ((self.flux[rows] * ok * free).sum(1) > 0)
        flux = self.flux.copy()
        flux[rows[kept]] *= ok[kept]
        self.flux = flux
        self.torque_informed[rows[kept]] = True
        self.driving_lean = float(np.degrees(np.arcsin(min(s_drive, 1.0))))

    def p_tip(self, until: Any = None) -> tuple[FloatArray, NDArray[np.bool_]]:
        """P_T with the map of samples ``<= until`` (scalar or (M,); None = whole run).

        Returns ``(p_tip (M,), consistent (M,))``.
        """
        if until is None:
            u = np.full(len(self.contacts), NEVER - 1, dtype=np.int64)
        else:
            u = np.broadcast_to(np.asarray(until, dtype=np.int64), (len(self.contacts),))
        free = self.tmin > u[:, None]
        pc = self.params.prior * np.where(free, 1.0, self.params.swept_doubt)
        num = (self.flux * pc * self.tip).sum(1)
        den = (self.flux * pc).sum(1)
        den0 = self._flux_total
        ok = (self.flux * free).sum(1) > 1e-9 * np.maximum(den0, 1e-300)
        live = den > 1e-9 * np.maximum(den0, 1e-300)
        p = np.where(live, num / np.where(live, den, 1.0), self.p_nomap)
        return np.clip(p, 0.0, 1.0), ok

    def classification(self, causal: bool, log: JointLog) -> Classification:
        p, ok = self.p_tip(self.index if causal else None)
        c = self.contacts
        M = len(c)
        prm = self.params
        label = labels_from_p_tip(p, prm)
        pts = self.robot.joint_positions(np.asarray(c.q)) if M else np.zeros((0, 2, 3))
        ar = np.arange(M)
        L = (np.linalg.norm(pts[ar, c.link + 1] - pts[ar, c.link], axis=-1) if M
             else np.zeros(0))
        variance = prm.sigma0**2 + np.minimum(p, 1 - p) * (0.5 * L) ** 2
        swept = _eq1_all(self.robot, log, c, self.B)
        meta = {"resolution": self.grid.resolution, "tol": self.tol,
                "tip_threshold": prm.tip_threshold, "link_threshold": prm.link_threshold,
                "swept_doubt": prm.swept_doubt, "sigma0": prm.sigma0,
                "torque_informed": int(np.count_nonzero(self.torque_informed)),
                "driving_lean": self.driving_lean}
        return Classification(p, label, variance, self.p_nomap, swept, ok, self.B, causal, meta)


def tip_probability(run_or_log: Run | JointLog, contacts: Contacts, B: float, *,
                    robot: RobotModel | None = None, causal: bool = False,
                    grid: SweptMap | None = None,
                    params: ClassifyParams | None = None) -> Classification:
    """Tip probability, label and fit variance of every contact.

    Parameters
    ----------
    run_or_log : Run, or JointLog together with ``robot``
    contacts : Contacts from :func:`wholearm_tools.contacts.detect_contacts`
    B : float, smallest expected surface curvature radius [m]
    causal : bool
        Use the map as the robot saw it at each contact (samples up to the contact) instead of
        the whole run's map.
    grid : SweptMap, optional; built from the log with ``B`` when omitted (reuse it across calls)
    params : ClassifyParams, optional

    Returns
    -------
    Classification
    """
    log, robot = _resolve(run_or_log, robot)
    ev = TipEvaluator(robot, log, contacts, B, grid=grid, params=params)
    return ev.classification(causal, log)


def tip_probability_history(run_or_log: Run | JointLog, contacts: Contacts, B: float,
                            times: Any, *, robot: RobotModel | None = None,
                            grid: SweptMap | None = None,
                            params: ClassifyParams | None = None) -> FloatArray:
    """Causal replay: P_T of every contact with the map of the samples up to each time.

    ``times (T,)`` seconds on the log clock → ``(M, T)`` float, NaN before each contact.
    This is the paper's Figure 4: each contact's P_T drifts toward 0 or 1 as the map grows.
    """
    log, robot = _resolve(run_or_log, robot)
    times = np.asarray(times, dtype=float).reshape(-1)
    ev = TipEvaluator(robot, log, contacts, B, grid=grid, params=params)
    idx = np.searchsorted(log.t, times, side="right") - 1
    out = np.full((len(contacts), times.shape[0]), np.nan)
    for k, i in enumerate(idx):
        p, _ = ev.p_tip(max(int(i), 0))
        live = contacts.index <= i
        out[live, k] = p[live]
    return out
