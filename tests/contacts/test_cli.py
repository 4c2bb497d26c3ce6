"""``wholearm contacts`` and ``wholearm plot-ptip`` through click's CliRunner."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from cli.main import cli
from wholearm_tools.contact_table import read_contact_table


def run(*args: str):
    return CliRunner().invoke(cli, list(args))


@pytest.fixture(scope="module")
def mcap(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("run") / "run.mcap"
    # 20 s: at 12 s the five contacts on the circle fit one r 0.22 m through a bending one
    res = run("simulate", "lab_circle", "-o", str(out), "--duration", "20", "--seed", "1")
    assert res.exit_code == 0, res.output
    return out


def test_contacts_csv_is_the_fit_table_plus_diagnostics(mcap: Path, tmp_path: Path) -> None:
    out = tmp_path / "contacts.csv"
    res = run("contacts", str(mcap), "--B", "0.02", "-o", str(out))
    assert res.exit_code == 0, res.output
    table = read_contact_table(out)
    assert len(table) >= 3
    assert table.dim == 2
    with out.open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(table)
    for col in ("p_tip_nomap", "p_tip_swept", "consistent", "true_link", "true_kind"):
        assert col in rows[0], col
    assert sum(c.startswith("q_") for c in rows[0]) == 2
    assert sum(c.startswith("qd_") for c in rows[0]) == 2
    # the link in contact agrees with the truth on a short lab run
    agree = sum(int(r["link"]) == int(r["true_link"]) for r in rows)
    assert agree >= 0.9 * len(rows)


def test_fit_reads_the_contacts_csv(mcap: Path, tmp_path: Path) -> None:
    out = tmp_path / "contacts.csv"
    assert run("contacts", str(mcap), "--B", "0.02", "-o", str(out)).exit_code == 0
    res = run("fit", str(out), "-o", str(tmp_path / "map.json"))
    assert res.exit_code == 0, res.output
    m = json.loads((tmp_path / "map.json").read_text())
    assert m["format"] == "wholearm-map"
    circles = [p for p in m["primitives"] if p["type"] == "circle"]
    assert len(circles) == 1  # the post r 0.06 m at (0.38, 0.24)
    assert circles[0]["params"]["radius"] == pytest.approx(0.06, rel=0.01)
    assert circles[0]["params"]["center"] == pytest.approx([0.38, 0.24], abs=1e-3)


def test_contacts_parquet_holds_the_csv_columns_typed(mcap: Path, tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    from wholearm_tools._tables import read_meta

    csv_out, pq_out = tmp_path / "contacts.csv", tmp_path / "contacts.parquet"
    assert run("contacts", str(mcap), "--B", "0.02", "-o", str(csv_out)).exit_code == 0
    res = run("contacts", str(mcap), "--B", "0.02", "-o", str(pq_out))
    assert res.exit_code == 0, res.output
    table = pq.read_table(pq_out)
    with csv_out.open() as fh:
        rows = list(csv.DictReader(fh))
    assert table.column_names == list(rows[0])
    assert table.num_rows == len(rows)
    assert table.schema.field("link").type == pa.int64()
    assert table.schema.field("p_tip").type == pa.float64()
    assert table.schema.field("label").type == pa.string()
    assert table.column("primitive").null_count == 0  # -1 before fitting
    assert table.column("residual").null_count == len(rows)  # empty before fitting
    # declared types, whatever the cells hold: empty columns keep theirs
    assert table.schema.field("residual").type == pa.float64()
    assert table.schema.field("link_by_map").type == pa.int64()
    assert table.schema.field("label_map").type == pa.string()
    assert table.schema.field("consistent").type == pa.int64()
    assert table.schema.field("true_kind").type == pa.string()
    p_tip = table.column("p_tip").to_pylist()
    assert p_tip == [float(r["p_tip"]) for r in rows]
    assert read_meta(pq_out) == {"run": str(mcap), "B": 0.02, "causal": False}
    # the fit reads either file and fits the same map
    for src, name in ((csv_out, "a.json"), (pq_out, "b.json")):
        assert run("fit", str(src), "-o", str(tmp_path / name)).exit_code == 0
    a = json.loads((tmp_path / "a.json").read_text())
    b = json.loads((tmp_path / "b.json").read_text())
    assert a["primitives"]
    assert a["primitives"] == b["primitives"]


def test_fit_of_a_broken_parquet_file_is_a_one_line_error(tmp_path: Path) -> None:
    bad = tmp_path / "contacts.parquet"
    bad.write_bytes(b"PAR1 not really")
    res = run("fit", str(bad), "-o", str(tmp_path / "map.json"))
    assert res.exit_code != 0
    assert "Traceback" not in res.output
    errors = [line for line in res.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1, res.output
    assert str(bad) in errors[0]
    assert not (tmp_path / "map.json").exists()


def test_contacts_json_and_table(mcap: Path) -> None:
    res = run("contacts", str(mcap), "--B", "0.02", "--json", "--causal")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["causal"] is True
    assert doc["contacts"]
    first = doc["contacts"][0]  # typed numbers, as in the Parquet schema
    assert isinstance(first["t"], float)
    assert isinstance(first["link"], int)
    assert isinstance(first["p_tip"], float)
    assert first["residual"] is None
    assert isinstance(first["label"], str)
    res = run("contacts", str(mcap), "--B", "0.02")
    assert res.exit_code == 0, res.output
    assert "P_T" in res.output.splitlines()[0]


def test_plot_ptip_writes_png(mcap: Path, tmp_path: Path) -> None:
    out = tmp_path / "ptip.png"
    res = run("plot-ptip", str(mcap), "--B", "0.02", "-o", str(out), "--steps", "20")
    assert res.exit_code == 0, res.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_b_defaults_to_2_cm_and_is_bounded_by_the_reach(mcap: Path) -> None:
    default = run("contacts", str(mcap), "--json")
    assert default.exit_code == 0, default.output
    typed = run("contacts", str(mcap), "--json", "--B", "0.02")
    assert json.loads(default.stdout)["contacts"] == json.loads(typed.stdout)["contacts"]
    assert json.loads(default.stdout)["B"] == 0.02
    far = run("contacts", str(mcap), "--B", "1e9")
    assert far.exit_code == 1
    assert "--B = 1e+09 m is larger than the robot's reach" in far.output
    assert len(far.output.strip().splitlines()) == 1


@pytest.mark.parametrize("command", ["contacts", "plot-ptip"])
def test_bad_file_is_a_one_line_error(command: str, tmp_path: Path) -> None:
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not an mcap file at all")
    args = [command, str(bad), "--B", "0.02"]
    if command == "plot-ptip":
        args += ["-o", str(tmp_path / "p.png")]
    res = run(*args)
    assert res.exit_code != 0
    assert "Traceback" not in res.output
    errors = [line for line in res.output.splitlines() if line.startswith("Error")]
    assert len(errors) == 1, res.output
    assert not (tmp_path / "p.png").exists()


@pytest.mark.parametrize("command", ["contacts", "plot-ptip", "report"])
def test_topics_are_selectable(command: str, mcap: Path, tmp_path: Path) -> None:
    out = {"contacts": [], "plot-ptip": ["-o", str(tmp_path / "p.png")],
           "report": ["-o", str(tmp_path / "r.pdf")]}[command]
    res = run(command, str(mcap), "--B", "0.02", "--joint-topic", "/arm/joint_states", *out)
    assert res.exit_code == 1
    assert "no JointState topic '/arm/joint_states'" in res.output
    assert "/joint_states" in res.output  # the topics the log has
    if command == "contacts":
        named = run(command, str(mcap), "--B", "0.02", "--joint-topic", "/joint_states",
                    "--command-topic", "/joint_commands", "--json")
        assert named.exit_code == 0, named.output
        assert json.loads(named.output)["contacts"] == json.loads(
            run(command, str(mcap), "--B", "0.02", "--json").output)["contacts"]


def test_existing_output_is_refused(mcap: Path, tmp_path: Path) -> None:
    out = tmp_path / "contacts.csv"
    out.write_text("keep me")
    res = run("contacts", str(mcap), "--B", "0.02", "-o", str(out))
    assert res.exit_code == 1
    assert "--overwrite" in res.output
    assert out.read_text() == "keep me"


@pytest.mark.parametrize("command", ["contacts", "plot-ptip"])
@pytest.mark.parametrize("b_args", [["--B", "-1"], ["--B", "0"], ["--B", "nan"]])
def test_a_non_positive_b_is_a_usage_error(command: str, b_args: list[str],
                                           mcap: Path, tmp_path: Path) -> None:
    res = run(command, str(mcap), *b_args, "-o", str(tmp_path / "out.png"))
    assert res.exit_code == 2
    assert "--B" in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "out.png").exists()


def test_a_truncated_log_is_read_with_a_one_line_warning(mcap: Path, tmp_path: Path) -> None:
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(mcap.read_bytes()[: mcap.stat().st_size * 3 // 5])
    res = run("contacts", str(cut), "--B", "0.02", "--json")
    assert res.exit_code == 0, res.output
    warned = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(warned) == 1, res.stderr
    assert warned[0].startswith("WARNING: ")
    assert str(cut) in warned[0]
    assert "truncated" in warned[0]
    assert ".py:" not in res.stderr  # no source location of the library
    assert json.loads(res.stdout)["contacts"]


def test_every_contact_shows_its_evidence(tmp_path):
    """The printed table gives each contact's duration and its load in detection thresholds
    (a clear simulated contact is many thresholds over; the CSV carries the number)."""
    from wholearm_tools.logs import write_run
    from wholearm_tools.sim.scenarios import load_scenario

    path = tmp_path / "run.mcap"
    write_run(path, load_scenario("lab_circle").simulate(seed=0, duration=8.0).run)
    out = CliRunner().invoke(cli, ["contacts", str(path)])
    assert out.exit_code == 0, out.output
    head = out.output.splitlines()[0]
    assert "load" in head
    assert "dur s" in head
    table = tmp_path / "c.csv"
    assert CliRunner().invoke(cli, ["contacts", str(path), "-o", str(table)]).exit_code == 0
    with table.open() as fh:
        rows = list(csv.DictReader(fh))
    assert rows
    assert all(float(r["load"]) > 1.0 for r in rows)
