"""Exploration strategies: which guarded move to make next.

Each strategy is registered by name in :data:`STRATEGIES` and built with
``make_strategy(name, robot, rng=..., **params)``.  Common parameters:

``lower``, ``upper`` : (n,) target box in joint space (default: the joint limits);
``margin`` : float, targets whose clearance is below it are rejected (default 5 mm);
``min_step`` : float, smallest joint-space distance [rad] from the current configuration;
``max_step`` : float or None, largest change of any joint in one move [rad];
``free_target`` : bool, True (default): the target configuration itself must be free; False:
targets behind obstacles are allowed (the guarded move stops at the wall), only moves that would
be in collision right at their start are rejected.

A strategy only proposes *targets*; guarded moves stop at the first contact, so a target behind a
wall is a perfectly good way to find the wall.  Targets that start in collision are rejected.
"""

from __future__ import annotations

import itertools
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError
from wholearm_tools.robot.model import RobotModel
from wholearm_tools.sim.collision import Collider
from wholearm_tools.sim.occupancy import SweptGrid

FloatArray = NDArray[np.float64]

STRATEGIES: dict[str, type[Strategy]] = {}


def register(cls: type[Strategy]) -> type[Strategy]:
    STRATEGIES[cls.name] = cls
    return cls


def make_strategy(name: str, robot: RobotModel, collider: Collider, grid: SweptGrid,
                  rng: np.random.Generator | int | None = None, **params: Any) -> Strategy:
    """Build the strategy registered under ``name``."""
    try:
        cls = STRATEGIES[name]
    except KeyError:
        raise InputError(f"unknown strategy {name!r} (known: {', '.join(sorted(STRATEGIES))})"
                         ) from None
    try:
        return cls(robot, collider, grid, rng=rng, **params)
    except TypeError as exc:
        raise InputError(f"strategy {name!r}: {exc}") from None


class Strategy(ABC):
    """Base class: target box, collision rejection, explicit random generator."""

    name: ClassVar[str]

    def __init__(self, robot: RobotModel, collider: Collider, grid: SweptGrid, *,
                 rng: np.random.Generator | int | None = None,
                 lower: Sequence[float] | None = None, upper: Sequence[float] | None = None,
                 margin: float = 0.005, min_step: float = 0.15, max_step: float | None = None,
                 free_target: bool = True) -> None:
        self.robot = robot
        self.collider = collider
        self.grid = grid
        self.rng = np.random.default_rng(rng)
        lo = np.array(robot.lower if lower is None else lower, dtype=float)
        hi = np.array(robot.upper if upper is None else upper, dtype=float)
        if lo.shape != (robot.dof,) or hi.shape != (robot.dof,):
            raise InputError(f"strategy box must have {robot.dof} values per bound, got "
                             f"{lo.shape} and {hi.shape}")
        self.lower = np.maximum(lo, robot.lower)
        self.upper = np.minimum(hi, robot.upper)
        if np.any(self.lower > self.upper):
            raise InputError(f"strategy box {lo.tolist()}..{hi.tolist()} is outside the joint "
                             "limits")
        self.margin = float(margin)
        self.min_step = float(min_step)
        self.max_step = None if max_step is None else float(max_step)
        self.free_target = bool(free_target)

    def acceptable(self, q: FloatArray, candidates: FloatArray,
                   min_step: float | None = None) -> NDArray[np.bool_]:
        """Candidates at least ``min_step`` (default: the strategy's) from ``q`` whose
        configuration is free (with margin)."""
        dist = np.linalg.norm(candidates - q, axis=1)
        far = dist >= (self.min_step if min_step is None else min_step)
        ok = np.zeros(len(candidates), dtype=bool)
        if not np.any(far):
            return ok
        if self.free_target:
            ok[far] = self.collider.is_free(candidates[far], self.margin)
        else:
            # the first few millimetres of the move must be free: no zero-length guarded moves
            step = np.abs(candidates[far] - q) @ self.collider.lever[:, -1]
            frac = np.minimum(1.0, 0.003 / np.maximum(step, 1e-12))[:, None]
            ok[far] = self.collider.is_free(q + frac * (candidates[far] - q), 0.0)
        return ok

    def uniform(self, count: int, q: FloatArray | None = None) -> FloatArray:
        """Uniform targets in the box (intersected with ``q ± max_step`` when set)."""
        lo, hi = self.lower, self.upper
        if q is not None and self.max_step is not None:
            lo = np.maximum(lo, q - self.max_step)
            hi = np.minimum(hi, q + self.max_step)
        return self.rng.uniform(lo, hi, size=(count, self.robot.dof))

    @abstractmethod
    def next_target(self, q: FloatArray) -> FloatArray | None:
        """Next joint target from configuration ``q (n,)``, or None when nothing is reachable."""

    def observe(self, swept: FloatArray, attempted: FloatArray | None) -> None:  # noqa: B027
        """Called after each move with the configurations the robot swept ``(K, n)`` and, when
        the move stopped at a contact, the configurations it was commanded toward but could not
        reach ``(J, n)``."""


@register
class RandomStrategy(Strategy):
    """Seeded random guarded moves: uniform targets in the box, colliding ones rejected."""

    name = "random"

    def __init__(self, *args: Any, batch: int = 32, tries: int = 20, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.batch = int(batch)
        self.tries = int(tries)

    def next_target(self, q: FloatArray) -> FloatArray | None:
        for _ in range(self.tries):
            cand = self.uniform(self.batch, q)
            ok = np.flatnonzero(self.acceptable(q, cand))
            if ok.size:
                return cand[ok[0]]
        return None


@register
class SweepStrategy(Strategy):
    """Systematic sweep: a grid over the joint box visited in serpentine order.

    ``counts`` gives the number of grid values per joint (default 5); the last joint varies
    fastest, so consecutive targets differ mostly in one joint.  The sweep wraps around.
    """

    name = "sweep"

    def __init__(self, *args: Any, counts: int | Sequence[int] = 5, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        n = self.robot.dof
        counts_arr = np.broadcast_to(np.asarray(counts, dtype=int), (n,))
        if np.any(counts_arr < 1):
            raise InputError(f"sweep counts must be >= 1, got {counts_arr.tolist()}")
        axes = [np.linspace(lo, hi, c) if c > 1 else np.array([0.5 * (lo + hi)])
                for lo, hi, c in zip(self.lower, self.upper, counts_arr, strict=True)]
        self.points = self._serpentine(axes)
        self.index = 0

    @staticmethod
    def _serpentine(axes: list[FloatArray]) -> FloatArray:
        """All grid points, ordered so that consecutive points are grid neighbours."""
        idx = np.array(list(itertools.product(*[range(len(a)) for a in axes])), dtype=int)
        # boustrophedon: reverse a digit whenever the sum of the slower digits is odd
        snake = idx.copy()
        for d in range(1, idx.shape[1]):
            flip = idx[:, :d].sum(axis=1) % 2 == 1
            snake[flip, d] = len(axes[d]) - 1 - idx[flip, d]
        return np.stack([axes[d][snake[:, d]] for d in range(len(axes))], axis=1)

    def next_target(self, q: FloatArray) -> FloatArray | None:
        total = len(self.points)
        chunk = min(total, 64)
        for _ in range(int(np.ceil(total / chunk))):
            order = (self.index + np.arange(chunk)) % total
            ok = np.flatnonzero(self.acceptable(q, self.points[order]))
            if ok.size:
                self.index = int((order[ok[0]] + 1) % total)
                return self.points[order[ok[0]]]
            self.index = int((order[-1] + 1) % total)
        return None


@register
class NoveltyStrategy(Strategy):
    """Prefer unexplored space: among random free candidates, pick the one whose straight
    joint-space path sweeps the most cells of the swept-occupancy grid not yet visited."""

    name = "novelty"

    def observe(self, swept: FloatArray, attempted: FloatArray | None) -> None:
        if attempted is not None and len(attempted):
            self.grid.attempt(attempted)

    def __init__(self, *args: Any, candidates: int = 24, path_samples: int = 6,
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.candidates = int(candidates)
        self.path_samples = int(path_samples)

    def next_target(self, q: FloatArray) -> FloatArray | None:
        cand = self.uniform(self.candidates * 2, q)
        ok = np.flatnonzero(self.acceptable(q, cand))[: self.candidates]
        if ok.size == 0:
            return None
        fr = np.linspace(0.0, 1.0, self.path_samples)[1:, None]
        scores = np.array([self.grid.novelty(q + fr * (c - q)) for c in cand[ok]], dtype=float)
        scores += self.rng.uniform(0.0, 0.5, size=scores.shape)  # seeded tie break
        return cand[ok[int(np.argmax(scores))]]



@register
class FrontierStrategy(NoveltyStrategy):
    """Frontier exploration in the workspace, from the robot's own swept map only.

    Every move is one of:

    * **return home** every ``home_every`` moves (a guarded move back to the start
      configuration: unfolds an arm hooked around an obstacle).  With ``unhook`` the return is
      a sequence of single-joint guarded moves, outermost joint first (each move sets joints
      ``j..n-1`` to their home values): the distal links unwrap before the inner ones swing,
      so an arm folded around a post comes off it instead of dragging along it;
    * **directed** (probability ``directed``): pick a few *frontier* cells of the swept grid
      (neither swept nor already tried, next to a swept cell) and, for each, solve a damped
      least-squares IK step that carries a probe point of the arm (the tip with probability
      ``tip_probe``, else a random inner joint) to ``overshoot`` metres beyond the cell, moving
      the probe at most ``probe_step`` metres; probing inner joints is what produces link
      contacts;
    * **follow** (probability ``follow``, right after a blocked move, at most ``follow_max``
      in a row): aim past the configuration where the arm was just stopped, shifted sideways by
      a random joint-space step of scale ``follow_step`` [rad]; of a few such candidates the one
      whose target tip lies farthest from the tip positions of earlier blocked moves wins.  The
      arm touches the same surface again a little further along it: short moves, many contacts,
      spread along the surface (from the contact history only).  No follow where more than
      ``follow_density`` earlier blocked-tip positions lie within ``follow_radius`` m of the
      last one: a well-touched place sends the arm back to the frontier;
    * **single-joint** (probability ``single_joint``): one joint changed to a uniform value;
    * otherwise a uniform random target, as :class:`NoveltyStrategy`.

    In each family the candidate whose straight joint-space path visits the most unexplored
    cells wins (seeded tie break).  With ``crowd`` > 0 that score loses ``crowd`` per earlier
    blocked-tip position within ``crowd_radius`` m of the candidate's tip path, and the uniform
    fallback is scored the same way: the arm spends fewer moves where it has already been
    stopped many times and more on the surfaces it has touched little (balancing from its own
    contact history; ``crowd`` = 0 keeps the original behaviour and random draws).
    With ``vary_return``, a home-return step whose joint-space path passes within 0.1 rad of
    a configuration where an earlier return step was blocked puts the joints it would leave at
    home to a random posture around it instead (normal, ``vary_scale`` rad): a return blocked
    by the same obstacle at the same place makes the same contact every time (paper_spatial
    seed 0, 180 s: seven of the sphere's eleven contacts are one configuration, the base yaw
    swinging home into it), while another posture passes it or touches it elsewhere.
    With ``probe_links`` > 0, a move stopped by an inner link (the outermost joint that did not
    reach its target is not the last one: the robot's own link identification) is followed,
    with that probability, by a **tip probe** of the place: a point along the stopped link, in
    the stopped configuration, and the direction it was moving there give a line through the
    contact; the arm first puts its tip ``probe_depth`` m behind that point (space the link
    just swept) and then pushes it ``probe_depth`` m beyond (into the obstacle).  A link
    contact constrains a surface only through a tangent line, and link contacts of one joint's
    sweep all lie in one plane (a vertical post touched by link 2 of a yawing arm fits a whole
    family of cylinders); a tip on the same surface pins it.  No probe where the place is
    already well touched (as for follow moves).
    Nothing here reads the environment: frontier cells come from
    the swept map and the blocked moves (``observe``), i.e. the robot's own motion history.
    """

    name = "frontier"

    def __init__(self, *args: Any, home_every: int = 8, directed: float = 0.5,
                 single_joint: float = 0.2, tip_probe: float = 0.6, probe_step: float = 0.3,
                 overshoot: float = 0.05, goals: int = 6, unhook: bool = False,
                 follow: float = 0.0, follow_step: float = 0.25, follow_max: int = 4,
                 follow_radius: float = 0.08, follow_density: int = 5, crowd: float = 0.0,
                 crowd_radius: float = 0.1, vary_return: bool = False,
                 vary_scale: float = 0.4, probe_links: float = 0.0, probe_depth: float = 0.04,
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.probe_links = float(probe_links)
        self.probe_depth = float(probe_depth)
        self._probe: FloatArray | None = None  # second stage of a tip probe, when queued
        self._stopped_link: tuple[FloatArray, FloatArray, int] | None = None
        self.vary_return = bool(vary_return)
        self.vary_scale = float(vary_scale)
        self._returning = False  # the last target was a home-return step
        self._return_blocks: list[FloatArray] = []  # where return steps were blocked
        self.crowd = float(crowd)
        self.crowd_radius = float(crowd_radius)
        self.follow = float(follow)
        self.follow_step = float(follow_step)
        self.follow_max = int(follow_max)
        self.follow_radius = float(follow_radius)
        self.follow_density = int(follow_density)
        self._blocked: FloatArray | None = None  # where the last move was stopped, if it was
        self._streak = 0  # follow moves in a row
        self.home_every = int(home_every)
        self.unhook = bool(unhook)
        self._unhook_joints: list[int] = []  # joints still to put back, outermost first
        self.directed = float(directed)
        self.single_joint = float(single_joint)
        self.tip_probe = float(tip_probe)
        self.probe_step = float(probe_step)
        self.overshoot = float(overshoot)
        self.goals = int(goals)
        self.home: FloatArray | None = None
        self.count = 0
        self.touched: list[FloatArray] = []  # tip positions where moves were blocked
        g = self.grid
        idx = np.indices(g.shape).reshape(g.dim, -1).T
        centres = g.origin + (idx + 0.5) * g.cell
        base = self.robot.base
        self._centres = centres
        self._in_reach = (np.linalg.norm(centres - base, axis=1)
                          <= 0.95 * self.robot.reach).reshape(g.shape)

    def observe(self, swept: FloatArray, attempted: FloatArray | None) -> None:
        super().observe(swept, attempted)
        self._blocked = None if attempted is None or not len(attempted) else attempted[0].copy()
        self._stopped_link = None
        if self._blocked is not None:
            self._probe = None  # a probe's approach was stopped: the probe is over
            short = np.abs(attempted[-1] - attempted[0]) > 1e-6  # joints short of target
            if np.any(short):
                link = int(np.flatnonzero(short).max())
                if link < self.robot.dof - 1:
                    self._stopped_link = (self._blocked, attempted[-1] - attempted[0], link)
        if self._returning and self._blocked is not None:
            self._return_blocks.append(self._blocked)
        if attempted is not None and len(attempted):
            # the arm was blocked at attempted[0]: remember where its tip was, and count the
            # cells around it as tried (most blocks are tip contacts)
            g = self.grid
            tip = self.robot.joint_positions(attempted[0])[-1, : g.dim]
            self.touched.append(tip)
            offs = np.stack(np.meshgrid(*[np.array([-1.0, 0.0, 1.0])] * g.dim,
                                        indexing="ij"), -1).reshape(-1, g.dim)
            g.attempted.flat[g.cells(tip + offs * g.cell)] = True

    # ------------------------------------------------------------------ helpers
    def frontier(self) -> NDArray[np.int64]:
        """Flat indices of the frontier cells (unknown, within reach, next to a swept cell)."""
        g = self.grid
        swept = g.swept
        near = np.zeros_like(swept)
        for ax in range(g.dim):
            for sh in (1, -1):
                near |= np.roll(swept, sh, axis=ax)
        unknown = ~(swept | g.attempted) & self._in_reach
        return np.flatnonzero(near & unknown)

    def _ik(self, q: FloatArray, probe: int, goal: FloatArray, step: float | None = None,
            iterations: int = 8) -> FloatArray:
        """Damped least-squares steps moving point ``probe`` (joint index, ``dof`` = tip) of
        the arm toward ``goal``, at most ``step`` (default ``probe_step``) metres in all."""
        robot, dim = self.robot, self.grid.dim
        step = self.probe_step if step is None else step
        p0 = robot.joint_positions(q)[probe, :dim]
        d = goal - p0
        dist = float(np.linalg.norm(d))
        if dist > step:
            goal = p0 + d * (step / dist)
        x = q.copy()
        for _ in range(iterations):
            pts, axes = robot.joint_positions_and_axes(x)
            p = pts[probe]
            err = goal - p[:dim]
            if np.linalg.norm(err) < 1e-3:
                break
            Jm = np.cross(axes, p - pts[:-1])[:, :dim].T  # (dim, n)
            Jm[:, probe:] = 0.0
            lam = 0.05
            dx = Jm.T @ np.linalg.solve(Jm @ Jm.T + lam**2 * np.eye(dim), err)
            x = np.clip(x + dx, self.lower, self.upper)
        return x

    def _best(self, q: FloatArray, cand: FloatArray) -> FloatArray | None:
        ok = np.flatnonzero(self.acceptable(q, cand))
        if ok.size == 0:
            return None
        fr = np.linspace(0.0, 1.0, self.path_samples)[1:, None]
        scores = np.array([self.grid.novelty(q + fr * (c - q)) for c in cand[ok]], dtype=float)
        if self.crowd > 0.0 and self.touched:
            scores -= self.crowd * self._crowding(q, cand[ok])
        scores += self.rng.uniform(0.0, 0.5, size=scores.shape)
        return cand[ok[int(np.argmax(scores))]]

    def _crowding(self, q: FloatArray, cand: FloatArray) -> FloatArray:
        """Per candidate: how many earlier blocked-tip positions lie within ``crowd_radius`` of
        the tip's path (a polyline through 12 configurations of the straight joint-space move).
        A move whose tip runs through a well-touched place is likely to be stopped there again
        and learn little."""
        dim = self.grid.dim
        fr = np.linspace(0.0, 1.0, 12)[None, :, None]
        paths = q + fr * (cand - q)[:, None, :]  # (C, S, n)
        tips = self.robot.joint_positions(paths.reshape(-1, q.size))[:, -1, :dim]
        tips = tips.reshape(len(cand), -1, dim)
        a, b = tips[:, :-1, None, :], tips[:, 1:, None, :]  # (C, S-1, 1, dim)
        T = np.array(self.touched)[None, None]  # (1, 1, M, dim)
        ab = b - a
        t = np.clip(np.sum((T - a) * ab, axis=-1) / np.maximum(np.sum(ab * ab, axis=-1),
                                                               1e-12), 0.0, 1.0)
        d = np.linalg.norm(a + t[..., None] * ab - T, axis=-1).min(axis=1)  # (C, M)
        return np.count_nonzero(d < self.crowd_radius, axis=1).astype(float)

    def _sparse(self) -> bool:
        """Fewer than ``follow_density`` earlier blocked-tip positions lie within
        ``follow_radius`` of the last one (the place is worth following further)."""
        if not self.touched:
            return True
        T = np.array(self.touched)
        near = np.linalg.norm(T - T[-1], axis=1) < self.follow_radius
        return int(np.count_nonzero(near)) <= self.follow_density

    def _follow(self, q: FloatArray, stop: FloatArray) -> FloatArray | None:
        """A move past the configuration ``stop`` where the arm was just blocked, shifted
        sideways in joint space (see the class docstring)."""
        d = stop - q
        dn = float(np.linalg.norm(d))
        ahead = stop + (0.5 * self.follow_step * d / dn if dn > 1e-9 else 0.0)
        cand = ahead + self.rng.normal(0.0, self.follow_step, size=(self.candidates, q.size))
        cand = np.clip(cand, self.lower, self.upper)
        ok = np.flatnonzero(self.acceptable(q, cand))
        if ok.size == 0:
            return None
        cand = cand[ok]
        if not self.touched:
            return cand[0]
        dim = self.grid.dim
        tips = self.robot.joint_positions(cand)[:, -1, :dim]
        T = np.array(self.touched)
        far = np.min(np.linalg.norm(tips[:, None] - T[None], axis=2), axis=1)
        far += self.rng.uniform(0.0, 0.5 * self.grid.cell, size=far.shape)
        return cand[int(np.argmax(far))]

    def _tip_probe(self, q: FloatArray) -> FloatArray | None:
        """First stage of a tip probe of the place where an inner link was just stopped (see
        the class docstring); queues the second stage."""
        stop, delta, link = self._stopped_link
        dim, robot = self.grid.dim, self.robot
        pts = robot.joint_positions(stop)
        s = self.rng.uniform(0.3, 1.0)
        p = pts[link] + s * (pts[link + 1] - pts[link])
        v = robot.point_velocities(stop, delta, link, s)[:dim]  # the link's motion there
        vn = float(np.linalg.norm(v))
        if vn < 1e-9:
            return None
        d = v / vn
        far = 2.0 * robot.reach
        pre = self._ik(q, robot.dof, p[:dim] - self.probe_depth * d, step=far, iterations=40)
        push = self._ik(pre, robot.dof, p[:dim] + self.probe_depth * d, step=far, iterations=40)
        if not self.acceptable(q, pre[None])[0] or np.linalg.norm(push - pre) < 1e-3:
            return None
        self._probe = push
        return pre

    def _blocked_before(self, q: FloatArray, target: FloatArray, tol: float = 0.1) -> bool:
        """The straight joint-space path ``q`` → ``target`` passes within ``tol`` rad of a
        configuration where an earlier home-return step was blocked."""
        if not self._return_blocks:
            return False
        path = q + np.linspace(0.0, 1.0, 25)[:, None] * (target - q)
        blocks = np.array(self._return_blocks)
        d = np.linalg.norm(path[:, None, :] - blocks[None], axis=2)
        return bool(d.min() < tol)

    # ------------------------------------------------------------------ strategy
    def next_target(self, q: FloatArray) -> FloatArray | None:
        if self.home is None:
            self.home = q.copy()
        self._returning = False
        while self._unhook_joints:
            j = self._unhook_joints.pop(0)
            target = q.copy()
            target[j:] = self.home[j:]  # retry outer joints a blocked step left behind
            if np.max(np.abs(target - q)) >= 1e-3:
                if self.vary_return and self._blocked_before(q, target):
                    target[j + 1:] = np.clip(
                        target[j + 1:] + self.rng.normal(0.0, self.vary_scale,
                                                         target.size - j - 1),
                        self.lower[j + 1:], self.upper[j + 1:])
                self._returning = True
                return target
        self.count += 1
        if (self.home_every > 0 and self.count % self.home_every == 0
                and np.linalg.norm(q - self.home) >= self.min_step):
            if not self.unhook:
                return self.home.copy()
            self._unhook_joints = list(range(self.robot.dof - 1, -1, -1))
            return self.next_target(q)
        if self._probe is not None:
            push, self._probe = self._probe, None
            if self.acceptable(q, push[None], min_step=1e-3)[0]:
                return push
        if (self.probe_links > 0.0 and self._stopped_link is not None and self._sparse()
                and self.rng.random() < self.probe_links):
            pre = self._tip_probe(q)
            if pre is not None:
                return pre
        n = self.robot.dof
        if (self._blocked is not None and self._streak < self.follow_max
                and self._sparse() and self.rng.random() < self.follow):
            self._streak += 1
            best = self._follow(q, self._blocked)
            if best is not None:
                return best
        else:
            self._streak = 0
        r = self.rng.random()
        if r < self.directed:
            front = self.frontier()
            if front.size:
                g = self.grid
                pick = self.rng.choice(front, size=min(self.goals * 8, front.size),
                                       replace=False)
                if self.touched:
                    # prefer goals far from where the arm was already blocked
                    T = np.array(self.touched)
                    far = np.min(np.linalg.norm(self._centres[pick][:, None] - T[None],
                                                axis=2), axis=1)
                    far += self.rng.uniform(0.0, g.cell, size=far.shape)
                    pick = pick[np.argsort(-far)[: self.goals]]
                else:
                    pick = pick[: self.goals]
                cand = []
                for cell in pick:
                    probe = n if self.rng.random() < self.tip_probe else int(
                        self.rng.integers(max(1, n // 2), n))
                    goal = self._centres[cell]
                    p = self.robot.joint_positions(q)[probe, : g.dim]
                    d = goal - p
                    goal = goal + self.overshoot * d / max(float(np.linalg.norm(d)), 1e-9)
                    cand.append(self._ik(q, probe, goal))
                best = self._best(q, np.array(cand))
                if best is not None:
                    return best
        elif r < self.directed + self.single_joint:
            cand = np.repeat(q[None], self.candidates, axis=0)
            joints = self.rng.integers(0, n, size=self.candidates)
            vals = self.uniform(self.candidates, q)
            cand[np.arange(self.candidates), joints] = vals[np.arange(self.candidates), joints]
            best = self._best(q, cand)
            if best is not None:
                return best
        if self.crowd > 0.0:
            best = self._best(q, self.uniform(self.candidates, q))
            if best is not None:
                return best
        return super().next_target(q)
