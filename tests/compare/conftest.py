"""Shared inputs: two short simulated lab_circle runs and their local comparison."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

#: B values compared in the tests (the larger the B, the cheaper the classification)
BS = (0.02, 0.05)


@pytest.fixture(scope="session")
def Bs() -> tuple[float, ...]:  # noqa: N802 - B is the paper's name
    return BS


@pytest.fixture(scope="session")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Logs in a fresh folder: ``a``/``b`` (8 s of arm time each, with ground truth),
    ``empty`` (1 s, no contact, with truth), ``real`` (same 1 s without truth), ``garbage``
    (not an MCAP file) and ``missing`` (does not exist)."""
    from wholearm_tools.logs import write_run
    from wholearm_tools.sim.scenarios import load_scenario

    folder = tmp_path_factory.mktemp("compare_logs")
    scenario = load_scenario("lab_circle")
    out = {"a": folder / "circle_a.mcap", "b": folder / "circle_b.mcap",
           "empty": folder / "empty.mcap", "real": folder / "real.mcap",
           "garbage": folder / "garbage.mcap", "missing": folder / "missing.mcap"}
    write_run(out["a"], scenario.simulate(seed=1, duration=8).run)
    write_run(out["b"], scenario.simulate(seed=6, duration=8).run)
    short = scenario.simulate(seed=1, duration=1).run
    write_run(out["empty"], short)
    write_run(out["real"], replace(short, truth=None))
    out["garbage"].write_bytes(b"this is not an mcap file\n" * 10)
    return out


@pytest.fixture(scope="session")
def local_table(logs: dict[str, Path]):
    """Comparison of b, missing, a (in that order, a duplicate too) over BS on 2 processes."""
    from wholearm_tools.compare import compare_runs

    paths = [logs["b"], logs["missing"], logs["a"], logs["b"]]
    return compare_runs(paths, list(reversed(BS)), workers=2)
