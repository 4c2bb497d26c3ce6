"""``wholearm plot-ptip RUN.mcap --B 0.02 -o ptip.png``: P_T of every contact as the map grows.

The causal replay of the paper's Figure 4: each contact's tip probability is re-evaluated with
the swept map of the samples up to each time, so it starts at its causal value and drifts toward
0 or 1 as the robot explores around it.  Markers at the end show the offline value, coloured by
the true label when the log has ground truth (orange = tip/joint, blue = body).
"""

from __future__ import annotations

import json
from pathlib import Path

import click

from cli.options import (
    B_option,
    InputPath,
    RigOptions,
    check_output_file,
    command_topic_option,
    joint_topic_option,
    json_option,
    overwrite_option,
    result,
    rig_options,
    stage,
    status,
)


@click.command("plot-ptip")
@click.argument("run", type=InputPath())
@B_option()
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path),
              required=True, help="Image file (PNG, PDF or SVG by extension).")
@click.option("--steps", type=click.IntRange(2, 2000), default=200, show_default=True,
              help="Number of replay times.")
@rig_options
@joint_topic_option
@command_topic_option
@json_option
@overwrite_option
def command(run: Path, B: float, output: Path, steps: int, rig: RigOptions,
            joint_topic: str | None, command_topic: str | None, as_json: bool,
            overwrite: bool) -> None:
    """Plot every contact's tip probability over time (causal replay, Figure 4)."""
    import numpy as np

    from wholearm_tools._io import atomic_output
    from wholearm_tools.classify import ClassifyParams, swept_map, tip_probability_history
    from wholearm_tools.classify.swept import check_B
    from wholearm_tools.contacts import detect_contacts, match_events
    from wholearm_tools.logs import read_run

    check_output_file(output, overwrite)
    fmt = output.suffix.lstrip(".").lower() or "png"
    if fmt not in ("png", "pdf", "svg"):
        raise click.BadParameter(f"expected a .png, .pdf or .svg file name, got {output}",
                                 param_hint="-o/--output")
    with stage(f"reading {run}"):
        data = read_run(run, joint_topic=joint_topic, command_topic=command_topic,
                        require_commands=True, **rig.read_kwargs())
    check_B(B, data.robot, what="--B")
    with stage("detecting contacts"):
        contacts = detect_contacts(data.log, data.robot)
    with stage(f"replaying the swept map at {steps} times"):
        grid = swept_map(data.robot, data.robot.link_angles(data.log.q, data.log.tau_cmd), B=B)
        times = np.linspace(data.log.t[0], data.log.t[-1], steps)
        hist = tip_probability_history(data, contacts, B, times, grid=grid)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    truth_tip = None
    if data.truth is not None and len(contacts):
        m = match_events(contacts, data.truth)
        truth_tip = np.where(m >= 0, data.truth.is_tip[np.maximum(m, 0)], np.nan)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for k in range(len(contacts)):
        live = ~np.isnan(hist[k])
        color = "0.4"
        if truth_tip is not None and not np.isnan(truth_tip[k]):
            color = "tab:orange" if truth_tip[k] else "tab:blue"
        ax.plot(times[live], hist[k, live], color=color, lw=0.8, alpha=0.7)
        ax.plot([contacts.t[k]], [hist[k, live][0] if live.any() else np.nan], "o", ms=3,
                color=color)
        ax.plot([times[-1]], [hist[k, -1]], "s", ms=4, color=color)
    band = ClassifyParams()
    ax.axhspan(band.link_threshold, band.tip_threshold, color="0.9", zorder=0,
               label="ambiguous")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("tip probability $P_T$")
    ax.set_ylim(-0.03, 1.03)
    title = f"{run.name}: {len(contacts)} contacts, B = {B:g} m (causal replay)"
    if truth_tip is not None:
        title += "  — orange: true tip/joint, blue: true body"
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    with atomic_output(output, "wb") as fh:
        fig.savefig(fh, format=fmt, dpi=120)
    plt.close(fig)
    if as_json:
        result(json.dumps({"run": str(run), "B": B, "output": str(output), "steps": steps,
                           "contacts": len(contacts),
                           "final_p_tip": [None if np.isnan(v) else float(v)
                                           for v in hist[:, -1]] if len(contacts) else []}))
    else:
        status(f"wrote {output}")
