"""Write the URDF of every bundled scenario's robot from its spec (run from the repo root).

    .venv/bin/python datasets/build_robots.py

The scenarios read only the URDF files; this script is how they were made.
"""

from __future__ import annotations

from pathlib import Path

from wholearm_tools.robot.model import RobotModel
from wholearm_tools.robot.urdf import robot_to_urdf

HERE = Path(__file__).resolve().parent

LAB_ARM = [  # two-joint planar lab arm, 0.35 m + 0.30 m
    {"name": "shoulder", "origin": [0, 0, 0], "radius": 0.02, "limits": [-1.0, 2.6],
     "velocity": 1.5, "effort": 6.0},
    {"name": "elbow", "origin": [0.35, 0, 0], "radius": 0.012, "limits": [-2.6, 2.6],
     "velocity": 1.5, "effort": 3.0},
]

SPECS = {
    "paper_planar": {
        "name": "planar_3r",
        "joints": [
            {"name": "joint_1", "origin": [0, 0, 0], "radius": 0.025, "limits": [-3.0, 3.0],
             "velocity": 1.2, "effort": 12.0},
            {"name": "joint_2", "origin": [0.30, 0, 0], "radius": 0.02, "limits": [-2.5, 2.5],
             "velocity": 1.5, "effort": 8.0},
            {"name": "joint_3", "origin": [0.25, 0, 0], "radius": 0.015, "limits": [-2.5, 2.5],
             "velocity": 1.5, "effort": 4.0},
        ],
        "tip": {"offset": [0.20, 0, 0], "radius": 0.02},
    },
    "paper_spatial": {
        "name": "spatial_5r",
        "joints": [
            {"name": "base_yaw", "origin": [0, 0, 0], "axis": [0, 0, 1], "radius": 0.045,
             "limits": [-3.1, 3.1], "velocity": 1.5, "effort": 40.0},
            {"name": "shoulder", "origin": [0, 0, 0.12], "axis": [0, 1, 0], "radius": 0.035,
             "limits": [-1.9, 0.6], "velocity": 1.5, "effort": 40.0},
            {"name": "elbow", "origin": [0.32, 0, 0], "axis": [0, 1, 0], "radius": 0.028,
             "limits": [-2.2, 2.2], "velocity": 1.5, "effort": 20.0},
            {"name": "wrist_yaw", "origin": [0.26, 0, 0], "axis": [0, 0, 1], "radius": 0.022,
             "limits": [-1.8, 1.8], "velocity": 1.5, "effort": 8.0},
            {"name": "wrist_pitch", "origin": [0.12, 0, 0], "axis": [0, 1, 0], "radius": 0.016,
             "limits": [-1.8, 1.8], "velocity": 1.5, "effort": 8.0},
        ],
        "tip": {"offset": [0.12, 0, 0], "radius": 0.02},
    },
    "lab_circle": {
        "name": "lab_arm_round_tip",
        "joints": LAB_ARM,
        "tip": {"offset": [0.30, 0, 0], "radius": 0.015},
    },
    "lab_sharp": {
        "name": "lab_arm_sharp_tip",
        "joints": [LAB_ARM[0], {**LAB_ARM[1], "radius": 0.005}],
        "tip": {"offset": [0.30, 0, 0], "radius": 0.0},
    },
    "well_junction": {
        # tool body (j1 roll + 0.30 m nose) on the main-bore axis; the shoulder j2 sits 0.30 m up
        # the axis, the elbow j3/j4 (roll + pitch) at the junction centre, so the distal links
        # can turn into the lateral branch, fold back below the junction or sweep the bore wall
        "name": "well_arm_5r",
        "joints": [
            {"name": "j1_roll", "origin": [0, 0, 0], "axis": [0, 0, 1], "radius": 0.05,
             "limits": [-3.1, 3.1], "velocity": 0.8, "effort": 60.0},
            {"name": "j2_pitch", "origin": [0, 0, 0.30], "axis": [0, 1, 0], "radius": 0.04,
             "limits": [-1.2, 1.2], "velocity": 0.8, "effort": 40.0},
            {"name": "j3_roll", "origin": [0, 0, 0.18], "axis": [0, 0, 1], "radius": 0.035,
             "limits": [-3.1, 3.1], "velocity": 1.2, "effort": 20.0},
            {"name": "j4_pitch", "origin": [0, 0, 0.03], "axis": [0, 1, 0], "radius": 0.03,
             "limits": [-2.6, 2.6], "velocity": 1.0, "effort": 20.0},
            {"name": "j5_pitch", "origin": [0, 0, 0.15], "axis": [0, 1, 0], "radius": 0.022,
             "limits": [-2.4, 2.4], "velocity": 1.2, "effort": 8.0},
        ],
        "tip": {"offset": [0, 0, 0.12], "radius": 0.025},
    },
}


def main() -> None:
    for scenario, spec in SPECS.items():
        robot = RobotModel.from_spec(spec, name=spec["name"])
        (HERE / f"{scenario}.urdf").write_text(robot_to_urdf(robot), encoding="utf-8")
        print(f"{scenario}.urdf: {robot.dof} joints, planar={robot.planar}")


if __name__ == "__main__":
    main()
