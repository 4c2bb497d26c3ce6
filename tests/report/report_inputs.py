"""Hand-built inputs of the report tests: ground truths, junction surfaces, maps."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from wholearm_tools.logs.records import GroundTruth
from wholearm_tools.mapfile import MappedPrimitive, SurfaceMap


def make_truth(surfaces, t, link, kind, point, surface) -> GroundTruth:
    m = len(t)
    return GroundTruth(surfaces=tuple(surfaces), contact_t=np.asarray(t, float),
                       contact_link=np.asarray(link, np.int64),
                       contact_kind=np.asarray(kind, dtype=str),
                       contact_point=np.asarray(point, float).reshape(m, 3),
                       contact_surface=np.asarray(surface, np.int64),
                       contact_s=np.ones(m))


def junction_surfaces(main_point=(0.0, 0.0, 0.35), main_axis=(0.0, 0.0, 1.0), main_r=0.18,
                      branch_axis=(0.7071067811865476, 0.0, 0.7071067811865476), branch_r=0.12):
    main = {"type": "cylinder", "params": {"point": list(main_point), "axis": list(main_axis),
                                           "radius": main_r}}
    branch = {"type": "cylinder", "params": {"point": list(main_point),
                                             "axis": list(branch_axis), "radius": branch_r}}
    bounds = {"main_range": [-1.5, 1.5], "branch_range": [0.0, 0.8]}
    obstacle = {"type": "cylinder_junction", "surface_id": 0, "free_side": -1, "main": main,
                "branch": branch, "bounds": bounds}
    return [{"id": 0, **main, "free_side": -1, "bounds": bounds, "obstacle": obstacle},
            {"id": 1, **branch, "free_side": -1, "bounds": bounds, "obstacle": obstacle}]


def cylinder(pid, point, axis, radius, s_range, support=(10, 2), cov=None):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return MappedPrimitive(
        id=pid, kind="cylinder",
        params={"point": np.asarray(point, float), "axis": axis, "radius": float(radius)},
        covariance=np.zeros((0, 0)) if cov is None else np.asarray(cov, float),
        support={"tip": support[0], "link": support[1]}, rms_residual=1e-4,
        extent={"s": list(s_range), "angle": {"reference": [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9
                                               else [0.0, 1.0, 0.0], "start": 0.0,
                                               "sweep": 2 * np.pi, "full": True},
                "pad": 0.0, "n_points": 10})


def fake_rec(primitives, truth=None, planar=False, table=None):
    """Just what the report's pure functions read from a Reconstruction."""
    sm = SurfaceMap(planar=planar, B=0.02, primitives=tuple(primitives),
                    unexplained=np.zeros((0, 2 if planar else 3)))
    return SimpleNamespace(surface_map=sm, fits=(), table=table,
                           run=SimpleNamespace(truth=truth, source="<test>"))
