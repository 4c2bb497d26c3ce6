"""Foxglove overlay of a reconstruction: an MCAP file (JSON encoding) to open beside the run.

Channels, all on the run's clock (``t0_ns`` = the log's first sample, contact times from the
contact table):

``/tf`` (``foxglove.FrameTransform``)
    one transform at ``t0_ns``: the map frame (the robot base frame, e.g. ``base_link``) placed
    at the origin of ``world``, so the 3D panel has a frame to show the overlay in; a log that
    already places the base frame keeps its own tree (the transform is the identity).
``/wholearm/map`` (``foxglove.SceneUpdate``)
    one message at ``t0_ns``: every primitive as a triangle list over its extent, in its fixed
    colour (:mod:`wholearm_tools.mesh.style`) with its type, id, parameters and RMS residual
    in the entity metadata, and the surface through the unexplained contacts.
``/wholearm/contacts`` (``foxglove.SceneUpdate``)
    one message per contact at the contact's own time: a tip contact as a sphere (the tip or
    joint sphere), a link contact as the link's axis segment, coloured by P_T (blue = link body,
    red = tip), with time, link (and its probability, and the link the fitted map holds), label,
    P_T and primitive in the metadata.  Entities never
    expire, so scrubbing the timeline shows the contacts gathered up to that time.

Same inputs → same bytes.
"""

from __future__ import annotations

import functools
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from wholearm_tools import __version__
from wholearm_tools._io import atomic_path
from wholearm_tools.errors import InputError
from wholearm_tools.mapfile import SurfaceMap
from wholearm_tools.mesh.export import DEFAULT_HEIGHT, map_meshes
from wholearm_tools.mesh.triangle_mesh import TriangleMesh

TOPIC = "/wholearm/map"
CONTACTS_TOPIC = "/wholearm/contacts"
TF_TOPIC = "/tf"
SCHEMA_NAME = "foxglove.SceneUpdate"
TF_SCHEMA_NAME = "foxglove.FrameTransform"
#: parent frame of the map frame in ``/tf``
WORLD_FRAME = "world"
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


def _quaternion() -> dict[str, Any]:
    return _obj("foxglove.Quaternion", {"x": _num(), "y": _num(), "z": _num(), "w": _num()})


def _color() -> dict[str, Any]:
    return _obj("foxglove.Color", {"r": _num(), "g": _num(), "b": _num(), "a": _num()})


def _pose() -> dict[str, Any]:
    return _obj("foxglove.Pose", {"position": _vec3(), "orientation": _quaternion()})


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


def frame_transform_schema() -> dict[str, Any]:
    """JSON schema of ``foxglove.FrameTransform`` (field names as Foxglove)."""
    schema = _obj(TF_SCHEMA_NAME, {
        "timestamp": _time(), "parent_frame_id": {"type": "string"},
        "child_frame_id": {"type": "string"}, "translation": _vec3(),
        "rotation": _quaternion()})
    schema["description"] = "A transform between two reference frames in 3D space"
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


def _stamp(t_ns: int) -> dict[str, int]:
    return {"sec": int(t_ns) // 1_000_000_000, "nsec": int(t_ns) % 1_000_000_000}


def scene_update(surface_map: SurfaceMap, t0_ns: int = 0, resolution: float = OVERLAY_RESOLUTION,
                 height: float = DEFAULT_HEIGHT) -> dict[str, Any]:
    """The map's ``foxglove.SceneUpdate`` (a JSON-ready dict): one entity per surface of
    :func:`~wholearm_tools.mesh.export.map_meshes`, named as in the mesh files."""
    if int(t0_ns) < 0:
        raise InputError(f"overlay time must be >= 0 ns, got {t0_ns}")
    stamp = _stamp(t0_ns)
    entities = []
    for part in map_meshes(surface_map, resolution, height):
        alpha = 0.8 if part.primitive_id >= 0 else 0.6
        meta = {k: (v if isinstance(v, str) else json.dumps(v, separators=(",", ":")))
                for k, v in part.metadata.items()}
        entities.append(_entity(part.name, surface_map.frame, stamp, meta,
                                triangles=[_triangle_list(part.mesh, _rgba(*part.colour,
                                                                           alpha))]))
    return {"deletions": [], "entities": entities}


def _float_text(x: float) -> str:
    return f"{float(x):.6g}" if np.isfinite(x) else ""


def contact_updates(table: Any, frame: str, t0_ns: int = 0
                    ) -> list[tuple[int, dict[str, Any]]]:
    """One ``(log time [ns], foxglove.SceneUpdate)`` per contact of ``table`` (a
    :class:`~wholearm_tools.contact_table.ContactTable`), in time order: entity
    ``contact/<k>`` (k = the table row), a sphere for a contact used as a tip contact, the link's
    axis segment otherwise, coloured by P_T."""
    if int(t0_ns) < 0:
        raise InputError(f"overlay time must be >= 0 ns, got {t0_ns}")
    n = len(table)
    if n == 0:
        return []
    t = np.asarray(table.t, float)
    times = int(t0_ns) + np.round(t * 1e9).astype(np.int64)
    if np.any(times < 0):
        raise InputError(f"contact times must not precede the log start, got t = {t.min()} s")
    tips = _points3(_lift(np.asarray(table.tip_center, float)))
    a = _points3(_lift(np.asarray(table.seg_a, float)))
    b = _points3(_lift(np.asarray(table.seg_b, float)))
    out = []
    for k in np.argsort(times, kind="stable"):
        k = int(k)
        colour = p_tip_color(float(table.p_tip[k]))
        meta = {"t": f"{t[k]:.6f}", "link": str(int(table.link[k])),
                "p_link": _float_text(table.p_link[k]),
                "link_by_map": str(int(table.link_by_map[k])) if table.link_by_map[k] >= 0
                else "",
                "label": str(table.label[k]), "p_tip": _float_text(table.p_tip[k]),
                "label_map": str(table.label_map[k]),
                "p_tip_map": _float_text(table.p_tip_map[k]),
                "used_as": "tip" if table.used_as_tip[k] else "link",
                "primitive": str(int(table.primitive[k]))}
        stamp = _stamp(int(times[k]))
        if table.used_as_tip[k]:
            d = max(2.0 * float(table.tip_radius[k]), SPHERE_DIAMETER)
            prims = {"spheres": [{"pose": {"position": tips[k],
                                           "orientation": _IDENTITY["orientation"]},
                                  "size": {"x": d, "y": d, "z": d}, "color": colour}]}
        else:
            prims = {"lines": [{"type": 2, "pose": _IDENTITY, "thickness": LINE_THICKNESS,
                                "scale_invariant": False, "points": [a[k], b[k]],
                                "color": colour, "colors": [], "indices": []}]}
        out.append((int(times[k]), {"deletions": [], "entities": [
            _entity(f"contact/{k}", frame, stamp, meta, **prims)]}))
    return out


def frame_transform(frame: str, t0_ns: int = 0) -> dict[str, Any]:
    """The ``/tf`` message: ``frame`` at the origin of :data:`WORLD_FRAME`."""
    return {"timestamp": _stamp(t0_ns), "parent_frame_id": WORLD_FRAME,
            "child_frame_id": frame, "translation": {"x": 0.0, "y": 0.0, "z": 0.0},
            "rotation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}


def write_overlay(path: str | os.PathLike[str], surface_map: SurfaceMap, table: Any = None, *,
                  t0_ns: int = 0, resolution: float = OVERLAY_RESOLUTION) -> Path:
    """Write the overlay MCAP of a map and its contacts (see the module docstring).

    Parameters
    ----------
    path : path
        Output ``.mcap`` file (written atomically).
    surface_map : SurfaceMap
        The map; its frame is the entities' ``frame_id``.
    table : ContactTable, optional
        The contacts, each drawn at its own time (``table.t`` seconds after ``t0_ns``).
    t0_ns : int
        Absolute time of the log's first sample (``JointLog.t0_ns``), nanoseconds.
    resolution : float
        Tessellation resolution, metres.
    """
    from mcap.writer import CompressionType, Writer

    pack = functools.partial(json.dumps, separators=(",", ":"))
    frame = surface_map.frame
    messages = [(TF_TOPIC, int(t0_ns), frame_transform(frame, t0_ns)),
                (TOPIC, int(t0_ns), scene_update(surface_map, t0_ns, resolution))]
    if table is not None:
        messages += [(CONTACTS_TOPIC, t, m) for t, m in contact_updates(table, frame, t0_ns)]
    path = Path(path)
    with atomic_path(path, ".mcap") as tmp, open(tmp, "wb") as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD)
        writer.start(profile="", library=f"wholearm_tools {__version__}")
        scene_id = writer.register_schema(SCHEMA_NAME, "jsonschema",
                                          pack(scene_update_schema()).encode("utf-8"))
        tf_id = writer.register_schema(TF_SCHEMA_NAME, "jsonschema",
                                       pack(frame_transform_schema()).encode("utf-8"))
        channels = {topic: writer.register_channel(topic, "json",
                                                   tf_id if topic == TF_TOPIC else scene_id)
                    for topic in (TF_TOPIC, TOPIC, CONTACTS_TOPIC)}
        sequence = dict.fromkeys(channels, 0)
        for topic, t_ns, message in messages:
            writer.add_message(channels[topic], log_time=t_ns, publish_time=t_ns,
                               data=pack(message).encode("utf-8"), sequence=sequence[topic])
            sequence[topic] += 1
        writer.finish()
    return path
