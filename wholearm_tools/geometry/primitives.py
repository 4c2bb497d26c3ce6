"""Concrete primitives: 2-D line and circle; plane, sphere, cylinder, cone and torus in 3-D.

Each type is a frozen dataclass registered in :data:`~wholearm_tools.geometry.base.PRIMITIVE_TYPES`
and holds everything about itself in one place: exact signed distance, its unit gradient, the
closest surface point, the map.json parameters and, where one exists, a closed-form minimum of
the clearance over a segment.

Directions (line direction, plane normal, axes) are normalised on construction; every stored
array is read-only.  Signs follow :mod:`wholearm_tools.geometry.base`: negative inside closed
shapes, positive on the side a line's or plane's normal points to.

Where the gradient is not defined (the centre of a sphere, the axis of a cylinder, the apex of a
cone, the core circle of a torus) a deterministic unit vector is returned so that
``closest_point = p - signed_distance * gradient`` still lands on the surface.
"""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from wholearm_tools.errors import InputError
from wholearm_tools.geometry.base import (
    FloatArray,
    Primitive,
    as_points,
    as_segments,
    check_free_side,
    endpoint_min,
    fixed_point,
    perpendicular,
    positive_float,
    register,
    segment_min_numeric,
    squeeze1,
    squeeze2,
    unit_vector,
)

_EPS = 1e-12


def _get(params: Mapping[str, Any], name: str, kind: str) -> Any:
    try:
        return params[name]
    except KeyError:
        raise InputError(
            f"{kind} parameters need {name!r}, got keys {sorted(params)}") from None


class _Exact(Primitive):
    """Shared plumbing: validation and single-point squeezing around ``_sd`` / ``_sd_grad``.

    Subclasses implement ``_sd(p)`` and ``_sd_grad(p)`` on validated ``(N, dim)`` arrays; other
    modules of this package call those directly to skip re-validation in hot loops.
    """

    __slots__ = ()

    @abstractmethod
    def _sd(self, p: FloatArray) -> FloatArray:
        """Signed distance of validated points ``(N, dim)``."""

    @abstractmethod
    def _sd_grad(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Signed distance and its gradient at validated points ``(N, dim)``."""

    def signed_distance(self, points: ArrayLike) -> FloatArray:
        """Signed Euclidean distance, ``points (N, dim) -> (N,)`` (``(dim,) -> ()``)."""
        return squeeze1(self._sd(as_points(points, self.dim)), np.ndim(points) == 1)

    def gradient(self, points: ArrayLike) -> FloatArray:
        """Unit gradient of the signed distance, ``points (N, dim) -> (N, dim)``."""
        return squeeze1(self._sd_grad(as_points(points, self.dim))[1], np.ndim(points) == 1)

    def closest_point(self, points: ArrayLike) -> FloatArray:
        """Closest surface point, ``points (N, dim) -> (N, dim)`` (``p - sd * gradient``)."""
        p = as_points(points, self.dim)
        sd, g = self._sd_grad(p)
        return squeeze1(p - sd[:, None] * g, np.ndim(points) == 1)

    def _segment(self, a: FloatArray, b: FloatArray, fs: float) -> tuple[FloatArray, FloatArray]:
        sd = self._sd
        return segment_min_numeric(lambda p: fs * sd(p), a, b)

    def segment_signed_distance(
        self, a: ArrayLike, b: ArrayLike, free_side: float = 1.0
    ) -> tuple[FloatArray, FloatArray]:
        """Smallest ``free_side * signed_distance`` over segments ``a (N, dim)–b (N, dim)``.

        Returns ``(clearance (N,), t (N,))``; see each type for closed form vs numeric.
        """
        fs = check_free_side(free_side)
        a_, b_, single = as_segments(a, b, self.dim)
        val, t = self._segment(a_, b_, fs)
        return squeeze2(val, t, single)


def _radial(p: FloatArray, origin: FloatArray, axis: FloatArray, fallback: FloatArray,
            ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Axial coordinate ``h (N,)``, radial distance ``rho (N,)`` and radial unit ``e (N, 3)``.

    ``e`` is ``fallback`` on the axis.
    """
    q = p - origin
    h = q @ axis
    v = q - h[:, None] * axis
    rho = np.sqrt(np.einsum("ij,ij->i", v, v))
    on_axis = rho < _EPS
    e = v / np.where(on_axis, 1.0, rho)[:, None]
    if np.any(on_axis):
        e[on_axis] = fallback
    return h, rho, e


# ----------------------------------------------------------------------------------- planar


@register
@dataclass(frozen=True, eq=False)
class Line2D(_Exact):
    """Infinite 2-D line through ``point`` along unit ``direction``.

    The normal is the direction rotated by +90 degrees, ``(-dy, dx)``; the signed distance is
    positive on the normal's side.  Segment clearance is closed form (linear: minimum at an end).
    """

    point: FloatArray
    direction: FloatArray
    normal: FloatArray = field(init=False, repr=False)

    kind: ClassVar[str] = "line"
    dim: ClassVar[int] = 2
    dof: ClassVar[int] = 2

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", fixed_point(self.point, 2, "line point"))
        d = unit_vector(self.direction, 2, "line direction")
        object.__setattr__(self, "direction", d)
        n = np.array([-d[1], d[0]])
        n.flags.writeable = False
        object.__setattr__(self, "normal", n)

    def _sd(self, p: FloatArray) -> FloatArray:
        return (p - self.point) @ self.normal

    def _sd_grad(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        return self._sd(p), np.broadcast_to(self.normal, p.shape).copy()

    def _segment(self, a: FloatArray, b: FloatArray, fs: float) -> tuple[FloatArray, FloatArray]:
        return endpoint_min(fs * self._sd(a), fs * self._sd(b))

    def params(self) -> dict[str, Any]:
        return {"point": self.point.copy(), "direction": self.direction.copy()}

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> Line2D:
        return cls(_get(params, "point", "line"), _get(params, "direction", "line"))


class _Round(_Exact):
    """Sphere (3-D) and circle (2-D): ``|p - center| - radius``."""

    __slots__ = ()
    center: FloatArray
    radius: float
    _fallback: FloatArray

    def _init_round(self, name: str) -> None:
        object.__setattr__(self, "center", fixed_point(self.center, self.dim, f"{name} center"))
        object.__setattr__(self, "radius", positive_float(self.radius, f"{name} radius"))
        e = np.zeros(self.dim)
        e[0] = 1.0
        e.flags.writeable = False
        object.__setattr__(self, "_fallback", e)

    def _sd(self, p: FloatArray) -> FloatArray:
        q = p - self.center
        return np.sqrt(np.einsum("ij,ij->i", q, q)) - self.radius

    def _sd_grad(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        q = p - self.center
        r = np.sqrt(np.einsum("ij,ij->i", q, q))
        at_center = r < _EPS
        g = q / np.where(at_center, 1.0, r)[:, None]
        if np.any(at_center):
            g[at_center] = self._fallback
        return r - self.radius, g

    def _segment(self, a: FloatArray, b: FloatArray, fs: float) -> tuple[FloatArray, FloatArray]:
        if fs < 0:  # inside free: R - |x - c| is concave along a segment -> end point
            return endpoint_min(-self._sd(a), -self._sd(b))
        d = b - a
        dd = np.einsum("ij,ij->i", d, d)
        t = np.clip(np.einsum("ij,ij->i", self.center - a, d) / np.where(dd > 0, dd, 1.0),
                    0.0, 1.0)
        return self._sd(a + t[:, None] * d), t

    def params(self) -> dict[str, Any]:
        return {"center": self.center.copy(), "radius": self.radius}


@register
@dataclass(frozen=True, eq=False)
class Circle2D(_Round):
    """2-D circle; negative inside.  Segment clearance closed form (point–segment distance
    outside, end points inside)."""

    center: FloatArray
    radius: float
    _fallback: FloatArray = field(init=False, repr=False)

    kind: ClassVar[str] = "circle"
    dim: ClassVar[int] = 2
    dof: ClassVar[int] = 3

    def __post_init__(self) -> None:
        self._init_round("circle")

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> Circle2D:
        return cls(_get(params, "center", "circle"), _get(params, "radius", "circle"))


# ----------------------------------------------------------------------------------- spatial


@register
@dataclass(frozen=True, eq=False)
class Plane(_Exact):
    """Infinite plane through ``point`` with unit ``normal``; positive on the normal's side.

    Segment clearance closed form (linear: minimum at an end point).
    """

    point: FloatArray
    normal: FloatArray

    kind: ClassVar[str] = "plane"
    dim: ClassVar[int] = 3
    dof: ClassVar[int] = 3

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", fixed_point(self.point, 3, "plane point"))
        object.__setattr__(self, "normal", unit_vector(self.normal, 3, "plane normal"))

    def _sd(self, p: FloatArray) -> FloatArray:
        return (p - self.point) @ self.normal

    def _sd_grad(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        return self._sd(p), np.broadcast_to(self.normal, p.shape).copy()

    def _segment(self, a: FloatArray, b: FloatArray, fs: float) -> tuple[FloatArray, FloatArray]:
        return endpoint_min(fs * self._sd(a), fs * self._sd(b))

    def params(self) -> dict[str, Any]:
        return {"point": self.point.copy(), "normal": self.normal.copy()}

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> Plane:
        return cls(_get(params, "point", "plane"), _get(params, "normal", "plane"))


@register
@dataclass(frozen=True, eq=False)
class Sphere(_Round):
    """Sphere; negative inside.  Segment clearance closed form (point–segment distance outside,
    end points inside)."""

    center: FloatArray
    radius: float
    _fallback: FloatArray = field(init=False, repr=False)

    kind: ClassVar[str] = "sphere"
    dim: ClassVar[int] = 3
    dof: ClassVar[int] = 4

    def __post_init__(self) -> None:
        self._init_round("sphere")

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> Sphere:
        return cls(_get(params, "center", "sphere"), _get(params, "radius", "sphere"))


@register
@dataclass(frozen=True, eq=False)
class Cylinder(_Exact):
    """Infinite circular cylinder: ``point`` on the axis, unit ``axis``, ``radius``.

    Signed distance ``rho - radius`` (``rho`` = distance to the axis); negative inside.  Segment
    clearance closed form: outside, the segment–axis distance (a clamped quadratic in ``t``);
    inside, an end point (``radius - rho`` is concave along a segment).
    """

    point: FloatArray
    axis: FloatArray
    radius: float
    _perp: FloatArray = field(init=False, repr=False)

    kind: ClassVar[str] = "cylinder"
    dim: ClassVar[int] = 3
    dof: ClassVar[int] = 5

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", fixed_point(self.point, 3, "cylinder point"))
        u = unit_vector(self.axis, 3, "cylinder axis")
        object.__setattr__(self, "axis", u)
        object.__setattr__(self, "radius", positive_float(self.radius, "cylinder radius"))
        object.__setattr__(self, "_perp", perpendicular(u))

    def _rho(self, p: FloatArray) -> FloatArray:
        q = p - self.point
        v = q - (q @ self.axis)[:, None] * self.axis
        return np.sqrt(np.einsum("ij,ij->i", v, v))

    def _sd(self, p: FloatArray) -> FloatArray:
        return self._rho(p) - self.radius

    def _sd_grad(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        _, rho, e = _radial(p, self.point, self.axis, self._perp)
        return rho - self.radius, e

    def _segment(self, a: FloatArray, b: FloatArray, fs: float) -> tuple[FloatArray, FloatArray]:
        if fs < 0:
            return endpoint_min(-self._sd(a), -self._sd(b))
        u = self.axis
        qa = a - self.point
        pa = qa - (qa @ u)[:, None] * u
        d = b - a
        pd = d - (d @ u)[:, None] * u
        dd = np.einsum("ij,ij->i", pd, pd)
        t = np.clip(-np.einsum("ij,ij->i", pa, pd) / np.where(dd > _EPS, dd, 1.0), 0.0, 1.0)
        t = np.where(dd > _EPS, t, 0.0)
        v = pa + t[:, None] * pd
        return np.sqrt(np.einsum("ij,ij->i", v, v)) - self.radius, t

    def params(self) -> dict[str, Any]:
        return {"point": self.point.copy(), "axis": self.axis.copy(), "radius": self.radius}

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> Cylinder:
        return cls(_get(params, "point", "cylinder"), _get(params, "axis", "cylinder"),
                   _get(params, "radius", "cylinder"))


@register
@dataclass(frozen=True, eq=False)
class Cone(_Exact):
    """One-sided infinite circular cone: ``apex``, unit ``axis`` (opening direction),
    ``half_angle`` in (0, pi/2).

    Exact Euclidean signed distance.  In the meridian half-plane of a point, with ``h`` its axial
    and ``rho`` its radial coordinate, the surface is the ray ``s (sin a, cos a)``, ``s >= 0``:
    ``sd = rho cos a - h sin a`` where the projection ``s = rho sin a + h cos a`` is positive,
    else the distance to the apex (that region lies behind the apex, always outside).  Negative
    inside.  Segment clearance: inside the cone (``free_side=-1``) at an end point (the signed
    distance of a convex set is convex); outside, numeric but exact to ~1e-6 because the convex
    signed distance is unimodal along a segment.
    """

    apex: FloatArray
    axis: FloatArray
    half_angle: float
    _perp: FloatArray = field(init=False, repr=False)
    _sc: tuple[float, float] = field(init=False, repr=False)

    kind: ClassVar[str] = "cone"
    dim: ClassVar[int] = 3
    dof: ClassVar[int] = 6

    def __post_init__(self) -> None:
        object.__setattr__(self, "apex", fixed_point(self.apex, 3, "cone apex"))
        u = unit_vector(self.axis, 3, "cone axis")
        object.__setattr__(self, "axis", u)
        a = positive_float(self.half_angle, "cone half_angle")
        if not a < np.pi / 2:
            raise InputError(f"cone half_angle must be in (0, pi/2), got {self.half_angle!r}")
        object.__setattr__(self, "half_angle", a)
        object.__setattr__(self, "_perp", perpendicular(u))
        object.__setattr__(self, "_sc", (float(np.sin(a)), float(np.cos(a))))

    def _sd(self, p: FloatArray) -> FloatArray:
        sa, ca = self._sc
        q = p - self.apex
        h = q @ self.axis
        qq = np.einsum("ij,ij->i", q, q)
        rho = np.sqrt(np.maximum(qq - h * h, 0.0))
        return np.where(rho * sa + h * ca > 0.0, rho * ca - h * sa, np.sqrt(qq))

    def _sd_grad(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        sa, ca = self._sc
        u = self.axis
        h, rho, e = _radial(p, self.apex, u, self._perp)
        front = rho * sa + h * ca > 0.0
        q = p - self.apex
        r = np.sqrt(h * h + rho * rho)
        sd = np.where(front, rho * ca - h * sa, r)
        g_front = ca * e - sa * u
        at_apex = r < _EPS
        g_back = q / np.where(at_apex, 1.0, r)[:, None]
        g_back[at_apex] = -u
        return sd, np.where(front[:, None], g_front, g_back)

    def _segment(self, a: FloatArray, b: FloatArray, fs: float) -> tuple[FloatArray, FloatArray]:
        if fs < 0:
            return endpoint_min(-self._sd(a), -self._sd(b))
        return segment_min_numeric(self._sd, a, b)

    def params(self) -> dict[str, Any]:
        return {"apex": self.apex.copy(), "axis": self.axis.copy(),
                "half_angle": self.half_angle}

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> Cone:
        return cls(_get(params, "apex", "cone"), _get(params, "axis", "cone"),
                   _get(params, "half_angle", "cone"))


@register
@dataclass(frozen=True, eq=False)
class Torus(_Exact):
    """Ring torus: ``center``, unit ``axis``, ``major_radius > minor_radius > 0``.

    Exact signed distance: distance to the core circle (radius ``major_radius`` in the plane
    through ``center`` normal to ``axis``) minus ``minor_radius``; negative inside the tube.
    Segment clearance is numeric on both sides (the distance to a circle is not convex).
    """

    center: FloatArray
    axis: FloatArray
    major_radius: float
    minor_radius: float
    _perp: FloatArray = field(init=False, repr=False)

    kind: ClassVar[str] = "torus"
    dim: ClassVar[int] = 3
    dof: ClassVar[int] = 7

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", fixed_point(self.center, 3, "torus center"))
        u = unit_vector(self.axis, 3, "torus axis")
        object.__setattr__(self, "axis", u)
        big = positive_float(self.major_radius, "torus major_radius")
        small = positive_float(self.minor_radius, "torus minor_radius")
        if not small < big:
            raise InputError(
                f"torus minor_radius must be < major_radius (a ring torus), got "
                f"minor_radius={self.minor_radius!r}, major_radius={self.major_radius!r}")
        object.__setattr__(self, "major_radius", big)
        object.__setattr__(self, "minor_radius", small)
        object.__setattr__(self, "_perp", perpendicular(u))

    def _sd(self, p: FloatArray) -> FloatArray:
        q = p - self.center
        h = q @ self.axis
        rho = np.sqrt(np.maximum(np.einsum("ij,ij->i", q, q) - h * h, 0.0))
        return np.hypot(rho - self.major_radius, h) - self.minor_radius

    def _sd_grad(self, p: FloatArray) -> tuple[FloatArray, FloatArray]:
        u = self.axis
        h, rho, e = _radial(p, self.center, u, self._perp)
        dr = rho - self.major_radius
        dc = np.hypot(dr, h)
        on_core = dc < _EPS
        g = (dr[:, None] * e + h[:, None] * u) / np.where(on_core, 1.0, dc)[:, None]
        if np.any(on_core):
            g[on_core] = e[on_core]
        return dc - self.minor_radius, g

    def params(self) -> dict[str, Any]:
        return {"center": self.center.copy(), "axis": self.axis.copy(),
                "major_radius": self.major_radius, "minor_radius": self.minor_radius}

    @classmethod
    def from_params(cls, params: Mapping[str, Any]) -> Torus:
        return cls(_get(params, "center", "torus"), _get(params, "axis", "torus"),
                   _get(params, "major_radius", "torus"), _get(params, "minor_radius", "torus"))


def capsule_clearance(
    primitive: Primitive, a: ArrayLike, b: ArrayLike, radius: ArrayLike, free_side: float,
) -> tuple[FloatArray, FloatArray]:
    """Clearance of capsules (segments ``a (N, d)–b (N, d)`` dilated by ``radius``) to a surface.

    ``radius`` is a scalar or ``(N,)`` and must be >= 0.  Returns ``(clearance (N,), t (N,))``:
    the segment clearance ``min_t free_side * signed_distance(a + t (b - a))`` minus ``radius``,
    and the parameter attaining it.  Negative clearance means the capsule penetrates.
    """
    r = np.asarray(radius, dtype=float)
    if not np.all(np.isfinite(r)) or np.any(r < 0):
        raise InputError(f"capsule radius must be finite and >= 0, got {radius!r}")
    val, t = primitive.segment_signed_distance(a, b, free_side)
    if r.ndim and r.shape != np.shape(val):
        raise InputError(
            f"capsule radius must be a scalar or shape {np.shape(val)}, got shape {r.shape}")
    return val - r, t
