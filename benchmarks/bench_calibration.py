"""How far eq. (2)'s tip probability can be trusted: the true tip rate per band of P_T.

For every scenario × seed: detect the contacts, compute P_T offline at the scenario's B, pair
each detection with its true contact, and count per band of P_T the contacts and the share
that were truly tip (or joint) contacts.  A calibrated P_T has the true rate near the band's
mean.  The confident bands (P_T below 0.001 or at least 0.999) say how often a label eq. (2)
is sure of is wrong, against the weight the fit's reading prior keeps on the other reading
(``wholearm_tools.fit.readings.P_TIP_CLIP``).

Run:  .venv/bin/python benchmarks/bench_calibration.py [--engine physics] [--seeds 0-9]
      [--cache DIR]
"""

from __future__ import annotations

import itertools
import sys
import warnings
from pathlib import Path

import numpy as np

from wholearm_tools.classify import swept_map, tip_probability
from wholearm_tools.contacts import detect_contacts, match_events
from wholearm_tools.sim.scenarios import load_scenario

EDGES = (0.0, 1e-3, 1e-2, 0.05, 0.2, 0.5, 0.8, 0.95, 0.99, 0.999, 1.0 + 1e-9)


def main() -> None:
    sys.path.insert(0, str(Path(__file__).parent))
    from bench_events import get_run, scenarios_parser

    args = scenarios_parser(__doc__, "kinematic", "0-9").parse_args()
    warnings.simplefilter("ignore")
    p_tip, is_tip = [], []
    for name in args.scenarios.split(","):
        B = float(load_scenario(name).hints.get("B", 0.02))
        for seed in args.seeds:
            run = get_run(name, seed, args)
            contacts = detect_contacts(run.log, run.robot)
            cls = tip_probability(run, contacts, B, grid=swept_map(run.robot, run.log.q, B=B))
            m = match_events(contacts, run.truth)
            ok = m >= 0
            p_tip.append(np.asarray(cls.p_tip)[ok])
            is_tip.append(run.truth.is_tip[m[ok]].astype(float))
    p, t = np.concatenate(p_tip), np.concatenate(is_tip)
    print(f"{args.engine} engine, seeds {args.seeds[0]}-{args.seeds[-1]}, "
          f"{len(p)} detections paired with a true contact\n")
    print(f"{'P_T band':<16}{'contacts':>9}{'mean P_T':>10}{'true tip':>10}{'label wrong':>13}")
    for lo, hi in itertools.pairwise(EDGES):
        k = (p >= lo) & (p < hi)
        if not k.any():
            continue
        wrong = np.where(p[k] >= 0.5, 1.0 - t[k], t[k])
        band = f"[{lo:g}, {min(hi, 1.0):g}{']' if hi > 1 else ')'}"
        print(f"{band:<16}{int(k.sum()):>9}{p[k].mean():>10.4f}{t[k].mean():>10.4f}"
              f"{wrong.mean():>13.4f}")
    sure = (p < EDGES[1]) | (p >= EDGES[-2])
    wrong = np.where(p[sure] >= 0.5, 1.0 - t[sure], t[sure])
    print(f"\nlabels eq. (2) is sure of (P_T < 0.001 or >= 0.999): {int(sure.sum())}, "
          f"wrong {int(wrong.sum())} ({100 * wrong.mean():.2f} %)")


if __name__ == "__main__":
    main()
