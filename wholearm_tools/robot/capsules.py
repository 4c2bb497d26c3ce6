"""Capsules fitted to a URDF's collision geometry (meshes, boxes, cylinders, spheres).

wholearm models link ``i`` as a capsule around the segment from joint ``i`` to joint ``i + 1``
(the tip for the last link).  For a link described by meshes or boxes the axis is that segment
and the radius is the largest distance from it to any point of the link's collision geometry,
so the capsule covers the link completely.  Distance to a segment is convex, so its largest
value over a solid is reached at a vertex of the solid's convex hull: only hull vertices are
measured.  The capsule over-covers wherever the link is thinner than its widest point (a servo
that sticks out on one side sets the radius all round the link), and its end spheres reach
beyond short links; :class:`CapsuleFit` reports the capsule's volume against the hull's so the
user can judge.

Mesh files are found relative to the URDF's folder, through ``package://NAME/…`` in the
``package_paths`` folders (a folder ``NAME`` inside one of them, or a folder that is the package
itself) and ``$ROS_PACKAGE_PATH``, or as ``file://`` / absolute paths.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wholearm_tools.errors import RobotModelError

SPHERE_SUBDIVISIONS = 3
"""Icosphere subdivisions for sphere primitives in a mesh fit (642 vertices; the inscribed
polyhedron is within 0.3 % of the radius)."""

CYLINDER_SECTIONS = 64
"""Cylinder primitives in a mesh fit are polygons of this many sides, scaled so that they
circumscribe the cylinder (covering it)."""


@dataclass(frozen=True, slots=True)
class CapsuleFit:
    """How one link's capsule was obtained.

    ``method``: ``"capsule"`` (the URDF already describes the link with a cylinder and/or
    spheres: its radius is used as is) or ``"mesh"`` (fitted to meshes/boxes as described in
    the module docstring).
    ``sources``: the URDF links whose geometry was used; ``radius`` and ``length`` [m];
    ``hull_volume`` and ``capsule_volume`` [m³] (0 when not a mesh fit); ``widest``: where the
    radius was set, as a fraction along the axis (may lie outside 0..1 when geometry reaches
    beyond a joint).
    """

    link: int
    joint: str
    method: str
    sources: tuple[str, ...]
    radius: float
    length: float
    hull_volume: float = 0.0
    capsule_volume: float = 0.0
    widest: float = 0.0
    vertices: int = 0

    @property
    def over_cover(self) -> float:
        """Capsule volume over the geometry's convex hull volume (≥ 1; 0 when not fitted)."""
        return self.capsule_volume / self.hull_volume if self.hull_volume > 0 else 0.0

    def describe(self) -> str:
        """One line for the capsule URDF's comments and ``wholearm robot``."""
        what = ", ".join(self.sources)
        if self.method == "capsule":
            return f"capsule radius from the URDF's cylinder/sphere on {what}"
        return (f"capsule fitted to the collision geometry of {what} ({self.vertices} hull "
                f"vertices): covers all of it; widest at {self.widest:.2f} of the axis; capsule "
                f"volume {self.over_cover:.1f}x the geometry's convex hull")


def resolve_mesh_path(filename: str, *, urdf_dir: Path | None, package_paths: Sequence[Path],
                      source: str, link: str) -> Path:
    """Local file of a URDF mesh reference; RobotModelError naming the reference otherwise."""
    searched: list[Path] = []
    if filename.startswith("package://"):
        package, _, rest = filename[len("package://"):].partition("/")
        roots = list(package_paths) + [Path(p) for p in
                                       os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep)
                                       if p]
        for root in roots:
            for candidate in (root / package / rest, root / rest if root.name == package
                              else None):
                if candidate is None:
                    continue
                searched.append(candidate)
                if candidate.is_file():
                    return candidate
        where = ", ".join(str(r) for r in roots) or "none given"
        raise RobotModelError(f"{source}: link {link!r}: mesh {filename!r} not found: package "
                              f"{package!r} is not in the --package-path folders ({where})")
    path = Path(filename[len("file://"):] if filename.startswith("file://") else filename)
    if path.is_absolute():
        searched.append(path)
    else:
        bases = ([urdf_dir] if urdf_dir is not None else []) + list(package_paths)
        searched.extend(base / path for base in bases)
    for candidate in searched:
        if candidate.is_file():
            return candidate
    where = ", ".join(str(p) for p in searched) or (
        "a URDF from a log has no folder: give the mesh folder with --package-path")
    raise RobotModelError(f"{source}: link {link!r}: mesh {filename!r} not found (looked for "
                          f"{where})")


def _mesh_vertices(geometry: Any, *, urdf_dir: Path | None, package_paths: Sequence[Path],
                   source: str, link: str) -> np.ndarray:
    """Vertices (k, 3) of one collision geometry in its own frame (primitives covered)."""
    from wholearm_tools._parallel import interruptible_import

    trimesh = interruptible_import("trimesh")

    if geometry.mesh is not None:
        path = resolve_mesh_path(geometry.mesh.filename, urdf_dir=urdf_dir,
                                 package_paths=package_paths, source=source, link=link)
        try:
            mesh = trimesh.load(str(path), force="mesh", process=False)
        except Exception as exc:
            raise RobotModelError(f"{source}: link {link!r}: cannot read mesh {path} "
                                  f"({type(exc).__name__}: {exc})") from None
        vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=float)
        if vertices.ndim != 2 or vertices.shape[0] == 0 or vertices.shape[1] != 3:
            raise RobotModelError(f"{source}: link {link!r}: mesh {path} has no vertices")
        scale = geometry.mesh.scale
        if scale is not None:
            vertices = vertices * np.broadcast_to(np.asarray(scale, dtype=float), (3,))
        return vertices
    if geometry.box is not None:
        return trimesh.creation.box(extents=np.asarray(geometry.box.size, dtype=float)).vertices
    if geometry.cylinder is not None:
        c = geometry.cylinder
        # a polygon circumscribing the circle, so the covering radius is not underestimated
        r = float(c.radius) / math.cos(math.pi / CYLINDER_SECTIONS)
        return trimesh.creation.cylinder(radius=r, height=float(c.length),
                                         sections=CYLINDER_SECTIONS).vertices
    if geometry.sphere is not None:
        sphere = trimesh.creation.icosphere(subdivisions=SPHERE_SUBDIVISIONS,
                                            radius=float(geometry.sphere.radius))
        return sphere.vertices
    raise RobotModelError(f"{source}: link {link!r}: collision without geometry")


def group_points(links: Sequence[Any], poses: Sequence[np.ndarray], *, urdf_dir: Path | None,
                 package_paths: Sequence[Path], source: str) -> tuple[np.ndarray, list[str]]:
    """Collision vertices of ``links`` (yourdfpy Links at ``poses`` in a joint frame), ``(k, 3)``,
    and the names of the links that had collision geometry.  Links without collision geometry
    fall back to their visual geometry."""
    clouds: list[np.ndarray] = []
    used: list[str] = []
    for link, pose in zip(links, poses, strict=True):
        shapes = link.collisions or link.visuals
        for shape in shapes:
            if shape.geometry is None:
                continue
            vertices = _mesh_vertices(shape.geometry, urdf_dir=urdf_dir,
                                      package_paths=package_paths, source=source, link=link.name)
            origin = np.eye(4) if shape.origin is None else np.asarray(shape.origin, dtype=float)
            tf = pose @ origin
            clouds.append(vertices @ tf[:3, :3].T + tf[:3, 3])
        if shapes and link.name not in used:
            used.append(link.name)
    return (np.concatenate(clouds) if clouds else np.zeros((0, 3))), used


def hull(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Convex hull vertices and volume of ``points (k, 3)`` (the points and 0 when flat)."""
    from scipy.spatial import ConvexHull, QhullError

    if points.shape[0] < 4:
        return points, 0.0
    try:
        h = ConvexHull(points)
    except QhullError:
        return points, 0.0
    return points[h.vertices], float(h.volume)


def segment_distances(points: np.ndarray, end: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distances of ``points (k, 3)`` to the segment from the origin to ``end (3,)`` and the
    unclamped fraction along it of each point's projection."""
    length2 = float(end @ end)
    s = points @ end / length2 if length2 > 0 else np.zeros(points.shape[0])
    closest = np.clip(s, 0.0, 1.0)[:, None] * end
    return np.linalg.norm(points - closest, axis=1), s


def far_point(points: np.ndarray) -> np.ndarray:
    """The point of ``points (k, 3)`` farthest from the origin (the joint)."""
    return points[int(np.argmax(np.linalg.norm(points, axis=1)))]


def fit_capsule(points: np.ndarray, end: np.ndarray, *, link: int, joint: str,
                sources: Sequence[str]) -> CapsuleFit:
    """The capsule around the segment origin → ``end`` covering ``points (k, 3)``."""
    vertices, volume = hull(points)
    dist, s = segment_distances(vertices, end)
    k = int(np.argmax(dist))
    radius = float(dist[k])
    length = float(np.linalg.norm(end))
    capsule = math.pi * radius ** 2 * length + 4.0 / 3.0 * math.pi * radius ** 3
    return CapsuleFit(link=link, joint=joint, method="mesh", sources=tuple(sources),
                      radius=radius, length=length, hull_volume=volume, capsule_volume=capsule,
                      widest=float(s[k]), vertices=int(vertices.shape[0]))
