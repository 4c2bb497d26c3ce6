"""Read MCAP joint logs (ROS 2 or JSON profile) into :class:`JointLog` / :class:`Run`.

Rules (see ``docs/log-format.md``):

* Times are the JointState ``header.stamp`` (the MCAP log time when every stamp is zero, and
  for ``Float64MultiArray`` commands, which have no header).
* Messages out of time order are sorted by stamp (stable) with a :class:`LogWarning`; messages
  repeating an earlier stamp are then dropped (the first one is kept) with a warning, so
  ``JointLog.t`` is strictly increasing.
* Joints are matched by name; log joints the robot does not have are ignored with a warning;
  robot joints missing from the log are an error.
* Missing or partial velocities are differentiated from positions (central differences on the
  stamps, ``numpy.gradient``).
* Commands are held onto the state stamps (zero-order hold: the latest command at or before each
  state).  Before the first command the torque is 0 and the commanded position is the measured
  one.
* The torque evidence (``JointLog.tau_cmd``) comes from the source ``effort`` names (recorded
  in ``JointLog.torque_source``): ``"commanded"`` torque on the command topic (default),
  ``"measured"`` effort on the state topic, or ``"position"``: the controller's stiffness times
  (commanded - measured) position.  A command topic that is the state topic carries measured
  values, never commands: it is refused unless the effort is read as measured.
* Bags (rosbag2 folders, ``.db3``, ROS 1 ``.bag``) are read through
  :mod:`wholearm_tools.logs.bags`; everything after the scan is the same.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import os
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError, LogFormatError, RobotModelError
from wholearm_tools.logs.bags import scan_log
from wholearm_tools.logs.decoders import ArrayColumns, JointStateColumns, ValueList
from wholearm_tools.logs.records import TORQUE_SOURCES, GroundTruth, JointLog, Run
from wholearm_tools.logs.scan import LogScan, check_log_path
from wholearm_tools.logs.schemas import (
    COMMAND_TOPIC,
    DESCRIPTION_TOPIC,
    FLOAT64_MULTI_ARRAY,
    GROUND_TRUTH,
    JOINT_STATE,
    JOINT_TOPIC,
    METADATA_NAME,
    STRING,
    TRUTH_TOPIC,
)
from wholearm_tools.robot.model import RobotModel

log = logging.getLogger(__name__)


class LogWarning(UserWarning):
    """A log was readable but something in it was fixed up (sorted, dropped, truncated)."""


def _warn(message: str) -> None:
    warnings.warn(message, LogWarning, stacklevel=3)


def joint_state_topics(scan: LogScan) -> list[str]:
    """Topics of ``scan`` carrying ``sensor_msgs/msg/JointState``."""
    return [t for t, s in scan.topics.items() if s.schema_name == JOINT_STATE]


def _scan(path: Path, joint_topic: str | None, command_topic: str | None) -> LogScan:
    commands = command_topic or COMMAND_TOPIC

    def wanted(topic: str, schema: str) -> bool:
        if schema == JOINT_STATE:
            return joint_topic is None or topic in (joint_topic, commands)
        if schema == FLOAT64_MULTI_ARRAY:
            return topic == commands
        if schema == STRING:
            return topic in (DESCRIPTION_TOPIC, TRUTH_TOPIC)
        return schema == GROUND_TRUTH

    check_log_path(path)
    scan = scan_log(path, wanted)
    if scan.truncated:
        _warn(f"{path}: file is truncated ({scan.truncation}); read the {scan.n_messages} "
              "messages before the cut")
    return scan


def _select_joint_topic(scan: LogScan, joint_topic: str | None,
                        command_topic: str | None) -> str:
    topics = joint_state_topics(scan)
    if joint_topic is not None:
        if joint_topic not in scan.decoded or joint_topic not in topics:
            raise LogFormatError(f"{scan.source}: no JointState topic {joint_topic!r}; "
                                 f"JointState topics: {topics or 'none'}")
        return joint_topic
    if JOINT_TOPIC in topics:
        return JOINT_TOPIC
    candidates = [t for t in topics if t != (command_topic or COMMAND_TOPIC)]
    if not candidates:
        raise LogFormatError(f"{scan.source}: no JointState topic (expected {JOINT_TOPIC}); "
                             f"topics: {sorted(scan.topics)}")
    if len(candidates) > 1:
        raise LogFormatError(f"{scan.source}: no {JOINT_TOPIC} and several JointState topics "
                             f"{candidates}; choose one with joint_topic (--joint-topic)")
    return candidates[0]


#: fewest JointState messages a run can have: contacts are found where joints stop while
#: torque is applied, which needs a sample before, at and after a stop
MIN_SAMPLES = 3
#: a gap between consecutive stamps longer than this many median periods (and than
#: LONG_GAP_S) is reported: the recording stopped, and no motion is known inside it
LONG_GAP_PERIODS = 50
LONG_GAP_S = 1.0


def _describe_bad(values: NDArray[np.float64], carried: NDArray[np.bool_]) -> tuple[int, int, str]:
    """``(missing, non_finite, what)`` counts of the bad cells of ``values``: not carried by
    their message, or carried but NaN/infinite (``what`` says which: "NaN", "infinite" or
    "NaN and infinite")."""
    bad = ~np.isfinite(values)
    carried = np.asarray(carried, dtype=bool)
    missing = int(np.count_nonzero(bad & ~carried))
    data_bad = bad & carried
    nan = bool(np.any(np.isnan(values[data_bad]))) if data_bad.any() else False
    inf = bool(np.any(np.isinf(values[data_bad]))) if data_bad.any() else False
    what = "NaN and infinite" if nan and inf else ("NaN" if nan else "infinite")
    return missing, int(np.count_nonzero(data_bad)), what


def _first_bad(bad: NDArray[np.bool_], names: tuple[str, ...], stamps: NDArray[np.int64]) -> str:
    row, col = np.argwhere(bad)[0]
    return f"joint {names[col]!r} at t = {(stamps[row] - stamps[0]) * 1e-9:.6f} s"


def _warn_long_gaps(stamps: NDArray[np.int64], source: str, topic: str) -> None:
    """Warn about gaps in the stamps far longer than the log's own period."""
    if stamps.shape[0] < 3:
        return
    steps = np.diff(stamps).astype(np.float64) * 1e-9
    limit = max(LONG_GAP_S, LONG_GAP_PERIODS * float(np.median(steps)))
    long = np.flatnonzero(steps > limit)
    if long.shape[0] == 0:
        return
    worst = int(long[np.argmax(steps[long])])
    t_at = (stamps[worst] - stamps[0]) * 1e-9
    _warn(f"{source}: topic {topic!r}: {long.shape[0]} gap(s) in the stamps longer than "
          f"{limit:.3g} s, the longest {steps[worst]:.3g} s after t = {t_at:.3f} s (no joint "
          "motion is known inside a gap)")


def _times(stamp_ns: NDArray[np.int64], log_time_ns: NDArray[np.int64], source: str,
           topic: str) -> NDArray[np.int64]:
    if stamp_ns.shape[0] > 1 and not np.any(stamp_ns):
        _warn(f"{source}: topic {topic!r} has zero header stamps; using MCAP log times")
        return log_time_ns
    return stamp_ns


def _order(times: NDArray[np.int64], source: str, topic: str) -> NDArray[np.intp]:
    """Indices that sort ``times`` (stable) and drop repeated stamps (first kept)."""
    order = np.argsort(times, kind="stable")
    if times.shape[0] > 1 and np.any(np.diff(times) < 0):
        moved = int(np.count_nonzero(order != np.arange(order.shape[0])))
        _warn(f"{source}: topic {topic!r}: {moved} messages out of time order; sorted by stamp")
    sorted_times = times[order]
    keep = np.ones(order.shape[0], dtype=bool)
    keep[1:] = np.diff(sorted_times) > 0
    if not keep.all():
        _warn(f"{source}: topic {topic!r}: dropped {int((~keep).sum())} messages repeating an "
              "earlier stamp (kept the first)")
    return order[keep]


def _take(values: NDArray[np.float64], rows: NDArray[np.intp], cols: list[int]
          ) -> NDArray[np.float64]:
    """``values[rows][:, cols]`` with one copy at most (none when both are the identity)."""
    all_rows = rows.shape[0] == values.shape[0] and bool(np.all(rows == np.arange(rows.shape[0])))
    all_cols = cols == list(range(values.shape[1]))
    if all_rows and all_cols:
        return values
    if all_rows:
        return values[:, cols]
    return values[np.ix_(rows, cols)]


def _columns_for(names: tuple[str, ...], available: tuple[str, ...], source: str, topic: str,
                 warn_extra: bool) -> list[int]:
    index = {name: i for i, name in enumerate(available)}
    missing = [n for n in names if n not in index]
    if missing:
        raise LogFormatError(f"{source}: topic {topic!r} lacks joints {missing} "
                             f"(log joints: {list(available)})")
    extra = [n for n in available if n not in set(names)]
    if extra and warn_extra:
        _warn(f"{source}: topic {topic!r}: ignoring joints not in the robot: {extra}")
    return [index[n] for n in names]


def _hold(t_cmd: NDArray[np.int64], values: NDArray[np.float64], t_state: NDArray[np.int64],
          before: NDArray[np.float64]) -> NDArray[np.float64]:
    """Zero-order hold of ``values (M, n)`` at ``t_cmd`` onto ``t_state``; ``before (N, n)``
    where no command was given yet."""
    idx = np.searchsorted(t_cmd, t_state, side="right") - 1
    out = np.array(before, dtype=float, copy=True)
    ok = idx >= 0
    out[ok] = values[idx[ok]]
    return out


def _commands(scan: LogScan, topic: str, explicit: bool, names: tuple[str, ...],
              t_state: NDArray[np.int64], q: NDArray[np.float64]
              ) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None]:
    decoded = scan.decoded.get(topic)
    if decoded is None:
        if explicit:
            raise LogFormatError(f"{scan.source}: no command topic {topic!r} "
                                 f"(JointState or Float64MultiArray); topics: "
                                 f"{sorted(scan.topics)}")
        return None, None
    source = scan.source
    if isinstance(decoded, ArrayColumns):
        if decoded.n_messages == 0:
            return None, None
        if decoded.data.shape[1] != len(names):
            raise LogFormatError(f"{source}: command topic {topic!r} carries "
                                 f"{decoded.data.shape[1]} values per message, expected "
                                 f"{len(names)} (one per joint, in robot joint order)")
        keep = _order(decoded.log_time_ns, source, topic)
        tau = _hold(decoded.log_time_ns[keep], decoded.data[keep], t_state,
                    np.zeros_like(q))
        return tau, None
    assert isinstance(decoded, JointStateColumns)
    if decoded.n_messages == 0:
        return None, None
    cols = _columns_for(names, decoded.names, source, topic, warn_extra=True)
    times = _times(decoded.stamp_ns, decoded.log_time_ns, source, topic)
    keep = _order(times, source, topic)
    t_cmd = times[keep]
    tau = q_cmd = None
    effort = _take(decoded.effort, keep, cols)
    if np.all(np.isfinite(effort)):
        tau = _hold(t_cmd, effort, t_state, np.zeros_like(q))
    else:
        carried = _take(decoded.carried("effort"), keep, cols)
        missing, non_finite, what = _describe_bad(effort, carried)
        if non_finite:
            raise LogFormatError(
                f"{source}: command topic {topic!r}: {non_finite} {what} commanded torques "
                f"(effort; first: {_first_bad(carried & ~np.isfinite(effort), names, t_cmd)})")
        if missing < effort.size:
            raise LogFormatError(f"{source}: command topic {topic!r} has efforts in some "
                                 f"messages or joints only ({missing} of {effort.size} "
                                 "missing)")
    position = _take(decoded.position, keep, cols)
    if np.all(np.isfinite(position)):
        q_cmd = _hold(t_cmd, position, t_state, q)
    return tau, q_cmd


def _stiffness(scan: LogScan, stiffness: float | Sequence[float] | None,
               names: tuple[str, ...]) -> tuple[NDArray[np.float64] | None, str]:
    """Controller stiffness per joint [N m/rad] from the argument or the log's ``wholearm``
    metadata record (key ``stiffness``: a JSON number or list), and where it came from."""
    origin = "given"
    if stiffness is None:
        text = scan.metadata.get(METADATA_NAME, {}).get("stiffness")
        if text is None:
            return None, ""
        try:
            stiffness = json.loads(text)
        except ValueError:
            raise LogFormatError(f"{scan.source}: metadata {METADATA_NAME!r} stiffness is not a "
                                 f"JSON number or list: {text!r}") from None
        origin = "from the log's metadata"
    try:
        k = np.asarray(stiffness, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"stiffness must be numbers, got {stiffness!r}") from None
    if k.ndim == 0:
        k = np.full(len(names), float(k))
    if k.shape != (len(names),):
        raise InputError(f"expected one stiffness or {len(names)} (one per joint "
                         f"{list(names)}), got {k.size}")
    if not np.all(np.isfinite(k)) or np.any(k <= 0):
        raise InputError(f"stiffness must be positive and finite [N m/rad], got {k.tolist()}")
    return k, origin


def _torque_evidence(scan: LogScan, topic: str, state: JointStateColumns,
                     keep: NDArray[np.intp], cols: list[int], names: tuple[str, ...],
                     stamps: NDArray[np.int64], q: NDArray[np.float64],
                     command_topic: str | None, effort: str,
                     stiffness: float | Sequence[float] | None, require: bool
                     ) -> tuple[NDArray[np.float64] | None, NDArray[np.float64] | None,
                                str | None, str]:
    """``(tau, q_cmd, torque_source, note)``: the torque evidence from the source ``effort``."""
    source = scan.source
    if effort not in TORQUE_SOURCES:
        raise InputError(f"effort must be one of {list(TORQUE_SOURCES)}, got {effort!r}")
    cmd_topic = command_topic or COMMAND_TOPIC
    if cmd_topic == topic and effort != "measured":
        raise LogFormatError(f"{source}: the command topic {cmd_topic!r} is the state topic: its "
                             "effort[] is the measured effort and its position[] the measured "
                             "position, not commands; read them with --effort measured "
                             "(effort='measured') or give the topic that carries the commands")
    tau, q_cmd = (None, None) if cmd_topic == topic else _commands(
        scan, cmd_topic, command_topic is not None, names, stamps, q)
    if effort == "measured":
        measured = _take(state.effort, keep, cols)
        if not np.all(np.isfinite(measured)):
            carried = _take(state.carried("effort"), keep, cols)
            _, non_finite, what = _describe_bad(measured, carried)
            if non_finite:
                raise LogFormatError(
                    f"{source}: topic {topic!r}: {non_finite} {what} measured efforts (first: "
                    f"{_first_bad(carried & ~np.isfinite(measured), names, stamps)})")
        missing = [n for n, ok in zip(names, np.all(np.isfinite(measured), axis=0), strict=True)
                   if not ok]
        if missing:
            raise LogFormatError(f"{source}: topic {topic!r} has no measured effort[] for joints "
                                 f"{missing} (--effort measured reads the state topic's effort)")
        return measured, q_cmd, "measured", f"measured effort (effort[] on {topic})"
    if effort == "position":
        if q_cmd is None:
            raise LogFormatError(f"{source}: --effort position needs commanded positions "
                                 f"(position[] on a JointState command topic; {cmd_topic!r} has "
                                 "none); choose the topic with --command-topic")
        k, origin = _stiffness(scan, stiffness, names)
        if k is None:
            raise InputError(f"{source}: --effort position needs the controller's stiffness: "
                             "--stiffness K [N m/rad], one value or one per joint")
        shown = (f"{k[0]:g}" if np.all(k == k[0]) else
                 "[" + ", ".join(f"{v:g}" for v in k) + "]")
        return (k * (q_cmd - q), q_cmd, "position",
                f"stiffness {shown} N m/rad ({origin}) x (commanded - measured position), "
                f"commands on {cmd_topic}")
    if tau is None:
        if require:
            hint = ""
            if np.all(np.isfinite(_take(state.effort, keep, cols))):
                hint = f"; {topic!r} carries measured effort: use --effort measured"
            elif q_cmd is not None:
                hint = ("; the commands carry positions: use --effort position --stiffness K")
            raise LogFormatError(f"{source}: no commanded torques (expected effort[] on "
                                 f"{cmd_topic!r} as JointState or Float64MultiArray){hint}")
        return None, q_cmd, None, ""
    kind = ("Float64MultiArray" if isinstance(scan.decoded.get(cmd_topic), ArrayColumns)
            else "effort[]")
    return tau, q_cmd, "commanded", f"commanded torque ({kind} on {cmd_topic})"


def _joint_log(scan: LogScan, topic: str, names: tuple[str, ...] | None,
               command_topic: str | None, require_commands: bool, warn_extra: bool,
               effort: str = "commanded", stiffness: float | Sequence[float] | None = None,
               ignored: tuple[str, ...] = ()) -> JointLog:
    source = scan.source
    cols_data = scan.decoded[topic]
    assert isinstance(cols_data, JointStateColumns)
    if cols_data.n_messages == 0:
        raise LogFormatError(f"{source}: topic {topic!r} has no messages")
    names = cols_data.names if names is None else tuple(names)
    cols = _columns_for(names, cols_data.names, source, topic, warn_extra)
    times = _times(cols_data.stamp_ns, cols_data.log_time_ns, source, topic)
    keep = _order(times, source, topic)
    stamps = times[keep]
    if stamps.shape[0] < MIN_SAMPLES:
        raise LogFormatError(f"{source}: topic {topic!r} has {stamps.shape[0]} sample(s) at "
                             f"distinct stamps; a run needs at least {MIN_SAMPLES}")
    q = _take(cols_data.position, keep, cols)
    bad = ~np.isfinite(q)
    if bad.any():
        carried = _take(cols_data.carried("position"), keep, cols)
        missing, non_finite, what = _describe_bad(q, carried)
        if non_finite:
            raise LogFormatError(
                f"{source}: topic {topic!r}: {non_finite} {what} positions (first: "
                f"{_first_bad(carried & bad, names, stamps)})")
        raise LogFormatError(
            f"{source}: topic {topic!r}: {missing} missing positions (first: "
            f"{_first_bad(bad, names, stamps)})")
    _warn_long_gaps(stamps, source, topic)
    t = (stamps - stamps[0]).astype(np.float64) * 1e-9
    qd = _take(cols_data.velocity, keep, cols)
    if not np.all(np.isfinite(qd)):
        carried = _take(cols_data.carried("velocity"), keep, cols)
        missing, non_finite, what = _describe_bad(qd, carried)
        if missing == qd.size:  # no velocities logged: the usual case, nothing lost
            log.info("%s: topic %r has no velocities; differentiating positions", source,
                     topic)
        else:
            first = _first_bad(~np.isfinite(qd), names, stamps)
            reason = (f"{non_finite} {what}" if non_finite else "") + \
                (" and " if non_finite and missing else "") + \
                (f"{missing} missing" if missing else "")
            _warn(f"{source}: topic {topic!r}: {reason} velocities of {qd.size} (first: "
                  f"{first}); every logged velocity is replaced by differentiated positions")
        qd = np.gradient(q, t, axis=0)
    tau_cmd, q_cmd, torque_source, note = _torque_evidence(
        scan, topic, cols_data, keep, cols, names, stamps, q, command_topic, effort, stiffness,
        require_commands)
    return JointLog(joint_names=names, t=_handover(t), q=_handover(q), qd=_handover(qd),
                    tau_cmd=_handover(tau_cmd), q_cmd=_handover(q_cmd), t0_ns=int(stamps[0]),
                    torque_source=torque_source, torque_note=note, ignored_joints=ignored)


def _handover(arr: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
    """Freeze a column this reader owns so that JointLog adopts it instead of copying it (the
    decoded position column often *is* q: copying it would hold the log twice at the peak)."""
    if arr is None:
        return None
    arr = np.asarray(arr, dtype=np.float64)
    if arr.base is not None:
        arr = arr.copy()
    arr.setflags(write=False)
    return arr


def read_joint_log(
    path: str | os.PathLike[str],
    *,
    joint_topic: str | None = None,
    command_topic: str | None = None,
    joint_names: tuple[str, ...] | None = None,
    require_commands: bool = False,
    effort: str = "commanded",
    stiffness: float | Sequence[float] | None = None,
) -> JointLog:
    """Read one arm's joint states (and commands if present) without a robot model.

    Parameters
    ----------
    path : MCAP file, rosbag2 folder, ``.db3`` or ROS 1 ``.bag``
    joint_topic : JointState topic; default ``/joint_states``, or the only JointState topic
    command_topic : command topic (JointState effort[] or Float64MultiArray); default
        ``/joint_commands`` when present
    joint_names : joints to read, in this order (default: every joint of the topic)
    require_commands : raise LogFormatError when there is no torque evidence
    effort : torque source, one of :data:`~wholearm_tools.logs.records.TORQUE_SOURCES`
        (``"commanded"``, ``"measured"``, ``"position"``)
    stiffness : controller stiffness [N m/rad] for ``effort="position"`` (one value, or one per
        joint; default: the log's ``wholearm`` metadata ``stiffness`` if present)
    """
    path = Path(path)
    scan = _scan(path, joint_topic, command_topic)
    topic = _select_joint_topic(scan, joint_topic, command_topic)
    return _joint_log(scan, topic, joint_names, command_topic, require_commands,
                      warn_extra=joint_names is not None, effort=effort, stiffness=stiffness)


def _nan_column(values: Any, shape: tuple[int, ...]) -> NDArray[np.float64]:
    """Numbers with null as NaN, reshaped to ``shape``."""
    arr = np.array(values, dtype=object).reshape(shape)
    arr[np.equal(arr, None)] = np.nan
    return arr.astype(float)


def ground_truth_from_json(body: Any, source: str = "ground truth") -> GroundTruth:
    """Inverse of :func:`wholearm_tools.logs.writer.ground_truth_to_json`.

    ``body`` is the decoded JSON object, or its text (the data of a ``std_msgs/msg/String``
    ground-truth message).  Files written before the event fields (``t_end``, ``force``, ``q``,
    ``stopped``, ``point_first``) existed read with their defaults (see ``GroundTruth``).
    """
    try:
        if isinstance(body, str | bytes):
            body = json.loads(body)
        contacts = body["contacts"]
        m = len(contacts["t"])
        q = contacts.get("q")
        n = len(q[0]) if q else 0
        return GroundTruth(
            surfaces=tuple(body["surfaces"]),
            contact_t=np.asarray(contacts["t"], dtype=float).reshape(m),
            contact_link=np.asarray(contacts["link"], dtype=np.int64).reshape(-1),
            contact_kind=np.asarray(contacts["kind"], dtype=np.str_).reshape(-1),
            contact_point=np.asarray(contacts["point"], dtype=float).reshape(m, 3),
            contact_surface=np.asarray(contacts["surface"], dtype=np.int64).reshape(-1),
            contact_s=np.asarray(contacts["s"], dtype=float).reshape(-1),
            meta=dict(body.get("meta") or {}),
            contact_t_end=(None if "t_end" not in contacts
                           else _nan_column(contacts["t_end"], (m,))),
            contact_force=(None if "force" not in contacts
                           else _nan_column(contacts["force"], (m,))),
            contact_q=None if q is None else _nan_column(q, (m, n)),
            contact_stopped=(None if "stopped" not in contacts
                             else np.asarray(contacts["stopped"], dtype=bool).reshape(-1)),
            contact_point_first=(None if "point_first" not in contacts else np.asarray(
                contacts["point_first"], dtype=float).reshape(m, 3)),
        )
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise LogFormatError(f"{source}: malformed ground truth ({exc!r})") from None


def _robot(scan: LogScan, robot: RobotModel | str | os.PathLike[str] | None,
           log_joints: tuple[str, ...], chain: dict[str, Any]
           ) -> tuple[RobotModel, dict[str, str]]:
    """The robot, and the log joints its chain does not drive with the reason for each."""
    from wholearm_tools.robot import load_urdf_chain, urdf_chain

    if isinstance(robot, RobotModel):
        given = {k: v for k, v in chain.items() if v}
        if given:
            raise InputError(f"{sorted(given)} choose a chain in a URDF; robot is already a "
                             "RobotModel")
        return robot, {n: "not in the robot" for n in log_joints if n not in robot.joint_names}
    if robot is not None:
        from wholearm_tools._io import check_input_file
        from wholearm_tools.robot.urdf import MAX_URDF_BYTES

        # a bounded regular file before the URDF reader opens it (a FIFO would block it)
        check_input_file(robot, "URDF", max_bytes=MAX_URDF_BYTES, error=RobotModelError)
        source = str(robot)
        with _errors_named(source):
            found = load_urdf_chain(robot, joints=log_joints, **chain)
    else:
        description = scan.decoded.get(DESCRIPTION_TOPIC)
        if not isinstance(description, ValueList) or not description.values:
            raise LogFormatError(f"{scan.source}: no URDF on {DESCRIPTION_TOPIC} and no robot "
                                 "given (pass robot=RobotModel or a URDF path, or --robot)")
        source = f"{scan.source} {DESCRIPTION_TOPIC}"
        with _errors_named(source):
            found = urdf_chain(description.values[0], source, joints=log_joints, **chain)
    return found.robot, found.ignored_log_joints(log_joints)


@contextlib.contextmanager
def _errors_named(source: str) -> Iterator[None]:
    """Robot errors raised within name ``source`` (the URDF file, or the log and topic)."""
    try:
        yield
    except RobotModelError as exc:
        if str(exc).startswith(source):
            raise
        raise RobotModelError(f"{source}: {exc}") from None


LIMIT_SLACK = 0.05
"""Logged positions may pass a URDF joint limit by this much [rad] (soft limits, encoder
noise) before the reader says the URDF may not describe the logged arm."""


def _check_limits(path: Path, topic: str, log: JointLog, robot: RobotModel) -> None:
    """Warn, per joint, when the logged positions leave the robot's joint limits: the URDF
    then describes another arm, or another calibration (zero offsets) of it, and every pose
    computed from it is wrong."""
    low, high = log.q.min(axis=0), log.q.max(axis=0)
    outside = [f"{name} {lo:.2f}..{hi:.2f} (limits {a:.2f}..{b:.2f})"
               for name, lo, hi, a, b in zip(robot.joint_names, low, high, robot.lower,
                                             robot.upper, strict=True)
               if lo < a - LIMIT_SLACK or hi > b + LIMIT_SLACK]
    if outside:
        _warn(f"{path}: topic {topic!r}: positions outside the robot's joint limits [rad]: "
              f"{'; '.join(outside)}; the URDF may not describe this arm or its calibration")


def read_run(
    path: str | os.PathLike[str],
    *,
    joint_topic: str | None = None,
    command_topic: str | None = None,
    robot: RobotModel | str | os.PathLike[str] | None = None,
    require_commands: bool = False,
    effort: str = "commanded",
    stiffness: float | Sequence[float] | None = None,
    base_link: str | None = None,
    tip_link: str | None = None,
    package_paths: Sequence[str | os.PathLike[str]] = (),
    joint_compliance: float | Sequence[float] | None = None,
    joint_backlash: float | Sequence[float] | None = None,
) -> Run:
    """Read a run: robot (``robot`` argument or the log's URDF), joint log, ground truth.

    Parameters
    ----------
    path : MCAP file (ROS 2 or JSON profile, detected from the channels), rosbag2 folder
        (MCAP or SQLite storage), ``.db3`` file or ROS 1 ``.bag``
    joint_topic, command_topic, effort, stiffness : see :func:`read_joint_log`
    robot : RobotModel or URDF file; default: the URDF on ``/robot_description``
    require_commands : raise LogFormatError when there is no torque evidence
    base_link, tip_link : ends of the chain in the URDF (default: the root, and the only
        branch the log's joints drive); log joints off the chain are ignored with a
        :class:`LogWarning` naming each, and listed in ``JointLog.ignored_joints``
    package_paths : folders that resolve the URDF's ``package://`` meshes
    joint_compliance : deflection of each joint's transmission at its effort limit [rad], one
        value or one per joint, for encoders on the motor side (``RobotModel.joint_compliance``;
        default: the robot's, stiff for a URDF)
    joint_backlash : lost motion of each joint's transmission [rad], one value or one per joint,
        for encoders on the motor side (``RobotModel.joint_backlash``; default: the robot's,
        none for a URDF)
    """
    path = Path(path)
    scan = _scan(path, joint_topic, command_topic)
    topic = _select_joint_topic(scan, joint_topic, command_topic)
    state = scan.decoded[topic]
    log_joints = tuple(state.names) if isinstance(state, JointStateColumns) else ()
    model, ignored = _robot(scan, robot, log_joints, {
        "base_link": base_link, "tip_link": tip_link, "package_paths": tuple(package_paths)})
    drives = {k: v for k, v in (("joint_compliance", joint_compliance),
                                ("joint_backlash", joint_backlash)) if v is not None}
    if drives:
        try:
            model = dataclasses.replace(model, **drives)
        except RobotModelError as exc:
            raise InputError(f"{path}: {exc}") from None
    if ignored:
        _warn(f"{path}: topic {topic!r}: ignoring joints not in the robot: {list(ignored)} ("
              + "; ".join(f"{name}: {why}" for name, why in ignored.items()) + ")")
    joint_log = _joint_log(scan, topic, model.joint_names, command_topic, require_commands,
                           warn_extra=False, effort=effort, stiffness=stiffness,
                           ignored=tuple(ignored))
    _check_limits(path, topic, joint_log, model)
    truth = None
    values = scan.decoded.get(TRUTH_TOPIC)
    if isinstance(values, ValueList) and values.values:
        truth = ground_truth_from_json(values.values[0], f"{path} {TRUTH_TOPIC}")
    return Run(robot=model, log=joint_log, truth=truth, source=str(path))
