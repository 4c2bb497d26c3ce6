"""``wholearm simulate``: simulate a scenario and write the run as MCAP."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import click

from cli.options import check_output_file, overwrite_option, progress_enabled


@click.command("simulate")
@click.argument("scenario")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="MCAP file to write.")
@click.option("--seed", type=int, default=None, help="Random seed (default: the scenario's).")
@click.option("--rate", type=click.FloatRange(min=1.0), default=None,
              help="Log rate in Hz (default: the scenario's, usually 500).")
@click.option("--duration", type=click.FloatRange(min=0.0, min_open=True), default=None,
              help="Arm time to simulate in seconds (default: the scenario's).")
@click.option("--strategy", type=str, default=None,
              help="Exploration strategy: random, sweep or novelty (default: the scenario's).")
@click.option("--profile", type=click.Choice(["ros2", "json"]), default="ros2",
              show_default=True, help="MCAP message encoding.")
@overwrite_option
def command(scenario: str, output: Path, seed: int | None, rate: float | None,
            duration: float | None, strategy: str | None, profile: str,
            overwrite: bool) -> None:
    """Simulate SCENARIO (a bundled name or a YAML path) and write the run to OUTPUT."""
    from wholearm_tools.logs import write_run
    from wholearm_tools.sim.scenarios import load_scenario
    from wholearm_tools.sim.strategies import STRATEGIES

    check_output_file(output, overwrite)
    folder = output.parent if str(output.parent) else Path(".")
    if not folder.is_dir():
        raise click.ClickException(f"{output}: output folder {folder} does not exist")
    if strategy is not None and strategy not in STRATEGIES:
        raise click.ClickException(
            f"unknown strategy {strategy!r} (known: {', '.join(sorted(STRATEGIES))})")
    sc = load_scenario(scenario)
    wall0 = time.perf_counter()
    total = sc.duration if duration is None else duration
    if progress_enabled():
        with click.progressbar(length=1000, label=f"simulating {sc.name}",
                               file=sys.stderr) as bar:
            done = [0]

            def progress(t: float, _total: float) -> None:
                pos = int(1000 * min(t / total, 1.0))
                bar.update(pos - done[0])
                done[0] = pos

            result = sc.simulate(seed=seed, duration=duration, rate=rate, strategy=strategy,
                                 progress=progress)
    else:
        result = sc.simulate(seed=seed, duration=duration, rate=rate, strategy=strategy)
    write_run(output, result.run, profile=profile)
    wall = time.perf_counter() - wall0
    counts = result.contact_counts()
    log = result.run.log
    click.echo(
        f"{sc.name}: simulated {log.duration:.1f} s at {log.rate:.0f} Hz ({log.n_samples} samples,"
        f" {len(result.moves)} moves) with strategy {result.truth.meta['strategy']} and seed "
        f"{result.truth.meta['seed']}; {result.truth.n_contacts} contacts (tip {counts['tip']}, "
        f"joint {counts['joint']}, body {counts['body']}) on "
        f"{len(set(result.truth.contact_surface.tolist()))} of {len(result.truth.surfaces)} "
        f"surfaces; wrote {output} ({profile}) in {wall:.1f} s wall time.")
