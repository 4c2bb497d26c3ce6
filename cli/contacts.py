"""``wholearm contacts RUN.mcap --B 0.02``: detected contacts, link in contact, tip probability.

CSV columns (one row per contact, time order): ``contact`` (0-based), ``t`` [s, log clock],
``index`` (log sample), ``link`` (0-based link in contact), ``p_tip`` (eq. 2, offline map or
causal with ``--causal``), ``label`` (tip / link / ambiguous), ``variance`` (σ² for fit weights,
m²), ``p_tip_nomap`` (eq. 2 without the map), ``p_tip_swept`` (eq. 1), ``consistent`` (0 when the
map left no admissible boundary), ``t_end`` [s], ``q_<joint>`` (configuration at contact, rad),
``qd_<joint>`` (joint velocity just before the stop, rad/s), and for simulated runs
``true_link``, ``true_kind`` (-1 / empty when the detection matches no true contact).
"""

from __future__ import annotations

import csv
import io
import json
import logging
from pathlib import Path
from typing import Any

import click

from cli.options import check_output_file, json_option, overwrite_option

log = logging.getLogger(__name__)


def contact_rows(run: Any, B: float, causal: bool) -> list[dict[str, Any]]:
    """Detect, classify and (when ground truth exists) match: one dict per contact."""
    from wholearm_tools.classify import tip_probability
    from wholearm_tools.contacts import detect_contacts, match_truth

    contacts = detect_contacts(run.log, run.robot)
    cls = tip_probability(run, contacts, B, causal=causal)
    match = match_truth(contacts, run.truth) if run.truth is not None else None
    names = run.robot.joint_names
    rows = []
    for k in range(len(contacts)):
        row: dict[str, Any] = {
            "contact": k, "t": round(float(contacts.t[k]), 6), "index": int(contacts.index[k]),
            "link": int(contacts.link[k]), "p_tip": round(float(cls.p_tip[k]), 6),
            "label": str(cls.label[k]), "variance": float(f"{cls.variance[k]:.6g}"),
            "p_tip_nomap": round(float(cls.p_tip_nomap[k]), 6),
            "p_tip_swept": round(float(cls.p_tip_swept[k]), 6),
            "consistent": int(cls.consistent[k]), "t_end": round(float(contacts.t_end[k]), 6)}
        row.update({f"q_{n}": float(f"{v:.8g}") for n, v in zip(names, contacts.q[k],
                                                                 strict=True)})
        row.update({f"qd_{n}": float(f"{v:.6g}") for n, v in zip(names, contacts.qd_before[k],
                                                                  strict=True)})
        if match is not None and run.truth is not None:
            j = int(match[k])
            row["true_link"] = int(run.truth.contact_link[j]) if j >= 0 else -1
            row["true_kind"] = str(run.truth.contact_kind[j]) if j >= 0 else ""
        rows.append(row)
    return rows


@click.command("contacts")
@click.argument("run", type=click.Path(dir_okay=False, exists=True, path_type=Path))
@click.option("--B", "B", type=float, required=True,
              help="Smallest expected surface curvature radius [m].")
@click.option("--causal", is_flag=True,
              help="Classify with the map as seen at each contact (default: whole run).")
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write the contacts as CSV (default: a table on stdout).")
@click.option("--robot", "robot_file", type=click.Path(dir_okay=False, exists=True,
                                                       path_type=Path), default=None,
              help="URDF file (default: the log's /robot_description).")
@json_option
@overwrite_option
def command(run: Path, B: float, causal: bool, output: Path | None, robot_file: Path | None,
            as_json: bool, overwrite: bool) -> None:
    """Detect the contacts of RUN, identify the link, and classify tip vs link body."""
    from wholearm_tools._io import atomic_output
    from wholearm_tools.logs import read_run

    if not B > 0:
        raise click.BadParameter(f"must be a positive length in metres, got {B}", param_hint="--B")
    if output is not None:
        check_output_file(output, overwrite)
    data = read_run(run, robot=robot_file, require_commands=True)
    rows = contact_rows(data, B, causal)
    log.info("%d contacts in %s", len(rows), run)
    if output is not None:
        buf = io.StringIO()
        fields = list(rows[0]) if rows else ["contact", "t", "index", "link", "p_tip", "label",
                                             "variance", "p_tip_nomap", "p_tip_swept",
                                             "consistent", "t_end"]
        writer = csv.DictWriter(buf, fieldnames=fields, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
        with atomic_output(output, "w") as fh:
            fh.write(buf.getvalue())
    if as_json:
        click.echo(json.dumps({"run": str(run), "B": B, "causal": causal, "contacts": rows},
                              indent=2))
    elif output is None:
        head = f"{'#':>3} {'t [s]':>9} {'link':>4} {'P_T':>6} {'label':<9}"
        truth = bool(rows) and "true_link" in rows[0]
        click.echo(head + ("  true" if truth else ""))
        for r in rows:
            line = (f"{r['contact']:>3} {r['t']:>9.3f} {r['link']:>4} {r['p_tip']:>6.3f} "
                    f"{r['label']:<9}")
            if truth:
                line += f"  {r['true_link']} {r['true_kind']}"
            click.echo(line)
    else:
        click.echo(f"{len(rows)} contacts written to {output}", err=True)
