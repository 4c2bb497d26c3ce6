"""Robot models: capsule-link serial chains, forward kinematics, URDF in and out."""

from wholearm_tools.robot.model import RobotModel, rotation_about_axis, transform_from_xyz_rpy
from wholearm_tools.robot.urdf import (
    UrdfChain,
    load_urdf,
    load_urdf_chain,
    robot_from_urdf,
    robot_to_urdf,
    urdf_chain,
)

__all__ = ["RobotModel", "UrdfChain", "load_urdf", "load_urdf_chain", "robot_from_urdf",
           "robot_to_urdf", "rotation_about_axis", "transform_from_xyz_rpy", "urdf_chain"]
