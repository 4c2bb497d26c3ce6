"""Per-topic message decoders, registered by ``(message_encoding, schema_name)``.

A decoder receives the messages of one channel a chunk at a time, as payload offsets into the
chunk's decompressed bytes, and keeps only decoded columns (never the raw payloads), so memory
is bounded by the decoded arrays.  :data:`DECODERS` is the registry the scanner consults; add an
entry to support another message type.
"""

from __future__ import annotations

import json
import logging
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import LogFormatError
from wholearm_tools.logs import cdr
from wholearm_tools.logs.schemas import FLOAT64_MULTI_ARRAY, GROUND_TRUTH, JOINT_STATE, STRING

log = logging.getLogger(__name__)

#: more distinct layouts than this within one chunk of one topic → decode message by message
MAX_LAYOUTS_PER_CHUNK = 8


@dataclass(frozen=True, slots=True)
class ChannelInfo:
    """What the scanner knows about a channel when it creates its decoder."""

    id: int
    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes


@dataclass(frozen=True, slots=True)
class JointStateColumns:
    """All JointState messages of a topic, in file order, as columns.

    ``names`` is the union of the joint names seen (first-appearance order);
    ``position, velocity, effort : (N, len(names))`` are NaN where a message did not carry the
    joint or the field.
    """

    names: tuple[str, ...]
    stamp_ns: NDArray[np.int64]
    log_time_ns: NDArray[np.int64]
    position: NDArray[np.float64]
    velocity: NDArray[np.float64]
    effort: NDArray[np.float64]
    fast_messages: int = 0
    """How many messages the vectorised path decoded (the rest went through the stock decoder)."""
    present: tuple[NDArray[np.bool_], NDArray[np.bool_], NDArray[np.bool_]] | None = None
    """Per field (position, velocity, effort), ``(N, len(names))`` True where the message
    carried the value (so a NaN there is a NaN in the data, not a missing value); None when
    every message carried every joint in every field."""

    @property
    def n_messages(self) -> int:
        return int(self.stamp_ns.shape[0])

    def carried(self, field: str) -> NDArray[np.bool_]:
        """``(N, len(names))`` True where the messages carried ``field`` ("position",
        "velocity" or "effort") for the joint."""
        k = ("position", "velocity", "effort").index(field)
        shape = (self.n_messages, len(self.names))
        if self.present is None:
            return np.broadcast_to(np.True_, shape)
        return self.present[k]


@dataclass(frozen=True, slots=True)
class ArrayColumns:
    """Float64MultiArray messages: ``data : (N, k)``, timed by the MCAP log time."""

    log_time_ns: NDArray[np.int64]
    data: NDArray[np.float64]

    @property
    def n_messages(self) -> int:
        return int(self.log_time_ns.shape[0])


@dataclass(frozen=True, slots=True)
class ValueList:
    """Small topics (robot description, ground truth): decoded values with their log times."""

    log_time_ns: tuple[int, ...]
    values: tuple[Any, ...]

    @property
    def n_messages(self) -> int:
        return len(self.values)


class TopicDecoder(ABC):
    """Base class: ``add`` one chunk's messages of the channel, ``result`` at the end."""

    def __init__(self, channel: ChannelInfo, source: str) -> None:
        self.channel = channel
        self.source = source

    def error(self, what: str) -> LogFormatError:
        return LogFormatError(f"{self.source}: topic {self.channel.topic!r}: {what}")

    def expect(self, count: int) -> None:  # noqa: B027 - optional hint
        """The file's summary says the channel has ``count`` messages (a sizing hint: a
        decoder may preallocate, but must still cope with more, fewer or none)."""

    @abstractmethod
    def add(self, buf: NDArray[np.uint8], starts: NDArray[np.int64], lengths: NDArray[np.int64],
            log_time: NDArray[np.int64]) -> None:
        """Take one chunk's messages of the channel (payload ``starts``/``lengths`` in ``buf``)."""

    @abstractmethod
    def result(self) -> Any:
        """The decoded topic, once every chunk has been added."""

    def payloads(self, buf: NDArray[np.uint8], starts: NDArray[np.int64],
                 lengths: NDArray[np.int64]) -> list[bytes]:
        raw = buf.data
        return [bytes(raw[s:s + n]) for s, n in zip(starts.tolist(), lengths.tolist(),
                                                     strict=True)]

    def stock_decoder(self) -> Callable[[bytes], Any]:
        from mcap.records import Schema
        from mcap_ros2.decoder import DecoderFactory

        schema = Schema(id=0, name=self.channel.schema_name,
                        encoding=self.channel.schema_encoding, data=self.channel.schema_data)
        decoder = DecoderFactory().decoder_for(self.channel.message_encoding, schema)
        if decoder is None:
            raise self.error(f"no decoder for schema {self.channel.schema_name!r} "
                             f"({self.channel.schema_encoding})")
        return decoder


# ---------------------------------------------------------------------------- JointState
class _Direct:
    """Final columns filled in place while every block has the first block's joints and
    fields, sized by the summary's message count (no blocks are kept, so the peak is the
    columns plus one chunk)."""

    def __init__(self, names: tuple[str, ...], carried: list[bool], count: int) -> None:
        self.names = names
        self.carried = carried
        self.count = count
        n = len(names)
        self.stamps = np.empty(count, np.int64)
        self.log_times = np.empty(count, np.int64)
        self.fields = [np.empty((count, n)) if c else None for c in carried]
        self.filled = np.zeros(count, dtype=bool)

    def accepts(self, names: tuple[str, ...], fields: list[NDArray], index: NDArray) -> bool:
        return (names == self.names and index.shape[0] > 0 and int(index.max()) < self.count
                and [f.shape[1] > 0 for f in fields] == self.carried)

    def write(self, index: NDArray[np.int64], stamp: NDArray, log_time: NDArray,
              fields: list[NDArray]) -> None:
        rows = _as_rows(index)
        self.stamps[rows] = stamp
        self.log_times[rows] = log_time
        self.filled[rows] = True
        for target, arr in zip(self.fields, fields, strict=True):
            if target is not None:
                target[rows] = arr

    def block(self) -> tuple[tuple[str, ...], NDArray, NDArray, NDArray, list[NDArray]]:
        """What was written so far, as one ordinary block."""
        rows = np.flatnonzero(self.filled)
        empty = np.zeros((rows.shape[0], 0))
        return (self.names, rows, self.stamps[rows], self.log_times[rows],
                [empty if f is None else f[rows] for f in self.fields])


def _as_rows(index: NDArray[np.int64]) -> slice | NDArray[np.int64]:
    """``index`` as a slice when it is a run of consecutive rows (a cheap, copy-free write)."""
    k = index.shape[0]
    if k and int(index[-1]) - int(index[0]) == k - 1 and np.all(np.diff(index) == 1):
        return slice(int(index[0]), int(index[0]) + k)
    return index


def _missing(rows: int, cols: int) -> NDArray[np.float64]:
    """A field no message carries: NaN everywhere, as a read-only broadcast (no memory)."""
    return np.broadcast_to(np.float64(np.nan), (rows, cols))


class _JointStateAccumulator(TopicDecoder):
    """Collects blocks ``(names, message indices, stamp, log_time, [position, velocity,
    effort])``; ``result`` scatters them back into file order.  With the summary's message
    count (``expect``) the blocks are written straight into the final columns instead, for as
    long as every block has the first block's joints and fields."""

    def __init__(self, channel: ChannelInfo, source: str) -> None:
        super().__init__(channel, source)
        self.blocks: list[tuple[tuple[str, ...], NDArray, NDArray, NDArray, list[NDArray]]] = []
        self.fast = 0
        self.count = 0
        self._expected = 0
        self._direct: _Direct | None = None

    def expect(self, count: int) -> None:
        self._expected = int(count)

    def add_block(self, names: tuple[str, ...], index: NDArray[np.int64], stamp: NDArray,
                  log_time: NDArray, fields: list[NDArray]) -> None:
        n = len(names)
        for label, arr in zip(("position", "velocity", "effort"), fields, strict=True):
            if arr.shape[1] not in (0, n):
                raise self.error(f"message {int(index[0])} has {n} names but {arr.shape[1]} "
                                 f"{label} values")
        if (self._direct is None and not self.blocks and self._expected
                and len(set(names)) == n):
            self._direct = _Direct(names, [f.shape[1] > 0 for f in fields], self._expected)
        if self._direct is not None:
            if self._direct.accepts(names, fields, index):
                self._direct.write(index, stamp, log_time, fields)
                return
            self.blocks.append(self._direct.block())  # a new layout: back to blocks
            self._direct = None
        self.blocks.append((names, index, stamp, log_time, fields))

    def result(self) -> JointStateColumns:
        d = self._direct
        if d is not None and self.count == d.count and d.filled.all():
            self._direct = None
            present = None if all(d.carried) else tuple(
                np.broadcast_to(np.bool_(c), (d.count, len(d.names))) for c in d.carried)
            return JointStateColumns(d.names, d.stamps, d.log_times,
                                     *(_missing(d.count, len(d.names)) if f is None else f
                                       for f in d.fields), fast_messages=self.fast,
                                     present=present)
        if d is not None:  # fewer messages than the summary said
            self.blocks.append(d.block())
            self._direct = None
        names: list[str] = []
        for block_names, *_ in self.blocks:
            names.extend(x for x in block_names if x not in names)
        lookup = {name: i for i, name in enumerate(names)}
        total = self.count
        carried = [any(block[4][k].shape[1] for block in self.blocks) for k in range(3)]
        out = [np.full((total, len(names)), np.nan) if c else None for c in carried]
        present = [np.zeros((total, len(names)), dtype=bool) for _ in range(3)]
        stamps = np.zeros(total, np.int64)
        log_times = np.zeros(total, np.int64)
        filled = np.zeros(total, dtype=bool)
        self.blocks.reverse()
        while self.blocks:  # release each block once copied
            block_names, index, stamp, log_time, fields = self.blocks.pop()
            cols = [lookup[x] for x in block_names]
            rows = _as_rows(index)
            stamps[rows] = stamp
            log_times[rows] = log_time
            filled[rows] = True
            for target, arr, mark in zip(out, fields, present, strict=True):
                if target is None or arr.shape[1] == 0:
                    continue
                if cols == list(range(len(names))):
                    target[rows] = arr
                    mark[rows] = True
                elif isinstance(rows, slice):
                    target[rows, np.asarray(cols)] = arr
                    mark[rows, np.asarray(cols)] = True
                else:
                    target[np.ix_(rows, np.asarray(cols))] = arr
                    mark[np.ix_(rows, np.asarray(cols))] = True
        if not filled.all():  # pragma: no cover - every message lands in exactly one block
            raise self.error("internal error: messages lost while decoding")
        position, velocity, effort = (_missing(total, len(names)) if a is None else a
                                      for a in out)
        complete = all(bool(m.all()) for m in present)
        return JointStateColumns(tuple(names), stamps, log_times, position, velocity, effort,
                                 fast_messages=self.fast,
                                 present=None if complete else (present[0], present[1],
                                                                present[2]))


def _rows(buf: NDArray[np.uint8], starts: NDArray[np.int64], length: int) -> NDArray[np.uint8]:
    """``(k, length)`` matrix of payloads; a zero-copy strided view when evenly spaced."""
    if starts.shape[0] > 1:
        steps = np.diff(starts)
        if steps[0] >= length and np.all(steps == steps[0]):
            base = buf[int(starts[0]):]
            return np.lib.stride_tricks.as_strided(
                base, shape=(starts.shape[0], length), strides=(int(steps[0]), 1),
                writeable=False)
    return buf[starts[:, None] + np.arange(length)]


class CdrJointStateDecoder(_JointStateAccumulator):
    """CDR JointState: numpy over every group of same-layout messages, stock decoder otherwise."""

    def __init__(self, channel: ChannelInfo, source: str) -> None:
        super().__init__(channel, source)
        self.layouts: dict[int, list[cdr.JointStateLayout]] = {}
        self._stock: Callable[[bytes], Any] | None = None

    def add(self, buf: NDArray[np.uint8], starts: NDArray[np.int64], lengths: NDArray[np.int64],
            log_time: NDArray[np.int64]) -> None:
        base_index = self.count
        self.count += starts.shape[0]
        if lengths.shape[0] and lengths.min() == lengths.max():
            groups = [(int(lengths[0]), np.arange(lengths.shape[0]))]
        else:
            uniq, inverse = np.unique(lengths, return_inverse=True)
            groups = [(int(u), np.flatnonzero(inverse == i)) for i, u in enumerate(uniq)]
        for length, members in groups:
            rows = _rows(buf, starts[members], length)
            todo = np.ones(members.shape[0], dtype=bool)
            known = self.layouts.setdefault(length, [])
            tried = 0
            while todo.any() and tried <= MAX_LAYOUTS_PER_CHUNK:
                if tried < len(known):
                    layout = known[tried]
                else:
                    first = int(np.flatnonzero(todo)[0])
                    try:
                        layout = cdr.joint_state_layout(rows[first].tobytes())
                    except ValueError:
                        break
                    known.append(layout)
                tried += 1
                hit = todo & cdr.matches_layout(rows, layout)
                if not hit.any():
                    continue
                sel = np.flatnonzero(hit)
                batch = cdr.decode_joint_states(rows[sel] if sel.shape[0] < rows.shape[0]
                                                else rows, layout)
                self.add_block(layout.names, base_index + members[sel], batch.stamp_ns,
                               log_time[members[sel]],
                               [batch.position, batch.velocity, batch.effort])
                self.fast += sel.shape[0]
                todo &= ~hit
            for i in np.flatnonzero(todo).tolist():
                j = int(members[i])
                self._decode_stock(bytes(rows[i]), int(log_time[j]), base_index + j)

    def _decode_stock(self, data: bytes, log_time: int, index: int) -> None:
        if self._stock is None:
            self._stock = self.stock_decoder()
        try:
            msg = self._stock(data)
            stamp = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
            names = tuple(str(x) for x in msg.name)
            fields = [np.asarray(v, dtype=float).reshape(1, -1)
                      for v in (msg.position, msg.velocity, msg.effort)]
        except LogFormatError:
            raise
        except Exception as exc:
            raise self.error(f"message {index} cannot be decoded as {JOINT_STATE} "
                             f"({exc})") from None
        self.add_block(names, np.array([index], np.int64), np.array([stamp], np.int64),
                       np.array([log_time], np.int64), fields)


def _json_list(decoder: TopicDecoder, buf: NDArray[np.uint8], starts: NDArray[np.int64],
               lengths: NDArray[np.int64]) -> list[Any]:
    """All payloads of a chunk parsed by one ``json.loads`` call."""
    text = b"[" + b",".join(decoder.payloads(buf, starts, lengths)) + b"]"
    try:
        values = json.loads(text)
    except RecursionError:
        raise decoder.error("a JSON message is nested too deeply") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise decoder.error(f"invalid JSON message ({exc})") from None
    if len(values) != starts.shape[0]:  # pragma: no cover - a payload holding "1,2"
        raise decoder.error("a JSON message holds more than one value")
    return values


class JsonJointStateDecoder(_JointStateAccumulator):
    """JSON JointState (ROS field names), grouped by joint names into column blocks."""

    def add(self, buf: NDArray[np.uint8], starts: NDArray[np.int64], lengths: NDArray[np.int64],
            log_time: NDArray[np.int64]) -> None:
        values = _json_list(self, buf, starts, lengths)
        groups: dict[tuple[Any, ...], list[int]] = {}
        try:
            for i, msg in enumerate(values):
                key = (tuple(msg["name"]), len(msg.get("position") or ()),
                       len(msg.get("velocity") or ()), len(msg.get("effort") or ()))
                groups.setdefault(key, []).append(i)
            for (names, *_), members in groups.items():
                msgs = [values[i] for i in members]
                stamp = np.array([int(m["header"]["stamp"]["sec"]) * 1_000_000_000
                                  + int(m["header"]["stamp"]["nanosec"]) for m in msgs], np.int64)
                fields = [np.array([m.get(f) or [] for m in msgs], dtype=float).reshape(
                    len(msgs), -1) for f in ("position", "velocity", "effort")]
                self.add_block(tuple(str(x) for x in names),
                               self.count + np.asarray(members, np.int64), stamp,
                               log_time[members], fields)
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, LogFormatError):
                raise
            raise self.error(f"JSON message is not a {JOINT_STATE} ({exc!r})") from None
        self.fast += len(values)
        self.count += len(values)


# ---------------------------------------------------------------------------- small topics
class _ArrayDecoder(TopicDecoder):
    def __init__(self, channel: ChannelInfo, source: str) -> None:
        super().__init__(channel, source)
        self.times: list[NDArray[np.int64]] = []
        self.rows: list[list[float]] = []

    def result(self) -> ArrayColumns:
        lengths = {len(r) for r in self.rows}
        if len(lengths) > 1:
            raise self.error(f"Float64MultiArray messages have different lengths {sorted(lengths)}")
        times = np.concatenate(self.times) if self.times else np.zeros(0, np.int64)
        data = np.array(self.rows, dtype=float).reshape(len(self.rows), -1)
        return ArrayColumns(times, data)


class CdrArrayDecoder(_ArrayDecoder):
    """CDR Float64MultiArray through the stock decoder (command topics are small)."""

    def add(self, buf: NDArray[np.uint8], starts: NDArray[np.int64], lengths: NDArray[np.int64],
            log_time: NDArray[np.int64]) -> None:
        decode = self.stock_decoder()
        for i, data in enumerate(self.payloads(buf, starts, lengths)):
            try:
                self.rows.append([float(x) for x in decode(data).data])
            except Exception as exc:
                raise self.error(f"message {len(self.rows) + i} cannot be decoded as "
                                 f"{FLOAT64_MULTI_ARRAY} ({exc})") from None
        self.times.append(np.asarray(log_time, np.int64).copy())


class JsonArrayDecoder(_ArrayDecoder):
    def add(self, buf: NDArray[np.uint8], starts: NDArray[np.int64], lengths: NDArray[np.int64],
            log_time: NDArray[np.int64]) -> None:
        try:
            self.rows.extend([float(x) for x in m["data"]]
                             for m in _json_list(self, buf, starts, lengths))
        except (KeyError, TypeError, ValueError) as exc:
            raise self.error(f"JSON message is not a {FLOAT64_MULTI_ARRAY} ({exc!r})") from None
        self.times.append(np.asarray(log_time, np.int64).copy())


class _ValueDecoder(TopicDecoder):
    def __init__(self, channel: ChannelInfo, source: str) -> None:
        super().__init__(channel, source)
        self.times: list[int] = []
        self.values: list[Any] = []

    def result(self) -> ValueList:
        return ValueList(tuple(self.times), tuple(self.values))


class CdrStringDecoder(_ValueDecoder):
    def add(self, buf: NDArray[np.uint8], starts: NDArray[np.int64], lengths: NDArray[np.int64],
            log_time: NDArray[np.int64]) -> None:
        decode = self.stock_decoder()
        for data in self.payloads(buf, starts, lengths):
            try:
                self.values.append(str(decode(data).data))
            except Exception as exc:
                raise self.error(f"message cannot be decoded as {STRING} ({exc})") from None
        self.times.extend(log_time.tolist())


class JsonStringDecoder(_ValueDecoder):
    def add(self, buf: NDArray[np.uint8], starts: NDArray[np.int64], lengths: NDArray[np.int64],
            log_time: NDArray[np.int64]) -> None:
        try:
            self.values.extend(str(m["data"]) for m in _json_list(self, buf, starts, lengths))
        except (KeyError, TypeError) as exc:
            raise self.error(f"JSON message is not a {STRING} ({exc!r})") from None
        self.times.extend(log_time.tolist())


class JsonObjectDecoder(_ValueDecoder):
    def add(self, buf: NDArray[np.uint8], starts: NDArray[np.int64], lengths: NDArray[np.int64],
            log_time: NDArray[np.int64]) -> None:
        self.values.extend(_json_list(self, buf, starts, lengths))
        self.times.extend(log_time.tolist())


DECODERS: dict[tuple[str, str], type[TopicDecoder]] = {
    ("cdr", JOINT_STATE): CdrJointStateDecoder,
    ("json", JOINT_STATE): JsonJointStateDecoder,
    ("cdr", FLOAT64_MULTI_ARRAY): CdrArrayDecoder,
    ("json", FLOAT64_MULTI_ARRAY): JsonArrayDecoder,
    ("cdr", STRING): CdrStringDecoder,
    ("json", STRING): JsonStringDecoder,
    ("json", GROUND_TRUTH): JsonObjectDecoder,
}
"""Decoder class by ``(message_encoding, schema_name)``."""
