"""Foxglove overlay MCAP: readable, schema-valid SceneUpdate, right entities, deterministic."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest
from mcap.reader import make_reader

from wholearm_tools.errors import InputError
from wholearm_tools.mesh.overlay import TOPIC, scene_update_schema, write_overlay


def read_overlay(path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        msgs = list(reader.iter_messages())
    assert len(msgs) == 1
    schema, channel, message = msgs[0]
    return summary, schema, channel, message


def test_overlay_reads_back_with_all_entities(map_3d, tmp_path):
    tips = np.array([[0.1, 0.2, 0.3], [0.2, 0.2, 0.3], [0.3, 0.1, 0.2]])
    p_tip = np.array([0.0, 0.5, 1.0])
    segments = np.array([[[0, 0, 0], [0.1, 0, 0]], [[0, 0, 0.1], [0, 0.1, 0.1]]], dtype=float)
    out = write_overlay(tmp_path / "overlay.mcap", map_3d, contact_points=tips,
                        contact_p_tip=p_tip, contact_segments=segments, t0_ns=1_500_000_000)
    _, schema, channel, message = read_overlay(out)
    assert channel.topic == TOPIC
    assert channel.message_encoding == "json"
    assert schema.name == "foxglove.SceneUpdate"
    assert schema.encoding == "jsonschema"
    assert message.log_time == 1_500_000_000
    update = json.loads(message.data)
    jsonschema.validate(update, json.loads(schema.data))
    ids = [e["id"] for e in update["entities"]]
    assert ids == ["primitive/0", "primitive/1", "unexplained", "contacts/tip", "contacts/link"]
    for ent in update["entities"]:
        assert ent["frame_id"] == "base_link"
        assert ent["timestamp"] == {"sec": 1, "nsec": 500_000_000}
    tri = update["entities"][0]["triangles"][0]
    assert len(tri["indices"]) % 3 == 0
    assert max(tri["indices"]) < len(tri["points"])
    meta = {kv["key"]: kv["value"] for kv in update["entities"][0]["metadata"]}
    assert meta["kind"] == "cylinder"
    spheres = update["entities"][3]["spheres"]
    assert len(spheres) == 3
    assert spheres[0]["color"]["b"] == 1.0  # P_T = 0: link, blue
    assert spheres[2]["color"]["r"] == 1.0  # P_T = 1: tip, red
    assert spheres[2]["pose"]["position"] == {"x": 0.3, "y": 0.1, "z": 0.2}
    line = update["entities"][4]["lines"][0]
    assert line["type"] == 2
    assert len(line["points"]) == 4


def test_overlay_is_deterministic_and_optional_parts_are_left_out(map_3d, tmp_path):
    a = write_overlay(tmp_path / "a.mcap", map_3d)
    b = write_overlay(tmp_path / "b.mcap", map_3d)
    assert a.read_bytes() == b.read_bytes()
    _, _, _, message = read_overlay(a)
    ids = [e["id"] for e in json.loads(message.data)["entities"]]
    assert ids == ["primitive/0", "primitive/1", "unexplained"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.mcap", "b.mcap"]


def test_planar_overlay_lifts_points_to_the_plane(map_2d, tmp_path):
    out = write_overlay(tmp_path / "o.mcap", map_2d, contact_points=[[0.5, 0.1]],
                        contact_segments=[[[0.0, 0.0], [0.5, 0.1]]])
    _, schema, _, message = read_overlay(out)
    update = json.loads(message.data)
    jsonschema.validate(update, json.loads(schema.data))
    assert [e["id"] for e in update["entities"]] == [
        "primitive/0", "primitive/1", "contacts/tip", "contacts/link"]
    assert update["entities"][2]["spheres"][0]["pose"]["position"]["z"] == 0.0
    assert [p["z"] for p in update["entities"][3]["lines"][0]["points"]] == [0.0, 0.0]


def test_schema_rejects_a_broken_entity():
    bad = {"deletions": [], "entities": [{"id": "x"}]}
    with pytest.raises(jsonschema.ValidationError, match="'timestamp' is a required property"):
        jsonschema.validate(bad, scene_update_schema())


def test_overlay_input_errors(map_3d, tmp_path):
    with pytest.raises(InputError, match=r"contact_p_tip of shape \(2,\)"):
        write_overlay(tmp_path / "o.mcap", map_3d, contact_points=np.zeros((2, 3)),
                      contact_p_tip=[0.5, 1.5])
    with pytest.raises(InputError, match=r"shape \(N, 3\), got \(2, 2\)"):
        write_overlay(tmp_path / "o.mcap", map_3d, contact_points=np.zeros((2, 2)))
    with pytest.raises(InputError, match=r"segments of shape \(M, 2, 3\)"):
        write_overlay(tmp_path / "o.mcap", map_3d, contact_segments=np.zeros((2, 3)))
    with pytest.raises(InputError, match="without contact_points"):
        write_overlay(tmp_path / "o.mcap", map_3d, contact_p_tip=[0.5])
    assert list(tmp_path.iterdir()) == []
