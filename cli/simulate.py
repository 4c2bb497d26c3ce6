"""``wholearm simulate``: simulate a scenario and write the run as MCAP."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import click

from cli.options import (
    check_output_file,
    json_option,
    overwrite_option,
    progress_enabled,
    result,
    status,
)

#: most log samples (rate x duration) one simulated run may hold: a run is held in memory
#: several times over while it is simulated and written (2 million samples of a 7-joint arm
#: are about 1 GB at the peak)
MAX_SAMPLES = 2_000_000
#: largest scenario file read [bytes]
MAX_SCENARIO_BYTES = 16 * 2**20

#: CLI physics option → ``Physics`` field it sets
_PHYSICS_OPTIONS = {
    "friction": "friction",
    "joint_friction": "joint_friction",
    "gravity": "gravity",
    "contact_timeconst": "contact_timeconst",
    "contact_dampratio": "contact_dampratio",
    "physics_rate": "rate",
    "joint_compliance": "joint_compliance",
    "joint_backlash": "joint_backlash",
    "log_jitter": "log_jitter",
    "log_drop": "log_drop",
}


def _scenario_source(scenario: str) -> None:
    """A scenario given as a file must exist as a bounded regular UTF-8 file (not a FIFO or a
    device): otherwise a usage error, like any missing input file.  Bundled names are left
    to the loader."""
    from wholearm_tools._io import check_input_file, read_text_input
    from wholearm_tools.errors import ScenarioError

    path = Path(scenario)
    if scenario.endswith((".yaml", ".yml")) or path.exists():
        if not path.exists():
            raise click.BadParameter(f"File {scenario!r} does not exist.",
                                     param_hint="'SCENARIO'")
        try:
            check_input_file(path, "scenario", max_bytes=MAX_SCENARIO_BYTES, error=ScenarioError)
        except ScenarioError as exc:
            raise click.BadParameter(str(exc), param_hint="'SCENARIO'") from None
        read_text_input(path, "scenario", max_bytes=MAX_SCENARIO_BYTES, error=ScenarioError)


@click.command("simulate")
@click.argument("scenario")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="MCAP file to write.")
@click.option("--seed", type=int, default=None, help="Random seed (default: the scenario's).")
@click.option("--rate", type=click.FloatRange(min=1.0, max=100_000.0), default=None,
              help="Log rate in Hz (default: the scenario's, usually 500).")
@click.option("--duration", type=click.FloatRange(min=0.0, min_open=True, max=86_400.0),
              default=None, help="Arm time to simulate in seconds (default: the scenario's).")
@click.option("--strategy", type=str, default=None,
              help="Exploration strategy: random, sweep or novelty (default: the scenario's).")
@click.option("--profile", type=click.Choice(["ros2", "json"]), default="ros2",
              show_default=True, help="MCAP message encoding.")
@click.option("--engine", type=click.Choice(["kinematic", "physics"]), default="kinematic",
              show_default=True,
              help="kinematic: idealised rigid stops; physics: MuJoCo with friction, soft "
                   "contacts, joint friction and a torque-limited PD controller.")
@click.option("--friction", type=click.FloatRange(min=0.0), default=None,
              help="[physics] Coulomb friction arm-environment (default: the scenario's, 0.4).")
@click.option("--joint-friction", type=click.FloatRange(min=0.0, max=1.0, max_open=True),
              default=None,
              help="[physics] Coulomb joint friction as a fraction of the effort limit "
                   "(default: the scenario's, 0.02).")
@click.option("--gravity/--no-gravity", default=None,
              help="[physics] Gravity along -z, compensated by the controller (default: the "
                   "scenario's, off).")
@click.option("--contact-timeconst", type=click.FloatRange(min=0.0, min_open=True),
              default=None,
              help="[physics] Soft-contact time constant in s: stiffness (default: the "
                   "scenario's, 0.005).")
@click.option("--contact-dampratio", type=click.FloatRange(min=0.0, min_open=True),
              default=None,
              help="[physics] Soft-contact damping ratio; below 1 contacts rebound (default: "
                   "the scenario's, 0.7).")
@click.option("--physics-rate", type=click.FloatRange(min=1.0), default=None,
              help="[physics] Smallest physics rate in Hz (default: the scenario's, 1000).")
@click.option("--joint-compliance", type=click.FloatRange(min=0.0, max=0.1), default=None,
              help="[physics] Deflection of each joint's transmission at its effort limit in "
                   "rad, read by motor-side encoders (default: the scenario's, 0; harmonic "
                   "drives 0.0005-0.002).")
@click.option("--joint-backlash", type=click.FloatRange(min=0.0, max=0.1), default=None,
              help="[physics] Lost motion of each joint's transmission in rad, read by "
                   "motor-side encoders (default: the scenario's, 0; gearboxes 0.0003-0.004).")
@click.option("--log-jitter", type=click.FloatRange(min=0.0, max=0.5), default=None,
              help="[physics] A rig's log clock: relative standard deviation of each interval "
                   "between samples, stamped when taken (default: the scenario's, 0; real "
                   "rigs about 0.05).")
@click.option("--log-drop", type=click.FloatRange(min=0.0, max=0.5), default=None,
              help="[physics] Share of log samples lost (default: the scenario's, 0; real "
                   "rigs about 0.007).")
@click.option("--mjcf", "mjcf_file", type=click.Path(dir_okay=False, path_type=Path),
              default=None, help="[physics] Also write the MuJoCo scene (MJCF) to this file.")
@json_option
@overwrite_option
def command(scenario: str, output: Path, seed: int | None, rate: float | None,
            duration: float | None, strategy: str | None, profile: str, engine: str,
            mjcf_file: Path | None, as_json: bool, overwrite: bool,
            **physics_options: Any) -> None:
    """Simulate SCENARIO (a bundled name or a YAML path) and write the run to OUTPUT."""
    from wholearm_tools.logs import write_run
    from wholearm_tools.sim.scenarios import load_scenario
    from wholearm_tools.sim.strategies import STRATEGIES

    check_output_file(output, overwrite)
    if strategy is not None and strategy not in STRATEGIES:
        raise click.ClickException(
            f"unknown strategy {strategy!r} (known: {', '.join(sorted(STRATEGIES))})")
    given = {k: v for k, v in physics_options.items() if v is not None}
    if engine != "physics" and (given or mjcf_file is not None):
        names = [f"--{k.replace('_', '-')}" for k in given] + (["--mjcf"] if mjcf_file else [])
        raise click.ClickException(f"{', '.join(names)} apply to --engine physics only")
    if mjcf_file is not None:
        check_output_file(mjcf_file, overwrite)
    _scenario_source(scenario)
    sc = load_scenario(scenario)
    physics = sc.physics.replace(**{_PHYSICS_OPTIONS[k]: v for k, v in given.items()})
    total = sc.duration if duration is None else duration
    hz = sc.rate if rate is None else rate
    if hz * total > MAX_SAMPLES:
        raise click.BadParameter(
            f"{hz:g} Hz for {total:g} s is {hz * total:.3g} samples; at most {MAX_SAMPLES:,} "
            "per run (lower --rate or --duration)", param_hint="--rate/--duration")
    wall0 = time.perf_counter()
    run_args = {"seed": seed, "duration": duration, "rate": rate, "strategy": strategy,
                "engine": engine, "physics": physics}
    if progress_enabled():
        with click.progressbar(length=1000, label=f"simulating {sc.name} ({engine})",
                               file=sys.stderr) as bar:
            done = [0]

            def progress(t: float, _total: float) -> None:
                pos = int(1000 * min(t / total, 1.0))
                bar.update(pos - done[0])
                done[0] = pos

            sim = sc.simulate(progress=progress, **run_args)
    else:
        sim = sc.simulate(**run_args)
    write_run(output, sim.run, profile=profile)
    if mjcf_file is not None:
        from wholearm_tools._io import write_text_atomic

        write_text_atomic(mjcf_file, sim.stats["mjcf"])
    wall = time.perf_counter() - wall0
    counts = sim.contact_counts()
    log = sim.run.log
    truth = sim.truth
    stopped = ""
    if engine == "physics":
        stopped = f", {int(truth.contact_stopped.sum())} stopped the arm"
    surfaces = len(set(truth.contact_surface.tolist()))
    if as_json:
        result(json.dumps({
            "scenario": sc.name, "output": str(output), "profile": profile, "engine": engine,
            "duration_s": float(log.duration), "rate_hz": float(log.rate),
            "samples": int(log.n_samples), "moves": len(sim.moves),
            "strategy": str(truth.meta["strategy"]), "seed": int(truth.meta["seed"]),
            "contacts": int(truth.n_contacts),
            "contacts_by_kind": {k: int(v) for k, v in counts.items()},
            "surfaces_touched": surfaces, "surfaces": len(truth.surfaces),
            "wall_time_s": wall}))
        return
    status(
        f"{sc.name}: simulated {log.duration:.1f} s at {log.rate:.0f} Hz ({log.n_samples} samples,"
        f" {len(sim.moves)} moves) with the {engine} engine, strategy "
        f"{truth.meta['strategy']} and seed {truth.meta['seed']}; {truth.n_contacts} contacts "
        f"(tip {counts['tip']}, joint {counts['joint']}, body {counts['body']}{stopped}) on "
        f"{surfaces} of {len(truth.surfaces)} surfaces; wrote {output} ({profile}) in "
        f"{wall:.1f} s wall time.")
