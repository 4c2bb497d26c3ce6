"""Free-form surface through the contacts no primitive explains (open3d surface reconstruction)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from wholearm_tools.errors import InputError
from wholearm_tools.mesh.triangle_mesh import TriangleMesh

#: fewest distinct points a surface is reconstructed from
MIN_POINTS = 4
#: ball radii for ball pivoting, as multiples of the mean nearest-neighbour spacing
BALL_RADII = (1.5, 3.0, 6.0)
#: alpha of the alpha-shape fallback, as a multiple of the mean nearest-neighbour spacing
ALPHA = 6.0


@dataclass(frozen=True, slots=True)
class SurfaceReconstruction:
    """A reconstructed free-form surface; falsy (empty mesh, ``reason`` says why) on failure.

    ``method`` is ``"ball_pivoting"``, ``"alpha_shape"`` or ``"none"``.
    """

    mesh: TriangleMesh
    method: str
    reason: str = ""

    def __bool__(self) -> bool:
        return not self.mesh.is_empty


def _failed(reason: str) -> SurfaceReconstruction:
    return SurfaceReconstruction(TriangleMesh.empty(), "none", reason)


def unexplained_mesh(points: ArrayLike, knn: int = 10) -> SurfaceReconstruction:
    """Mesh the contact points no primitive explains.

    Normals are estimated from the ``knn`` nearest neighbours and oriented consistently, then
    ball pivoting runs with radii of 1.5, 3 and 6 times the mean nearest-neighbour spacing; if
    that yields no triangle, an alpha shape (alpha = 6 spacings) is tried.

    Parameters
    ----------
    points : (N, 3) float
        Contact points (tip contacts, link contacts at their latent t).
    knn : int
        Neighbours used for normal estimation.

    Returns
    -------
    SurfaceReconstruction
        The mesh and the method used; an empty mesh with a reason when there are too few
        distinct points or the points span no surface.
    """
    arr = np.asarray(points, dtype=float)
    if arr.size == 0:
        return _failed(f"needs at least {MIN_POINTS} points, got 0")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise InputError(f"expected unexplained points of shape (N, 3), got {np.shape(points)}")
    if not np.all(np.isfinite(arr)):
        raise InputError("unexplained points contain NaN or infinite values")
    if knn < 3:
        raise InputError(f"normal estimation needs knn >= 3, got {knn}")
    pts = np.unique(arr, axis=0)
    if pts.shape[0] < MIN_POINTS:
        return _failed(f"needs at least {MIN_POINTS} distinct points, got {pts.shape[0]}")
    centred = pts - pts.mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv[1] <= 1e-9 * max(sv[0], 1e-300):
        return _failed(f"the {pts.shape[0]} points are collinear: they span no surface")

    try:
        import open3d as o3d
    except ImportError as exc:      # open3d is optional: only this surface needs it
        return _failed(f"open3d is not available ({exc})")

    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        spacing = float(np.mean(np.asarray(cloud.compute_nearest_neighbor_distance())))
        cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=min(knn, len(pts))))
        cloud.orient_normals_consistent_tangent_plane(min(knn, len(pts) - 1))
        radii = o3d.utility.DoubleVector([k * spacing for k in BALL_RADII])
        mesh = o3d.geometry.TriangleMesh.create_from_point_cloud_ball_pivoting(cloud, radii)
        method = "ball_pivoting"
        if len(mesh.triangles) == 0:
            method = "alpha_shape"
            try:
                mesh = o3d.geometry.TriangleMesh.create_from_point_cloud_alpha_shape(
                    cloud, ALPHA * spacing)
            except RuntimeError:  # qhull on degenerate (e.g. coplanar) input
                mesh = o3d.geometry.TriangleMesh()
    triangles = np.asarray(mesh.triangles, dtype=np.int64)
    if triangles.shape[0] == 0:
        return _failed(f"surface reconstruction of {pts.shape[0]} points produced no triangle")
    return SurfaceReconstruction(
        TriangleMesh(np.asarray(mesh.vertices, dtype=float), triangles), method)
