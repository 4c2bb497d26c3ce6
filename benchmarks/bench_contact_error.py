"""How far a detected contact lies from the surface it touched: the error model of the readings.

For every scenario × seed: detect the contacts, pair each with its true contact event, and, for
the detections on the right link, place the true reading at the detected (settled)
configuration: the link's outer sphere for a tip or joint contact, its side for a body contact.
Its clearance from the true surface the event touched, minus the contact radius, is the error
the reconstruction has to absorb: encoder noise and link geometry on the kinematic engine; soft
contacts' penetration, a bore's convex tiles and contacts on no listed surface (an edge, a
post's end cap) on the physics engine.  The table gives the ``|error|`` percentiles per scenario
and per kind, the signed mean (negative: inside the surface) and the share beyond 1 mm.

Run:  .venv/bin/python benchmarks/bench_contact_error.py [--engine physics] [--seeds 0-9]
      [--scenarios ...] [--cache DIR]
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np

from wholearm_tools.contacts import detect_contacts, match_events
from wholearm_tools.geometry.base import primitive_from_dict

PERCENTILES = (50, 90, 95, 99)


def contact_errors(run) -> list[tuple[str, float]]:
    """``(kind, signed error [m])`` of every detection paired on its true link."""
    robot, truth = run.robot, run.truth
    surfaces = {int(s["id"]): primitive_from_dict(s) for s in truth.surfaces}
    contacts = detect_contacts(run.log, robot)
    pair = match_events(contacts, truth)
    out = []
    for i in np.flatnonzero(pair >= 0):
        j = int(pair[i])
        link, kind = int(truth.contact_link[j]), str(truth.contact_kind[j])
        surface = surfaces.get(int(truth.contact_surface[j]))
        if contacts.link[i] != link or surface is None:
            continue
        a, b = (p[link, : surface.dim] for p in robot.link_segments(contacts.q[i]))
        if kind == "body":
            # the side's clearance, measured from whichever side of the surface it lies on
            clear = min((surface.segment_signed_distance(a[None], b[None], free_side=fs)[0][0]
                         for fs in (1.0, -1.0)), key=abs)
        else:
            clear = float(np.asarray(surface.distance(b[None])).reshape(-1)[0])
        out.append((kind, float(abs(clear) - robot.contact_radius(link, kind != "body"))))
    return out


def row(label: str, errors: list[float]) -> str:
    e = np.asarray(errors) * 1e3
    if not len(e):
        return f"{label:<16} {0:>6}"
    pct = np.percentile(np.abs(e), PERCENTILES)
    return (f"{label:<16} {len(e):>6} " + " ".join(f"{p:>9.3f}" for p in pct)
            + f" {e.mean():>9.3f} {np.mean(np.abs(e) > 1.0):>8.3f}")


def main() -> None:
    sys.path.insert(0, str(Path(__file__).parent))
    from bench_events import get_run, scenarios_parser

    args = scenarios_parser(__doc__, "kinematic", "0-9").parse_args()
    warnings.simplefilter("ignore")
    by_scenario: dict[str, list[float]] = {}
    by_kind: dict[str, list[float]] = {}
    for name in args.scenarios.split(","):
        for seed in args.seeds:
            for kind, err in contact_errors(get_run(name, seed, args)):
                by_scenario.setdefault(name, []).append(err)
                by_kind.setdefault(kind, []).append(err)
    print(f"# contact error at the settled configuration, engine {args.engine}, "
          f"seeds {args.seeds[0]}-{args.seeds[-1]} (mm)")
    head = (f"{'':<16} {'n':>6} " + " ".join(f"{'p' + str(p):>9}" for p in PERCENTILES)
            + f" {'mean':>9} {'>1 mm':>8}")
    print(head)
    for name, errors in by_scenario.items():
        print(row(name, errors))
    for kind, errors in sorted(by_kind.items()):
        print(row(kind, errors))
    print(row("all", [e for v in by_scenario.values() for e in v]))


if __name__ == "__main__":
    main()
