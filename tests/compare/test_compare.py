"""compare_runs: rows, order, counts, truth errors, failures, outputs."""

from __future__ import annotations

import csv
import json
import re
from pathlib import Path

import numpy as np
import pytest

from wholearm_tools.compare import (
    LEADING_COLUMNS,
    OUTPUT_NAMES,
    ComparisonTable,
    compare_runs,
    comparison_row,
    write_comparison,
)
from wholearm_tools.contacts import arm_stops
from wholearm_tools.errors import InputError


def test_rows_sorted_by_log_then_b(local_table: ComparisonTable, logs: dict[str, Path],
                                   Bs: tuple[float, ...]) -> None:
    got = [(row["log"], row["B"]) for row in local_table]
    names = sorted(logs[k].name for k in ("a", "b", "missing"))
    assert got == [(name, B) for name in names for B in Bs]
    assert local_table.logs == tuple(names)
    assert local_table.Bs == Bs
    assert local_table.columns[:len(LEADING_COLUMNS)] == LEADING_COLUMNS


def test_counts_add_up_to_detected_contacts(local_table: ComparisonTable,
                                            logs: dict[str, Path], Bs: tuple[float, ...]
                                            ) -> None:
    from wholearm_tools.contacts import detect_contacts
    from wholearm_tools.logs import read_run

    for key in ("a", "b"):
        run = read_run(logs[key])
        detected = len(detect_contacts(run.log, run.robot))
        rows = [r for r in local_table if r["log"] == logs[key].name]
        assert len(rows) == len(Bs)
        for row in rows:
            assert row["status"] in ("ok", "no-fit"), row["error"]
            assert row["contacts"] == detected > 0
            assert row["tip"] + row["link"] + row["ambiguous"] == row["contacts"]
            assert 0 <= row["unexplained"] <= row["contacts"]
            counts = dict(item.split("=") for item in row["types"].split(";") if item)
            assert sum(int(n) for n in counts.values()) == row["primitives"]
            # simulated runs carry ground truth: every truth column is scored
            assert row["truth_contacts"] == run.truth.n_contacts
            assert row["matched"] + row["false_detections"] == row["contacts"]
            # the arm's stops against contact, and how many a detection found
            assert row["stops"] == len(arm_stops(run.truth)) > 0
            assert 0 < row["stops_found"] <= row["stops"]
            assert 0.0 <= row["link_accuracy"] <= 1.0
            assert row["surfaces_found"] + row["surfaces_missed"] == row["surfaces_touched"]
            assert row["wall_time_s"] > 0


def test_missing_log_gives_error_rows(local_table: ComparisonTable,
                                      logs: dict[str, Path], Bs: tuple[float, ...]) -> None:
    rows = [r for r in local_table if r["log"] == logs["missing"].name]
    assert [r["status"] for r in rows] == ["error"] * len(Bs)
    for row in rows:
        assert "missing.mcap" in row["error"]
        assert "\n" not in row["error"]
        assert row["contacts"] is None
    assert len(local_table.failed) == len(Bs)


def test_garbage_log_and_unfitted_runs(logs: dict[str, Path]) -> None:
    table = compare_runs([logs["garbage"], logs["empty"], logs["real"]], [0.05], workers=1)
    rows = {r["log"]: r for r in table}
    assert rows["garbage.mcap"]["status"] == "error"
    assert "garbage.mcap" in rows["garbage.mcap"]["error"]
    for name in ("empty.mcap", "real.mcap"):
        row = rows[name]
        assert row["status"] == "no-fit"
        assert row["error"].startswith("nothing fitted")
        assert (row["contacts"], row["primitives"], row["types"]) == (0, 0, "")
    assert rows["empty.mcap"]["truth_contacts"] == 0
    # a real log (no ground truth): every truth column is empty
    assert all(rows["real.mcap"][c] is None for c in
               ("truth_contacts", "matched", "link_accuracy", "class_accuracy",
                "surfaces_touched", "surfaces_found", "surfaces_missed"))
    assert [r["log"] for r in table.failed] == ["garbage.mcap"]


def test_task_is_a_plain_picklable_row(logs: dict[str, Path]) -> None:
    import pickle

    row = comparison_row(str(logs["empty"]), 0.05, {"reconstruct": {"causal": True}})
    assert pickle.loads(pickle.dumps(row)) == row
    assert all(v is None or isinstance(v, str | int | float) for v in row.values())
    assert comparison_row(str(logs["empty"]), 0.05, {"reconstruct": {"bogus": 1}}
                          )["error"].startswith("TypeError")


def test_local_processes_equal_in_process(logs: dict[str, Path]) -> None:
    paths = [logs["empty"], logs["missing"], logs["real"]]
    serial = compare_runs(paths, [0.05, 0.1], workers=1)
    parallel = compare_runs(paths, [0.1, 0.05], workers=2)
    assert serial.results() == parallel.results()


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"paths": [], "Bs": [0.02]}, "no logs"),
    ({"paths": ["x.mcap"], "Bs": []}, "no B values"),
    ({"paths": ["x.mcap"], "Bs": [0.0]}, "B must be a positive length .* 0.0"),
    ({"paths": ["x.mcap"], "Bs": [float("nan")]}, "B must be a positive length"),
    ({"paths": ["x.mcap"], "Bs": ["wide"]}, "B values must be numbers"),
    ({"paths": ["x.mcap"], "Bs": [0.02], "workers": 0}, "workers must be a positive"),
    ({"paths": ["x.mcap"], "Bs": [0.02], "scheduler": 42}, "scheduler must be an address"),
])
def test_invalid_input(kwargs: dict, match: str) -> None:
    with pytest.raises(InputError, match=match):
        compare_runs(**kwargs)


def test_outputs_written(local_table: ComparisonTable, tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    paths = write_comparison(out, local_table)
    assert sorted(p.name for p in out.iterdir()) == sorted(OUTPUT_NAMES)  # no temp files left
    with open(paths["csv"], newline="") as handle:
        rows = list(csv.reader(handle))
    assert tuple(rows[0]) == local_table.columns
    assert len(rows) == 1 + len(local_table)
    col = rows[0].index
    for cells, row in zip(rows[1:], local_table, strict=True):
        assert (cells[col("log")], float(cells[col("B")])) == (row["log"], row["B"])
        assert cells[col("status")] == row["status"]
        if row["contacts"] is not None:
            assert int(cells[col("contacts")]) == row["contacts"]
        else:
            assert cells[col("contacts")] == ""
    data = json.loads(paths["json"].read_text())
    assert data["format"] == "wholearm-comparison"
    assert data["rows"] == [{c: r.get(c) for c in local_table.columns} for r in local_table]
    pdf = paths["pdf"].read_bytes()
    assert pdf.startswith(b"%PDF")
    assert len(re.findall(rb"/Type\s*/Page[^s]", pdf)) == 2


def test_text_table_has_one_line_per_row(local_table: ComparisonTable) -> None:
    lines = local_table.to_text().splitlines()
    assert len(lines) == 1 + len(local_table)
    assert lines[0].split()[:3] == ["log", "B", "[m]"]
    for line, row in zip(lines[1:], local_table, strict=True):
        assert line.startswith(row["log"])
        assert f"{row['B']:g}" in line


def test_outputs_refuse_missing_parent_atomically(local_table: ComparisonTable,
                                                  tmp_path: Path) -> None:
    target = tmp_path / "file"
    target.write_text("x")
    with pytest.raises(OSError, match="file"):
        write_comparison(target / "sub", local_table)
    assert np.all([p.name == "file" for p in tmp_path.iterdir()])
