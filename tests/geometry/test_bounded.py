"""Bounded obstacles against brute force: dense samples of the material's boundary."""

from __future__ import annotations

import json
from collections.abc import Callable

import numpy as np
import pytest
from numpy.typing import ArrayLike
from scipy.spatial import cKDTree

from wholearm_tools.errors import InputError
from wholearm_tools.geometry import (
    Arc2D,
    Cylinder,
    CylinderJunction,
    CylinderSection,
    Obstacle,
    PlanePatch,
    Segment2D,
    Sphere,
    Surface,
    Torus,
    obstacle_from_dict,
)


def _lin(a: float, b: float, n: int) -> np.ndarray:
    return np.linspace(a, b, n)


def _rect(o: np.ndarray, e1: np.ndarray, e2: np.ndarray, n1: int, n2: int) -> np.ndarray:
    """Samples of the parallelogram o + [0,1] e1 + [0,1] e2."""
    a, b = np.meshgrid(_lin(0, 1, n1), _lin(0, 1, n2), indexing="ij")
    return o + a.reshape(-1, 1) * e1 + b.reshape(-1, 1) * e2


def _frame(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    u = u / np.linalg.norm(u)
    v = np.cross(u, np.eye(3)[np.argmin(np.abs(u))])
    v /= np.linalg.norm(v)
    return u, v, np.cross(u, v)


def _cyl_coords(p: np.ndarray, o: np.ndarray, u: np.ndarray, ref: np.ndarray,
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(h, rho, phi) of points about the axis o + s u, phi from ref towards u x ref."""
    q = p - o
    h = q @ u
    x, y = q @ ref, q @ np.cross(u, ref)
    return h, np.hypot(x, y), np.arctan2(y, x)


def _revolve(o: np.ndarray, u: np.ndarray, ref: np.ndarray, rho: np.ndarray, h: np.ndarray,
             phi: np.ndarray) -> np.ndarray:
    w = np.cross(u, ref)
    return (o + h[:, None] * u + rho[:, None] * (np.cos(phi)[:, None] * ref
                                                  + np.sin(phi)[:, None] * w))


def _grid_revolve(o: np.ndarray, u: np.ndarray, ref: np.ndarray, rhos: ArrayLike,
                  hs: ArrayLike, phis: ArrayLike) -> np.ndarray:
    r, h, f = (g.ravel() for g in np.meshgrid(rhos, hs, phis, indexing="ij"))
    return _revolve(o, u, ref, r, h, f)


def _check_exact(obstacle: Obstacle, boundary: np.ndarray, material: Callable, pts: np.ndarray,
                 tol: float) -> None:
    c = obstacle.clearance(pts)
    brute, _ = cKDTree(boundary).query(pts)
    assert np.all(np.abs(c) <= brute + 1e-9)
    np.testing.assert_allclose(np.abs(c), brute, atol=tol)
    np.testing.assert_array_equal(c < 0, material(pts))


def test_segment2d_is_an_exact_rectangle_distance() -> None:
    p0, d = np.array([0.2, 0.1]), np.array([1.0, 1.0]) / np.sqrt(2)
    n = np.array([-d[1], d[0]])
    seg = Segment2D(p0, 5 * d, (-0.4, 0.6), free_side=-1, thickness=0.3)
    # material: s in [-0.4, 0.6], n-coordinate in [0, 0.3] (free side is -normal)
    corners = [p0 + s * d + t * n for s, t in [(-0.4, 0), (0.6, 0), (0.6, 0.3), (-0.4, 0.3)]]
    boundary = np.vstack([c0 + _lin(0, 1, 20001)[:, None] * (c1 - c0)
                          for c0, c1 in zip(corners, corners[1:] + corners[:1], strict=True)])

    def material(x: np.ndarray) -> np.ndarray:
        s, t = (x - p0) @ d, (x - p0) @ n
        return (s > -0.4) & (s < 0.6) & (t > 0) & (t < 0.3)

    pts = p0 + np.random.default_rng(0).uniform(-1.2, 1.2, (500, 2))
    _check_exact(seg, boundary, material, pts, 1e-4)


def test_plane_patch_is_an_exact_box_distance() -> None:
    c, n = np.array([0.1, -0.2, 0.3]), np.array([0.2, 0.3, 1.0])
    patch = PlanePatch(c, n, [1.0, 0.0, 0.0], (0.5, 0.3), free_side=1, thickness=0.2)
    n, u, v = patch.normal, patch.u, patch.v
    assert abs(u @ n) < 1e-12
    assert abs(v @ n) < 1e-12
    lo = c - 0.5 * u - 0.3 * v - 0.2 * n
    e = [1.0 * u, 0.6 * v, 0.2 * n]
    m = [200, 120, 40]
    faces = []
    for i, j, k in [(0, 1, 2), (0, 2, 1), (1, 2, 0)]:
        faces += [_rect(lo, e[i], e[j], m[i], m[j]), _rect(lo + e[k], e[i], e[j], m[i], m[j])]
    boundary = np.vstack(faces)

    def material(x: np.ndarray) -> np.ndarray:
        q = x - c
        return (np.abs(q @ u) < 0.5) & (np.abs(q @ v) < 0.3) & (q @ n < 0) & (q @ n > -0.2)

    pts = c + np.random.default_rng(1).uniform(-0.9, 0.9, (500, 3))
    _check_exact(patch, boundary, material, pts, 4e-3)
    # an infinitely deep patch equals a very thick one near the patch
    deep = PlanePatch(c, n, u, (0.5, 0.3), free_side=1)
    thick = PlanePatch(c, n, u, (0.5, 0.3), free_side=1, thickness=100.0)
    np.testing.assert_allclose(deep.clearance(pts), thick.clearance(pts))
    # flipping the free side mirrors the material through the plane
    flipped = PlanePatch(c, -n, u, (0.5, 0.3), free_side=-1, thickness=0.2)
    np.testing.assert_allclose(flipped.clearance(pts), patch.clearance(pts), atol=1e-12)


@pytest.mark.parametrize("free_side", [-1.0, 1.0])
def test_cylinder_section_without_angle_range_is_exact(free_side: float) -> None:
    o, u = np.array([0.1, 0.0, -0.1]), _frame(np.array([0.3, -0.2, 1.0]))[0]
    r, t, s0, s1 = 0.3, 0.1, -0.4, 0.5
    sec = CylinderSection(o, u, r, (s0, s1), free_side=free_side, thickness=t)
    phis = _lin(0, 2 * np.pi, 600)
    if free_side < 0:  # shell r <= rho <= r + t
        boundary = np.vstack([
            _grid_revolve(o, u, sec.ref, [r, r + t], _lin(s0, s1, 300), phis),
            _grid_revolve(o, u, sec.ref, _lin(r, r + t, 30), [s0, s1], phis)])

        def material(x: np.ndarray) -> np.ndarray:
            h, rho, _ = _cyl_coords(x, o, u, sec.ref)
            return (rho > r) & (rho < r + t) & (h > s0) & (h < s1)
    else:  # solid rho <= r
        boundary = np.vstack([
            _grid_revolve(o, u, sec.ref, [r], _lin(s0, s1, 300), phis),
            _grid_revolve(o, u, sec.ref, _lin(0, r, 100), [s0, s1], phis)])

        def material(x: np.ndarray) -> np.ndarray:
            h, rho, _ = _cyl_coords(x, o, u, sec.ref)
            return (rho < r) & (h > s0) & (h < s1)

    pts = o + np.random.default_rng(2).uniform(-0.8, 0.8, (600, 3))
    _check_exact(sec, boundary, material, pts, 5e-3)
    # unbounded section = the infinite cylinder surface
    full = CylinderSection(o, u, r, None, free_side=free_side)
    np.testing.assert_allclose(full.clearance(pts),
                               free_side * Cylinder(o, u, r).signed_distance(pts), atol=1e-12)


def _conservative(obstacle: Obstacle, boundary: np.ndarray, material: np.ndarray,
                  pts: np.ndarray, exact_where: np.ndarray, tol: float) -> None:
    """Zero set exact, exact in the material and where flagged, a lower bound elsewhere."""
    c = obstacle.clearance(pts)
    brute, _ = cKDTree(boundary).query(pts)
    np.testing.assert_array_equal(c < 0, material)
    assert np.all(c <= brute + 1e-9)
    np.testing.assert_allclose(-c[material], brute[material], atol=tol)
    assert exact_where.sum() > 20
    np.testing.assert_allclose(c[exact_where], brute[exact_where], atol=tol)


def test_cylinder_section_with_angle_range_is_conservative_and_exact_on_faces() -> None:
    o, (u, ref, _) = np.zeros(3), _frame(np.array([0.0, 0.0, 1.0]))
    r, t, s0, s1, a0, a1 = 0.3, 0.1, -0.4, 0.5, 0.3, 2.5
    sec = CylinderSection(o, u, r, (s0, s1), free_side=-1, angle_range=(a0, a1), ref=ref,
                          thickness=t)
    phis = _lin(a0, a1, 500)
    boundary = np.vstack([
        _grid_revolve(o, u, ref, [r, r + t], _lin(s0, s1, 300), phis),
        _grid_revolve(o, u, ref, _lin(r, r + t, 30), [s0, s1], phis),
        _grid_revolve(o, u, ref, _lin(r, r + t, 30), _lin(s0, s1, 300), [a0, a1])])
    pts = np.random.default_rng(3).uniform(-0.5, 0.5, (4000, 3))
    h, rho, phi = _cyl_coords(pts, o, u, ref)
    in_wedge = (phi > a0) & (phi < a1)
    in_range = (h > s0) & (h < s1)
    material = (rho > r) & (rho < r + t) & in_range & in_wedge
    # closest point on the inner face interior: inside the bore, well within the wedge and range
    margin = 0.05
    exact = ((rho < r) & (h > s0 + r) & (h < s1 - r) & (phi > a0 + margin) & (phi < a1 - margin)
             & (r - rho < np.minimum(rho * np.sin(phi - a0), rho * np.sin(a1 - phi))))
    _conservative(sec, boundary, material, pts, exact, 5e-3)


def test_arc2d() -> None:
    c, r, t = np.array([0.2, -0.1]), 0.5, 0.1
    full = Arc2D(c, r, None, free_side=1)
    pts = c + np.random.default_rng(4).uniform(-0.8, 0.8, (3000, 2))
    np.testing.assert_allclose(full.clearance(pts), np.linalg.norm(pts - c, axis=1) - r)
    a0, a1 = -0.5, 2.0
    arc = Arc2D(c, r, (a0, a1), free_side=-1, thickness=t)
    th = _lin(a0, a1, 20000)
    ring = _lin(r, r + t, 2000)
    boundary = np.vstack([
        c + r * np.c_[np.cos(th), np.sin(th)], c + (r + t) * np.c_[np.cos(th), np.sin(th)],
        c + ring[:, None] * [np.cos(a0), np.sin(a0)], c + ring[:, None] * [np.cos(a1), np.sin(a1)]])
    q = pts - c
    rho, phi = np.linalg.norm(q, axis=1), np.arctan2(q[:, 1], q[:, 0])
    material = (rho > r) & (rho < r + t) & (phi > a0) & (phi < a1)
    exact = (rho < r) & (phi > a0 + 0.3) & (phi < a1 - 0.3) & (r - rho < 0.1)
    _conservative(arc, boundary, material, pts, exact, 2e-4)


def _junction_case() -> tuple[CylinderJunction, np.ndarray, Callable]:
    j = CylinderJunction.lateral([0.1, 0.2, 0.0], [0, 0, 1], 0.3, 0.2, np.pi / 3, 1.0,
                                 main_range=(-1.0, 1.0), ref=[1, 0, 0], surface_id="well")
    parts = []
    inside_fns = []
    for cyl, (s0, s1) in ((j.main, j.main_range), (j.branch, j.branch_range)):
        u, ref, _ = _frame(cyl.axis)
        phis = _lin(0, 2 * np.pi, 500)
        parts.append(np.vstack([
            _grid_revolve(cyl.point, u, ref, [cyl.radius], _lin(s0, s1, 500), phis),
            _grid_revolve(cyl.point, u, ref, _lin(0, cyl.radius, 60), [s0, s1], phis)]))

        def inside(x: np.ndarray, cyl: Cylinder = cyl, s0: float = s0, s1: float = s1,
                   ) -> np.ndarray:
            h, rho, _ = _cyl_coords(x, cyl.point, cyl.axis, _frame(cyl.axis)[1])
            return (rho < cyl.radius) & (h > s0) & (h < s1)

        inside_fns.append(inside)
    # boundary of the union: each cylinder's boundary outside the other cylinder
    boundary = np.vstack([parts[0][~inside_fns[1](parts[0])], parts[1][~inside_fns[0](parts[1])]])

    def free(x: np.ndarray) -> np.ndarray:
        return inside_fns[0](x) | inside_fns[1](x)

    return j, boundary, free


def test_junction_clearance_is_the_union_of_the_bores() -> None:
    j, boundary, free = _junction_case()
    rng = np.random.default_rng(5)
    pts = j.main.point + rng.uniform(-0.8, 0.8, (3000, 3))
    pts[:1000, 2] = j.main.point[2] + rng.uniform(-1.2, 1.2, 1000)
    is_free = free(pts)
    h = (pts - j.main.point) @ j.main.axis
    # in the main bore far below the junction and the caps, the main wall is the closest feature
    exact = is_free & (h < -0.3) & (h > -0.6)
    _conservative(j, boundary, ~is_free, pts, exact, 6e-3)
    # the union really is a union: points on the branch axis beyond the main bore are free
    on_branch = j.branch.point + np.outer([0.5, 0.7, 0.9], j.branch.axis)
    np.testing.assert_allclose(j.clearance(on_branch), [0.2, 0.2, 0.1], atol=1e-12)
    # beyond the branch's end cap it is material
    assert j.clearance(j.branch.point + 1.1 * j.branch.axis) < 0


OBSTACLES: list[tuple[Obstacle, float]] = [
    (Surface(Sphere([0, 0, 0], 0.5), -1, 3), 1.0),
    (Surface(Torus([0, 0, 0], [0, 0, 1], 0.6, 0.2), 1, "torus"), 1.0),
    (PlanePatch([0, 0, 0], [0, 0, 1], [1, 1, 0], (0.4, 0.2), 1, 0.1, 7), 0.7),
    (CylinderSection([0, 0, 0], [0, 1, 0], 0.3, (-0.2, 0.4), -1, (0.5, 4.0), [0, 0, 1], 0.05),
     0.6),
    (CylinderSection([0, 0, 0], [1, 0, 0], 0.2, (None, 0.3), 1), 0.6),
    (_junction_case()[0], 0.8),
    (Segment2D([0, 0], [1, 0.2], (-0.3, 0.5), 1, 0.2, 1), 0.8),
    (Arc2D([0, 0], 0.5, (1.0, 5.0), -1, None, 2), 0.9),
]


@pytest.mark.parametrize(("obstacle", "box"), OBSTACLES, ids=lambda o: getattr(o, "type_name", ""))
def test_segment_clearance_matches_dense_sampling(obstacle: Obstacle, box: float) -> None:
    dim = obstacle.dim  # type: ignore[attr-defined]
    rng = np.random.default_rng(6)
    a = rng.uniform(-box, box, (300, dim))
    b = a + rng.normal(scale=0.4, size=a.shape)
    val, t = obstacle.segment_clearance(a, b)
    assert np.all((t >= 0) & (t <= 1))
    np.testing.assert_allclose(obstacle.clearance(a + t[:, None] * (b - a)), val, atol=1e-12)
    ts = _lin(0, 1, 4001)
    dense = (a[:, None, :] + ts[None, :, None] * (b - a)[:, None, :]).reshape(-1, dim)
    brute = obstacle.clearance(dense).reshape(len(a), -1).min(axis=1)
    length = np.linalg.norm(b - a, axis=1)
    assert np.all(val <= brute + 1e-9)
    assert np.all(val >= brute - length / 64)  # the documented worst case
    assert np.mean(np.abs(val - brute) <= length / 4000 + 1e-9) >= 0.98


@pytest.mark.parametrize(("obstacle", "box"), OBSTACLES, ids=lambda o: getattr(o, "type_name", ""))
def test_obstacle_round_trips_through_json(obstacle: Obstacle, box: float) -> None:
    assert isinstance(obstacle, Obstacle)
    text = json.dumps(obstacle.to_dict(), allow_nan=False)
    back = obstacle_from_dict(json.loads(text))
    assert type(back) is type(obstacle)
    assert back.surface_id == obstacle.surface_id
    assert back.to_dict() == obstacle.to_dict()
    pts = np.random.default_rng(7).uniform(-box, box, (50, obstacle.dim))  # type: ignore[attr-defined]
    np.testing.assert_allclose(back.clearance(pts), obstacle.clearance(pts), atol=1e-14)
    single = obstacle.clearance(pts[0])
    assert np.shape(single) == ()
    assert all(p.kind for p in obstacle.primitives)  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("factory", "match"),
    [
        (lambda: Surface(Sphere([0, 0, 0], 1), 0), "free_side.*0"),
        (lambda: Surface("sphere", 1), "Primitive.*'sphere'"),
        (lambda: Surface(Sphere([0, 0, 0], 1), 1, 2.5), "surface_id.*2.5"),
        (lambda: PlanePatch([0, 0, 0], [0, 0, 1], [0, 0, 2], (1, 1)),
         r"parallel.*\[0.0, 0.0, 1.0\]"),
        (lambda: PlanePatch([0, 0, 0], [0, 0, 1], [1, 0, 0], (1, -2)), r"half_extents\[1\].*-2"),
        (lambda: PlanePatch([0, 0, 0], [0, 0, 1], [1, 0, 0], (1, 1), thickness=0), "thickness.*0"),
        (lambda: Segment2D([0, 0], [1, 0], (0.5, 0.1)), r"s_range.*\(0.5, 0.1\)"),
        (lambda: Segment2D([0, 0], [1, 0], (None, 0.1)), "s_range.*finite"),
        (lambda: CylinderSection([0, 0, 0], [0, 0, 1], 0.1, angle_range=(1.0, 1.0)),
         r"angle_range.*\(1.0, 1.0\)"),
        (lambda: CylinderSection([0, 0, 0], [0, 0, 1], 0.1, angle_range=(0, 7)), "angle_range"),
        (lambda: CylinderSection([0, 0, 0], [0, 0, 1], 0.1, ref=[0, 0, 3]), "ref.*parallel"),
        (lambda: CylinderSection([0, 0, 0], [0, 0, 1], -0.1), "radius.*-0.1"),
        (lambda: Arc2D([0, 0], 1.0, "half"), "angle_range.*'half'"),
        (lambda: CylinderJunction.lateral([0, 0, 0], [0, 0, 1], 0.1, 0.1, 3.5, 1.0), "angle.*3.5"),
        (lambda: CylinderJunction(Sphere([0, 0, 0], 1), Cylinder([0, 0, 0], [1, 0, 0], 1)),
         "main must be a Cylinder"),
        (lambda: obstacle_from_dict({"type": "wall"}), "unknown obstacle type 'wall'"),
        (lambda: obstacle_from_dict([1, 2]), r"'type' key, got \[1, 2\]"),
        (lambda: obstacle_from_dict({"type": "surface"}), "needs 'primitive'"),
    ],
)
def test_invalid_obstacles_raise_input_error(factory: Callable, match: str) -> None:
    with pytest.raises(InputError, match=match):
        factory()


def test_arc2d_disc_sector_wider_than_half_a_turn() -> None:
    # a "pac-man" disc: material rho <= r over 4.5 rad; inside it, the apex can be the nearest
    # boundary point (both edge rays more than 90 degrees away)
    r, a0, a1 = 0.5, 0.0, 4.5
    arc = Arc2D([0, 0], r, (a0, a1), free_side=1)
    th = _lin(a0, a1, 30000)
    ray = _lin(0, r, 5000)[:, None]
    boundary = np.vstack([r * np.c_[np.cos(th), np.sin(th)],
                          ray * [np.cos(a0), np.sin(a0)], ray * [np.cos(a1), np.sin(a1)]])
    pts = np.random.default_rng(8).uniform(-0.7, 0.7, (4000, 2))
    rho, phi = np.linalg.norm(pts, axis=1), np.mod(np.arctan2(pts[:, 1], pts[:, 0]), 2 * np.pi)
    material = (rho < r) & (phi < a1)
    exact = (rho > r) & (phi > a0 + 0.1) & (phi < a1 - 0.1)
    _conservative(arc, boundary, material, pts, exact, 2e-4)
    apex_nearest = material & (rho < 0.2) & (phi > 1.7) & (phi < 2.8)
    assert apex_nearest.sum() > 10
    np.testing.assert_allclose(arc.clearance(pts[apex_nearest]), -rho[apex_nearest])
