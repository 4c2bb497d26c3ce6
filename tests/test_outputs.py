"""The output set of a reconstruction: every deliverable, its provenance, written as a unit
(old set or new set, never a mix), existing outputs regular files only."""

from __future__ import annotations

import hashlib
import json
import os
import pickle
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from wholearm_tools.errors import OutputError
from wholearm_tools.outputs import (
    OutputSet,
    reconstruction_names,
    write_reconstruction,
)
from wholearm_tools.report.data import load_report_data

LIGHT = {"meshes": (), "overlay": False, "report": False}


@pytest.fixture(scope="module")
def short_rec(tmp_path_factory):
    """A short simulated planar run (paper_planar, 20 s), written as MCAP and reconstructed."""
    from wholearm_tools.logs import read_run, write_run
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.sim import load_scenario

    sc = load_scenario("paper_planar")
    path = tmp_path_factory.mktemp("run") / "run.mcap"
    write_run(path, sc.simulate(seed=0, duration=20.0).run)
    return reconstruct(read_run(path), B=sc.hints.get("B", 0.03))


@pytest.fixture(autouse=True)
def fixed_date(monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1767225600")


def listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_every_output_with_provenance(short_rec, tmp_path):
    out = tmp_path / "out"
    paths = write_reconstruction(out, short_rec, meshes=("ply", "glb"))
    assert listing(out) == ["contacts.csv", "map.glb", "map.json", "map.ply", "overlay.mcap",
                            "report.pdf", "report_data.json"]
    assert listing(tmp_path) == ["out"]                       # no staging folder left
    assert set(paths) == {"map", "contacts", "report_data", "mesh.ply", "mesh.glb", "overlay",
                          "report"}
    meta = json.loads((out / "map.json").read_text())["meta"]
    source = Path(short_rec.run.source)
    assert meta["tool"]["name"] == "wholearm_tools"
    assert meta["created"] == "2026-01-01T00:00:00Z"
    assert meta["input"]["sha256"] == hashlib.sha256(source.read_bytes()).hexdigest()
    assert meta["input"]["path"] == os.path.relpath(source, out)
    assert meta["source"] == meta["input"]["path"]
    prm = meta["parameters"]
    assert prm["B"] == short_rec.params.B
    assert prm["loss"] == "huber"
    assert prm["torque_source"] == "commanded"
    assert prm["detection"]["settings"]["k_velocity"] > 0
    assert len(prm["detection"]["velocity_threshold"]) == short_rec.run.robot.dof
    assert prm["classification"]["tip_threshold"] > prm["classification"]["link_threshold"]
    for name in ("contacts.csv", "report_data.json", "map.ply", "overlay.mcap"):
        digest = hashlib.sha256((out / name).read_bytes()).hexdigest()
        assert meta["outputs"][name]["sha256"] == digest
    # the report rendered from the files is the one `wholearm report OUT/` renders
    from wholearm_tools.report import write_report

    write_report(tmp_path / "again.pdf", load_report_data(out))
    assert (tmp_path / "again.pdf").read_bytes() == (out / "report.pdf").read_bytes()


def test_report_data_round_trip(short_rec, tmp_path):
    import numpy as np

    write_reconstruction(tmp_path / "out", short_rec, **LIGHT)
    data = load_report_data(tmp_path / "out" / "map.json")
    table, original = data.table, short_rec.table
    assert np.array_equal(table.primitive, original.primitive)
    assert np.allclose(table.residual, original.residual, equal_nan=True, atol=1e-9)
    assert list(table.label_map) == list(original.label_map)
    assert data.run.truth is not None
    assert data.run.truth.n_contacts == short_rec.run.truth.n_contacts
    assert data.run.dof == short_rec.run.robot.dof
    assert data.run.torque_source == "commanded"
    assert "<robot" in data.run.robot_urdf
    assert data.ptip_history.shape == (len(original), data.ptip_times.shape[0])
    assert [f.id for f in data.fits] == [p.id for p in short_rec.surface_map.primitives]
    for fit, result in zip(data.fits, short_rec.fits, strict=True):
        assert np.array_equal(fit.tip_residuals, np.asarray(result.tip_residuals))
        assert fit.param_labels == tuple(result.param_labels)


def test_existing_set_is_refused_then_replaced_whole(short_rec, tmp_path):
    out = tmp_path / "out"
    write_reconstruction(out, short_rec, meshes=("stl",), overlay=False, report=False)
    before = (out / "map.json").read_bytes()
    with pytest.raises(OutputError, match=r"already holds .*map\.json.*--overwrite"):
        write_reconstruction(out, short_rec, **LIGHT)
    assert (out / "map.json").read_bytes() == before
    write_reconstruction(out, short_rec, overwrite=True, **LIGHT)
    # the earlier run's mesh does not stay behind beside the new set
    assert listing(out) == ["contacts.csv", "map.json", "report_data.json"]
    assert listing(tmp_path) == ["out"]


def test_other_files_in_the_folder_are_kept(short_rec, tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    write_reconstruction(out, short_rec, **LIGHT)
    write_reconstruction(out, short_rec, overwrite=True, meshes=("obj",), overlay=False,
                         report=False)
    assert listing(out) == ["contacts.csv", "map.json", "map.obj", "notes.txt",
                            "report_data.json"]
    assert (out / "notes.txt").read_text() == "mine"
    load_report_data(out)                                  # a consistent set


def test_without_the_atomic_swap_the_files_move_in_with_map_json_last(short_rec, tmp_path,
                                                                      monkeypatch):
    import wholearm_tools.outputs as outputs

    moved = []
    real_replace = os.replace
    monkeypatch.setattr(outputs, "_exchange", lambda a, b: False)
    monkeypatch.setattr(outputs.os, "replace",
                        lambda a, b: (moved.append(Path(b).name), real_replace(a, b))[1])
    out = tmp_path / "out"
    write_reconstruction(out, short_rec, **LIGHT)
    write_reconstruction(out, short_rec, overwrite=True, **LIGHT)
    assert moved[-1] == "map.json"
    assert listing(out) == ["contacts.csv", "map.json", "report_data.json"]


@pytest.mark.parametrize("kind", ["symlink", "folder", "fifo"])
def test_outputs_must_be_regular_files(short_rec, tmp_path, kind):
    out = tmp_path / "out"
    out.mkdir()
    target = tmp_path / "elsewhere.json"
    target.write_text("keep")
    if kind == "symlink":
        (out / "map.json").symlink_to(target)
    elif kind == "folder":
        (out / "map.json").mkdir()
    else:
        os.mkfifo(out / "map.json")
    with pytest.raises(OutputError, match=r"map\.json: is (a symbolic link|not a regular file)"):
        write_reconstruction(out, short_rec, overwrite=True, **LIGHT)
    assert target.read_text() == "keep"
    assert listing(tmp_path) == ["elsewhere.json", "out"]


def test_two_writers_into_one_new_folder_do_not_replace_each_other(short_rec, tmp_path):
    from wholearm_tools.outputs import write_outputs

    out = tmp_path / "new"
    first = OutputSet(out, reconstruction_names())
    second = OutputSet(out, reconstruction_names())    # both checked before either commits
    write_outputs(first, short_rec, **LIGHT)
    write_outputs(second, short_rec, **LIGHT)
    first.commit()
    written = (out / "report_data.json").read_bytes()
    with pytest.raises(OutputError, match="already holds"):
        second.commit()
    second.discard()
    assert (out / "report_data.json").read_bytes() == written
    assert listing(tmp_path) == ["new"]


def test_a_failure_leaves_the_old_set_and_no_staging_folder(short_rec, tmp_path, monkeypatch):
    import wholearm_tools.mesh.export as export

    out = tmp_path / "out"
    write_reconstruction(out, short_rec, **LIGHT)
    before = {n: (out / n).read_bytes() for n in listing(out)}

    def broken(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(export, "export_mesh", broken)
    with pytest.raises(OSError, match="No space left"):
        write_reconstruction(out, short_rec, overwrite=True, meshes=("ply",), overlay=False,
                             report=False)
    assert {n: (out / n).read_bytes() for n in listing(out)} == before
    assert listing(tmp_path) == ["out"]


KILLER = """
import os, pickle, signal, sys
import wholearm_tools.outputs as outputs
rec = pickle.load(open(sys.argv[1], "rb"))
step, point = sys.argv[3], sys.argv[4]
die = lambda *a, **k: os.kill(os.getpid(), signal.SIGKILL)
if point == "swap":          # after the folders are swapped, before the old one is deleted
    outputs.shutil.rmtree = die
progress = (lambda s: die() if step in s else None) if point == "step" else None
outputs.write_reconstruction(sys.argv[2], rec, overwrite=True, meshes=("ply",),
                             overlay=False, report=False, progress=progress)
"""


@pytest.mark.parametrize(("step", "point"), [("contact table", "step"), ("replaying", "step"),
                                             ("meshing", "step"), ("", "swap")])
def test_kill_9_leaves_the_old_set_or_the_new_set(short_rec, tmp_path, step, point):
    """SIGKILL at each step of writing a set over an earlier one: the folder holds one run's
    complete set (the old one, or the new one after the swap), and the next writer removes the
    killed writer's staging folder."""
    out = tmp_path / "out"
    write_reconstruction(out, short_rec, **LIGHT)
    old = {n: (out / n).read_bytes() for n in listing(out)}
    rec_file = tmp_path / "rec.pkl"
    rec_file.write_bytes(pickle.dumps(short_rec))
    env = {**os.environ, "SOURCE_DATE_EPOCH": "1800000000"}       # a new set differs
    proc = subprocess.run([sys.executable, "-c", KILLER, str(rec_file), str(out), step, point],
                          env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    names = listing(out)
    if point == "swap":
        assert names == ["contacts.csv", "map.json", "map.ply", "report_data.json"]
        assert (out / "map.json").read_bytes() != old["map.json"]
    else:
        assert {n: (out / n).read_bytes() for n in names} == old
    load_report_data(out)                                 # consistent: hashes match
    leftovers = [p for p in listing(tmp_path) if p.startswith(".out.wholearm-")]
    assert len(leftovers) == 1
    write_reconstruction(tmp_path / "out", short_rec, overwrite=True, **LIGHT)
    assert not [p for p in listing(tmp_path) if p.startswith(".out.wholearm-")]


def test_cli_reconstruct_writes_every_output_or_nothing(short_rec, tmp_path):
    from click.testing import CliRunner

    from cli.main import cli

    run = short_rec.run.source
    res = CliRunner().invoke(cli, ["reconstruct", run, "-o", str(tmp_path / "all"),
                                   "--B", str(short_rec.params.B), "--json"])
    assert res.exit_code == 0, res.output
    assert listing(tmp_path / "all") == [
        "contacts.csv", "map.glb", "map.json", "map.obj", "map.ply", "map.stl", "map.vtp",
        "overlay.mcap", "report.pdf", "report_data.json"]
    doc = json.loads(res.output)
    assert doc["outputs"]["report"] == str(tmp_path / "all" / "report.pdf")
    res = CliRunner().invoke(cli, ["reconstruct", run, "-o", str(tmp_path / "some"),
                                   "--B", str(short_rec.params.B), "--no-report",
                                   "--no-overlay", "--mesh-format", "gltf"])
    assert res.exit_code == 0, res.output
    assert listing(tmp_path / "some") == ["contacts.csv", "map.gltf", "map.json",
                                          "report_data.json"]
    res = CliRunner().invoke(cli, ["reconstruct", run, "-o", str(tmp_path / "none"),
                                   "--no-meshes", "--mesh-format", "ply"])
    assert res.exit_code == 2
    assert "exclude each other" in res.output
    res = CliRunner().invoke(cli, ["reconstruct", run, "-o", str(tmp_path / "bad"),
                                   "--joint-topic", "/nothing"])
    assert res.exit_code == 1
    assert listing(tmp_path) == ["all", "some"]          # a failed run leaves nothing


def test_a_folder_from_before_report_data_still_reports(short_rec, tmp_path):
    """An older output folder (map.json and contacts.csv only) reports from the contact table;
    a folder with neither report data nor a table says what is missing."""
    out = tmp_path / "old"
    write_reconstruction(out, short_rec, **LIGHT)
    (out / "report_data.json").unlink()
    doc = json.loads((out / "map.json").read_text())
    for key in ("outputs", "input", "tool", "created", "parameters"):
        doc["meta"].pop(key)
    (out / "map.json").write_text(json.dumps(doc))
    data = load_report_data(out)
    assert len(data.table) == len(short_rec.table)
    assert data.ptip_history is None
    assert data.run.truth is None
    from wholearm_tools.report import write_report

    info = write_report(tmp_path / "old.pdf", data)
    assert info.pages[:2] == ("Summary", "Map")
    (out / "contacts.csv").unlink()
    from wholearm_tools.errors import InputError

    with pytest.raises(InputError, match=r"no report data and no contact table beside map\.json"):
        load_report_data(out)


def test_the_working_directory_is_never_swapped_away(short_rec, tmp_path, monkeypatch):
    import wholearm_tools.outputs as outputs

    out = tmp_path / "out"
    write_reconstruction(out, short_rec, **LIGHT)
    monkeypatch.chdir(out)
    swapped = []
    monkeypatch.setattr(outputs, "_exchange", lambda a, b: swapped.append(b) or False)
    write_reconstruction(".", short_rec, overwrite=True, **LIGHT)
    assert swapped == []
    assert os.path.samefile(os.getcwd(), out)
    assert listing(out) == ["contacts.csv", "map.json", "report_data.json"]
