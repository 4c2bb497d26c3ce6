"""Primitives against brute force: dense surface samples, finite differences, dense segments."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.spatial import cKDTree

from wholearm_tools.errors import InputError
from wholearm_tools.geometry import (
    PRIMITIVE_TYPES,
    Circle2D,
    Cone,
    Cylinder,
    Line2D,
    Plane,
    Primitive,
    Sphere,
    Torus,
    capsule_clearance,
    primitive_from_dict,
    primitive_to_dict,
    primitive_type,
)


def _frame(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = u / np.linalg.norm(u)
    e = np.eye(3)[np.argmin(np.abs(u))]
    v = np.cross(u, e)
    v /= np.linalg.norm(v)
    return v, np.cross(u, v)


@dataclass
class Case:
    prim: Primitive
    samples: np.ndarray  # dense surface samples
    tol: float  # brute-force resolution (half a sample cell diagonal, generous)
    on_surface: Callable[[np.ndarray], np.ndarray]  # independent surface equation residual
    inside: Callable[[np.ndarray], np.ndarray]  # independent "negative side" predicate
    box: float  # test points in [-box, box]^d around `origin`
    origin: np.ndarray


def rho(x: np.ndarray, o: np.ndarray, ax: np.ndarray) -> np.ndarray:
    """Distance of points ``x`` to the axis through ``o`` along unit ``ax``."""
    q = x - o
    return np.linalg.norm(q - np.outer(q @ ax, ax), axis=1)


def _grid(n1: int, n2: int, r1: tuple, r2: tuple) -> tuple[np.ndarray, np.ndarray]:
    a, b = np.meshgrid(np.linspace(*r1, n1), np.linspace(*r2, n2), indexing="ij")
    return a.ravel(), b.ravel()


def _case_0(out: dict[str, Case]) -> None:
    # 2-D line
    p0, d = np.array([0.3, -0.2]), np.array([2.0, 1.0]) / np.sqrt(5)
    n = np.array([-d[1], d[0]])
    s = np.linspace(-6, 6, 120001)
    out["line"] = Case(
        Line2D(p0, 3 * d), p0 + s[:, None] * d, 1e-4,
        lambda x: (x - p0) @ n, lambda x: (x - p0) @ n < 0, 2.0, p0)


def _case_1(out: dict[str, Case]) -> None:
    # circle
    c, r = np.array([0.5, -1.0]), 0.8
    th = np.linspace(0, 2 * np.pi, 100001)
    out["circle"] = Case(
        Circle2D(c, r), c + r * np.c_[np.cos(th), np.sin(th)], 1e-4,
        lambda x: np.linalg.norm(x - c, axis=1) - r,
        lambda x: np.linalg.norm(x - c, axis=1) < r, 1.5, c)


def _case_2(out: dict[str, Case]) -> None:
    # plane
    p0, nrm = np.array([0.1, 0.2, -0.3]), np.array([1.0, -2.0, 0.5])
    nrm = nrm / np.linalg.norm(nrm)
    v, w = _frame(nrm)
    a, b = _grid(801, 801, (-4, 4), (-4, 4))
    out["plane"] = Case(
        Plane(p0, 2 * nrm), p0 + a[:, None] * v + b[:, None] * w, 8e-3,
        lambda x: (x - p0) @ nrm, lambda x: (x - p0) @ nrm < 0, 1.5, p0)


def _case_3(out: dict[str, Case]) -> None:
    # sphere (Fibonacci lattice)
    c, r, m = np.array([0.2, -0.1, 0.4]), 0.7, 400000
    k = np.arange(m) + 0.5
    phi, z = np.pi * (1 + 5**0.5) * k, 1 - 2 * k / m
    sph = np.c_[np.sqrt(1 - z**2) * np.cos(phi), np.sqrt(1 - z**2) * np.sin(phi), z]
    out["sphere"] = Case(
        Sphere(c, r), c + r * sph, 3e-3,
        lambda x: np.linalg.norm(x - c, axis=1) - r,
        lambda x: np.linalg.norm(x - c, axis=1) < r, 1.5, c)


def _case_4(out: dict[str, Case]) -> None:
    # cylinder
    p0, u, r = np.array([0.3, 0.1, -0.2]), np.array([1.0, 1.0, 2.0]), 0.5
    u = u / np.linalg.norm(u)
    v, w = _frame(u)
    h, th = _grid(1201, 700, (-3.5, 3.5), (0, 2 * np.pi))

    out["cylinder"] = Case(
        Cylinder(p0, 3 * u, r),
        p0 + h[:, None] * u + r * (np.cos(th)[:, None] * v + np.sin(th)[:, None] * w), 6e-3,
        lambda x: rho(x, p0, u) - r, lambda x: rho(x, p0, u) < r, 1.5, p0)


def _case_5(out: dict[str, Case]) -> None:
    # cone
    apex, u, al = np.array([-0.2, 0.3, 0.1]), np.array([0.0, -1.0, 1.0]), 0.45
    u = u / np.linalg.norm(u)
    v, w = _frame(u)
    s, th = _grid(1000, 900, (0, 4.0), (0, 2 * np.pi))
    ang = lambda x: np.arccos(np.clip(  # noqa: E731
        ((x - apex) @ u) / np.maximum(np.linalg.norm(x - apex, axis=1), 1e-300), -1, 1))
    out["cone"] = Case(
        Cone(apex, u, al),
        apex + s[:, None] * (np.sin(al) * (np.cos(th)[:, None] * v + np.sin(th)[:, None] * w)
                             + np.cos(al) * u), 1e-2,
        lambda x: np.where(np.linalg.norm(x - apex, axis=1) < 1e-9, 0.0, ang(x) - al),
        lambda x: ang(x) < al, 1.5, apex)


def _case_6(out: dict[str, Case]) -> None:
    # torus
    c, u, big, small = np.array([0.1, 0.0, -0.2]), np.array([1.0, 0.5, 0.2]), 1.0, 0.3
    u = u / np.linalg.norm(u)
    v, w = _frame(u)
    th, ph = _grid(1200, 400, (0, 2 * np.pi), (0, 2 * np.pi))
    e = np.cos(th)[:, None] * v + np.sin(th)[:, None] * w
    core = lambda x: np.hypot(rho(x, c, u) - big, (x - c) @ u)  # noqa: E731
    out["torus"] = Case(
        Torus(c, u, big, small),
        c + (big + small * np.cos(ph))[:, None] * e + small * np.sin(ph)[:, None] * u, 5e-3,
        lambda x: core(x) - small, lambda x: core(x) < small, 1.7, c)




def _cases() -> dict[str, Case]:
    out: dict[str, Case] = {}
    for make in (_case_0, _case_1, _case_2, _case_3, _case_4, _case_5, _case_6):
        make(out)
    return out

CASES = _cases()
KINDS = sorted(CASES)


def _points(case: Case, n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = case.prim.dim
    return case.origin + rng.uniform(-case.box, case.box, (n, d))


def test_every_registered_type_is_tested() -> None:
    assert set(PRIMITIVE_TYPES) == set(KINDS)


@pytest.mark.parametrize("kind", KINDS)
def test_signed_distance_matches_dense_surface_samples(kind: str) -> None:
    case = CASES[kind]
    pts = _points(case, 400, 1)
    if kind == "cone":  # include points behind the apex and on the axis
        u = case.prim.axis
        pts = np.vstack([pts, case.origin - np.outer([0.3, 1.0, 0.05], u),
                         case.origin + np.outer([0.5, 1.2], u)])
    sd = case.prim.signed_distance(pts)
    brute, _ = cKDTree(case.samples).query(pts)
    assert np.all(np.abs(sd) <= brute + 1e-9)
    np.testing.assert_allclose(np.abs(sd), brute, atol=case.tol)
    inside = case.inside(pts)
    assert np.all((sd < 0) == inside)


@pytest.mark.parametrize("kind", KINDS)
def test_closest_point_is_on_the_surface_at_the_signed_distance(kind: str) -> None:
    case = CASES[kind]
    pts = _points(case, 300, 2)
    cp = case.prim.closest_point(pts)
    np.testing.assert_allclose(case.on_surface(cp), 0.0, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(pts - cp, axis=1),
                               np.abs(case.prim.signed_distance(pts)), atol=1e-12)
    # the surface samples are fixed points of closest_point
    some = case.samples[:: max(1, len(case.samples) // 500)]
    np.testing.assert_allclose(case.prim.signed_distance(some), 0.0, atol=1e-9)


@pytest.mark.parametrize("kind", KINDS)
def test_gradient_matches_finite_differences(kind: str) -> None:
    case = CASES[kind]
    prim = case.prim
    pts = _points(case, 200, 3)
    sd = prim.signed_distance(pts)
    g = prim.gradient(pts)
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-12)
    h = 1e-6
    fd = np.stack([(prim.signed_distance(pts + h * e) - prim.signed_distance(pts - h * e))
                   / (2 * h) for e in np.eye(prim.dim)], axis=1)
    # stay away from the kinks (axis, apex region boundary): compare where fd is a unit vector
    smooth = np.abs(np.linalg.norm(fd, axis=1) - 1.0) < 1e-4
    assert smooth.mean() > 0.9
    np.testing.assert_allclose(g[smooth], fd[smooth], atol=1e-5)
    assert sd.shape == (len(pts),)


@pytest.mark.parametrize("kind", KINDS)
def test_single_point_gives_scalar_shaped_results(kind: str) -> None:
    prim = CASES[kind].prim
    p = CASES[kind].origin + 0.37
    assert prim.signed_distance(p).shape == ()
    assert prim.gradient(p).shape == (prim.dim,)
    assert prim.closest_point(p).shape == (prim.dim,)
    val, t = prim.segment_signed_distance(p, p + 0.5)
    assert val.shape == ()
    assert t.shape == ()


@pytest.mark.parametrize("kind", KINDS)
def test_params_round_trip_through_json(kind: str) -> None:
    prim = CASES[kind].prim
    d = json.loads(json.dumps(primitive_to_dict(prim)))
    assert d["type"] == kind
    back = primitive_from_dict(d)
    assert type(back) is type(prim)
    for key, value in prim.params().items():
        np.testing.assert_allclose(back.params()[key], value, rtol=0, atol=1e-15)
    again = primitive_type(kind).from_params(prim.params())
    pts = _points(CASES[kind], 20, 4)
    np.testing.assert_allclose(again.signed_distance(pts), prim.signed_distance(pts))


@pytest.mark.parametrize("kind", KINDS)
def test_stored_arrays_are_read_only_and_directions_unit(kind: str) -> None:
    prim = CASES[kind].prim
    for name in ("direction", "normal", "axis"):
        if hasattr(prim, name):
            assert np.isclose(np.linalg.norm(getattr(prim, name)), 1.0)
    for value in vars(prim).values():
        if isinstance(value, np.ndarray):
            with pytest.raises(ValueError, match="read-only"):
                value[0] = 1.0


def _segments(case: Case, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    a = _points(case, n, seed)
    b = a + rng.normal(scale=0.8, size=a.shape)
    b[: n // 10] = a[: n // 10]  # degenerate (zero-length) segments
    return a, b


@pytest.mark.parametrize("free_side", [1.0, -1.0])
@pytest.mark.parametrize("kind", KINDS)
def test_segment_clearance_matches_dense_sampling(kind: str, free_side: float) -> None:
    case = CASES[kind]
    prim = case.prim
    a, b = _segments(case, 150, 5)
    val, t = prim.segment_signed_distance(a, b, free_side)
    assert np.all((t >= 0) & (t <= 1))
    # the reported t attains the reported value
    np.testing.assert_allclose(free_side * prim.signed_distance(a + t[:, None] * (b - a)), val,
                               atol=1e-12)
    ts = np.linspace(0, 1, 4001)
    dense = a[:, None, :] + ts[None, :, None] * (b - a)[:, None, :]
    brute = (free_side * prim.signed_distance(dense.reshape(-1, prim.dim))).reshape(len(a), -1)
    brute = brute.min(axis=1)
    length = np.linalg.norm(b - a, axis=1)
    assert np.all(val <= brute + 1e-9)
    assert np.all(val >= brute - length / 4000 - 1e-9)


def test_segment_clearance_finds_interior_minimum_outside_cylinder() -> None:
    cyl = Cylinder([0, 0, 0], [0, 0, 1], 1.0)
    val, t = cyl.segment_signed_distance([[3, -2, 0]], [[3, 2, 5]], 1.0)
    np.testing.assert_allclose(val, [2.0])
    np.testing.assert_allclose(t, [0.5])
    val, t = cyl.segment_signed_distance([[0.5, 0, 0]], [[-0.2, 0, 0]], -1.0)
    np.testing.assert_allclose(val, [0.5])
    np.testing.assert_allclose(t, [0.0])


def test_capsule_clearance_subtracts_radius() -> None:
    sph = Sphere([0, 0, 0], 1.0)
    a = np.array([[2.0, -1.0, 0.0], [0.0, 0.0, 3.0]])
    b = np.array([[2.0, 1.0, 0.0], [0.0, 0.0, 5.0]])
    val, t = capsule_clearance(sph, a, b, 0.25, 1)
    np.testing.assert_allclose(val, [0.75, 1.75])
    np.testing.assert_allclose(t, [0.5, 0.0])
    val, _ = capsule_clearance(sph, a, b, np.array([0.1, 0.2]), 1)
    np.testing.assert_allclose(val, [0.9, 1.8])
    with pytest.raises(InputError, match=r"-0\.1"):
        capsule_clearance(sph, a, b, -0.1, 1)
    with pytest.raises(InputError, match="shape"):
        capsule_clearance(sph, a, b, np.ones(3), 1)


@pytest.mark.parametrize(
    ("factory", "match"),
    [
        (lambda: Sphere([0, 0, 0], -1.0), "radius.*-1.0"),
        (lambda: Sphere([0, 0, np.nan], 1.0), "center.*nan"),
        (lambda: Circle2D([0, 0, 0], 1.0), r"circle center of shape \(2,\)"),
        (lambda: Circle2D([0, 0], 0.0), "radius.*0.0"),
        (lambda: Plane([0, 0, 0], [0, 0, 0]), r"normal must be a non-zero.*\[0.0, 0.0, 0.0\]"),
        (lambda: Line2D([0, 0], [0, np.inf]), "direction must be finite.*inf"),
        (lambda: Cylinder([0, 0, 0], [0, 0, 1], float("inf")), "radius.*inf"),
        (lambda: Cylinder([0, 0, 0], [0, 0, 1], "wide"), "radius must be a number.*wide"),
        (lambda: Cone([0, 0, 0], [0, 0, 1], 1.6), r"half_angle.*\(0, pi/2\).*1.6"),
        (lambda: Cone([0, 0, 0], [0, 0, 1], 0.0), "half_angle.*0.0"),
        (lambda: Torus([0, 0, 0], [0, 0, 1], 0.2, 0.3), "minor_radius=0.3.*major_radius=0.2"),
        (lambda: Torus([0, 0, 0], [0, 0, 1], 1.0, -0.3), "minor_radius.*-0.3"),
        (lambda: primitive_type("blob"), "'blob'"),
        (lambda: Sphere.from_params({"center": [0, 0, 0]}), "'radius'"),
        (lambda: primitive_from_dict({"kind": "sphere"}), "'kind'"),
    ],
)
def test_invalid_constructions_raise_input_error(factory: Callable, match: str) -> None:
    with pytest.raises(InputError, match=match):
        factory()


def test_invalid_queries_raise_input_error() -> None:
    sph = Sphere([0, 0, 0], 1.0)
    with pytest.raises(InputError, match=r"shape \(N, 3\), got \(4, 2\)"):
        sph.signed_distance(np.zeros((4, 2)))
    with pytest.raises(InputError, match="NaN"):
        sph.gradient([[0, 0, np.nan]])
    with pytest.raises(InputError, match=r"free_side must be \+1 or -1, got 0.5"):
        sph.segment_signed_distance([0, 0, 0], [1, 0, 0], 0.5)
    with pytest.raises(InputError, match="3 vs 2"):
        sph.segment_signed_distance(np.zeros((3, 3)), np.zeros((2, 3)))
