"""Synthetic contacts on known primitives (tip contacts and tangent link contacts)."""

from __future__ import annotations

from typing import Any

import numpy as np

from wholearm_tools.fit import FitData
from wholearm_tools.geometry import primitive_type


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e = np.eye(3)[int(np.argmin(np.abs(axis)))]
    u = _unit(np.cross(axis, e))
    return u, np.cross(axis, u)


def truth(kind: str, rng: np.random.Generator) -> dict[str, Any]:
    """Random true parameters of a primitive of size ~1 near the origin."""
    c3 = rng.uniform(-0.3, 0.3, 3)
    ax = _unit(rng.normal(size=3))
    if kind == "line":
        a = rng.uniform(0, np.pi)
        return {"point": rng.uniform(-0.3, 0.3, 2), "direction": np.array([np.cos(a), np.sin(a)])}
    if kind == "circle":
        return {"center": rng.uniform(-0.3, 0.3, 2), "radius": rng.uniform(0.3, 0.6)}
    if kind == "plane":
        return {"point": c3, "normal": ax}
    if kind == "sphere":
        return {"center": c3, "radius": rng.uniform(0.3, 0.6)}
    if kind == "cylinder":
        return {"point": c3, "axis": ax, "radius": rng.uniform(0.2, 0.4)}
    if kind == "cone":
        return {"apex": c3, "axis": ax, "half_angle": rng.uniform(0.3, 0.7)}
    if kind == "torus":
        return {"center": c3, "axis": ax, "major_radius": rng.uniform(0.5, 0.7),
                "minor_radius": rng.uniform(0.15, 0.25)}
    raise ValueError(kind)


def surface_samples(kind: str, p: dict[str, Any], n: int, rng: np.random.Generator
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Surface points, outward unit normals and a tangent direction along which the surface is
    convex seen from outside (so a tangent segment outside touches at one point)."""
    if kind == "line":
        s = rng.uniform(-1, 1, n)
        d = p["direction"]
        nrm = np.array([-d[1], d[0]])
        return p["point"] + s[:, None] * d, np.tile(nrm, (n, 1)), np.tile(d, (n, 1))
    if kind == "circle":
        a = rng.uniform(0, 2 * np.pi, n)
        e = np.stack([np.cos(a), np.sin(a)], 1)
        return p["center"] + p["radius"] * e, e, np.stack([-e[:, 1], e[:, 0]], 1)
    if kind == "plane":
        u, v = _basis(p["normal"])
        s = rng.uniform(-1, 1, (n, 2))
        q = p["point"] + s[:, :1] * u + s[:, 1:] * v
        tan = np.array([_unit(rng.normal() * u + rng.normal() * v) for _ in range(n)])
        return q, np.tile(p["normal"], (n, 1)), tan
    if kind == "sphere":
        e = np.array([_unit(x) for x in rng.normal(size=(n, 3))])
        tan = np.array([_unit(np.cross(x, rng.normal(size=3))) for x in e])
        return p["center"] + p["radius"] * e, e, tan
    if kind == "cylinder":
        u, v = _basis(p["axis"])
        a = rng.uniform(0, 2 * np.pi, n)
        h = rng.uniform(-0.6, 0.6, n)
        e = np.cos(a)[:, None] * u + np.sin(a)[:, None] * v
        q = p["point"] + h[:, None] * p["axis"] + p["radius"] * e
        tan = np.cross(p["axis"], e)
        return q, e, tan
    if kind == "cone":
        u, v = _basis(p["axis"])
        al = p["half_angle"]
        a = rng.uniform(0, 2 * np.pi, n)
        s = rng.uniform(0.4, 1.2, n)
        e = np.cos(a)[:, None] * u + np.sin(a)[:, None] * v
        gen = np.cos(al) * p["axis"] + np.sin(al) * e  # generator direction
        q = p["apex"] + s[:, None] * gen
        nrm = np.cos(al) * e - np.sin(al) * p["axis"]
        tan = np.cross(nrm, gen)  # along the circular cross-section (convex)
        return q, nrm, np.array([_unit(x) for x in tan])
    if kind == "torus":
        u, v = _basis(p["axis"])
        a = rng.uniform(0, 2 * np.pi, n)
        b = rng.uniform(0, 2 * np.pi, n)
        e = np.cos(a)[:, None] * u + np.sin(a)[:, None] * v
        nrm = np.cos(b)[:, None] * e + np.sin(b)[:, None] * p["axis"]
        q = p["center"] + p["major_radius"] * e + p["minor_radius"] * nrm
        tan = -np.sin(b)[:, None] * e + np.cos(b)[:, None] * p["axis"]  # meridian circle
        return q, nrm, tan
    raise ValueError(kind)


def contacts(kind: str, p: dict[str, Any], n_tip: int, n_link: int, side: float,
             rng: np.random.Generator, w_tip: float = 0.02, w_link: float = 0.03,
             link_length: float = 0.3, noise: float = 0.0) -> FitData:
    """Noise-free (unless ``noise``) tip and link contacts on the free side ``side``.

    Links on a surface that is convex seen from free space are tangent at an interior point;
    otherwise (concave side, or lines/planes half the time) they touch with an end point and
    lean into free space.
    """
    prim = primitive_type(kind).from_params(p)
    q, nrm, tan = surface_samples(kind, p, n_tip + n_link, rng)
    nf = side * nrm
    tips = q[:n_tip] + w_tip * nf[:n_tip] + noise * rng.normal(size=(n_tip, q.shape[1]))
    ql, nl_, tl = q[n_tip:], nf[n_tip:], tan[n_tip:]
    convex = side > 0 and kind not in ("line", "plane")
    if side < 0:  # keep links leaning into a concave free space inside it
        size = p.get("minor_radius", p.get("radius", 0.2))
        link_length = min(link_length, 0.5 * size)
    a = np.zeros_like(ql)
    b = np.zeros_like(ql)
    for i in range(n_link):
        c = ql[i] + w_link * nl_[i]
        if convex or (kind in ("line", "plane") and i % 2 == 0):
            tau = rng.uniform(0.25, 0.75)
            a[i] = c - tau * link_length * tl[i]
            b[i] = c + (1 - tau) * link_length * tl[i]
        else:
            beta = rng.uniform(0.5, 1.0)
            dirn = np.cos(beta) * tl[i] + np.sin(beta) * nl_[i]
            a[i] = c
            b[i] = c + link_length * dirn
    if n_link:
        a += noise * rng.normal(size=a.shape)
        b += noise * rng.normal(size=b.shape)
        clear, _ = prim.segment_signed_distance(a, b, side)
        assert np.allclose(clear, w_link, atol=1e-9 + 6 * noise), "bad synthetic link contact"
    # one free-space hint (where the robot stands)
    depth = 0.5 * p.get("minor_radius", p.get("radius", 0.6)) if side < 0 else 0.3
    free = q[:1] + depth * nf[:1]
    return FitData.create(tips, w_tip, 1.0, a, b, w_link, 1.0, free_points=free,
                          dim=q.shape[1])


def perturbed(p: dict[str, Any]) -> dict[str, Any]:
    """A start near the truth ``p``: points moved 2 cm, unit vectors ~3.5 degrees, scalars
    by 5 %."""
    q: dict[str, Any] = {}
    rot = np.array([0.05, -0.03, 0.04])
    for key, v in p.items():
        if key in ("normal", "axis", "direction"):
            u = v + rot[: len(v)]
            q[key] = u / np.linalg.norm(u)
        elif np.ndim(v):
            q[key] = v + 0.02
        else:
            q[key] = 1.05 * v
    return q


def param_error(kind: str, fit: dict[str, Any], true: dict[str, Any]) -> float:
    """Largest absolute error of the identifiable quantities (axes up to sign where the sign is
    not meaningful, points on lines/axes compared by distance)."""
    def ang(a: np.ndarray, b: np.ndarray, signed: bool = True) -> float:
        a, b = _unit(np.asarray(a)), _unit(np.asarray(b))
        return float(min(np.linalg.norm(a - b), np.inf if signed else np.linalg.norm(a + b)))

    def off_line(pt: np.ndarray, p0: np.ndarray, d: np.ndarray) -> float:
        v = pt - p0
        return float(np.linalg.norm(v - (v @ d) * d))

    if kind == "line":
        d = _unit(fit["direction"])
        return max(ang(fit["direction"], true["direction"], signed=False),
                   off_line(true["point"], fit["point"], d))
    if kind in ("circle", "sphere"):
        return max(float(np.abs(fit["center"] - true["center"]).max()),
                   abs(fit["radius"] - true["radius"]))
    if kind == "plane":
        n = fit["normal"]
        return max(ang(n, true["normal"]), abs((true["point"] - fit["point"]) @ n))
    if kind == "cylinder":
        return max(ang(fit["axis"], true["axis"], signed=False),
                   off_line(true["point"], fit["point"], _unit(fit["axis"])),
                   abs(fit["radius"] - true["radius"]))
    if kind == "cone":
        return max(ang(fit["axis"], true["axis"]),
                   float(np.abs(fit["apex"] - true["apex"]).max()),
                   abs(fit["half_angle"] - true["half_angle"]))
    if kind == "torus":
        return max(ang(fit["axis"], true["axis"], signed=False),
                   float(np.abs(fit["center"] - true["center"]).max()),
                   abs(fit["major_radius"] - true["major_radius"]),
                   abs(fit["minor_radius"] - true["minor_radius"]))
    raise ValueError(kind)


def merge(*parts: FitData) -> FitData:
    """Concatenate contact sets (tips first, then links, as FitData orders them)."""
    cat = np.concatenate
    return FitData.create(
        cat([p.tip_points for p in parts]), cat([p.tip_radius for p in parts]),
        cat([p.tip_weight for p in parts]), cat([p.link_a for p in parts]),
        cat([p.link_b for p in parts]), cat([p.link_radius for p in parts]),
        cat([p.link_weight for p in parts]), cat([p.free_points for p in parts]),
        dim=parts[0].dim)


def planar_scene(rng: np.random.Generator, noise: float = 0.0
                 ) -> tuple[FitData, list[tuple[str, dict[str, Any]]], np.ndarray]:
    """Two lines (floor and wall) and a circle (a post), mixed tip and link contacts.
    Returns the data, the true primitives and each contact's true primitive index."""
    prims = [
        ("line", {"point": np.array([0.0, -0.5]), "direction": np.array([1.0, 0.0])}),
        ("line", {"point": np.array([1.0, 0.0]), "direction": np.array([0.0, 1.0])}),
        ("circle", {"center": np.array([-0.2, 0.3]), "radius": 0.25}),
    ]
    counts = [(14, 8), (12, 8), (14, 8)]
    return _scene(prims, counts, rng, noise)


def spatial_scene(rng: np.random.Generator, noise: float = 0.0
                  ) -> tuple[FitData, list[tuple[str, dict[str, Any]]], np.ndarray]:
    """A floor plane and a vertical cylindrical post standing on it."""
    prims = [
        ("plane", {"point": np.array([0.0, 0.0, -0.5]), "normal": np.array([0.0, 0.0, 1.0])}),
        ("cylinder", {"point": np.array([0.2, 0.1, 0.0]), "axis": np.array([0.0, 0.0, 1.0]),
                      "radius": 0.2}),
    ]
    counts = [(30, 15), (30, 15)]
    return _scene(prims, counts, rng, noise)


def _scene(prims, counts, rng, noise):
    parts, labels_t, labels_l = [], [], []
    for i, ((kind, p), (nt, nl)) in enumerate(zip(prims, counts, strict=True)):
        d = contacts(kind, p, nt, nl, 1, rng, noise=noise, link_length=0.2)
        if kind == "cylinder":  # keep the post above the floor
            keep_t = d.tip_points[:, 2] > -0.4
            mids = 0.5 * (d.link_a + d.link_b)
            keep_l = (mids[:, 2] > -0.4) & (np.minimum(d.link_a[:, 2], d.link_b[:, 2]) > -0.45)
            d = FitData.create(d.tip_points[keep_t], d.tip_radius[keep_t], 1.0,
                               d.link_a[keep_l], d.link_b[keep_l], d.link_radius[keep_l], 1.0,
                               d.free_points, dim=3)
        parts.append(d)
        labels_t.append(np.full(d.n_tip, i))
        labels_l.append(np.full(d.n_link, i))
    data = merge(*parts)
    return data, prims, np.concatenate(labels_t + labels_l)
