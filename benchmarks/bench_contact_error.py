"""How far a detected contact lies from the surface it touched: the error model of the readings.

For every scenario × seed: detect the contacts, pair each with its true contact event, and, for
the detections on the right link, place the true reading at the detected (settled)
configuration: the link's outer sphere for a tip or joint contact, its side for a body contact.
Its clearance from the true surface the event touched, minus the contact radius, is the error
the reconstruction has to absorb: encoder noise and link geometry on the kinematic engine; soft
contacts' penetration, a bore's convex tiles and contacts on no listed surface (an edge, a
post's end cap) on the physics engine.  The table gives the ``|error|`` percentiles per scenario
and per kind, the signed mean (negative: inside the surface) and the share beyond 1 mm.

A second table gives the angle the approach eq. (2) reads (``qd_before``) makes with the surface
at the true contact point: the cosine of that point's velocity, as a point of the link, with the
surface's normal into the surface (a body contact's velocity along its link left out).  Eq. (2)
weighs where on the arm a contact lies by ``(n·v)+``; a cosine near 0 or below is a contact
met at a grazing angle or read from a motion that did not lead into it (a slide, a rebound).

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


def _approach_cosine(robot, q, qd, link: int, kind: str, point, a, b, surface) -> float:
    """Cosine of the approach velocity with the normal into ``surface`` at ``point``; NaN where
    the link did not move there.  The velocity is that of the touching feature's centre (the
    outer sphere's, or the axis point under ``point`` for the side, its motion along the link
    left out): the feature's rolling adds nothing along the normal."""
    axis = b - a
    length = float(np.linalg.norm(axis))
    u = axis / length
    s = 1.0 if kind != "body" else float(np.clip(np.dot(point - a, u) / length, 0.0, 1.0))
    v = robot.point_velocities(q, qd, link, s)[: surface.dim]
    if kind == "body":
        v = v - np.dot(v, u) * u
    normal = np.asarray(surface.gradient(np.asarray(point)[None])).reshape(-1)
    normal = normal / np.linalg.norm(normal)
    if np.dot(normal, a + s * axis - point) < 0:
        normal = -normal          # from the surface towards the arm
    speed = float(np.linalg.norm(v))
    return -float(np.dot(v, normal)) / speed if speed > 1e-9 else float("nan")


def contact_errors(run) -> list[tuple[str, float, float]]:
    """``(kind, signed error [m], approach cosine)`` of every detection paired on its true
    link."""
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
        point = np.asarray(truth.contact_point[j], dtype=float)[: surface.dim]
        cosine = _approach_cosine(robot, contacts.q[i], contacts.qd_before[i], link, kind,
                                  point, a, b, surface)
        out.append((kind, float(abs(clear) - robot.contact_radius(link, kind != "body")),
                    cosine))
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
    cos_scenario: dict[str, list[float]] = {}
    cos_kind: dict[str, list[float]] = {}
    for name in args.scenarios.split(","):
        for seed in args.seeds:
            for kind, err, cosine in contact_errors(get_run(name, seed, args)):
                by_scenario.setdefault(name, []).append(err)
                by_kind.setdefault(kind, []).append(err)
                if np.isfinite(cosine):
                    cos_scenario.setdefault(name, []).append(cosine)
                    cos_kind.setdefault(kind, []).append(cosine)
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
    print("\n# cosine of the approach with the normal into the true surface at the true point")
    print(f"{'':<16} {'n':>6} {'p10':>7} {'p25':>7} {'median':>7} {'< 0':>7} {'< 0.1':>7}")
    for label, cos in [*cos_scenario.items(), *sorted(cos_kind.items()),
                       ("all", [c for v in cos_scenario.values() for c in v])]:
        c = np.asarray(cos)
        if len(c):
            p10, p25, p50 = np.percentile(c, (10, 25, 50))
            print(f"{label:<16} {len(c):>6} {p10:>7.2f} {p25:>7.2f} {p50:>7.2f} "
                  f"{np.mean(c < 0):>7.3f} {np.mean(c < 0.1):>7.3f}")


if __name__ == "__main__":
    main()
