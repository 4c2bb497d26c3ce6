"""Package-level promises: a fast import with lazy entry points, and a working console script."""

from __future__ import annotations

import subprocess
import sys

from click.testing import CliRunner

from cli.main import cli


def test_import_does_not_load_heavy_libraries() -> None:
    code = ("import sys, wholearm_tools; heavy = {'casadi', 'open3d', 'pyvista', 'matplotlib', "
            "'mcap'} & set(sys.modules); print(sorted(heavy))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_lazy_entry_points_resolve() -> None:
    import wholearm_tools as wt
    from wholearm_tools.pipeline import reconstruct

    assert wt.reconstruct is reconstruct
    assert callable(wt.read_run)


def test_every_command_has_help() -> None:
    runner = CliRunner()
    result = runner.invoke(cli, ["--help"])
    assert result.exit_code == 0
    for name in ("simulate", "inspect", "scenarios", "contacts", "plot-ptip", "reconstruct", "fit",
                 "export", "report", "compare", "demo"):
        assert name in result.output
        sub = runner.invoke(cli, [name, "--help"])
        assert sub.exit_code == 0, (name, sub.output)
