"""Map meshes, unexplained surfaces, file export round trips and atomicity, drawings."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from wholearm_tools.errors import InputError, OutputError
from wholearm_tools.mapfile import MappedPrimitive, SurfaceMap
from wholearm_tools.mesh.export import (
    export_drawing,
    export_mesh,
    map_mesh,
    map_meshes,
)
from wholearm_tools.mesh.triangle_mesh import TriangleMesh
from wholearm_tools.mesh.unexplained import unexplained_mesh

FORMATS = ("ply", "stl", "obj", "gltf", "glb", "vtp")


def read_back(path) -> tuple[np.ndarray, int]:
    """Vertices and triangle count of a written file, read by open3d (pyvista for VTP)."""
    if path.suffix == ".vtp":
        import pyvista as pv

        poly = pv.read(path)
        assert poly.is_all_triangles
        return np.asarray(poly.points), poly.n_cells
    import open3d as o3d

    mesh = o3d.io.read_triangle_mesh(str(path))
    return np.asarray(mesh.vertices), len(mesh.triangles)


@pytest.mark.parametrize("fmt", FORMATS)
def test_export_round_trip(fmt, map_3d, tmp_path):
    mesh = map_mesh(map_3d, resolution=0.02, include_unexplained=False)
    out = export_mesh(mesh, tmp_path / f"map.{fmt}")
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"map.{fmt}"]  # no temporaries
    verts, n_tri = read_back(out)
    assert n_tri == mesh.n_triangles
    if fmt != "stl":  # STL stores three corners per triangle, readers re-index them
        assert len(verts) == mesh.n_vertices
    tol = 1e-6 if fmt != "obj" else 2e-6  # float32 in STL/glTF, printed decimals in OBJ
    assert np.abs(verts.min(axis=0) - mesh.bounds[0]).max() < tol
    assert np.abs(verts.max(axis=0) - mesh.bounds[1]).max() < tol


def test_export_format_from_argument_and_errors(map_3d, tmp_path):
    mesh = map_mesh(map_3d, resolution=0.05, include_unexplained=False)
    out = export_mesh(mesh, tmp_path / "mesh.bin", format="PLY")
    assert read_back(out.rename(tmp_path / "mesh.ply"))[1] == mesh.n_triangles
    with pytest.raises(InputError, match="unsupported format 'dxf'"):
        export_mesh(mesh, tmp_path / "m.dxf")
    with pytest.raises(InputError, match="nothing to export"):
        export_mesh(TriangleMesh.empty(), tmp_path / "empty.ply")
    with pytest.raises(OutputError, match="does not exist"):
        export_mesh(mesh, tmp_path / "missing" / "m.ply")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.ply"]


def test_failed_write_leaves_target_and_no_temporary(map_3d, tmp_path, monkeypatch):
    import open3d as o3d

    mesh = map_mesh(map_3d, resolution=0.05, include_unexplained=False)
    target = tmp_path / "map.stl"
    target.write_bytes(b"previous")

    def failing(path, *args, **kwargs):
        with open(path, "wb") as f:
            f.write(b"half")
        return False

    monkeypatch.setattr(o3d.io, "write_triangle_mesh", failing)
    with pytest.raises(OutputError, match="could not write the STL"):
        export_mesh(mesh, target)
    assert target.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["map.stl"]


def test_map_mesh_merges_primitives_and_unexplained(map_3d):
    named = map_meshes(map_3d, resolution=0.02)
    assert [name for name, _ in named] == ["primitive/0", "primitive/1", "unexplained"]
    merged = map_mesh(map_3d, resolution=0.02)
    assert merged.n_vertices == sum(m.n_vertices for _, m in named)
    assert merged.n_triangles == sum(m.n_triangles for _, m in named)
    without = map_mesh(map_3d, resolution=0.02, include_unexplained=False)
    assert without.n_triangles == merged.n_triangles - named[2][1].n_triangles


def test_map_without_extent_for_unbounded_primitive_is_an_input_error():
    plane = MappedPrimitive(3, "plane", {"point": np.zeros(3), "normal": np.array([0, 0, 1.0])})
    with pytest.raises(InputError, match=r"primitive 3 \(plane\): no extent"):
        map_mesh(SurfaceMap(planar=False, B=0.02, primitives=(plane,)))
    sphere = MappedPrimitive(4, "sphere", {"center": np.zeros(3), "radius": 0.1})
    whole = map_mesh(SurfaceMap(planar=False, B=0.02, primitives=(sphere,)))
    assert np.allclose(np.linalg.norm(whole.vertices, axis=1), 0.1)


def test_unexplained_mesh_passes_through_the_points():
    rng = np.random.default_rng(1)
    xy = rng.uniform(-0.1, 0.1, size=(60, 2))
    pts = np.c_[xy, 0.02 * np.sin(20 * xy[:, 0])]
    surface = unexplained_mesh(pts)
    assert surface
    assert surface.method in ("ball_pivoting", "alpha_shape")
    assert surface.mesh.n_triangles >= 30
    # reconstruction interpolates: its vertices are the input points
    d = np.linalg.norm(surface.mesh.vertices[:, None] - pts[None], axis=2).min(axis=1)
    assert d.max() < 1e-12


@pytest.mark.parametrize(("points", "reason"), [
    (np.zeros((0, 3)), "at least 4 points, got 0"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]), "at least 4 distinct points, got 3"),
    (np.array([[0, 0, 0.0]] * 10), "at least 4 distinct points, got 1"),
    (np.c_[np.linspace(0, 1, 8), np.zeros(8), np.zeros(8)], "collinear"),
])
def test_unexplained_mesh_degrades_with_a_reason(points, reason):
    surface = unexplained_mesh(points)
    assert not surface
    assert surface.mesh.is_empty
    assert reason in surface.reason


def test_unexplained_mesh_rejects_bad_input():
    with pytest.raises(InputError, match=r"shape \(N, 3\), got \(4, 2\)"):
        unexplained_mesh(np.zeros((4, 2)))


@pytest.mark.parametrize("fmt", ["svg", "png"])
def test_drawing_of_planar_map(fmt, map_2d, tmp_path):
    out = export_drawing(map_2d, tmp_path / f"map.{fmt}",
                         contact_points=np.array([[0.5, 0.0], [0.1, 0.4]]))
    data = out.read_bytes()
    if fmt == "png":
        assert data.startswith(b"\x89PNG\r\n\x1a\n")
    else:
        root = ET.fromstring(data)
        assert root.tag.endswith("svg")
        # legend entries (matplotlib keeps text as comments next to the glyph paths)
        for label in (b"#0 line", b"#1 circle", b"unexplained", b"contacts"):
            assert label in data
        again = export_drawing(map_2d, tmp_path / "again.svg",
                               contact_points=np.array([[0.5, 0.0], [0.1, 0.4]]))
        assert again.read_bytes() == data  # deterministic
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries


def test_drawing_errors(map_2d, map_3d, tmp_path):
    with pytest.raises(InputError, match="planar maps only"):
        export_drawing(map_3d, tmp_path / "m.svg")
    with pytest.raises(InputError, match=r"shape \(N, 2\)"):
        export_drawing(map_2d, tmp_path / "m.svg", contact_points=np.zeros((3, 3)))
    with pytest.raises(InputError, match="unsupported format 'pdf'"):
        export_drawing(map_2d, tmp_path / "m.pdf")
    assert list(tmp_path.iterdir()) == []


def test_planar_map_mesh_is_extruded_strips(map_2d):
    mesh = map_mesh(map_2d, height=0.3)
    assert np.allclose(np.abs(mesh.vertices[:, 2]), 0.15)


def test_unexplained_contacts_too_few_to_mesh_are_reported_once(map_3d, caplog):
    """The exports, the overlay and the report mesh the same map: the reason the unexplained
    contacts could not be meshed is logged once, not once per output."""
    import dataclasses
    import logging

    from wholearm_tools.mesh.export import map_meshes

    few = dataclasses.replace(map_3d, unexplained=map_3d.unexplained[:2] + 1e-3)
    with caplog.at_level(logging.WARNING):
        names = [name for name, _ in map_meshes(few)]
        map_mesh(few)
    assert "unexplained" not in names
    assert sum("not meshed" in r.getMessage() for r in caplog.records) == 1
