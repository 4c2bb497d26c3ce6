"""The main job end to end on a short planar run: every deliverable is written and readable."""

from __future__ import annotations

from click.testing import CliRunner

from cli.main import cli
from wholearm_tools.logs import read_run
from wholearm_tools.mapfile import read_map


def test_demo_writes_every_deliverable(tmp_path) -> None:
    out = tmp_path / "demo"
    result = CliRunner().invoke(cli, ["demo", "-o", str(out), "--scenario", "lab_circle",
                                      "--duration", "60"])
    assert result.exit_code == 0, result.output
    for name in ("run.mcap", "map.json", "contacts.csv", "report_data.json", "map.ply",
                 "map.stl", "map.obj", "map.glb", "map.vtp", "overlay.mcap", "report.pdf"):
        assert (out / name).stat().st_size > 0, name
    assert (out / "report.pdf").read_bytes().startswith(b"%PDF")
    surface_map = read_map(out / "map.json")
    assert surface_map.planar
    assert surface_map.primitives, "the demo map has no primitive"
    run = read_run(out / "run.mcap")
    assert run.truth is not None
    assert run.truth.n_contacts > 0
    assert "outputs in" in result.output
    assert not list(out.glob(".*")), "temporary files left behind"
    assert not list(tmp_path.glob(".*")), "staging folder left behind"
    assert read_map(out / "map.json").meta["input"]["path"] == "run.mcap"


def test_demo_on_the_physics_engine_reconstructs_its_surfaces(tmp_path) -> None:
    """The whole job on a MuJoCo run (friction, soft contacts, joint friction): the map holds
    the scenario's surfaces, sized within their stated intervals."""
    out = tmp_path / "demo"
    result = CliRunner().invoke(cli, ["demo", "-o", str(out), "--scenario", "lab_circle",
                                      "--duration", "60", "--engine", "physics"])
    assert result.exit_code == 0, result.output
    assert "physics engine" in result.output
    surface_map = read_map(out / "map.json")
    run = read_run(out / "run.mcap")
    assert run.truth.meta["engine"] == "physics"
    true_radius = {float(s["params"]["radius"]) for s in run.truth.surfaces
                   if s["type"] == "circle"}
    circles = [p for p in surface_map.primitives if p.kind == "circle"]
    assert circles, "the post was not reconstructed"
    for c in circles:
        r, half = float(c.params["radius"]), float(c.ci95["radius"])
        assert min(abs(r - t) for t in true_radius) <= max(half, 0.01 * r)
