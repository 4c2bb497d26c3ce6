"""Robot models: capsule-link serial chains, forward kinematics, URDF in and out."""

from wholearm_tools.robot.model import RobotModel, rotation_about_axis, transform_from_xyz_rpy
from wholearm_tools.robot.urdf import load_urdf, robot_from_urdf, robot_to_urdf

__all__ = ["RobotModel", "load_urdf", "robot_from_urdf", "robot_to_urdf", "rotation_about_axis",
           "transform_from_xyz_rpy"]
