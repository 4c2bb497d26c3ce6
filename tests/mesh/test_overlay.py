"""Foxglove overlay MCAP: /tf, the map and every contact at its own time; schema-valid,
deterministic."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from wholearm_tools.contact_table import ContactTable
from wholearm_tools.errors import InputError
from wholearm_tools.mesh.overlay import (
    CONTACTS_TOPIC,
    TF_TOPIC,
    TOPIC,
    frame_transform_schema,
    scene_update_schema,
    write_overlay,
)
from wholearm_tools.mesh.style import surface_colour

T0 = 1_500_000_000


def small_table(dim: int = 3) -> ContactTable:
    """Three contacts: a tip contact at 2.0 s, a link contact at 0.5 s, a tip contact at 1.25 s
    (out of time order on purpose)."""
    t = np.array([2.0, 0.5, 1.25])
    tip = np.array([[0.3, 0.1, 0.2], [0.0, 0.2, 0.1], [0.1, 0.2, 0.3]])[:, :dim]
    a = np.zeros((3, dim))
    return ContactTable(
        t=t, link=np.array([2, 1, 2]), p_tip=np.array([1.0, 0.0, 0.5]),
        label=np.array(["tip", "link", "ambiguous"]), variance=np.full(3, 1e-6),
        used_as_tip=np.array([True, False, True]), tip_center=tip,
        tip_radius=np.full(3, 0.01), seg_a=a, seg_b=tip, link_radius=np.full(3, 0.02),
        primitive=np.array([0, 1, -1]), residual=np.array([1e-4, -2e-4, np.nan]),
        p_link=np.array([1.0, 0.6, 1.0]))


def read_overlay(path) -> list[tuple[str, int, dict, dict]]:
    """``(topic, log time, message, schema)`` of every message, in file order."""
    with open(path, "rb") as f:
        out = []
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            assert channel.message_encoding == "json"
            assert schema.encoding == "jsonschema"
            assert message.publish_time == message.log_time
            out.append((channel.topic, message.log_time, json.loads(message.data),
                        json.loads(schema.data)))
    return out


def test_overlay_has_tf_map_and_each_contact_at_its_own_time(map_3d, tmp_path):
    out = write_overlay(tmp_path / "overlay.mcap", map_3d, small_table(), t0_ns=T0)
    msgs = read_overlay(out)
    for _, _, message, schema in msgs:
        jsonschema.validate(message, schema)
    assert [m[0] for m in msgs] == [TF_TOPIC, TOPIC] + [CONTACTS_TOPIC] * 3
    tf = msgs[0][2]
    assert msgs[0][3]["title"] == "foxglove.FrameTransform"
    assert (tf["parent_frame_id"], tf["child_frame_id"]) == ("world", "base_link")
    assert tf["rotation"] == {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}
    assert msgs[1][1] == T0
    update = msgs[1][2]
    ids = [e["id"] for e in update["entities"]]
    assert ids == ["primitive-0-cylinder", "primitive-1-plane", "unexplained"]
    for ent in update["entities"]:
        assert ent["frame_id"] == "base_link"
        assert ent["timestamp"] == {"sec": 1, "nsec": 500_000_000}
    tri = update["entities"][0]["triangles"][0]
    assert len(tri["indices"]) % 3 == 0
    assert max(tri["indices"]) < len(tri["points"])
    colour = tri["color"]
    assert np.allclose([colour["r"], colour["g"], colour["b"]], surface_colour(0), atol=1e-3)
    meta = {kv["key"]: kv["value"] for kv in update["entities"][0]["metadata"]}
    assert meta["type"] == "cylinder"
    assert json.loads(meta["params"])["radius"] == pytest.approx(0.1)
    # contacts in time order, each stamped at the log start plus its own time
    times = [m[1] for m in msgs[2:]]
    assert times == [T0 + 500_000_000, T0 + 1_250_000_000, T0 + 2_000_000_000]
    link, amb, tip = (m[2]["entities"][0] for m in msgs[2:])
    assert [link["id"], amb["id"], tip["id"]] == ["contact/1", "contact/2", "contact/0"]
    assert tip["timestamp"] == {"sec": 3, "nsec": 500_000_000}
    sphere = tip["spheres"][0]
    assert sphere["pose"]["position"] == {"x": 0.3, "y": 0.1, "z": 0.2}
    assert sphere["size"]["x"] == pytest.approx(0.02)           # the tip sphere's diameter
    assert sphere["color"]["r"] == 1.0                          # P_T = 1: tip, red
    line = link["lines"][0]
    assert line["type"] == 2
    assert line["color"]["b"] == 1.0                            # P_T = 0: link body, blue
    assert [p["y"] for p in line["points"]] == [0.0, 0.2]
    meta = {kv["key"]: kv["value"] for kv in link["metadata"]}
    assert (meta["link"], meta["label"], meta["primitive"]) == ("1", "link", "1")
    # the joint signals left this contact's link among its rigid group's, at 0.6
    assert (meta["p_link"], meta["link_by_map"]) == ("0.6", "")


def test_overlay_is_deterministic_and_contacts_are_optional(map_3d, tmp_path):
    a = write_overlay(tmp_path / "a.mcap", map_3d, small_table())
    b = write_overlay(tmp_path / "b.mcap", map_3d, small_table())
    assert a.read_bytes() == b.read_bytes()
    c = write_overlay(tmp_path / "c.mcap", map_3d)
    assert [m[0] for m in read_overlay(c)] == [TF_TOPIC, TOPIC]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.mcap", "b.mcap", "c.mcap"]


def test_planar_overlay_lifts_points_to_the_plane(map_2d, tmp_path):
    out = write_overlay(tmp_path / "o.mcap", map_2d, small_table(dim=2))
    msgs = read_overlay(out)
    assert [e["id"] for e in msgs[1][2]["entities"]] == ["primitive-0-line",
                                                         "primitive-1-circle"]
    link, _, tip = (m[2]["entities"][0] for m in msgs[2:])
    assert tip["spheres"][0]["pose"]["position"]["z"] == 0.0
    assert [p["z"] for p in link["lines"][0]["points"]] == [0.0, 0.0]


def test_schemas_reject_broken_messages():
    with pytest.raises(jsonschema.ValidationError, match="'timestamp' is a required property"):
        jsonschema.validate({"deletions": [], "entities": [{"id": "x"}]}, scene_update_schema())
    with pytest.raises(jsonschema.ValidationError, match="'rotation' is a required property"):
        jsonschema.validate({"timestamp": {"sec": 0, "nsec": 0}, "parent_frame_id": "world",
                             "child_frame_id": "base_link",
                             "translation": {"x": 0, "y": 0, "z": 0}},
                            frame_transform_schema())


def test_overlay_input_errors(map_3d, tmp_path):
    with pytest.raises(InputError, match="overlay time must be >= 0 ns"):
        write_overlay(tmp_path / "o.mcap", map_3d, t0_ns=-1)
    early = small_table()
    with pytest.raises(InputError, match="must not precede the log start"):
        write_overlay(tmp_path / "o.mcap", map_3d, early.__class__(
            **{**{f: getattr(early, f) for f in early.__dataclass_fields__},
               "t": np.array([-2.0, 0.5, 1.0])}))
    assert list(tmp_path.iterdir()) == []
