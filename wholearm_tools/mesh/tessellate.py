"""Bounded meshes of primitives over their extents (numpy only).

Every vertex lies exactly on the primitive (to rounding): curved directions are sampled, ruled
directions (cylinder and cone generators, plane polygons, extruded 2-D lines) use their exact end
points.  Triangles face the positive side of the primitive's signed distance (outside closed
shapes, along a plane's normal, along a 2-D line's left normal), see
:mod:`wholearm_tools.geometry.base`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from wholearm_tools.errors import InputError
from wholearm_tools.mesh._params import (
    TWO_PI,
    FloatArray,
    check_kind,
    scalar,
    unit_vector,
    vector,
)
from wholearm_tools.mesh.triangle_mesh import TriangleMesh

#: default largest edge length along curved directions, metres
DEFAULT_RESOLUTION = 0.005
#: largest angular step whatever the radius, so small shapes still look round (5 degrees)
MAX_ANGLE_STEP = math.radians(5.0)
#: cap on the samples of one curved direction (keeps a huge radius from exploding the mesh)
MAX_SAMPLES = 2048


# ---------------------------------------------------------------------------------------------
# extent access (extents come from JSON: validate with the offending value in the message)


def _get(extent: Mapping[str, Any], key: str, kind: str) -> Any:
    try:
        return extent[key]
    except (KeyError, TypeError):
        raise InputError(f"{kind} extent lacks {key!r} (got {extent!r:.200})") from None


def _range(extent: Mapping[str, Any], key: str, kind: str) -> tuple[float, float]:
    value = _get(extent, key, kind)
    try:
        lo, hi = (float(x) for x in value)
    except (TypeError, ValueError):
        raise InputError(f"{kind} extent {key!r} must be [lo, hi], got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise InputError(f"{kind} extent {key!r} must be finite with lo < hi, got {value!r}")
    return lo, hi


def _angle(extent: Mapping[str, Any], key: str, kind: str) -> tuple[float, float, bool]:
    """``(start, sweep, full)`` of an ANGLE entry."""
    value = _get(extent, key, kind)
    try:
        full = bool(value.get("full", False))
        start = float(value.get("start", 0.0))
        sweep = float(value.get("sweep", TWO_PI))
    except (AttributeError, TypeError, ValueError):
        raise InputError(f"{kind} extent {key!r} must be an angle record, got {value!r}") from None
    if full:
        return start, TWO_PI, True
    if not (math.isfinite(start) and math.isfinite(sweep) and 0.0 < sweep <= TWO_PI):
        raise InputError(f"{kind} extent {key!r} needs a finite sweep in (0, 2π], got {value!r}")
    return start, sweep, sweep >= TWO_PI


def _reference(extent: Mapping[str, Any], axis: FloatArray, kind: str) -> tuple[FloatArray,
                                                                                FloatArray]:
    """The extent's reference direction made exactly perpendicular to ``axis``, and axis × it."""
    rec = _get(extent, "angle", kind)
    ref = vector(rec if isinstance(rec, Mapping) else {}, "reference", f"{kind} extent angle",
                 (3,))
    ref = ref - float(ref @ axis) * axis
    norm = float(np.linalg.norm(ref))
    if norm < 1e-9:
        raise InputError(f"{kind} extent reference {rec.get('reference')!r} is parallel to the "
                         f"axis {axis.tolist()}")
    ref = ref / norm
    return ref, np.cross(axis, ref)


def _samples(length: float, resolution: float, angle: float | None = None) -> int:
    """Number of intervals for a curve of ``length`` metres (and ``angle`` radians)."""
    n = math.ceil(length / resolution) if length > 0 else 1
    if angle is not None:
        n = max(n, math.ceil(angle / MAX_ANGLE_STEP))
    return int(min(max(n, 1), MAX_SAMPLES))


# ---------------------------------------------------------------------------------------------
# generic surface of revolution


def revolve(origin: FloatArray, axis: FloatArray, ref: FloatArray, profile: FloatArray,
            start: float, sweep: float, full: bool, n_phi: int,
            closed_profile: bool = False) -> TriangleMesh:
    """Mesh of the surface swept by ``profile`` rotating about ``axis``.

    ``profile (K, 2)`` holds (axial, radial) coordinates in the meridian half-plane; vertex
    ``(k, j)`` is ``origin + axial_k axis + radial_k (cos φ_j ref + sin φ_j (axis × ref))``.  A
    profile point on the axis (radial 0) becomes a single vertex (pole / apex).  ``full`` closes
    the angular direction; ``closed_profile`` joins the last profile point to the first.
    """
    binormal = np.cross(axis, ref)
    n_ring = n_phi if full else n_phi + 1
    phi = start + np.arange(n_ring) * (sweep / n_phi)
    circle = np.cos(phi)[:, None] * ref + np.sin(phi)[:, None] * binormal  # (n_ring, 3)
    verts: list[FloatArray] = []
    rings: list[np.ndarray] = []
    count = 0
    for axial, radial in profile:
        centre = origin + axial * axis
        if abs(radial) < 1e-15:
            verts.append(centre[None, :])
            rings.append(np.full(n_ring, count))
            count += 1
        else:
            verts.append(centre + radial * circle)
            rings.append(count + np.arange(n_ring))
            count += n_ring
    pairs = [(k, k + 1) for k in range(len(rings) - 1)]
    if closed_profile:
        pairs.append((len(rings) - 1, 0))
    tris: list[np.ndarray] = []
    j = np.arange(n_phi)
    j1 = (j + 1) % n_ring
    for k0, k1 in pairs:
        a, b = rings[k0][j], rings[k0][j1]
        c, d = rings[k1][j1], rings[k1][j]
        for t in (np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)):
            keep = (t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 0] != t[:, 2])
            tris.append(t[keep])
    return TriangleMesh(np.concatenate(verts, axis=0),
                        np.concatenate(tris, axis=0) if tris else np.zeros((0, 3), np.int64))


def _orient(mesh: TriangleMesh, outward: Callable[[FloatArray], FloatArray]) -> TriangleMesh:
    """Flip ``mesh`` if its triangles mostly face against ``outward(centroids)``."""
    if mesh.is_empty:
        return mesh
    cent = mesh.vertices[mesh.triangles].mean(axis=1)
    n = np.cross(*(mesh.vertices[mesh.triangles[:, i]] - mesh.vertices[mesh.triangles[:, 0]]
                   for i in (1, 2)))
    score = float(np.sum(np.einsum("ij,ij->i", n, outward(cent))))
    return mesh if score >= 0.0 else mesh.flipped()


def _radial_dir(origin: FloatArray, axis: FloatArray) -> Callable[[FloatArray], FloatArray]:
    def outward(p: FloatArray) -> FloatArray:
        q = p - origin
        return q - np.outer(q @ axis, axis)

    return outward


# ---------------------------------------------------------------------------------------------
# the 3-D primitives


def _plane(params: Mapping[str, Any], extent: Mapping[str, Any], resolution: float
           ) -> TriangleMesh:
    p0 = vector(params, "point", "plane", (3,))
    n = unit_vector(params, "normal", "plane", (3,))
    u = vector(extent, "u", "plane extent", (3,))
    v = vector(extent, "v", "plane extent", (3,))
    poly = np.asarray(_get(extent, "polygon", "plane"), dtype=float)
    if poly.ndim != 2 or poly.shape[1] != 2 or poly.shape[0] < 3 or \
            not np.all(np.isfinite(poly)):
        raise InputError(f"plane extent polygon must be (K >= 3, 2) finite, got shape "
                         f"{poly.shape}")
    # make u, v exactly in-plane so every vertex lies on the plane to rounding
    u = u - float(u @ n) * n
    v = v - float(v @ n) * n
    verts = p0 + poly[:, 0:1] * u + poly[:, 1:2] * v
    centre = verts.mean(axis=0)
    k = poly.shape[0]
    idx = np.arange(k)
    tris = np.stack([np.full(k, k), idx, (idx + 1) % k], axis=1)
    mesh = TriangleMesh(np.vstack([verts, centre]), tris)
    return _orient(mesh, lambda p: np.broadcast_to(n, p.shape))


def _sphere(params: Mapping[str, Any], extent: Mapping[str, Any], resolution: float
            ) -> TriangleMesh:
    c = vector(params, "center", "sphere", (3,))
    r = scalar(params, "radius", "sphere")
    cap = _get(extent, "cap", "sphere")
    if not isinstance(cap, Mapping):
        raise InputError(f"sphere extent 'cap' must be a record, got {cap!r}")
    if cap.get("full", False):
        d, half = np.array([0.0, 0.0, 1.0]), math.pi
    else:
        d = unit_vector(cap, "direction", "sphere extent cap", (3,))
        half = scalar(cap, "half_angle", "sphere extent cap")
        half = min(half, math.pi)
    ref = np.zeros(3)
    ref[int(np.argmin(np.abs(d)))] = 1.0
    ref = ref - float(ref @ d) * d
    ref /= np.linalg.norm(ref)
    n_theta = _samples(r * half, resolution, half)
    theta = np.linspace(0.0, half, n_theta + 1)
    profile = np.stack([r * np.cos(theta), r * np.sin(theta)], axis=1)
    if half >= math.pi:
        profile[-1] = (-r, 0.0)
    n_phi = max(_samples(TWO_PI * r * math.sin(min(half, math.pi / 2)), resolution, TWO_PI), 3)
    mesh = revolve(c, d, ref, profile, 0.0, TWO_PI, True, n_phi)
    return _orient(mesh, lambda p: p - c)


def _cylinder(params: Mapping[str, Any], extent: Mapping[str, Any], resolution: float
              ) -> TriangleMesh:
    p0 = vector(params, "point", "cylinder", (3,))
    a = unit_vector(params, "axis", "cylinder", (3,))
    r = scalar(params, "radius", "cylinder")
    s0, s1 = _range(extent, "s", "cylinder")
    start, sweep, full = _angle(extent, "angle", "cylinder")
    ref, _ = _reference(extent, a, "cylinder")
    n_phi = _samples(r * sweep, resolution, sweep)
    mesh = revolve(p0, a, ref, np.array([[s0, r], [s1, r]]), start, sweep, full,
                   max(n_phi, 3) if full else n_phi)
    return _orient(mesh, _radial_dir(p0, a))


def _cone(params: Mapping[str, Any], extent: Mapping[str, Any], resolution: float
          ) -> TriangleMesh:
    apex = vector(params, "apex", "cone", (3,))
    a = unit_vector(params, "axis", "cone", (3,))
    alpha = scalar(params, "half_angle", "cone", upper=math.pi / 2)
    s0, s1 = _range(extent, "s", "cone")
    if s0 < 0.0:
        raise InputError(f"cone extent 's' must start at or after the apex (s0 >= 0), got {s0}")
    start, sweep, full = _angle(extent, "angle", "cone")
    ref, _ = _reference(extent, a, "cone")
    tan = math.tan(alpha)
    n_phi = _samples(s1 * tan * sweep, resolution, sweep)
    mesh = revolve(apex, a, ref, np.array([[s0, s0 * tan], [s1, s1 * tan]]), start, sweep,
                   full, max(n_phi, 3) if full else n_phi)
    sa, ca = math.sin(alpha), math.cos(alpha)

    def outward(p: FloatArray) -> FloatArray:
        radial = _radial_dir(apex, a)(p)
        e = radial / np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-300)
        return ca * e - sa * a

    return _orient(mesh, outward)


def _torus(params: Mapping[str, Any], extent: Mapping[str, Any], resolution: float
           ) -> TriangleMesh:
    c = vector(params, "center", "torus", (3,))
    a = unit_vector(params, "axis", "torus", (3,))
    big = scalar(params, "major_radius", "torus")
    small = scalar(params, "minor_radius", "torus")
    if small >= big:
        raise InputError(f"torus minor_radius must be < major_radius, got {small} >= {big}")
    start, sweep, full = _angle(extent, "angle", "torus")
    ref, _ = _reference(extent, a, "torus")
    n_psi = max(_samples(TWO_PI * small, resolution, TWO_PI), 3)
    psi = np.arange(n_psi) * (TWO_PI / n_psi)
    profile = np.stack([small * np.sin(psi), big + small * np.cos(psi)], axis=1)
    n_phi = _samples((big + small) * sweep, resolution, sweep)
    mesh = revolve(c, a, ref, profile, start, sweep, full, max(n_phi, 3) if full else n_phi,
                   closed_profile=True)

    def outward(p: FloatArray) -> FloatArray:
        radial = _radial_dir(c, a)(p)
        e = radial / np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-300)
        return p - (c + big * e)

    return _orient(mesh, outward)


Tessellator = Callable[[Mapping[str, Any], Mapping[str, Any], float], TriangleMesh]

#: 3-D tessellators by primitive kind
TESSELLATORS: dict[str, Tessellator] = {
    "plane": _plane, "sphere": _sphere, "cylinder": _cylinder, "cone": _cone, "torus": _torus,
}


def _check_resolution(resolution: float) -> float:
    if not (math.isfinite(resolution) and resolution > 0.0):
        raise InputError(f"mesh resolution must be a positive length, got {resolution!r}")
    return float(resolution)


def tessellate(kind: str, params: Mapping[str, Any], extent: Mapping[str, Any],
               resolution: float = DEFAULT_RESOLUTION) -> TriangleMesh:
    """Triangle mesh of a 3-D primitive over its extent.

    Parameters
    ----------
    kind : str
        ``"plane"``, ``"sphere"``, ``"cylinder"``, ``"cone"`` or ``"torus"`` (2-D lines and
        circles: :func:`extrude`).
    params : mapping
        Parameters under their map.json names.
    extent : mapping
        The region to mesh, as made by :func:`~wholearm_tools.mesh.extent.support_extent`.
    resolution : float
        Largest edge length along curved directions, metres (angular steps are at most 5°).

    Returns
    -------
    TriangleMesh
        Vertices on the primitive, triangles facing its positive side.
    """
    check_kind(kind)
    resolution = _check_resolution(resolution)
    if kind not in TESSELLATORS:
        raise InputError(f"{kind} is a 2-D primitive: use extrude() or polyline() for it")
    return TESSELLATORS[kind](params, extent, resolution)


# ---------------------------------------------------------------------------------------------
# planar maps: 2-D lines and circles


def _line2d(params: Mapping[str, Any], extent: Mapping[str, Any]
            ) -> tuple[FloatArray, FloatArray, float, float]:
    p0 = vector(params, "point", "line", (2,))
    d = unit_vector(params, "direction", "line", (2,))
    s0, s1 = _range(extent, "s", "line")
    return p0, d, s0, s1


def _circle2d(params: Mapping[str, Any], extent: Mapping[str, Any]
              ) -> tuple[FloatArray, float, float, float, bool]:
    c = vector(params, "center", "circle", (2,))
    r = scalar(params, "radius", "circle")
    start, sweep, full = _angle(extent, "angle", "circle")
    return c, r, start, sweep, full


def polyline(kind2d: str, params: Mapping[str, Any], extent: Mapping[str, Any],
             resolution: float = DEFAULT_RESOLUTION) -> FloatArray:
    """Points ``(N, 2)`` along a 2-D line or circle over its extent (closed circles repeat the
    first point at the end)."""
    resolution = _check_resolution(resolution)
    if kind2d == "line":
        p0, d, s0, s1 = _line2d(params, extent)
        return np.stack([p0 + s0 * d, p0 + s1 * d])
    if kind2d == "circle":
        c, r, start, sweep, _ = _circle2d(params, extent)
        n = _samples(r * sweep, resolution, sweep)
        phi = start + np.linspace(0.0, sweep, n + 1)
        pts = c + r * np.stack([np.cos(phi), np.sin(phi)], axis=1)
        if sweep >= TWO_PI:
            pts[-1] = pts[0]
        return pts
    raise InputError(f"polyline() draws 2-D lines and circles, got {kind2d!r}")


def extrude(kind2d: str, params: Mapping[str, Any], extent: Mapping[str, Any], height: float,
            resolution: float = DEFAULT_RESOLUTION) -> TriangleMesh:
    """A 3-D strip mesh of a 2-D line or circle over its extent, extruded along z to ±height/2.

    The arm's plane is z = 0; triangles face the 2-D primitive's positive side (left of a line's
    direction, outside a circle).
    """
    resolution = _check_resolution(resolution)
    if not (math.isfinite(height) and height > 0.0):
        raise InputError(f"extrusion height must be a positive length, got {height!r}")
    h = 0.5 * height
    z = np.array([0.0, 0.0, 1.0])
    if kind2d == "line":
        p0, d, s0, s1 = _line2d(params, extent)
        a = np.append(p0 + s0 * d, 0.0)
        b = np.append(p0 + s1 * d, 0.0)
        verts = np.stack([a - h * z, b - h * z, b + h * z, a + h * z])
        normal = np.array([-d[1], d[0], 0.0])
        mesh = TriangleMesh(verts, np.array([[0, 1, 2], [0, 2, 3]]))
        return _orient(mesh, lambda p: np.broadcast_to(normal, p.shape))
    if kind2d == "circle":
        c2, r, start, sweep, full = _circle2d(params, extent)
        c = np.append(c2, 0.0)
        n_phi = _samples(r * sweep, resolution, sweep)
        mesh = revolve(c, z, np.array([1.0, 0.0, 0.0]), np.array([[-h, r], [h, r]]), start,
                       sweep, full, max(n_phi, 3) if full else n_phi)
        return _orient(mesh, _radial_dir(c, z))
    raise InputError(f"extrude() takes 2-D lines and circles, got {kind2d!r}")
