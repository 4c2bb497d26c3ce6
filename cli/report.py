"""``wholearm report RUN.mcap|OUT_DIR -o report.pdf``: the PDF accuracy report of a run.

With an MCAP log: read → reconstruct with ``--B`` → report.  With the output folder of
``wholearm reconstruct`` (``map.json``): the run recorded in the map's ``meta.source`` is read
and reconstructed again with the map's B and classification mode (``--B`` overrides B); the report
needs the run itself (contacts over time, P_T replay, ground truth), not only the map.
"""

from __future__ import annotations

from pathlib import Path

import click

from cli.options import (
    RigOptions,
    check_output_file,
    command_topic_option,
    joint_topic_option,
    overwrite_option,
    rig_options,
)

#: B used for an MCAP log when --B is not given [m]
DEFAULT_B = 0.02


def run_from_output_dir(out_dir: Path) -> tuple[Path, float, bool]:
    """``(run path, B, causal)`` recorded in ``out_dir/map.json``; ClickException otherwise."""
    from wholearm_tools.errors import InputError
    from wholearm_tools.mapfile import read_map

    map_path = out_dir / "map.json"
    if not map_path.is_file():
        raise click.ClickException(f"{out_dir}: no map.json (expected an MCAP log or the output "
                                   "folder of `wholearm reconstruct`)")
    try:
        surface_map = read_map(map_path)
    except InputError as exc:
        raise click.ClickException(str(exc)) from None
    source = surface_map.meta.get("source")
    if not source or str(source).startswith("<"):
        raise click.ClickException(f"{map_path}: records no run log (meta.source); run "
                                   "`wholearm report RUN.mcap -o report.pdf` on the log instead")
    candidates = [Path(str(source))]
    if not candidates[0].is_absolute():
        candidates.append(out_dir / candidates[0])
    for path in candidates:
        if path.is_file():
            return path, float(surface_map.B), bool(surface_map.meta.get("causal", False))
    raise click.ClickException(f"{map_path}: the recorded run log {source} was not found; run "
                               "`wholearm report RUN.mcap -o report.pdf` on the log instead")


@click.command("report")
@click.argument("run", type=click.Path(exists=True, path_type=Path))
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="PDF file to write.")
@click.option("--B", "B", type=click.FloatRange(min=0.0, min_open=True), default=None,
              help=f"Smallest expected surface curvature radius B [m] (default: {DEFAULT_B} for "
                   "a log, the map's B for an output folder).")
@click.option("--title", default=None, help="Title of page one.")
@rig_options
@joint_topic_option
@command_topic_option
@overwrite_option
def command(run: Path, output: Path, B: float | None, title: str | None,
            rig: RigOptions, joint_topic: str | None, command_topic: str | None,
            overwrite: bool) -> None:
    """Write the PDF report of RUN (an MCAP log or a `wholearm reconstruct` output folder)."""
    from wholearm_tools.logs import read_run
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report import write_report
    from wholearm_tools.report.pdf import summary_lines

    check_output_file(output, overwrite)
    if output.suffix.lower() != ".pdf":
        raise click.BadParameter(f"expected a .pdf file name, got {output}",
                                 param_hint="-o/--output")
    causal = False
    if run.is_dir():
        log_path, map_B, causal = run_from_output_dir(run)
        B = map_B if B is None else B
    else:
        log_path = run
        B = DEFAULT_B if B is None else B
    data = read_run(log_path, joint_topic=joint_topic, command_topic=command_topic,
                    require_commands=True, **rig.read_kwargs())
    rec = reconstruct(data, B=B, causal=causal)
    info = write_report(output, rec, title=title)
    for line in summary_lines(rec, info.accuracy, info.junction):
        click.echo(line)
    click.echo(f"wrote {output} ({info.n_pages} pages)", err=True)
