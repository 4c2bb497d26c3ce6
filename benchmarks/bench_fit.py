"""Primitive-fit benchmark: wholearm_tools.fit against scipy and pyransac3d.

Two sections (``--section speed|robust|all``, default all).

**speed** — every primitive type (line, circle, plane, sphere, cylinder, cone, torus) on
problems of 30, 300 and 3,000 residuals, each twice: tip contacts only (``tip``), and one
third link contacts (``mixed``: capsule bodies tangent to the surface, contact point unknown).
Contacts carry 1 mm noise (tip radius 2 cm, link radius 3 cm, free space outside).  Both
solvers start from the same perturbed truth (5 % on lengths and angles, 2 cm on points,
about 3.5 degrees on directions) and minimise the same sum of squares:

* ours: ``fit_primitive(kind, data, free_side=+1, initial=start, covariance=False)``
  (Levenberg-Marquardt on the minimal parameterisation, CasADi-generated Jacobians; the
  covariance is off because scipy does not compute one either);
* scipy: ``least_squares`` (``--scipy-method``, default ``trf``; its default two-point
  finite-difference Jacobian) on an unconstrained minimal parameterisation: points and
  scalars as they are, a unit vector as ``normalise(a0 + x u0 + y v0)`` about its start
  ``a0`` (``u0, v0`` perpendicular to it), and the gauge of a point on an axis or a plane fixed
  by moving it only across the start axis / along the start normal.  A link residual is posed
  the same way as ours, by variable projection: ``min_t clearance(a + t (b - a)) - w``,
  computed per evaluation by the geometry module (``Primitive._segment``: closed form for
  lines, planes, circles, spheres and cylinders, a vectorised numeric minimum for cones and
  tori), so scipy optimises only the primitive's parameters too.

Each problem is timed ``--repeats`` times, ours and scipy alternating; the table gives the
median wall time, its spread (min-max) and the median process (CPU) time, in ms; ``it`` our
iterations, ``nfev`` scipy's residual evaluations (not counting its finite differences);
``ratio`` ours / scipy of the median wall and CPU times.  ``err`` is the largest error of the
identifiable parameters against the truth (metres / radians); ``apart`` the same measure
between the two solutions (both found the same optimum when it is far below ``err``).

**robust** — 500 tip points (sharp tip) on a 60-degree arc of a cylinder (radius 0.15 m,
0.5 m long, 0.1 mm noise per coordinate), 10 % of them outliers spread uniformly over the
arc's bounding box grown by 5 cm; ``--draws`` random draws.  No start is given to us:

* ``ours``: ``fit_primitive("cylinder", data, loss="huber")`` (consensus start, inlier scale,
  pseudo-Huber refit; :mod:`wholearm_tools.fit.robust`);
* ``pyransac3d``: ``Cylinder().fit(points, thresh, maxIteration)`` (``--ransac-thresh``,
  ``--ransac-iter``; its sampling uses Python's ``random``, seeded with the draw number);
* ``scipy<-pyransac3d``: ``least_squares(loss="soft_l1", f_scale=2 sigma)`` (the true noise
  given) on the cylinder residual above, started from pyransac3d's cylinder (a RANSAC start,
  as a scipy user without one of ours would do);
* ``scipy<-truth``: the same started from the true cylinder: what the loss itself does with
  the best start there is (a loss that keeps growing with the residual lets every outlier
  pull);
* ``oracle``: least squares on the true inliers only (what no outlier would cost; its error
  is the noise's share).

Radius errors in mm, times in ms (wall); the last rows give the largest and median.

Run:  .venv/bin/python benchmarks/bench_fit.py [--section speed] [--kinds cone torus]
      [--sizes 30 300] [--repeats 7] [--draws 8]
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "fit"))
from fit_synth import contacts, param_error, perturbed, truth

from wholearm_tools.errors import InputError
from wholearm_tools.fit import FitData, fit_primitive
from wholearm_tools.geometry import primitive_type

KINDS = ("line", "circle", "plane", "sphere", "cylinder", "cone", "torus")
SIZES = (30, 300, 3000)
W_TIP, W_LINK = 0.02, 0.03
NOISE = 0.001

#: per type: (name, role) with role "point" (free), "across" (moves across the unit vector
#: that follows it: a point on an axis), "along" (moves along it: a point on a plane or line),
#: "unit", or "scalar"
_LAYOUT = {
    "line": (("point", "along"), ("direction", "unit")),
    "circle": (("center", "point"), ("radius", "scalar")),
    "plane": (("point", "along"), ("normal", "unit")),
    "sphere": (("center", "point"), ("radius", "scalar")),
    "cylinder": (("point", "across"), ("axis", "unit"), ("radius", "scalar")),
    "cone": (("apex", "point"), ("axis", "unit"), ("half_angle", "scalar")),
    "torus": (("center", "point"), ("axis", "unit"), ("major_radius", "scalar"),
              ("minor_radius", "scalar")),
}


# --------------------------------------------------------------------------- scipy side


def _perp(a: np.ndarray) -> list[np.ndarray]:
    """Unit vectors spanning the complement of unit ``a`` (one in 2-D, two in 3-D)."""
    if len(a) == 2:
        return [np.array([-a[1], a[0]])]
    e = np.eye(3)[int(np.argmin(np.abs(a)))]
    u = np.cross(a, e)
    u /= np.linalg.norm(u)
    return [u, np.cross(a, u)]


class ScipyProblem:
    """The fit posed for ``scipy.optimize.least_squares``: an unconstrained minimal vector
    about a start, and the residual ``clearance - w`` of tips and (variable projection) links."""

    def __init__(self, kind: str, start: dict[str, Any], data: FitData, side: float) -> None:
        self.kind, self.side, self.data = kind, float(side), data
        self.cls = primitive_type(kind)
        self.start = {k: np.array(v, dtype=float) if np.ndim(v) else float(v)
                      for k, v in start.items()}
        unit = next((n for n, r in _LAYOUT[kind] if r == "unit"), None)
        self.frame = _perp(self.start[unit] / np.linalg.norm(self.start[unit])) if unit else []
        self.normal = self.start[unit] / np.linalg.norm(self.start[unit]) if unit else None
        if kind == "line":  # the line's point moves along its normal
            d = self.normal
            self.normal = np.array([-d[1], d[0]])
        self.sizes = []
        for name, role in _LAYOUT[kind]:
            dim = np.size(self.start[name])
            self.sizes.append({"point": dim, "across": dim - 1, "along": 1,
                               "unit": dim - 1, "scalar": 1}[role])

    def x0(self) -> np.ndarray:
        return np.zeros(sum(self.sizes))

    def params(self, x: np.ndarray) -> dict[str, Any]:
        out: dict[str, Any] = {}
        k = 0
        for (name, role), n in zip(_LAYOUT[self.kind], self.sizes, strict=True):
            v, k = x[k:k + n], k + n
            s = self.start[name]
            if role == "point":
                out[name] = s + v
            elif role == "across":
                out[name] = s + sum(vi * f for vi, f in zip(v, self.frame, strict=True))
            elif role == "along":
                out[name] = s + v[0] * self.normal
            elif role == "unit":
                u = s / np.linalg.norm(s) + sum(vi * f for vi, f in
                                                 zip(v, self.frame, strict=True))
                out[name] = u / np.linalg.norm(u)
            else:
                out[name] = s + v[0]
        return out

    def residuals(self, x: np.ndarray) -> np.ndarray:
        d = self.data
        try:
            prim = self.cls.from_params(self.params(x))
        except InputError:  # a radius or angle out of range: a large, finite residual
            return np.full(d.n_contacts, 1e3)
        rt = self.side * prim._sd(d.tip_points) - d.tip_radius
        if d.n_link == 0:
            return rt
        val, _ = prim._segment(d.link_a, d.link_b, self.side)
        return np.concatenate([rt, val - d.link_radius])

    def solve(self, method: str = "trf", **kw: Any) -> dict[str, Any]:
        return self.params(least_squares(self.residuals, self.x0(), method=method, **kw).x)


# --------------------------------------------------------------------------- speed section


def _timed(fn: Any) -> tuple[float, float, Any]:
    w0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return time.perf_counter() - w0, time.process_time() - c0, out


def _stats(xs: list[float]) -> tuple[float, float, float]:
    a = np.asarray(xs) * 1e3
    return float(np.median(a)), float(a.min()), float(a.max())


def speed(kinds: list[str], sizes: list[int], repeats: int, method: str) -> None:
    head = (f"{'type':8s} {'mode':5s} {'N':>5s} | {'ours ms':>7s} {'(min-max)':>13s} "
            f"{'cpu':>6s} {'it':>3s} | {'scipy ms':>8s} {'(min-max)':>13s} {'cpu':>6s} "
            f"{'nfev':>4s} | {'ratio':>5s} {'(cpu)':>5s} | {'ours err':>8s} {'scipy err':>9s} "
            f"{'apart':>8s}")
    print(f"speed: ours vs scipy least_squares (method={method}), {repeats} repeats\n")
    print(head)
    print("-" * len(head))
    worst = worst_cpu = 0.0
    for kind in kinds:
        for mode in ("tip", "mixed"):
            for n in sizes:
                rng = np.random.default_rng(n + (7 if mode == "mixed" else 0))
                p = truth(kind, rng)
                n_link = n // 3 if mode == "mixed" else 0
                data = contacts(kind, p, n - n_link, n_link, 1, rng, w_tip=W_TIP,
                                w_link=W_LINK, noise=NOISE)
                p0 = perturbed(p)
                prob = ScipyProblem(kind, p0, data, 1.0)

                def ours(d: FitData = data, k: str = kind, q: dict = p0) -> Any:
                    return fit_primitive(k, d, free_side=1, initial=q, covariance=False)

                ours()  # generated code and caches built once per type, as in a pipeline
                sp = least_squares(prob.residuals, prob.x0(), method=method)
                tw, tc, sw, sc = [], [], [], []
                res = fit = None
                for _ in range(repeats):
                    w, c, res = _timed(ours)
                    tw.append(w)
                    tc.append(c)
                    w, c, fit = _timed(lambda pr=prob: pr.solve(method))
                    sw.append(w)
                    sc.append(c)
                eo = param_error(kind, res.params, p)
                es = param_error(kind, fit, p)
                apart = param_error(kind, res.params, fit)
                (om, olo, ohi), (sm, slo, shi) = _stats(tw), _stats(sw)
                ratio, cpu_ratio = om / sm, _stats(tc)[0] / _stats(sc)[0]
                worst, worst_cpu = max(worst, ratio), max(worst_cpu, cpu_ratio)
                print(f"{kind:8s} {mode:5s} {n:5d} | {om:7.2f} {f'({olo:.2f}-{ohi:.2f})':>13s} "
                      f"{_stats(tc)[0]:6.2f} {res.iterations:3d} | {sm:8.2f} "
                      f"{f'({slo:.2f}-{shi:.2f})':>13s} {_stats(sc)[0]:6.2f} {sp.nfev:4d} | "
                      f"{ratio:5.2f} {cpu_ratio:5.2f} | {eo:8.2e} {es:9.2e} {apart:8.1e}",
                      flush=True)
    print(f"\nlargest ratio ours/scipy of the median times: wall {worst:.2f}, "
          f"CPU {worst_cpu:.2f}")


# --------------------------------------------------------------------------- robust section


def arc_with_outliers(draw: int, n: int = 500, outliers: float = 0.10, radius: float = 0.15,
                      arc_deg: float = 60.0, length: float = 0.5, noise: float = 1e-4
                      ) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    """Points of a ``arc_deg`` arc of a cylinder (random axis and centre) with a share of
    outliers uniform over the arc's bounding box grown by 5 cm; returns the points (shuffled),
    whether each is an inlier, and the true cylinder."""
    rng = np.random.default_rng(draw)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    u, v = _perp(axis)
    centre = rng.uniform(-0.5, 0.5, 3)
    n_out = round(outliers * n)
    n_in = n - n_out
    az = rng.uniform(0.0, np.radians(arc_deg), n_in) + rng.uniform(0, 2 * np.pi)
    h = rng.uniform(0.0, length, n_in)
    on = (centre + h[:, None] * axis
          + radius * (np.cos(az)[:, None] * u + np.sin(az)[:, None] * v))
    on += noise * rng.normal(size=on.shape)
    lo, hi = on.min(axis=0) - 0.05, on.max(axis=0) + 0.05
    out = rng.uniform(lo, hi, (n_out, 3))
    pts = np.vstack([on, out])
    inlier = np.arange(n) < n_in
    perm = rng.permutation(n)
    return pts[perm], inlier[perm], {"point": centre, "axis": axis, "radius": radius}


def robust(draws: int, thresh: float, iters: int, noise: float = 1e-4) -> None:
    import pyransac3d

    print("\nrobust: 500 points of a 60-degree cylinder arc (r 0.15 m, noise 0.1 mm), "
          f"10 % outliers, no start given; pyransac3d thresh {thresh * 1e3:g} mm, "
          f"{iters} iterations; scipy soft_l1 f_scale 2 sigma (true sigma)\n")
    cols = ("ours", "pyransac3d", "scipy<-pyransac3d", "scipy<-truth", "oracle")
    head = f"{'draw':>4s} | " + " | ".join(f"{c:>17s} {'ms':>5s}" for c in cols)
    print("radius error [mm] and time [ms, wall] per draw\n")
    print(head)
    print("-" * len(head))
    errs: dict[str, list[float]] = {c: [] for c in cols}
    times: dict[str, list[float]] = {c: [] for c in cols}
    fit_primitive("cylinder", FitData.create(arc_with_outliers(99)[0], 0.0, 1.0, dim=3),
                  loss="huber")  # generated code and caches built once, as in a pipeline
    for draw in range(draws):
        pts, inl, p = arc_with_outliers(draw, noise=noise)
        data = FitData.create(pts, 0.0, 1.0, dim=3)
        row: dict[str, tuple[float, float]] = {}
        t, _, res = _timed(lambda d=data: fit_primitive("cylinder", d, loss="huber"))
        row["ours"] = (abs(res.params["radius"] - p["radius"]) if res else np.inf, t)

        def ransac(x: np.ndarray = pts, seed: int = draw) -> Any:
            random.seed(seed)
            return pyransac3d.Cylinder().fit(x, thresh=thresh, maxIteration=iters)

        t, _, rc = _timed(ransac)
        rc_params = {"point": np.asarray(rc.center, float), "axis": np.asarray(rc.axis, float),
                     "radius": max(float(rc.radius), 1e-3)}
        row["pyransac3d"] = (abs(float(rc.radius) - p["radius"]), t)
        for col, start in (("scipy<-pyransac3d", rc_params), ("scipy<-truth", p)):
            t, _, sp = _timed(lambda d=data, s=start: ScipyProblem(
                "cylinder", s, d, 1.0).solve(loss="soft_l1", f_scale=2 * noise))
            row[col] = (abs(sp["radius"] - p["radius"]), t)
        clean = FitData.create(pts[inl], 0.0, 1.0, dim=3)
        t, _, oracle = _timed(lambda d=clean, q=p: fit_primitive(
            "cylinder", d, free_side=1, initial=q))
        row["oracle"] = (abs(oracle.params["radius"] - p["radius"]), t)
        for c in cols:
            errs[c].append(row[c][0])
            times[c].append(row[c][1])
        print(f"{draw:4d} | " + " | ".join(f"{row[c][0] * 1e3:17.3f} {row[c][1] * 1e3:5.0f}"
                                           for c in cols), flush=True)
    print("-" * len(head))
    for name, fn in (("max", np.max), ("med", np.median)):
        print(f"{name:>4s} | " + " | ".join(
            f"{fn(errs[c]) * 1e3:17.3f} {fn(times[c]) * 1e3:5.0f}" for c in cols))
    print("\noracle: least squares on the true inliers from the true cylinder (the noise's "
          "share of the error)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--section", choices=("speed", "robust", "all"), default="all")
    ap.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    ap.add_argument("--sizes", nargs="+", type=int, default=list(SIZES))
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--scipy-method", default="trf", choices=("trf", "dogbox", "lm"))
    ap.add_argument("--draws", type=int, default=8)
    ap.add_argument("--ransac-thresh", type=float, default=1e-3, help="metres")
    ap.add_argument("--ransac-iter", type=int, default=2000)
    args = ap.parse_args()
    if args.section in ("speed", "all"):
        speed(args.kinds, args.sizes, args.repeats, args.scipy_method)
    if args.section in ("robust", "all"):
        robust(args.draws, args.ransac_thresh, args.ransac_iter)


if __name__ == "__main__":
    main()
