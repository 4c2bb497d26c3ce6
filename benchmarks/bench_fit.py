"""Primitive-fit benchmark: wholearm_tools.fit (CasADi/IPOPT) vs scipy.optimize.least_squares.

Tip-only problems with 30, 300 and 3,000 noisy contacts (sigma = 1 mm, tip radius 2 cm) on a
circle, sphere, cylinder and plane.  Both solvers start from the same perturbed parameters (5 %
on lengths, ~3 degrees on directions).  Our time is warm (the graph for the problem shape is
built by a first call and reused, as in a pipeline); scipy uses 'trf' with its default
finite-difference Jacobian on a singularity-free parameterisation (angles for unit vectors).
The error column is the largest error of the identifiable parameters (metres / radians).

Run:  .venv/bin/python benchmarks/bench_fit.py
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "fit"))
from fit_synth import contacts, param_error, truth

from wholearm_tools.fit import fit_primitive

KINDS = ("circle", "sphere", "cylinder", "plane")
SIZES = (30, 300, 3000)
W = 0.02
NOISE = 0.001


def _sph(v):
    v = v / np.linalg.norm(v)
    return np.array([np.arccos(np.clip(v[2], -1, 1)), np.arctan2(v[1], v[0])])


def _vec(a):
    return np.array([np.sin(a[0]) * np.cos(a[1]), np.sin(a[0]) * np.sin(a[1]), np.cos(a[0])])


def _perturb(kind, p):
    q = dict(p)
    rot = np.array([0.05, -0.03, 0.04])
    for key in ("normal", "axis"):
        if key in q:
            v = q[key] + rot[: len(q[key])]
            q[key] = v / np.linalg.norm(v)
    for key in ("radius",):
        if key in q:
            q[key] = 1.05 * q[key]
    for key in ("center", "point"):
        if key in q:
            q[key] = q[key] + 0.02
    return q


def _scipy_fit(kind, p0, pts, side):
    if kind in ("circle", "sphere"):
        x0 = np.concatenate([p0["center"], [p0["radius"]]])
        d = len(p0["center"])

        def f(x):
            return side * (np.linalg.norm(pts - x[:d], axis=1) - x[d]) - W

        x = least_squares(f, x0, method="trf").x
        return {"center": x[:d], "radius": x[d]}
    if kind == "plane":
        x0 = np.concatenate([_sph(p0["normal"]), [p0["point"] @ p0["normal"]]])

        def f(x):
            return pts @ _vec(x[:2]) - x[2] - W

        x = least_squares(f, x0, method="trf").x
        n = _vec(x[:2])
        return {"point": x[2] * n, "normal": n}
    # cylinder: axis angles, point = u*a + v*b in the plane normal to the axis, radius
    ax0 = p0["axis"]

    def basis(a):
        e = np.eye(3)[int(np.argmin(np.abs(a)))]
        u = np.cross(a, e)
        u /= np.linalg.norm(u)
        return u, np.cross(a, u)

    u0, v0 = basis(ax0)
    x0 = np.concatenate([_sph(ax0), [p0["point"] @ u0, p0["point"] @ v0, p0["radius"]]])

    def f(x):
        a = _vec(x[:2])
        u, v = basis(a)
        c = x[2] * u + x[3] * v
        q = pts - c
        rho = np.linalg.norm(q - np.outer(q @ a, a), axis=1)
        return side * (rho - x[4]) - W

    x = least_squares(f, x0, method="trf").x
    a = _vec(x[:2])
    u, v = basis(a)
    return {"point": x[2] * u + x[3] * v, "axis": a, "radius": x[4]}


def _time(fn, repeats):
    best = []
    out = None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best.append(time.perf_counter() - t0)
    return float(np.median(best)), out


def main() -> None:
    rows = []
    for kind in KINDS:
        for n in SIZES:
            rng = np.random.default_rng(n)
            p = truth(kind, rng)
            side = 1
            data = contacts(kind, p, n, 0, side, rng, w_tip=W, noise=NOISE)
            p0 = _perturb(kind, p)
            expected = p
            reps = 5 if n <= 300 else 3
            fit_primitive(kind, data, free_side=side, initial=p0)  # build the graph
            t_ours, res = _time(lambda k=kind, d=data, q=p0, s=side: fit_primitive(
                k, d, free_side=s, initial=q), reps)
            t_sp, sp = _time(lambda k=kind, q=p0, d=data, s=side: _scipy_fit(
                k, q, np.asarray(d.tip_points), s), reps)
            rows.append((kind, n, t_ours * 1e3, param_error(kind, res.params, expected),
                         t_sp * 1e3, param_error(kind, sp, expected), res.iterations))
    print(f"{'type':9s} {'N':>5s} | {'ours ms':>8s} {'ours err':>9s} {'iters':>5s} | "
          f"{'scipy ms':>8s} {'scipy err':>9s}")
    for kind, n, to, eo, ts, es, it in rows:
        print(f"{kind:9s} {n:5d} | {to:8.2f} {eo:9.2e} {it:5d} | {ts:8.2f} {es:9.2e}")


if __name__ == "__main__":
    main()
