"""The mesher's own small triangle-mesh record (numpy only; open3d/pyvista appear at export)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wholearm_tools.errors import InputError


@dataclass(frozen=True, slots=True)
class TriangleMesh:
    """An indexed triangle mesh.

    Attributes
    ----------
    vertices : (V, 3) float
        Vertex positions in metres (robot base frame).
    triangles : (F, 3) int64
        Vertex indices of each triangle, counter-clockwise seen from the side the triangle's
        normal points to (for primitives: the positive side of the signed distance, i.e. outside
        closed shapes and along a plane's normal).
    """

    vertices: NDArray[np.float64]
    triangles: NDArray[np.int64]

    def __post_init__(self) -> None:
        v = np.array(self.vertices, dtype=float)
        t = np.array(self.triangles, dtype=np.int64)
        if v.size == 0:
            v = v.reshape(0, 3)
        if t.size == 0:
            t = t.reshape(0, 3)
        if v.ndim != 2 or v.shape[1] != 3:
            raise InputError(
                f"expected mesh vertices of shape (V, 3), got {np.shape(self.vertices)}")
        if t.ndim != 2 or t.shape[1] != 3:
            raise InputError(
                f"expected mesh triangles of shape (F, 3), got {np.shape(self.triangles)}")
        if not np.all(np.isfinite(v)):
            raise InputError("mesh vertices contain NaN or infinite values")
        if t.size and (t.min() < 0 or t.max() >= len(v)):
            raise InputError(
                f"mesh triangle indices must lie in [0, {len(v)}), got [{t.min()}, {t.max()}]")
        v.setflags(write=False)
        t.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "triangles", t)

    @classmethod
    def empty(cls) -> TriangleMesh:
        return cls(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64))

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])

    @property
    def is_empty(self) -> bool:
        return self.n_triangles == 0

    @property
    def bounds(self) -> NDArray[np.float64]:
        """``[[xmin, ymin, zmin], [xmax, ymax, zmax]]``, shape ``(2, 3)`` (NaN when empty)."""
        if self.n_vertices == 0:
            return np.full((2, 3), np.nan)
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def triangle_normals(self) -> NDArray[np.float64]:
        """Unit normals (right-hand rule on the vertex order), shape ``(F, 3)``."""
        v = self.vertices[self.triangles]
        n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return n / np.where(norm > 0, norm, 1.0)

    def triangle_areas(self) -> NDArray[np.float64]:
        """Triangle areas in m², shape ``(F,)``."""
        v = self.vertices[self.triangles]
        return 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)

    def flipped(self) -> TriangleMesh:
        """The same surface with every triangle's orientation reversed."""
        return TriangleMesh(self.vertices, self.triangles[:, ::-1])


def merge_meshes(meshes: Iterable[TriangleMesh]) -> TriangleMesh:
    """Concatenate meshes into one (vertex indices offset; no welding)."""
    verts: list[ArrayLike] = []
    tris: list[ArrayLike] = []
    offset = 0
    for mesh in meshes:
        verts.append(mesh.vertices)
        tris.append(mesh.triangles + offset)
        offset += mesh.n_vertices
    if not verts:
        return TriangleMesh.empty()
    return TriangleMesh(np.concatenate(verts, axis=0), np.concatenate(tris, axis=0))
