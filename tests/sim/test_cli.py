"""``wholearm simulate`` and ``wholearm scenarios`` through click's CliRunner."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from cli.main import cli


def run(*args: str):
    return CliRunner().invoke(cli, list(args))


def test_scenarios_json() -> None:
    res = run("scenarios", "--json")
    assert res.exit_code == 0, res.output
    rows = {r["name"]: r for r in json.loads(res.output)}
    assert rows["well_junction"]["dof"] == 5
    assert rows["lab_circle"]["planar"] is True
    assert rows["paper_planar"]["surfaces"].count("line") == 4


def test_simulate_writes_mcap_and_summary(tmp_path: Path) -> None:
    out = tmp_path / "run.mcap"
    res = run("simulate", "lab_circle", "-o", str(out), "--duration", "2", "--seed", "4")
    assert res.exit_code == 0, res.output
    assert out.is_file()
    assert out.stat().st_size > 1000
    assert "1001 samples" in res.output
    assert "contacts" in res.output
    from wholearm_tools.logs import read_run

    back = read_run(out)
    assert back.log.n_samples == 1001
    assert back.truth is not None
    assert back.truth.meta["seed"] == 4


def test_same_seed_byte_identical_mcap(tmp_path: Path) -> None:
    a, b, c = (tmp_path / f"{x}.mcap" for x in "abc")
    for path, seed in ((a, "7"), (b, "7"), (c, "8")):
        res = run("simulate", "lab_sharp", "-o", str(path), "--duration", "1.5", "--seed", seed,
                  "--profile", "json")
        assert res.exit_code == 0, res.output
    assert a.read_bytes() == b.read_bytes()
    assert a.read_bytes() != c.read_bytes()


@pytest.mark.parametrize(("args", "message"), [
    (("simulate", "nope"), "unknown scenario 'nope'"),
    (("simulate", "lab_circle", "--strategy", "zigzag"), "unknown strategy 'zigzag'"),
])
def test_bad_input_one_line_error_and_no_file(tmp_path: Path, args, message) -> None:
    out = tmp_path / "x.mcap"
    res = run(*args, "-o", str(out))
    assert res.exit_code != 0
    assert message in res.output
    assert len(res.output.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_malformed_scenario_file(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot: [", encoding="utf-8")
    out = tmp_path / "x.mcap"
    res = run("simulate", str(bad), "-o", str(out))
    assert res.exit_code != 0
    assert "bad.yaml: malformed YAML" in res.output
    assert len(res.output.strip().splitlines()) == 1
    assert not out.exists()


def test_unwritable_output_folder(tmp_path: Path) -> None:
    out = tmp_path / "missing" / "x.mcap"
    res = run("simulate", "lab_circle", "-o", str(out), "--duration", "1")
    assert res.exit_code != 0
    assert "does not exist" in res.output
    assert not out.parent.exists()


def test_existing_output_needs_overwrite(tmp_path: Path) -> None:
    out = tmp_path / "x.mcap"
    out.write_bytes(b"keep")
    res = run("simulate", "lab_circle", "-o", str(out), "--duration", "1")
    assert res.exit_code != 0
    assert "--overwrite" in res.output
    assert out.read_bytes() == b"keep"
    res = run("simulate", "lab_circle", "-o", str(out), "--duration", "1", "--overwrite")
    assert res.exit_code == 0, res.output
    assert out.read_bytes() != b"keep"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.mcap"]


def test_inspect_shows_the_contacts_found(tmp_path: Path) -> None:
    out = tmp_path / "run.mcap"
    assert run("simulate", "lab_sharp", "-o", str(out), "--duration", "10").exit_code == 0
    res = run("inspect", str(out), "--json")
    assert res.exit_code == 0, res.output
    info = json.loads(res.output)
    found = info["contacts_found"]
    assert found["count"] == info["ground_truth"]["contacts"] > 0
    assert found["matched"] == found["link_right"] == found["count"]
    text = run("inspect", str(out)).output
    assert f"contacts:  {found['count']} detected" in text
