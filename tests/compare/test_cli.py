"""wholearm compare: table on stdout, outputs, one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner, Result

from cli.compare import command
from wholearm_tools.compare import OUTPUT_NAMES


def _run(*args: object):
    return CliRunner().invoke(command, [str(a) for a in args])


def _one_line_error(result: Result) -> str:
    assert result.exit_code != 0
    assert result.exception is None or isinstance(result.exception, SystemExit)
    assert "Traceback" not in result.output
    lines = [ln for ln in result.stderr.strip().splitlines() if not ln.startswith("wrote ")]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("Error: ")
    return lines[0]


def test_table_printed_and_outputs_written(logs: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    result = _run(logs["empty"], logs["a"], "--B", 0.05, "-o", out, "--workers", 2)
    assert result.exit_code == 0, result.output
    lines = result.stdout.splitlines()
    assert lines[0].startswith("log ")
    assert [ln.split()[:2] for ln in lines[1:3]] == [["circle_a.mcap", "0.05"],
                                                     ["empty.mcap", "0.05"]]
    assert len(lines) == 3  # the table on stdout; what was written is status on stderr
    assert result.stderr.startswith("wrote ")
    assert sorted(p.name for p in out.iterdir()) == sorted(OUTPUT_NAMES)
    # existing outputs are refused without --overwrite, replaced with it
    line = _one_line_error(_run(logs["empty"], "--B", 0.05, "-o", out))
    assert "already holds comparison.csv" in line
    result = _run(logs["empty"], "--B", 0.05, "-o", out, "--overwrite", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert [r["log"] for r in data["rows"]] == ["empty.mcap"]
    assert json.loads((out / "comparison.json").read_text())["rows"] == data["rows"]


def test_missing_log_is_a_usage_error(logs: dict[str, Path], tmp_path: Path) -> None:
    result = _run(logs["missing"], "--B", 0.02, "-o", tmp_path / "cmp")
    assert result.exit_code == 2
    assert "missing.mcap' does not exist" in result.stderr
    assert "Traceback" not in result.output
    assert not (tmp_path / "cmp").exists()


def test_unreadable_log_fails_after_writing_the_table(logs: dict[str, Path],
                                                      tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    result = _run(logs["garbage"], logs["empty"], "--B", 0.05, "-o", out, "--workers", 1)
    line = _one_line_error(result)
    assert "1 of 2 runs failed; first: garbage.mcap B=0.05" in line
    assert "garbage.mcap" in result.stdout
    assert sorted(p.name for p in out.iterdir()) == sorted(OUTPUT_NAMES)


def test_bad_option_values(logs: dict[str, Path], tmp_path: Path) -> None:
    for args in (["--B", "-1"], ["--B", "0.02", "--workers", "0"], ["--B", "inf"]):
        result = _run(logs["empty"], *args, "-o", tmp_path / "cmp")
        assert result.exit_code == 2
        assert "Error" in result.stderr
