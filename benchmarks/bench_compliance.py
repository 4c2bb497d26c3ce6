"""The drives' compliance learned from each run's map, against the compliance simulated.

For every scenario × seed of the physics engine (``--joint-compliance C``: each transmission
deflects by C at its effort limit, read on the motor side; 0 or omitted: stiff drives): the
run is reconstructed at the readings and ``calibration.estimate_compliance`` fits the
compliance that puts the contacts on the reported primitives.  The table gives, per scenario,
the estimates of every joint over the seeds (median, 10th-90th percentiles), the share within
0.25 mrad of the truth, and the median stated standard error.  On stiff runs the estimate
measures what else reads as compliance: the soft contacts' give, which grows with the force.

Run:  .venv/bin/python benchmarks/bench_compliance.py --seeds 0-9 --cache DIR
      [--joint-compliance 0.001] [--rate 50 --log-jitter 0.05 --log-drop 0.0065]
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

from wholearm_tools.calibration import estimate_compliance
from wholearm_tools.pipeline import reconstruct
from wholearm_tools.sim.scenarios import load_scenario

TOLERANCE = 0.00025  # rad: "within" the truth


def main() -> None:
    sys.path.insert(0, str(Path(__file__).parent))
    from bench_events import get_run, scenarios_parser

    args = scenarios_parser(__doc__, "physics", "0-9").parse_args()
    args.known_compliance = False
    warnings.simplefilter("ignore")
    truth = float(args.joint_compliance or 0.0)
    print(f"# compliance learned from the map, physics engine, seeds {args.seeds[0]}-"
          f"{args.seeds[-1]}, simulated {truth * 1e3:g} mrad at the effort limit")
    print(f"{'scenario':<14} {'runs':>4} {'joints':>6} {'median':>8} {'p10':>7} {'p90':>7} "
          f"{'within':>7} {'std':>7} {'s/run':>6}   (mrad)")
    every: list[float] = []
    for name in args.scenarios.split(","):
        B = float(load_scenario(name).hints.get("B", 0.02))
        values, stds, secs = [], [], []
        for seed in args.seeds:
            run = get_run(name, seed, args)
            rec = reconstruct(run, B=B, workers=1)
            t0 = time.perf_counter()
            est = estimate_compliance(rec)
            secs.append(time.perf_counter() - t0)
            if est.readings:
                values.extend(est.compliance)
                stds.extend(est.std)
        v = np.asarray(values)
        every.extend(values)
        if not len(v):
            print(f"{name:<14} {len(args.seeds):>4} {0:>6}")
            continue
        p10, p50, p90 = np.percentile(v, [10, 50, 90]) * 1e3
        print(f"{name:<14} {len(args.seeds):>4} {len(v):>6} {p50:>8.3f} {p10:>7.3f} {p90:>7.3f} "
              f"{np.mean(np.abs(v - truth) <= TOLERANCE):>7.2f} "
              f"{np.median(stds) * 1e3:>7.3f} {np.mean(secs):>6.2f}")
    v = np.asarray(every)
    if len(v):
        p10, p50, p90 = np.percentile(v, [10, 50, 90]) * 1e3
        print(f"{'all':<14} {'':>4} {len(v):>6} {p50:>8.3f} {p10:>7.3f} {p90:>7.3f} "
              f"{np.mean(np.abs(v - truth) <= TOLERANCE):>7.2f}")


if __name__ == "__main__":
    main()
