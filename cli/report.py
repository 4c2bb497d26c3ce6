"""``wholearm report OUT/`` or ``wholearm report RUN.mcap -o report.pdf``: the PDF report.

With an output folder of ``wholearm reconstruct`` or ``wholearm fit`` (or its map.json): the
report is rendered again from the files there (map.json, contacts.csv, report_data.json) with
the parameters they record — no log, no refitting; paths inside are relative to the folder, so
it works from anywhere.  Default output: ``OUT/report.pdf``.

With a log (MCAP, or a bag): read → reconstruct with ``--B``/``--loss``/``--causal`` → report.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from cli.options import (
    DEFAULT_B,
    InputPath,
    PositiveLength,
    RigOptions,
    causal_option,
    check_output_file,
    command_topic_option,
    joint_topic_option,
    json_option,
    loss_option,
    overwrite_option,
    result,
    rig_options,
    stage,
    status,
)

#: options that only apply to a log (an output folder records what it was made with)
_LOG_OPTIONS = (("B", "--B"), ("causal", "--causal"), ("loss", "--loss"),
                ("robot_file", "--robot"), ("base_link", "--base-link"),
                ("tip_link", "--tip-link"), ("package_paths", "--package-path"),
                ("effort", "--effort"), ("stiffness", "--stiffness"),
                ("joint_topic", "--joint-topic"), ("command_topic", "--command-topic"))


def _is_output_folder(path: Path) -> bool:
    """A map.json, or a folder that is not a rosbag2 bag (bags hold metadata.yaml)."""
    if path.is_dir():
        return not (path / "metadata.yaml").is_file()
    return path.suffix.lower() == ".json"


@click.command("report")
@click.argument("run", type=InputPath())
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="PDF file to write (default for an output folder: OUT/report.pdf; "
                   "required for a log).")
@click.option("--B", "B", type=PositiveLength(), default=None,
              help=f"Smallest expected surface curvature radius B [m] for a log (default "
                   f"{DEFAULT_B}); an output folder uses the B it records.")
@click.option("--title", default=None, help="Title of page one.")
@causal_option
@loss_option
@rig_options
@joint_topic_option
@command_topic_option
@json_option
@overwrite_option
def command(run: Path, output: Path | None, B: float | None, title: str | None, causal: bool,
            loss: str, rig: RigOptions, joint_topic: str | None, command_topic: str | None,
            as_json: bool, overwrite: bool) -> None:
    """Write the PDF report of RUN: an output folder (or its map.json), rendered again from
    its files, or an MCAP log, reconstructed first."""
    from wholearm_tools.report import write_report
    from wholearm_tools.report.pdf import summary_lines

    ctx = click.get_current_context()
    if _is_output_folder(run):
        given = [flag for name, flag in _LOG_OPTIONS
                 if ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE]
        if given:
            raise click.UsageError(f"{', '.join(given)} apply to a log; {run} records the "
                                   "parameters it was made with (run `wholearm reconstruct` "
                                   "again to change them)")
        folder = run if run.is_dir() else run.parent
        output = folder / "report.pdf" if output is None else output
    elif output is None:
        raise click.UsageError("-o/--output is required for a log (the PDF file to write)")
    if output.suffix.lower() != ".pdf":
        raise click.BadParameter(f"expected a .pdf file name, got {output}",
                                 param_hint="-o/--output")
    check_output_file(output, overwrite)
    from wholearm_tools.errors import WholearmError

    try:
        if _is_output_folder(run):
            from wholearm_tools.report.data import load_report_data

            with stage(f"reading {run}"):
                data = load_report_data(run)
        else:
            data = _from_log(run, output, B=DEFAULT_B if B is None else B, causal=causal,
                             loss=loss, rig=rig, joint_topic=joint_topic,
                             command_topic=command_topic)
        with stage(f"writing {output}"):
            info = write_report(output, data, title=title)
    except WholearmError as exc:  # one line, however the command is mounted
        raise click.ClickException(str(exc)) from None
    if as_json:
        result(json.dumps({"input": str(run), "output": str(output),
                           "pages": int(info.n_pages)}))
        return
    for line in summary_lines(data, info.accuracy, info.junction):
        status(line)
    status(f"wrote {output} ({info.n_pages} pages)")


def _from_log(run: Path, output: Path, *, B: float, causal: bool, loss: str, rig: RigOptions,
              joint_topic: str | None, command_topic: str | None):
    """Reconstruct the log and return its report data, the input recorded relative to the
    PDF's folder."""
    from wholearm_tools.classify.swept import check_B
    from wholearm_tools.logs import read_run
    from wholearm_tools.outputs import map_with_provenance, reconstruction_parameters
    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.data import report_data_from_reconstruction, run_info

    with stage(f"reading {run}"):
        data = read_run(run, joint_topic=joint_topic, command_topic=command_topic,
                        require_commands=True, **rig.read_kwargs(maps=True))
    check_B(B, data.robot, what="--B")
    with stage(f"reconstructing with B = {B:g} m") as step:
        rec = reconstruct(data, B=B, causal=causal, loss=loss,
                          progress=step, **rig.learning())
    folder = output.parent if str(output.parent) else Path(".")
    sm = map_with_provenance(rec.surface_map, folder, run, "log", reconstruction_parameters(rec))
    record = sm.meta["input"]
    return report_data_from_reconstruction(
        rec, surface_map=sm, run=run_info(rec.run, source=record["path"],
                                          sha256=record["sha256"]))
