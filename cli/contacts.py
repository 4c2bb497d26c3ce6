"""``wholearm contacts RUN.mcap --B 0.02``: detected contacts, link in contact, tip probability.

The CSV (``-o contacts.csv``; ``-o contacts.parquet`` writes the same columns as typed Parquet,
with the run, B and classification mode in the file's metadata) is the fit's contact table
(``wholearm_tools.contact_table``, the file ``wholearm fit`` reads, either format) with
diagnostic columns appended, one row per contact in time order:

* the table's columns: ``t`` [s], ``link`` (0-based), ``p_tip`` (eq. 2, offline map, or causal
  with ``--causal``), ``label`` (tip / link / ambiguous), ``variance`` (σ² for the fit, m²),
  ``used_as``, ``tip_x, tip_y[, tip_z]``, ``tip_radius``, ``a_*``, ``b_*`` (link axis),
  ``link_radius``, ``primitive``, ``residual`` (empty before fitting), ``p_link`` (the named
  link's probability among its rigid group's links; 1 where the joints name one link);
* diagnostics (ignored by the fit): ``contact`` (0-based), ``index`` (log sample),
  ``p_tip_nomap`` (eq. 2 without the map), ``p_tip_swept`` (eq. 1), ``consistent`` (0 when the
  map left no admissible boundary), ``t_end`` [s], ``load`` (the largest torque at the stop on
  the joints up to the link, in detection thresholds: the evidence for the contact),
  ``q_<joint>`` (configuration at contact, rad), ``qd_<joint>`` (joint velocity just before
  the stop, rad/s), and for simulated runs ``true_link``, ``true_kind`` (-1 / empty when the
  detection matches no true contact event).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import click
import numpy as np

from cli.options import (
    B_option,
    InputPath,
    RigOptions,
    causal_option,
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

log = logging.getLogger(__name__)


def column_types(fields: list[str]) -> dict[str, str]:
    """Declared type of every column :func:`contact_rows` writes: the contact table's own
    (:func:`wholearm_tools.contact_table.table_column_types`), then the diagnostics."""
    from wholearm_tools.contact_table import table_column_types

    dim = 3 if "tip_z" in fields else 2
    types = table_column_types(dim)
    types.update({"contact": "int64", "index": "int64", "p_tip_nomap": "float64",
                  "p_tip_swept": "float64", "consistent": "int64",
                  "load": "float64",
                  "true_link": "int64", "true_kind": "string"})
    types.update({f: "float64" for f in fields if f.startswith(("q_", "qd_"))})
    return {f: types[f] for f in fields}


def contact_rows(run: Any, B: float, causal: bool) -> tuple[list[str], list[dict[str, Any]]]:
    """Detect, classify and (when ground truth exists) match.

    Returns the CSV header and one dict per contact: the contact table's columns (as the fit
    writes them) followed by the diagnostic columns.
    """
    from wholearm_tools.classify import tip_probability
    from wholearm_tools.contacts import detect_contacts, match_events
    from wholearm_tools.pipeline import contact_table

    with stage("detecting contacts"):
        contacts = detect_contacts(run.log, run.robot)
    with stage(f"classifying {len(contacts)} contacts with B = {B:g} m"):
        cls = tip_probability(run, contacts, B, causal=causal)
    table = contact_table(run.robot, contacts, cls)
    header, base = table.rows()
    match = match_events(contacts, run.truth) if run.truth is not None else None
    names = run.robot.joint_names
    # the evidence: the largest torque at the stop on the joints up to the contact's link, in
    # units of the detection threshold (what the free-motion model may be wrong by at rest)
    peak = np.abs(np.asarray(contacts.tau_peak, dtype=float).reshape(len(contacts), -1))
    ratio = peak / np.maximum(np.asarray(contacts.torque_threshold, dtype=float), 1e-300)
    upto = np.arange(ratio.shape[1])[None, :] <= np.asarray(contacts.link)[:, None]
    load = np.where(upto, ratio, 0.0).max(axis=1, initial=0.0)
    extra = ["contact", "index", "p_tip_nomap", "p_tip_swept", "consistent", "load",
             *[f"q_{n}" for n in names], *[f"qd_{n}" for n in names]]
    if match is not None:
        extra += ["true_link", "true_kind"]
    rows = []
    for k in range(len(contacts)):
        row: dict[str, Any] = dict(base[k])
        row.update({
            "contact": k, "index": int(contacts.index[k]),
            "p_tip_nomap": f"{cls.p_tip_nomap[k]:.6f}",
            "p_tip_swept": f"{cls.p_tip_swept[k]:.6f}",
            "consistent": int(cls.consistent[k]), "load": f"{load[k]:.4g}"})
        row.update({f"q_{n}": f"{v:.8g}" for n, v in zip(names, contacts.q[k], strict=True)})
        row.update({f"qd_{n}": f"{v:.6g}" for n, v in zip(names, contacts.qd_before[k],
                                                           strict=True)})
        if match is not None and run.truth is not None:
            j = int(match[k])
            row["true_link"] = int(run.truth.contact_link[j]) if j >= 0 else -1
            row["true_kind"] = str(run.truth.contact_kind[j]) if j >= 0 else ""
        rows.append(row)
    return header + extra, rows


@click.command("contacts")
@click.argument("run", type=InputPath())
@B_option()
@causal_option
@click.option("-o", "--output", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write the contacts as CSV, or Parquet for a .parquet name (default: a "
                   "table on stdout).")
@rig_options
@joint_topic_option
@command_topic_option
@json_option
@overwrite_option
def command(run: Path, B: float, causal: bool, output: Path | None, rig: RigOptions,
            joint_topic: str | None, command_topic: str | None, as_json: bool,
            overwrite: bool) -> None:
    """Detect the contacts of RUN, identify the link, and classify tip vs link body."""
    from wholearm_tools._tables import typed_rows, write_rows
    from wholearm_tools.classify.swept import check_B
    from wholearm_tools.logs import read_run

    if output is not None:
        check_output_file(output, overwrite)
    with stage(f"reading {run}"):
        data = read_run(run, joint_topic=joint_topic, command_topic=command_topic,
                        require_commands=True, **rig.read_kwargs())
    check_B(B, data.robot, what="--B")
    fields, rows = contact_rows(data, B, causal)
    types = column_types(fields)
    log.info("%d contacts in %s", len(rows), run)
    if output is not None:
        write_rows(output, fields, rows, types, meta={"run": str(run), "B": B,
                                                      "causal": causal})
    if as_json:
        result(json.dumps({"run": str(run), "B": B, "causal": causal,
                           "output": None if output is None else str(output),
                           "contacts": typed_rows(fields, rows, types)}, indent=2))
    elif output is None:
        head = (f"{'#':>3} {'t [s]':>9} {'dur s':>6} {'link':>4} {'load':>7} {'P_T':>6} "
                f"{'label':<9}")
        truth = bool(rows) and "true_link" in rows[0]
        lines = [head + ("  true" if truth else "")]
        for r in rows:
            dur = float(r["t_end"]) - float(r["t"])
            line = (f"{r['contact']:>3} {float(r['t']):>9.3f} {dur:>6.2f} {r['link']:>4} "
                    f"{float(r['load']):>6.1f}x {float(r['p_tip']):>6.3f} {r['label']:<9}")
            if truth:
                line += f"  {r['true_link']} {r['true_kind']}"
            lines.append(line)
        result("\n".join(lines))
    else:
        status(f"{len(rows)} contacts written to {output}")
