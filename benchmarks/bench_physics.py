"""Physics engine: speed and what its contacts look like, per bundled scenario and seed, with the
kinematic engine's time for the same runs beside it.

    .venv/bin/python benchmarks/bench_physics.py [--duration 240] [--seeds 0 1 2]
        [--scenarios lab_circle ...] [--no-kinematic]

Columns (default physics parameters, the scenario's own settings otherwise):
  wall      wall time of the physics run [s] (target: 240 s of arm time in <= 60 s)
  cpu       CPU time of the physics run [s] (what wall time is on an idle core)
  kin       wall time of the kinematic engine on the same scenario, seed and duration [s]
  moves     guarded moves of the physics run (kmoves: of the kinematic run)
  tip/joint/body  contact events by kind (where they settled)
  stop%     share of events that stopped the arm (blocked a commanded motion)
  dur       median event duration, first touch to release [s]
  slid      events whose contact point moved more than 5 mm from where it first touched
  rebound   events that separated (wider than sim.physics.REBOUND_GAP) and touched again
  F50       median peak normal force [N]
  pen       median deepest penetration of the soft contacts [mm]
  dev       largest deviation of the simulated surfaces from the ideal ones [mm]
The last rows give the totals over every run.  Wall times depend on what else runs on the
machine: run it when it is quiet and say what else was running.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from wholearm_tools.sim import list_scenarios, load_scenario

SLIDE = 0.005  # an event slid when its contact point moved more than this [m]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=240.0)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--scenarios", nargs="+", default=None)
    ap.add_argument("--no-kinematic", action="store_true",
                    help="skip the kinematic engine's runs")
    args = ap.parse_args()
    names = args.scenarios or list_scenarios()
    print(f"{args.duration:.0f} s of arm time per run; load average before: "
          f"{os.getloadavg()[0]:.2f}", flush=True)
    head = (f"{'scenario':<14}{'seed':>5}{'wall':>7}{'cpu':>6}{'kin':>6}{'moves':>6}"
            f"{'kmoves':>7}{'tip':>5}{'joint':>6}{'body':>5}{'stop%':>6}{'dur':>6}{'slid':>5}{'rebound':>8}"
            f"{'F50':>7}{'pen':>6}{'dev':>6}")
    print(head)
    print("-" * len(head))
    totals: dict[str, list[float]] = {"wall": [], "cpu": [], "kin": [], "events": [], "stopped": [],
                                      "slid": [], "rebound": [], "dur": []}
    for name in names:
        sc = load_scenario(name)
        for seed in args.seeds:
            t0, c0 = time.perf_counter(), time.process_time()
            res = sc.simulate(engine="physics", seed=seed, duration=args.duration)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            kin, kmoves = float("nan"), -1
            if not args.no_kinematic:
                t0 = time.perf_counter()
                kmoves = len(sc.simulate(seed=seed, duration=args.duration).moves)
                kin = time.perf_counter() - t0
            truth = res.truth
            ev = res.stats["events"]
            kinds = truth.contact_kind.tolist()
            m = truth.n_contacts
            dur = truth.contact_duration
            slid = int(np.count_nonzero(ev["slide"] > SLIDE))
            rebound = int(np.count_nonzero(ev["rebounds"] > 0))
            stopped = int(truth.contact_stopped.sum())
            dev = max(res.stats["deviation"].values(), default=0.0)
            print(f"{name:<14}{seed:>5}{wall:>7.1f}{cpu:>6.1f}{kin:>6.1f}{len(res.moves):>6}{kmoves:>7}"
                  f"{kinds.count('tip'):>5}{kinds.count('joint'):>6}{kinds.count('body'):>5}"
                  f"{100 * stopped / max(m, 1):>6.0f}"
                  f"{(np.median(dur) if m else float('nan')):>6.2f}{slid:>5}{rebound:>8}"
                  f"{(np.median(truth.contact_force) if m else float('nan')):>7.0f}"
                  f"{(1e3 * np.median(ev['depth']) if m else float('nan')):>6.2f}"
                  f"{1e3 * dev:>6.2f}", flush=True)
            totals["wall"].append(wall)
            totals["cpu"].append(cpu)
            totals["kin"].append(kin)
            totals["events"].append(m)
            totals["stopped"].append(stopped)
            totals["slid"].append(slid)
            totals["rebound"].append(rebound)
            totals["dur"].extend(dur.tolist())
    events = sum(totals["events"])
    print("-" * len(head))
    print(f"{len(totals['wall'])} runs: physics wall median {np.median(totals['wall']):.1f} s, "
          f"max {np.max(totals['wall']):.1f} s (CPU max {np.max(totals['cpu']):.1f} s); "
          f"kinematic median "
          f"{np.median(totals['kin']):.1f} s; {events:.0f} events, "
          f"{100 * sum(totals['stopped']) / max(events, 1):.0f} % stopped the arm, "
          f"median duration {np.median(totals['dur']) if events else float('nan'):.2f} s, "
          f"{sum(totals['slid']):.0f} slid, {sum(totals['rebound']):.0f} rebounded; "
          f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
