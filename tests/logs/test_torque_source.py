"""The torque evidence from what a rig logs: commanded torque, measured effort on the state
topic, or commanded position times the controller's stiffness; the choice recorded."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap_ros2.writer import Writer as Ros2Writer

from wholearm_tools.errors import InputError, LogFormatError
from wholearm_tools.logs import read_joint_log, read_run
from wholearm_tools.logs.records import JointLog
from wholearm_tools.logs.schemas import JOINT_STATE, ROS2_DEFINITIONS

# the logs below carry a gripper joint the 3-joint robots lack (asserted once, below)
pytestmark = pytest.mark.filterwarnings("ignore:.*ignoring joints not in the robot")

NAMES = ("joint_1", "joint_2", "joint_3")
STAMPS = 1_700_000_000_000_000_000 + np.arange(6) * 10_000_000
Q = np.arange(18.0).reshape(6, 3) * 0.01
EFFORT = np.arange(18.0).reshape(6, 3) * -0.1
LEADER = Q + 0.02


def write(path, *, effort=True, leader=True, metadata=None):
    """States on /arm/joint_states (with measured effort), and a leader arm's positions on
    /arm_lead/joint_states (the commanded positions of a teleoperated arm)."""
    with open(path, "wb") as handle:
        writer = Ros2Writer(handle)
        schema = writer.register_msgdef(JOINT_STATE, ROS2_DEFINITIONS[JOINT_STATE])
        for i, stamp in enumerate(STAMPS.tolist()):
            sec, nanosec = divmod(stamp, 10**9)
            header = {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": ""}
            writer.write_message("/arm/joint_states", schema, {
                "header": header, "name": [*NAMES, "gripper"], "position": [*Q[i], 0.5],
                "velocity": [], "effort": [*EFFORT[i], 1.0] if effort else []}, log_time=stamp)
            if leader:
                writer.write_message("/arm_lead/joint_states", schema, {
                    "header": header, "name": list(NAMES), "position": list(LEADER[i]),
                    "velocity": [], "effort": []}, log_time=stamp)
        for name, data in (metadata or {}).items():
            writer.add_metadata(name, data)
        writer.finish()
    return path


def test_measured_effort_on_the_state_topic(tmp_path, robot) -> None:
    path = write(tmp_path / "rig.mcap")
    with pytest.raises(LogFormatError, match=r"no commanded torques .*'/arm/joint_states' "
                                             r"carries measured effort: use --effort measured"):
        read_run(path, joint_topic="/arm/joint_states", robot=robot, require_commands=True)
    with pytest.warns(UserWarning, match=r"ignoring joints not in the robot: \['gripper'\]"):
        run = read_run(path, joint_topic="/arm/joint_states", robot=robot, effort="measured",
                       require_commands=True)
    np.testing.assert_array_equal(run.log.tau_cmd, EFFORT)
    assert run.log.torque_source == "measured"
    assert run.log.torque_note == "measured effort (effort[] on /arm/joint_states)"
    assert run.log.ignored_joints == ("gripper",)


def test_measured_effort_must_be_logged(tmp_path) -> None:
    path = write(tmp_path / "rig.mcap", effort=False)
    with pytest.raises(LogFormatError, match=r"'/arm/joint_states' has no measured effort\[\] "
                                             r"for joints \['joint_1', 'joint_2', 'joint_3'\]"):
        read_joint_log(path, joint_topic="/arm/joint_states", joint_names=NAMES,
                       effort="measured")


def test_the_state_topic_is_never_read_as_commands(tmp_path) -> None:
    path = write(tmp_path / "rig.mcap")
    for effort in ("commanded", "position"):
        with pytest.raises(LogFormatError, match=r"the command topic '/arm/joint_states' is the "
                                                 r"state topic: its effort\[\] is the measured"):
            read_joint_log(path, joint_topic="/arm/joint_states",
                           command_topic="/arm/joint_states", effort=effort, stiffness=1.0)
    log = read_joint_log(path, joint_topic="/arm/joint_states", joint_names=NAMES,
                         command_topic="/arm/joint_states", effort="measured")
    assert log.torque_source == "measured"


def test_commanded_position_times_stiffness(tmp_path) -> None:
    path = write(tmp_path / "rig.mcap")
    options = {"joint_topic": "/arm/joint_states", "joint_names": NAMES,
               "command_topic": "/arm_lead/joint_states", "effort": "position"}
    with pytest.raises(InputError, match=r"--effort position needs the controller's stiffness"):
        read_joint_log(path, **options)
    log = read_joint_log(path, stiffness=[2.0, 3.0, 4.0], **options)
    np.testing.assert_allclose(log.tau_cmd, 0.02 * np.array([2.0, 3.0, 4.0]) * np.ones((6, 1)))
    np.testing.assert_array_equal(log.q_cmd, LEADER)
    assert log.torque_source == "position"
    assert log.torque_note == ("stiffness [2, 3, 4] N m/rad (given) x (commanded - measured "
                               "position), commands on /arm_lead/joint_states")
    with pytest.raises(InputError, match=r"expected one stiffness or 3 \(one per joint"):
        read_joint_log(path, stiffness=[1.0, 2.0], **options)
    with pytest.raises(InputError, match="stiffness must be positive"):
        read_joint_log(path, stiffness=-1.0, **options)


def test_stiffness_from_the_log_metadata(tmp_path) -> None:
    path = write(tmp_path / "rig.mcap", metadata={"wholearm": {"stiffness": json.dumps(5.0)}})
    log = read_joint_log(path, joint_topic="/arm/joint_states", joint_names=NAMES,
                         command_topic="/arm_lead/joint_states", effort="position")
    np.testing.assert_allclose(log.tau_cmd, 0.1)
    assert "stiffness 5 N m/rad (from the log's metadata)" in log.torque_note


def test_position_needs_commanded_positions(tmp_path) -> None:
    path = write(tmp_path / "rig.mcap", leader=False)
    with pytest.raises(LogFormatError, match=r"--effort position needs commanded positions"):
        read_joint_log(path, joint_topic="/arm/joint_states", stiffness=1.0, effort="position")
    with pytest.raises(InputError, match=r"effort must be one of \['commanded', 'measured', "
                                         r"'position'\], got 'torque'"):
        read_joint_log(path, joint_topic="/arm/joint_states", effort="torque")


def test_joint_log_records_its_torque_source() -> None:
    t, q = np.arange(3.0), np.zeros((3, 1))
    assert JointLog(("j",), t, q, q, tau_cmd=q).torque_source == "commanded"
    assert JointLog(("j",), t, q, q).torque_source is None
    with pytest.raises(InputError, match="torque_source 'measured' does not fit tau_cmd"):
        JointLog(("j",), t, q, q, torque_source="measured")


def test_positions_outside_the_urdf_limits_are_reported(tmp_path) -> None:
    from wholearm_tools.robot import RobotModel

    path = write(tmp_path / "rig.mcap")
    narrow = RobotModel.from_spec({"joints": [
        {"name": n, "radius": 0.01, "origin": [0.1 * (i > 0), 0, 0], "limits": [-0.05, 0.05]}
        for i, n in enumerate(NAMES)], "tip": {"offset": [0.1, 0, 0]}})
    with pytest.warns(UserWarning, match=r"positions outside the robot's joint limits \[rad\]: "
                                         r"joint_1 0.00..0.15 \(limits -0.05..0.05\); joint_2 "
                                         r"0.01..0.16 .*may not describe this arm"):
        read_run(path, joint_topic="/arm/joint_states", robot=narrow, effort="measured")
