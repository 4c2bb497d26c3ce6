"""Physics simulation of exploration runs on MuJoCo: what a real rig does and the kinematic
engine idealises away.

Plant
-----
The robot and its environment come from :mod:`wholearm_tools.sim.mjcf` (MJCF built from the
``RobotModel`` and the obstacles).  Contacts are soft (MuJoCo ``solref``: a time constant and a
damping ratio below one let a contact rebound) and have Coulomb friction, so a tip slides along
a surface it meets obliquely.  Joints have Coulomb friction (``frictionloss``), viscous friction
and reflected rotor inertia; motors are limited to the effort limits.  Gravity is off by default.

Controller
----------
A joint PD law on *measured* positions (the encoder model of the kinematic engine, read at every
physics step) with an encoder-derived velocity estimate (backward difference over
``velocity_time``, 10 ms: the drive's loop does not slow down when the log does)::

    tau = clip(K (q_ref - q_m) + D (qd_ref - qd_m) + g(q_m), -effort, effort)

with the kinematic engine's gains (``Controller.gains``) and, when gravity is on, the gravity
torque ``g`` of the controller's own model at the measured configuration.  The reference
``q_ref`` follows the planned motion but never leads the measured position by more than
``lead`` times the position error that saturates the joint (``effort / K``): a blocked joint
pushes with at most its effort limit, and when it is released the arm does not whip toward a
reference far ahead.  The log's ``/joint_commands`` carry that reference and the clipped torque.

Guarded moves
-------------
As in the kinematic engine, a strategy picks a target and the reference moves toward it along
the straight joint-space line at the planned joint speeds.  The move ends when the supervisor
sees the arm at rest (every measured joint speed below ``rest_speed`` for ``settle_time``) and
either the plan is complete or a joint's reference is held at its lead limit (the arm pushes
against something).  Nothing in this decision reads the engine's contact list.  The move
*reached* its target when every joint is within ``reach_tolerance`` of it; otherwise it was
blocked: the arm dwells (``Controller.dwell``) still pushing, then retreats back along the path
it swept (measured positions) as the kinematic engine does, and waits until it is at rest.

Ground truth
------------
Every physics step lists the engine's contacts between a robot geom and an environment geom and
groups them by (link, surface): the deepest point gives the contact point on the surface and the
fraction ``s`` along the link (a point on a link's outer round end is a ``joint`` contact, the
tip's a ``tip`` contact), the normal forces add up.  A contact *event* runs from first touch
until the pair has been apart for ``release_time``; within it, opening wider than
:data:`REBOUND_GAP` and touching again is a rebound (environment geoms list pairs within a
millimetre as inactive contacts, so the gap is known).  An event that is in contact when a
blocked move comes to rest *stopped the arm*: its settled point, kind and configuration are
taken there; a graze keeps those of its last touch.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools._arrays import read_only
from wholearm_tools.errors import InputError
from wholearm_tools.logs.records import GroundTruth, JointLog, Run
from wholearm_tools.robot.model import PLAY_TORQUE, RobotModel
from wholearm_tools.sim.collision import Collider, ObstacleLike, surface_dicts
from wholearm_tools.sim.motion import PolylinePath, synchronised_law
from wholearm_tools.sim.occupancy import SweptGrid, densify
from wholearm_tools.sim.simulator import (
    SIM_T0_NS,
    Controller,
    Move,
    ProgressCallback,
    Sensors,
    SimResult,
    _retreat_vertices,
)
from wholearm_tools.sim.strategies import Strategy, make_strategy

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

ENGINES = ("kinematic", "physics")
"""Simulation engines ``wholearm simulate --engine`` accepts."""

KEY_STRIDE = 1 << 20  # contact pair key = link * KEY_STRIDE + surface id

REBOUND_GAP = 5e-4
"""A contact that opens wider than this [m] and closes again within its event rebounded (the
soft contact's own flutter about zero penetration does not count)."""


@dataclass(frozen=True, slots=True)
class Physics:
    """Physical parameters of the physics engine (defaults: a small electric arm with geared
    joints touching rigid, dry surfaces; see ``docs/simulator.md``).

    friction : Coulomb friction coefficient arm–environment (dry metal/plastic on steel or rock)
    joint_friction : Coulomb joint friction as a fraction of each joint's effort limit
    gravity : gravity along -z; the controller then compensates it from its model
    contact_timeconst : soft-contact time constant [s] (stiffness; MuJoCo ``solref[0]``)
    contact_dampratio : soft-contact damping ratio (< 1: contacts rebound)
    rate : smallest physics rate [Hz]; the step is the log period divided by a whole number
    velocity_time : the drive's velocity estimate, a backward difference of its encoder reads
        over this time [s]: the control loop runs at the physics rate whatever the log rate
    density : mass density of the links [kg/m³] (thin-walled aluminium tube with its drives)
    armature : reflected rotor inertia per N m of effort limit [kg m² / (N m)]
    lead : largest lead of the reference over the measured position, as a fraction of the
        position error that saturates the joint (``effort / K``)
    settle_time : how long every joint must be at rest for a move to end [s]
    rest_speed : joint speed below which a joint is at rest, as a fraction of its cruise speed
    release_time : separation that ends a contact event [s] (shorter ones are rebounds)
    max_deviation : largest deviation of a tiled concave wall from the ideal surface [m]
    joint_compliance : deflection of each joint's transmission at its effort limit [rad]: the
        encoders sit on the motor side and read the link's position plus the deflection under
        the torque the drive applies (quasi-static: the torque last commanded); harmonic
        drives deflect 0.5-2 mrad at their rated torque, 0 is a rigid transmission
    joint_backlash : lost motion of each joint's transmission [rad]: the encoders sit on the
        motor side, whose play the drive holds closed on the side it pushes once its torque
        exceeds ``robot.model.PLAY_TORQUE`` of the effort limit; they read the link's position
        plus or minus half the play (quasi-static: the motor crosses the gap within a step).
        Spur and planetary gearboxes have 0.3-4 mrad, harmonic drives about none
    log_jitter : a rig's logger does not tick exactly: each interval between log samples is the
        log period times ``1 + e``, ``e`` Gaussian with this standard deviation, and a sample
        is taken at the physics step nearest its time and stamped with it (the state stamps
        of a real 50 Hz rig vary by about 5 % of the period)
    log_drop : share of log samples lost (not written), each independently (a real rig's
        logger loses about 0.7 %)
    """

    friction: float = 0.4
    joint_friction: float = 0.02
    gravity: bool = False
    contact_timeconst: float = 0.005
    contact_dampratio: float = 0.7
    rate: float = 1000.0
    velocity_time: float = 0.01
    density: float = 1000.0
    armature: float = 0.002
    lead: float = 1.0
    settle_time: float = 0.05
    rest_speed: float = 0.02
    release_time: float = 0.1
    max_deviation: float = 3e-4
    joint_compliance: float = 0.0
    joint_backlash: float = 0.0
    log_jitter: float = 0.0
    log_drop: float = 0.0

    def __post_init__(self) -> None:
        positive = ("contact_timeconst", "contact_dampratio", "rate", "velocity_time", "density",
                    "lead", "settle_time", "rest_speed", "release_time", "max_deviation")
        for name in positive:
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise InputError(f"physics {name} must be positive, got {value}")
        for name in ("friction", "joint_friction", "armature", "joint_compliance",
                     "joint_backlash"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise InputError(f"physics {name} must be >= 0, got {value}")
        if self.joint_friction >= 1:
            raise InputError(f"physics joint_friction is a fraction of the effort limit (< 1), "
                             f"got {self.joint_friction}")
        for name, what in (("log_jitter", "a fraction of the log period"),
                           ("log_drop", "a share of the samples")):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0 <= value <= 0.5):
                raise InputError(f"physics {name} is {what} in [0, 0.5], got {value}")

    def replace(self, **changes: Any) -> Physics:
        """A copy with ``changes`` (None values are ignored)."""
        values = asdict(self)
        values.update({k: v for k, v in changes.items() if v is not None})
        return Physics(**values)


@dataclass
class _Event:
    """One contact event between a link and a surface (see the module docstring)."""

    link: int
    surface: int
    t_start: float
    t_last: float
    point_first: FloatArray
    point: FloatArray
    kind: str
    s: float
    q: FloatArray
    force: float
    rebounds: int = 0
    path: float = 0.0  # distance the contact point travelled
    max_shift: float = 0.0  # farthest the contact point got from where it first touched
    depth: float = 0.0  # deepest penetration of the soft contact
    apart: bool = False
    stopped: bool = False
    settled: tuple[FloatArray, str, float, FloatArray] | None = None


@dataclass
class _Log:
    """Log-rate buffers."""

    q_meas: FloatArray
    q_ref: FloatArray
    tau: FloatArray
    q_true: FloatArray
    qd_true: FloatArray
    k: int = 0

    @property
    def full(self) -> bool:
        return self.k >= self.q_meas.shape[0]


class _Rig:
    """The simulated arm: MuJoCo plant, encoders, PD controller, contact bookkeeping."""

    def __init__(self, robot: RobotModel, obstacles: Sequence[ObstacleLike], physics: Physics,
                 controller: Controller, sensors: Sensors, rate: float, n_samples: int,
                 home: FloatArray, rng: np.random.Generator,
                 clock_rng: np.random.Generator) -> None:
        import mujoco

        from wholearm_tools.sim.mjcf import SceneOptions, build_scene

        self.mujoco = mujoco
        self.robot = robot
        n = robot.dof
        self.n = n
        self.K, self.D, b = controller.gains(robot)
        self.effort = np.asarray(robot.effort_limits, dtype=float)
        self.substeps = max(1, int(np.ceil(physics.rate / rate - 1e-9)))
        self.dt = 1.0 / (rate * self.substeps)
        options = SceneOptions(
            timestep=self.dt, gravity=physics.gravity, friction=physics.friction,
            solref=(physics.contact_timeconst, physics.contact_dampratio),
            density=physics.density, armature=tuple(physics.armature * self.effort),
            frictionloss=tuple(physics.joint_friction * self.effort), damping=tuple(b),
            max_deviation=physics.max_deviation)
        if physics.contact_timeconst < 2 * self.dt:
            raise InputError(f"physics contact_timeconst {physics.contact_timeconst} s must be at "
                             f"least two physics steps ({2 * self.dt:.4g} s): raise the rate")
        self.scene = build_scene(robot, obstacles, options)
        self.model = mujoco.MjModel.from_xml_string(self.scene.xml)
        self.data = mujoco.MjData(self.model)
        self.data.qpos[:] = home
        mujoco.mj_forward(self.model, self.data)
        self.gravity = physics.gravity
        if physics.gravity:
            self._ctrl_data = mujoco.MjData(self.model)
        self.lead = physics.lead * self.effort / self.K
        # geom id -> link (robot) and surface id (environment), -1 where not
        m = self.model
        self.geom_link = np.full(m.ngeom, -1, dtype=np.int64)
        self.geom_surface = np.full(m.ngeom, -1, dtype=np.int64)
        for i, name in enumerate(self.scene.link_geoms):
            self.geom_link[m.geom(name).id] = i
        self.tip_geom = -1 if self.scene.tip_geom is None else m.geom(self.scene.tip_geom).id
        if self.tip_geom >= 0:
            self.geom_link[self.tip_geom] = n - 1
        for name, sid in self.scene.env_geoms.items():
            self.geom_surface[m.geom(name).id] = sid
        self.body_ids = np.array([m.body(f"link{i}").id for i in range(n)])
        self._geom_link = self.geom_link.tolist()
        self._geom_surface = self.geom_surface.tolist()
        self.planar = robot.planar
        self.tip_site = m.site("tip").id
        # encoders
        self.quantum = 2.0 * np.pi / sensors.counts_per_rev
        self.noise_sd = sensors.position_noise
        self.rng = rng
        self._noise = np.zeros((0, n))
        self._noise_i = 0
        self.window = max(1, round(physics.velocity_time / self.dt))
        self._per_count = 1.0 / self.quantum
        self._compliance = (physics.joint_compliance / self.effort
                            if physics.joint_compliance > 0 else None)
        self._tau = np.zeros(n)  # torque the drives apply (the transmission's deflection)
        self._half_play = 0.5 * physics.joint_backlash if physics.joint_backlash > 0 else None
        self._play_band = PLAY_TORQUE * self.effort
        self._side = np.zeros(n)  # side of its play each drive holds closed (+1, -1, 0)
        self._per_window = 1.0 / (self.window * self.dt)
        self._hist_len = self.window + 1
        self._neg_effort = -self.effort
        self.log_steps = _log_schedule(n_samples, self.substeps, physics, clock_rng)
        self._steps = self.log_steps.tolist()
        n_samples = len(self._steps)
        self._next_log = self._steps[0]
        self._mj_step = mujoco.mj_step
        self._hist = np.repeat(self._measure()[None], self.window + 1, axis=0)
        self._hist_i = 0
        self.q_m = self._hist[0].copy()
        self.q_ref = np.array(home, dtype=float)  # last reference sent
        self.qd_m = np.zeros(n)
        self.step_i = 0
        self.rest = np.zeros(n)  # joint speeds below which the supervisor sees a joint at rest
        self.release_time = physics.release_time
        self.events: list[_Event] = []
        self.active: dict[int, _Event] = {}  # by pair key (see KEY_STRIDE)
        self.log = _Log(np.zeros((n_samples, n)), np.zeros((n_samples, n)),
                        np.zeros((n_samples, n)), np.zeros((n_samples, n)),
                        np.zeros((n_samples, n)))

    # ------------------------------------------------------------------ sensing and control
    @property
    def t(self) -> float:
        return self.step_i * self.dt

    def _measure(self) -> FloatArray:
        """Encoder reading of the joint positions (on the motor side: the link's plus the
        transmission's deflection under the drive's torque): Gaussian noise, then
        quantisation."""
        if self._noise_i >= self._noise.shape[0]:
            self._noise = self.rng.normal(0.0, self.noise_sd, size=(4096, self.n))
            self._noise_i = 0
        noisy = self.data.qpos + self._noise[self._noise_i]
        if self._compliance is not None:
            noisy = noisy + self._compliance * self._tau
        if self._half_play is not None:
            noisy = noisy + self._half_play * self._side
        self._noise_i += 1
        return np.round(noisy * self._per_count) * self.quantum

    def step(self, q_plan: FloatArray, qd_plan: FloatArray) -> bool:
        """One control period and physics step toward the planned ``q_plan``, ``qd_plan``;
        returns whether the reference was held at its lead limit on some joint.  (Written
        with few numpy calls: it runs at every physics step.)"""
        q_m = self._measure()
        h = self._hist_i = (self._hist_i + 1) % self._hist_len
        self._hist[h] = q_m
        qd_m = (q_m - self._hist[(h + 1) % self._hist_len]) * self._per_window
        self.q_m, self.qd_m = q_m, qd_m
        err = q_plan - q_m
        held = bool((np.abs(err) > self.lead).any())
        if held:
            over = np.abs(err) > self.lead
            err = np.minimum(np.maximum(err, -self.lead), self.lead)
            qd_plan = np.where(over, 0.0, qd_plan)
        q_ref = q_m + err if held else q_plan
        tau = self.K * err + self.D * (qd_plan - qd_m)
        if self.gravity:
            tau += self._gravity_torque(q_m)
        tau = np.minimum(np.maximum(tau, self._neg_effort), self.effort)
        self.q_ref = q_ref
        if self.step_i == self._next_log:
            lg, k = self.log, self.log.k
            lg.q_meas[k], lg.q_ref[k], lg.tau[k] = q_m, q_ref, tau
            lg.q_true[k], lg.qd_true[k] = self.data.qpos, self.data.qvel
            lg.k += 1
            self._next_log = self._steps[lg.k] if lg.k < len(self._steps) else -1
        self.data.ctrl[:] = tau
        self._tau = tau
        if self._half_play is not None:
            band = self._play_band
            self._side = np.where(tau > band, 1.0, np.where(tau < -band, -1.0, self._side))
        self._mj_step(self.model, self.data)
        self.step_i += 1
        self._contacts()
        return held

    def _gravity_torque(self, q: FloatArray) -> FloatArray:
        """Gravity torque of the controller's model at ``q`` (zero velocity)."""
        mujoco, d = self.mujoco, self._ctrl_data
        d.qpos[:] = q
        d.qvel[:] = 0.0
        mujoco.mj_forward(self.model, d)
        return np.array(d.qfrc_bias)

    @property
    def at_rest(self) -> bool:
        return bool((np.abs(self.qd_m) < self.rest).all())

    # ------------------------------------------------------------------ ground truth
    def _contacts(self) -> None:
        """Contact events from this step's contact list (plain Python: a handful of contacts
        per step, where numpy's per-call cost would dominate)."""
        d = self.data
        ncon = d.ncon
        if not ncon and not self.active:
            return
        t = self.t
        # key -> (distance, contact index, robot geom, robot is geom1) of its deepest point
        deepest: dict[int, tuple[float, int, int, bool]] = {}
        force: dict[int, float] = {}
        if ncon:
            con = d.contact
            gl, gs = self._geom_link, self._geom_surface
            g1, g2 = con.geom1.tolist(), con.geom2.tolist()
            dist = con.dist.tolist()
            pos = None
            for c in range(ncon):
                a, b = g1[c], g2[c]
                if gl[a] >= 0 and gs[b] >= 0:
                    geom, surf, rf = a, gs[b], True
                elif gl[b] >= 0 and gs[a] >= 0:
                    geom, surf, rf = b, gs[a], False
                else:
                    continue
                if pos is None:
                    pos = con.pos.tolist()
                    pts = self._joint_points()
                link, _, _ = self._where(geom, pos[c], pts)
                key = link * KEY_STRIDE + surf
                dc = dist[c]
                prev = deepest.get(key)
                if prev is None or dc < prev[0]:
                    deepest[key] = (dc, c, geom, rf)
                if dc < 0.0:
                    adr = int(con.efc_address[c])
                    force[key] = force.get(key, 0.0) + (float(d.efc_force[adr]) if adr >= 0
                                                        else 0.0)
        for key, (dc, c, geom, rf) in deepest.items():
            ev = self.active.get(key)
            if dc >= 0.0:
                if ev is not None and dc > REBOUND_GAP:
                    ev.apart = True
                continue
            # the contact position is midway between the surfaces; the normal points from
            # geom1 to geom2
            half = (0.5 if rf else -0.5) * dc
            p = np.array(pos[c]) + half * con.frame[c, :3]
            if self.planar:
                p[2] = 0.0
            _, kind, s = self._where(geom, pos[c], pts)
            f = force.get(key, 0.0)
            if ev is None:
                ev = _Event(key // KEY_STRIDE, key % KEY_STRIDE, t, t, p, p, kind, s,
                            d.qpos.copy(), f, depth=-dc)
                self.active[key] = ev
                self.events.append(ev)
                continue
            if ev.apart:
                ev.rebounds += 1
                ev.apart = False
            step = p - ev.point
            ev.path += float(np.sqrt(step @ step))
            shift = p - ev.point_first
            ev.max_shift = max(ev.max_shift, float(np.sqrt(shift @ shift)))
            ev.t_last, ev.point, ev.kind, ev.s = t, p, kind, s
            ev.q = d.qpos.copy()
            ev.force = max(ev.force, f)
            ev.depth = max(ev.depth, -dc)
        for key in [k for k, ev in self.active.items() if ev.t_last < t]:
            ev = self.active[key]
            if key not in deepest:
                ev.apart = True  # farther apart than the contact list's margin
            if t - ev.t_last > self.release_time:
                del self.active[key]

    def _joint_points(self) -> list[list[float]]:
        """Joint origins and the tip point, as lists."""
        d = self.data
        return [*d.xpos[self.body_ids].tolist(), d.site_xpos[self.tip_site].tolist()]

    def _where(self, geom: int, pos: list[float], pts: list[list[float]]
               ) -> tuple[int, str, float]:
        """Link, kind and fraction along the link of a robot contact on ``geom`` at ``pos``:
        a point beyond the outer end of a link is on its joint sphere (the tip for the last
        link); a point before the inner end of link ``i > 0`` lies inside the larger joint
        sphere of link ``i - 1``."""
        link = self._geom_link[geom]
        if geom == self.tip_geom:
            return link, "tip", 1.0
        a, b = pts[link], pts[link + 1]
        ab = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
        L2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2]
        if L2 <= 0.0:
            s = 1.0
        else:
            s = ((pos[0] - a[0]) * ab[0] + (pos[1] - a[1]) * ab[1]
                 + (pos[2] - a[2]) * ab[2]) / L2
        if s >= 1.0:
            return link, ("tip" if link == self.n - 1 else "joint"), 1.0
        if s <= 0.0 and link > 0:
            return link - 1, "joint", 1.0
        return link, "body", max(s, 0.0)

    def mark_stopped(self) -> list[_Event]:
        """Events in contact now: they stopped the arm here (settled point and configuration)."""
        out = []
        for ev in self.active.values():
            if ev.t_last == self.t:
                ev.stopped = True
                ev.settled = (ev.point.copy(), ev.kind, ev.s, self.data.qpos.copy())
                out.append(ev)
        return out


def simulate_physics(
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
    physics: Physics | None = None,
    progress: ProgressCallback | None = None,
    meta: dict[str, Any] | None = None,
) -> SimResult:
    """Simulate an exploration run on MuJoCo (see the module docstring); the arguments are
    those of :func:`wholearm_tools.sim.simulator.simulate` plus ``physics``.

    Returns
    -------
    SimResult
        ``run`` in the kinematic engine's log profile, ground truth one row per contact event;
        ``stats`` adds ``events`` (per event: ``rebounds``, ``slide`` = farthest the contact
        point got from where it first touched [m], ``path`` = distance it travelled [m],
        ``depth`` = deepest penetration of the soft contact [m]) and the
        scene (``tiles``, ``deviation`` per surface, ``mjcf`` text).
    """
    wall0 = time.perf_counter()
    if not (duration > 0 and np.isfinite(duration)):
        raise InputError(f"duration must be positive, got {duration}")
    if not (rate > 0 and np.isfinite(rate)):
        raise InputError(f"rate must be positive, got {rate}")
    controller = controller or Controller()
    sensors = sensors or Sensors()
    physics = physics or Physics()
    n = robot.dof
    collider = Collider(robot, obstacles)
    seq = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    strat_seq, noise_seq = seq.spawn(2)
    clock_seq = seq.spawn(1)[0]
    grid = SweptGrid(robot)
    if isinstance(strategy, Strategy):
        strat = strategy
    else:
        strat = make_strategy(strategy, robot, collider, grid, rng=np.random.default_rng(
            strat_seq), **(strategy_params or {}))
    q_home = robot.check_q(np.array(0.5 * (robot.lower + robot.upper) if home is None else home,
                                    dtype=float), "home")
    if q_home.shape != (n,):
        raise InputError(f"expected home of shape ({n},), got {q_home.shape}")
    if np.any(q_home < robot.lower) or np.any(q_home > robot.upper):
        raise InputError(f"home {q_home.tolist()} is outside the joint limits")
    c0 = collider.min_clearance(q_home[None])[0]
    if c0 <= 0:
        raise InputError(f"home configuration {q_home.tolist()} is in collision "
                         f"(clearance {c0:.4g} m)")

    N = int(np.floor(duration * rate + 1e-9)) + 1
    rig = _Rig(robot, obstacles, physics, controller, sensors, rate, N, q_home,
               np.random.default_rng(noise_seq), np.random.default_rng(clock_seq))
    sup = _Supervisor(rig, collider, controller, physics)
    sweep_step = grid.cell / 2
    max_lever = float(collider.lever.max())
    moves: list[Move] = []
    idle = 0
    while not rig.log.full:
        q = rig.q_m.copy()  # the strategy sees the encoders
        target = strat.next_target(q)
        if target is None:
            idle += 1
            if idle > 3:
                break
            continue
        idle = 0
        t0 = rig.t
        plan, vertices, at_rest = sup.guarded_move(target)
        if rig.log.full:
            break
        t_stop = rig.t
        q_stop = vertices[-1]
        short = np.abs(target - q_stop) > sup.reach_tol
        swept = densify(vertices, sweep_step, max_lever)
        grid.mark(swept)
        if not short.any():
            strat.observe(swept, None)
            moves.append(Move(t0, t_stop, t_stop, t_stop, q, target, ()))
        else:
            # contacts the arm came to rest against stopped it; after a timeout it was still
            # moving (sliding), and nothing stopped it
            stopped = rig.mark_stopped() if at_rest else []
            sup.follow(plan, round(controller.dwell / rig.dt))  # dwell, still pushing
            # the supervisor's view: joints within tolerance reached their target
            reached = np.where(short, q_stop, target)
            strat.observe(swept, densify(np.stack([reached, target]), sweep_step, max_lever))
            t_retreat = rig.t
            sup.retreat(vertices)
            ids = tuple(sorted(id(ev) for ev in stopped))
            moves.append(Move(t0, t_stop, t_retreat, rig.t, q, target, ids))
        if progress is not None:
            progress(min(rig.t, duration), duration)

    while not rig.log.full:  # the strategy gave up: hold the last reference
        rig.step(rig.q_ref.copy(), np.zeros(n))

    return _result(robot, collider, rig, strat, moves, controller, sensors, physics, rate,
                   duration, seed, meta, progress, wall0)


@dataclass
class _Plan:
    """Reference positions and velocities at every physics step; held at the end."""

    q: FloatArray  # (K, n)
    qd: FloatArray  # (K, n)
    i: int = 0

    def next(self) -> tuple[FloatArray, FloatArray]:
        j = min(self.i, len(self.q) - 1)
        self.i += 1
        return self.q[j], self.qd[j]

    @property
    def done(self) -> bool:
        return self.i >= len(self.q) - 1


class _Supervisor:
    """Guarded moves and retreats as a rig's supervisor runs them, from encoders only."""

    def __init__(self, rig: _Rig, collider: Collider, controller: Controller,
                 physics: Physics) -> None:
        self.rig = rig
        self.collider = collider
        self.controller = controller
        self.vmax = controller.speed * np.asarray(rig.robot.velocity_limits)
        self.amax = self.vmax / controller.t_acc
        rig.rest = physics.rest_speed * self.vmax
        friction_error = physics.joint_friction * rig.effort / rig.K
        #: joints this close to their target reached it
        self.reach_tol = 2.0 * friction_error + 10.0 * rig.quantum + 1e-3
        self.settle_steps = max(1, round(physics.settle_time / rig.dt))
        self.sample_every = max(1, round(0.01 / rig.dt))  # swept path vertices every 10 ms

    def guarded_move(self, target: FloatArray) -> tuple[_Plan, FloatArray, bool]:
        """Move toward ``target`` from the last reference until the arm is at rest with the
        plan complete or a reference held, or the plan and a grace time are over.  Returns
        the plan (to keep pushing), the measured path ``(K, n)`` and whether it came to rest."""
        rig = self.rig
        q_from = rig.q_ref.copy()  # the plan continues from the last reference
        delta = target - q_from
        law = synchronised_law(delta, self.vmax, self.amax)
        T = law.duration
        timeout = T + 2.0 + float(np.max(rig.lead / np.maximum(self.vmax, 1e-9)))
        s, sd = law(np.arange(int(np.ceil(T / rig.dt)) + 2) * rig.dt)
        plan = _Plan(q_from + s[:, None] * delta, sd[:, None] * delta)
        path = [rig.q_m.copy()]
        still = 0
        at_rest = False
        while not rig.log.full:
            held = rig.step(*plan.next())
            if rig.step_i % self.sample_every == 0:
                path.append(rig.q_m.copy())
            still = still + 1 if rig.at_rest else 0
            at_rest = still >= self.settle_steps
            if at_rest and (plan.done or held):
                break
            if plan.i * rig.dt > timeout:  # still sliding: the supervisor gives up
                break
        path.append(rig.q_m.copy())
        return plan, np.array(path), at_rest

    def follow(self, plan: _Plan, steps: int) -> None:
        for _ in range(steps):
            if self.rig.log.full:
                return
            self.rig.step(*plan.next())

    def retreat(self, vertices: FloatArray) -> None:
        """Back along the measured path as the kinematic engine retreats, then until the arm is
        at rest (at most half a second)."""
        rig = self.rig
        back = _retreat_vertices(self.collider, vertices, self.controller)
        path = PolylinePath.build(back, self.vmax, self.controller.t_acc)
        qr, qdr = path.sample(np.arange(int(path.duration / rig.dt) + 1) * rig.dt)
        self.follow(_Plan(qr, qdr), len(qr))
        still, t_end = 0, rig.t + 0.5
        zero = np.zeros(rig.n)
        while not rig.log.full and still < self.settle_steps and rig.t < t_end:
            rig.step(back[-1], zero)
            still = still + 1 if rig.at_rest else 0


def _result(robot: RobotModel, collider: Collider, rig: _Rig, strat: Strategy,
            moves: list[Move], controller: Controller, sensors: Sensors, physics: Physics,
            rate: float, duration: float, seed: Any, meta: dict[str, Any] | None,
            progress: ProgressCallback | None, wall0: float) -> SimResult:
    n = robot.dof
    lg = rig.log
    t_log_end = float(rig.log_steps[-1] / rig.substeps) / rate
    events = sorted((ev for ev in rig.events if ev.t_start <= t_log_end),
                    key=lambda ev: (ev.t_start, ev.link, ev.surface))
    order = {id(ev): i for i, ev in enumerate(events)}
    moves = [Move(m.t_start, m.t_stop, m.t_retreat, m.t_end, m.q_start, m.q_target,
                  tuple(sorted(order[i] for i in m.contacts if i in order))) for m in moves]

    def settled(ev: _Event) -> tuple[FloatArray, str, float, FloatArray]:
        return ev.settled if ev.settled is not None else (ev.point, ev.kind, ev.s, ev.q)

    rows = [settled(ev) for ev in events]
    K, D, _ = controller.gains(robot)
    truth = GroundTruth(
        surfaces=_surfaces_with_deviation(collider, rig.scene.deviation),
        contact_t=np.array([ev.t_start for ev in events], dtype=float),
        contact_link=np.array([ev.link for ev in events], dtype=np.int64),
        contact_kind=np.array([r[1] for r in rows], dtype=np.str_),
        contact_point=np.array([r[0] for r in rows], dtype=float).reshape(-1, 3),
        contact_surface=np.array([ev.surface for ev in events], dtype=np.int64),
        contact_s=np.array([r[2] for r in rows], dtype=float),
        contact_t_end=np.array([min(ev.t_last, t_log_end) for ev in events], dtype=float),
        contact_force=np.array([ev.force for ev in events], dtype=float),
        contact_q=np.array([r[3] for r in rows], dtype=float).reshape(-1, n),
        contact_stopped=np.array([ev.stopped for ev in events], dtype=bool),
        contact_point_first=np.array([ev.point_first for ev in events],
                                     dtype=float).reshape(-1, 3),
        meta={"simulator": "wholearm_tools.sim.physics", "engine": "physics",
              "strategy": strat.name,
              "seed": None if isinstance(seed, np.random.SeedSequence) else seed,
              "rate": rate, "duration": duration, "physics_rate": 1.0 / rig.dt,
              "physics": asdict(physics), "stiffness": K.tolist(), "damping": D.tolist(),
              "mujoco": rig.mujoco.__version__, **(meta or {})},
    )
    log = _joint_log(robot, lg, rig.log_steps / rig.substeps, rate, sensors)
    run = Run(robot=robot, log=log, truth=truth,
              source=str((meta or {}).get("scenario", "<simulated>")))
    if progress is not None:
        progress(duration, duration)
    stats = {
        "moves": len(moves), "swept_fraction": strat.grid.fraction_swept,
        "tiles": rig.scene.tiles, "deviation": dict(rig.scene.deviation),
        "mjcf": rig.scene.xml,
        "physics_steps": rig.step_i,
        "events": {"rebounds": np.array([ev.rebounds for ev in events], dtype=np.int64),
                   "slide": np.array([ev.max_shift for ev in events], dtype=float),
                   "path": np.array([ev.path for ev in events], dtype=float),
                   "depth": np.array([ev.depth for ev in events], dtype=float)},
    }
    return SimResult(
        run=run, q_true=read_only(lg.q_true), qd_true=read_only(lg.qd_true),
        contact_q=read_only(truth.contact_q), moves=tuple(moves), obstacles=collider.obstacles,
        wall_time=time.perf_counter() - wall0, clearance_evals=collider.n_evals, stats=stats)


def _log_schedule(n_samples: int, substeps: int, physics: Physics,
                  rng: np.random.Generator) -> IntArray:
    """Physics step of each log sample over the run's ``n_samples`` log periods: every
    ``substeps`` steps, or by a rig's clock (``physics.log_jitter``, ``log_drop``): intervals
    of ``substeps * (1 + e)`` steps accumulated (the clock drifts as it does on a rig, no
    sample is pulled back to a grid), each sample at the nearest step (two falling on one step
    are one sample), then samples lost at random (never the first)."""
    last = (n_samples - 1) * substeps
    if physics.log_jitter == 0 and physics.log_drop == 0:
        return np.arange(n_samples, dtype=np.int64) * substeps
    m = 2 * n_samples + 16
    steps = substeps * np.maximum(1.0 + physics.log_jitter * rng.standard_normal(m), 0.1)
    at = np.unique(np.rint(np.concatenate([[0.0], np.cumsum(steps)])).astype(np.int64))
    at = at[at <= last]
    keep = rng.random(at.shape[0]) >= physics.log_drop
    keep[0] = True
    return at[keep]


def _surfaces_with_deviation(collider: Collider, deviation: dict[int, float]
                             ) -> tuple[dict[str, Any], ...]:
    """Ground-truth surface records, each with the measured deviation of the simulated surface
    from the ideal one (``physics_deviation`` [m]; 0 for exact primitives)."""
    return tuple({**s, "physics_deviation": float(deviation.get(s["id"], 0.0))}
                 for s in surface_dicts(collider))


def _joint_log(robot: RobotModel, lg: _Log, periods: FloatArray, rate: float,
               sensors: Sensors) -> JointLog:
    """The logged topics at ``periods`` (each sample's time in log periods): encoder
    positions, encoder-derived velocity (backward difference over ``velocity_window``
    samples, as the kinematic engine, on the samples' own times), reference and clipped
    torque."""
    q = lg.q_meas
    N = q.shape[0]
    w = sensors.velocity_window
    qd = np.zeros_like(q)
    if N > 1:
        ks = np.arange(1, N)
        back = np.maximum(ks - w, 0)
        qd[1:] = (q[ks] - q[back]) * rate / (periods[ks] - periods[back])[:, None]
    t = periods * (1.0 / rate)
    return JointLog(joint_names=robot.joint_names, t=t, q=q, qd=qd, tau_cmd=lg.tau,
                    q_cmd=lg.q_ref, t0_ns=SIM_T0_NS)
