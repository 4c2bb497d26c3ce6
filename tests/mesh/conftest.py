"""Small maps and support points shared by the mesh tests."""

from __future__ import annotations

import numpy as np
import pytest

import wholearm_tools.geometry.primitives  # noqa: F401  (registers the primitive types)
from wholearm_tools.geometry.base import primitive_type
from wholearm_tools.mapfile import MappedPrimitive, SurfaceMap
from wholearm_tools.mesh.extent import support_extent

#: one instance of every 3-D primitive, with a point cloud centre near which contacts are taken
PRIMITIVES_3D = {
    "plane": ({"point": [0.1, 0.2, 0.3], "normal": [0.2, 0.3, 1.0]}, [0.1, 0.2, 0.3]),
    "sphere": ({"center": [0.1, 0.0, 0.5], "radius": 0.2}, [0.3, 0.1, 0.6]),
    "cylinder": ({"point": [0.0, 0.1, 0.0], "axis": [0.0, 0.6, 0.8], "radius": 0.1},
                 [0.1, 0.2, 0.2]),
    "cone": ({"apex": [0.0, 0.0, 1.0], "axis": [0.0, 0.0, -1.0], "half_angle": 0.4},
             [0.2, 0.0, 0.5]),
    "torus": ({"center": [0.0, 0.0, 0.3], "axis": [1.0, 0.0, 0.0], "major_radius": 0.3,
               "minor_radius": 0.05}, [0.0, 0.3, 0.3]),
}


def normalised(params: dict) -> dict:
    """JSON-like params → arrays, directions made unit (as the fitter writes them)."""
    out = {}
    for k, v in params.items():
        arr = np.asarray(v, dtype=float)
        if k in ("normal", "axis", "direction"):
            arr = arr / np.linalg.norm(arr)
        out[k] = arr if arr.ndim else float(arr)
    return out


def support_points(kind: str, n: int = 40, spread: float = 0.1, seed: int = 0) -> np.ndarray:
    """``n`` points on the primitive near its cloud centre (closest points of a Gaussian blob)."""
    params, centre = PRIMITIVES_3D[kind]
    prim = primitive_type(kind).from_params(normalised(params))
    rng = np.random.default_rng(seed)
    return prim.closest_point(np.asarray(centre) + spread * rng.normal(size=(n, 3)))


@pytest.fixture
def map_3d() -> SurfaceMap:
    """A 3-D map: a cylinder patch and a plane patch, plus a few unexplained contacts."""
    prims = []
    for i, kind in enumerate(("cylinder", "plane")):
        params = normalised(PRIMITIVES_3D[kind][0])
        ext = support_extent(kind, params, support_points(kind, seed=i))
        prims.append(MappedPrimitive(id=i, kind=kind, params=params, extent=ext,
                                     rms_residual=0.001))
    rng = np.random.default_rng(5)
    xy = rng.uniform(-0.05, 0.05, size=(30, 2))
    bump = np.c_[xy + np.array([0.6, 0.0]), 0.8 + 0.01 * np.sin(40 * xy[:, 0])]
    return SurfaceMap(planar=False, B=0.02, primitives=tuple(prims),
                      contacts={"count": 110, "tip": 80, "link": 30}, unexplained=bump)


@pytest.fixture
def map_2d() -> SurfaceMap:
    """A planar map: a wall (line) and a pipe section (arc), and two unexplained contacts."""
    line = {"point": np.array([0.5, -0.2]), "direction": np.array([0.0, 1.0])}
    circle = {"center": np.array([0.2, 0.4]), "radius": 0.1}
    t = np.linspace(-0.1, 0.25, 8)
    line_pts = line["point"] + t[:, None] * line["direction"]
    ang = np.linspace(3.0, 4.0, 6)
    arc_pts = circle["center"] + 0.1 * np.c_[np.cos(ang), np.sin(ang)]
    prims = (
        MappedPrimitive(0, "line", line, extent=support_extent("line", line, line_pts)),
        MappedPrimitive(1, "circle", circle, extent=support_extent("circle", circle, arc_pts)),
    )
    return SurfaceMap(planar=True, B=0.02, primitives=prims,
                      unexplained=np.array([[0.0, 0.6], [0.05, 0.62]]))


@pytest.fixture
def shapes():
    """The helpers above (test modules cannot import conftest under --import-mode=importlib)."""
    from types import SimpleNamespace

    return SimpleNamespace(params=lambda kind: normalised(PRIMITIVES_3D[kind][0]),
                           support_points=support_points, kinds=sorted(PRIMITIVES_3D))
