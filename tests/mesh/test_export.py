"""Map meshes, unexplained surfaces, file export round trips, named parts and atomicity,
drawings."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from wholearm_tools.errors import InputError, OutputError
from wholearm_tools.mapfile import MappedPrimitive, SurfaceMap
from wholearm_tools.mesh.export import (
    Z_UP_TO_Y_UP,
    export_drawing,
    export_map,
    export_mesh,
    map_mesh,
    map_meshes,
)
from wholearm_tools.mesh.style import surface_colour
from wholearm_tools.mesh.triangle_mesh import TriangleMesh
from wholearm_tools.mesh.unexplained import unexplained_mesh

FORMATS = ("ply", "stl", "obj", "gltf", "glb", "vtp")


def read_back(path) -> tuple[np.ndarray, int]:
    """Vertices (robot base frame) and triangle count of a written file, read by trimesh
    (pyvista for VTP); glTF scenes are flattened with their node transforms undone."""
    if path.suffix == ".vtp":
        import pyvista as pv

        poly = pv.read(path)
        assert poly.is_all_triangles
        return np.asarray(poly.points), poly.n_cells
    import trimesh

    loaded = trimesh.load(path, process=False)
    if isinstance(loaded, trimesh.Scene):
        loaded = loaded.to_geometry()
    verts = np.asarray(loaded.vertices)
    if path.suffix in (".gltf", ".glb"):      # +Y up back to the base frame (z up)
        verts = verts @ np.linalg.inv(Z_UP_TO_Y_UP[:3, :3]).T
    return verts, len(loaded.faces)


@pytest.mark.parametrize("fmt", FORMATS)
def test_export_round_trip(fmt, map_3d, tmp_path):
    mesh = map_mesh(map_3d, resolution=0.02, include_unexplained=False)
    out = export_map(map_3d, tmp_path / f"map.{fmt}", resolution=0.02,
                     include_unexplained=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"map.{fmt}"]  # no temporaries
    verts, n_tri = read_back(out)
    assert n_tri == mesh.n_triangles
    if fmt != "stl":  # STL stores three corners per triangle, readers re-index them
        assert len(verts) == mesh.n_vertices
    tol = 1e-6 if fmt != "obj" else 2e-6  # float32 in STL/glTF, printed decimals in OBJ
    assert np.abs(verts.min(axis=0) - mesh.bounds[0]).max() < tol
    assert np.abs(verts.max(axis=0) - mesh.bounds[1]).max() < tol


@pytest.mark.parametrize("fmt", ["gltf", "glb"])
def test_gltf_has_one_named_node_per_surface_with_colour_and_parameters(fmt, map_3d, tmp_path):
    import trimesh

    out = export_map(map_3d, tmp_path / f"map.{fmt}", resolution=0.02)
    scene = trimesh.load(out, process=False)
    names = ["primitive-0-cylinder", "primitive-1-plane", "unexplained"]
    assert sorted(scene.graph.nodes_geometry) == sorted(names)
    doc = gltf_json(out)
    nodes = {n["name"]: n for n in doc["nodes"]}
    root = doc["nodes"][doc["scenes"][0]["nodes"][0]]
    assert root["name"] == "base_link"
    assert sorted(doc["nodes"][i]["name"] for i in root["children"]) == sorted(names)
    # the root turns the base frame's z up into glTF's +Y up: base z -> glTF y, base y -> -z
    m = np.asarray(root["matrix"]).reshape(4, 4).T       # glTF stores column-major
    assert np.allclose(m[:3, :3] @ [0, 0, 1], [0, 1, 0])
    assert np.allclose(m[:3, :3] @ [0, 1, 0], [0, 0, -1])
    cyl = nodes["primitive-0-cylinder"]["extras"]
    assert cyl["type"] == "cylinder"
    assert cyl["params"]["radius"] == pytest.approx(map_3d.primitives[0].params["radius"])
    assert nodes["unexplained"]["extras"]["type"] == "free-form"
    colours = [doc["materials"][doc["meshes"][nodes[k]["mesh"]]["primitives"][0]["material"]]
               ["pbrMetallicRoughness"]["baseColorFactor"][:3] for k in names]
    assert np.allclose(colours[0], surface_colour(0), atol=1 / 255)
    assert np.allclose(colours[1], surface_colour(1), atol=1 / 255)
    assert doc["scenes"][0]["extras"]["wholearm"]["B"] == map_3d.B


def gltf_json(path) -> dict:
    """The JSON document of a .gltf or .glb file."""
    import json
    import struct

    data = path.read_bytes()
    if path.suffix == ".gltf":
        return json.loads(data)
    length = struct.unpack_from("<I", data, 12)[0]
    assert data[16:20] == b"JSON"
    return json.loads(data[20:20 + length])


@pytest.mark.parametrize("fmt", ["gltf", "glb"])
def test_gltf_accessor_bounds_and_buffer_targets_match_the_data(fmt, map_3d, tmp_path):
    """What the Khronos validator checks first: every accessor's min/max are those of its
    data (ACCESSOR_MAX_MISMATCH, open3d's fault), and every bufferView declares its target."""
    import base64
    import struct

    out = export_map(map_3d, tmp_path / f"map.{fmt}", resolution=0.02)
    doc = gltf_json(out)
    data = out.read_bytes()
    if fmt == "glb":
        json_len = struct.unpack_from("<I", data, 12)[0]
        blob = data[20 + json_len + 8:]
    else:
        blob = base64.b64decode(doc["buffers"][0]["uri"].split(",", 1)[1])
    kinds = {5125: np.uint32, 5126: np.float32}
    widths = {"SCALAR": 1, "VEC3": 3}
    for acc in doc["accessors"]:
        view = doc["bufferViews"][acc["bufferView"]]
        assert view["target"] in (34962, 34963)
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        values = np.frombuffer(blob, kinds[acc["componentType"]],
                               acc["count"] * widths[acc["type"]], start)
        values = values.reshape(acc["count"], widths[acc["type"]])
        assert np.array_equal(np.asarray(acc["min"], values.dtype), values.min(axis=0))
        assert np.array_equal(np.asarray(acc["max"], values.dtype), values.max(axis=0))


def test_obj_ply_vtp_keep_the_surfaces_apart(map_3d, tmp_path):
    import pyvista as pv
    import trimesh

    names = ["primitive-0-cylinder", "primitive-1-plane", "unexplained"]
    parts = map_meshes(map_3d, resolution=0.02)
    sizes = [p.mesh.n_triangles for p in parts]
    obj = export_map(map_3d, tmp_path / "map.obj", resolution=0.02).read_text()
    assert [ln[2:] for ln in obj.splitlines() if ln.startswith("o ")] == names
    assert [ln[2:] for ln in obj.splitlines() if ln.startswith("g ")] == names
    scene = trimesh.load_scene(tmp_path / "map.obj", split_groups=True, group_material=False,
                               process=False)
    assert sorted(len(g.faces) for g in scene.geometry.values()) == sorted(sizes)
    vtp = pv.read(export_map(map_3d, tmp_path / "map.vtp", resolution=0.02))
    ids = np.asarray(vtp.cell_data["primitive_id"])
    assert [int(np.sum(ids == i)) for i in (0, 1, -1)] == sizes
    assert list(vtp.field_data["surface_names"]) == names
    ply = trimesh.load(export_map(map_3d, tmp_path / "map.ply", resolution=0.02),
                       process=False)
    colours = np.asarray(ply.visual.face_colors)[:, :3] / 255.0
    assert np.allclose(colours[0], surface_colour(0), atol=1 / 255)
    assert np.allclose(colours[-1], surface_colour(-1), atol=1 / 255)
    header = (tmp_path / "map.ply").read_bytes().split(b"end_header")[0]
    assert b"property int primitive_id" in header


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
    import pyvista as pv

    target = tmp_path / "map.vtp"
    target.write_bytes(b"previous")

    def failing(self, path, *args, **kwargs):
        with open(path, "wb") as f:
            f.write(b"half")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(pv.PolyData, "save", failing)
    with pytest.raises(OSError, match="No space left"):
        export_map(map_3d, target, resolution=0.05)
    assert target.read_bytes() == b"previous"
    assert [p.name for p in tmp_path.iterdir()] == ["map.vtp"]


def test_map_meshes_name_and_colour_every_surface(map_3d):
    parts = map_meshes(map_3d, resolution=0.02)
    assert [p.name for p in parts] == ["primitive-0-cylinder", "primitive-1-plane",
                                       "unexplained"]
    assert [p.primitive_id for p in parts] == [0, 1, -1]
    assert parts[0].colour == surface_colour(0)
    assert parts[0].metadata["params"]["radius"] == pytest.approx(0.1)
    merged = map_mesh(map_3d, resolution=0.02)
    assert merged.n_vertices == sum(p.mesh.n_vertices for p in parts)
    assert merged.n_triangles == sum(p.mesh.n_triangles for p in parts)
    without = map_mesh(map_3d, resolution=0.02, include_unexplained=False)
    assert without.n_triangles == merged.n_triangles - parts[2].mesh.n_triangles


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

    few = dataclasses.replace(map_3d, unexplained=map_3d.unexplained[:2] + 1e-3)
    with caplog.at_level(logging.WARNING):
        names = [part.name for part in map_meshes(few)]
        map_mesh(few)
    assert "unexplained" not in names
    assert sum("not meshed" in r.getMessage() for r in caplog.records) == 1
