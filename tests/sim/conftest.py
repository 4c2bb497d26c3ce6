"""Small robots and environments for simulator tests (short runs keep the suite fast)."""

from __future__ import annotations

import numpy as np
import pytest

from wholearm_tools.geometry import Arc2D, Circle2D, Line2D, Surface
from wholearm_tools.robot.model import RobotModel


def two_link() -> RobotModel:
    return RobotModel.from_spec({
        "joints": [
            {"name": "j1", "origin": [0, 0, 0], "radius": 0.02, "limits": [-2.5, 2.5],
             "velocity": 1.5, "effort": 6.0},
            {"name": "j2", "origin": [0.35, 0, 0], "radius": 0.012, "limits": [-2.6, 2.6],
             "velocity": 1.5, "effort": 3.0},
        ],
        "tip": {"offset": [0.30, 0, 0], "radius": 0.015},
    }, name="two_link")


def pocket() -> list:
    """A post close to the base (link-0 contacts) and two walls (tip contacts)."""
    return [
        Arc2D([0.24, 0.22], 0.05, free_side=1, surface_id=0),
        Surface(Line2D([0.0, 0.52], [1.0, 0.0]), free_side=-1, surface_id=1),
        Surface(Circle2D([0.0, 0.0], 0.62), free_side=-1, surface_id=2),
    ]


@pytest.fixture
def robot() -> RobotModel:
    return two_link()


@pytest.fixture
def obstacles() -> list:
    return pocket()


def dense_penetration(robot: RobotModel, obstacles: list, Q: np.ndarray,
                      samples: int = 64) -> float:
    """Deepest penetration of any link capsule or the tip sphere, by dense point sampling
    (independent of the obstacles' segment minimisation), over configurations ``Q``."""
    pts = robot.joint_positions(Q)[..., : robot.dim]
    fr = np.linspace(0.0, 1.0, samples)
    worst = np.inf
    for i in range(robot.dof):
        a, b = pts[:, i], pts[:, i + 1]
        P = (a[:, None] + fr[None, :, None] * (b - a)[:, None]).reshape(-1, robot.dim)
        c = np.min([obs.clearance(P) for obs in obstacles], axis=0) - robot.link_radii[i]
        worst = min(worst, float(c.min()))
    tip = pts[:, -1]
    c = np.min([obs.clearance(tip) for obs in obstacles], axis=0) - robot.tip_radius
    return -min(worst, float(c.min()))
