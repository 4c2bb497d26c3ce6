"""The drives' compliance (and play) learned from each run's map, against what was simulated.

For every scenario × seed of the physics engine (``--joint-compliance C``: each transmission
deflects by C at its effort limit, read on the motor side; ``--joint-backlash B``: each has B
of play; 0 or omitted: stiff, without play): the run is reconstructed at the readings and
``calibration.estimate_drives`` fits what ``--learn`` names (compliance, backlash or both)
so that the contacts lie on the reported primitives.  The table gives, per scenario and
quantity, the estimates of every joint over the seeds (median, 10th-90th percentiles), the
share within 0.25 mrad of the truth, and the median stated standard error.  On stiff runs the
estimate measures what else reads as compliance: the soft contacts' give, which grows with
the force.

Run:  .venv/bin/python benchmarks/bench_compliance.py --seeds 0-9 --cache DIR
      [--joint-compliance 0.001] [--joint-backlash 0.002] [--learn compliance,backlash]
      [--rate 50 --log-jitter 0.05 --log-drop 0.0065]
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

from wholearm_tools.calibration import estimate_drives
from wholearm_tools.pipeline import reconstruct
from wholearm_tools.sim.scenarios import load_scenario

TOLERANCE = 0.00025  # rad: "within" the truth


def main() -> None:
    sys.path.insert(0, str(Path(__file__).parent))
    from bench_events import get_run, scenarios_parser

    ap = scenarios_parser(__doc__, "physics", "0-9")
    ap.add_argument("--learn", default="compliance",
                    help="what to learn: compliance, backlash or compliance,backlash")
    args = ap.parse_args()
    args.known_compliance = False
    learn = tuple(args.learn.split(","))
    warnings.simplefilter("ignore")
    truth = {"compliance": float(args.joint_compliance or 0.0),
             "backlash": float(args.joint_backlash or 0.0)}
    print(f"# drives learned from the map, physics engine, seeds {args.seeds[0]}-"
          f"{args.seeds[-1]}, simulated compliance {truth['compliance'] * 1e3:g} mrad at the "
          f"effort limit, backlash {truth['backlash'] * 1e3:g} mrad")
    print(f"{'scenario':<14} {'learned':<10} {'runs':>4} {'joints':>6} {'median':>8} {'p10':>7} "
          f"{'p90':>7} {'within':>7} {'std':>7} {'s/run':>6}   (mrad)")
    every: dict[str, list[float]] = {w: [] for w in learn}
    for name in args.scenarios.split(","):
        B = float(load_scenario(name).hints.get("B", 0.02))
        values: dict[str, list[float]] = {w: [] for w in learn}
        stds: dict[str, list[float]] = {w: [] for w in learn}
        secs = []
        for seed in args.seeds:
            run = get_run(name, seed, args)
            rec = reconstruct(run, B=B, workers=1)
            t0 = time.perf_counter()
            est = estimate_drives(rec, compliance="compliance" in learn,
                                  backlash="backlash" in learn)
            secs.append(time.perf_counter() - t0)
            for w in est.learned:
                values[w].extend(getattr(est, w))
                stds[w].extend(getattr(est, f"{w}_std"))
        for w in learn:
            v = np.asarray(values[w])
            every[w].extend(values[w])
            if not len(v):
                print(f"{name:<14} {w:<10} {len(args.seeds):>4} {0:>6}")
                continue
            p10, p50, p90 = np.percentile(v, [10, 50, 90]) * 1e3
            print(f"{name:<14} {w:<10} {len(args.seeds):>4} {len(v):>6} {p50:>8.3f} "
                  f"{p10:>7.3f} {p90:>7.3f} {np.mean(np.abs(v - truth[w]) <= TOLERANCE):>7.2f} "
                  f"{np.median(stds[w]) * 1e3:>7.3f} {np.mean(secs):>6.2f}")
    for w in learn:
        v = np.asarray(every[w])
        if len(v):
            p10, p50, p90 = np.percentile(v, [10, 50, 90]) * 1e3
            print(f"{'all':<14} {w:<10} {'':>4} {len(v):>6} {p50:>8.3f} {p10:>7.3f} "
                  f"{p90:>7.3f} {np.mean(np.abs(v - truth[w]) <= TOLERANCE):>7.2f}")


if __name__ == "__main__":
    main()
