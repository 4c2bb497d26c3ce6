"""Summarise an MCAP log without a robot model: topics, joints, rates, what a run needs."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from wholearm_tools.errors import LogFormatError, RobotModelError
from wholearm_tools.logs.bags import scan_log
from wholearm_tools.logs.decoders import ArrayColumns, JointStateColumns, ValueList
from wholearm_tools.logs.reader import _select_joint_topic, ground_truth_from_json
from wholearm_tools.logs.scan import check_log_path
from wholearm_tools.logs.schemas import (
    COMMAND_TOPIC,
    DESCRIPTION_TOPIC,
    FLOAT64_MULTI_ARRAY,
    JOINT_STATE,
    STRING,
    TRUTH_TOPIC,
)

_PROFILES = {"cdr": "ros2", "json": "json"}


def _rate(times_ns: np.ndarray) -> tuple[float, float]:
    """(median rate, duration) of sorted times; 0 rate for fewer than two distinct times."""
    if times_ns.shape[0] < 2:
        return 0.0, 0.0
    times = np.sort(times_ns)
    steps = np.diff(times)
    steps = steps[steps > 0]
    median = float(1e9 / np.median(steps)) if steps.shape[0] else 0.0
    return median, float(times[-1] - times[0]) * 1e-9


def inspect_log(path: str | os.PathLike[str], *, joint_topic: str | None = None
                ) -> dict[str, Any]:
    """Describe the log at ``path`` as a JSON-ready dict.

    Keys: ``file, profile, mcap_profile, library, truncated, messages, start_ns, end_ns,
    duration_s, topics`` (list of ``topic, schema, schema_encoding, message_encoding, messages,
    duration_s, rate_hz``), ``joint_topics`` (topic → ``joints, velocity, effort, rate_hz,
    duration_s``), ``joint_topic`` and ``joints`` (the topic a run would use, None when the
    choice is ambiguous), ``urdf, robot, commands, ground_truth, metadata, attachments``.
    Rates are median rates: header stamps for JointState, MCAP log times otherwise.
    """
    path = Path(path)

    def wanted(topic: str, schema: str) -> bool:
        if schema == STRING:
            return topic in (DESCRIPTION_TOPIC, TRUTH_TOPIC)
        if schema == FLOAT64_MULTI_ARRAY:
            return topic == COMMAND_TOPIC
        return True

    check_log_path(path)
    scan = scan_log(path, wanted)
    topics = []
    start = [s.first_log_ns for s in scan.topics.values() if s.first_log_ns is not None]
    end = [s.last_log_ns for s in scan.topics.values() if s.last_log_ns is not None]
    joint_topics: dict[str, Any] = {}
    for name, stats in sorted(scan.topics.items()):
        decoded = scan.decoded.get(name)
        if isinstance(decoded, JointStateColumns) and decoded.n_messages:
            stamps = decoded.stamp_ns if np.any(decoded.stamp_ns) else decoded.log_time_ns
            rate, duration = _rate(stamps)
            joint_topics[name] = {
                "joints": list(decoded.names),
                "velocity": bool(np.all(np.isfinite(decoded.velocity))),
                "effort": bool(np.all(np.isfinite(decoded.effort))),
                "rate_hz": rate, "duration_s": duration,
            }
        elif stats.count > 1 and stats.first_log_ns is not None:
            rate, duration = _rate(np.array([stats.first_log_ns, stats.last_log_ns]))
            rate = (stats.count - 1) / duration if duration > 0 else 0.0
        else:
            rate, duration = 0.0, 0.0
        topics.append({"topic": name, "schema": stats.schema_name,
                       "schema_encoding": stats.schema_encoding,
                       "message_encoding": stats.message_encoding, "messages": stats.count,
                       "duration_s": duration, "rate_hz": rate})

    encodings = {scan.topics[t].message_encoding for t in joint_topics}
    profile = (_PROFILES.get(next(iter(encodings)), next(iter(encodings)))
               if len(encodings) == 1 else ("mixed" if encodings else ""))
    selected: str | None
    if joint_topic is not None:
        selected = _select_joint_topic(scan, joint_topic, None)
    else:
        try:
            selected = _select_joint_topic(scan, None, None)
        except LogFormatError:
            selected = None

    urdf = scan.decoded.get(DESCRIPTION_TOPIC)
    robot: dict[str, Any] | None = None
    has_urdf = isinstance(urdf, ValueList) and bool(urdf.values)
    if has_urdf:
        from wholearm_tools.robot import robot_from_urdf

        try:
            model = robot_from_urdf(urdf.values[0], source=f"{path} {DESCRIPTION_TOPIC}")
            robot = {"name": model.name, "joints": list(model.joint_names),
                     "planar": model.planar}
        except RobotModelError as exc:
            robot = {"error": str(exc)}

    commands = None
    cmd = scan.decoded.get(COMMAND_TOPIC)
    if isinstance(cmd, JointStateColumns) and cmd.n_messages:
        commands = {"topic": COMMAND_TOPIC, "schema": JOINT_STATE,
                    "torques": bool(np.all(np.isfinite(cmd.effort))),
                    "positions": bool(np.all(np.isfinite(cmd.position)))}
    elif isinstance(cmd, ArrayColumns) and cmd.n_messages:
        commands = {"topic": COMMAND_TOPIC, "schema": FLOAT64_MULTI_ARRAY, "torques": True,
                    "positions": False}

    truth = None
    gt = scan.decoded.get(TRUTH_TOPIC)
    if isinstance(gt, ValueList) and gt.values:
        parsed = ground_truth_from_json(gt.values[0], f"{path} {TRUTH_TOPIC}")
        kinds = parsed.contact_kind.tolist()
        truth = {"contacts": parsed.n_contacts, "tip": int(parsed.is_tip.sum()),
                 "body": int((~parsed.is_tip).sum()),
                 "stopped": int(np.count_nonzero(parsed.contact_stopped)),
                 "by_kind": {k: kinds.count(k) for k in sorted(set(kinds))},
                 "surfaces": len(parsed.surfaces),
                 "surface_types": [str(s.get("type", "?")) for s in parsed.surfaces]}

    return {
        "file": str(path),
        "profile": profile,
        "mcap_profile": scan.profile,
        "library": scan.library,
        "truncated": scan.truncated,
        "messages": scan.n_messages,
        "start_ns": min(start) if start else None,
        "end_ns": max(end) if end else None,
        "duration_s": (max(end) - min(start)) * 1e-9 if start else 0.0,
        "topics": topics,
        "joint_topics": joint_topics,
        "joint_topic": selected,
        "joints": joint_topics[selected]["joints"] if selected in joint_topics else None,
        "urdf": has_urdf,
        "robot": robot,
        "commands": commands,
        "ground_truth": truth,
        "metadata": {name: {k: _scalar(v) for k, v in rec.items()}
                     for name, rec in scan.metadata.items()},
        "attachments": list(scan.attachments),
    }


def _scalar(text: str) -> Any:
    """An MCAP metadata value (always a string in the file) as the number it spells, when it
    spells one exactly (``"1"`` -> 1, ``"0.5"`` -> 0.5; ``"0.1.0"`` stays text)."""
    for kind in (int, float):
        try:
            value = kind(text)
        except (TypeError, ValueError):
            continue
        if kind is int or math.isfinite(value):
            return value
    return text
