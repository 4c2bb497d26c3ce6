"""Immutable records passed between stages: a joint log, ground truth, and a whole run.

Arrays are columnar (one array per field) and read-only.  Times are seconds from the first
message of the log (``t0_ns`` keeps the absolute start so exports can restore log time).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError
from wholearm_tools.robot.model import RobotModel

FloatArray = NDArray[np.float64]

TORQUE_SOURCES = ("commanded", "measured", "position")
"""Where ``JointLog.tau_cmd`` comes from: the commanded torque (``/joint_commands`` effort[] or
Float64MultiArray), the measured effort on the state topic, or the controller's stiffness times
(commanded - measured) position."""

CONTACT_KINDS = ("tip", "joint", "body")
"""Ground-truth contact location on a link: the tip sphere (last link), the outer joint sphere
(inner links), or the link body (cylinder side)."""


def _frozen(arr: Any, dtype: Any = float) -> NDArray[Any]:
    """Read-only array of ``arr``: a copy, except that a read-only array of that dtype which owns
    its memory is adopted as it is (the reader hands its decoded columns over, so a log is held
    once; a view, or an array the caller can still write, is always copied)."""
    if (isinstance(arr, np.ndarray) and arr.dtype == np.dtype(dtype) and arr.base is None
            and not arr.flags.writeable):
        return arr
    out = np.array(arr, dtype=dtype)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, slots=True, eq=False)
class JointLog:
    """Joint states of one arm, columnar, on the state timestamps.

    Parameters
    ----------
    joint_names : tuple of n str
    t : (N,) float, seconds since ``t0_ns``, strictly increasing (kept to whole nanoseconds)
    q : (N, n) float, measured joint positions [rad]
    qd : (N, n) float, joint velocities [rad/s] (logged, or differentiated from ``q``)
    tau_cmd : (N, n) float or None, the torque evidence [N m] on the state timestamps: what
        the joints were driven with, from the source ``torque_source`` names
    q_cmd : (N, n) float or None, commanded positions when the log has them
    t0_ns : int, absolute time of ``t[0]`` in nanoseconds
    torque_source : one of :data:`TORQUE_SOURCES`, or None without ``tau_cmd``
        (default: ``"commanded"`` when ``tau_cmd`` is given)
    torque_note : one line saying where ``tau_cmd`` was read (topic, stiffness), for reports
    ignored_joints : joints of the log that were not read because the robot's chain does not
        drive them (each named in a warning when the log was read)
    """

    joint_names: tuple[str, ...]
    t: FloatArray
    q: FloatArray
    qd: FloatArray
    tau_cmd: FloatArray | None = None
    q_cmd: FloatArray | None = None
    t0_ns: int = 0
    torque_source: str | None = None
    torque_note: str = ""
    ignored_joints: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        t = _frozen(self.t)
        if t.ndim != 1:
            raise InputError(f"expected t of shape (N,), got {t.shape}")
        # times on the whole-nanosecond grid every log format stamps them on, exactly as
        # read_run returns them: a run and its MCAP round trip are the same input
        on_grid = np.round(t * 1e9) * 1e-9
        if not np.array_equal(on_grid, t, equal_nan=True):
            t = _frozen(on_grid)
        object.__setattr__(self, "t", t)
        for name in ("q", "qd", "tau_cmd", "q_cmd"):
            value = getattr(self, name)
            if value is None:
                continue
            arr = _frozen(value)
            if arr.shape != (t.shape[0], n):
                raise InputError(f"expected {name} of shape ({t.shape[0]}, {n}), got {arr.shape}")
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "t0_ns", int(self.t0_ns))
        source = self.torque_source
        if source is None and self.tau_cmd is not None:
            source = "commanded"
        if (source is None) != (self.tau_cmd is None) or (
                source is not None and source not in TORQUE_SOURCES):
            raise InputError(f"torque_source {self.torque_source!r} does not fit tau_cmd "
                             f"({'absent' if self.tau_cmd is None else 'given'}); expected one "
                             f"of {TORQUE_SOURCES} with tau_cmd, None without")
        object.__setattr__(self, "torque_source", source)
        object.__setattr__(self, "ignored_joints", tuple(self.ignored_joints))

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.n_samples else 0.0

    @property
    def rate(self) -> float:
        """Median sample rate in Hz (0 for fewer than two samples)."""
        if self.n_samples < 2:
            return 0.0
        return float(1.0 / np.median(np.diff(self.t)))


@dataclass(frozen=True, slots=True, eq=False)
class GroundTruth:
    """What really happened in a simulated run (absent for real logs).

    Parameters
    ----------
    surfaces : tuple of dict
        Environment surfaces as JSON-ready dicts: ``{"id": int, "type": str, "params": {...},
        "free_side": +1|-1, "bounds": {...}}`` (see ``wholearm_tools.sim.environment``).
    contact_t : (M,) float, contact times (seconds, same clock as ``JointLog.t``)
    contact_link : (M,) int, 0-based link index in contact
    contact_kind : (M,) str, one of :data:`CONTACT_KINDS`
    contact_point : (M, 3) float, contact point on the surface (base frame)
    contact_surface : (M,) int, surface id touched
    contact_s : (M,) float, fraction along the link axis of the robot point in contact
    meta : dict, scenario name, seed, B hint, anything else JSON-serialisable
    contact_t_end : (M,) float, when the contact was released (NaN: unknown)
    contact_force : (M,) float, peak normal force during the contact [N] (NaN: unknown)
    contact_q : (M, n) float, true configuration where the contact settled ((M, 0): unknown)
    contact_stopped : (M,) bool, the contact blocked a commanded motion (the arm stopped against
        it), as opposed to a graze the arm slid past
    contact_point_first : (M, 3) float, contact point at first touch (``contact_point`` is where
        the contact settled; equal when it did not slide)

    One row per contact *event*, from first touch (``contact_t``) until release
    (``contact_t_end``); ``contact_point``, ``contact_kind``, ``contact_s`` and ``contact_q``
    describe where it settled.  The last five fields are optional: records built without them
    (older files) get NaN times and forces, an unknown configuration, ``stopped`` True (the
    kinematic engine's contacts stop the arm by construction) and the settled point as the first.
    """

    surfaces: tuple[dict[str, Any], ...]
    contact_t: FloatArray
    contact_link: NDArray[np.int64]
    contact_kind: NDArray[np.str_]
    contact_point: FloatArray
    contact_surface: NDArray[np.int64]
    contact_s: FloatArray
    meta: dict[str, Any] = field(default_factory=dict)
    contact_t_end: FloatArray | None = None
    contact_force: FloatArray | None = None
    contact_q: FloatArray | None = None
    contact_stopped: NDArray[np.bool_] | None = None
    contact_point_first: FloatArray | None = None

    def __post_init__(self) -> None:
        m = np.asarray(self.contact_t).shape[0]
        object.__setattr__(self, "contact_t", _frozen(self.contact_t))
        object.__setattr__(self, "contact_link", _frozen(self.contact_link, np.int64))
        object.__setattr__(self, "contact_kind", _frozen(self.contact_kind, np.str_))
        object.__setattr__(self, "contact_point", _frozen(self.contact_point).reshape(m, 3))
        object.__setattr__(self, "contact_surface", _frozen(self.contact_surface, np.int64))
        object.__setattr__(self, "contact_s", _frozen(self.contact_s))
        for name in ("contact_link", "contact_kind", "contact_surface", "contact_s"):
            if getattr(self, name).shape != (m,):
                raise InputError(f"expected {name} of shape ({m},), got "
                                 f"{getattr(self, name).shape}")
        defaults = {
            "contact_t_end": (np.full(m, np.nan), float, (m,)),
            "contact_force": (np.full(m, np.nan), float, (m,)),
            "contact_stopped": (np.ones(m, dtype=bool), np.bool_, (m,)),
            "contact_point_first": (self.contact_point, float, (m, 3)),
        }
        for name, (default, dtype, shape) in defaults.items():
            value = getattr(self, name)
            arr = _frozen(default if value is None else value, dtype)
            if arr.size == 0 and m == 0:
                arr = _frozen(arr.reshape(shape), dtype)  # e.g. [] read back from JSON
            if arr.shape != shape:
                raise InputError(f"expected {name} of shape {shape}, got {arr.shape}")
            object.__setattr__(self, name, arr)
        q = _frozen(np.zeros((m, 0)) if self.contact_q is None else self.contact_q)
        if q.size == 0 and q.ndim != 2:
            q = _frozen(q.reshape(m, 0))
        if q.ndim != 2 or q.shape[0] != m:
            raise InputError(f"expected contact_q of shape ({m}, n), got {q.shape}")
        object.__setattr__(self, "contact_q", q)
        bad = set(self.contact_kind.tolist()) - set(CONTACT_KINDS)
        if bad:
            raise InputError(f"unknown contact kinds {sorted(bad)}; expected {CONTACT_KINDS}")
        object.__setattr__(self, "surfaces", tuple(self.surfaces))

    @property
    def n_contacts(self) -> int:
        return int(self.contact_t.shape[0])

    @property
    def contact_duration(self) -> FloatArray:
        """Duration of each contact event [s] (NaN where the release time is unknown)."""
        return np.asarray(self.contact_t_end) - self.contact_t

    @property
    def is_tip(self) -> NDArray[np.bool_]:
        """True where the contact is on the tip or a joint sphere (the paper's "tip" class)."""
        return self.contact_kind != "body"


@dataclass(frozen=True, slots=True, eq=False)
class Run:
    """A logged run: robot, joint log, optional ground truth, and where it came from."""

    robot: RobotModel
    log: JointLog
    truth: GroundTruth | None = None
    source: str = "<memory>"

    def __post_init__(self) -> None:
        if tuple(self.log.joint_names) != tuple(self.robot.joint_names):
            raise InputError(f"{self.source}: log joints {self.log.joint_names} do not match "
                             f"robot joints {self.robot.joint_names}")
