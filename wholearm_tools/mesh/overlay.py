"""Foxglove overlay of a map: one ``foxglove.SceneUpdate`` (JSON encoding) in an MCAP file.

Open it next to the run in Foxglove (or Lichtblick): the 3D panel shows, in frame ``base_link``
(the map's frame), every primitive as a triangle list over its extent, the surface through the
unexplained contacts, tip contacts as spheres coloured by P_T (blue = link, red = tip) and link
contacts as line segments.  Same inputs → same bytes.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from wholearm_tools import __version__
from wholearm_tools._io import atomic_path
from wholearm_tools.errors import InputError
from wholearm_tools.mapfile import SurfaceMap
from wholearm_tools.mesh.export import DEFAULT_HEIGHT, map_meshes
from wholearm_tools.mesh.triangle_mesh import TriangleMesh

TOPIC = "/wholearm/map"
SCHEMA_NAME = "foxglove.SceneUpdate"
#: default tessellation resolution of the overlay (coarser than file exports: JSON is verbose)
OVERLAY_RESOLUTION = 0.02
#: diameter of the tip-contact spheres, metres
SPHERE_DIAMETER = 0.01
#: line width of link contacts, metres
LINE_THICKNESS = 0.004
_DECIMALS = 6  # micrometres: plenty for display, keeps the JSON compact


# ---------------------------------------------------------------------------------------------
# the JSON schema (the parts of foxglove.SceneUpdate this overlay uses, in full; the other
# primitive arrays of SceneEntity are declared as arrays of objects)


def _obj(title: str, props: dict[str, Any]) -> dict[str, Any]:
    return {"title": title, "type": "object", "properties": props, "required": list(props)}


def _num() -> dict[str, Any]:
    return {"type": "number"}


def _time(title: str = "time", signed: bool = False) -> dict[str, Any]:
    sec: dict[str, Any] = {"type": "integer"} if signed else {"type": "integer", "minimum": 0}
    return {"title": title, "type": "object", "properties": {
        "sec": sec, "nsec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}}


def _vec3(title: str = "foxglove.Vector3") -> dict[str, Any]:
    return _obj(title, {"x": _num(), "y": _num(), "z": _num()})


def _color() -> dict[str, Any]:
    return _obj("foxglove.Color", {"r": _num(), "g": _num(), "b": _num(), "a": _num()})


def _pose() -> dict[str, Any]:
    return _obj("foxglove.Pose", {
        "position": _vec3(),
        "orientation": _obj("foxglove.Quaternion",
                            {"x": _num(), "y": _num(), "z": _num(), "w": _num()})})


def _array(items: dict[str, Any]) -> dict[str, Any]:
    return {"type": "array", "items": items}


def scene_update_schema() -> dict[str, Any]:
    """JSON schema of ``foxglove.SceneUpdate`` (the subset used here, field names as Foxglove)."""
    sphere = _obj("foxglove.SpherePrimitive", {"pose": _pose(), "size": _vec3(),
                                               "color": _color()})
    line = _obj("foxglove.LinePrimitive", {
        "type": {"title": "foxglove.LineType", "enum": [0, 1, 2],
                 "description": "0 LINE_STRIP, 1 LINE_LOOP, 2 LINE_LIST"},
        "pose": _pose(), "thickness": _num(), "scale_invariant": {"type": "boolean"},
        "points": _array(_vec3("foxglove.Point3")), "color": _color(),
        "colors": _array(_color()), "indices": _array({"type": "integer", "minimum": 0})})
    triangles = _obj("foxglove.TriangleListPrimitive", {
        "pose": _pose(), "points": _array(_vec3("foxglove.Point3")), "color": _color(),
        "colors": _array(_color()), "indices": _array({"type": "integer", "minimum": 0})})
    other = _array({"type": "object"})
    entity = _obj("foxglove.SceneEntity", {
        "timestamp": _time(), "frame_id": {"type": "string"}, "id": {"type": "string"},
        "lifetime": _time("duration", signed=True), "frame_locked": {"type": "boolean"},
        "metadata": _array(_obj("foxglove.KeyValuePair", {"key": {"type": "string"},
                                                          "value": {"type": "string"}})),
        "arrows": other, "cubes": other, "spheres": _array(sphere), "cylinders": other,
        "lines": _array(line), "triangles": _array(triangles), "texts": other, "models": other})
    deletion = _obj("foxglove.SceneEntityDeletion", {
        "timestamp": _time(), "type": {"enum": [0, 1], "description": "0 MATCHING_ID, 1 ALL"},
        "id": {"type": "string"}})
    schema = _obj(SCHEMA_NAME, {"deletions": _array(deletion), "entities": _array(entity)})
    schema["description"] = "An update to the entities displayed in a 3D scene"
    return schema


# ---------------------------------------------------------------------------------------------
# message building


def _points3(arr: np.ndarray) -> list[dict[str, float]]:
    r = np.round(arr, _DECIMALS) + 0.0  # + 0.0 turns -0.0 into 0.0
    return [{"x": float(x), "y": float(y), "z": float(z)} for x, y, z in r]


def _rgba(r: float, g: float, b: float, a: float = 1.0) -> dict[str, float]:
    return {"r": round(float(r), 4), "g": round(float(g), 4), "b": round(float(b), 4),
            "a": round(float(a), 4)}


def p_tip_color(p: float) -> dict[str, float]:
    """Colour of a contact with tip probability ``p``: blue (link, 0) → red (tip, 1)."""
    p = float(np.clip(p, 0.0, 1.0))
    return _rgba(p, 0.15, 1.0 - p)


_PALETTE = ((0.12, 0.47, 0.71), (1.0, 0.5, 0.05), (0.17, 0.63, 0.17), (0.58, 0.4, 0.74),
            (0.55, 0.34, 0.29), (0.89, 0.47, 0.76), (0.74, 0.74, 0.13), (0.09, 0.75, 0.81))
_IDENTITY = {"position": {"x": 0.0, "y": 0.0, "z": 0.0},
             "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}


def _entity(eid: str, frame: str, stamp: dict[str, int], metadata: dict[str, str],
            **primitives: list[dict[str, Any]]) -> dict[str, Any]:
    ent: dict[str, Any] = {
        "timestamp": stamp, "frame_id": frame, "id": eid, "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": False,
        "metadata": [{"key": k, "value": v} for k, v in metadata.items()],
    }
    for name in ("arrows", "cubes", "spheres", "cylinders", "lines", "triangles", "texts",
                 "models"):
        ent[name] = primitives.get(name, [])
    return ent


def _triangle_list(mesh: TriangleMesh, color: dict[str, float]) -> dict[str, Any]:
    return {"pose": _IDENTITY, "points": _points3(mesh.vertices), "color": color, "colors": [],
            "indices": mesh.triangles.ravel().tolist()}


def _lift(arr: np.ndarray) -> np.ndarray:
    """2-D points of planar maps → z = 0."""
    if arr.shape[-1] == 2:
        return np.concatenate([arr, np.zeros((*arr.shape[:-1], 1))], axis=-1)
    return arr


def scene_update(surface_map: SurfaceMap, contact_points: ArrayLike | None = None,
                 contact_p_tip: ArrayLike | None = None,
                 contact_segments: ArrayLike | None = None, t0_ns: int = 0,
                 resolution: float = OVERLAY_RESOLUTION,
                 height: float = DEFAULT_HEIGHT) -> dict[str, Any]:
    """The ``foxglove.SceneUpdate`` message (a JSON-ready dict) of :func:`write_overlay`.

    Entities, in order: ``primitive/<id>`` per primitive, ``unexplained`` (when the unexplained
    contacts could be meshed), ``contacts/tip`` (when ``contact_points`` is given and non-empty)
    and ``contacts/link`` (when ``contact_segments`` is given and non-empty).
    """
    if int(t0_ns) < 0:
        raise InputError(f"overlay time must be >= 0 ns, got {t0_ns}")
    dim = surface_map.dim
    stamp = {"sec": int(t0_ns) // 1_000_000_000, "nsec": int(t0_ns) % 1_000_000_000}
    frame = surface_map.frame
    kinds = {f"primitive/{p.id}": p for p in surface_map.primitives}
    entities = []
    for i, (name, mesh) in enumerate(map_meshes(surface_map, resolution, height)):
        prim = kinds.get(name)
        meta = {"kind": prim.kind, "id": str(prim.id),
                "rms_residual": f"{prim.rms_residual:.6g}"} if prim else {"kind": "free-form"}
        colour = _rgba(*_PALETTE[i % len(_PALETTE)], 0.8) if prim else _rgba(0.6, 0.6, 0.6, 0.6)
        entities.append(_entity(name, frame, stamp, meta,
                                triangles=[_triangle_list(mesh, colour)]))
    if contact_points is not None:
        pts = np.asarray(contact_points, dtype=float)
        if pts.size == 0:
            pts = pts.reshape(0, dim)
        if pts.ndim != 2 or pts.shape[1] != dim or not np.all(np.isfinite(pts)):
            raise InputError(f"expected finite contact points of shape (N, {dim}), got "
                             f"{np.shape(contact_points)}")
        if contact_p_tip is None:
            p_tip = np.full(len(pts), 0.5)
        else:
            p_tip = np.asarray(contact_p_tip, dtype=float).ravel()
            if p_tip.shape != (len(pts),) or not np.all((p_tip >= 0) & (p_tip <= 1)):
                raise InputError(f"expected contact_p_tip of shape ({len(pts)},) in [0, 1], "
                                 f"got shape {np.shape(contact_p_tip)}")
        if len(pts):
            size = {"x": SPHERE_DIAMETER, "y": SPHERE_DIAMETER, "z": SPHERE_DIAMETER}
            spheres = [{"pose": {"position": pos, "orientation": _IDENTITY["orientation"]},
                        "size": size, "color": p_tip_color(p)}
                       for pos, p in zip(_points3(_lift(pts)), p_tip, strict=True)]
            entities.append(_entity("contacts/tip", frame, stamp, {"count": str(len(pts))},
                                    spheres=spheres))
    elif contact_p_tip is not None:
        raise InputError("contact_p_tip given without contact_points")
    if contact_segments is not None:
        seg = np.asarray(contact_segments, dtype=float)
        if seg.size == 0:
            seg = seg.reshape(0, 2, dim)
        if seg.ndim != 3 or seg.shape[1:] != (2, dim) or not np.all(np.isfinite(seg)):
            raise InputError(f"expected finite contact segments of shape (M, 2, {dim}), got "
                             f"{np.shape(contact_segments)}")
        if len(seg):
            line = {"type": 2, "pose": _IDENTITY, "thickness": LINE_THICKNESS,
                    "scale_invariant": False, "points": _points3(_lift(seg).reshape(-1, 3)),
                    "color": _rgba(1.0, 0.55, 0.0), "colors": [], "indices": []}
            entities.append(_entity("contacts/link", frame, stamp, {"count": str(len(seg))},
                                    lines=[line]))
    return {"deletions": [], "entities": entities}


def write_overlay(path: str | os.PathLike[str], surface_map: SurfaceMap,
                  contact_points: ArrayLike | None = None,
                  contact_p_tip: ArrayLike | None = None,
                  contact_segments: ArrayLike | None = None, t0_ns: int = 0,
                  resolution: float = OVERLAY_RESOLUTION) -> Path:
    """Write the map overlay MCAP (channel ``/wholearm/map``, one SceneUpdate at ``t0_ns``).

    Parameters
    ----------
    path : path
        Output ``.mcap`` file (written atomically).
    surface_map : SurfaceMap
        The map; its frame is the entities' ``frame_id``.
    contact_points : (N, d) float, optional
        Tip-contact points (d = 2 for planar maps, drawn at z = 0), as spheres.
    contact_p_tip : (N,) float, optional
        Their tip probability P_T in [0, 1], the spheres' colour (grey-purple 0.5 if absent).
    contact_segments : (M, 2, d) float, optional
        Link contacts as segments (e.g. the link in contact), drawn as a line list.
    t0_ns : int
        Log and publish time of the message, and the entities' timestamp (ns).
    resolution : float
        Tessellation resolution, metres.
    """
    from mcap.writer import CompressionType, Writer

    message = scene_update(surface_map, contact_points, contact_p_tip, contact_segments, t0_ns,
                           resolution)
    data = json.dumps(message, separators=(",", ":")).encode("utf-8")
    schema = json.dumps(scene_update_schema(), separators=(",", ":")).encode("utf-8")
    path = Path(path)
    with atomic_path(path, ".mcap") as tmp, open(tmp, "wb") as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD)
        writer.start(profile="", library=f"wholearm_tools {__version__}")
        schema_id = writer.register_schema(SCHEMA_NAME, "jsonschema", schema)
        channel_id = writer.register_channel(TOPIC, "json", schema_id)
        writer.add_message(channel_id, log_time=int(t0_ns), data=data,
                           publish_time=int(t0_ns), sequence=0)
        writer.finish()
    return path
