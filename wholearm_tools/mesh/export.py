"""Meshes of a whole map and their files: PLY, STL, OBJ, glTF/GLB (open3d), VTP (pyvista);
drawings of planar maps: SVG, PNG (matplotlib, Agg).

Every file is written atomically: to a temporary name with the right extension in the target
folder, then renamed onto the target; a failure removes the temporary file and leaves any
existing target untouched.
"""

from __future__ import annotations

import base64
import functools
import json
import logging
import os
import struct
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from wholearm_tools._io import atomic_path, write_bytes_atomic
from wholearm_tools.errors import InputError, OutputError
from wholearm_tools.mapfile import MappedPrimitive, SurfaceMap
from wholearm_tools.mesh.extent import full_extent
from wholearm_tools.mesh.tessellate import DEFAULT_RESOLUTION, extrude, polyline, tessellate
from wholearm_tools.mesh.triangle_mesh import TriangleMesh, merge_meshes
from wholearm_tools.mesh.unexplained import unexplained_mesh

log = logging.getLogger(__name__)

#: default height (m) of the strips extruded from the lines and circles of planar maps
DEFAULT_HEIGHT = 0.1

PLANAR_KINDS = ("line", "circle")


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


def map_meshes(surface_map: SurfaceMap, resolution: float = DEFAULT_RESOLUTION,
               height: float = DEFAULT_HEIGHT, include_unexplained: bool = True
               ) -> list[tuple[str, TriangleMesh]]:
    """Named meshes of a map: ``("primitive/<id>", mesh)`` per primitive, then
    ``("unexplained", mesh)`` when the unexplained contacts of a 3-D map could be meshed."""
    named = [(f"primitive/{p.id}", primitive_mesh(p, resolution, height))
             for p in surface_map.primitives]
    if include_unexplained and not surface_map.planar and len(surface_map.unexplained):
        pts = np.ascontiguousarray(surface_map.unexplained, dtype=float)
        surface = _unexplained_surface(pts.tobytes(), pts.shape)
        if surface:
            named.append(("unexplained", surface.mesh))
    return named


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
    return merge_meshes(m for _, m in map_meshes(surface_map, resolution, height,
                                                  include_unexplained))


# ---------------------------------------------------------------------------------------------
# atomic file helpers


# ---------------------------------------------------------------------------------------------
# mesh writers


def _to_open3d(mesh: TriangleMesh) -> Any:
    import open3d as o3d

    out = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.array(mesh.vertices)),
                                    o3d.utility.Vector3iVector(mesh.triangles.astype(np.int32)))
    out.compute_triangle_normals()
    out.compute_vertex_normals()
    return out


def _write_open3d(mesh: TriangleMesh, path: Path, suffix: str) -> None:
    import open3d as o3d

    o3d_mesh = _to_open3d(mesh)
    with atomic_path(path, suffix) as tmp, \
            o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        ok = o3d.io.write_triangle_mesh(str(tmp), o3d_mesh, write_ascii=False,
                                        write_vertex_normals=suffix != ".stl")
        if not ok:
            raise OutputError(f"{path}: open3d could not write the {suffix[1:].upper()} file")


def glb_from_gltf(gltf: dict[str, Any]) -> bytes:
    """Binary glTF (GLB) from a glTF document whose buffers are base64 data URIs.

    open3d 0.20 writes ``.glb`` files that keep the buffer as a data URI and have no BIN chunk,
    which common readers (assimp, hence open3d itself) reject; this packs the buffers into the
    standard BIN chunk.
    """
    doc = json.loads(json.dumps(gltf))  # deep copy
    blob = bytearray()
    starts: list[int] = []
    for buf in doc.get("buffers", []):
        uri = buf.get("uri", "")
        head, sep, data = uri.partition(",")
        if not (sep and head.startswith("data:") and head.endswith(";base64")):
            raise OutputError(f"cannot pack glTF buffer with uri {uri[:40]!r} into a GLB")
        raw = base64.b64decode(data)
        starts.append(len(blob))
        blob += raw + b"\0" * (-len(raw) % 4)
    for view in doc.get("bufferViews", []):
        view["byteOffset"] = starts[view.get("buffer", 0)] + view.get("byteOffset", 0)
        view["buffer"] = 0
    doc["buffers"] = [{"byteLength": len(blob)}] if blob else []
    body = json.dumps(doc, separators=(",", ":"), sort_keys=True).encode("utf-8")
    body += b" " * (-len(body) % 4)
    chunks = struct.pack("<I4s", len(body), b"JSON") + body
    if blob:
        chunks += struct.pack("<I4s", len(blob), b"BIN\0") + bytes(blob)
    return struct.pack("<4sII", b"glTF", 2, 12 + len(chunks)) + chunks


def _write_glb(mesh: TriangleMesh, path: Path, suffix: str) -> None:
    import open3d as o3d

    o3d_mesh = _to_open3d(mesh)
    with tempfile.TemporaryDirectory(prefix="wholearm-glb-") as folder:
        gltf_path = Path(folder) / "mesh.gltf"
        with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
            ok = o3d.io.write_triangle_mesh(str(gltf_path), o3d_mesh)
        if not ok:
            raise OutputError(f"{path}: open3d could not write the glTF data")
        data = glb_from_gltf(json.loads(gltf_path.read_text(encoding="utf-8")))
    write_bytes_atomic(path, data)


def _write_vtp(mesh: TriangleMesh, path: Path, suffix: str) -> None:
    import pyvista as pv

    poly = pv.PolyData.from_regular_faces(np.asarray(mesh.vertices),
                                          np.asarray(mesh.triangles))
    with atomic_path(path, suffix) as tmp:
        poly.save(str(tmp), binary=True)


MeshWriter = Callable[[TriangleMesh, Path, str], None]

#: mesh writers by format name
MESH_FORMATS: dict[str, MeshWriter] = {
    "ply": _write_open3d, "stl": _write_open3d, "obj": _write_open3d, "gltf": _write_open3d,
    "glb": _write_glb, "vtp": _write_vtp,
}
#: drawing formats of planar maps
DRAWING_FORMATS = ("svg", "png")


def _format_of(path: Path, fmt: str | None, known: tuple[str, ...]) -> str:
    name = (fmt or path.suffix.lstrip(".")).lower()
    if name not in known:
        raise InputError(f"{path}: unsupported format {name!r} (supported: {', '.join(known)})")
    return name


def export_mesh(mesh: TriangleMesh, path: str | os.PathLike[str],
                format: str | None = None) -> Path:
    """Write ``mesh`` to ``path`` as PLY, STL, OBJ, glTF, GLB or VTP, atomically.

    ``format`` defaults to the file's extension.  Returns the path written.
    """
    path = Path(path)
    fmt = _format_of(path, format, tuple(MESH_FORMATS))
    if mesh.is_empty:
        raise InputError(f"{path}: nothing to export (the mesh has no triangles)")
    MESH_FORMATS[fmt](mesh, path, f".{fmt}")
    return path


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
        colours = mpl.colormaps["tab10"].colors
        for i, (prim, pts) in enumerate(curves):
            ax.plot(pts[:, 0], pts[:, 1], "-", lw=2.0, color=colours[i % len(colours)],
                    label=f"#{prim.id} {prim.kind}")
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

