"""Well-junction summary: main bore and lateral branch from a map with two cylinders.

Conventions (all in the robot base frame, metres and degrees)
-------------------------------------------------------------
* **Main bore**: the fitted cylinder whose interior contains the robot base (the origin); when
  several do, the one with the most supporting contacts.  **Lateral**: among the other cylinders
  whose axis passes inside the main bore (a branch, not a post elsewhere), the one with the most
  support.  No main bore or no lateral: no junction summary.
* **Main axis direction** ``u``: oriented from the base towards the window (the closest approach
  of the two axes), so the window position is >= 0 when it lies beyond the base.
* **Lateral direction** ``v``: oriented from the window into the branch, i.e. towards the centre
  of the lateral's support (its extent's axial mid-point; for the true junction the middle of
  its ``branch_range``).
* **Angle**: between ``u`` and ``v``, in [0, 180]; 0 = lateral continuing straight up the bore.
* **Window position**: axial coordinate, along ``u`` from the base's projection on the main axis,
  of the main-axis point closest to the lateral axis (where the lateral's axis crosses the bore).
  ``axis_offset`` is the distance between the two axes there (≈ 0 for a true junction).
* **Window azimuth**: angle about ``u`` (right-handed) of the lateral direction projected
  perpendicular to ``u``, measured from the reference direction = the base frame's x axis
  projected perpendicular to ``u`` (the y axis when the main axis is within 25° of x).
  In (-180, 180].
* **Uncertainty**: 95 % half-widths (1.96 standard deviations) from Monte Carlo sampling of the
  two fits' parameter covariances (``samples`` draws, fixed seed; axes renormalised, orientation
  kept consistent with the nominal one).  NaN where a covariance is missing or not finite.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError

FloatArray = NDArray[np.float64]

QUANTITIES = ("main_diameter", "lateral_diameter", "angle_deg", "window_position",
              "window_azimuth_deg", "axis_offset")
LABELS = {"main_diameter": ("main bore diameter", "m"),
          "lateral_diameter": ("lateral diameter", "m"),
          "angle_deg": ("angle between axes", "deg"),
          "window_position": ("window position along main axis", "m"),
          "window_azimuth_deg": ("window azimuth", "deg"),
          "axis_offset": ("axis offset at the window", "m")}


@dataclass(frozen=True, slots=True)
class Estimate:
    """A value, its 95 % half-width and the true value when known."""

    value: float
    half95: float
    truth: float | None = None
    unit: str = ""

    @property
    def error(self) -> float | None:
        if self.truth is None:
            return None
        e = self.value - self.truth
        if self.unit == "deg":      # angles wrap
            e = (e + 180.0) % 360.0 - 180.0
        return e

    def to_dict(self) -> dict[str, Any]:
        def f(x: float | None) -> float | None:
            return float(x) if x is not None and math.isfinite(x) else None
        return {"value": f(self.value), "half95": f(self.half95), "truth": f(self.truth),
                "error": f(self.error), "unit": self.unit}


@dataclass(frozen=True, slots=True)
class JunctionSummary:
    """Main bore and lateral of a well junction (see the module docstring for conventions)."""

    main_id: int
    lateral_id: int
    main_diameter: Estimate
    lateral_diameter: Estimate
    angle_deg: Estimate
    window_position: Estimate
    window_azimuth_deg: Estimate
    axis_offset: Estimate
    reference: tuple[float, float, float]
    samples: int

    def rows(self) -> list[tuple[str, str, Estimate]]:
        """``(key, label, estimate)`` for tables."""
        return [(k, LABELS[k][0], getattr(self, k)) for k in QUANTITIES]

    def to_dict(self) -> dict[str, Any]:
        return {"main_id": self.main_id, "lateral_id": self.lateral_id,
                "reference_direction": list(self.reference), "samples": self.samples,
                **{k: getattr(self, k).to_dict() for k in QUANTITIES}}


# ----------------------------------------------------------------------------- geometry


def _unit(v: Any) -> FloatArray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def reference_direction(u: FloatArray) -> FloatArray:
    """Azimuth reference: base x (or y when ``u`` is within 25° of x) projected ⊥ ``u``."""
    u = _unit(u)
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < math.cos(math.radians(25)) else \
        np.array([0.0, 1.0, 0.0])
    r = ref - (ref @ u) * u
    return r / np.linalg.norm(r)


def _closest_params(p: FloatArray, u: FloatArray, q: FloatArray, v: FloatArray
                    ) -> tuple[FloatArray, FloatArray]:
    """Parameters (s along u from p, r along v from q) of the closest points of two lines,
    batched over the leading axis; parallel lines take s at q's projection."""
    w = p - q
    b = np.einsum("...i,...i", u, v)
    d = np.einsum("...i,...i", u, w)
    e = np.einsum("...i,...i", v, w)
    den = 1.0 - b * b
    par = den < 1e-12
    den = np.where(par, 1.0, den)
    s = np.where(par, -d, (b * e - d) / den)
    r = np.where(par, e - b * d, (e - b * d) / den)
    return s, r


def junction_quantities(main_point: Any, main_axis: Any, main_radius: Any,
                        lat_point: Any, lat_axis: Any, lat_radius: Any, *,
                        lateral_mid: Any = None, base: Any = (0.0, 0.0, 0.0),
                        reference: Any = None) -> dict[str, FloatArray]:
    """The junction quantities of two cylinders (batched over a leading axis).

    ``lateral_mid`` is a point (or points) in the branch used to orient the lateral direction;
    None keeps the given axis sign.  The main axis is oriented from the base towards the window.
    Returns arrays (same leading shape) for each of :data:`QUANTITIES` plus ``"u"``, ``"v"``.
    """
    p = np.asarray(main_point, dtype=float)
    u = _unit(main_axis)
    q = np.asarray(lat_point, dtype=float)
    v = _unit(lat_axis)
    base = np.asarray(base, dtype=float)
    s, r = _closest_params(p, u, q, v)
    c_main = p + s[..., None] * u
    c_lat = q + r[..., None] * v
    if lateral_mid is not None:
        flip = np.einsum("...i,...i", np.asarray(lateral_mid, float) - c_lat, v) < 0
        v = np.where(flip[..., None], -v, v)
    pos = np.einsum("...i,...i", c_main - base, u)
    flip_u = pos < 0
    u = np.where(flip_u[..., None], -u, u)
    pos = np.abs(pos)
    ref = reference_direction(u.reshape(-1, 3)[0]) if reference is None else _unit(reference)
    ref = ref - np.einsum("...i,i", u, ref)[..., None] * u
    ref = _unit(ref)
    w = v - np.einsum("...i,...i", v, u)[..., None] * u
    az = np.degrees(np.arctan2(np.einsum("...i,...i", np.cross(u, ref), w),
                               np.einsum("...i,...i", ref, w)))
    angle = np.degrees(np.arccos(np.clip(np.einsum("...i,...i", u, v), -1.0, 1.0)))
    return {"main_diameter": 2.0 * np.asarray(main_radius, float),
            "lateral_diameter": 2.0 * np.asarray(lat_radius, float),
            "angle_deg": angle, "window_position": pos, "window_azimuth_deg": az,
            "axis_offset": np.linalg.norm(c_main - c_lat, axis=-1), "u": u, "v": v}


# --------------------------------------------------------------------------- covariance


def _flat_labels(params: Mapping[str, Any]) -> list[tuple[str, int | None]]:
    out: list[tuple[str, int | None]] = []
    for k, v in params.items():
        arr = np.asarray(v, dtype=float)
        if arr.ndim == 0:
            out.append((k, None))
        else:
            out.extend((k, i) for i in range(arr.size))
    return out


def _parse_label(label: str) -> tuple[str, int | None]:
    if label.endswith("]") and "[" in label:
        name, idx = label[:-1].split("[", 1)
        return name, int(idx)
    return label, None


def sample_params(params: Mapping[str, Any], covariance: Any, labels: Sequence[str] | None,
                  n: int, rng: np.random.Generator) -> dict[str, FloatArray] | None:
    """``n`` draws of a primitive's parameters from N(params, covariance); None when the
    covariance is missing, not finite or does not match the parameters."""
    cov = np.asarray(covariance, dtype=float) if covariance is not None else np.zeros((0, 0))
    names = [_parse_label(s) for s in labels] if labels else _flat_labels(params)
    if cov.ndim != 2 or cov.shape != (len(names), len(names)) or not np.all(np.isfinite(cov)):
        return None
    w, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    z = rng.standard_normal((n, len(names))) @ (vecs * np.sqrt(np.clip(w, 0.0, None))).T
    out = {k: np.broadcast_to(np.asarray(v, float), (n, *np.shape(v))).copy()
           for k, v in params.items()}
    for j, (name, idx) in enumerate(names):
        if name not in out:
            return None
        if idx is None:
            out[name] = out[name] + z[:, j]
        else:
            out[name][:, idx] += z[:, j]
    return out


def _fit_labels(rec: Any, pid: int) -> tuple[str, ...] | None:
    fits = getattr(rec, "fits", None) or ()
    if 0 <= pid < len(fits):
        return tuple(getattr(fits[pid], "param_labels", ()) or ()) or None
    return None


# ------------------------------------------------------------------------------ summary


def _support(p: Any) -> int:
    return int(sum(p.support.values())) if p.support else 0


def _branch_mid(p: Any) -> FloatArray | None:
    s = (p.extent or {}).get("s")
    if s is None:
        return None
    return np.asarray(p.params["point"], float) + 0.5 * (s[0] + s[1]) * _unit(p.params["axis"])


def _contains(p: Any, point: FloatArray) -> bool:
    a = _unit(p.params["axis"])
    r = point - np.asarray(p.params["point"], float)
    return float(np.linalg.norm(r - (r @ a) * a)) < float(p.params["radius"])


def main_bore(primitives: Sequence[Any], base: Any = (0.0, 0.0, 0.0)) -> Any | None:
    """The cylinder holding the robot base with the most support, or None."""
    base = np.asarray(base, float)
    holders = [p for p in primitives if p.kind == "cylinder" and _contains(p, base)]
    return max(holders, key=lambda p: (_support(p), -p.id)) if holders else None


def pick_bores(primitives: Sequence[Any], base: Any = (0.0, 0.0, 0.0)) -> tuple[Any, Any] | None:
    """(main, lateral): the main bore (:func:`main_bore`) and, among the other cylinders whose
    axis passes within the main bore (a branch of it, not a post standing elsewhere), the one
    with the most support.  None when there is no such pair."""
    main = main_bore(primitives, base)
    if main is None:
        return None
    p, u = np.asarray(main.params["point"], float), _unit(main.params["axis"])
    radius = float(main.params["radius"])

    def branches(c: Any) -> bool:
        q, v = np.asarray(c.params["point"], float), _unit(c.params["axis"])
        s, r = _closest_params(p, u, q, v)
        return float(np.linalg.norm(p + s * u - (q + r * v))) < radius

    laterals = [c for c in primitives if c.kind == "cylinder" and c is not main and branches(c)]
    if not laterals:
        return None
    return main, max(laterals, key=lambda c: (_support(c), -c.id))


def _true_junction(truth: Any) -> dict[str, Any] | None:
    """(main params, branch params, branch mid point) of the truth's junction, if any."""
    if truth is None:
        return None
    for s in truth.surfaces:
        ob = s.get("obstacle") or {}
        if ob.get("type") == "cylinder_junction":
            main, branch = ob["main"]["params"], ob["branch"]["params"]
            rng = (ob.get("bounds") or {}).get("branch_range") or [0.0, 1.0]
            lo = rng[0] if rng[0] is not None else -1.0
            hi = rng[1] if rng[1] is not None else 1.0
            mid = np.asarray(branch["point"], float) + 0.5 * (lo + hi) * _unit(branch["axis"])
            return {"main": main, "branch": branch, "mid": mid}
    cyl = [s for s in truth.surfaces if s.get("type") == "cylinder"]
    if len(cyl) >= 2:
        return {"main": cyl[0]["params"], "branch": cyl[1]["params"], "mid": None}
    return None


def junction_summary(rec: Any, *, samples: int = 4000, seed: int = 0,
                     base: Any = (0.0, 0.0, 0.0)) -> JunctionSummary | None:
    """Junction summary of a reconstruction (or anything with ``surface_map``; ``run.truth``
    and ``fits`` are used when present).  None when the map has fewer than two cylinders.

    Parameters
    ----------
    rec : Reconstruction
    samples : Monte Carlo draws for the uncertainties
    seed : seed of the draws (same seed, same numbers)
    base : (3,) robot base position in the map frame (the origin of base_link)
    """
    if samples < 2:
        raise InputError(f"samples must be >= 2, got {samples}")
    surface_map = rec.surface_map
    if surface_map.planar:
        return None
    pair = pick_bores(surface_map.primitives, base)
    if pair is None:
        return None
    main, lat = pair
    mp, lp = main.params, lat.params
    mid = _branch_mid(lat)
    nominal = junction_quantities(mp["point"], mp["axis"], mp["radius"], lp["point"],
                                  lp["axis"], lp["radius"], lateral_mid=mid, base=base)
    ref = reference_direction(nominal["u"])
    nominal = junction_quantities(mp["point"], nominal["u"], mp["radius"], lp["point"],
                                  nominal["v"], lp["radius"], base=base, reference=ref)

    rng = np.random.default_rng(seed)
    ms = sample_params(mp, main.covariance, _fit_labels(rec, main.id), samples, rng)
    ls = sample_params(lp, lat.covariance, _fit_labels(rec, lat.id), samples, rng)
    half: dict[str, float] = dict.fromkeys(QUANTITIES, float("nan"))
    if ms is not None and ls is not None:
        mu = _unit(ms["axis"])
        mu = np.where((mu @ nominal["u"] < 0)[:, None], -mu, mu)
        lv = _unit(ls["axis"])
        lv = np.where((lv @ nominal["v"] < 0)[:, None], -lv, lv)
        draws = junction_quantities(ms["point"], mu, ms["radius"], ls["point"], lv,
                                    ls["radius"], base=base, reference=ref)
        for k in QUANTITIES:
            d = draws[k] - nominal[k]
            if k == "window_azimuth_deg":
                d = (d + 180.0) % 360.0 - 180.0
            half[k] = 1.96 * float(np.std(d))

    truth_vals: dict[str, float | None] = dict.fromkeys(QUANTITIES)
    tj = _true_junction(getattr(getattr(rec, "run", None), "truth", None))
    if tj is not None:
        tm, tb = tj["main"], tj["branch"]
        tq = junction_quantities(tm["point"], tm["axis"], tm["radius"], tb["point"], tb["axis"],
                                 tb["radius"], lateral_mid=tj["mid"], base=base)
        if tj["mid"] is None and float(tq["v"] @ nominal["v"]) < 0:
            tq = junction_quantities(tm["point"], tq["u"], tm["radius"], tb["point"], -tq["v"],
                                     tb["radius"], base=base)
        tq = junction_quantities(tm["point"], tq["u"], tm["radius"], tb["point"], tq["v"],
                                 tb["radius"], base=base, reference=reference_direction(tq["u"]))
        truth_vals = {k: float(tq[k]) for k in QUANTITIES}

    est = {k: Estimate(float(nominal[k]), half[k], truth_vals[k], LABELS[k][1])
           for k in QUANTITIES}
    return JunctionSummary(main_id=int(main.id), lateral_id=int(lat.id), reference=(
        float(ref[0]), float(ref[1]), float(ref[2])), samples=int(samples), **est)
