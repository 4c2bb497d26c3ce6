"""The region of a primitive covered by its supporting contacts (map.json ``"extent"``).

A fitted primitive is unbounded (a plane, a cylinder) or closed (a sphere) while the robot only
touched part of it.  :func:`support_extent` records the part the supporting contact points cover,
padded by ``pad`` metres, as a JSON-ready dict; :mod:`wholearm_tools.mesh.tessellate` meshes
exactly that region.  Schemas (all lengths in metres, angles in radians):

``line``      ``{"s": [s0, s1]}`` — parameter range along the unit ``direction`` from ``point``.
``circle``    ``{"angle": ANGLE}`` — angles from +x, counter-clockwise, about ``center``.
``plane``     ``{"u": [3], "v": [3], "polygon": [[a, b], ...]}`` — orthonormal in-plane basis with
              ``u × v = normal``; the convex polygon (counter-clockwise in (a, b)) of the points
              ``point + a u + b v``.
``sphere``    ``{"cap": {"direction": [3], "half_angle": θ, "full": bool}}`` — the points within
              angle θ of the unit direction seen from ``center`` (θ = π and ``full`` for all).
``cylinder``  ``{"s": [s0, s1], "angle": ANGLE}`` — ``s`` along the unit ``axis`` from ``point``.
``cone``      ``{"s": [s0, s1], "angle": ANGLE}`` — ``s`` = axial distance from ``apex`` along
              ``axis`` (0 ≤ s0 < s1); the surface radius at ``s`` is ``s tan(half_angle)``.
``torus``     ``{"angle": ANGLE, "minor": {"start": 0, "sweep": 2π, "full": true}}`` — ``angle``
              around the main axis; ``minor`` (around the tube, from the outward radial
              direction towards ``axis``) is always the full circle.

``ANGLE = {"reference": [d], "start": a0, "sweep": w, "full": bool}``: the arc of angles
``[a0, a0 + w]`` (0 ≤ a0 < 2π, 0 ≤ w ≤ 2π) measured from the unit ``reference`` direction
(perpendicular to the axis) towards ``axis × reference`` (right-handed about the axis); for 2-D
circles the reference is ``[1, 0]``.  ``full`` is true (and a0 = 0, w = 2π) when the points wrap
around: no angular gap between consecutive points exceeds ``wrap_gap``.

Every extent also holds ``"pad"`` (the padding used, metres) and ``"n_points"``.  Angular padding
is ``pad`` divided by the relevant radius.  Wrap-around is handled with the largest-gap method: the
arc covering all points is the complement of the largest gap between sorted angles.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from wholearm_tools.errors import InputError
from wholearm_tools.mesh._params import (
    KIND_DIMS,
    TWO_PI,
    FloatArray,
    as_support_points,
    check_kind,
    perpendicular_basis,
    scalar,
    unit_vector,
    vector,
)

#: default padding of an extent beyond its outermost support points, metres
DEFAULT_PAD = 0.005
#: default largest angular gap (rad) between support points still counted as a full turn
DEFAULT_WRAP_GAP = math.pi / 3.0


def angular_range(angles: ArrayLike, pad_angle: float = 0.0,
                  wrap_gap: float = DEFAULT_WRAP_GAP) -> dict[str, Any]:
    """Smallest arc covering ``angles`` (rad), by the largest-gap method, padded each side.

    Returns ``{"start": a0, "sweep": w, "full": bool}`` with ``0 <= a0 < 2π``.  The arc is the
    full turn when the largest gap between consecutive sorted angles is at most ``wrap_gap`` or
    when the padded sweep reaches 2π.
    """
    a = np.sort(np.mod(np.asarray(angles, dtype=float).ravel(), TWO_PI))
    if a.size == 0:
        raise InputError("cannot compute an angular range from 0 angles")
    if not (pad_angle >= 0.0 and math.isfinite(pad_angle)):
        raise InputError(f"angular padding must be finite and >= 0, got {pad_angle!r}")
    gaps = np.diff(np.append(a, a[0] + TWO_PI))
    k = int(np.argmax(gaps))
    largest = float(gaps[k])
    start = float(a[(k + 1) % a.size])
    sweep = TWO_PI - largest
    if a.size > 1 and largest <= wrap_gap:
        return _full()
    start -= pad_angle
    sweep += 2.0 * pad_angle
    if sweep >= TWO_PI:
        return _full()
    return {"start": float(np.mod(start, TWO_PI)), "sweep": float(sweep), "full": False}


def _full() -> dict[str, Any]:
    return {"start": 0.0, "sweep": TWO_PI, "full": True}


def _angles_about(axis: FloatArray, ref: FloatArray, rel: FloatArray) -> tuple[FloatArray,
                                                                             FloatArray]:
    """Angles of ``rel (N, 3)`` about ``axis`` from ``ref``, and their distances from the axis."""
    binormal = np.cross(axis, ref)
    x = rel @ ref
    y = rel @ binormal
    return np.arctan2(y, x), np.hypot(x, y)


def _angle_dict(ref: FloatArray, angles: FloatArray, radial: FloatArray, pad_angle: float,
                wrap_gap: float) -> dict[str, Any]:
    ok = radial > 1e-12
    rng = angular_range(angles[ok], pad_angle, wrap_gap) if np.any(ok) else _full()
    return {"reference": ref.tolist(), **rng}


def _line(params: Mapping[str, Any], pts: FloatArray, pad: float,
          wrap_gap: float) -> dict[str, Any]:
    dim = pts.shape[1]
    p0 = vector(params, "point", "line", (dim,))
    d = unit_vector(params, "direction", "line", (dim,))
    s = (pts - p0) @ d
    return {"s": [float(s.min() - pad), float(s.max() + pad)]}


def _circle(params: Mapping[str, Any], pts: FloatArray, pad: float,
            wrap_gap: float) -> dict[str, Any]:
    c = vector(params, "center", "circle", (2,))
    r = scalar(params, "radius", "circle")
    rel = pts - c
    angles = np.arctan2(rel[:, 1], rel[:, 0])
    radial = np.hypot(rel[:, 0], rel[:, 1])
    return {"angle": _angle_dict(np.array([1.0, 0.0]), angles, radial, pad / r, wrap_gap)}


def _plane(params: Mapping[str, Any], pts: FloatArray, pad: float,
           wrap_gap: float) -> dict[str, Any]:
    from scipy.spatial import ConvexHull

    p0 = vector(params, "point", "plane", (3,))
    n = unit_vector(params, "normal", "plane", (3,))
    u, v = perpendicular_basis(n)
    ab = np.stack([(pts - p0) @ u, (pts - p0) @ v], axis=1)
    # Minkowski sum with a 16-gon circumscribing the pad circle: pads the hull by >= pad in
    # every direction and makes 1, 2 or collinear points a proper polygon.
    k = 16
    radius = max(pad, 1e-6) / math.cos(math.pi / k)
    phi = np.arange(k) * (TWO_PI / k)
    ring = radius * np.stack([np.cos(phi), np.sin(phi)], axis=1)
    cloud = (ab[:, None, :] + ring[None, :, :]).reshape(-1, 2)
    hull = ConvexHull(cloud)
    polygon = cloud[hull.vertices]  # counter-clockwise for 2-D hulls
    return {"u": u.tolist(), "v": v.tolist(), "polygon": polygon.tolist()}


def _sphere(params: Mapping[str, Any], pts: FloatArray, pad: float,
            wrap_gap: float) -> dict[str, Any]:
    c = vector(params, "center", "sphere", (3,))
    r = scalar(params, "radius", "sphere")
    rel = pts - c
    norm = np.linalg.norm(rel, axis=1)
    dirs = rel[norm > 1e-12] / norm[norm > 1e-12, None]
    full = {"cap": {"direction": [0.0, 0.0, 1.0], "half_angle": math.pi, "full": True}}
    if dirs.shape[0] == 0:
        return full
    mean = dirs.mean(axis=0)
    if np.linalg.norm(mean) < 1e-9:
        return full
    d = mean / np.linalg.norm(mean)
    half = float(np.max(np.arccos(np.clip(dirs @ d, -1.0, 1.0)))) + pad / r
    # the uncovered cap around -d spans 2 (π - half): "wraps" like a circle's largest gap
    if 2.0 * (math.pi - half) <= wrap_gap:
        return full
    return {"cap": {"direction": d.tolist(), "half_angle": half, "full": False}}


def _cylinder(params: Mapping[str, Any], pts: FloatArray, pad: float,
              wrap_gap: float) -> dict[str, Any]:
    p0 = vector(params, "point", "cylinder", (3,))
    a = unit_vector(params, "axis", "cylinder", (3,))
    r = scalar(params, "radius", "cylinder")
    ref, _ = perpendicular_basis(a)
    rel = pts - p0
    s = rel @ a
    angles, radial = _angles_about(a, ref, rel)
    return {"s": [float(s.min() - pad), float(s.max() + pad)],
            "angle": _angle_dict(ref, angles, radial, pad / r, wrap_gap)}


def _cone(params: Mapping[str, Any], pts: FloatArray, pad: float,
          wrap_gap: float) -> dict[str, Any]:
    apex = vector(params, "apex", "cone", (3,))
    a = unit_vector(params, "axis", "cone", (3,))
    alpha = scalar(params, "half_angle", "cone", upper=math.pi / 2)
    ref, _ = perpendicular_basis(a)
    rel = pts - apex
    s = rel @ a
    s0 = max(0.0, float(s.min()) - pad)
    s1 = max(float(s.max()) + pad, s0 + pad, 1e-9)
    angles, radial = _angles_about(a, ref, rel)
    mean_radius = max(float(np.mean(np.clip(s, 0.0, None))) * math.tan(alpha), pad, 1e-9)
    return {"s": [s0, s1], "angle": _angle_dict(ref, angles, radial, pad / mean_radius, wrap_gap)}


def _torus(params: Mapping[str, Any], pts: FloatArray, pad: float,
           wrap_gap: float) -> dict[str, Any]:
    c = vector(params, "center", "torus", (3,))
    a = unit_vector(params, "axis", "torus", (3,))
    big = scalar(params, "major_radius", "torus")
    scalar(params, "minor_radius", "torus")
    ref, _ = perpendicular_basis(a)
    angles, radial = _angles_about(a, ref, pts - c)
    return {"angle": _angle_dict(ref, angles, radial, pad / big, wrap_gap), "minor": _full()}


ExtentFn = Callable[[Mapping[str, Any], FloatArray, float, float], dict[str, Any]]

#: extent builders by primitive kind
EXTENT_BUILDERS: dict[str, ExtentFn] = {
    "line": _line, "circle": _circle, "plane": _plane, "sphere": _sphere,
    "cylinder": _cylinder, "cone": _cone, "torus": _torus,
}


def support_extent(kind: str, params: Mapping[str, Any], points: ArrayLike, *,
                   pad: float = DEFAULT_PAD, wrap_gap: float = DEFAULT_WRAP_GAP
                   ) -> dict[str, Any]:
    """The region of a primitive its supporting contact points cover, as a JSON-ready dict.

    Parameters
    ----------
    kind : str
        Primitive type name (``"line"``, ``"circle"``, ``"plane"``, ``"sphere"``,
        ``"cylinder"``, ``"cone"``, ``"torus"``).
    params : mapping
        Parameters under their map.json names (arrays or lists).
    points : (N, d) float
        Supporting contact points (tip points; link contacts at their latent t), d = 2 for
        line/circle in planar maps, 3 otherwise.
    pad : float
        Padding beyond the outermost points, metres (angles: divided by the radius).
    wrap_gap : float
        Largest angular gap (rad) between points still treated as a full turn.

    Returns
    -------
    dict
        The extent (schemas in this module's docstring) plus ``"pad"`` and ``"n_points"``.
    """
    check_kind(kind)
    if not (math.isfinite(pad) and pad >= 0.0):
        raise InputError(f"extent padding must be finite and >= 0, got {pad!r}")
    if not (math.isfinite(wrap_gap) and 0.0 <= wrap_gap < TWO_PI):
        raise InputError(f"wrap_gap must lie in [0, 2π), got {wrap_gap!r}")
    dims = KIND_DIMS[kind]
    shape = np.shape(points)
    dim = shape[-1] if len(shape) and shape[-1] in dims else dims[-1]
    pts = as_support_points(points, dim, kind)
    extent = EXTENT_BUILDERS[kind](params, pts, float(pad), float(wrap_gap))
    extent["pad"] = float(pad)
    extent["n_points"] = int(pts.shape[0])
    return extent


def full_extent(kind: str, params: Mapping[str, Any]) -> dict[str, Any]:
    """The whole surface of a closed primitive (circle, sphere, torus); InputError otherwise."""
    check_kind(kind)
    if kind == "circle":
        return {"angle": {"reference": [1.0, 0.0], **_full()}, "pad": 0.0, "n_points": 0}
    if kind == "sphere":
        return {"cap": {"direction": [0.0, 0.0, 1.0], "half_angle": math.pi, "full": True},
                "pad": 0.0, "n_points": 0}
    if kind == "torus":
        a = unit_vector(params, "axis", "torus", (3,))
        ref, _ = perpendicular_basis(a)
        return {"angle": {"reference": ref.tolist(), **_full()},
                "minor": _full(), "pad": 0.0, "n_points": 0}
    raise InputError(f"a {kind} is unbounded: it needs an extent from its support points")
