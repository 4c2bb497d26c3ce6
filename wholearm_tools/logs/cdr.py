"""Vectorised CDR (little-endian XCDR1, the ROS 2 default) for ``sensor_msgs/msg/JointState``.

A log holds tens of thousands of JointState messages that all share one *layout*: the same
``frame_id``, the same joint names and the same array lengths.  Such messages differ only in the
stamp and the float64 values, which sit at fixed byte offsets.  So one message is parsed in
Python (:func:`joint_state_layout`) and every message of the same layout is encoded or decoded in
one numpy pass over an ``(N, L)`` byte matrix.

CDR rules used (as ``mcap_ros2``'s encoder and decoder apply them): a 4-byte encapsulation
header, then fields aligned to their size counted from the end of that header; strings are a
uint32 length (including the NUL) followed by the bytes and a NUL; sequences are a uint32 count
then the elements, and a float64 element is aligned to 8 (so an *empty* float64 sequence adds no
alignment padding).  Padding bytes may hold anything on input (real rigs leave garbage there);
trailing bytes after the last field are ignored (some rigs append 8).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

CDR_LE = b"\x00\x01\x00\x00"
_FIELDS = ("position", "velocity", "effort")


def _align(offset: int, size: int) -> int:
    return offset + (-(offset - 4)) % size


@dataclass(frozen=True, slots=True)
class JointStateLayout:
    """Byte layout shared by JointState messages with the same frame_id, names and lengths.

    Parameters
    ----------
    size : int, bytes used by the fields (a payload may be longer: trailing bytes are ignored)
    frame_id : str
    names : tuple of str
    counts : (3,) int, lengths of position, velocity, effort
    offsets : (3,) int, byte offset of the first element of each float64 array
    structure : (S,) int, byte offsets that must equal ``template`` for a payload to have this
        layout (encapsulation header, string lengths and contents, sequence counts; not padding)
    template : (size,) uint8, a payload of this layout with zero stamp and zero values
    """

    size: int
    frame_id: str
    names: tuple[str, ...]
    counts: tuple[int, int, int]
    offsets: tuple[int, int, int]
    structure: NDArray[np.intp]
    template: NDArray[np.uint8]


class _Builder:
    """Builds a template payload and records which bytes are structural."""

    def __init__(self) -> None:
        self.buf = bytearray(CDR_LE)
        self.structural: list[int] = [0, 1, 2, 3]

    def pad(self, size: int) -> None:
        self.buf += b"\x00" * (_align(len(self.buf), size) - len(self.buf))

    def uint32(self, value: int, structural: bool = True) -> None:
        self.pad(4)
        if structural:
            self.structural.extend(range(len(self.buf), len(self.buf) + 4))
        self.buf += struct.pack("<I", value)

    def string(self, text: str) -> None:
        data = text.encode("utf-8") + b"\x00"
        self.uint32(len(data))
        self.structural.extend(range(len(self.buf), len(self.buf) + len(data)))
        self.buf += data

    def float64s(self, count: int) -> int:
        self.uint32(count)
        if count:
            self.pad(8)
        start = len(self.buf)
        self.buf += b"\x00" * (8 * count)
        return start


def make_joint_state_layout(
    names: tuple[str, ...], counts: tuple[int, int, int], frame_id: str = ""
) -> JointStateLayout:
    """Layout of a JointState with these names, array lengths and frame_id."""
    b = _Builder()
    b.uint32(0, structural=False)  # stamp.sec
    b.uint32(0, structural=False)  # stamp.nanosec
    b.string(frame_id)
    b.uint32(len(names))
    for name in names:
        b.string(name)
    offsets = tuple(b.float64s(c) for c in counts)
    template = np.frombuffer(bytes(b.buf), dtype=np.uint8)
    return JointStateLayout(
        size=len(b.buf), frame_id=frame_id, names=tuple(names),
        counts=(int(counts[0]), int(counts[1]), int(counts[2])),
        offsets=(offsets[0], offsets[1], offsets[2]),
        structure=np.array(b.structural, dtype=np.intp), template=template,
    )


def joint_state_layout(payload: bytes | memoryview) -> JointStateLayout:
    """Parse one little-endian CDR JointState payload into its layout.

    Raises ``ValueError`` for a payload that is not little-endian CDR or is cut short.
    """
    data = bytes(payload)
    if data[:2] != CDR_LE[:2]:
        raise ValueError(f"not little-endian CDR (encapsulation {data[:4].hex()})")
    try:
        off = 12
        (length,) = struct.unpack_from("<I", data, off)
        frame_id = data[off + 4: off + 4 + length - 1].decode("utf-8")
        off = _align(off + 4 + length, 4)
        (count,) = struct.unpack_from("<I", data, off)
        off += 4
        names = []
        for _ in range(count):
            off = _align(off, 4)
            (length,) = struct.unpack_from("<I", data, off)
            if length == 0 or off + 4 + length > len(data):
                raise ValueError("bad string length")
            names.append(data[off + 4: off + 4 + length - 1].decode("utf-8"))
            off += 4 + length
        counts = []
        for _ in _FIELDS:
            off = _align(off, 4)
            (count,) = struct.unpack_from("<I", data, off)
            off += 4
            if count:
                off = _align(off, 8) + 8 * count
            counts.append(count)
    except struct.error as exc:
        raise ValueError(f"payload of {len(data)} bytes is cut short ({exc})") from None
    if off > len(data):
        raise ValueError(f"payload of {len(data)} bytes is cut short (needs {off})")
    layout = make_joint_state_layout(tuple(names), (counts[0], counts[1], counts[2]), frame_id)
    if layout.size != off:  # pragma: no cover - the builder and the parser follow the same rules
        raise ValueError("inconsistent JointState layout")
    return layout


@dataclass(frozen=True, slots=True)
class JointStateBatch:
    """Decoded columns of N JointState messages sharing one layout.

    ``stamp_ns : (N,) int64``; ``position, velocity, effort : (N, k) float64`` with ``k`` the
    field's count in the layout (0 when the field is empty).
    """

    layout: JointStateLayout
    stamp_ns: NDArray[np.int64]
    position: NDArray[np.float64]
    velocity: NDArray[np.float64]
    effort: NDArray[np.float64]


def matches_layout(rows: NDArray[np.uint8], layout: JointStateLayout) -> NDArray[np.bool_]:
    """Which rows of an ``(N, L)`` payload matrix (L >= layout.size) have exactly ``layout``."""
    s = layout.structure
    return np.all(rows[:, s] == layout.template[s], axis=1)


def decode_joint_states(rows: NDArray[np.uint8], layout: JointStateLayout) -> JointStateBatch:
    """Decode an ``(N, L)`` uint8 matrix of payloads that all have ``layout`` (not checked here;
    see :func:`matches_layout`)."""
    n = rows.shape[0]

    def column(start: int, count: int, dtype: str) -> NDArray:
        if count == 0:
            # (an empty slice counts as contiguous, so ascontiguousarray would return a view
            # that keeps the whole decompressed chunk alive)
            return np.zeros((n, 0), dtype)
        width = count * np.dtype(dtype).itemsize
        block = np.ascontiguousarray(rows[:, start:start + width])
        return block.view(dtype).reshape(n, count)

    sec = column(4, 1, "<i4")[:, 0].astype(np.int64)
    nanosec = column(8, 1, "<u4")[:, 0].astype(np.int64)
    arrays = [column(off, c, "<f8").astype(np.float64, copy=False)
              for off, c in zip(layout.offsets, layout.counts, strict=True)]
    return JointStateBatch(layout, sec * 1_000_000_000 + nanosec, *arrays)


def encode_joint_states(
    stamp_ns: NDArray[np.int64],
    names: tuple[str, ...],
    position: NDArray[np.float64] | None = None,
    velocity: NDArray[np.float64] | None = None,
    effort: NDArray[np.float64] | None = None,
    frame_id: str = "",
) -> NDArray[np.uint8]:
    """Encode N JointState messages at once into an ``(N, L)`` uint8 matrix (row i = payload i).

    ``stamp_ns : (N,) int``; each of ``position, velocity, effort`` is ``(N, k)`` or None
    (an empty array in every message).  Byte-identical to ``mcap_ros2``'s encoder.
    """
    stamp_ns = np.asarray(stamp_ns, dtype=np.int64).reshape(-1)
    n = stamp_ns.shape[0]
    fields = []
    for name, value in zip(_FIELDS, (position, velocity, effort), strict=True):
        arr = np.zeros((n, 0)) if value is None else np.asarray(value, dtype="<f8")
        if arr.ndim != 2 or arr.shape[0] != n:
            raise ValueError(f"expected {name} of shape ({n}, k), got {arr.shape}")
        fields.append(arr)
    layout = make_joint_state_layout(tuple(names), tuple(f.shape[1] for f in fields), frame_id)
    sec, nanosec = np.divmod(stamp_ns, 1_000_000_000)
    if n and (sec.min() < -(2**31) or sec.max() >= 2**31):
        raise ValueError("stamp seconds out of the int32 range of builtin_interfaces/Time")
    out = np.empty((n, layout.size), dtype=np.uint8)
    out[:] = layout.template
    out[:, 4:8] = sec.astype("<i4").view(np.uint8).reshape(n, 4)
    out[:, 8:12] = nanosec.astype("<u4").view(np.uint8).reshape(n, 4)
    for off, arr in zip(layout.offsets, fields, strict=True):
        width = 8 * arr.shape[1]
        out[:, off:off + width] = np.ascontiguousarray(arr, dtype="<f8").view(np.uint8).reshape(
            n, width)
    return out
