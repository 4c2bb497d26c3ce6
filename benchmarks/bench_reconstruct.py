"""Reconstruction accuracy and speed on the bundled scenarios, and the value of link data.

For each scenario and seed: simulate (the scenario's duration), ``reconstruct`` (detect →
classify → fit-and-grow), score against the ground truth with
:func:`wholearm_tools.report.metrics.evaluate` (primitives matched to true surfaces by the true
surfaces their member contacts touched), then refit the same classified contacts with the tip
contacts only (``used_as_tip``) and score again: the paper's claim is that tip + link beats tip
alone.

Columns: ``true`` = true surfaces; ``touched`` = surfaces with at least one true contact;
``dof-cov`` = touched surfaces whose distinct contacts (repeats of one configuration counted
once, as the fit counts them) consistent with them as used (true surface residual < 1 mm)
reach the type's ``dof + 2`` (what fit-and-grow needs to report a
primitive: below it the simulator's coverage is the limit, not the fit); ``det`` = those whose
consistent contacts also determine the true surface by the report gate's own test (links lying
flat on a flat surface left out of its type test, as the reconstruction does), evaluated at
the truth (``found/det``: found among them; where the contacts do not determine a surface, no
fit of them may be reported); ``found`` = touched
surfaces matched by a primitive of the right type; ``off`` = found surfaces none of whose
primitives is within 5 % of the radius and 5 mm RMS of the surface (found, but wrong in size or
place); ``extra`` = primitives matched to no
surface or of the wrong type; ``size %`` =
radius (major radius) error in percent per found curved surface; ``angle`` = axis / normal angle
error in degrees; ``srms`` = RMS distance of the fitted surface, sampled over its extent, to the
true surface [mm].  Times are wall seconds of ``reconstruct`` (detect / classify / fit).

The last table gives the totals per scenario over the seeds (surfaces touched, with enough
distinct contacts, found, determined by their contacts and found among those, off, extra,
the largest size error, the size errors above 1 % and of those the ones beyond the 95 %
interval the map states for that size: a size the contacts determine only to a few percent is
reported with that interval, one off by more than its interval is wrong; how many of all sizes
lie within their stated interval, and the median interval half-width, which says how much the
intervals claim: 95 % intervals under the stated kinematic error hold nearly every size of a
simulated arm, whose kinematics has no such error) and the CPU
seconds of ``reconstruct`` per run and per contact (one worker, so the figure does not
depend on the machine's cores).

Run:  .venv/bin/python benchmarks/bench_reconstruct.py [--seeds 0-9] [--scenarios a,b]
      [--engine physics] [--duration 120] [--no-tip-only] [--cache DIR]
      [--joint-compliance 0.001 [--known-compliance | --learn-compliance]]
      [--joint-backlash 0.002 [--known-drives | --learn-backlash]]
"""

from __future__ import annotations

import argparse
import dataclasses
import time
import warnings

import numpy as np

from wholearm_tools.contact_table import ContactTable
from wholearm_tools.contacts import match_events
from wholearm_tools.fit.models import MODELS
from wholearm_tools.pipeline import (
    DUPLICATE_TOL,
    Reconstruction,
    duplicate_groups,
    fit_table,
    position_noise_floor,
    reconstruct,
)
from wholearm_tools.report.metrics import evaluate, true_surfaces, truth_contact_touches
from wholearm_tools.sim.scenarios import load_scenario

SCENARIOS = ("lab_circle", "lab_sharp", "paper_planar", "paper_spatial", "well_junction")
#: a found surface is ``off`` unless one of its primitives is within these of it
OFF_SIZE_PCT, OFF_RMS = 5.0, 5e-3
#: a true contact touches every true surface within this of its point (``evaluate``'s default)
RESOLUTION = 0.01


def take_rows(table: ContactTable, rows: np.ndarray) -> ContactTable:
    """The contact table restricted to ``rows``."""
    vals = {f.name: np.asarray(getattr(table, f.name))[rows]
            for f in dataclasses.fields(table)}
    return ContactTable(**vals)


def _consistent(rec: Reconstruction, tol: float) -> dict[int, np.ndarray]:
    """Per true surface (position index), the distinct detected contacts (one table row per
    group of repeats, :func:`wholearm_tools.pipeline.duplicate_groups`, as the fit counts
    them) paired with a true contact that touched it (a corner contact counts for both walls)
    and consistent with it as the fit uses them: tip or link residual of the true surface
    below ``tol`` metres."""
    from wholearm_tools.fit import residuals
    from wholearm_tools.pipeline import fit_data_from_table

    truth = rec.run.truth
    surfaces = true_surfaces(truth)
    touches = truth_contact_touches(truth, surfaces, RESOLUTION)
    mi = match_events(rec.contacts, truth)
    table = rec.table
    # distinct as the reconstruction counts them: repeats of one configuration are one contact
    floor = position_noise_floor(rec.run.robot, np.asarray(rec.run.log.q))
    group = duplicate_groups(table, DUPLICATE_TOL * floor)
    out: dict[int, np.ndarray] = {}
    for i, s in enumerate(surfaces):
        rows = np.flatnonzero((mi >= 0) & touches[np.maximum(mi, 0), i])
        if len(rows) == 0:
            out[i] = rows
            continue
        data, order = fit_data_from_table(table, rows=rows)
        r = residuals(s.kind, s.params, data, float(s.data.get("free_side", 1)))
        good = order[np.abs(r) < tol]
        _, first = np.unique(group[good], return_index=True)
        out[i] = np.sort(good[first])
    return out


def coverage(consistent: dict[int, np.ndarray]) -> dict[int, int]:
    """Distinct detected contacts per true surface (position index) that are consistent with it
    as the fit uses them (:func:`_consistent`'s rows)."""
    return {i: len(r) for i, r in consistent.items()}


def determined(rec: Reconstruction, consistent: dict[int, np.ndarray]) -> dict[int, bool]:
    """Whether each true surface's consistent contacts (:func:`_consistent`) determine it by the
    report gate's own test (:func:`wholearm_tools.fit.gate.report_gate`, at the stated
    kinematic error of the default policy), evaluated at the true surface: where they do not,
    no primitive fitted to them could be reported, however well the fit went."""
    from types import SimpleNamespace

    from wholearm_tools.fit.gate import lying_flat, report_gate
    from wholearm_tools.fit.policy import FitPolicy
    from wholearm_tools.fit.readings import readings_from_contacts
    from wholearm_tools.pipeline import fit_data_from_table

    policy = FitPolicy()
    surfaces = true_surfaces(rec.run.truth)
    sigma_kin = policy.kinematic_error * float(rec.run.robot.reach)
    B = float(rec.params.B)
    t = rec.table
    out: dict[int, bool] = {}
    for i, rows in consistent.items():
        s = surfaces[i]
        if len(rows) == 0:
            out[i] = False
            continue
        data, order = fit_data_from_table(t, rows=rows)
        true_fit = SimpleNamespace(kind=s.kind, params=s.params, primitive=s.primitive,
                                   free_side=float(s.data.get("free_side", 1)))
        # as the pipeline's gate: a link lying flat on a flat surface leaves its point of
        # touch open and stays out of the type test
        rd = readings_from_contacts(t.link[order], t.p_tip[order], t.tip_center[order],
                                    t.tip_radius[order], t.seg_a[order], t.seg_b[order],
                                    t.link_radius[order])
        open_touch = lying_flat(true_fit, rd, np.arange(len(order)),
                                policy.k_sigma * sigma_kin, B)
        out[i] = bool(report_gate(true_fit, data, sigma_kin, policy.max_rel_std, B=B,
                                  open_touch=open_touch))
    return out


def score(rec: Reconstruction, cov: dict[int, int], det: dict[int, bool]) -> dict:
    ev = evaluate(rec)
    surfaces = true_surfaces(rec.run.truth)
    touched = [s for s in ev.surfaces if s.touched]
    enough = [s for i, s in enumerate(ev.surfaces)
              if cov[i] >= MODELS[surfaces[i].kind].dof + 2]
    found = [s for s in ev.surfaces if s.touched and s.found]
    determinable = [i for i, s in enumerate(ev.surfaces) if det.get(i, False)]
    good = [a for a in ev.primitives if a.type_correct]
    by_id = {a.primitive_id: a for a in ev.primitives}

    def close(a) -> bool:
        return ((a.size_error_pct is None or abs(a.size_error_pct) <= OFF_SIZE_PCT)
                and (a.surface_rms is None or a.surface_rms <= OFF_RMS))

    off = [s for s in found if not any(close(by_id[p]) for p in s.found_by)]
    prims = {p.id: p for p in rec.surface_map.primitives}

    def ci_pct(a) -> float:
        # the half-width of the 95 % interval the map states for the size, in % of it
        p = prims[a.primitive_id]
        half = p.ci95.get(a.size_name) if p.ci95 else None
        value = float(p.params[a.size_name])
        if half is None or not value:
            return float("nan")
        return 100.0 * float(np.asarray(half)) / abs(value)

    sized = [a for a in good if a.size_error_pct is not None]
    c, cm = ev.classification, ev.classification_map
    return {
        "link_acc": c.link_accuracy, "cls_acc": c.class_accuracy, "amb": c.ambiguous_fraction,
        "link_acc_map": cm.link_accuracy if cm else float("nan"),
        "cls_acc_map": cm.class_accuracy if cm else float("nan"),
        "amb_map": cm.ambiguous_fraction if cm else float("nan"),
        "cls_counts": [_counts(c), _counts(cm) if cm else [0] * 5],
        "true": len(ev.surfaces), "touched": len(touched), "dof_cov": len(enough),
        "determined": len(determinable),
        "found_determined": sum(1 for i in determinable
                                if ev.surfaces[i].touched and ev.surfaces[i].found),
        "found": len(found), "found_kinds": sorted(s.kind for s in found), "off": len(off),
        "n_prims": len(ev.primitives),
        "extra": sum(1 for a in ev.primitives if not a.type_correct)
        + (len(good) - len({a.truth_id for a in good})),
        "size_pct": [abs(a.size_error_pct) for a in sized],
        "size_ci_pct": [ci_pct(a) for a in sized],
        "angle": [a.axis_angle_deg for a in good if a.axis_angle_deg is not None],
        "srms_mm": [1e3 * a.surface_rms for a in good if a.surface_rms is not None],
        "coverage": {f"{surfaces[i].kind}{surfaces[i].id}": c for i, c in cov.items()},
    }


def _counts(c) -> list[int]:
    """Paired, on the right link, labels decided, decided right, left ambiguous."""
    conf = np.asarray(c.confusion)
    return [c.n_matched, c.link_correct, int(conf[:, :2].sum()), int(conf[0, 0] + conf[1, 1]),
            int(conf[:, 2].sum())]


def tip_only(rec: Reconstruction) -> Reconstruction:
    table = rec.table
    rows = np.flatnonzero(np.asarray(table.used_as_tip))
    sub = take_rows(table, rows)
    floor = position_noise_floor(rec.run.robot, np.asarray(rec.run.log.q))
    smap, fits, sub, msgs = fit_table(sub, planar=rec.planar, B=rec.params.B,
                                      loss=rec.params.loss, noise_floor=floor)
    return dataclasses.replace(rec, table=sub, fits=fits, surface_map=smap, messages=msgs)


def _fmt(values: list[float], digits: int = 2) -> str:
    if not values:
        return "-"
    return "max " + f"{max(values):.{digits}g}" + (f" (n={len(values)})" if len(values) > 1
                                                     else "")


def main() -> None:
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from bench_events import add_run_options, get_run, seeds_arg

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1", help="e.g. 0,1 or 0-9")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    add_run_options(ap, "kinematic")
    ap.add_argument("--no-tip-only", action="store_true", help="skip the tip-only refit")
    ap.add_argument("--learn-compliance", action="store_true",
                    help="learn the drives' compliance from a first map, then reconstruct at "
                         "the links' angles (reconstruct's learn_compliance)")
    ap.add_argument("--learn-backlash", action="store_true",
                    help="learn the drives' play likewise (reconstruct's learn_backlash)")
    args = ap.parse_args()
    seeds = seeds_arg(args.seeds)
    warnings.simplefilter("ignore")
    rows = []
    for name in args.scenarios.split(","):
        sc = load_scenario(name)
        B = float(sc.hints.get("B", 0.02))
        for seed in seeds:
            run = get_run(name, seed, args)
            t0, c0 = time.perf_counter(), time.process_time()
            rec = reconstruct(run, B=B, workers=1, learn_compliance=args.learn_compliance,
                              learn_backlash=args.learn_backlash)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            consistent = _consistent(rec, 1e-3)
            cov = coverage(consistent)
            det = determined(rec, consistent)
            both = score(rec, cov, det)
            both["cpu"] = cpu
            t1 = time.perf_counter()
            tip = both if args.no_tip_only else score(tip_only(rec), cov, det)
            t_tip = time.perf_counter() - t1
            rows.append((name, seed, B, run.log.duration, len(rec.table), wall, rec.timings,
                         both, tip, t_tip, rec.messages))
            print(f"# {name} seed {seed}: {len(rec.table)} contacts, reconstruct {wall:.1f} s; "
                  f"coverage (distinct correctly classified contacts per surface) "
                  f"{both['coverage']}", flush=True)

    print("\n## Primitives found (tip + link data)\n")
    print(f"{'scenario':<14}{'seed':>4}{'arm s':>7}{'cont':>6}{'true':>5}{'touch':>6}"
          f"{'dofcov':>7}{'det':>5}{'found':>6}{'off':>4}{'extra':>6}  {'found types':<34}"
          f"{'size %':<16}"
          f"{'angle deg':<18}{'srms mm':<16}")
    for name, seed, _, dur, n, _, _, b, _, _, _ in rows:
        print(f"{name:<14}{seed:>4}{dur:>7.0f}{n:>6}{b['true']:>5}{b['touched']:>6}"
              f"{b['dof_cov']:>7}{b['determined']:>5}{b['found']:>6}{b['off']:>4}"
              f"{b['extra']:>6}  "
              f"{','.join(b['found_kinds']):<34}{_fmt(b['size_pct']):<16}"
              f"{_fmt(b['angle']):<18}{_fmt(b['srms_mm']):<16}")

    print("\n## Classification: eq. (2) alone vs refined by the fitted map (labels right of "
          "decided / ambiguous)\n")
    print(f"{'scenario':<14}{'seed':>4}{'link %':>8}{'eq2 right %':>13}{'eq2 amb %':>11}"
          f"{'map link %':>12}{'map right %':>13}{'map amb %':>11}")
    for name, seed, _, _, _, _, _, b, _, _, _ in rows:
        print(f"{name:<14}{seed:>4}{100 * b['link_acc']:>8.1f}{100 * b['cls_acc']:>13.1f}"
              f"{100 * b['amb']:>11.1f}{100 * b['link_acc_map']:>12.1f}"
              f"{100 * b['cls_acc_map']:>13.1f}{100 * b['amb_map']:>11.1f}")
    print("-" * 82)

    def pct(a: int, b: int) -> float:
        return 100.0 * a / b if b else float("nan")

    for name in [*dict.fromkeys(r[0] for r in rows), "all"]:
        tot = np.sum([r[7]["cls_counts"] for r in rows if name in ("all", r[0])], axis=0)
        print(f"{name:<14}{'all':>4}"
              + "".join(f"{pct(t[1], t[0]):>{w1}.1f}{pct(t[3], t[2]):>13.1f}"
                        f"{pct(t[4], t[0]):>11.1f}" for t, w1 in ((tot[0], 8), (tot[1], 12))))

    print("\n## Value of link data: tip contacts only vs tip + link\n")
    print(f"{'scenario':<14}{'seed':>4}  {'found tip|both':<15}{'extra tip|both':<15}"
          f"{'size % tip | both':<34}{'angle deg tip | both':<36}{'srms mm tip | both':<30}")
    for name, seed, _, _, _, _, _, b, t, _, _ in rows:
        print(f"{name:<14}{seed:>4}  {t['found']:>3} | {b['found']:<8}{t['extra']:>3} | "
              f"{b['extra']:<8}{_fmt(t['size_pct']):>15} | {_fmt(b['size_pct']):<16}"
              f"{_fmt(t['angle']):>17} | {_fmt(b['angle']):<16}"
              f"{_fmt(t['srms_mm']):>14} | {_fmt(b['srms_mm']):<14}")

    print("\n## Time (wall s of reconstruct)\n")
    print(f"{'scenario':<14}{'seed':>4}{'arm s':>7}{'total':>8}{'detect':>8}{'classify':>9}"
          f"{'fit':>7}{'tip-only fit':>13}")
    for name, seed, _, dur, _, wall, tm, _, _, t_tip, _ in rows:
        print(f"{name:<14}{seed:>4}{dur:>7.0f}{wall:>8.1f}{tm.get('detect', 0):>8.2f}"
              f"{tm.get('classify', 0):>9.2f}{tm.get('fit', 0):>7.2f}{t_tip:>13.2f}")
    wj = [r for r in rows if r[0] == "well_junction"]
    if wj:
        worst = max(r[5] for r in wj)
        print(f"\nwell_junction reconstruct: worst {worst:.1f} s wall for "
              f"{wj[0][3]:.0f} s of arm time (target: < 30 s for 60 s of arm time, "
              "measured by bench_junction.py --duration 60)")
    print(f"\n## Totals over seeds {args.seeds} ({args.engine})\n")
    print(f"{'scenario':<14}{'runs':>5}{'touched':>8}{'dofcov':>7}{'found':>6}{'det':>5}"
          f"{'found/det':>10}{'off':>4}{'extra':>6}{'max size %':>11}{'>1 %':>5}"
          f"{'beyond ci':>10}{'in ci':>8}{'med ci %':>9}{'cpu s/run':>10}"
          f"{'cpu s/contact':>14}")
    for name in dict.fromkeys(r[0] for r in rows):
        rs = [r for r in rows if r[0] == name]
        b = [r[7] for r in rs]
        sizes = [x for bb in b for x in bb["size_pct"]]
        cis = [x for bb in b for x in bb["size_ci_pct"]]
        over = [(e, c) for e, c in zip(sizes, cis, strict=True) if e > 1.0]
        within = f"{sum(e <= c for e, c in zip(sizes, cis, strict=True))}/{len(sizes)}"
        print(f"{name:<14}{len(rs):>5}{sum(x['touched'] for x in b):>8}"
              f"{sum(x['dof_cov'] for x in b):>7}{sum(x['found'] for x in b):>6}"
              f"{sum(x['determined'] for x in b):>5}"
              f"{sum(x['found_determined'] for x in b):>10}"
              f"{sum(x['off'] for x in b):>4}{sum(x['extra'] for x in b):>6}"
              f"{max(sizes, default=0.0):>11.3f}{len(over):>5}"
              f"{sum(1 for e, c in over if not e <= c):>10}"
              f"{within:>8}"
              f"{np.nanmedian(cis) if cis else np.nan:>9.3f}"
              f"{np.mean([x['cpu'] for x in b]):>10.1f}"
              f"{np.mean([x['cpu'] / max(r[4], 1) for x, r in zip(b, rs, strict=True)]):>14.3f}")
    notes = {m for r in rows for m in r[10]}
    if notes:
        print("\nmessages: " + "; ".join(sorted(notes)))


if __name__ == "__main__":
    main()
