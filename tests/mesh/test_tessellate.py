"""Tessellation: vertices on the primitive, outward triangles, coverage of the support points."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wholearm_tools.errors import InputError
from wholearm_tools.geometry.base import primitive_type
from wholearm_tools.mesh.extent import full_extent, support_extent
from wholearm_tools.mesh.tessellate import extrude, polyline, tessellate
from wholearm_tools.mesh.triangle_mesh import TriangleMesh, merge_meshes


def mesh_distance(mesh: TriangleMesh, points: np.ndarray) -> np.ndarray:
    """Unsigned distance of points to the mesh (open3d RaycastingScene)."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)),
                        o3d.core.Tensor(mesh.triangles.astype(np.uint32)))
    return scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()


KINDS_3D = ("cone", "cylinder", "plane", "sphere", "torus")


def edge_use(mesh: TriangleMesh) -> np.ndarray:
    e = np.sort(mesh.triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return counts


@pytest.mark.parametrize("kind", KINDS_3D)
def test_patch_mesh_lies_on_primitive_faces_out_and_covers_support(kind, shapes):
    params = shapes.params(kind)
    prim = primitive_type(kind).from_params(params)
    pts = shapes.support_points(kind)
    ext = support_extent(kind, params, pts)
    mesh = tessellate(kind, params, ext, resolution=0.01)
    assert mesh.n_triangles > 0
    assert np.abs(prim.signed_distance(mesh.vertices)).max() < 1e-9
    centroids = mesh.vertices[mesh.triangles].mean(axis=1)
    facing = np.einsum("ij,ij->i", mesh.triangle_normals(), prim.gradient(centroids))
    assert facing.min() > 0.95
    assert mesh_distance(mesh, pts).max() < 0.002  # every support point on the mesh (2 mm)
    assert mesh.triangle_areas().min() > 0.0


def test_cylinder_patch_area_matches_its_extent(shapes):
    params = shapes.params("cylinder")
    ext = support_extent("cylinder", params, shapes.support_points("cylinder"))
    mesh = tessellate("cylinder", params, ext, resolution=0.002)
    s0, s1 = ext["s"]
    expected = (s1 - s0) * params["radius"] * ext["angle"]["sweep"]
    assert mesh.triangle_areas().sum() == pytest.approx(expected, rel=1e-3)
    s = (mesh.vertices - params["point"]) @ params["axis"]
    assert s.min() == pytest.approx(s0)
    assert s.max() == pytest.approx(s1)


def test_full_sphere_is_closed_with_the_right_area():
    params = {"center": np.array([0.1, 0.2, 0.3]), "radius": 0.15}
    mesh = tessellate("sphere", params, full_extent("sphere", params), resolution=0.005)
    assert np.all(edge_use(mesh) == 2)  # watertight
    assert mesh.triangle_areas().sum() == pytest.approx(4 * math.pi * 0.15**2, rel=5e-3)
    # outward: the signed volume (divergence theorem) is positive
    v = mesh.vertices[mesh.triangles] - params["center"]
    volume = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6
    assert volume == pytest.approx(4 / 3 * math.pi * 0.15**3, rel=1e-2)


def test_full_torus_is_closed_with_the_right_area(shapes):
    params = shapes.params("torus")
    mesh = tessellate("torus", params, full_extent("torus", params), resolution=0.005)
    assert np.all(edge_use(mesh) == 2)
    assert mesh.triangle_areas().sum() == pytest.approx(4 * math.pi**2 * 0.3 * 0.05, rel=5e-3)


def test_cone_from_apex_has_a_single_apex_vertex(shapes):
    params = shapes.params("cone")
    ext = {"s": [0.0, 0.5], "angle": {"reference": [1.0, 0.0, 0.0], "full": True}}
    mesh = tessellate("cone", params, ext)
    at_apex = np.linalg.norm(mesh.vertices - params["apex"], axis=1) < 1e-12
    assert at_apex.sum() == 1
    slant = 0.5 / math.cos(0.4)
    assert mesh.triangle_areas().sum() == pytest.approx(
        math.pi * 0.5 * math.tan(0.4) * slant, rel=1e-3)


def test_extrude_line_and_arc(map_2d):
    line, circle = map_2d.primitives
    strip = extrude("line", line.params, line.extent, height=0.2)
    assert np.allclose(np.abs(strip.vertices[:, 2]), 0.1)
    assert np.allclose(strip.vertices[:, 0], 0.5)  # the wall x = 0.5
    s0, s1 = line.extent["s"]
    assert strip.triangle_areas().sum() == pytest.approx(0.2 * (s1 - s0))
    # normal of a 2-D line is its direction (0, 1) turned +90°: (-1, 0)
    assert np.allclose(strip.triangle_normals(), [-1.0, 0.0, 0.0])
    arc = extrude("circle", circle.params, circle.extent, height=0.2)
    radial = arc.vertices[:, :2] - circle.params["center"]
    assert np.allclose(np.linalg.norm(radial, axis=1), 0.1)
    cent = arc.vertices[arc.triangles].mean(axis=1)
    out = np.c_[cent[:, :2] - circle.params["center"], np.zeros(len(cent))]
    assert np.all(np.einsum("ij,ij->i", arc.triangle_normals(), out) > 0)


def test_polyline_line_and_closed_circle():
    line = polyline("line", {"point": [0.0, 0.0], "direction": [2.0, 0.0]}, {"s": [-1.0, 2.0]})
    assert np.allclose(line, [[-1.0, 0.0], [2.0, 0.0]])
    circle = {"center": [1.0, 1.0], "radius": 0.5}
    pts = polyline("circle", circle, full_extent("circle", circle))
    assert np.allclose(pts[0], pts[-1])
    assert np.allclose(np.linalg.norm(pts - [1.0, 1.0], axis=1), 0.5)
    arc = polyline("circle", circle, {"angle": {"start": 6.0, "sweep": 1.0, "full": False}})
    ang = np.unwrap(np.arctan2(arc[:, 1] - 1.0, arc[:, 0] - 1.0))
    assert ang[0] % (2 * math.pi) == pytest.approx(6.0)
    assert ang[-1] - ang[0] == pytest.approx(1.0)


def test_merge_offsets_indices():
    params = {"center": np.zeros(3), "radius": 1.0}
    a = tessellate("sphere", params, full_extent("sphere", params), resolution=0.5)
    merged = merge_meshes([a, a])
    assert merged.n_vertices == 2 * a.n_vertices
    assert np.array_equal(merged.triangles[a.n_triangles:], a.triangles + a.n_vertices)
    assert merge_meshes([]).is_empty


def test_tessellate_errors(shapes):
    cyl = shapes.params("cylinder")
    good = {"s": [0.0, 1.0], "angle": {"reference": [1.0, 0.0, 0.0], "full": True}}
    with pytest.raises(InputError, match="use extrude"):
        tessellate("line", {"point": [0, 0], "direction": [1, 0]}, {"s": [0, 1]})
    with pytest.raises(InputError, match="cylinder extent lacks 's'"):
        tessellate("cylinder", cyl, {"angle": good["angle"]})
    with pytest.raises(InputError, match=r"lo < hi, got \[1.0, 0.0\]"):
        tessellate("cylinder", cyl, {**good, "s": [1.0, 0.0]})
    with pytest.raises(InputError, match="parallel to the axis"):
        tessellate("cylinder", cyl, {**good, "angle": {"reference": list(cyl["axis"]),
                                                       "full": True}})
    with pytest.raises(InputError, match="s0 >= 0"):
        tessellate("cone", shapes.params("cone"), {**good, "s": [-0.1, 1.0]})
    with pytest.raises(InputError, match="resolution must be a positive length, got 0"):
        tessellate("cylinder", cyl, good, resolution=0)
    with pytest.raises(InputError, match=r"vertices of shape \(V, 3\)"):
        TriangleMesh(np.zeros((3, 2)), np.zeros((1, 3)))
    with pytest.raises(InputError, match=r"indices must lie in \[0, 3\)"):
        TriangleMesh(np.zeros((3, 3)), [[0, 1, 3]])
