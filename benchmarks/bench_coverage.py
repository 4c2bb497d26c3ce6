"""Environment coverage of the bundled scenarios: per scenario × seed, contacts by kind and, per
surface, the count (tip/joint/body) and spread (see ``wholearm_tools.sim.coverage``).

    .venv/bin/python benchmarks/bench_coverage.py [--seeds 0-4] [--scenario NAME ...]
        [--duration S] [--jobs 2]

A surface is flagged ``LOW`` when it has fewer than 10 contacts.  The default duration is each
scenario's own default.
"""

from __future__ import annotations

import argparse
import time
from concurrent.futures import ProcessPoolExecutor

from wholearm_tools.sim import list_scenarios, load_scenario
from wholearm_tools.sim.coverage import kind_counts, surface_coverage


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            out.extend(range(int(a), int(b) + 1))
        else:
            out.append(int(part))
    return out


def _one(name: str, seed: int, duration: float | None) -> str:
    sc = load_scenario(name)
    t0 = time.perf_counter()
    res = sc.simulate(seed=seed, duration=duration)
    wall = time.perf_counter() - t0
    truth = res.truth
    k = kind_counts(truth)
    dur = sc.duration if duration is None else duration
    lines = [f"{name} seed {seed}: {truth.n_contacts} contacts (tip {k['tip']} / joint "
             f"{k['joint']} / body {k['body']}), {len(res.moves)} moves, {dur:.0f} s arm, "
             f"{wall:.1f} s wall"]
    for cov in surface_coverage(truth):
        flag = "  LOW" if cov.count < 10 else ""
        lines.append(f"    {cov.id} {cov.type:<8} {cov.count:3d} ({cov.tip:2d}/{cov.joint:2d}/"
                     f"{cov.body:2d})  {cov.spread()}{flag}")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0-4", help="e.g. 0-4 or 0,3,7")
    ap.add_argument("--scenario", action="append", help="scenario name (repeatable)")
    ap.add_argument("--duration", type=float, default=None)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    names = args.scenario or list_scenarios()
    jobs = [(n, s) for n in names for s in _seeds(args.seeds)]
    print("per surface: id type count (tip/joint/body) spread")
    if args.jobs <= 1:
        for n, s in jobs:
            print(_one(n, s, args.duration), flush=True)
        return
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futs = [pool.submit(_one, n, s, args.duration) for n, s in jobs]
        for f in futs:
            print(f.result(), flush=True)


if __name__ == "__main__":
    main()
