"""Robot–environment clearance and exact first-contact search along guarded moves.

The robot is a chain of capsules (link ``i``: segment joint ``i`` → joint ``i + 1``/tip, radius
``w_i``) plus the tip sphere.  Obstacles follow the ``Obstacle`` protocol of
``wholearm_tools.geometry.bounded``: ``clearance(points (N, d)) -> (N,)`` and
``segment_clearance(a, b) -> (clearance (N,), t (N,))`` where clearance is the distance to the
obstacle measured from free space (negative inside), and ``surface_id``.  Planar robots work in the
xy plane with 2-D obstacles.

Contact search (no tunnelling at any speed).  Clearance is 1-Lipschitz in the positions of the
robot's axis points, and along a monotone joint path every axis point of link ``i`` moves at most
``m_i = Σ_j |Δq_j| · lever[j, i]`` where ``lever[j, i]`` is the chain length from joint ``j`` to
the end of link ``i`` (a configuration-independent bound).  An interval whose end clearances
satisfy ``c(a) + c(b) > m`` cannot contain a contact; other intervals are subdivided in time order
(conservative advancement by interval bisection) down to a resolution where ``m`` is below half
the penetration tolerance, which returns the *first* contact time with at most ``tol`` of
penetration.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError
from wholearm_tools.robot.model import RobotModel

FloatArray = NDArray[np.float64]


class ObstacleLike(Protocol):
    """What the simulator needs from an obstacle (see ``geometry.bounded.Obstacle``)."""

    surface_id: int

    def clearance(self, points: FloatArray) -> FloatArray: ...

    def segment_clearance(self, a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]: ...

    def to_dict(self) -> dict[str, Any]: ...


@dataclass(frozen=True, slots=True)
class Clearance:
    """Per-link clearance at a batch of configurations.

    value : (M, L) float, clearance of each selected link (capsule and, for the last link, tip)
    obstacle : (M, L) int, index of the obstacle attaining it
    t : (M, L) float, segment parameter of the robot axis point attaining it
    tip_sphere : (M, L) bool, True where the tip sphere (not the capsule) attains it
    """

    value: FloatArray
    obstacle: NDArray[np.int64]
    t: FloatArray
    tip_sphere: NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class ContactInfo:
    """Ground truth of one link's contact (see ``logs.records.GroundTruth``)."""

    link: int
    kind: str
    point: FloatArray  # (3,)
    surface: int
    s: float
    clearance: float
    #: unit surface normal at the contact, pointing from the surface to the robot (3,)
    normal: FloatArray = field(default_factory=lambda: np.zeros(3))


class Collider:
    """Clearance queries of one robot against a fixed set of obstacles.

    Parameters
    ----------
    robot : RobotModel
    obstacles : sequence of ObstacleLike
    tolerance : float
        Largest penetration allowed at a detected contact [m].
    """

    def __init__(self, robot: RobotModel, obstacles: Sequence[ObstacleLike],
                 tolerance: float = 1e-6, sample_step: float = 0.005,
                 node_step: float = 0.01) -> None:
        if not obstacles:
            raise InputError("the environment has no obstacles")
        if tolerance <= 0:
            raise InputError(f"tolerance must be positive, got {tolerance}")
        radii = np.asarray(robot.link_radii)
        if np.any(np.diff(radii) >= 0):
            raise InputError(
                f"the simulator needs link radii that decrease outward (each joint sphere then "
                f"belongs to one link), got {radii.tolist()}")
        for obs in obstacles:
            dim = getattr(obs, "dim", robot.dim)
            if dim != robot.dim:
                raise InputError(f"obstacle {obs!r} is {dim}-D but the robot works in "
                                 f"{robot.dim}-D")
        self.robot = robot
        self.obstacles = tuple(obstacles)
        self.dim = robot.dim
        self.tolerance = float(tolerance)
        self.node_step = float(node_step)
        n = robot.dof
        pts0 = robot.joint_positions(np.zeros(n))
        lengths = np.linalg.norm(np.diff(pts0, axis=0), axis=1)
        lever = np.zeros((n, n))
        for i in range(n):
            for j in range(i + 1):
                lever[j, i] = lengths[j:i + 1].sum()
        self.lengths = lengths
        self.lever = lever
        self.radii = radii
        self.tip_sphere = robot.tip_radius > radii[-1]
        self.n_evals = 0
        # sample fractions and Lipschitz slack of the cheap lower bound (spacing <= sample_step)
        counts = np.maximum(2, np.ceil(lengths / sample_step).astype(int) + 1)
        self._fractions = [np.linspace(0.0, 1.0, c) for c in counts]
        self._slack = 0.5 * lengths / (counts - 1)
        self.surfaces = _surface_table(self.obstacles)

    # ------------------------------------------------------------------ queries
    def motion_bound(self, dq: FloatArray, links: NDArray[np.int64]) -> FloatArray:
        """Bound on the displacement of any axis point of ``links`` for monotone joint changes
        ``dq (..., n)``, shape ``(..., L)``."""
        return np.abs(dq) @ self.lever[:, links]

    def clearance(self, Q: FloatArray, links: NDArray[np.int64] | None = None,
                  bound: bool = False) -> Clearance:
        """Clearance of ``links`` (default all) at configurations ``Q (M, n)``.

        ``bound=False``: the obstacles' segment minima (accurate to ~1e-7 m).  ``bound=True``: a
        cheaper guaranteed lower bound, from point clearances at samples spaced ``delta`` along
        each link axis minus ``delta / 2`` (clearance is 1-Lipschitz); ``t`` is then approximate.
        """
        robot = self.robot
        if links is None:
            links = np.arange(robot.dof)
        Q = np.atleast_2d(Q)
        M, L = Q.shape[0], len(links)
        self.n_evals += M
        pts = robot.joint_positions(Q)[..., : self.dim]
        if bound:
            value, obstacle, t = self._sampled(pts, links)
        else:
            a = pts[:, links].reshape(M * L, self.dim)
            b = pts[:, links + 1].reshape(M * L, self.dim)
            vals = np.empty((len(self.obstacles), M * L))
            ts = np.empty_like(vals)
            for k, obs in enumerate(self.obstacles):
                vals[k], ts[k] = obs.segment_clearance(a, b)
            best = np.argmin(vals, axis=0)
            idx = np.arange(M * L)
            value = (vals[best, idx] - np.tile(self.radii[links], M)).reshape(M, L)
            t = ts[best, idx].reshape(M, L)
            obstacle = best.reshape(M, L)
        tip = np.zeros((M, L), dtype=bool)
        last = np.flatnonzero(links == robot.dof - 1)
        if self.tip_sphere and last.size:
            tips = pts[:, -1]
            tv = np.stack([obs.clearance(tips) for obs in self.obstacles])
            tb = np.argmin(tv, axis=0)
            tval = tv[tb, np.arange(M)] - robot.tip_radius
            j = int(last[0])
            better = tval < value[:, j]
            value[:, j] = np.where(better, tval, value[:, j])
            obstacle[:, j] = np.where(better, tb, obstacle[:, j])
            t[:, j] = np.where(better, 1.0, t[:, j])
            tip[:, j] = better
        return Clearance(value, obstacle, t, tip)

    def _sampled(self, pts: FloatArray, links: NDArray[np.int64],
                 ) -> tuple[FloatArray, NDArray[np.int64], FloatArray]:
        M = pts.shape[0]
        chunks, owners, params, slack = [], [], [], []
        for j, i in enumerate(links):
            fr = self._fractions[i]
            a, b = pts[:, i], pts[:, i + 1]
            chunks.append(a[:, None, :] + fr[None, :, None] * (b - a)[:, None, :])
            owners.append(np.full(len(fr), j))
            params.append(fr)
            slack.append(np.full(len(fr), self._slack[i] + self.radii[i]))
        P = np.concatenate(chunks, axis=1)  # (M, S, d)
        owner = np.concatenate(owners)
        frac = np.concatenate(params)
        sl = np.concatenate(slack)
        S = P.shape[1]
        flat = P.reshape(M * S, self.dim)
        vals = np.stack([obs.clearance(flat) for obs in self.obstacles])  # (K, M*S)
        best = np.argmin(vals, axis=0)
        v = vals[best, np.arange(M * S)].reshape(M, S) - sl
        ob = best.reshape(M, S)
        L = len(links)
        value = np.empty((M, L))
        obstacle = np.empty((M, L), dtype=np.int64)
        t = np.empty((M, L))
        start = 0
        for j in range(L):
            cnt = int(np.count_nonzero(owner == j))
            seg = v[:, start:start + cnt]
            k = np.argmin(seg, axis=1)
            value[:, j] = seg[np.arange(M), k]
            obstacle[:, j] = ob[np.arange(M), start + k]
            t[:, j] = frac[start + k]
            start += cnt
        return value, obstacle, t

    def min_clearance(self, Q: FloatArray) -> FloatArray:
        """Smallest clearance over all links at each configuration, ``(M,)``."""
        return self.clearance(Q).value.min(axis=1)

    def is_free(self, Q: FloatArray, margin: float = 0.0) -> NDArray[np.bool_]:
        """True where every link clears the environment by more than ``margin``, ``(M,)``."""
        return self.min_clearance(Q) > margin

    # ------------------------------------------------------------------ contact search
    def first_contact(
        self,
        path: Callable[[FloatArray], FloatArray],
        times: FloatArray,
        links: NDArray[np.int64],
        Q: FloatArray | None = None,
    ) -> tuple[float, FloatArray, NDArray[np.int64]] | None:
        """First time along a monotone joint path at which one of ``links`` touches.

        Parameters
        ----------
        path : callable, times (K,) -> configurations (K, n); joint values must be monotone in
            time between consecutive ``times``.
        times : (K,) float, increasing nodes (the log grid of the move); the path is checked on
            ``[times[0], times[-1]]``.
        links : (L,) int, the links that move.
        Q : (K, n) float, optional, ``path(times)`` if already computed.

        Returns
        -------
        None when the path is free, else ``(t_contact, q_contact (n,), touching links)``.
        The configuration at ``t_contact`` penetrates by at most ``tolerance``.
        """
        h = 0.5 * self.tolerance
        if Q is None:
            Q = path(times)
        # coarse nodes: every robot point moves at most node_step between consecutive ones
        step = self.motion_bound(np.diff(Q, axis=0), links).max(axis=1)
        cum = np.concatenate([[0.0], np.cumsum(step)])
        keep = np.flatnonzero(np.diff(np.floor(cum / self.node_step), prepend=-1.0) > 0)
        keep = np.unique(np.concatenate([keep, [len(times) - 1]]))
        times, Q = times[keep], Q[keep]
        lb = self.clearance(Q, links, bound=True).value + h  # lower bound of g; contact: g < 0
        m = self.motion_bound(np.diff(Q, axis=0), links)
        unsafe = np.flatnonzero(np.any(lb[:-1] + lb[1:] <= m, axis=1))
        exact: dict[int, FloatArray] = {}

        def g_at(k: int) -> FloatArray:
            if k not in exact:
                exact[k] = self.clearance(Q[k][None], links).value[0] + h
            return exact[k]

        if unsafe.size and unsafe[0] == 0 and np.any(g_at(0) < 0):
            raise InputError(f"guarded move starts in collision (clearance "
                             f"{g_at(0).min() - h:.3g})")
        for k in unsafe:
            g0, g1 = g_at(int(k)), g_at(int(k) + 1)
            if np.all(g0 + g1 > m[k]):
                continue
            hit = self._refine(path, float(times[k]), float(times[k + 1]), Q[k], Q[k + 1],
                               g0, g1, links, h)
            if hit is not None:
                return hit
        return None

    def _refine(self, path: Callable[[FloatArray], FloatArray], t0: float, t1: float,
                q0: FloatArray, q1: FloatArray, g0: FloatArray, g1: FloatArray,
                links: NDArray[np.int64], h: float, parts: int = 8,
                ) -> tuple[float, FloatArray, NDArray[np.int64]] | None:
        """Time-ordered subdivision of one unsafe interval (depth-first, earliest first)."""
        stack = [(t0, t1, q0, q1, g0, g1)]
        while stack:
            a, b, qa, qb, ga, gb = stack.pop()
            m = self.motion_bound(qb - qa, links)
            if np.all(ga + gb > m):
                continue  # provably free
            if np.max(m) <= h:
                # resolution reached: contact if some link ends below -h
                if np.any(gb < 0):
                    touching = links[ga <= m + 0.5 * h]
                    return a, qa, touching
                continue
            ts = np.linspace(a, b, parts + 1)
            Qs = path(ts[1:-1])
            gs = self.clearance(Qs, links).value + h
            Qall = np.vstack([qa[None], Qs, qb[None]])
            gall = np.vstack([ga[None], gs, gb[None]])
            for i in range(parts - 1, -1, -1):  # push latest first: earliest popped first
                stack.append((ts[i], ts[i + 1], Qall[i], Qall[i + 1], gall[i], gall[i + 1]))
        return None

    # ------------------------------------------------------------------ ground truth
    def contact_info(self, q: FloatArray, link: int) -> ContactInfo:
        """Where link ``link`` touches at configuration ``q (n,)``: kind, surface point, s."""
        robot = self.robot
        cl = self.clearance(q[None], np.array([link]))
        k = int(cl.obstacle[0, 0])
        t = float(cl.t[0, 0])
        obs = self.obstacles[k]
        pts = robot.joint_positions(q)
        last = link == robot.dof - 1
        if cl.tip_sphere[0, 0]:
            centre, kind, s = pts[-1], "tip", 1.0
        else:
            a, b = pts[link], pts[link + 1]
            centre = a + t * (b - a)
            s = t
            if t >= 1.0 - 1e-6:
                kind, s = ("tip" if last else "joint"), 1.0
            else:
                kind = "body"
        surf_point = _closest_surface_point(obs, centre[: self.dim])
        sid, surf_point = self._surface_of(k, centre[: self.dim], surf_point)
        point = np.zeros(3)
        point[: self.dim] = surf_point
        away = centre[: self.dim] - surf_point
        if np.linalg.norm(away) < 1e-6:
            # sharp tip on the surface: the normal at a point just behind it, inside the link
            back = pts[link] - centre
            x0 = centre + 1e-4 * back / max(float(np.linalg.norm(back)), 1e-12)
            away = x0[: self.dim] - _closest_surface_point(obs, x0[: self.dim])
        normal = np.zeros(3)
        normal[: self.dim] = away / max(float(np.linalg.norm(away)), 1e-15)
        return ContactInfo(link=link, kind=kind, point=point, surface=sid, s=float(s),
                           clearance=float(cl.value[0, 0]), normal=normal)

    def _surface_of(self, k: int, centre: FloatArray, approx: FloatArray,
                    ) -> tuple[int, FloatArray]:
        """Surface id of obstacle ``k`` nearest the contact point ``approx`` and the contact point
        snapped onto that primitive when the obstacle has several."""
        rows = [r for r in self.surfaces if r.obstacle == k]
        if len(rows) == 1:
            return rows[0].id, approx
        dist = [abs(float(r.primitive.signed_distance(approx[None])[0])) for r in rows]
        row = rows[int(np.argmin(dist))]
        snapped = np.asarray(row.primitive.closest_point(centre[None]))[0]
        if abs(np.linalg.norm(snapped - centre) - np.linalg.norm(approx - centre)) < 1e-5:
            return row.id, snapped
        return row.id, approx


@dataclass(frozen=True, slots=True)
class SurfaceRow:
    """One environment surface: ``id`` (0-based), the obstacle it belongs to, its primitive."""

    id: int
    obstacle: int
    primitive: Any
    free_side: int


def _surface_table(obstacles: Sequence[ObstacleLike]) -> tuple[SurfaceRow, ...]:
    """Number the primitives of every obstacle 0, 1, ... in order."""
    rows = []
    for k, obs in enumerate(obstacles):
        prims = getattr(obs, "primitives", None)
        if prims is None:
            prim = getattr(obs, "primitive", None)
            prims = () if prim is None else (prim,)
        free_side = int(getattr(obs, "free_side", -1))
        for prim in prims or (None,):
            rows.append(SurfaceRow(len(rows), k, prim, free_side))
    return tuple(rows)


def surface_dicts(collider: Collider) -> tuple[dict[str, Any], ...]:
    """Ground-truth surface records: ``{"id", "type", "params", "free_side", "bounds",
    "obstacle"}`` where ``obstacle`` is the owning obstacle's ``to_dict()`` (rebuild it with
    ``geometry.obstacle_from_dict``)."""
    from wholearm_tools.geometry.base import primitive_to_dict

    out = []
    for row in collider.surfaces:
        obs = collider.obstacles[row.obstacle]
        prim = primitive_to_dict(row.primitive) if row.primitive is not None else {
            "type": "unknown", "params": {}}
        bounds = obs.bounds() if hasattr(obs, "bounds") else {}
        out.append({"id": row.id, "type": prim["type"], "params": prim["params"],
                    "free_side": row.free_side, "bounds": bounds, "obstacle": obs.to_dict()})
    return tuple(out)


def _closest_surface_point(obs: ObstacleLike, p: FloatArray) -> FloatArray:
    """Closest point of the obstacle's material to ``p (d,)``: ``p - c * grad c``, with the
    gradient of the clearance by central differences."""
    d = p.shape[0]
    eps = 1e-6
    probes = np.concatenate([p[None], p + eps * np.eye(d), p - eps * np.eye(d)])
    c = np.asarray(obs.clearance(probes))
    grad = (c[1:d + 1] - c[d + 1:]) / (2 * eps)
    norm = np.linalg.norm(grad)
    if norm < 1e-12:
        return p.copy()
    return p - c[0] * grad / norm
