"""One sequential pass over an MCAP file: chunks decompressed one at a time, messages handed to
the registered decoders as offsets into the chunk (see :mod:`wholearm_tools.logs.decoders`).

The pass uses mcap's non-seeking :class:`mcap.stream_reader.StreamReader` with
``emit_chunks=True``, so a file cut short (a recording that crashed) is read up to the cut: the
scan records ``truncated=True`` and keeps every complete chunk before it.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import LogFormatError
from wholearm_tools.logs.decoders import DECODERS, ChannelInfo, TopicDecoder

MCAP_MAGIC = b"\x89MCAP0\r\n"
_RECORD = struct.Struct("<BQ")
_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE = 0x03, 0x04, 0x05
_MESSAGE_HEADER = 2 + 4 + 8 + 8  # channel id, sequence, log time, publish time
_UNCHUNKED_BATCH = 4096


@dataclass
class TopicStats:
    """Per-channel statistics gathered for every channel, decoded or not."""

    topic: str
    schema_name: str
    schema_encoding: str
    message_encoding: str
    count: int = 0
    first_log_ns: int | None = None
    last_log_ns: int | None = None


@dataclass
class LogScan:
    """Result of :func:`scan_mcap`.

    ``topics`` maps every topic to its statistics; ``decoded`` maps each decoded topic to its
    decoder's result (:class:`~wholearm_tools.logs.decoders.JointStateColumns`, ...).
    """

    source: str
    profile: str = ""
    library: str = ""
    topics: dict[str, TopicStats] = field(default_factory=dict)
    decoded: dict[str, Any] = field(default_factory=dict)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    attachments: list[str] = field(default_factory=list)
    truncated: bool = False
    truncation: str = ""

    @property
    def n_messages(self) -> int:
        return sum(t.count for t in self.topics.values())


def check_magic(path: Path) -> None:
    """LogFormatError unless ``path`` starts with the MCAP magic bytes."""
    try:
        with path.open("rb") as handle:
            head = handle.read(len(MCAP_MAGIC))
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read log ({exc.strerror})") from None
    if not head:
        raise LogFormatError(f"{path}: empty file, not an MCAP log")
    if head != MCAP_MAGIC:
        raise LogFormatError(f"{path}: not an MCAP file (starts with {head[:8]!r})")


class _Scanner:
    def __init__(self, source: str, wanted: Any) -> None:
        self.scan = LogScan(source=source)
        self.wanted = wanted
        self.schemas: dict[int, Any] = {}
        self.channels: dict[int, TopicStats] = {}
        self.decoders: dict[int, TopicDecoder | None] = {}

    # -------------------------------------------------------------- records
    def add_schema(self, schema: Any) -> None:
        self.schemas.setdefault(schema.id, schema)

    def add_channel(self, channel: Any) -> None:
        if channel.id in self.channels:
            return
        schema = self.schemas.get(channel.schema_id)
        name = schema.name if schema is not None else ""
        stats = self.scan.topics.get(channel.topic)
        if stats is None:
            stats = TopicStats(channel.topic, name, schema.encoding if schema else "",
                               channel.message_encoding)
            self.scan.topics[channel.topic] = stats
        self.channels[channel.id] = stats
        decoder_class = DECODERS.get((channel.message_encoding, name))
        decoder = None
        if decoder_class is not None and self.wanted(channel.topic, name):
            info = ChannelInfo(channel.id, channel.topic, channel.message_encoding, name,
                               schema.encoding if schema else "", schema.data if schema else b"")
            decoder = decoder_class(info, self.scan.source)
        self.decoders[channel.id] = decoder

    def add_messages(self, buf: NDArray[np.uint8], starts: NDArray[np.int64],
                     lengths: NDArray[np.int64], channel: NDArray[np.int64],
                     log_time: NDArray[np.int64]) -> None:
        """Messages given by payload ``starts``/``lengths`` into ``buf``."""
        if channel.shape[0] == 0:
            return
        if channel.min() == channel.max():
            groups = [(int(channel[0]), slice(None))]
        else:
            groups = [(int(c), channel == c) for c in np.unique(channel)]
        for cid, sel in groups:
            stats = self.channels.get(cid)
            if stats is None:
                raise LogFormatError(f"{self.scan.source}: message on unknown channel {cid}")
            times = log_time[sel]
            stats.count += int(times.shape[0])
            lo, hi = int(times.min()), int(times.max())
            stats.first_log_ns = lo if stats.first_log_ns is None else min(lo, stats.first_log_ns)
            stats.last_log_ns = hi if stats.last_log_ns is None else max(hi, stats.last_log_ns)
            decoder = self.decoders.get(cid)
            if decoder is not None:
                decoder.add(buf, starts[sel], lengths[sel], times)

    def add_chunk_data(self, data: bytes) -> None:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Channel, Schema

        positions: list[int] = []
        sizes: list[int] = []
        pos, end = 0, len(data)
        unpack = _RECORD.unpack_from
        try:
            while pos < end:
                op, length = unpack(data, pos)
                body = pos + 9
                if op == _OP_MESSAGE:
                    positions.append(body)
                    sizes.append(length)
                elif op in (_OP_SCHEMA, _OP_CHANNEL):
                    stream = ReadDataStream(BytesIO(data[body:body + length]))
                    if op == _OP_SCHEMA:
                        self.add_schema(Schema.read(stream))
                    else:
                        self.add_channel(Channel.read(stream))
                pos = body + length
        except Exception as exc:
            raise LogFormatError(f"{self.scan.source}: corrupt chunk ({exc})") from None
        if pos != end:
            raise LogFormatError(f"{self.scan.source}: corrupt chunk (record overruns the chunk)")
        if not positions:
            return
        buf = np.frombuffer(data, dtype=np.uint8)
        body = np.array(positions, dtype=np.int64)
        lengths = np.array(sizes, dtype=np.int64) - _MESSAGE_HEADER
        channel = buf[body].astype(np.int64) | (buf[body + 1].astype(np.int64) << 8)
        log_time = buf[body[:, None] + (6 + np.arange(8))].view("<i8")[:, 0]
        self.add_messages(buf, body + _MESSAGE_HEADER, lengths, channel, log_time)


def _decompress(chunk: Any, source: str) -> bytes:
    if chunk.compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(chunk.data,
                                                       max_output_size=chunk.uncompressed_size)
    if chunk.compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(chunk.data)
    if chunk.compression == "":
        return chunk.data
    raise LogFormatError(f"{source}: unsupported chunk compression {chunk.compression!r}")


def scan_mcap(path: str | Path, wanted: Any = None) -> LogScan:
    """Read ``path`` once; decode the topics for which ``wanted(topic, schema_name)`` is true
    (default: every topic with a registered decoder).

    Raises LogFormatError (naming the file) for a file that is not MCAP, empty, corrupt, or
    truncated before any message.  A file cut short after some messages returns what was read
    with ``truncated=True``.
    """
    from mcap.exceptions import EndOfFile, McapError
    from mcap.records import Attachment, Channel, Chunk, Footer, Header, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader

    path = Path(path)
    check_magic(path)
    scanner = _Scanner(str(path), wanted or (lambda topic, schema: True))
    scan = scanner.scan
    pending: list[Any] = []

    def flush() -> None:
        if not pending:
            return
        payloads = [m.data for m in pending]
        lengths = np.array([len(p) for p in payloads], dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
        buf = np.frombuffer(b"".join(payloads), dtype=np.uint8)
        scanner.add_messages(buf, starts, lengths,
                             np.array([m.channel_id for m in pending], np.int64),
                             np.array([m.log_time for m in pending], np.int64))
        pending.clear()

    with path.open("rb") as handle:
        reader = StreamReader(handle, emit_chunks=True, record_size_limit=2**32)
        try:
            for record in reader.records:
                if isinstance(record, Chunk):
                    flush()
                    try:
                        data = _decompress(record, str(path))
                    except LogFormatError:
                        raise
                    except Exception as exc:
                        raise LogFormatError(f"{path}: corrupt chunk ({exc})") from None
                    if record.uncompressed_crc and zlib.crc32(data) != record.uncompressed_crc:
                        raise LogFormatError(f"{path}: corrupt chunk (CRC mismatch)")
                    scanner.add_chunk_data(data)
                elif isinstance(record, Message):
                    pending.append(record)
                    if len(pending) >= _UNCHUNKED_BATCH:
                        flush()
                elif isinstance(record, Schema):
                    scanner.add_schema(record)
                elif isinstance(record, Channel):
                    flush()
                    scanner.add_channel(record)
                elif isinstance(record, Header):
                    scan.profile, scan.library = record.profile, record.library
                elif isinstance(record, Metadata):
                    scan.metadata.setdefault(record.name, dict(record.metadata))
                elif isinstance(record, Attachment):
                    scan.attachments.append(record.name)
                elif isinstance(record, Footer):
                    break
        except (EndOfFile, struct.error) as exc:
            scan.truncated = True
            scan.truncation = str(exc) or type(exc).__name__
        except LogFormatError:
            raise
        except (McapError, ValueError, OverflowError, MemoryError) as exc:
            raise LogFormatError(f"{path}: corrupt MCAP ({type(exc).__name__}: {exc})") from None
        flush()
    if scan.truncated and scan.n_messages == 0:
        raise LogFormatError(f"{path}: truncated MCAP file with no readable message")
    for decoder in scanner.decoders.values():
        if decoder is not None:
            scan.decoded[decoder.channel.topic] = decoder.result()
    return scan
