"""Support extents: ranges along axes, angular ranges across the 0/2π seam, padded hulls."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from wholearm_tools.errors import InputError
from wholearm_tools.mesh.extent import angular_range, full_extent, support_extent

TWO_PI = 2 * math.pi
PAD = 0.005


def _angle_close(a: float, b: float, tol: float = 1e-9) -> bool:
    d = (a - b + math.pi) % TWO_PI - math.pi
    return abs(d) < tol


# ------------------------------------------------------------------ angular ranges


def test_angular_range_crosses_the_seam():
    deg = np.radians([350.0, 355.0, 5.0, 10.0])
    rng = angular_range(deg)
    assert not rng["full"]
    assert _angle_close(rng["start"], math.radians(350.0))
    assert rng["sweep"] == pytest.approx(math.radians(20.0))


def test_angular_range_largest_gap_and_padding():
    deg = np.radians([0.0, 30.0, 60.0, 200.0])  # largest gap: 200 → 360
    rng = angular_range(deg, pad_angle=0.1)
    assert _angle_close(rng["start"], -0.1)
    assert rng["sweep"] == pytest.approx(math.radians(200.0) + 0.2)
    assert 0.0 <= rng["start"] < TWO_PI


def test_angular_range_full_when_points_wrap():
    ang = np.radians(np.arange(0.0, 360.0, 40.0)) + 1.0  # gaps of 40° < 60°
    assert angular_range(ang) == {"start": 0.0, "sweep": TWO_PI, "full": True}
    # the same points with one 80° hole are a partial arc starting after the hole
    holed = np.delete(ang, 3)
    rng = angular_range(holed)
    assert not rng["full"]
    assert _angle_close(rng["start"], ang[4] % TWO_PI)
    assert rng["sweep"] == pytest.approx(TWO_PI - math.radians(80.0))


def test_angular_range_padding_to_full_turn():
    assert angular_range([0.0, 3.0], pad_angle=2.0)["full"]


# ------------------------------------------------------------------ primitives


def test_circle_full_and_partial():
    params = {"center": np.array([1.0, -1.0]), "radius": 0.2}
    ang = np.radians(np.arange(0.0, 360.0, 30.0))
    pts = params["center"] + 0.2 * np.c_[np.cos(ang), np.sin(ang)]
    ext = support_extent("circle", params, pts)
    assert ext["angle"]["full"]
    assert ext["angle"]["sweep"] == pytest.approx(TWO_PI)
    assert ext["angle"]["reference"] == [1.0, 0.0]
    # an arc across the seam: 340° … 20°
    ang = np.radians(np.linspace(-20.0, 20.0, 9))
    pts = params["center"] + 0.2 * np.c_[np.cos(ang), np.sin(ang)]
    ext = support_extent("circle", params, pts, pad=PAD)
    assert not ext["angle"]["full"]
    assert _angle_close(ext["angle"]["start"], math.radians(-20.0) - PAD / 0.2)
    assert ext["angle"]["sweep"] == pytest.approx(math.radians(40.0) + 2 * PAD / 0.2)
    assert ext["n_points"] == 9
    assert ext["pad"] == PAD


def test_cylinder_patch_axial_and_angular_range():
    axis = np.array([0.0, 0.6, 0.8])
    p0 = np.array([0.1, 0.0, -0.2])
    r = 0.08
    e1 = np.cross(axis, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    s = np.array([0.1, 0.25, 0.4, 0.3, 0.15])
    theta = np.radians([350.0, 10.0, 40.0, 0.0, 20.0])  # wraps across my frame's 0
    pts = p0 + s[:, None] * axis + r * (np.cos(theta)[:, None] * e1
                                          + np.sin(theta)[:, None] * e2)
    params = {"point": p0, "axis": axis, "radius": r}
    ext = support_extent("cylinder", params, pts, pad=PAD)
    assert ext["s"] == pytest.approx([0.1 - PAD, 0.4 + PAD])
    ref = np.array(ext["angle"]["reference"])
    assert abs(ref @ axis) < 1e-12
    assert np.linalg.norm(ref) == pytest.approx(1.0)
    offset = math.atan2(ref @ e2, ref @ e1)  # angle of the extent's reference in my frame
    assert not ext["angle"]["full"]
    assert _angle_close(ext["angle"]["start"], math.radians(350.0) - offset - PAD / r)
    assert ext["angle"]["sweep"] == pytest.approx(math.radians(50.0) + 2 * PAD / r)


def test_cylinder_wrapping_points_give_full_angle():
    params = {"point": np.zeros(3), "axis": np.array([0.0, 0.0, 1.0]), "radius": 0.1}
    ang = np.radians(np.arange(0.0, 360.0, 45.0))
    pts = np.c_[0.1 * np.cos(ang), 0.1 * np.sin(ang), np.linspace(0, 0.3, 8)]
    ext = support_extent("cylinder", params, pts)
    assert ext["angle"]["full"]
    assert ext["s"] == pytest.approx([-PAD, 0.3 + PAD])


def test_plane_patch_polygon_contains_padded_points():
    n = np.array([0.0, 0.0, 1.0])
    rng = np.random.default_rng(3)
    ab = rng.uniform([0.0, 0.0], [0.2, 0.1], size=(50, 2))
    ab[:4] = [[0, 0], [0.2, 0], [0.2, 0.1], [0, 0.1]]
    pts = np.c_[ab, np.full(50, 0.5)]
    params = {"point": np.array([0.05, 0.05, 0.5]), "normal": n}
    ext = support_extent("plane", params, pts, pad=PAD)
    u, v = np.array(ext["u"]), np.array(ext["v"])
    assert np.allclose([u @ u, v @ v, u @ v, u @ n, v @ n], [1, 1, 0, 0, 0])
    assert np.allclose(np.cross(u, v), n)
    poly = np.array(ext["polygon"])
    # counter-clockwise: positive signed area, close to the padded rectangle's
    x, y = poly[:, 0], poly[:, 1]
    area = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    rect = (0.2 + 2 * PAD) * (0.1 + 2 * PAD)
    outer = PAD / math.cos(math.pi / 16)  # the padding 16-gon's circumradius
    assert rect - (4 - math.pi) * PAD**2 < area <= (0.2 + 2 * outer) * (0.1 + 2 * outer)
    # every projected point lies inside the polygon, at least pad from its edges
    q = np.stack([(pts - params["point"]) @ u, (pts - params["point"]) @ v], axis=1)
    edges = np.roll(poly, -1, axis=0) - poly
    normals = np.c_[edges[:, 1], -edges[:, 0]] / np.linalg.norm(edges, axis=1)[:, None]
    depth = -((q[:, None, :] - poly[None, :, :]) * normals[None]).sum(axis=2)  # >0 inside
    assert depth.min() >= PAD - 1e-9
    json.dumps(ext)  # JSON-ready


def test_plane_single_point_is_a_small_polygon():
    params = {"point": np.zeros(3), "normal": np.array([1.0, 0.0, 0.0])}
    ext = support_extent("plane", params, [[0.0, 0.1, 0.2]], pad=0.01)
    poly = np.array(ext["polygon"])
    assert len(poly) == 16
    centre = np.array([0.1 * np.array(ext["u"])[1] + 0.2 * np.array(ext["u"])[2],
                       0.1 * np.array(ext["v"])[1] + 0.2 * np.array(ext["v"])[2]])
    assert np.linalg.norm(poly - centre, axis=1).min() >= 0.01 - 1e-12


def test_sphere_cap_and_full_sphere():
    c = np.array([0.0, 0.1, 0.2])
    r = 0.3
    d = np.array([0.0, 0.0, 1.0])
    ang = np.radians(np.arange(0.0, 360.0, 30.0))
    half = math.radians(25.0)
    pts = c + r * np.c_[np.sin(half) * np.cos(ang), np.sin(half) * np.sin(ang),
                        np.full(12, np.cos(half))]
    ext = support_extent("sphere", {"center": c, "radius": r}, pts, pad=PAD)
    assert not ext["cap"]["full"]
    assert np.allclose(ext["cap"]["direction"], d)
    assert ext["cap"]["half_angle"] == pytest.approx(half + PAD / r)
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(200, 3))
    pts = c + r * dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    ext = support_extent("sphere", {"center": c, "radius": r}, pts)
    assert ext["cap"]["full"]
    assert ext["cap"]["half_angle"] == pytest.approx(math.pi)


def test_cone_axial_range_from_apex():
    apex = np.array([0.0, 0.0, 1.0])
    axis = np.array([0.0, 0.0, -1.0])
    alpha = 0.4
    h = np.array([0.2, 0.5, 0.35])
    ang = np.array([0.1, 0.3, 0.2])
    pts = apex + h[:, None] * axis + (h * math.tan(alpha))[:, None] * np.c_[
        np.cos(ang), np.sin(ang), np.zeros(3)]
    ext = support_extent("cone", {"apex": apex, "axis": axis, "half_angle": alpha}, pts)
    assert ext["s"] == pytest.approx([0.2 - PAD, 0.5 + PAD])
    assert not ext["angle"]["full"]
    # sweep = 0.2 rad plus the padding at the mean radius
    assert ext["angle"]["sweep"] == pytest.approx(
        0.2 + 2 * PAD / (np.mean(h) * math.tan(alpha)))


def test_torus_angle_around_main_axis_and_full_minor_circle():
    c = np.zeros(3)
    axis = np.array([0.0, 0.0, 1.0])
    big, small = 0.3, 0.05
    phi = np.radians([80.0, 100.0, 120.0])
    psi = np.array([0.0, 2.0, 4.0])
    rad = big + small * np.cos(psi)
    pts = np.c_[rad * np.cos(phi), rad * np.sin(phi), small * np.sin(psi)]
    params = {"center": c, "axis": axis, "major_radius": big, "minor_radius": small}
    ext = support_extent("torus", params, pts, pad=PAD)
    assert ext["minor"] == {"start": 0.0, "sweep": TWO_PI, "full": True}
    assert ext["angle"]["sweep"] == pytest.approx(math.radians(40.0) + 2 * PAD / big)


def test_full_extent_only_for_closed_shapes():
    assert full_extent("sphere", {"center": [0, 0, 0], "radius": 1.0})["cap"]["full"]
    assert full_extent("circle", {"center": [0, 0], "radius": 1.0})["angle"]["full"]
    with pytest.raises(InputError, match="plane is unbounded"):
        full_extent("plane", {"point": [0, 0, 0], "normal": [0, 0, 1]})


def test_extent_errors_name_the_value():
    cyl = {"point": [0, 0, 0], "axis": [0, 0, 1], "radius": 0.1}
    with pytest.raises(InputError, match="without support points"):
        support_extent("cylinder", cyl, np.zeros((0, 3)))
    with pytest.raises(InputError, match=r"shape \(N, 3\), got \(4, 2\)"):
        support_extent("cylinder", cyl, np.zeros((4, 2)))
    with pytest.raises(InputError, match="unknown primitive type 'blob'"):
        support_extent("blob", cyl, np.zeros((4, 3)))
    with pytest.raises(InputError, match=r"'radius' must be positive, got -0\.1"):
        support_extent("cylinder", {**cyl, "radius": -0.1}, np.ones((4, 3)))
    with pytest.raises(InputError, match="'axis' must be non-zero"):
        support_extent("cylinder", {**cyl, "axis": [0, 0, 0]}, np.ones((4, 3)))
    with pytest.raises(InputError, match="padding must be finite and >= 0, got -1"):
        support_extent("cylinder", cyl, np.ones((4, 3)), pad=-1)
    with pytest.raises(InputError, match="NaN"):
        support_extent("cylinder", cyl, [[0.0, np.nan, 0.0]])
