"""``wholearm reconstruct RUN.mcap --B 0.02 -o out/``: contacts, classification, fitted map and
every deliverable of the run (map.json, contacts.csv, report_data.json, meshes, overlay.mcap,
report.pdf), written into the folder as a unit (``wholearm_tools.outputs``)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from cli.options import (
    B_option,
    InputPath,
    RigOptions,
    causal_option,
    command_topic_option,
    fit_workers_option,
    joint_topic_option,
    json_option,
    loss_option,
    overwrite_option,
    result,
    rig_options,
    stage,
    status,
)


def summary_lines(rec) -> list[str]:
    """Human-readable summary of a reconstruction (also used by the demo)."""
    m = rec.surface_map
    c = m.contacts
    lines = [f"contacts: {c.get('count', 0)} (tip {c.get('tip', 0)}, link {c.get('link', 0)}, "
             f"ambiguous {c.get('ambiguous', 0)}, unexplained {c.get('unexplained', 0)}); "
             f"B = {m.B:g} m"]
    if "tip_map" in c:
        lines.append(f"  refined by the fitted map: tip {c['tip_map']}, link {c['link_map']}, "
                     f"ambiguous {c['ambiguous_map']}")
    for p in m.primitives:
        size = {k: v for k, v in p.params.items() if k in ("radius", "major_radius",
                                                            "minor_radius", "half_angle")}
        sizes = ", ".join(f"{k} {float(v):.4g}" for k, v in size.items())
        lines.append(f"  #{p.id} {p.kind:<8} {sizes:<28} support tip {p.support['tip']:>3} "
                     f"link {p.support['link']:>3}  rms {p.rms_residual * 1e3:.2f} mm")
    lines.extend(f"note: {msg}" for msg in rec.messages)
    t = rec.timings
    lines.append("time: " + ", ".join(f"{k} {v:.2f} s" for k, v in t.items()))
    return lines


def output_choice_options(func):
    """``--no-meshes``, ``--mesh-format``, ``--no-overlay``, ``--no-report``: which outputs of
    the set to write (map.json, contacts.csv and report_data.json always are)."""
    from wholearm_tools.outputs import DEFAULT_MESH_FORMATS, MESH_FORMATS

    for option in reversed([
        click.option("--mesh-format", "mesh_formats", multiple=True,
                     type=click.Choice(MESH_FORMATS, case_sensitive=False),
                     help="Mesh format to write (repeatable; default: "
                          f"{', '.join(DEFAULT_MESH_FORMATS)})."),
        click.option("--no-meshes", is_flag=True, help="Write no mesh files."),
        click.option("--no-overlay", is_flag=True, help="Do not write overlay.mcap."),
        click.option("--no-report", is_flag=True, help="Do not write report.pdf "
                     "(`wholearm report OUT/` renders it later from the folder)."),
    ]):
        func = option(func)
    return func


def chosen_meshes(mesh_formats: tuple[str, ...], no_meshes: bool) -> tuple[str, ...]:
    from wholearm_tools.outputs import DEFAULT_MESH_FORMATS

    if no_meshes:
        if mesh_formats:
            raise click.UsageError("--no-meshes and --mesh-format exclude each other")
        return ()
    return tuple(f.lower() for f in mesh_formats) or DEFAULT_MESH_FORMATS


@click.command("reconstruct")
@click.argument("run", type=InputPath())
@B_option()
@click.option("-o", "--output", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              required=True, help="Output folder (map.json, contacts.csv, report_data.json, "
              "meshes, overlay.mcap, report.pdf).")
@causal_option
@loss_option
@rig_options
@joint_topic_option
@command_topic_option
@fit_workers_option
@output_choice_options
@json_option
@overwrite_option
def command(run: Path, B: float, out_dir: Path, causal: bool, loss: str, rig: RigOptions,
            joint_topic: str | None, command_topic: str | None, workers: int | None,
            mesh_formats: tuple[str, ...], no_meshes: bool, no_overlay: bool, no_report: bool,
            as_json: bool, overwrite: bool) -> None:
    """Reconstruct the environment of RUN: detect, classify with B, fit primitives; write
    every output of the run into the folder (--overwrite replaces a previous set whole)."""
    import logging

    from wholearm_tools.classify.swept import check_B
    from wholearm_tools.logs import read_run
    from wholearm_tools.outputs import OutputSet, reconstruction_names, write_outputs
    from wholearm_tools.pipeline import reconstruct

    log = logging.getLogger("wholearm.reconstruct")
    meshes = chosen_meshes(mesh_formats, no_meshes)
    with OutputSet(out_dir, reconstruction_names(), overwrite=overwrite) as out:
        with stage(f"reading {run}"):
            data = read_run(run, joint_topic=joint_topic, command_topic=command_topic,
                            require_commands=True, **rig.read_kwargs(maps=True))
        check_B(B, data.robot, what="--B")
        with stage(f"reconstructing with B = {B:g} m") as step:
            rec = reconstruct(data, B=B, causal=causal, loss=loss, workers=workers,
                              progress=step, **rig.learning())
        if not rec.surface_map.primitives:
            reason = "; ".join(rec.messages) or "no primitive explains the contacts"
            raise click.ClickException(f"{run}: nothing could be fitted ({reason})")
        with stage("writing the outputs"):
            paths = write_outputs(out, rec, input_path=run, meshes=meshes,
                                  overlay=not no_overlay, report=not no_report,
                                  progress=log.info)
    if as_json:
        result(json.dumps({"outputs": {k: str(v) for k, v in paths.items()},
                           "map": str(paths["map"]), "contacts": str(paths["contacts"]),
                           **rec.surface_map.to_json()}))
        return
    for line in summary_lines(rec):
        status(line)
    status(f"wrote {out_dir}/: " + ", ".join(p.name for p in paths.values()))
