"""Reconstruct CPU time against run length: CPU seconds per run and per contact on one worker.

For each scenario and arm time: simulate (kinematic engine unless ``--engine physics``), run
``reconstruct`` with one worker at the scenario's B and read the process CPU time of the call
(detect / classify / fit split from the pipeline's own timings).  Beside each row, the linear
model the issue measured before the inference loop (``REFERENCE``: constant + per-contact CPU
seconds), evaluated at the same contact count, and its ratio to ours.

Run:  .venv/bin/python benchmarks/bench_cpu.py [--runs well_junction:60,120,240,480
      paper_spatial:60,120,240] [--seed 0] [--cache DIR]
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path

from wholearm_tools.pipeline import reconstruct
from wholearm_tools.sim.scenarios import load_scenario

#: CPU seconds of reconstruct before the inference loop, as (constant, per contact), one worker
REFERENCE = {"well_junction": (4.0, 0.21), "paper_spatial": (31.0, 0.14)}
DEFAULT_RUNS = ("well_junction:60,120,240,480", "paper_spatial:60,120,240")


def main() -> None:
    sys.path.insert(0, str(Path(__file__).parent))
    from bench_events import add_run_options, get_run

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", nargs="+", default=list(DEFAULT_RUNS),
                    help="scenario:seconds,seconds,...")
    ap.add_argument("--seed", type=int, default=0)
    add_run_options(ap, "kinematic")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    print(f"{'scenario':<14}{'arm s':>6}{'cont':>6}{'cpu s':>8}{'detect':>8}{'classify':>9}"
          f"{'fit':>7}{'s/contact':>10}{'before s':>9}{'before/now':>11}")
    for spec in args.runs:
        name, _, durations = spec.partition(":")
        B = float(load_scenario(name).hints.get("B", 0.02))
        for dur in (float(d) for d in durations.split(",")):
            args.duration = dur
            run = get_run(name, args.seed, args)
            c0 = time.process_time()
            rec = reconstruct(run, B=B, workers=1)
            cpu = time.process_time() - c0
            n = len(rec.table)
            tm = rec.timings
            a, b = REFERENCE.get(name, (float("nan"), float("nan")))
            before = a + b * n
            print(f"{name:<14}{dur:>6.0f}{n:>6}{cpu:>8.1f}{tm.get('detect', 0):>8.1f}"
                  f"{tm.get('classify', 0):>9.1f}{tm.get('fit', 0):>7.1f}"
                  f"{cpu / max(n, 1):>10.3f}{before:>9.1f}{before / cpu:>11.2f}", flush=True)


if __name__ == "__main__":
    main()
