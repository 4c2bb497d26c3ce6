"""Meshes of a whole map and their files; drawings of planar maps.

Every surface of the map is one named part (:class:`SurfaceMesh`): one per fitted primitive,
plus one for the free-form surface through the contacts no primitive explains.  The files keep
the parts apart, each with its fixed name and colour (:mod:`wholearm_tools.mesh.style`):

========  =======================================================================================
format    how the parts are kept (written with trimesh, VTP with pyvista)
========  =======================================================================================
glTF/GLB  one node per part under a root node named after the map frame, which turns the robot
          base frame (z up) into glTF's +Y up; node ``extras`` hold the type, id, parameters,
          95 % half-widths, support and RMS residual; one material per part (its colour); the
          scene's ``extras`` hold the map's B, frame and provenance
OBJ       one ``o``/``g`` group per part, robot base frame
PLY       per-face colour and a per-face ``primitive_id`` property (-1: unexplained), base frame
VTP       ``primitive_id`` and ``colour`` cell arrays, the part names in field data, base frame
STL       one body (the format has no groups), base frame
========  =======================================================================================

Drawings of planar maps: SVG, PNG (matplotlib, Agg).  Every file is written atomically: to a
temporary name in the target folder, then renamed onto the target; a failure removes the
temporary file and leaves any existing target untouched.
"""

from __future__ import annotations

import functools
import json
import logging
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from wholearm_tools import __version__
from wholearm_tools._io import atomic_path, write_bytes_atomic
from wholearm_tools._parallel import interruptible_import
from wholearm_tools.errors import InputError, OutputError
from wholearm_tools.mapfile import MappedPrimitive, SurfaceMap, jsonable
from wholearm_tools.mesh.extent import full_extent
from wholearm_tools.mesh.style import (
    UNEXPLAINED_NAME,
    surface_colour,
    surface_label,
    surface_name,
)
from wholearm_tools.mesh.tessellate import DEFAULT_RESOLUTION, extrude, polyline, tessellate
from wholearm_tools.mesh.triangle_mesh import TriangleMesh, merge_meshes
from wholearm_tools.mesh.unexplained import unexplained_mesh

log = logging.getLogger(__name__)

#: default height (m) of the strips extruded from the lines and circles of planar maps
DEFAULT_HEIGHT = 0.1

PLANAR_KINDS = ("line", "circle")

#: rotation of the robot base frame (z up) into glTF's frame (+Y up): (x, y, z) -> (x, z, -y)
Z_UP_TO_Y_UP = np.array([[1.0, 0.0, 0.0, 0.0],
                         [0.0, 0.0, 1.0, 0.0],
                         [0.0, -1.0, 0.0, 0.0],
                         [0.0, 0.0, 0.0, 1.0]])


@dataclass(frozen=True, eq=False)
class SurfaceMesh:
    """One named surface of a map, as the files keep it apart.

    Attributes
    ----------
    name : str
        Node / group name (``primitive-<id>-<type>`` or ``unexplained``).
    primitive_id : int
        The primitive's id in map.json; -1 for the surface through the unexplained contacts.
    kind : str
        Primitive type, or ``"free-form"``.
    mesh : TriangleMesh
        Vertices in the map frame (robot base frame), metres.
    colour : (3,) float
        RGB in [0, 1] (:func:`~wholearm_tools.mesh.style.surface_colour`).
    metadata : dict
        JSON-ready description written with the part (glTF node ``extras``).
    """

    name: str
    primitive_id: int
    kind: str
    mesh: TriangleMesh
    colour: tuple[float, float, float]
    metadata: dict[str, Any] = field(default_factory=dict)


# ---------------------------------------------------------------------------------------------
# map → meshes


def _extent_of(primitive: MappedPrimitive) -> dict[str, Any]:
    if primitive.extent:
        return primitive.extent
    try:
        return full_extent(primitive.kind, primitive.params)
    except InputError as exc:
        raise InputError(f"primitive {primitive.id} ({primitive.kind}): no extent in the map; "
                         f"{exc}") from None


def primitive_mesh(primitive: MappedPrimitive, resolution: float = DEFAULT_RESOLUTION,
                   height: float = DEFAULT_HEIGHT) -> TriangleMesh:
    """Mesh of one map primitive over its extent (2-D kinds: strip extruded to ±height/2).

    A primitive without an extent is meshed whole if it is closed (circle, sphere, torus);
    unbounded ones (line, plane, cylinder, cone) raise InputError.
    """
    extent = _extent_of(primitive)
    try:
        if primitive.kind in PLANAR_KINDS:
            return extrude(primitive.kind, primitive.params, extent, height, resolution)
        return tessellate(primitive.kind, primitive.params, extent, resolution)
    except InputError as exc:
        raise InputError(f"primitive {primitive.id} ({primitive.kind}): {exc}") from None


def primitive_metadata(primitive: MappedPrimitive) -> dict[str, Any]:
    """What a file says about one primitive: type, id, parameters (map.json names, metres and
    radians, robot base frame), 95 % half-widths, support and RMS residual."""
    return jsonable({
        "id": primitive.id, "type": primitive.kind,
        "label": surface_label(primitive.id, primitive.kind), "params": primitive.params,
        "ci95": primitive.ci95, "support": primitive.support,
        "rms_residual": primitive.rms_residual, "frame": "map (robot base frame), metres",
    })


def map_meshes(surface_map: SurfaceMap, resolution: float = DEFAULT_RESOLUTION,
               height: float = DEFAULT_HEIGHT, include_unexplained: bool = True
               ) -> list[SurfaceMesh]:
    """The named surfaces of a map: one per primitive (in map order), then ``unexplained``
    when the unexplained contacts of a 3-D map could be meshed."""
    parts = [SurfaceMesh(surface_name(p.id, p.kind), p.id, p.kind,
                         primitive_mesh(p, resolution, height), surface_colour(p.id),
                         primitive_metadata(p))
             for p in surface_map.primitives]
    if include_unexplained and not surface_map.planar and len(surface_map.unexplained):
        pts = np.ascontiguousarray(surface_map.unexplained, dtype=float)
        surface = _unexplained_surface(pts.tobytes(), pts.shape)
        if surface:
            parts.append(SurfaceMesh(
                UNEXPLAINED_NAME, -1, "free-form", surface.mesh, surface_colour(-1),
                {"id": -1, "type": "free-form", "label": surface_label(-1, ""),
                 "method": surface.method, "n_points": len(pts)}))
    return parts


@functools.lru_cache(maxsize=8)
def _unexplained_surface(data: bytes, shape: tuple[int, ...]) -> Any:
    """:func:`unexplained_mesh` of the points, computed (and a failure logged) once per point
    set: the exports, the overlay and the report all mesh the same map."""
    surface = unexplained_mesh(np.frombuffer(data, dtype=float).reshape(shape))
    if not surface:
        log.warning("unexplained contacts not meshed: %s", surface.reason)
    return surface


def map_mesh(surface_map: SurfaceMap, resolution: float = DEFAULT_RESOLUTION,
             height: float = DEFAULT_HEIGHT, include_unexplained: bool = True) -> TriangleMesh:
    """One mesh of every primitive of the map over its extent, plus the unexplained surface.

    Parameters
    ----------
    surface_map : SurfaceMap
        The map (``read_map`` output).
    resolution : float
        Largest edge length along curved directions, metres.
    height : float
        Extrusion height of the strips of a planar map, metres.
    include_unexplained : bool
        Also mesh ``surface_map.unexplained`` (3-D maps; skipped with a logged reason when too
        few points).
    """
    return merge_meshes(part.mesh for part in map_meshes(surface_map, resolution, height,
                                                         include_unexplained))


def map_scene_metadata(surface_map: SurfaceMap) -> dict[str, Any]:
    """The map-level description the mesh files carry (glTF scene ``extras``)."""
    meta = surface_map.meta or {}
    return jsonable({
        "format": "wholearm-map-mesh", "frame": surface_map.frame, "B": surface_map.B,
        "planar": surface_map.planar, "units": "m",
        "tool": meta.get("tool", {"name": "wholearm_tools", "version": __version__}),
        **{k: meta[k] for k in ("created", "input") if k in meta},
    })


# ---------------------------------------------------------------------------------------------
# mesh writers (trimesh; VTP with pyvista)


def _rgba8(colour: Sequence[float]) -> np.ndarray:
    return np.round(255.0 * np.clip(np.append(np.asarray(colour, float)[:3], 1.0), 0, 1)
                    ).astype(np.uint8)


def _trimesh(part: SurfaceMesh, material: bool) -> Any:
    trimesh = interruptible_import("trimesh")
    from trimesh.visual import TextureVisuals
    from trimesh.visual.material import PBRMaterial

    mesh = trimesh.Trimesh(vertices=np.array(part.mesh.vertices),
                           faces=np.array(part.mesh.triangles), process=False,
                           validate=False)
    if material:
        mesh.visual = TextureVisuals(material=PBRMaterial(
            name=part.name, baseColorFactor=_rgba8(part.colour), metallicFactor=0.0,
            roughnessFactor=0.7, doubleSided=True))
    mesh.metadata = {"name": part.name}
    return mesh


def _scene(parts: Sequence[SurfaceMesh], frame: str, scene_meta: Mapping[str, Any],
           y_up: bool, material: bool) -> Any:
    """A trimesh scene: a root node named ``frame`` (turned to +Y up when ``y_up``) with one
    child node per part, the part's metadata on the node."""
    trimesh = interruptible_import("trimesh")

    scene = trimesh.Scene(base_frame="world")
    scene.graph.update(frame_to=frame, frame_from="world",
                       matrix=Z_UP_TO_Y_UP if y_up else np.eye(4),
                       metadata={"description": f"robot base frame {frame!r}"
                                 + (", turned from z up to glTF's +Y up" if y_up else "")})
    for part in parts:
        scene.add_geometry(_trimesh(part, material), geom_name=part.name, node_name=part.name,
                           parent_node_name=frame, metadata=dict(part.metadata))
    scene.metadata = {"wholearm": dict(scene_meta)}
    return scene


#: glTF bufferView targets: vertex attributes and triangle indices
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


def _tidy_gltf(tree: dict[str, Any]) -> None:
    """Declare every bufferView's target (vertex data or indices) and name the generator."""
    targets: dict[int, int] = {}
    accessors = tree.get("accessors", [])
    for mesh in tree.get("meshes", []):
        for prim in mesh.get("primitives", []):
            for acc in prim.get("attributes", {}).values():
                targets[accessors[acc]["bufferView"]] = _ARRAY_BUFFER
            if "indices" in prim:
                targets[accessors[prim["indices"]]["bufferView"]] = _ELEMENT_ARRAY_BUFFER
    for i, view in enumerate(tree.get("bufferViews", [])):
        if i in targets:
            view["target"] = targets[i]
    tree["asset"]["generator"] = f"wholearm_tools {__version__} (trimesh)"
    for mesh in tree.get("meshes", []):
        mesh.pop("extras", None)     # the part's description sits on its node


def _write_gltf(parts: Sequence[SurfaceMesh], path: Path, fmt: str, frame: str,
                scene_meta: Mapping[str, Any]) -> None:
    interruptible_import("trimesh")
    from trimesh.exchange.gltf import export_glb, export_gltf

    scene = _scene(parts, frame, scene_meta, y_up=True, material=True)
    if fmt == "glb":
        data = export_glb(scene, include_normals=True, tree_postprocessor=_tidy_gltf)
    else:   # trimesh builds a .gltf's bufferViews after its post-processor: tidy afterwards
        tree = json.loads(export_gltf(scene, include_normals=True, embed_buffers=True,
                                      merge_buffers=True)["model.gltf"])
        _tidy_gltf(tree)
        data = json.dumps(tree, separators=(",", ":")).encode("utf-8")
    write_bytes_atomic(path, data)


def _write_obj(parts: Sequence[SurfaceMesh], path: Path, fmt: str, frame: str,
               scene_meta: Mapping[str, Any]) -> None:
    interruptible_import("trimesh")
    from trimesh.exchange.obj import export_obj

    scene = _scene(parts, frame, scene_meta, y_up=False, material=False)
    text = export_obj(scene, include_normals=False, include_color=False, include_texture=False,
                      digits=9, header=f"wholearm map, frame {frame} (z up), metres")
    lines = []
    for line in text.splitlines():
        lines.append(line)
        if line.startswith("o "):
            lines.append("g " + line[2:])       # a group too: some readers only know groups
    write_bytes_atomic(path, ("\n".join(lines) + "\n").encode("utf-8"))


def _merged(parts: Sequence[SurfaceMesh]) -> tuple[TriangleMesh, np.ndarray, np.ndarray]:
    """Merged mesh, per-face primitive id (int32) and per-face RGBA colour (uint8)."""
    merged = merge_meshes(part.mesh for part in parts)
    ids = np.concatenate([np.full(p.mesh.n_triangles, p.primitive_id, np.int32)
                          for p in parts]) if parts else np.zeros(0, np.int32)
    rgba = np.concatenate([np.tile(_rgba8(p.colour), (p.mesh.n_triangles, 1))
                           for p in parts]) if parts else np.zeros((0, 4), np.uint8)
    return merged, ids, rgba


def _write_ply_stl(parts: Sequence[SurfaceMesh], path: Path, fmt: str, frame: str,
                   scene_meta: Mapping[str, Any]) -> None:
    trimesh = interruptible_import("trimesh")
    from trimesh.exchange.ply import export_ply
    from trimesh.exchange.stl import export_stl

    merged, ids, rgba = _merged(parts)
    mesh = trimesh.Trimesh(vertices=np.array(merged.vertices), faces=np.array(merged.triangles),
                           process=False, validate=False)
    if fmt == "stl":
        data = export_stl(mesh)
    else:
        mesh.visual = trimesh.visual.ColorVisuals(mesh, face_colors=rgba)
        mesh.face_attributes["primitive_id"] = ids
        data = export_ply(mesh, encoding="binary", vertex_normal=False, include_attributes=True)
    write_bytes_atomic(path, data)


def _write_vtp(parts: Sequence[SurfaceMesh], path: Path, fmt: str, frame: str,
               scene_meta: Mapping[str, Any]) -> None:
    import pyvista as pv

    merged, ids, rgba = _merged(parts)
    poly = pv.PolyData.from_regular_faces(np.asarray(merged.vertices),
                                          np.asarray(merged.triangles))
    poly.cell_data["primitive_id"] = ids
    poly.cell_data["colour"] = rgba[:, :3]
    poly.field_data["surface_names"] = np.array([p.name for p in parts])
    poly.field_data["surface_ids"] = np.array([p.primitive_id for p in parts], np.int32)
    with atomic_path(path, ".vtp") as tmp:
        poly.save(str(tmp), binary=True)


MeshWriter = Callable[[Sequence[SurfaceMesh], Path, str, str, Mapping[str, Any]], None]

#: mesh writers by format name
MESH_FORMATS: dict[str, MeshWriter] = {
    "ply": _write_ply_stl, "stl": _write_ply_stl, "obj": _write_obj, "gltf": _write_gltf,
    "glb": _write_gltf, "vtp": _write_vtp,
}
#: drawing formats of planar maps
DRAWING_FORMATS = ("svg", "png")


def _format_of(path: Path, fmt: str | None, known: tuple[str, ...]) -> str:
    name = (fmt or path.suffix.lstrip(".")).lower()
    if name not in known:
        raise InputError(f"{path}: unsupported format {name!r} (supported: {', '.join(known)})")
    return name


def export_mesh(mesh: TriangleMesh | Sequence[SurfaceMesh], path: str | os.PathLike[str],
                format: str | None = None, *, frame: str = "base_link",
                metadata: Mapping[str, Any] | None = None) -> Path:
    """Write a mesh, or the named surfaces of a map, as PLY, STL, OBJ, glTF, GLB or VTP.

    Parameters
    ----------
    mesh : TriangleMesh or sequence of SurfaceMesh
        One anonymous mesh (written as one part named ``mesh``) or the parts of
        :func:`map_meshes`, kept apart as the module docstring says.
    path : path
        Output file (written atomically); ``format`` defaults to its extension.
    frame : str
        Name of the vertices' frame (the map frame), the root node of glTF files.
    metadata : mapping, optional
        JSON-ready description of the whole file (glTF scene ``extras["wholearm"]``).

    Returns
    -------
    Path
        The path written.
    """
    path = Path(path)
    fmt = _format_of(path, format, tuple(MESH_FORMATS))
    if isinstance(mesh, TriangleMesh):
        parts: list[SurfaceMesh] = [SurfaceMesh("mesh", -1, "mesh", mesh, surface_colour(-1))]
    else:
        parts = [p for p in mesh if not p.mesh.is_empty]
    if not parts or all(p.mesh.is_empty for p in parts):
        raise InputError(f"{path}: nothing to export (the mesh has no triangles)")
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise OutputError(f"{path}: output folder {folder} does not exist")
    MESH_FORMATS[fmt](parts, path, fmt, frame, dict(metadata or {}))
    return path


def export_map(surface_map: SurfaceMap, path: str | os.PathLike[str], format: str | None = None,
               *, resolution: float = DEFAULT_RESOLUTION, height: float = DEFAULT_HEIGHT,
               include_unexplained: bool = True) -> Path:
    """Mesh ``surface_map`` (:func:`map_meshes`) and write it with :func:`export_mesh`, one
    named part per surface, the map's description in the file."""
    parts = map_meshes(surface_map, resolution, height, include_unexplained)
    return export_mesh(parts, path, format, frame=surface_map.frame,
                       metadata=map_scene_metadata(surface_map))


# ---------------------------------------------------------------------------------------------
# drawings of planar maps


def export_drawing(surface_map: SurfaceMap, path: str | os.PathLike[str],
                   contact_points: ArrayLike | None = None, format: str | None = None,
                   resolution: float = DEFAULT_RESOLUTION) -> Path:
    """Draw a planar map's lines and arcs over their extents as SVG or PNG, atomically.

    Parameters
    ----------
    surface_map : SurfaceMap
        A planar map.
    path : path
        Output file; the format defaults to its extension (``.svg`` or ``.png``).
    contact_points : (N, 2) float, optional
        Contact points drawn as dots; the map's unexplained contacts are always drawn (crosses).
    """
    from matplotlib.figure import Figure

    path = Path(path)
    fmt = _format_of(path, format, DRAWING_FORMATS)
    if not surface_map.planar:
        raise InputError(f"{path}: drawings are made of planar maps only (this map is 3-D)")
    contacts = None
    if contact_points is not None:
        contacts = np.asarray(contact_points, dtype=float)
        if contacts.ndim != 2 or contacts.shape[1] != 2:
            raise InputError(f"expected contact points of shape (N, 2), got {contacts.shape}")
    curves = []
    for prim in surface_map.primitives:
        if prim.kind not in PLANAR_KINDS:
            raise InputError(f"primitive {prim.id}: a planar map holds lines and circles, "
                             f"got {prim.kind!r}")
        try:
            curves.append((prim, polyline(prim.kind, prim.params, _extent_of(prim), resolution)))
        except InputError as exc:
            raise InputError(f"primitive {prim.id} ({prim.kind}): {exc}") from None

    import matplotlib as mpl

    with mpl.rc_context({"svg.hashsalt": "wholearm", "path.simplify": False}):
        fig = Figure(figsize=(6.0, 6.0), dpi=150)
        ax = fig.add_subplot()
        for prim, pts in curves:
            ax.plot(pts[:, 0], pts[:, 1], "-", lw=2.0, color=surface_colour(prim.id),
                    label=surface_label(prim.id, prim.kind))
        if len(surface_map.unexplained):
            u = surface_map.unexplained
            ax.plot(u[:, 0], u[:, 1], "x", color="0.4", ms=5, label="unexplained")
        if contacts is not None and len(contacts):
            ax.plot(contacts[:, 0], contacts[:, 1], ".", color="k", ms=4, label="contacts")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_title(f"wholearm map (B = {surface_map.B:g} m, frame {surface_map.frame})")
        ax.grid(True, lw=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="best", fontsize=7)
        metadata: dict[str, Any] = {"Date": None} if fmt == "svg" else {}
        with atomic_path(path, f".{fmt}") as tmp:
            fig.savefig(tmp, format=fmt, metadata=metadata)
    return path
