"""Kinematic simulation of guarded moves under an impedance controller, with ground truth.

Motion model
------------
Each move goes from the current configuration toward a target chosen by the exploration strategy,
along a straight joint-space line with a synchronised trapezoidal velocity law (per-joint speed
and acceleration limits).  The controller is an impedance law ``τ = K (q_cmd − q) − D q̇`` and the
arm has viscous friction ``b``; while a joint moves freely the command leads the joint by
``(D + b)/K · q̇`` so the arm follows the planned law exactly and the commanded torque is the small
friction torque ``b q̇``.

When link ``i`` touches the environment, joints ``0..i`` stop at once (their command keeps going
toward the target, so their torque rises and saturates at the effort limit) while joints beyond
``i`` keep following their plan until their own link touches or they reach the target; a tip
contact stops the whole arm.  After every joint has stopped the arm dwells (``dwell`` seconds,
torques persisting), then retreats back along the path it swept (known free) until every link
clears the environment by ``retreat_clearance`` (or to the move's start), and the strategy picks
the next target.

Contact loads: the joints a move does not command (held in place) are loaded by the contact
force too.  A frictionless contact on link ``k`` pushes along the surface normal with the force
that balances the blocked joints' impedance torques (least squares); each held joint ``i <= k``
resists with minus its moment, and joints beyond ``k`` carry nothing (:func:`_contact_loads`).
Positions stay frozen (a rigid stop), so this adds torque only — what lets the log tell, for a
single-joint move, which of the links moving as one rigid body touched.

Contacts are found exactly (see :mod:`wholearm_tools.sim.collision`): first-contact times, at most
``tolerance`` of penetration, at any speed.

Sensors
-------
Logged at ``rate`` Hz: encoder positions (``counts_per_rev`` quantisation of the true angle plus
Gaussian noise), an encoder-derived velocity estimate (backward difference over
``velocity_window`` samples, so quantisation shows as noise), commanded positions and the
commanded torque computed by the controller from the measured values, clipped to the effort
limits.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools._arrays import read_only
from wholearm_tools.errors import InputError
from wholearm_tools.logs.records import GroundTruth, JointLog, Run
from wholearm_tools.robot.model import RobotModel
from wholearm_tools.sim.collision import Collider, ObstacleLike, surface_dicts
from wholearm_tools.sim.motion import PolylinePath, Trapezoid, synchronised_law
from wholearm_tools.sim.occupancy import SweptGrid, densify
from wholearm_tools.sim.strategies import Strategy, make_strategy

FloatArray = NDArray[np.float64]

#: absolute start time of simulated logs (2024-01-01T00:00:00Z): fixed, so seeds reproduce bytes
SIM_T0_NS = 1_704_067_200_000_000_000

ProgressCallback = Callable[[float, float], None]
"""``progress(simulated_seconds, total_seconds)``."""


@dataclass(frozen=True, slots=True)
class Controller:
    """Impedance controller and motion parameters.

    speed : fraction of each joint's velocity limit used when cruising
    t_acc : time to reach cruise speed [s]
    stiffness : (n,) K [N m/rad]; default ``effort_limit / 0.25``
    damping : D as a multiple of K [s]
    friction : viscous joint friction b as a multiple of K [s]
    dwell : hold time after every joint has stopped [s]
    retreat_clearance : retreat until every link clears the environment by this much [m]
    retreat_fraction : retreat at least this fraction of the move's path
    """

    speed: float = 0.5
    t_acc: float = 0.15
    stiffness: tuple[float, ...] | None = None
    damping: float = 0.02
    friction: float = 0.01
    dwell: float = 0.1
    retreat_clearance: float = 0.02
    retreat_fraction: float = 0.5

    def __post_init__(self) -> None:
        for name in ("speed", "t_acc", "damping", "dwell"):
            if not getattr(self, name) > 0:
                raise InputError(f"controller {name} must be positive, got {getattr(self, name)}")
        if self.speed > 1:
            raise InputError(f"controller speed is a fraction of the velocity limit (<= 1), got "
                             f"{self.speed}")

    def gains(self, robot: RobotModel) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``(K, D, b)`` per joint."""
        if self.stiffness is None:
            K = np.asarray(robot.effort_limits) / 0.25
        else:
            K = np.broadcast_to(np.asarray(self.stiffness, dtype=float), (robot.dof,)).copy()
        return K, self.damping * K, self.friction * K


@dataclass(frozen=True, slots=True)
class Sensors:
    """Encoder model: ``counts_per_rev`` quantisation, Gaussian ``position_noise`` [rad],
    velocity estimated by a backward difference over ``velocity_window`` samples."""

    counts_per_rev: int = 2**17
    position_noise: float = 1e-5
    velocity_window: int = 5

    def __post_init__(self) -> None:
        if self.counts_per_rev < 1 or self.velocity_window < 1 or self.position_noise < 0:
            raise InputError(f"invalid sensor model {self!r}")


@dataclass(frozen=True, slots=True)
class Move:
    """One guarded move: times in seconds on the log clock; ``contacts`` index the truth arrays."""

    t_start: float
    t_stop: float
    t_retreat: float
    t_end: float
    q_start: FloatArray
    q_target: FloatArray
    contacts: tuple[int, ...]


@dataclass(frozen=True, slots=True, eq=False)
class SimResult:
    """A simulated run and what only a simulator knows.

    run : Run (robot, noisy joint log, ground truth) — what ``logs.write_run`` stores
    q_true : (N, n) true joint positions at the log samples
    qd_true : (N, n) true joint velocities at the log samples
    contact_q : (M, n) true configuration at each ground-truth contact
    moves : tuple of Move
    obstacles : the environment
    wall_time : seconds spent simulating
    clearance_evals : number of configurations whose clearance was evaluated
    """

    run: Run
    q_true: FloatArray
    qd_true: FloatArray
    contact_q: FloatArray
    moves: tuple[Move, ...]
    obstacles: tuple[ObstacleLike, ...]
    wall_time: float
    clearance_evals: int
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def truth(self) -> GroundTruth:
        assert self.run.truth is not None
        return self.run.truth

    def contact_counts(self) -> dict[str, int]:
        """Ground-truth contacts by kind."""
        kinds = self.truth.contact_kind.tolist()
        return {k: kinds.count(k) for k in ("tip", "joint", "body")}


@dataclass
class _Contact:
    t: float
    link: int
    kind: str
    point: FloatArray
    surface: int
    s: float
    q: FloatArray
    t_end: float = np.nan  # release: the retreat start
    force: float = np.nan  # peak normal force from the quasi-static balance


class _Recorder:
    """Fills the true-state buffers on the global log grid."""

    def __init__(self, n_samples: int, dof: int, dt: float) -> None:
        self.N = n_samples
        self.dt = dt
        self.q = np.zeros((n_samples, dof))
        self.qd = np.zeros((n_samples, dof))
        self.q_cmd = np.zeros((n_samples, dof))
        #: torque held joints exert against contact forces (see :func:`_contact_loads`)
        self.load = np.zeros((n_samples, dof))
        self.k = 0  # last filled index

    def time(self, k: int) -> float:
        return k * self.dt

    def fill(self, k_end: int, fn: Callable[[FloatArray], tuple[FloatArray, ...]]) -> int:
        """Fill samples ``k+1 .. k_end`` (clipped to the log) from ``fn(times)``; returns the
        new last index."""
        k_end = min(k_end, self.N - 1)
        if k_end > self.k:
            ks = np.arange(self.k + 1, k_end + 1)
            q, qd, q_cmd = fn(ks * self.dt)
            self.q[ks], self.qd[ks], self.q_cmd[ks] = q, qd, q_cmd
            self.k = k_end
        return self.k

    @property
    def full(self) -> bool:
        return self.k >= self.N - 1


def simulate(
    robot: RobotModel,
    obstacles: Sequence[ObstacleLike],
    *,
    strategy: str | Strategy = "random",
    strategy_params: dict[str, Any] | None = None,
    duration: float = 60.0,
    rate: float = 500.0,
    seed: int | np.random.SeedSequence | None = None,
    home: Sequence[float] | None = None,
    controller: Controller | None = None,
    sensors: Sensors | None = None,
    tolerance: float = 1e-6,
    progress: ProgressCallback | None = None,
    meta: dict[str, Any] | None = None,
) -> SimResult:
    """Simulate an exploration run of ``duration`` seconds logged at ``rate`` Hz.

    Parameters
    ----------
    robot : RobotModel
        Link radii must decrease outward (each joint sphere belongs to one link).
    obstacles : sequence of obstacles (``geometry.bounded.Obstacle`` protocol), 2-D for planar
        robots.
    strategy : registered strategy name (see :data:`~wholearm_tools.sim.strategies.STRATEGIES`)
        or a ready :class:`Strategy`.
    strategy_params : keyword parameters for a named strategy.
    seed : seed of every random draw (targets and sensor noise); same seed, same run.
    home : (n,) start configuration (default: middle of the joint limits); must be free.
    tolerance : largest penetration at a contact [m].
    progress : called as ``progress(simulated_s, duration)`` after each move.

    Returns
    -------
    SimResult
    """
    wall0 = time.perf_counter()
    if not (duration > 0 and np.isfinite(duration)):
        raise InputError(f"duration must be positive, got {duration}")
    if not (rate > 0 and np.isfinite(rate)):
        raise InputError(f"rate must be positive, got {rate}")
    controller = controller or Controller()
    sensors = sensors or Sensors()
    n = robot.dof
    collider = Collider(robot, obstacles, tolerance)
    seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    strat_seq, noise_seq = seq.spawn(2)
    grid = SweptGrid(robot)
    if isinstance(strategy, Strategy):
        strat = strategy
    else:
        strat = make_strategy(strategy, robot, collider, grid, rng=np.random.default_rng(
            strat_seq), **(strategy_params or {}))
    q = np.array(0.5 * (robot.lower + robot.upper) if home is None else home, dtype=float)
    q = robot.check_q(q, "home")
    if q.shape != (n,):
        raise InputError(f"expected home of shape ({n},), got {q.shape}")
    if np.any(q < robot.lower) or np.any(q > robot.upper):
        raise InputError(f"home {q.tolist()} is outside the joint limits")
    c0 = collider.min_clearance(q[None])[0]
    if c0 <= 0:
        raise InputError(f"home configuration {q.tolist()} is in collision (clearance {c0:.4g} m)")

    K, D, b = controller.gains(robot)
    lead = (D + b) / K  # command lead per unit velocity [s]
    vmax = controller.speed * np.asarray(robot.velocity_limits)
    amax = vmax / controller.t_acc
    dt = 1.0 / rate
    N = int(np.floor(duration * rate + 1e-9)) + 1
    rec = _Recorder(N, n, dt)
    rec.q[0] = q
    rec.q_cmd[0] = q
    contacts: list[_Contact] = []
    moves: list[Move] = []
    sweep_step = grid.cell / 2
    max_lever = float(collider.lever.max())
    idle = 0

    while not rec.full:
        target = strat.next_target(q)
        if target is None:
            idle += 1
            if idle > 3:
                break  # nothing reachable: hold still for the rest of the run
            continue
        idle = 0
        k0 = rec.k
        t0 = rec.time(k0)
        law = synchronised_law(target - q, vmax, amax)
        result = _guarded_move(collider, q, target, law, dt)
        first = len(contacts)
        for tc, link, info, qc in result.contacts:
            contacts.append(_Contact(t0 + tc, link, info.kind, info.point, info.surface, info.s,
                                     qc))
        delta = target - q
        q_start = q.copy()
        phi = result.freeze

        def move_samples(ts: FloatArray, q_start: FloatArray = q_start, delta: FloatArray = delta,
                         law: Trapezoid = law, phi: FloatArray = phi, t0: float = t0,
                         ) -> tuple[FloatArray, FloatArray, FloatArray]:
            tau = ts - t0
            s_free, sd_free = law(tau)
            s_act, _ = law(np.minimum(tau[:, None], phi[None, :]))
            q_act = q_start + s_act * delta
            moving = tau[:, None] < phi[None, :]
            qd_act = np.where(moving, sd_free[:, None] * delta, 0.0)
            q_cmd = q_start + s_free[:, None] * delta + lead * sd_free[:, None] * delta
            return q_act, qd_act, q_cmd

        t_stop = t0 + result.end_time
        has_contact = bool(result.contacts)
        hold = controller.dwell if has_contact else 0.0
        k_hold = int(np.ceil((t_stop + hold) / dt - 1e-9))
        rec.fill(k_hold, move_samples)
        if has_contact:
            forces = _contact_loads(rec, robot, K, result, delta, t0, k_hold)
            for c, f in zip(contacts[first:], forces, strict=True):
                c.t_end, c.force = rec.time(k_hold), f
        if not has_contact:
            q_end = result.vertices[-1]
            swept = densify(result.vertices, sweep_step, max_lever)
            grid.mark(swept)
            strat.observe(swept, None)
            moves.append(Move(t0, t_stop, t_stop, rec.time(k_hold), q_start, target, ()))
            q = q_end
        else:
            # retreat back along the swept polyline to a configuration with clearance
            swept = densify(result.vertices, sweep_step, max_lever)
            grid.mark(swept)
            strat.observe(swept, densify(np.stack([result.vertices[-1], target]), sweep_step,
                                         max_lever))
            back = _retreat_vertices(collider, result.vertices, controller)
            path = PolylinePath.build(back, vmax, controller.t_acc)
            t_r0 = rec.time(k_hold)

            def retreat_samples(ts: FloatArray, path: PolylinePath = path, t_r0: float = t_r0,
                                ) -> tuple[FloatArray, FloatArray, FloatArray]:
                qr, qdr = path.sample(ts - t_r0)
                return qr, qdr, qr + lead * qdr

            k_end = int(np.ceil((t_r0 + path.duration) / dt - 1e-9))
            rec.fill(k_end, retreat_samples)
            moves.append(Move(t0, t_stop, t_r0, rec.time(k_end), q_start, target,
                              tuple(range(first, len(contacts)))))
            q = back[-1]
        if progress is not None:
            progress(min(rec.time(rec.k), duration), duration)

    if not rec.full:  # strategy gave up: hold still
        last = rec.q[rec.k].copy()
        rec.fill(N - 1, lambda ts: (np.broadcast_to(last, (len(ts), n)),
                                     np.zeros((len(ts), n)),
                                     np.broadcast_to(last, (len(ts), n))))
    t_log_end = rec.time(N - 1)
    contacts = [c for c in contacts if c.t <= t_log_end]

    log = _sense(robot, rec, sensors, K, D, np.random.default_rng(noise_seq))
    truth = GroundTruth(
        surfaces=surface_dicts(collider),
        contact_t=np.array([c.t for c in contacts], dtype=float),
        contact_link=np.array([c.link for c in contacts], dtype=np.int64),
        contact_kind=np.array([c.kind for c in contacts], dtype=np.str_),
        contact_point=np.array([c.point for c in contacts], dtype=float).reshape(-1, 3),
        contact_surface=np.array([c.surface for c in contacts], dtype=np.int64),
        contact_s=np.array([c.s for c in contacts], dtype=float),
        contact_t_end=np.array([c.t_end for c in contacts], dtype=float),
        contact_force=np.array([c.force for c in contacts], dtype=float),
        contact_q=np.array([c.q for c in contacts], dtype=float).reshape(-1, n),
        contact_stopped=np.ones(len(contacts), dtype=bool),
        meta={"simulator": "wholearm_tools.sim", "engine": "kinematic", "strategy": strat.name,
              "seed": None if isinstance(seed, np.random.SeedSequence) else seed,
              "rate": rate, "duration": duration, "tolerance": tolerance,
              "stiffness": K.tolist(), "damping": D.tolist(), **(meta or {})},
    )
    run = Run(robot=robot, log=log, truth=truth, source=str((meta or {}).get("scenario",
                                                                              "<simulated>")))
    if progress is not None:
        progress(duration, duration)
    wall = time.perf_counter() - wall0
    return SimResult(
        run=run, q_true=read_only(rec.q), qd_true=read_only(rec.qd),
        contact_q=read_only(np.reshape([c.q for c in contacts], (-1, n))),
        moves=tuple(moves), obstacles=collider.obstacles, wall_time=wall,
        clearance_evals=collider.n_evals,
        stats={"moves": len(moves), "swept_fraction": grid.fraction_swept},
    )


@dataclass
class _MoveResult:
    freeze: FloatArray  # (n,) freeze time of each joint (inf: never), relative to the move start
    end_time: float  # when every joint has stopped
    vertices: FloatArray  # (K, n) executed joint-space polyline
    contacts: list[tuple[float, int, Any, FloatArray]]


def _guarded_move(collider: Collider, q0: FloatArray, q1: FloatArray, law: Trapezoid,
                  dt: float) -> _MoveResult:
    """Execute one guarded move (times relative to its start)."""
    n = q0.shape[0]
    delta = q1 - q0
    T = law.duration
    phi = np.full(n, np.inf)

    def path(ts: FloatArray) -> FloatArray:
        s, _ = law(np.minimum(np.asarray(ts)[:, None], phi[None, :]))
        return q0 + s * delta

    grid = np.arange(int(np.ceil(T / dt - 1e-9)) + 1) * dt
    contacts: list[tuple[float, int, Any, FloatArray]] = []
    start = 0.0
    frozen = -1
    end_time = T
    while frozen < n - 1:
        nodes = np.concatenate([[start], grid[grid > start + 1e-12]])
        if len(nodes) < 2 or start >= T:
            break
        links = np.arange(frozen + 1, n)
        hit = collider.first_contact(path, nodes, links)
        if hit is None:
            break
        tc, qc, touching = hit
        for link in touching:
            contacts.append((tc, int(link), collider.contact_info(qc, int(link)), qc.copy()))
        frozen = int(touching.max())
        phi[: frozen + 1] = np.minimum(phi[: frozen + 1], tc)
        start = tc
        if frozen == n - 1:
            end_time = tc
    events = np.unique(phi[np.isfinite(phi)])
    times = np.concatenate([[0.0], events[events < end_time], [end_time]])
    return _MoveResult(freeze=phi, end_time=float(end_time), vertices=path(times),
                       contacts=contacts)


def _contact_loads(rec: _Recorder, robot: RobotModel, K: FloatArray, result: _MoveResult,
                   delta: FloatArray, t0: float, k_last: int) -> list[float]:
    """Normal force of each contact of a move, and the torques of the *held* joints (not
    commanded to move) against it.

    A frictionless contact on link ``k`` at surface point ``p`` with unit normal ``nu``
    (surface → robot) pushes with ``F = f nu``; its moment about joint ``i <= k`` is
    ``f g_i`` with ``g_i = (a_i x (p - o_i)) . nu`` (joints beyond ``k`` carry none).  The
    joints the contact blocked while they moved press with their impedance torque
    ``K (q_cmd - q)``; quasi-static balance gives ``f = max(0, -sum_b tau_b g_b / sum_b g_b^2)``
    (least squares over the blocked joints), and every held joint ``i <= k`` resists with
    ``-f g_i`` — the torque a real controller shows when a joint it holds in place is loaded.
    Positions stay frozen (the kinematic model's rigid stop), so this adds torque only.
    Written into ``rec.load`` from the contact sample to ``k_last`` (the end of the dwell).

    Returns the peak ``f`` of each contact of ``result.contacts`` [N] over that span, NaN where
    no blocked joint has a moment about it (the balance does not determine the force).
    """
    n = robot.dof
    moving = np.abs(delta) > 1e-12
    joints = np.arange(n)
    peaks: list[float] = []
    for tc, link, info, qc in result.contacts:
        k0 = int(np.ceil((t0 + tc) / rec.dt - 1e-9))
        k1 = min(k_last, rec.k)
        held = ~moving & (joints <= link)
        blocked = moving & (joints <= link) & (np.abs(result.freeze - tc) <= 1e-12)
        peaks.append(np.nan)
        if k0 > k1 or not blocked.any():
            continue
        pts, axes = robot.joint_positions_and_axes(qc)
        g = np.cross(axes, info.point - pts[:n]) @ info.normal
        g[joints > link] = 0.0
        gb = g[blocked]
        if float(gb @ gb) <= 1e-18:
            continue
        ks = np.arange(k0, k1 + 1)
        tau_b = K[blocked] * (rec.q_cmd[ks][:, blocked] - rec.q[ks][:, blocked])
        f = np.maximum(-(tau_b @ gb) / float(gb @ gb), 0.0)
        peaks[-1] = float(f.max())
        if held.any():
            rec.load[np.ix_(ks, np.flatnonzero(held))] -= f[:, None] * g[held][None, :]
    return peaks


def _retreat_vertices(collider: Collider, vertices: FloatArray, ctrl: Controller) -> FloatArray:
    """Reversed executed polyline from its end back to the retreat point."""
    rev = vertices[::-1]
    seg = np.linalg.norm(np.diff(rev, axis=0), axis=1)
    total = float(seg.sum())
    if total <= 0:
        return rev[:1]
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    fr = np.linspace(ctrl.retreat_fraction, 1.0, 17)
    pts = np.array([_along(rev, cum, f * total) for f in fr])
    ok = np.flatnonzero(collider.min_clearance(pts) >= ctrl.retreat_clearance)
    f_stop = fr[ok[0]] if ok.size else 1.0
    dist = f_stop * total
    i = int(np.searchsorted(cum, dist, side="right"))
    return np.vstack([rev[:i], _along(rev, cum, dist)[None]])


def _along(vertices: FloatArray, cum: FloatArray, dist: float) -> FloatArray:
    i = int(np.clip(np.searchsorted(cum, dist, side="right") - 1, 0, len(cum) - 2))
    seg = cum[i + 1] - cum[i]
    f = 0.0 if seg <= 0 else min(1.0, (dist - cum[i]) / seg)
    return vertices[i] + f * (vertices[i + 1] - vertices[i])


def _sense(robot: RobotModel, rec: _Recorder, sensors: Sensors, K: FloatArray, D: FloatArray,
           rng: np.random.Generator) -> JointLog:
    """Encoder readings, velocity estimate and commanded torques from the true state."""
    quantum = 2.0 * np.pi / sensors.counts_per_rev
    noisy = rec.q + rng.normal(0.0, sensors.position_noise, size=rec.q.shape)
    q_meas = np.round(noisy / quantum) * quantum
    w = sensors.velocity_window
    qd_meas = np.zeros_like(q_meas)
    N = q_meas.shape[0]
    if N > 1:
        ks = np.arange(1, N)
        back = np.maximum(ks - w, 0)
        qd_meas[1:] = (q_meas[ks] - q_meas[back]) / ((ks - back) * rec.dt)[:, None]
    eff = np.asarray(robot.effort_limits)
    tau = np.clip(K * (rec.q_cmd - q_meas) - D * qd_meas + rec.load, -eff, eff)
    t = np.arange(N) * rec.dt
    return JointLog(joint_names=robot.joint_names, t=t, q=q_meas, qd=qd_meas, tau_cmd=tau,
                    q_cmd=rec.q_cmd.copy(), t0_ns=SIM_T0_NS)
