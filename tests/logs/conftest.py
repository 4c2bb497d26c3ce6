"""Small runs built in memory for the log tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wholearm_tools.logs.records import GroundTruth, JointLog, Run
from wholearm_tools.robot import RobotModel

REAL = Path("/work/shared/data/real")
REAL_50 = REAL / "prismax_airbot_50.mcap"
REAL_100 = REAL / "prismax_airbot_100.mcap"
REAL_TOPICS = tuple(f"/robot/arm_{side}_{role}/joint_states"
                    for side in ("left", "right") for role in ("lead", "follow"))


@pytest.fixture
def robot() -> RobotModel:
    spec = {"joints": [{"name": f"joint_{i + 1}", "origin": [0.3 * (i > 0), 0.0, 0.0],
                        "radius": 0.02} for i in range(3)],
            "tip": {"offset": [0.25, 0.0, 0.0], "radius": 0.01}}
    return RobotModel.from_spec(spec, name="tri")


def make_log(n: int = 20, commands: bool = True, t0_ns: int = 1_700_000_000_123_456_789
             ) -> JointLog:
    rng = np.random.default_rng(7)
    t = np.arange(n) * 0.01 + rng.uniform(0, 1e-3, n).cumsum() * 0.0
    q = rng.normal(size=(n, 3))
    qd = rng.normal(size=(n, 3))
    return JointLog(("joint_1", "joint_2", "joint_3"), t, q, qd,
                    tau_cmd=rng.normal(size=(n, 3)) if commands else None,
                    q_cmd=rng.normal(size=(n, 3)) if commands else None, t0_ns=t0_ns)


def make_truth() -> GroundTruth:
    return GroundTruth(
        surfaces=({"id": 0, "type": "plane", "params": {"point": [1.0, 0.0, 0.0],
                                                        "normal": [-1.0, 0.0, 0.0]},
                   "free_side": 1},),
        contact_t=[0.05, 0.12, 0.17], contact_link=[2, 1, 2],
        contact_kind=["tip", "body", "joint"],
        contact_point=[[1.0, 0.1, 0.0], [1.0, -0.2, 0.0], [1.0, 0.3, 0.0]],
        contact_surface=[0, 0, 0], contact_s=[1.0, 0.4, 1.0],
        meta={"scenario": "wall", "seed": 11})


@pytest.fixture
def run(robot: RobotModel) -> Run:
    return Run(robot=robot, log=make_log(), truth=make_truth(), source="test")
