"""One sequential pass over an MCAP file: chunks decompressed one at a time, messages handed to
the registered decoders as offsets into the chunk (see :mod:`wholearm_tools.logs.decoders`).

Records are read front to back with mcap's record classes (as its non-seeking
``StreamReader`` does, minus the index records, which are skipped unparsed), so a file cut short
(a recording that crashed) is read up to the cut: the scan records ``truncated=True`` and keeps
every complete chunk before it.
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


#: what a file that is not MCAP looks like, by its first bytes (named in the error, so the
#: file's own bytes are never shown)
_OTHER_FORMATS = ((b"SQLite format 3\x00", "an SQLite database (a rosbag2 .db3?)"),
                  (b"#ROSBAG", "a ROS 1 bag"), (b"PK\x03\x04", "a zip archive"),
                  (b"\x1f\x8b", "a gzip file"), (b"\x28\xb5\x2f\xfd", "a zstd stream"),
                  (b"%PDF", "a PDF"), (b"PAR1", "a Parquet file"), (b"<", "XML or HTML text"),
                  (b"{", "JSON text"))


def check_log_path(path: str | Path) -> None:
    """LogFormatError unless ``path`` is a folder (a rosbag2 recording) or a regular file: a
    device node or a FIFO is refused before anything opens it (opening a FIFO blocks until a
    writer appears; a device is read forever)."""
    from wholearm_tools._io import check_input_file

    if not Path(path).is_dir():
        check_input_file(path, "log", error=LogFormatError)


def check_magic(path: Path) -> None:
    """LogFormatError unless ``path`` is a regular file starting with the MCAP magic bytes.

    A device node or a FIFO is refused before it is opened (it would be read forever).  The
    message names a few other formats by their signature but never shows the file's bytes.
    """
    from wholearm_tools._io import check_input_file

    check_input_file(path, "log", error=LogFormatError)
    try:
        with path.open("rb") as handle:
            head = handle.read(16)
    except OSError as exc:
        raise LogFormatError(f"{path}: cannot read log ({exc.strerror})") from None
    if not head:
        raise LogFormatError(f"{path}: empty file, not an MCAP log")
    if head[:len(MCAP_MAGIC)] != MCAP_MAGIC:
        kind = next((name for sig, name in _OTHER_FORMATS if head.startswith(sig)), None)
        raise LogFormatError(f"{path}: not an MCAP file" + (f" (it looks like {kind})"
                                                            if kind else " (no MCAP magic)"))


class _Scanner:
    def __init__(self, source: str, wanted: Any) -> None:
        self.scan = LogScan(source=source)
        self.wanted = wanted
        self.schemas: dict[int, Any] = {}
        self.channels: dict[int, TopicStats] = {}
        self.decoders: dict[int, TopicDecoder | None] = {}
        self.counts: dict[int, int] = {}  # messages per channel id, from the summary if any

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
            if self.counts.get(channel.id):
                decoder.expect(self.counts[channel.id])
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
        """Hand every message record of a decompressed chunk to its decoder."""
        from mcap.data_stream import ReadDataStream
        from mcap.records import Channel, Schema

        buf = np.frombuffer(data, dtype=np.uint8)
        positions: list[int] = []
        sizes: list[int] = []
        pos, end = 0, len(data)
        unpack = _RECORD.unpack_from
        try:
            while pos < end:
                op, length = unpack(data, pos)
                body = pos + 9
                if op == _OP_MESSAGE:
                    if not positions:
                        found = _periodic_messages(buf, pos)
                        if found is not None:
                            positions, sizes = found
                            pos = end
                            break
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
        if len(positions) == 0:
            return
        body_arr = np.asarray(positions, dtype=np.int64)
        lengths = np.asarray(sizes, dtype=np.int64) - _MESSAGE_HEADER
        channel = buf[body_arr].astype(np.int64) | (buf[body_arr + 1].astype(np.int64) << 8)
        log_time = buf[body_arr[:, None] + (6 + np.arange(8))].view("<i8")[:, 0]
        self.add_messages(buf, body_arr + _MESSAGE_HEADER, lengths, channel, log_time)


def _u64(buf: NDArray[np.uint8], at: NDArray[np.int64]) -> NDArray[np.int64]:
    return buf[at[:, None] + np.arange(8)].view("<i8")[:, 0]


def _periodic_messages(buf: NDArray[np.uint8], start: int, max_period: int = 4
                       ) -> tuple[NDArray[np.int64], NDArray[np.int64]] | None:
    """Message records from ``start`` to the end of the chunk when they repeat a pattern of
    1..max_period record lengths (one topic, or states and commands interleaved): every
    record's opcode and length are checked in one numpy pass.  None when there is no pattern
    (the caller then walks the records one by one)."""
    end = buf.shape[0]
    lengths: list[int] = []
    pos = start
    for _ in range(max_period):
        if pos + 9 > end or buf[pos] != _OP_MESSAGE:
            return None
        lengths.append(int(_u64(buf, np.array([pos + 1]))[0]))
        pos += 9 + lengths[-1]
        stride = pos - start
        if (end - start) % stride:
            continue
        offsets = np.cumsum([0] + [9 + n for n in lengths[:-1]])
        count = (end - start) // stride
        heads = (start + stride * np.arange(count, dtype=np.int64)[:, None] + offsets).ravel()
        expected = np.tile(np.asarray(lengths, dtype=np.int64), count)
        if np.all(buf[heads] == _OP_MESSAGE) and np.array_equal(_u64(buf, heads + 1), expected):
            return heads + 9, expected
    return None


#: largest decompressed chunk accepted [bytes] (writers use 1-4 MiB chunks)
MAX_CHUNK_BYTES = 1 << 30
#: largest ratio of a chunk's declared decompressed size to its compressed length; zstd and
#: lz4 reach a few hundred on the most repetitive real logs
MAX_CHUNK_RATIO = 1000
#: below this declared size [bytes] the ratio is not checked (tiny chunks of repeated bytes)
_RATIO_FREE_BYTES = 1 << 20


def _decompress(chunk: Any, source: str) -> bytes:
    """The chunk's records, decompressed after checking its declared size against its own
    compressed length (a few KiB declaring hundreds of MiB is refused before any work) and
    checked to be exactly that size afterwards."""
    size = int(chunk.uncompressed_size)
    stored = len(chunk.data)
    if chunk.compression == "":
        if stored != size:
            raise LogFormatError(f"{source}: corrupt chunk (holds {stored} bytes, declares "
                                 f"{size})")
        return chunk.data
    if size > MAX_CHUNK_BYTES or (size > _RATIO_FREE_BYTES
                                  and size > MAX_CHUNK_RATIO * max(stored, 1)):
        raise LogFormatError(f"{source}: corrupt chunk ({stored} compressed bytes declare "
                             f"{size} bytes; at most {MAX_CHUNK_RATIO} times the compressed "
                             f"size and {MAX_CHUNK_BYTES >> 20} MiB)")
    if chunk.compression == "zstd":
        import zstandard

        declared = zstandard.frame_content_size(chunk.data)  # -1 when the frame omits it
        if declared not in (-1, size):
            raise LogFormatError(f"{source}: corrupt chunk (its zstd frame holds {declared} "
                                 f"bytes, the chunk declares {size})")
        data = zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=size)
    elif chunk.compression == "lz4":
        import lz4.frame

        decompressor = lz4.frame.LZ4FrameDecompressor()
        data = decompressor.decompress(chunk.data, max_length=size)
        if not decompressor.eof:
            raise LogFormatError(f"{source}: corrupt chunk (decompresses to more than the "
                                 f"{size} bytes it declares)")
    else:
        raise LogFormatError(f"{source}: unsupported chunk compression {chunk.compression!r}")
    if len(data) != size:
        raise LogFormatError(f"{source}: corrupt chunk (decompresses to {len(data)} bytes, "
                             f"declares {size})")
    return data


_SKIP = {0x07, 0x08, 0x0A, 0x0B, 0x0D, 0x0E, 0x0F}
"""Opcodes skipped unread: chunk/message/attachment/metadata indexes, statistics, summary
offsets, data end (parsing message indexes in Python would cost more than the decoding)."""


def _summary_counts(handle: Any) -> dict[int, int]:
    """Messages per channel id from the file's summary statistics, or {} (no summary, a file
    cut short, a damaged footer).  Only a sizing hint for the decoders: the records are still
    read sequentially and counted."""
    from mcap.reader import SeekingReader

    try:
        summary = SeekingReader(handle, validate_crcs=False).get_summary()
    except Exception:
        return {}
    if summary is None or summary.statistics is None:
        return {}
    return {int(k): int(v) for k, v in summary.statistics.channel_message_counts.items()}


def scan_mcap(path: str | Path, wanted: Any = None) -> LogScan:
    """Read ``path`` once; decode the topics for which ``wanted(topic, schema_name)`` is true
    (default: every topic with a registered decoder).

    Records are read sequentially (no seeking to the summary, so a file cut short is read up to
    the cut); chunks are decompressed one at a time and their CRC checked.  Raises
    LogFormatError (naming the file) for a file that is not MCAP, empty, corrupt, or truncated
    before any message.  A file cut short after some messages returns what was read with
    ``truncated=True``.
    """
    import os

    from mcap.data_stream import ReadDataStream
    from mcap.records import Attachment, Channel, Chunk, Header, Message, Metadata, Schema

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

    def truncated(what: str) -> None:
        scan.truncated = True
        scan.truncation = what

    readers = {0x01: Header, 0x03: Schema, 0x04: Channel, 0x05: Message, 0x06: Chunk,
               0x09: Attachment, 0x0C: Metadata}
    with path.open("rb") as handle:
        size = os.fstat(handle.fileno()).st_size
        scanner.counts = _summary_counts(handle)
        handle.seek(len(MCAP_MAGIC))
        while True:
            head = handle.read(9)
            if len(head) < 9:
                truncated(f"end of file at byte {handle.tell()} before the footer")
                break
            op, length = _RECORD.unpack(head)
            if op == 0x02:  # footer
                break
            if length > size - handle.tell():
                truncated(f"record of {length} bytes at byte {handle.tell() - 9} runs past the "
                          f"end of the file ({size} bytes)")
                break
            if op in _SKIP or op not in readers:
                handle.seek(length, 1)
                continue
            body = handle.read(length)
            try:
                record = readers[op].read(ReadDataStream(BytesIO(body)), length) \
                    if op == 0x05 else readers[op].read(ReadDataStream(BytesIO(body)))
            except Exception as exc:
                raise LogFormatError(f"{path}: corrupt MCAP record at byte "
                                     f"{handle.tell() - length - 9} ({type(exc).__name__}: "
                                     f"{exc})") from None
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
        flush()
    if scan.truncated and scan.n_messages == 0:
        raise LogFormatError(f"{path}: truncated MCAP file with no readable message")
    for decoder in scanner.decoders.values():
        if decoder is not None:
            scan.decoded[decoder.channel.topic] = decoder.result()
    return scan
