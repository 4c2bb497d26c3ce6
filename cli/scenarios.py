"""``wholearm scenarios``: list the bundled simulation scenarios."""

from __future__ import annotations

import json

import click

from cli.options import json_option


@click.command("scenarios")
@json_option
def command(as_json: bool) -> None:
    """List bundled scenarios: name, joints, planar, surfaces, description."""
    from wholearm_tools.sim.scenarios import list_scenarios, load_scenario

    rows = [load_scenario(name).summary() for name in list_scenarios()]
    if as_json:
        click.echo(json.dumps(rows, indent=2))
        return
    if not rows:
        click.echo("no scenarios found")
        return
    width = max(len(r["name"]) for r in rows)
    for r in rows:
        kind = "planar" if r["planar"] else "spatial"
        surfaces = ", ".join(r["surfaces"])
        click.echo(f"{r['name']:<{width}}  {r['dof']} dof {kind:<7}  {surfaces}")
        click.echo(f"{'':<{width}}  {r['description']}")
