"""Contact detection and tip/link classification accuracy on every bundled scenario.

Run: ``.venv/bin/python benchmarks/bench_classify.py [--seeds 3] [--duration SECONDS]
[--B 0.01 0.02 0.04] [--scenarios lab_circle paper_planar] [--list] [--refine]``

For every scenario × seed the run is simulated in process; for every B the contacts are
classified offline (whole-run map) and causally (map up to each contact).  Columns:

* ``det``: detected / true contacts; ``link%``: detections whose link equals the matched true
  contact's link (unmatched detections count as wrong);
* ``lab%``: tip/link labels that agree with the truth among the contacts labelled (not
  ambiguous), offline; ``amb%``: ambiguous fraction, offline; ``lab%c``/``amb%c``: causal;
* ``|P-T| off`` / ``|P-T| cau``: mean |P_T − truth| (truth 1 for tip/joint, 0 for body);
* ``s``: seconds spent in detection + classification (both modes), summed over the seeds;
* with ``--refine`` (one reconstruction per run and B): ``link%m`` the links refined by the
  fitted map (``link_by_map``: where the joint signals could not tell the links of a rigid
  group apart), ``lab%m`` / ``amb%m`` the labels refined by it (``label_map``).

``--list`` also prints every detection whose link differs from its true contact's (time,
detected link, true link, kind and fraction along the link, the held joints and the torque
signature) and every true contact no detection matched.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from wholearm_tools.classify import swept_map, tip_probability
from wholearm_tools.contacts import detect_contacts, match_events
from wholearm_tools.sim.scenarios import list_scenarios, load_scenario


def refined(run, B):
    """Counts of the map-refined labels and links of one run at one B (a whole
    reconstruction)."""
    import warnings

    from wholearm_tools.pipeline import reconstruct
    from wholearm_tools.report.metrics import evaluate as score

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cm = score(reconstruct(run, B=B)).classification_map
    conf = cm.confusion
    return {"map_link_ok": cm.link_correct,
            "map_right": int(conf[0, 0] + conf[1, 1]), "map_decided": int(conf[:, :2].sum()),
            "map_amb": int(conf[:, 2].sum()), "map_matched": int(conf.sum())}


def evaluate(run, B, wrong=None, refine=False):
    """Accuracy counts of one run at one B; appends one line per misidentified or missed
    contact to ``wrong`` when given; with ``refine`` also the map-refined labels' counts."""
    t0 = time.perf_counter()
    contacts = detect_contacts(run.log, run.robot)
    grid = swept_map(run.robot, run.log.q, B=B)
    off = tip_probability(run, contacts, B, grid=grid)
    cau = tip_probability(run, contacts, B, grid=grid, causal=True)
    secs = time.perf_counter() - t0
    truth = run.truth
    m = match_events(contacts, truth)
    ok = m >= 0
    true_link = np.where(ok, truth.contact_link[np.maximum(m, 0)], -1)
    true_tip = truth.is_tip[np.maximum(m, 0)].astype(float)
    row = {"n_true": truth.n_contacts, "n_det": len(contacts),
           "link_ok": int(np.sum(contacts.link == true_link)), "secs": secs}
    for name, cl in (("off", off), ("cau", cau)):
        lab = ok & (cl.label != "ambiguous")
        row[f"labelled_{name}"] = int(lab.sum())
        row[f"label_ok_{name}"] = int(np.sum((cl.label == "tip")[lab] == (true_tip[lab] > 0.5)))
        row[f"amb_{name}"] = int(np.sum(ok & (cl.label == "ambiguous")))
        row[f"err_{name}"] = float(np.sum(np.abs(cl.p_tip - true_tip)[ok]))
        row["matched"] = int(ok.sum())
    if wrong is not None:
        wrong.extend(_misidentified(contacts, truth, m))
    if refine:
        row.update(refined(run, B))
    return row


def _misidentified(contacts, truth, m):
    out = []
    true_link = np.where(m >= 0, truth.contact_link[np.maximum(m, 0)], -1)
    for i in np.flatnonzero(contacts.link != true_link):
        j = int(m[i])
        what = (f"true link {truth.contact_link[j]} {truth.contact_kind[j]} "
                f"s={truth.contact_s[j]:.2f}" if j >= 0 else "no true contact")
        held = "".join("h" if h else "." for h in contacts.held[i])
        sig = " ".join(f"{v:.3g}" for v in contacts.tau_peak[i])
        out.append(f"t={contacts.t[i]:.3f} #{i} link {contacts.link[i]}, {what}; "
                   f"held {held}, torques [{sig}]")
    for j in np.setdiff1d(np.arange(truth.n_contacts), m[m >= 0]):
        out.append(f"t={truth.contact_t[j]:.3f} missed: true link {truth.contact_link[j]} "
                   f"{truth.contact_kind[j]} s={truth.contact_s[j]:.2f}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--duration", type=float, default=None,
                    help="seconds per run (default: each scenario's own duration)")
    ap.add_argument("--B", type=float, nargs="+", default=[0.01, 0.02, 0.04])
    ap.add_argument("--scenarios", nargs="+", default=None)
    ap.add_argument("--list", action="store_true",
                    help="print every misidentified or missed contact")
    ap.add_argument("--refine", action="store_true",
                    help="also score the labels refined by the fitted map (reconstructs)")
    args = ap.parse_args()
    names = args.scenarios or list_scenarios()
    head = (f"{'scenario':<14} {'B':>5} {'det':>9} {'link%':>6} {'lab%':>6} {'amb%':>5} "
            f"{'lab%c':>6} {'amb%c':>5} {'|P-T| off':>9} {'|P-T| cau':>9} {'s':>5}"
            + (f" {'link%m':>6} {'lab%m':>6} {'amb%m':>5}" if args.refine else ""))
    print(head)
    print("-" * len(head))
    total: dict[float, dict[str, float]] = {}
    for name in names:
        sc = load_scenario(name)
        runs = [sc.simulate(seed=s, duration=args.duration).run for s in range(args.seeds)]
        for b_index, B in enumerate(args.B):
            # detection does not depend on B: list its misses once per run
            wrong = [[] if args.list and b_index == 0 else None for _ in runs]
            rows = [evaluate(run, B, w, args.refine) for run, w in zip(runs, wrong, strict=True)]
            agg = {k: sum(r[k] for r in rows) for k in rows[0]}
            acc = total.setdefault(B, dict.fromkeys(agg, 0.0))
            for k, v in agg.items():
                acc[k] += v
            print(_line(name, B, agg))
            for seed, w in enumerate(wrong):
                for line in w or []:
                    print(f"    {name} seed {seed} {line}")
    print("-" * len(head))
    for B, agg in total.items():
        print(_line("ALL", B, agg))


def _pct(a: float, b: float) -> str:
    return f"{100 * a / b:6.1f}" if b else f"{'-':>6}"


def _line(name: str, B: float, a: dict[str, float]) -> str:
    matched = max(a["matched"], 1)
    return (f"{name:<14} {B:>5.3f} {int(a['n_det']):>4}/{int(a['n_true']):<4} "
            f"{_pct(a['link_ok'], max(a['n_det'], a['n_true'])):>6} "
            f"{_pct(a['label_ok_off'], a['labelled_off'])} "
            f"{100 * a['amb_off'] / matched:5.1f} "
            f"{_pct(a['label_ok_cau'], a['labelled_cau'])} "
            f"{100 * a['amb_cau'] / matched:5.1f} "
            f"{a['err_off'] / matched:>9.3f} {a['err_cau'] / matched:>9.3f} {a['secs']:>5.1f}"
            + (f" {_pct(a['map_link_ok'], max(a['n_det'], a['n_true']))} "
               f"{_pct(a['map_right'], a['map_decided'])} "
               f"{100 * a['map_amb'] / max(a['map_matched'], 1):5.1f}" if "map_right" in a
               else ""))


if __name__ == "__main__":
    main()
