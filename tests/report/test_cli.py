"""``wholearm report``: from an MCAP log, from a reconstruct output folder, and its errors."""

from __future__ import annotations

import dataclasses
import json

from click.testing import CliRunner

from cli.report import command
from wholearm_tools.logs import write_run
from wholearm_tools.outputs import write_reconstruction


def _invoke(*args):
    return CliRunner().invoke(command, [str(a) for a in args])


def test_report_from_log_then_refuses_to_overwrite(planar_rec, tmp_path):
    log = tmp_path / "run.mcap"
    write_run(log, planar_rec.run)
    out = tmp_path / "report.pdf"
    res = _invoke(log, "-o", out, "--B", planar_rec.params.B)
    assert res.exit_code == 0, res.output
    assert out.read_bytes().startswith(b"%PDF")
    assert "Contacts:" in res.output
    assert "Accuracy against ground truth" in res.output
    before = out.read_bytes()
    res = _invoke(log, "-o", out)
    assert res.exit_code == 1
    lines = res.output.strip().splitlines()
    assert len(lines) == 1
    assert "already exists" in lines[0]
    assert "--overwrite" in lines[0]
    assert out.read_bytes() == before


def test_report_from_output_folder_uses_the_recorded_run(planar_rec, tmp_path):
    log = tmp_path / "run.mcap"
    write_run(log, planar_rec.run)
    sm = planar_rec.surface_map
    rec = dataclasses.replace(planar_rec, surface_map=dataclasses.replace(
        sm, meta={**sm.meta, "source": str(log)}))
    out_dir = tmp_path / "out"
    write_reconstruction(out_dir, rec)
    out = tmp_path / "r.pdf"
    out.write_bytes(b"old")
    res = _invoke(out_dir, "-o", out, "--overwrite")
    assert res.exit_code == 0, res.output
    assert out.read_bytes().startswith(b"%PDF")
    assert f"B = {planar_rec.params.B:g} m" in res.output        # the map's B


def test_output_folder_without_a_run_is_a_clear_error(planar_rec, tmp_path):
    out_dir = tmp_path / "out"
    write_reconstruction(out_dir, planar_rec)          # source: the scenario name, not a file
    res = _invoke(out_dir, "-o", tmp_path / "r.pdf")
    assert res.exit_code == 1
    assert "was not found" in res.output or "records no run log" in res.output
    data = json.loads((out_dir / "map.json").read_text())
    data["meta"].pop("source")
    (out_dir / "map.json").write_text(json.dumps(data))
    res = _invoke(out_dir, "-o", tmp_path / "r.pdf")
    assert res.exit_code == 1
    assert "records no run log" in res.output
    res = _invoke(tmp_path, "-o", tmp_path / "r.pdf")
    assert res.exit_code == 1
    assert "no map.json" in res.output
    assert not (tmp_path / "r.pdf").exists()


def test_output_must_be_a_pdf(tmp_path):
    log = tmp_path / "run.mcap"
    log.write_bytes(b"")
    res = _invoke(log, "-o", tmp_path / "r.png")
    assert res.exit_code == 2
    assert ".pdf" in res.output
