"""ROS bags in: rosbag2 folders (MCAP or SQLite storage), bare ``.db3`` files, ROS 1 ``.bag``.

:func:`scan_log` is the one opener every reader uses: a bag goes through :func:`scan_bag`, an
MCAP file through :func:`wholearm_tools.logs.scan.scan_mcap`.  Both return the same
:class:`~wholearm_tools.logs.scan.LogScan`, so everything after the scan (topic choice, joint
matching, torque source, robot) is shared.

``scan_bag`` reads the bag with ``rosbags`` (``AnyReader``: metadata, split files, per-message
or per-file compression, ROS 1 and ROS 2) and hands the raw payloads of the wanted topics to
the same decoders as the MCAP path (:data:`wholearm_tools.logs.decoders.DECODERS`), so quirks
such as trailing bytes after a CDR payload are handled the same way.  ROS 1 messages are
deserialised by rosbags and serialised again as ROS 2 CDR first (JointState's ROS 1 header has
a sequence number the ROS 2 layout lacks; the other fields are the same).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from wholearm_tools.errors import LogFormatError
from wholearm_tools.logs.decoders import DECODERS, ChannelInfo, TopicDecoder
from wholearm_tools.logs.scan import LogScan, TopicStats, scan_mcap

SQLITE_MAGIC = b"SQLite format 3\x00"
ROS1_MAGIC = b"#ROSBAG V2.0"
_BATCH = 4096


def _head(path: Path) -> bytes:
    try:
        with path.open("rb") as handle:
            return handle.read(16)
    except OSError:
        return b""


def bag_kind(path: str | Path) -> str | None:
    """``"rosbag2"`` (a folder), ``"sqlite3"`` (a ``.db3``), ``"ros1"`` (a ``.bag``), or None
    for anything else (MCAP files, and files the MCAP reader will name as unreadable)."""
    path = Path(path)
    if path.is_dir():
        return "rosbag2"
    head = _head(path)
    if path.suffix == ".db3" or head.startswith(SQLITE_MAGIC):
        return "sqlite3"
    if path.suffix == ".bag" or head.startswith(ROS1_MAGIC):
        return "ros1"
    return None


def scan_log(path: str | Path, wanted: Callable[[str, str], bool] | None = None) -> LogScan:
    """Scan ``path``, an MCAP file or a bag; decode the topics ``wanted(topic, schema)`` says."""
    path = Path(path)
    if bag_kind(path) is None:
        return scan_mcap(path, wanted)
    return scan_bag(path, wanted)


def _bag_path(path: Path) -> Path:
    """The path rosbags opens: a rosbag2 folder, a storage file, or a ROS 1 bag.

    A folder without ``metadata.yaml`` that holds exactly one ``.mcap`` or ``.db3`` is that
    file; the suffix rosbags dispatches on is required.
    """
    kind = bag_kind(path)
    if kind == "rosbag2" and not (path / "metadata.yaml").is_file():
        files = sorted(p for p in path.iterdir() if p.suffix in (".mcap", ".db3"))
        if len(files) != 1:
            raise LogFormatError(f"{path}: a folder, but not a rosbag2 recording (no "
                                 "metadata.yaml) and not one .mcap or .db3 file")
        return files[0]
    if kind == "sqlite3" and path.suffix != ".db3":
        raise LogFormatError(f"{path}: an SQLite file: rosbag2 SQLite storage is read from a "
                             "file named *.db3 or from its rosbag2 folder")
    if kind == "ros1" and path.suffix != ".bag":
        raise LogFormatError(f"{path}: a ROS 1 bag: name it *.bag to read it")
    return path


def _schema_text(connection: Any, ros2: Any, is2: bool) -> tuple[str, bytes]:
    """Schema encoding and ROS 2 message definition handed to the decoders (their stock
    fallback decodes with it)."""
    from rosbags.interfaces import MessageDefinitionFormat

    if is2 and connection.msgdef.format == MessageDefinitionFormat.MSG and connection.msgdef.data:
        return "ros2msg", connection.msgdef.data.encode("utf-8")
    try:
        text, _ = ros2.generate_msgdef(connection.msgtype, ros_version=2)
    except Exception:  # a type the ROS 2 store does not know: no stock fallback for it
        text = ""
    return "ros2msg", text.encode("utf-8")


def _feed(decoder: TopicDecoder, batch: list[tuple[bytes, int]]) -> None:
    """Hand one batch of ``(payload, log time)`` to a decoder, as the MCAP scanner does."""
    lengths = np.array([len(p) for p, _ in batch], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    buf = np.frombuffer(b"".join(p for p, _ in batch), dtype=np.uint8)
    decoder.add(buf, starts, lengths, np.array([t for _, t in batch], dtype=np.int64))
    batch.clear()


def scan_bag(path: str | Path, wanted: Callable[[str, str], bool] | None = None) -> LogScan:
    """Read a bag once; decode the topics for which ``wanted(topic, schema_name)`` is true.

    Raises LogFormatError naming the bag when rosbags cannot open or read it.
    """
    from importlib.metadata import version

    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    source = str(path)
    wanted = wanted or (lambda topic, schema: True)
    target = _bag_path(path)
    kind = bag_kind(target) or "rosbag2"
    ros2 = get_typestore(Stores.LATEST)
    profile = {"ros1": "ros1 bag", "sqlite3": "rosbag2 (sqlite3)"}.get(kind, "rosbag2")
    scan = LogScan(source=source, profile=profile, library=f"rosbags {version('rosbags')}")
    decoders: dict[str, TopicDecoder] = {}
    batches: dict[str, list[tuple[bytes, int]]] = {}
    try:
        with AnyReader([target], default_typestore=ros2) as reader:
            encoding = "cdr" if reader.is2 else "ros1"
            for conn in reader.connections:
                if conn.topic in scan.topics:
                    continue
                schema_encoding, schema = _schema_text(conn, ros2, reader.is2)
                scan.topics[conn.topic] = TopicStats(
                    conn.topic, conn.msgtype, schema_encoding if reader.is2 else "ros1msg",
                    encoding)
                decoder_class = DECODERS.get(("cdr", conn.msgtype))
                if decoder_class is not None and wanted(conn.topic, conn.msgtype):
                    info = ChannelInfo(len(decoders), conn.topic, "cdr", conn.msgtype,
                                       schema_encoding, schema)
                    decoders[conn.topic] = decoder_class(info, source)
                    batches[conn.topic] = []
            for conn, timestamp, raw in reader.messages():
                stats = scan.topics[conn.topic]
                stats.count += 1
                stats.first_log_ns = (timestamp if stats.first_log_ns is None
                                      else min(stats.first_log_ns, timestamp))
                stats.last_log_ns = (timestamp if stats.last_log_ns is None
                                     else max(stats.last_log_ns, timestamp))
                decoder = decoders.get(conn.topic)
                if decoder is None:
                    continue
                payload = bytes(raw) if reader.is2 else bytes(
                    ros2.serialize_cdr(reader.deserialize(raw, conn.msgtype), conn.msgtype))
                batch = batches[conn.topic]
                batch.append((payload, int(timestamp)))
                if len(batch) >= _BATCH:
                    _feed(decoder, batch)
    except LogFormatError:
        raise
    except Exception as exc:  # rosbags' reader, storage and serde errors
        raise LogFormatError(f"{source}: cannot read the bag ({type(exc).__name__}: "
                             f"{exc})") from None
    for topic, decoder in decoders.items():
        if batches[topic]:
            _feed(decoder, batches[topic])
        scan.decoded[topic] = decoder.result()
    return scan
