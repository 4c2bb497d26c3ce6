"""Contact events: detection, link identification and tip/link labels against ground truth.

For every scenario × seed, a run is simulated with the chosen engine (``--engine physics``:
MuJoCo with friction, soft contacts, joint friction; ``kinematic``: the idealised engine), its
contacts detected from the joint signals alone and classified by eq. (2), and the detections
paired with the true contact events (:func:`wholearm_tools.contacts.match_events`: intervals
first obstruction → release; a detection whose link was in contact where it settled pairs
with that contact or nothing, so a contact split in two costs precision).  Per run:

* ``events`` true contact events; ``stop`` those that stopped the arm (blocked a commanded
  motion); ``det`` detections;
* ``recall``: stopping events paired with a detection / ``stop``;
* ``stops``: the arm's stops against contact (the stopping events that share one settled
  configuration: the arm can be held by two contacts at once); ``s.rec``: stops with a
  detection paired to one of their events / ``stops``.  One stop gives one configuration and
  the joint signals name one link for it, so a stop held by two contacts counts as one
  detection and one miss in ``recall``;
* ``prec``: detections paired with a true event (stopping or not) / ``det``;
* ``link``: paired detections whose link is the true event's link; ``group``: whose true link
  is among the candidates the joint signals leave (a rigid group; the fitted map decides);
* ``lab``: tip/link labels right (tip or joint sphere = tip, side = link) among the paired
  detections on the right link that eq. (2) decided; a label is right when the named link
  touched that way at the settled configuration (its paired event, or another true event on
  that link in contact then: a tip held on one surface while the side rests on an edge makes
  both labels true); ``amb``: share left ambiguous.

Last, how often the named link is right by its share ``p_link`` (contacts.csv), over the
detections whose rigid group left several links: a calibrated share is right that often.

The last rows give each column's total over the runs and its spread (min-max over seeds).
Physics parameters can be swept (``--friction``, ``--joint-friction`` as a fraction of the
effort limit, ``--gravity``) to check that the figures hold beyond the defaults, and the log
rate lowered (``--rate``, Hz) to the 50-100 Hz real rigs often log at, on a clock that
ticks irregularly and loses samples as theirs do (``--log-jitter``, ``--log-drop``), and
the joints read through compliant transmissions (``--joint-compliance``, rad at the effort
limit).

Run:  .venv/bin/python benchmarks/bench_events.py --engine physics --seeds 0-9
      [--scenarios paper_spatial,well_junction] [--friction 1.0] [--joint-friction 0.05]
      [--gravity] [--rate 50] [--log-jitter 0.05 --log-drop 0.0065] [--joint-compliance 0.001]
      [--duration 60] [--cache DIR] [--list]
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import time
import warnings
from pathlib import Path

import numpy as np

from wholearm_tools.classify import tip_probability
from wholearm_tools.contacts import arm_stops, detect_contacts, in_contact_at, match_events
from wholearm_tools.logs import read_run, write_run
from wholearm_tools.sim.scenarios import list_scenarios, load_scenario


def seeds_arg(text: str) -> list[int]:
    if "-" in text:
        a, b = (int(x) for x in text.split("-"))
        return list(range(a, b + 1))
    return [int(x) for x in text.split(",")]


def get_run(name: str, seed: int, args: argparse.Namespace):
    """The run, simulated (or read back from ``--cache``, keyed by every parameter; a physics
    run cached by another MuJoCo release is simulated again)."""
    sc = load_scenario(name)
    physics = None
    tag = f"{name}_{seed}_{args.engine}_{args.duration or 'd'}"
    if args.rate is not None:
        tag += f"_{args.rate:g}Hz"
    if args.engine == "physics":
        physics = sc.physics
        changes = {}
        if args.friction is not None:
            changes["friction"] = args.friction
        if args.joint_friction is not None:
            changes["joint_friction"] = args.joint_friction
        if args.gravity:
            changes["gravity"] = True
        for key in ("joint_compliance", "joint_backlash", "log_jitter", "log_drop"):
            if getattr(args, key) is not None:
                changes[key] = getattr(args, key)
        physics = dataclasses.replace(physics, **changes)
        tag += "_" + "_".join(f"{k}{v}" for k, v in sorted(changes.items()))
    path = Path(args.cache) / f"{tag}.mcap" if args.cache else None
    run = read_run(path) if path is not None and path.exists() else None
    if run is not None and args.engine == "physics":
        import mujoco

        # another MuJoCo release integrates the same scenario and seed to another run
        if run.truth is None or run.truth.meta.get("mujoco") != mujoco.__version__:
            run = None
    if run is None:
        kw = {"physics": physics} if physics is not None else {}
        run = sc.simulate(seed=seed, duration=args.duration, rate=args.rate, engine=args.engine,
                          **kw).run
        if path is not None:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_run(path, run)
    told = {k: getattr(args, k) for k in ("joint_compliance", "joint_backlash")
            if getattr(args, k)} if args.known_compliance else {}
    if told:
        # the analysis told the drives' compliance and play, as a datasheet would
        run = dataclasses.replace(run, robot=dataclasses.replace(run.robot, **told))
    return run


TOL = 0.05  # seconds: how far apart a detection and a true event may be and still meet


def score(run, B: float) -> dict:
    contacts = detect_contacts(run.log, run.robot)
    cls = tip_probability(run, contacts, B)
    truth = run.truth
    mi = match_events(contacts, truth, tol=TOL)
    ok = mi >= 0
    stopped = np.asarray(truth.contact_stopped, dtype=bool)
    hit = np.zeros(truth.n_contacts, dtype=bool)
    hit[mi[ok]] = True
    stops = arm_stops(truth)
    true_link = np.where(ok, truth.contact_link[np.maximum(mi, 0)], -1)
    link_ok = ok & (np.asarray(contacts.link) == true_link)
    prior = np.asarray(contacts.link_prior)
    # detections whose rigid group left several links, with the named link's share
    multi = ok & (np.count_nonzero(prior > 0, axis=1) >= 2)
    p_link = contacts.p_link
    in_group = ok & (prior[np.arange(len(contacts)), np.maximum(true_link, 0)] > 0)
    lab = np.asarray(cls.label)
    decided = link_ok & (lab != "ambiguous")
    # a label describes the settled configuration: where the named link touched with its tip
    # and its side at once (a tip on one surface, the side on an edge), either label is right
    there = in_contact_at(contacts.t_settle, contacts.link, truth, tol=TOL)
    there[np.flatnonzero(ok), mi[ok]] = True
    is_tip = np.asarray(truth.is_tip, dtype=bool)[None]
    right = decided & np.where(lab == "tip", (there & is_tip).any(1), (there & ~is_tip).any(1))
    return {"events": truth.n_contacts, "stop": int(stopped.sum()), "det": len(contacts),
            "found": int((hit & stopped).sum()), "paired": int(ok.sum()),
            "stops": len(stops), "stops_found": sum(bool(hit[g].any()) for g in stops),
            "link_ok": int(link_ok.sum()), "in_group": int(in_group.sum()),
            "decided": int(decided.sum()),
            "right": int(right.sum()), "amb": int((link_ok & (lab == "ambiguous")).sum()),
            "shares": [(float(p_link[i]), bool(link_ok[i])) for i in np.flatnonzero(multi)],
            "missed": [(round(float(truth.contact_t[j]), 3), int(truth.contact_link[j]),
                        str(truth.contact_kind[j])) for j in np.flatnonzero(stopped & ~hit)],
            "false": [(round(float(contacts.t[i]), 3), int(contacts.link[i]))
                      for i in np.flatnonzero(~ok)],
            "wrong_link": [(round(float(contacts.t[i]), 3), int(contacts.link[i]),
                            int(truth.contact_link[mi[i]]), str(truth.contact_kind[mi[i]]))
                           for i in np.flatnonzero(ok & ~link_ok)]}


def rate(a: int, b: int) -> float:
    return a / b if b else float("nan")


def add_run_options(ap: argparse.ArgumentParser, engine: str) -> None:
    """The options :func:`get_run` reads: engine, arm time, physics sweeps, run cache."""
    ap.add_argument("--engine", default=engine, choices=["physics", "kinematic"])
    ap.add_argument("--duration", type=float, default=None, help="arm seconds (scenario's)")
    ap.add_argument("--rate", type=float, default=None,
                    help="log rate in Hz (scenario's, 500; rigs often log at 50-100)")
    ap.add_argument("--friction", type=float, default=None)
    ap.add_argument("--joint-friction", type=float, default=None)
    ap.add_argument("--gravity", action="store_true")
    ap.add_argument("--joint-compliance", type=float, default=None,
                    help="[physics] transmission deflection at the effort limit, rad (~0.001)")
    ap.add_argument("--joint-backlash", type=float, default=None,
                    help="[physics] transmission lost motion, rad (gearboxes 0.0003-0.004)")
    ap.add_argument("--known-compliance", "--known-drives", dest="known_compliance",
                    action="store_true",
                    help="[physics] give the analysis the simulated --joint-compliance and "
                         "--joint-backlash (a datasheet's): contacts at the links' angles")
    ap.add_argument("--log-jitter", type=float, default=None,
                    help="[physics] relative std of each log interval (a rig's clock; ~0.05)")
    ap.add_argument("--log-drop", type=float, default=None,
                    help="[physics] share of log samples lost (a rig's logger; ~0.007)")
    ap.add_argument("--cache", default=None, help="folder to keep simulated runs in")


def scenarios_parser(doc: str, engine: str, seeds: str) -> argparse.ArgumentParser:
    """A benchmark over scenarios × seeds: ``--seeds``, ``--scenarios`` (every bundled one by
    default) and the run options of :func:`add_run_options`."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--seeds", default=seeds, type=seeds_arg)
    ap.add_argument("--scenarios", default=",".join(list_scenarios()))
    add_run_options(ap, engine)
    return ap


def main() -> None:
    ap = scenarios_parser(__doc__, "physics", "0-2")
    ap.add_argument("--list", action="store_true", help="list missed, false and wrong-link")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    rows = []
    for name in args.scenarios.split(","):
        B = float(load_scenario(name).hints.get("B", 0.02))
        for seed in args.seeds:
            run = get_run(name, seed, args)
            t0 = time.perf_counter()
            s = score(run, B)
            s.update(scenario=name, seed=seed, time=time.perf_counter() - t0)
            rows.append(s)
            print(f"# {name} seed {seed}: {s['events']} events ({s['stop']} stopped), "
                  f"{s['det']} detections, {s['time']:.1f} s", flush=True)
            if args.list:
                print(f"    missed {s['missed']}\n    false {s['false']}\n"
                      f"    wrong link {s['wrong_link']}")
    hdr = (f"{'scenario':<14}{'seed':>5}{'events':>7}{'stop':>5}{'det':>5}{'recall':>8}"
           f"{'stops':>6}{'s.rec':>7}{'prec':>7}{'link':>7}{'group':>7}{'lab':>7}{'amb':>7}")
    print("\n" + hdr)

    def line(label: str, seed: str, rs: list[dict]) -> str:
        tot = {k: sum(r[k] for r in rs) for k in ("events", "stop", "det", "found", "paired",
                                                 "link_ok", "in_group", "decided", "right",
                                                 "amb", "stops", "stops_found")}
        return (f"{label:<14}{seed:>5}{tot['events']:>7}{tot['stop']:>5}{tot['det']:>5}"
                f"{rate(tot['found'], tot['stop']):>8.3f}{tot['stops']:>6}"
                f"{rate(tot['stops_found'], tot['stops']):>7.3f}"
                f"{rate(tot['paired'], tot['det']):>7.3f}"
                f"{rate(tot['link_ok'], tot['paired']):>7.3f}"
                f"{rate(tot['in_group'], tot['paired']):>7.3f}"
                f"{rate(tot['right'], tot['decided']):>7.3f}"
                f"{rate(tot['amb'], tot['link_ok']):>7.3f}")

    for r in rows:
        print(line(r["scenario"], str(r["seed"]), [r]))
    print("-" * len(hdr))
    for name in dict.fromkeys(r["scenario"] for r in rows):
        print(line(name, "all", [r for r in rows if r["scenario"] == name]))
    print(line("all", "all", rows))
    cols = {"recall": ("found", "stop"), "s.rec": ("stops_found", "stops"),
            "prec": ("paired", "det"),
            "link": ("link_ok", "paired"), "group": ("in_group", "paired"),
            "lab": ("right", "decided"), "amb": ("amb", "link_ok")}
    spread = []
    for c, (a, b) in cols.items():
        v = [rate(r[a], r[b]) for r in rows if r[b]]
        spread.append(f"{c} {min(v):.3f}-{max(v):.3f}" if v else f"{c} -")
    print("spread over runs: " + ", ".join(spread))
    print_share_calibration([x for r in rows for x in r["shares"]])


#: bins of the named link's share within a rigid group (p_link of contacts.csv)
SHARE_BINS = (0.0, 0.55, 0.65, 0.75, 0.85, 0.95, 1.0 + 1e-9)


def print_share_calibration(shares: list[tuple[float, bool]]) -> None:
    """How often the named link is right, by its share, over the detections whose rigid
    group left several links: a calibrated share is right that often."""
    if not shares:
        return
    p = np.array([s for s, _ in shares])
    ok = np.array([r for _, r in shares])
    cells = []
    for lo, hi in itertools.pairwise(SHARE_BINS):
        sel = (p >= lo) & (p < hi)
        n = int(sel.sum())
        cells.append(f"[{lo:.2f},{min(hi, 1.0):.2f}) {rate(int(ok[sel].sum()), n):.2f} of {n}")
    print(f"link right by p_link, {len(p)} detections left among a rigid group's links "
          f"(right {ok.mean():.3f}): " + "; ".join(cells))


if __name__ == "__main__":
    main()
