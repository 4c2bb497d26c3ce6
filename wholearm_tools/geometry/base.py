"""The primitive contract shared by the simulator, the fitter and the mesher.

Conventions (written once, used everywhere):

* Points are arrays of shape ``(N, d)`` with ``d = Primitive.dim`` (2 for planar primitives,
  3 for spatial ones); a single point ``(d,)`` is accepted and returns a scalar-shaped result
  (a 0-d value for distances, a ``(d,)`` vector for gradients and closest points).
* ``signed_distance`` is the Euclidean signed distance to the *surface*.  Its sign follows the
  primitive's canonical orientation: for closed shapes (circle, sphere, cylinder, cone, torus)
  negative inside the enclosed volume, positive outside; for lines and planes positive on the side
  the normal points to (a 2-D line's normal is its direction rotated by +90 degrees).
* The environment (``wholearm_tools.sim``) decides which side is free space with a ``free_side``
  of +1 or -1: clearance = ``free_side * signed_distance``.
* ``params()`` returns the map.json parameter names of ARCHITECTURE.md (line ``point,
  direction``; circle ``center, radius``; plane ``point, normal``; sphere ``center, radius``;
  cylinder ``point, axis, radius``; cone ``apex, axis, half_angle``; torus ``center, axis,
  major_radius, minor_radius``) as numpy arrays / floats, and ``from_params`` inverts it.

Every concrete type registers itself in :data:`PRIMITIVE_TYPES` with :func:`register`, so the
rest of the code looks types up by name instead of branching on them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from typing import Any, ClassVar, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wholearm_tools.errors import InputError

FloatArray = NDArray[np.float64]

PRIMITIVE_TYPES: dict[str, type[Primitive]] = {}

P = TypeVar("P", bound="type[Primitive]")


def register(cls: P) -> P:
    """Class decorator: add a primitive type to :data:`PRIMITIVE_TYPES` under ``cls.kind``."""
    if cls.kind in PRIMITIVE_TYPES:
        raise RuntimeError(f"primitive type {cls.kind!r} registered twice")
    PRIMITIVE_TYPES[cls.kind] = cls
    return cls


def primitive_type(kind: str) -> type[Primitive]:
    """Look up a registered primitive type by name (``"circle"``, ``"cylinder"``, ...)."""
    try:
        return PRIMITIVE_TYPES[kind]
    except KeyError:
        known = ", ".join(sorted(PRIMITIVE_TYPES))
        raise InputError(f"unknown primitive type {kind!r} (known: {known})") from None


def as_points(points: ArrayLike, dim: int, name: str = "points") -> FloatArray:
    """Validate and return ``points`` as a float array of shape ``(N, dim)``."""
    arr = np.asarray(points, dtype=float)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise InputError(f"expected {name} of shape (N, {dim}), got {np.shape(points)}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contain NaN or infinite values")
    return arr


class Primitive(ABC):
    """A geometric primitive surface (abstract).  Concrete types are frozen dataclasses."""

    kind: ClassVar[str]
    dim: ClassVar[int]
    #: number of free parameters (degrees of freedom), used by model selection
    dof: ClassVar[int]

    @abstractmethod
    def signed_distance(self, points: ArrayLike) -> FloatArray:
        """Signed Euclidean distance of ``points (N, dim)`` to the surface, shape ``(N,)``."""

    @abstractmethod
    def gradient(self, points: ArrayLike) -> FloatArray:
        """Unit gradient of the signed distance at ``points``, shape ``(N, dim)``."""

    @abstractmethod
    def closest_point(self, points: ArrayLike) -> FloatArray:
        """Closest surface point to each of ``points``, shape ``(N, dim)``."""

    @abstractmethod
    def params(self) -> dict[str, Any]:
        """Parameters under their map.json names (arrays and floats)."""

    @classmethod
    @abstractmethod
    def from_params(cls, params: Mapping[str, Any]) -> Primitive:
        """Build the primitive from :meth:`params` output (or its JSON form)."""

    def distance(self, points: ArrayLike) -> FloatArray:
        """Unsigned distance of ``points`` to the surface, shape ``(N,)``."""
        return np.abs(self.signed_distance(points))

    def segment_signed_distance(
        self, a: ArrayLike, b: ArrayLike, free_side: float = 1.0
    ) -> tuple[FloatArray, FloatArray]:
        """Smallest clearance ``free_side * signed_distance`` over each segment ``a[i]–b[i]``.

        Returns ``(clearance (N,), t (N,))`` with ``t in [0, 1]`` the parameter of the segment point
        that attains it.  The default samples and refines numerically (see
        :func:`segment_min_numeric`); types override it with a closed form where one exists.
        Capsule clearance = this minus the capsule radius.  ``free_side`` must be +1 or -1.
        """
        fs = check_free_side(free_side)
        a_, b_, single = as_segments(a, b, self.dim)
        sd = getattr(self, "_sd", None)
        fn = (lambda p: fs * sd(p)) if sd is not None else (
            lambda p: fs * self.signed_distance(p))
        val, t = segment_min_numeric(fn, a_, b_)
        return squeeze2(val, t, single)


# --------------------------------------------------------------------------- shared helpers


def check_free_side(free_side: float) -> float:
    """Return ``free_side`` as ``+1.0`` or ``-1.0``; anything else is an :class:`InputError`."""
    fs = float(free_side)
    if fs not in (1.0, -1.0):
        raise InputError(f"free_side must be +1 or -1, got {free_side!r}")
    return fs


def as_segments(a: ArrayLike, b: ArrayLike, dim: int) -> tuple[FloatArray, FloatArray, bool]:
    """Validate segment end points; returns ``(a (N, dim), b (N, dim), single)``.

    ``single`` is true when both were given as one point ``(dim,)`` (results are then squeezed).
    A single start (or end) is broadcast against ``N`` ends (or starts).
    """
    single = np.ndim(a) == 1 and np.ndim(b) == 1
    a_ = as_points(a, dim, "segment starts")
    b_ = as_points(b, dim, "segment ends")
    if a_.shape[0] != b_.shape[0]:
        if a_.shape[0] == 1:
            a_ = np.broadcast_to(a_, b_.shape)
        elif b_.shape[0] == 1:
            b_ = np.broadcast_to(b_, a_.shape)
        else:
            raise InputError(
                f"segment starts and ends differ in number: {a_.shape[0]} vs {b_.shape[0]}")
    return a_, b_, single


def squeeze1(values: FloatArray, single: bool) -> FloatArray:
    """Drop the leading axis of a per-point result when the input was one point."""
    return values[0] if single else values


def squeeze2(
    values: FloatArray, t: FloatArray, single: bool
) -> tuple[FloatArray, FloatArray]:
    """:func:`squeeze1` for a ``(clearance, t)`` pair."""
    return (values[0], t[0]) if single else (values, t)


def segment_min_numeric(
    fn: Callable[[FloatArray], FloatArray], a: FloatArray, b: FloatArray,
    samples: int = 33, levels: int = 3, points_per_level: int = 65,
) -> tuple[FloatArray, FloatArray]:
    """Minimise ``fn`` along the segments ``a[i]–b[i]`` (validated ``(N, d)`` arrays).

    ``fn`` maps ``(M, d)`` points to ``(M,)`` values.  The segments are sampled at ``samples``
    evenly spaced parameters, then the best sample's neighbourhood ``[t - h, t + h]`` (``h`` one
    sample spacing) is resampled ``levels`` times with ``points_per_level`` points, the bracket
    shrinking by ``(points_per_level - 1) / 2`` each time (32x with the defaults, so the final
    half-bracket is ``1/32 / 32**3 ~ 1e-6`` of the segment).  Every level is one vectorised ``fn``
    call (four calls in all): for small ``N`` the cost is the number of calls, not of points.

    Guarantees: for a function that is unimodal along the segment (e.g. a convex signed distance)
    the global minimum is found to the final bracket.  Otherwise the local minimum around the best
    initial sample is found; since distance-like functions are 1-Lipschitz, the global minimum is
    missed by at most half a sample spacing times the segment length (``|b - a| / 64``), and only
    when two separate basins are that close in value.

    Returns ``(min value (N,), t (N,))``.
    """
    n, dim = a.shape
    d = b - a
    ts = np.linspace(0.0, 1.0, samples)
    pts = a[:, None, :] + ts[None, :, None] * d[:, None, :]
    vals = fn(pts.reshape(-1, dim)).reshape(n, samples)
    rows = np.arange(n)
    k = np.argmin(vals, axis=1)
    best_t = ts[k]
    best_v = vals[rows, k]
    h = 1.0 / (samples - 1)
    offsets = np.linspace(-1.0, 1.0, points_per_level)
    shrink = 2.0 / (points_per_level - 1)
    for _ in range(levels):
        tt = np.clip(best_t[:, None] + h * offsets[None, :], 0.0, 1.0)
        pts = a[:, None, :] + tt[:, :, None] * d[:, None, :]
        vv = fn(pts.reshape(-1, dim)).reshape(n, points_per_level)
        k = np.argmin(vv, axis=1)
        better = vv[rows, k] <= best_v
        best_t = np.where(better, tt[rows, k], best_t)
        best_v = np.where(better, vv[rows, k], best_v)
        h *= shrink
    return best_v, best_t


def endpoint_min(va: FloatArray, vb: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Minimum of two end-point values and its parameter (0 at ``a``, 1 at ``b``).

    Exact for clearances that are concave along a segment (linear for planes and lines, the
    interior side of convex shapes), whose minimum over ``[0, 1]`` is at an end point.
    """
    at_b = vb < va
    return np.where(at_b, vb, va), at_b.astype(float)


def unit_vector(v: ArrayLike, dim: int, name: str) -> FloatArray:
    """Validate a direction of length ``dim`` and return it normalised and read-only."""
    arr = np.array(v, dtype=float)
    if arr.shape != (dim,):
        raise InputError(f"expected {name} of shape ({dim},), got {np.shape(v)}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} must be finite, got {arr.tolist()}")
    norm = float(np.linalg.norm(arr))
    if norm < 1e-12:
        raise InputError(f"{name} must be a non-zero vector, got {arr.tolist()}")
    arr /= norm
    arr.flags.writeable = False
    return arr


def fixed_point(v: ArrayLike, dim: int, name: str) -> FloatArray:
    """Validate a point of length ``dim`` and return it as a read-only float array."""
    arr = np.array(v, dtype=float)
    if arr.shape != (dim,):
        raise InputError(f"expected {name} of shape ({dim},), got {np.shape(v)}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} must be finite, got {arr.tolist()}")
    arr.flags.writeable = False
    return arr


def positive_float(v: Any, name: str) -> float:
    """Validate a finite, strictly positive scalar."""
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {v!r}") from None
    if not np.isfinite(x) or x <= 0.0:
        raise InputError(f"{name} must be finite and > 0, got {v!r}")
    return x


def perpendicular(u: FloatArray) -> FloatArray:
    """A deterministic unit vector perpendicular to the unit 3-vector ``u`` (read-only)."""
    e = np.zeros(3)
    e[int(np.argmin(np.abs(u)))] = 1.0
    w = np.cross(u, e)
    w /= np.linalg.norm(w)
    w.flags.writeable = False
    return w


def params_to_json(params: Mapping[str, Any]) -> dict[str, Any]:
    """Parameters with arrays turned into lists and numpy scalars into floats (JSON-ready)."""
    out: dict[str, Any] = {}
    for key, value in params.items():
        if isinstance(value, np.ndarray):
            out[key] = value.tolist()
        elif isinstance(value, np.generic):
            out[key] = value.item()
        else:
            out[key] = value
    return out


def primitive_to_dict(primitive: Primitive) -> dict[str, Any]:
    """``{"type": kind, "params": {...}}`` with JSON-ready parameters."""
    return {"type": primitive.kind, "params": params_to_json(primitive.params())}


def primitive_from_dict(data: Mapping[str, Any]) -> Primitive:
    """Inverse of :func:`primitive_to_dict` (looks the type up in :data:`PRIMITIVE_TYPES`)."""
    try:
        kind, params = data["type"], data["params"]
    except (KeyError, TypeError):
        raise InputError(
            f"expected a primitive as {{'type': ..., 'params': ...}}, got {data!r}") from None
    return primitive_type(str(kind)).from_params(params)
