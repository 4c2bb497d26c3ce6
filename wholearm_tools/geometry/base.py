"""The primitive contract shared by the simulator, the fitter and the mesher.

Conventions (written once, used everywhere):

* Points are arrays of shape ``(N, d)`` with ``d = Primitive.dim`` (2 for planar primitives,
  3 for spatial ones); a single point ``(d,)`` is accepted and returns a scalar-shaped result.
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
        that attains it.  The default samples and refines numerically; types override it with a
        closed form where one exists.  Capsule clearance = this minus the capsule radius.
        """
        return _segment_min_numeric(
            lambda p: free_side * self.signed_distance(p), a, b, self.dim
        )


def _segment_min_numeric(
    fn: Callable[[FloatArray], FloatArray], a: ArrayLike, b: ArrayLike, dim: int,
    samples: int = 33, iterations: int = 30,
) -> tuple[FloatArray, FloatArray]:
    """Minimise ``fn`` along segments by dense sampling then golden-section refinement."""
    a = as_points(a, dim, "segment starts")
    b = as_points(b, dim, "segment ends")
    n = a.shape[0]
    ts = np.linspace(0.0, 1.0, samples)
    pts = a[:, None, :] + ts[None, :, None] * (b - a)[:, None, :]
    vals = fn(pts.reshape(-1, dim)).reshape(n, samples)
    k = np.argmin(vals, axis=1)
    step = 1.0 / (samples - 1)
    lo = np.clip(ts[k] - step, 0.0, 1.0)
    hi = np.clip(ts[k] + step, 0.0, 1.0)
    g = (np.sqrt(5.0) - 1.0) / 2.0

    def f(t: FloatArray) -> FloatArray:
        return fn(a + t[:, None] * (b - a))

    for _ in range(iterations):
        x1 = hi - g * (hi - lo)
        x2 = lo + g * (hi - lo)
        left = f(x1) < f(x2)
        hi = np.where(left, x2, hi)
        lo = np.where(left, lo, x1)
    t = 0.5 * (lo + hi)
    cand_t = np.stack([t, np.zeros(n), np.ones(n), ts[k]], axis=1)
    cand_v = np.stack([f(t), vals[:, 0], vals[:, -1], vals[np.arange(n), k]], axis=1)
    j = np.argmin(cand_v, axis=1)
    return cand_v[np.arange(n), j], cand_t[np.arange(n), j]
