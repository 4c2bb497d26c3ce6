"""``wholearm export``: one file per format, refusal to overwrite, malformed maps."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from cli.export import command
from wholearm_tools.mapfile import write_map


@pytest.fixture
def map_file_3d(map_3d, tmp_path):
    path = tmp_path / "map.json"
    write_map(path, map_3d)
    return path


def listing(folder):
    return sorted(p.name for p in folder.iterdir())


def test_export_writes_one_file_per_format(map_file_3d, tmp_path):
    result = CliRunner().invoke(command, [str(map_file_3d), "-f", "ply", "-f", "stl",
                                          "-f", "glb", "--resolution", "0.02", "--json"])
    assert result.exit_code == 0, result.output
    assert listing(tmp_path) == ["map.glb", "map.json", "map.ply", "map.stl"]
    report = json.loads(result.output)
    assert report["outputs"]["ply"] == str(tmp_path / "map.ply")
    assert report["triangles"] > 0


def test_export_to_output_dir_and_drawings_of_planar_map(map_2d, tmp_path):
    write_map(tmp_path / "run.json", map_2d)
    out = tmp_path / "out"
    out.mkdir()
    result = CliRunner().invoke(command, [str(tmp_path / "run.json"), "-o", str(out),
                                          "-f", "svg", "-f", "png", "-f", "vtp"])
    assert result.exit_code == 0, result.output
    assert listing(out) == ["run.png", "run.svg", "run.vtp"]


def test_existing_output_without_overwrite_writes_nothing(map_file_3d, tmp_path):
    (tmp_path / "map.ply").write_bytes(b"old")
    runner = CliRunner()
    result = runner.invoke(command, [str(map_file_3d), "-f", "stl", "-f", "ply"])
    assert result.exit_code == 1
    assert result.output.strip().count("\n") == 0
    assert "map.ply: already exists (use --overwrite to replace it)" in result.output
    assert listing(tmp_path) == ["map.json", "map.ply"]
    assert (tmp_path / "map.ply").read_bytes() == b"old"
    result = runner.invoke(command, [str(map_file_3d), "-f", "stl", "-f", "ply",
                                     "--overwrite", "--resolution", "0.05"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "map.ply").read_bytes() != b"old"


def test_malformed_map_is_a_one_line_error(tmp_path):
    bad = tmp_path / "map.json"
    bad.write_text('{"format": "wholearm-map", "version": 1, "planar": false}')
    result = CliRunner().invoke(command, [str(bad), "-f", "ply", "-f", "obj"])
    assert result.exit_code == 1
    assert "malformed map" in result.output
    assert result.output.strip().count("\n") == 0
    assert listing(tmp_path) == ["map.json"]
    bad.write_text("{not json")
    result = CliRunner().invoke(command, [str(bad)])
    assert result.exit_code == 1
    assert "malformed JSON" in result.output
    assert listing(tmp_path) == ["map.json"]


def test_drawing_of_3d_map_is_refused(map_file_3d, tmp_path):
    result = CliRunner().invoke(command, [str(map_file_3d), "-f", "ply", "-f", "svg"])
    assert result.exit_code == 1
    assert "need a planar map" in result.output
    assert listing(tmp_path) == ["map.json"]
