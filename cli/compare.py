"""``wholearm compare a.mcap [b.mcap ...] --B 0.005 --B 0.02 -o cmp/``: reconstruct every log with
every B and tabulate the results side by side (comparison.csv, .json, .pdf)."""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

import click

from cli.options import (
    DEFAULT_B,
    InputPath,
    PositiveLength,
    RigOptions,
    causal_option,
    command_topic_option,
    joint_topic_option,
    json_option,
    loss_option,
    overwrite_option,
    prepare_output_dir,
    progress_enabled,
    result,
    rig_options,
    status,
)

log = logging.getLogger(__name__)


@click.command("compare")
@click.argument("logs", nargs=-1, required=True, type=InputPath())
@click.option("--B", "Bs", type=PositiveLength(), multiple=True,
              default=(DEFAULT_B,), show_default=True,
              help="Smallest expected surface curvature radius B [m] (repeat for each value "
                   "to compare).")
@click.option("-o", "--output", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              required=True, help="Output folder (comparison.csv, .json, .pdf).")
@click.option("--scheduler", default=None, metavar="ADDRESS",
              help="Dask scheduler address (tcp://host:port); default: local processes.")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="Local worker processes (default: one per core, at most one per run).")
@causal_option
@loss_option
@rig_options
@joint_topic_option
@command_topic_option
@json_option
@overwrite_option
def command(logs: tuple[Path, ...], Bs: tuple[float, ...], out_dir: Path,
            scheduler: str | None, workers: int | None, causal: bool, loss: str,
            rig: RigOptions, joint_topic: str | None, command_topic: str | None,
            as_json: bool, overwrite: bool) -> None:
    """Reconstruct every LOG with every --B value and compare the results.

    Prints the table (or JSON with --json); a (log, B) pair that fails shows its error in the
    table, and the command then exits with status 1 after writing the outputs.
    """
    from wholearm_tools.compare import OUTPUT_NAMES, compare_runs, write_comparison
    from wholearm_tools.errors import WholearmError

    prepare_output_dir(out_dir, list(OUTPUT_NAMES), overwrite)
    read_options = {"joint_topic": joint_topic, "command_topic": command_topic,
                    "require_commands": True, **rig.read_kwargs(maps=True)}
    learned = rig.learning()
    pairs = len({p.resolve() for p in logs}) * len(set(Bs))
    try:
        if progress_enabled():
            with click.progressbar(length=pairs, label=f"reconstructing {pairs} (log, B) pairs",
                                   file=sys.stderr) as bar:
                table = compare_runs(logs, Bs, scheduler=scheduler, workers=workers,
                                     read_options=read_options, causal=causal, loss=loss,
                                     progress=lambda done, total: bar.update(1), **learned)
        else:
            def progress(done: int, total: int) -> None:
                log.info("%d of %d (log, B) pairs reconstructed", done, total)

            table = compare_runs(logs, Bs, scheduler=scheduler, workers=workers,
                                 read_options=read_options, causal=causal, loss=loss,
                                 progress=progress, **learned)
        paths = write_comparison(out_dir, table)
    except WholearmError as exc:  # one line, however the command is mounted
        raise click.ClickException(str(exc)) from None
    if as_json:
        result(json.dumps({"outputs": {k: str(v) for k, v in paths.items()},
                           **table.to_json()}))
    else:
        result(table.to_text())
        status(f"wrote {paths['csv']}, {paths['json']} and {paths['pdf']}")
    failed = table.failed
    if failed:
        first = failed[0]
        raise click.ClickException(
            f"{len(failed)} of {len(table)} runs failed; first: {first['log']} "
            f"B={first['B']:g}: {first['error']}")
