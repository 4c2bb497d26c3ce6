"""Simulator speed: wall time to simulate each bundled scenario (default 60 s of arm time at
500 Hz; ``well_junction`` is the headline figure).

    .venv/bin/python benchmarks/bench_sim.py [--duration 60] [--rate 500] [--profile]
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

from wholearm_tools.sim import list_scenarios, load_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--rate", type=float, default=500.0)
    ap.add_argument("--profile", action="store_true", help="cProfile the well_junction run")
    args = ap.parse_args()
    names = ["well_junction"] + [n for n in list_scenarios() if n != "well_junction"]
    for name in names:
        sc = load_scenario(name)
        prof = cProfile.Profile() if args.profile and name == "well_junction" else None
        t0 = time.perf_counter()
        if prof:
            prof.enable()
        res = sc.simulate(duration=args.duration, rate=args.rate)
        if prof:
            prof.disable()
        wall = time.perf_counter() - t0
        c = res.contact_counts()
        print(f"{name:<14} {args.duration:5.0f} s arm @ {args.rate:.0f} Hz: {wall:6.2f} s wall "
              f"({res.run.log.n_samples} samples, {len(res.moves)} moves, "
              f"{res.truth.n_contacts} contacts: tip {c['tip']} joint {c['joint']} "
              f"body {c['body']}; {res.clearance_evals} clearance evaluations)", flush=True)
        if prof:
            pstats.Stats(prof).sort_stats("tottime").print_stats(12)


if __name__ == "__main__":
    main()
