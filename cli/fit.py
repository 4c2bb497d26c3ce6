"""``wholearm fit contacts.csv -o map.json``: fit already-classified contacts.

Writes the map and, beside it, its report data (``report_data.json`` beside ``map.json``): the
fit's assignment of the contacts, so ``wholearm report`` renders the folder without refitting.
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from cli.options import (
    B_option,
    InputFile,
    check_output_file,
    json_option,
    loss_option,
    overwrite_option,
    result,
    stage,
    status,
)


def _known_kinds(ctx: click.Context, param: click.Parameter, value: tuple[str, ...]
                 ) -> tuple[str, ...]:
    """``--kind`` values must name registered primitive types (a usage error otherwise)."""
    if not value:
        return value
    from wholearm_tools.geometry import PRIMITIVE_TYPES

    unknown = [k for k in value if k not in PRIMITIVE_TYPES]
    if unknown:
        raise click.BadParameter(f"unknown primitive type {unknown[0]!r} (known: "
                                 f"{', '.join(sorted(PRIMITIVE_TYPES))})")
    return value


@click.command("fit")
@click.argument("contacts", type=InputFile())
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), required=True,
              help="map.json to write.")
@B_option()
@click.option("--kind", "kinds", multiple=True, callback=_known_kinds,
              help="Primitive types to consider (repeatable; default: all for the dimension).")
@loss_option
@json_option
@overwrite_option
def command(contacts: Path, output: Path, B: float, kinds: tuple[str, ...], loss: str,
            as_json: bool, overwrite: bool) -> None:
    """Fit-and-grow primitives to the contacts of CONTACTS (a contacts.csv)."""
    from wholearm_tools.contact_table import read_contact_table
    from wholearm_tools.outputs import write_fit
    from wholearm_tools.pipeline import fit_table

    check_output_file(output, overwrite)
    table = read_contact_table(contacts)
    with stage(f"fitting {len(table)} contacts"):
        surface_map, fits, fitted, messages = fit_table(
            table, planar=table.dim == 2, B=B, kinds=kinds or None, loss=loss,
            meta={"source": str(contacts)})
    if not surface_map.primitives:
        reason = "; ".join(messages) or "no primitive explains the contacts"
        raise click.ClickException(f"{contacts}: nothing could be fitted ({reason})")
    paths = write_fit(output, contacts, surface_map, fits, fitted, messages,
                      {"B": B, "loss": loss, "kinds": list(kinds) or None}, overwrite=overwrite)
    if as_json:
        from wholearm_tools.mapfile import read_map

        result(json.dumps({"outputs": {k: str(v) for k, v in paths.items()},
                           **read_map(paths["map"]).to_json()}))
        return
    for p in surface_map.primitives:
        status(f"#{p.id} {p.kind}: support tip {p.support['tip']} link {p.support['link']}, "
               f"rms {p.rms_residual * 1e3:.2f} mm")
    status(f"wrote {paths['map']} and {paths['report_data'].name} "
           f"(`wholearm report {paths['map'].parent}` renders its report)")
