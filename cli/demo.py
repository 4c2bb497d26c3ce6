"""``wholearm demo``: the whole job on the bundled well junction.

simulate ``well_junction`` (kinematic engine, or ``--engine physics``) → write the run as
MCAP → read it back as a real log would be → reconstruct → every output of ``wholearm
reconstruct`` (map.json, contacts.csv, report_data.json, meshes, overlay.mcap, report.pdf)
beside the run.  The demo owns its output folder (default ``reports/demo``) and replaces what
it wrote before, as a unit (``wholearm_tools.outputs``).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from cli.options import PositiveLength, json_option, result, status
from cli.reconstruct import summary_lines

RUN_NAME = "run.mcap"


def _step(message: str) -> float:
    status(f"• {message}")
    return time.perf_counter()


@click.command("demo")
@click.option("-o", "--output", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              default=Path("reports/demo"), show_default=True, help="Output folder.")
@click.option("--scenario", default="well_junction", show_default=True,
              help="Bundled scenario to simulate.")
@click.option("--seed", type=int, default=None, help="Simulation seed (default: the scenario's).")
@click.option("--duration", type=click.FloatRange(min=0.0, min_open=True, max=3600.0),
              default=None, help="Arm time to simulate [s] (default: the scenario's).")
@click.option("--B", "B", type=PositiveLength(), default=None,
              help="B [m] (default: the scenario's B hint, else 0.02).")
@click.option("--engine", type=click.Choice(["kinematic", "physics"]), default="kinematic",
              show_default=True,
              help="kinematic: idealised rigid stops; physics: MuJoCo with the scenario's "
                   "friction, soft contacts, joint friction and torque-limited PD control "
                   "(the closer stand-in for a rig's log).")
@json_option
def command(out_dir: Path, scenario: str, seed: int | None, duration: float | None,
            B: float | None, engine: str, as_json: bool) -> None:
    """Run the whole pipeline on a simulated run and write every deliverable."""
    from wholearm_tools.logs import read_run, write_run
    from wholearm_tools.outputs import OutputSet, reconstruction_names, write_outputs
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.sim import load_scenario

    start = time.perf_counter()
    sc = load_scenario(scenario)
    with OutputSet(out_dir, reconstruction_names({RUN_NAME}), overwrite=True) as out:
        run_path = out.path(RUN_NAME)
        t = _step(f"simulating {sc.name} ({sc.duration if duration is None else duration:g} s "
                  f"of arm time, {engine} engine)")
        sim = sc.simulate(seed=seed, duration=duration, engine=engine)
        write_run(run_path, sim.run)
        status(f"  {sim.run.log.n_samples} samples, {sim.truth.n_contacts} true contacts "
               f"({time.perf_counter() - t:.1f} s)")

        B = float(B if B is not None else sc.hints.get("B", 0.02))
        t = _step(f"reconstructing from {out.final(RUN_NAME)} with B = {B:g} m")
        rec = reconstruct(read_run(run_path, require_commands=True), B=B)
        if not rec.surface_map.primitives:
            raise click.ClickException(f"{out.final(RUN_NAME)}: nothing could be fitted "
                                       f"({'; '.join(rec.messages) or 'no primitive found'})")
        status(f"  ({time.perf_counter() - t:.1f} s)")
        t = _step("writing map.json, contacts.csv, meshes, overlay and the PDF report")
        paths = write_outputs(out, rec, input_path=run_path)
        status(f"  ({time.perf_counter() - t:.1f} s)")

    if as_json:
        result(json.dumps({"outputs": {"run": str(out.final(RUN_NAME)),
                                       **{k: str(v) for k, v in paths.items()}},
                           **rec.surface_map.to_json()}))
        return
    for line in summary_lines(rec):
        status(line)
    status(f"\noutputs in {out_dir}/ (total {time.perf_counter() - start:.0f} s):")
    status(f"  {'run log':<12} {out.final(RUN_NAME)}")
    for key, path in paths.items():
        status(f"  {key:<12} {path}")
