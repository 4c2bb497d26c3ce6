"""Write a :class:`~wholearm_tools.logs.records.Run` as MCAP (ROS 2 or JSON profile).

See ``docs/log-format.md`` for the topics and fields.  The output is deterministic: the same
run gives a byte-identical file (log times come from the run's own clock, never the wall clock),
and it is written atomically (temporary file, then rename).
"""

from __future__ import annotations

import json
import os
from typing import Any

import numpy as np

from wholearm_tools.errors import InputError
from wholearm_tools.logs import cdr
from wholearm_tools.logs.records import GroundTruth, Run
from wholearm_tools.logs.schemas import (
    COMMAND_TOPIC,
    DESCRIPTION_TOPIC,
    FORMAT_VERSION,
    GROUND_TRUTH,
    JOINT_STATE,
    JOINT_TOPIC,
    METADATA_NAME,
    ROS2_DEFINITIONS,
    STRING,
    TRUTH_TOPIC,
    json_schema_bytes,
)

PROFILES = ("ros2", "json")
COMPRESSIONS = ("zstd", "lz4", "none")
_BLOCK = 16384  # samples encoded per numpy pass


def _json_default(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, tuple | set | frozenset):
        return list(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


def _dumps(value: Any) -> bytes:
    try:
        return json.dumps(value, sort_keys=True, separators=(",", ":"), allow_nan=False,
                          default=_json_default).encode("utf-8")
    except (TypeError, ValueError) as exc:
        raise InputError(f"cannot write as JSON: {exc}") from None


def _nullable(values: np.ndarray) -> list[Any]:
    """``values.tolist()`` with NaN as None (JSON has no NaN)."""
    out = np.asarray(values, dtype=object)
    out[np.isnan(np.asarray(values, dtype=float))] = None
    return out.tolist()


def ground_truth_to_json(truth: GroundTruth) -> dict[str, Any]:
    """The ground-truth message body (see the ``wholearm_msgs/msg/GroundTruth`` JSON schema);
    unknown values (NaN) are written as null."""
    return {
        "format_version": FORMAT_VERSION,
        "surfaces": list(truth.surfaces),
        "contacts": {
            "t": truth.contact_t.tolist(),
            "link": truth.contact_link.tolist(),
            "kind": [str(k) for k in truth.contact_kind.tolist()],
            "point": truth.contact_point.tolist(),
            "surface": truth.contact_surface.tolist(),
            "s": truth.contact_s.tolist(),
            "t_end": _nullable(truth.contact_t_end),
            "force": _nullable(truth.contact_force),
            "q": _nullable(truth.contact_q),
            "stopped": truth.contact_stopped.tolist(),
            "point_first": truth.contact_point_first.tolist(),
        },
        "meta": dict(truth.meta),
    }


def _joint_state_json(stamps: np.ndarray, names: list[str], fields: list[np.ndarray | None]
                      ) -> list[bytes]:
    """JSON JointState payloads (ROS field names), one per stamp."""
    sec, nanosec = np.divmod(stamps, 1_000_000_000)
    cols = [f.tolist() if f is not None else None for f in fields]
    empty: list[float] = []
    out = []
    for i, (s, ns) in enumerate(zip(sec.tolist(), nanosec.tolist(), strict=True)):
        msg = {"header": {"stamp": {"sec": s, "nanosec": ns}, "frame_id": ""}, "name": names,
               "position": cols[0][i] if cols[0] is not None else empty,
               "velocity": cols[1][i] if cols[1] is not None else empty,
               "effort": cols[2][i] if cols[2] is not None else empty}
        out.append(_dumps(msg))
    return out


def write_run(
    path: str | os.PathLike[str],
    run: Run,
    *,
    profile: str = "ros2",
    chunk_size: int = 1024 * 1024,
    compression: str = "zstd",
) -> None:
    """Write ``run`` to ``path`` as MCAP.

    Parameters
    ----------
    path : output file (replaced atomically; the folder must exist)
    run : the run; ``run.log.t`` is written as header stamps ``t0_ns + round(t * 1e9)`` ns
    profile : ``"ros2"`` (CDR messages, ``ros2msg`` schemas; ground truth is a
        ``std_msgs/msg/String`` holding its JSON) or ``"json"`` (JSON messages, ``jsonschema``
        schemas; ground truth is a ``wholearm_msgs/msg/GroundTruth`` JSON message)
    chunk_size : uncompressed chunk size in bytes
    compression : ``"zstd"``, ``"lz4"`` or ``"none"``
    """
    from mcap.well_known import MessageEncoding, SchemaEncoding
    from mcap.writer import CompressionType, Writer

    from wholearm_tools import __version__
    from wholearm_tools._io import atomic_output
    from wholearm_tools.robot import robot_to_urdf

    if profile not in PROFILES:
        raise InputError(f"unknown profile {profile!r}; expected one of {PROFILES}")
    if compression not in COMPRESSIONS:
        raise InputError(f"unknown compression {compression!r}; expected one of {COMPRESSIONS}")
    if int(chunk_size) <= 0:
        raise InputError(f"chunk_size must be positive, got {chunk_size}")
    log = run.log
    if log.n_samples > 1 and np.any(np.diff(log.t) <= 0):
        raise InputError(f"{run.source}: log times are not strictly increasing")
    stamps = log.t0_ns + np.round(np.asarray(log.t) * 1e9).astype(np.int64)
    if log.n_samples and stamps[0] < 0:
        raise InputError(f"log time {stamps[0]} ns is negative")
    names = list(log.joint_names)
    cmd_fields: list[np.ndarray | None] = [log.q_cmd, None, log.tau_cmd]
    has_commands = log.q_cmd is not None or log.tau_cmd is not None
    start_ns = int(stamps[0]) if log.n_samples else int(log.t0_ns)

    def encode(block: slice, fields: list[np.ndarray | None]) -> Any:
        """Payloads of samples ``block`` (encoded a block at a time to bound memory)."""
        parts = [None if f is None else f[block] for f in fields]
        if profile == "ros2":
            return cdr.encode_joint_states(stamps[block], tuple(names), *parts)
        return _joint_state_json(stamps[block], names, parts)

    if profile == "ros2":
        message_encoding, schema_encoding = MessageEncoding.CDR, SchemaEncoding.ROS2
        urdf = robot_to_urdf(run.robot).encode("utf-8") + b"\x00"
        description = cdr.CDR_LE + len(urdf).to_bytes(4, "little") + urdf
    else:
        message_encoding, schema_encoding = MessageEncoding.JSON, SchemaEncoding.JSONSchema
        description = _dumps({"data": robot_to_urdf(run.robot)})

    def schema_data(name: str) -> bytes:
        if profile == "ros2":
            return ROS2_DEFINITIONS[name].encode("utf-8")
        return json_schema_bytes(name)

    kinds = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
             "none": CompressionType.NONE}
    metadata = {"format_version": str(FORMAT_VERSION), "profile": profile,
                "tool_version": __version__, "robot": run.robot.name,
                "joints": json.dumps(names)}
    if run.truth is not None:
        for key in ("scenario", "seed"):
            if key in run.truth.meta:
                metadata[key] = str(run.truth.meta[key])

    with atomic_output(path, "wb") as handle:
        writer = Writer(handle, chunk_size=int(chunk_size), compression=kinds[compression])
        writer.start(profile="ros2" if profile == "ros2" else "",
                     library=f"wholearm_tools/{__version__}")
        state_schema = writer.register_schema(JOINT_STATE, schema_encoding,
                                              schema_data(JOINT_STATE))
        string_schema = writer.register_schema(STRING, schema_encoding, schema_data(STRING))
        desc_channel = writer.register_channel(DESCRIPTION_TOPIC, message_encoding, string_schema)
        state_channel = writer.register_channel(JOINT_TOPIC, message_encoding, state_schema)
        cmd_channel = (writer.register_channel(COMMAND_TOPIC, message_encoding, state_schema)
                       if has_commands else 0)
        writer.add_message(desc_channel, start_ns, bytes(description), start_ns)
        if run.truth is not None:
            body = _dumps(ground_truth_to_json(run.truth))
            if profile == "ros2":
                # a std_msgs/msg/String holding the JSON: stock ROS 2 readers read every channel
                truth_channel = writer.register_channel(TRUTH_TOPIC, message_encoding,
                                                        string_schema)
                payload = cdr.CDR_LE + (len(body) + 1).to_bytes(4, "little") + body + b"\x00"
            else:
                truth_schema = writer.register_schema(GROUND_TRUTH, SchemaEncoding.JSONSchema,
                                                      json_schema_bytes(GROUND_TRUTH))
                truth_channel = writer.register_channel(TRUTH_TOPIC, MessageEncoding.JSON,
                                                        truth_schema)
                payload = body
            writer.add_message(truth_channel, start_ns, payload, start_ns)
        add = writer.add_message
        for first in range(0, stamps.shape[0], _BLOCK):
            block = slice(first, first + _BLOCK)
            states = encode(block, [log.q, log.qd, None])
            commands = encode(block, cmd_fields) if has_commands else None
            for j, stamp in enumerate(stamps[block].tolist()):
                add(state_channel, stamp, bytes(states[j]), stamp, first + j)
                if commands is not None:
                    add(cmd_channel, stamp, bytes(commands[j]), stamp, first + j)
        writer.add_metadata(METADATA_NAME, metadata)
        writer.finish()
