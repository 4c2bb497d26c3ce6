"""Obstacles for simulated environments: unbounded surfaces and bounded patches of primitives.

An environment is a set of obstacles.  Every obstacle satisfies the small :class:`Obstacle`
protocol: ``clearance(points)``, ``segment_clearance(a, b)``, ``surface_id``, ``to_dict()`` and
``from_dict()``; :func:`obstacle_from_dict` rebuilds any of them from its ``to_dict()`` form (a
JSON-ready dict whose ``"type"`` names the obstacle class in :data:`OBSTACLE_TYPES`).

Clearance is a signed distance to the obstacle's *solid*: positive in free space, zero on the
surface, negative inside the material.  What the solid is, and how exact the clearance is:

* :class:`Surface` — an unbounded primitive; the solid is the ``-free_side`` side.  Exact.
* :class:`PlanePatch` / :class:`Segment2D` — a rectangle in a plane (a segment of a 2-D line);
  the solid is the box (rectangle) behind it, ``thickness`` deep on the ``-free_side`` side
  (``None``: infinitely deep).  Exact Euclidean box distance everywhere.
* :class:`CylinderSection` / :class:`Arc2D` — the wall of a cylinder (a circle) limited to an
  axial range ``s_range`` (3-D only) and an optional angular range.  With ``free_side=-1`` (a
  bore: free inside) the wall is the shell ``radius <= rho <= radius + thickness``; with
  ``free_side=+1`` (a post) it is the solid ``rho <= radius``.  Without an angular range the
  clearance is exact (a box distance in the meridian half-plane).  With an angular range it is
  ``max(shell clearance, wedge clearance)``: exact inside the material, exact zero set (contact
  happens exactly where it should), exact wherever the closest solid point lies on the curved
  face, and a lower bound (conservative) near the angular edges.
* :class:`CylinderJunction` — the free space is the UNION of two bores' interiors (each
  optionally cut to an axial range); clearance = ``max`` of the two interior clearances.  Exact in
  the material and on the zero set, exact wherever one bore's wall is the nearest feature, and a
  lower bound (conservative) near the intersection edge of the two bores.

``segment_clearance`` minimises the clearance along segments: closed form for :class:`Surface`
(see the primitive types), numeric for bounded obstacles
(:func:`~wholearm_tools.geometry.base.segment_min_numeric`, accurate to ~1e-6 of the segment
length around the best of 33 samples).  All clearances are 1-Lipschitz.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar, Protocol, TypeVar, cast, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from wholearm_tools.errors import InputError
from wholearm_tools.geometry.base import (
    FloatArray,
    Primitive,
    as_points,
    as_segments,
    check_free_side,
    fixed_point,
    perpendicular,
    positive_float,
    primitive_from_dict,
    primitive_to_dict,
    segment_min_numeric,
    squeeze1,
    squeeze2,
    unit_vector,
)
from wholearm_tools.geometry.primitives import Circle2D, Cylinder, Line2D, Plane

_TWO_PI = 2.0 * np.pi


@runtime_checkable
class Obstacle(Protocol):
    """What the simulator needs from one obstacle of an environment."""

    surface_id: int | str

    def clearance(self, points: ArrayLike) -> FloatArray:
        """Clearance of ``points (N, d)``, shape ``(N,)``: > 0 free, < 0 inside the material."""
        ...

    def segment_clearance(self, a: ArrayLike, b: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(min clearance (N,), t (N,))`` over the segments ``a (N, d)–b (N, d)``."""
        ...

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description; :func:`obstacle_from_dict` inverts it."""
        ...

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Obstacle:
        """Inverse of :meth:`to_dict`."""
        ...


OBSTACLE_TYPES: dict[str, type[Any]] = {}

ObstacleT = TypeVar("ObstacleT", bound=type[Any])


def register_obstacle(cls: ObstacleT) -> ObstacleT:
    """Class decorator: add an obstacle type to :data:`OBSTACLE_TYPES` under ``cls.type_name``."""
    if cls.type_name in OBSTACLE_TYPES:
        raise RuntimeError(f"obstacle type {cls.type_name!r} registered twice")
    OBSTACLE_TYPES[cls.type_name] = cls
    return cls


def obstacle_from_dict(data: Mapping[str, Any]) -> Obstacle:
    """Rebuild an obstacle from its ``to_dict()`` form, looking its ``"type"`` up by name."""
    if not isinstance(data, Mapping) or "type" not in data:
        raise InputError(f"expected an obstacle dict with a 'type' key, got {data!r}")
    try:
        cls = OBSTACLE_TYPES[data["type"]]
    except (KeyError, TypeError):
        known = ", ".join(sorted(OBSTACLE_TYPES))
        raise InputError(f"unknown obstacle type {data['type']!r} (known: {known})") from None
    obstacle: Obstacle = cls.from_dict(data)
    return obstacle


# ---------------------------------------------------------------------------------- helpers


def _surface_id(value: Any) -> int | str:
    if isinstance(value, bool) or not isinstance(value, int | str | np.integer):
        raise InputError(f"surface_id must be an int or a str, got {value!r}")
    return int(value) if isinstance(value, np.integer) else value


def _thickness(value: Any) -> float | None:
    return None if value is None else positive_float(value, "thickness")


def _range(value: Any, name: str) -> tuple[float, float]:
    """``(lo, hi)`` with ``None`` for an open end -> floats with +-inf; lo < hi."""
    if value is None:
        return (-np.inf, np.inf)
    try:
        lo, hi = value
        lo = -np.inf if lo is None else float(lo)
        hi = np.inf if hi is None else float(hi)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a pair (lo, hi), got {value!r}") from None
    if np.isnan(lo) or np.isnan(hi) or not lo < hi:
        raise InputError(f"{name} must satisfy lo < hi, got {value!r}")
    return (lo, hi)


def _range_json(r: tuple[float, float]) -> list[float | None]:
    return [None if np.isinf(x) else float(x) for x in r]


def _angle_range(value: Any, name: str = "angle_range") -> tuple[float, float] | None:
    """``(start, end)`` in radians with ``0 < end - start <= 2 pi``, or ``None`` (full turn)."""
    if value is None:
        return None
    try:
        lo, hi = (float(x) for x in value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a pair (start, end) in radians, got {value!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 < hi - lo <= _TWO_PI + 1e-12):
        raise InputError(f"{name} must satisfy 0 < end - start <= 2 pi, got {value!r}")
    return (lo, hi)


def _box_sdf(*d: FloatArray) -> FloatArray:
    """Exact signed distance to an axis-aligned box from per-axis ``d_i = max(lo - x, x - hi)``."""
    D = np.stack(d, axis=1)
    pos = np.maximum(D, 0.0)
    return np.sqrt(np.einsum("ij,ij->i", pos, pos)) + np.minimum(D.max(axis=1), 0.0)


def _interval(x: FloatArray, lo: float, hi: float) -> FloatArray:
    return np.maximum(lo - x, x - hi)


def _wedge_sdf(phi: FloatArray, rho: FloatArray, angles: tuple[float, float]) -> FloatArray:
    """Exact signed distance (in the cross-section) to the wedge ``start <= phi <= end``."""
    start, end = angles
    width = end - start
    rel0 = np.mod(phi - start, _TWO_PI)
    rel1 = np.mod(phi - end, _TWO_PI)
    inside = rel0 <= width
    d0 = np.minimum(rel0, _TWO_PI - rel0)
    d1 = np.minimum(rel1, _TWO_PI - rel1)
    dist = np.minimum(np.where(d0 < np.pi / 2, rho * np.sin(d0), rho),
                      np.where(d1 < np.pi / 2, rho * np.sin(d1), rho))
    return np.where(inside, -dist, dist)


def _radial_interval(rho: FloatArray, radius: float, free_side: float,
                     thickness: float | None) -> FloatArray:
    """Per-axis box term in ``rho`` for a wall (``free_side=-1``) or a post (``+1``)."""
    if free_side > 0:
        return rho - radius
    return _interval(rho, radius, np.inf if thickness is None else radius + thickness)


class _Numeric(ABC):
    """Validation, squeezing and the numeric segment minimum around ``_clear``."""

    __slots__ = ()
    dim: ClassVar[int]

    @abstractmethod
    def _clear(self, p: FloatArray) -> FloatArray:
        """Clearance (distance on the free side, negative inside) of validated points."""

    def clearance(self, points: ArrayLike) -> FloatArray:
        """Clearance of ``points (N, dim)``, shape ``(N,)`` (``()`` for one point)."""
        return squeeze1(self._clear(as_points(points, self.dim)), np.ndim(points) == 1)

    def segment_clearance(self, a: ArrayLike, b: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(min clearance (N,), t (N,))`` over segments ``a (N, dim)–b (N, dim)`` (numeric)."""
        a_, b_, single = as_segments(a, b, self.dim)
        val, t = segment_min_numeric(self._clear, a_, b_)
        return squeeze2(val, t, single)


def _get(data: Mapping[str, Any], key: str, what: str) -> Any:
    try:
        return data[key]
    except (KeyError, TypeError):
        raise InputError(f"{what} needs {key!r}, got {data!r}") from None


# -------------------------------------------------------------------------------- obstacles


@register_obstacle
@dataclass(frozen=True, eq=False)
class Surface:
    """An unbounded primitive with its free side: clearance = ``free_side * signed_distance``.

    Exact; ``segment_clearance`` uses the primitive's closed form where it has one.
    """

    primitive: Primitive
    free_side: float = 1.0
    surface_id: int | str = 0

    type_name: ClassVar[str] = "surface"

    def __post_init__(self) -> None:
        if not isinstance(self.primitive, Primitive):
            raise InputError(f"Surface needs a Primitive, got {self.primitive!r}")
        object.__setattr__(self, "free_side", check_free_side(self.free_side))
        object.__setattr__(self, "surface_id", _surface_id(self.surface_id))

    @property
    def dim(self) -> int:
        return self.primitive.dim

    @property
    def primitives(self) -> tuple[Primitive, ...]:
        return (self.primitive,)

    def bounds(self) -> dict[str, Any]:
        """No bounds: ``{}``."""
        return {}

    def clearance(self, points: ArrayLike) -> FloatArray:
        return self.free_side * self.primitive.signed_distance(points)

    def segment_clearance(self, a: ArrayLike, b: ArrayLike) -> tuple[FloatArray, FloatArray]:
        return self.primitive.segment_signed_distance(a, b, self.free_side)

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type_name, "surface_id": self.surface_id,
                "free_side": int(self.free_side), "primitive": primitive_to_dict(self.primitive)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Surface:
        return cls(primitive_from_dict(_get(data, "primitive", "surface")),
                   data.get("free_side", 1), data.get("surface_id", 0))


@register_obstacle
@dataclass(frozen=True, eq=False)
class PlanePatch(_Numeric):
    """A rectangle in a plane: ``center``, unit ``normal``, in-plane ``u`` direction and
    ``half_extents = (along u, along v = normal x u)``.

    The material is the box behind the rectangle on the ``-free_side * normal`` side,
    ``thickness`` deep (``None``: infinitely deep).  Clearance = exact box signed distance.
    ``u`` is projected onto the plane and normalised.
    """

    center: FloatArray
    normal: FloatArray
    u: FloatArray
    half_extents: tuple[float, float]
    free_side: float = 1.0
    thickness: float | None = None
    surface_id: int | str = 0
    v: FloatArray = field(init=False, repr=False)

    type_name: ClassVar[str] = "plane_patch"
    dim: ClassVar[int] = 3

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        set_(self, "center", fixed_point(self.center, 3, "patch center"))
        n = unit_vector(self.normal, 3, "patch normal")
        set_(self, "normal", n)
        u0 = unit_vector(self.u, 3, "patch u")
        u = u0 - (u0 @ n) * n
        if np.linalg.norm(u) < 1e-6:
            raise InputError(f"patch u must not be parallel to the normal, got {u0.tolist()}")
        set_(self, "u", unit_vector(u, 3, "patch u"))
        v = np.cross(n, self.u)
        v.flags.writeable = False
        set_(self, "v", v)
        try:
            hu, hv = self.half_extents
        except (TypeError, ValueError):
            raise InputError(
                f"half_extents must be a pair, got {self.half_extents!r}") from None
        set_(self, "half_extents",
             (positive_float(hu, "half_extents[0]"), positive_float(hv, "half_extents[1]")))
        set_(self, "free_side", check_free_side(self.free_side))
        set_(self, "thickness", _thickness(self.thickness))
        set_(self, "surface_id", _surface_id(self.surface_id))

    @property
    def primitive(self) -> Plane:
        return Plane(self.center, self.normal)

    @property
    def primitives(self) -> tuple[Primitive, ...]:
        return (self.primitive,)

    def bounds(self) -> dict[str, Any]:
        return {"u": self.u.tolist(), "v": self.v.tolist(),
                "half_extents": list(self.half_extents), "thickness": self.thickness}

    def _clear(self, p: FloatArray) -> FloatArray:
        q = p - self.center
        hu, hv = self.half_extents
        z = self.free_side * (q @ self.normal)
        dz = z if self.thickness is None else np.maximum(z, -z - self.thickness)
        return _box_sdf(np.abs(q @ self.u) - hu, np.abs(q @ self.v) - hv, dz)

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type_name, "surface_id": self.surface_id,
                "free_side": int(self.free_side), "primitive": primitive_to_dict(self.primitive),
                "bounds": self.bounds()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PlanePatch:
        prim = primitive_from_dict(_get(data, "primitive", "plane_patch"))
        b = _get(data, "bounds", "plane_patch")
        params = prim.params()
        return cls(params["point"], params["normal"], _get(b, "u", "plane_patch bounds"),
                   _get(b, "half_extents", "plane_patch bounds"), data.get("free_side", 1),
                   b.get("thickness"), data.get("surface_id", 0))


@register_obstacle
@dataclass(frozen=True, eq=False)
class Segment2D(_Numeric):
    """A 2-D line ``point + s * direction`` limited to ``s_range = (s0, s1)``.

    The material is the rectangle behind the segment on the ``-free_side * normal`` side
    (normal = direction rotated +90 degrees), ``thickness`` deep (``None``: infinitely deep).
    Clearance = exact rectangle signed distance.
    """

    point: FloatArray
    direction: FloatArray
    s_range: tuple[float, float]
    free_side: float = 1.0
    thickness: float | None = None
    surface_id: int | str = 0
    normal: FloatArray = field(init=False, repr=False)

    type_name: ClassVar[str] = "segment2d"
    dim: ClassVar[int] = 2

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        line = Line2D(self.point, self.direction)
        set_(self, "point", line.point)
        set_(self, "direction", line.direction)
        set_(self, "normal", line.normal)
        s0, s1 = _range(self.s_range, "s_range")
        if not (np.isfinite(s0) and np.isfinite(s1)):
            raise InputError(f"s_range of a segment must be finite, got {self.s_range!r}")
        set_(self, "s_range", (s0, s1))
        set_(self, "free_side", check_free_side(self.free_side))
        set_(self, "thickness", _thickness(self.thickness))
        set_(self, "surface_id", _surface_id(self.surface_id))

    @property
    def primitive(self) -> Line2D:
        return Line2D(self.point, self.direction)

    @property
    def primitives(self) -> tuple[Primitive, ...]:
        return (self.primitive,)

    def bounds(self) -> dict[str, Any]:
        return {"s_range": list(self.s_range), "thickness": self.thickness}

    def _clear(self, p: FloatArray) -> FloatArray:
        q = p - self.point
        y = self.free_side * (q @ self.normal)
        dy = y if self.thickness is None else np.maximum(y, -y - self.thickness)
        return _box_sdf(_interval(q @ self.direction, *self.s_range), dy)

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type_name, "surface_id": self.surface_id,
                "free_side": int(self.free_side), "primitive": primitive_to_dict(self.primitive),
                "bounds": self.bounds()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Segment2D:
        prim = primitive_from_dict(_get(data, "primitive", "segment2d")).params()
        b = _get(data, "bounds", "segment2d")
        return cls(prim["point"], prim["direction"], _get(b, "s_range", "segment2d bounds"),
                   data.get("free_side", 1), b.get("thickness"), data.get("surface_id", 0))


@register_obstacle
@dataclass(frozen=True, eq=False)
class CylinderSection(_Numeric):
    """The wall of a cylinder (``point`` on the axis, unit ``axis``, ``radius``) between axial
    coordinates ``s_range = (s0, s1)`` (measured from ``point`` along ``axis``; ``None`` ends are
    open), optionally only over ``angle_range = (start, end)`` radians about the axis, measured
    from ``ref`` (projected perpendicular to the axis; default a fixed perpendicular) towards
    ``axis x ref``.

    ``free_side=-1`` (a bore, free inside): the material is the shell ``radius <= rho <= radius
    + thickness`` (``None``: unbounded outwards); ``free_side=+1`` (a post): ``rho <= radius``.
    Clearance: exact without an angular range, else see the module docstring.
    """

    point: FloatArray
    axis: FloatArray
    radius: float
    s_range: tuple[float, float] | None = None
    free_side: float = -1.0
    angle_range: tuple[float, float] | None = None
    ref: FloatArray | None = None
    thickness: float | None = None
    surface_id: int | str = 0
    _w: FloatArray = field(init=False, repr=False)

    type_name: ClassVar[str] = "cylinder_section"
    dim: ClassVar[int] = 3

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        cyl = Cylinder(self.point, self.axis, self.radius)
        set_(self, "point", cyl.point)
        set_(self, "axis", cyl.axis)
        set_(self, "radius", cyl.radius)
        set_(self, "s_range", _range(self.s_range, "s_range"))
        set_(self, "free_side", check_free_side(self.free_side))
        set_(self, "angle_range", _angle_range(self.angle_range))
        u = cyl.axis
        if self.ref is None:
            ref = perpendicular(u)
        else:
            r0 = unit_vector(self.ref, 3, "ref")
            r1 = r0 - (r0 @ u) * u
            if np.linalg.norm(r1) < 1e-6:
                raise InputError(f"ref must not be parallel to the axis, got {r0.tolist()}")
            ref = unit_vector(r1, 3, "ref")
        set_(self, "ref", ref)
        w = np.cross(u, ref)
        w.flags.writeable = False
        set_(self, "_w", w)
        set_(self, "thickness", _thickness(self.thickness))
        set_(self, "surface_id", _surface_id(self.surface_id))

    @property
    def primitive(self) -> Cylinder:
        return Cylinder(self.point, self.axis, self.radius)

    @property
    def primitives(self) -> tuple[Primitive, ...]:
        return (self.primitive,)

    def bounds(self) -> dict[str, Any]:
        return {"s_range": _range_json(cast(tuple[float, float], self.s_range)),
                "angle_range": None if self.angle_range is None else list(self.angle_range),
                "ref": cast(FloatArray, self.ref).tolist(), "thickness": self.thickness}

    def _clear(self, p: FloatArray) -> FloatArray:
        q = p - self.point
        h = q @ self.axis
        x = q @ cast(FloatArray, self.ref)
        y = q @ self._w
        rho = np.hypot(x, y)
        dr = _radial_interval(rho, self.radius, self.free_side, self.thickness)
        s0, s1 = cast(tuple[float, float], self.s_range)
        c = dr if np.isinf(s0) and np.isinf(s1) else _box_sdf(dr, _interval(h, s0, s1))
        if self.angle_range is not None:
            c = np.maximum(c, _wedge_sdf(np.arctan2(y, x), rho, self.angle_range))
        return c

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type_name, "surface_id": self.surface_id,
                "free_side": int(self.free_side), "primitive": primitive_to_dict(self.primitive),
                "bounds": self.bounds()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> CylinderSection:
        prim = primitive_from_dict(_get(data, "primitive", "cylinder_section")).params()
        b = _get(data, "bounds", "cylinder_section")
        return cls(prim["point"], prim["axis"], prim["radius"], b.get("s_range"),
                   data.get("free_side", -1), b.get("angle_range"), b.get("ref"),
                   b.get("thickness"), data.get("surface_id", 0))


@register_obstacle
@dataclass(frozen=True, eq=False)
class Arc2D(_Numeric):
    """A circular arc: ``center``, ``radius``, optional ``angle_range = (start, end)`` radians
    measured from +x (``None``: the full circle).

    ``free_side=-1`` (free inside): the material is the ring sector ``radius <= rho <= radius +
    thickness``; ``free_side=+1``: the disc sector ``rho <= radius``.  Clearance: exact for the
    full circle; with an angular range ``max(ring clearance, wedge clearance)`` (see the module
    docstring).
    """

    center: FloatArray
    radius: float
    angle_range: tuple[float, float] | None = None
    free_side: float = -1.0
    thickness: float | None = None
    surface_id: int | str = 0

    type_name: ClassVar[str] = "arc"
    dim: ClassVar[int] = 2

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        circle = Circle2D(self.center, self.radius)
        set_(self, "center", circle.center)
        set_(self, "radius", circle.radius)
        set_(self, "angle_range", _angle_range(self.angle_range))
        set_(self, "free_side", check_free_side(self.free_side))
        set_(self, "thickness", _thickness(self.thickness))
        set_(self, "surface_id", _surface_id(self.surface_id))

    @property
    def primitive(self) -> Circle2D:
        return Circle2D(self.center, self.radius)

    @property
    def primitives(self) -> tuple[Primitive, ...]:
        return (self.primitive,)

    def bounds(self) -> dict[str, Any]:
        return {"angle_range": None if self.angle_range is None else list(self.angle_range),
                "thickness": self.thickness}

    def _clear(self, p: FloatArray) -> FloatArray:
        q = p - self.center
        rho = np.hypot(q[:, 0], q[:, 1])
        c = _radial_interval(rho, self.radius, self.free_side, self.thickness)
        if self.angle_range is not None:
            c = np.maximum(c, _wedge_sdf(np.arctan2(q[:, 1], q[:, 0]), rho, self.angle_range))
        return c

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type_name, "surface_id": self.surface_id,
                "free_side": int(self.free_side), "primitive": primitive_to_dict(self.primitive),
                "bounds": self.bounds()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Arc2D:
        prim = primitive_from_dict(_get(data, "primitive", "arc")).params()
        b = _get(data, "bounds", "arc")
        return cls(prim["center"], prim["radius"], b.get("angle_range"),
                   data.get("free_side", -1), b.get("thickness"), data.get("surface_id", 0))


def _bore_clearance(cyl: Cylinder, s_range: tuple[float, float]) -> Callable[
        [FloatArray], FloatArray]:
    """Interior clearance of a bore: minus the exact signed distance to the finite cylinder."""
    point, axis, radius = cyl.point, cyl.axis, cyl.radius
    s0, s1 = s_range
    open_ends = np.isinf(s0) and np.isinf(s1)

    def clear(p: FloatArray) -> FloatArray:
        q = p - point
        h = q @ axis
        rho = np.sqrt(np.maximum(np.einsum("ij,ij->i", q, q) - h * h, 0.0))
        if open_ends:
            return radius - rho
        return -_box_sdf(rho - radius, _interval(h, s0, s1))

    return clear


@register_obstacle
@dataclass(frozen=True, eq=False)
class CylinderJunction(_Numeric):
    """Two intersecting bores (e.g. a well's main bore and a lateral branch); the free space is
    the union of their interiors, each cut to its axial range (``None``: unbounded; a cut end is
    a closed cap).

    Clearance = ``max(main interior clearance, branch interior clearance)``, each the exact
    distance to its finite cylinder's wall; see the module docstring for where that is exact.
    Use :meth:`lateral` to build one from a branch angle.
    """

    main: Cylinder
    branch: Cylinder
    main_range: tuple[float, float] | None = None
    branch_range: tuple[float, float] | None = None
    surface_id: int | str = 0
    _main_clear: Callable[[FloatArray], FloatArray] = field(init=False, repr=False)
    _branch_clear: Callable[[FloatArray], FloatArray] = field(init=False, repr=False)

    type_name: ClassVar[str] = "cylinder_junction"
    dim: ClassVar[int] = 3

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        for name in ("main", "branch"):
            if not isinstance(getattr(self, name), Cylinder):
                raise InputError(f"{name} must be a Cylinder, got {getattr(self, name)!r}")
        set_(self, "main_range", _range(self.main_range, "main_range"))
        set_(self, "branch_range", _range(self.branch_range, "branch_range"))
        set_(self, "surface_id", _surface_id(self.surface_id))
        set_(self, "_main_clear",
             _bore_clearance(self.main, cast(tuple[float, float], self.main_range)))
        set_(self, "_branch_clear",
             _bore_clearance(self.branch, cast(tuple[float, float], self.branch_range)))

    @classmethod
    def lateral(
        cls, center: ArrayLike, axis: ArrayLike, radius: float, branch_radius: float,
        angle: float, branch_length: float, main_range: tuple[float, float] | None = None,
        ref: ArrayLike | None = None, surface_id: int | str = 0,
    ) -> CylinderJunction:
        """A branch leaving the main bore's axis at ``center``, at ``angle`` (radians, in
        (0, pi)) from ``axis`` towards ``ref`` (default a fixed perpendicular), reaching
        ``branch_length`` along its own axis.  ``main_range`` is measured from ``center``."""
        main = Cylinder(center, axis, radius)
        a = float(angle)
        if not 0.0 < a < np.pi:
            raise InputError(f"branch angle must be in (0, pi) radians, got {angle!r}")
        u = main.axis
        if ref is None:
            r = perpendicular(u)
        else:
            r0 = unit_vector(ref, 3, "ref")
            r1 = r0 - (r0 @ u) * u
            if np.linalg.norm(r1) < 1e-6:
                raise InputError(f"ref must not be parallel to the axis, got {r0.tolist()}")
            r = r1 / np.linalg.norm(r1)
        branch = Cylinder(main.point, np.cos(a) * u + np.sin(a) * r, branch_radius)
        length = positive_float(branch_length, "branch_length")
        return cls(main, branch, main_range, (0.0, length), surface_id)

    @property
    def primitives(self) -> tuple[Primitive, ...]:
        return (self.main, self.branch)

    def bounds(self) -> dict[str, Any]:
        return {"main_range": _range_json(cast(tuple[float, float], self.main_range)),
                "branch_range": _range_json(cast(tuple[float, float], self.branch_range))}

    def _clear(self, p: FloatArray) -> FloatArray:
        return np.maximum(self._main_clear(p), self._branch_clear(p))

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type_name, "surface_id": self.surface_id, "free_side": -1,
                "main": primitive_to_dict(self.main), "branch": primitive_to_dict(self.branch),
                "bounds": self.bounds()}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> CylinderJunction:
        main = primitive_from_dict(_get(data, "main", "cylinder_junction"))
        branch = primitive_from_dict(_get(data, "branch", "cylinder_junction"))
        b = data.get("bounds", {})
        if not isinstance(main, Cylinder) or not isinstance(branch, Cylinder):
            raise InputError(
                f"cylinder_junction needs two cylinders, got {main.kind!r} and {branch.kind!r}")
        return cls(main, branch, b.get("main_range"), b.get("branch_range"),
                   data.get("surface_id", 0))
