"""``wholearm reconstruct RUN.mcap --B 0.02 -o out/``: contacts, classification and fitted map."""

from __future__ import annotations

import json
from pathlib import Path

import click

from cli.options import (
    B_option,
    RigOptions,
    causal_option,
    command_topic_option,
    fit_workers_option,
    joint_topic_option,
    json_option,
    loss_option,
    overwrite_option,
    prepare_output_dir,
    rig_options,
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


@click.command("reconstruct")
@click.argument("run", type=click.Path(exists=True, path_type=Path))
@B_option()
@click.option("-o", "--output", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              required=True, help="Output folder (map.json, contacts.csv).")
@causal_option
@loss_option
@rig_options
@joint_topic_option
@command_topic_option
@fit_workers_option
@json_option
@overwrite_option
def command(run: Path, B: float, out_dir: Path, causal: bool, loss: str, rig: RigOptions,
            joint_topic: str | None, command_topic: str | None, workers: int | None,
            as_json: bool, overwrite: bool) -> None:
    """Reconstruct the environment of RUN: detect, classify with B, fit primitives."""
    from wholearm_tools.logs import read_run
    from wholearm_tools.outputs import write_reconstruction
    from wholearm_tools.pipeline import reconstruct

    prepare_output_dir(out_dir, ["map.json", "contacts.csv"], overwrite)
    data = read_run(run, joint_topic=joint_topic, command_topic=command_topic,
                    require_commands=True, **rig.read_kwargs())
    rec = reconstruct(data, B=B, causal=causal, loss=loss, workers=workers)
    if not rec.surface_map.primitives:
        reason = "; ".join(rec.messages) or "no primitive explains the contacts"
        raise click.ClickException(f"{run}: nothing could be fitted ({reason})")
    paths = write_reconstruction(out_dir, rec)
    if as_json:
        click.echo(json.dumps({"map": str(paths["map"]), "contacts": str(paths["contacts"]),
                               **rec.surface_map.to_json()}))
        return
    for line in summary_lines(rec):
        click.echo(line)
    click.echo(f"wrote {paths['map']} and {paths['contacts']}")
