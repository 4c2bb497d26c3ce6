"""``wholearm report``: from an MCAP log, from an output folder (no refit, from anywhere, a
folder made by ``fit``), and its errors."""

from __future__ import annotations

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
    assert "Input: run.mcap (sha256 " in res.output              # relative to the PDF
    assert "Against the simulator's ground truth" in res.output
    before = out.read_bytes()
    res = _invoke(log, "-o", out)
    assert res.exit_code == 1
    lines = res.output.strip().splitlines()
    assert len(lines) == 1
    assert "already exists" in lines[0]
    assert "--overwrite" in lines[0]
    assert out.read_bytes() == before


def test_report_from_output_folder_renders_without_the_log(planar_rec, tmp_path, monkeypatch):
    log = tmp_path / "logs" / "run.mcap"
    log.parent.mkdir()
    write_run(log, planar_rec.run)
    out_dir = tmp_path / "out"
    write_reconstruction(out_dir, planar_rec, input_path=log, meshes=(), overlay=False,
                         report=False)
    log.unlink()                                   # the folder alone is enough
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)                   # and from another folder
    res = _invoke("../out")
    assert res.exit_code == 0, res.output
    assert (out_dir / "report.pdf").read_bytes().startswith(b"%PDF")
    assert f"B = {planar_rec.params.B:g} m" in res.output          # the map's B
    assert "Input: ../logs/run.mcap" in res.output                # relative to the folder
    res = _invoke("../out", "-o", "r.pdf", "--B", "0.05")
    assert res.exit_code == 2
    assert "--B apply to a log" in res.output
    assert not (elsewhere / "r.pdf").exists()


def test_report_from_a_folder_made_by_fit(planar_rec, tmp_path):
    from cli.fit import command as fit

    out_dir = tmp_path / "rec"
    write_reconstruction(out_dir, planar_rec, meshes=(), overlay=False, report=False)
    fitted = tmp_path / "fitted"
    fitted.mkdir()
    res = CliRunner().invoke(fit, [str(out_dir / "contacts.csv"), "-o",
                                   str(fitted / "map.json"), "--B", str(planar_rec.params.B)])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in fitted.iterdir()) == ["map.json", "report_data.json"]
    res = _invoke(fitted, "-o", tmp_path / "fit.pdf")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "fit.pdf").read_bytes().startswith(b"%PDF")
    assert "Fitted from a contact table" in res.output
    assert "Input: ../rec/contacts.csv" in res.output


def test_folder_without_data_or_map_is_a_clear_error(planar_rec, tmp_path):
    out_dir = tmp_path / "out"
    write_reconstruction(out_dir, planar_rec, meshes=(), overlay=False, report=False)
    (out_dir / "contacts.csv").write_text("changed\n")
    res = _invoke(out_dir, "-o", tmp_path / "r.pdf")
    assert res.exit_code == 1
    assert "contacts.csv: changed since report_data.json was written" in res.output
    res = _invoke(tmp_path, "-o", tmp_path / "r.pdf")
    assert res.exit_code == 1
    assert "no map.json" in res.output
    assert not (tmp_path / "r.pdf").exists()
    data = json.loads((out_dir / "map.json").read_text())
    assert data["meta"]["outputs"]["report_data.json"]["sha256"]


def test_output_must_be_a_pdf_and_a_log_needs_one(tmp_path):
    log = tmp_path / "run.mcap"
    log.write_bytes(b"")
    res = _invoke(log, "-o", tmp_path / "r.png")
    assert res.exit_code == 2
    assert ".pdf" in res.output
    res = _invoke(log)
    assert res.exit_code == 2
    assert "-o/--output is required for a log" in res.output
