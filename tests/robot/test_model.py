"""Robot model: forward kinematics against hand-computed poses, velocities, URDF round trip."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from wholearm_tools.errors import InputError, RobotModelError
from wholearm_tools.robot import RobotModel, load_urdf, robot_from_urdf, robot_to_urdf
from wholearm_tools.robot.model import PLAY_TORQUE


def planar_two_link(l1: float = 0.5, l2: float = 0.3) -> RobotModel:
    return RobotModel.from_spec({
        "joints": [{"origin": [0, 0, 0], "radius": 0.02}, {"origin": [l1, 0, 0], "radius": 0.01}],
        "tip": {"offset": [l2, 0, 0], "radius": 0.015},
    }, name="two_link")


def spatial_three_dof() -> RobotModel:
    # yaw about z, then pitch about y at a 0.2 m high shoulder, then pitch about y at the elbow
    return RobotModel.from_spec({
        "joints": [
            {"origin": [0, 0, 0], "axis": [0, 0, 1], "radius": 0.03},
            {"origin": [0, 0, 0.2], "axis": [0, 1, 0], "radius": 0.02},
            {"origin": [0.4, 0, 0], "axis": [0, 1, 0], "radius": 0.02},
        ],
        "tip": {"offset": [0.3, 0, 0], "radius": 0.0},
    }, name="yaw_pitch_pitch")


@pytest.mark.parametrize(("q1", "q2"), [(0.0, 0.0), (np.pi / 2, 0.0), (0.3, -1.1), (-2.0, 2.5)])
def test_planar_two_link_matches_textbook_formula(q1: float, q2: float) -> None:
    robot = planar_two_link()
    pts = robot.joint_positions([q1, q2])
    elbow = [0.5 * np.cos(q1), 0.5 * np.sin(q1), 0.0]
    tip = [elbow[0] + 0.3 * np.cos(q1 + q2), elbow[1] + 0.3 * np.sin(q1 + q2), 0.0]
    np.testing.assert_allclose(pts, [[0, 0, 0], elbow, tip], atol=1e-12)
    assert robot.planar
    assert robot.dim == 2


def test_spatial_pose_by_hand() -> None:
    robot = spatial_three_dof()
    # yaw 90 deg turns the arm to +y; shoulder pitch +90 deg about y points the upper arm down (-z)
    pts = robot.joint_positions([np.pi / 2, np.pi / 2, 0.0])
    np.testing.assert_allclose(pts[2], [0.0, 0.0, 0.2 - 0.4], atol=1e-12)
    np.testing.assert_allclose(pts[3], [0.0, 0.0, 0.2 - 0.7], atol=1e-12)
    # elbow -90 deg brings the forearm back to horizontal, pointing along +y
    pts = robot.joint_positions([np.pi / 2, np.pi / 2, -np.pi / 2])
    np.testing.assert_allclose(pts[3], [0.0, 0.3, -0.2], atol=1e-12)
    assert not robot.planar


def test_batched_fk_equals_loop() -> None:
    robot = spatial_three_dof()
    q = np.random.default_rng(1).uniform(-2, 2, size=(5, 4, 3))
    batched = robot.joint_positions(q)
    assert batched.shape == (5, 4, 4, 3)
    np.testing.assert_allclose(batched[3, 2], robot.joint_positions(q[3, 2]), atol=1e-14)


def test_point_velocity_matches_finite_difference() -> None:
    robot = spatial_three_dof()
    rng = np.random.default_rng(7)
    q, qd = rng.uniform(-1, 1, 3), rng.uniform(-1, 1, 3)
    h = 1e-6
    for link in range(3):
        for s in (0.0, 0.4, 1.0):
            def point(qq: np.ndarray, link: int = link, s: float = s) -> np.ndarray:
                a, b = robot.link_segments(qq)
                return a[link] + s * (b[link] - a[link])
            fd = (point(q + h * qd) - point(q - h * qd)) / (2 * h)
            np.testing.assert_allclose(robot.point_velocities(q, qd, link, s), fd, atol=1e-7)


def test_inner_link_velocity_ignores_outer_joints() -> None:
    robot = spatial_three_dof()
    v = robot.point_velocities([0.1, 0.2, 0.3], [0.0, 0.0, 5.0], link=1, s=0.5)
    np.testing.assert_allclose(v, 0.0, atol=1e-15)


def test_urdf_round_trip(tmp_path) -> None:
    for robot in (planar_two_link(), spatial_three_dof()):
        path = tmp_path / f"{robot.name}.urdf"
        path.write_text(robot_to_urdf(robot))
        back = load_urdf(path)
        q = np.random.default_rng(3).uniform(-1, 1, size=(6, robot.dof))
        np.testing.assert_allclose(back.joint_positions(q), robot.joint_positions(q), atol=1e-8)
        np.testing.assert_allclose(back.link_radii, robot.link_radii)
        assert back.tip_radius == pytest.approx(robot.tip_radius)
        assert back.joint_names == robot.joint_names
        np.testing.assert_allclose([back.lower, back.upper], [robot.lower, robot.upper])


def test_urdf_errors_name_the_problem(tmp_path) -> None:
    with pytest.raises(RobotModelError, match="malformed URDF"):
        robot_from_urdf("<robot><link name='a'>", source="bad.urdf")
    with pytest.raises(RobotModelError, match="no collision or visual geometry"):
        robot_from_urdf("""<robot name="r"><link name="base"/><link name="l1"/>
            <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
            <axis xyz="0 0 1"/></joint></robot>""", source="meshes.urdf")
    with pytest.raises(RobotModelError, match="unsupported type 'prismatic'"):
        robot_from_urdf("""<robot name="r"><link name="base"/><link name="l1"/>
            <joint name="j1" type="prismatic"><parent link="base"/><child link="l1"/></joint>
            </robot>""")
    with pytest.raises(RobotModelError, match=r"missing\.urdf: cannot read URDF"):
        load_urdf(tmp_path / "missing.urdf")


def test_invalid_configurations_are_rejected() -> None:
    robot = planar_two_link()
    with pytest.raises(InputError, match=r"shape \(\.\.\., 2\)"):
        robot.joint_positions([0.1, 0.2, 0.3])
    with pytest.raises(InputError, match="NaN"):
        robot.joint_positions([np.nan, 0.0])
    with pytest.raises(RobotModelError, match="lower limit"):
        RobotModel.from_spec({"joints": [{"radius": 0.01, "limits": [1, -1]}],
                              "tip": {"offset": [1, 0, 0]}})


def test_motor_side_readings_become_link_angles_by_the_transmissions_deflection() -> None:
    stiff = planar_two_link()
    q = np.array([[0.3, -0.2], [0.31, -0.19]])
    tau = np.array([[5.0, -2.0], [-10.0, 0.0]])
    assert np.array_equal(stiff.link_angles(q, tau), q)
    compliant = dataclasses.replace(stiff, joint_compliance=[0.001, 0.002])
    effort = compliant.effort_limits
    np.testing.assert_allclose(compliant.link_angles(q, tau),
                               q - tau * np.array([0.001, 0.002]) / effort)
    assert np.array_equal(compliant.link_angles(q, None), q)  # no torque logged: as read
    with pytest.raises(RobotModelError, match="non-negative"):
        dataclasses.replace(stiff, joint_compliance=-0.001)
    with pytest.raises(RobotModelError, match="one joint compliance or 2"):
        dataclasses.replace(stiff, joint_compliance=[0.001, 0.001, 0.001])
    with pytest.raises(RobotModelError, match="positive effort limit"):
        dataclasses.replace(stiff, effort_limits=[0.0, 1.0], joint_compliance=0.001)


def test_a_drives_play_is_closed_on_the_side_it_last_pushed() -> None:
    """Backlash: the reading leads the link by half the play in the direction the drive
    pushes, and keeps the side it last pushed while the torque is too small to turn the motor
    through the gap (nothing is known before the first push)."""
    robot = dataclasses.replace(planar_two_link(), joint_backlash=[0.002, 0.0])
    band = PLAY_TORQUE * robot.effort_limits[0]
    tau = np.zeros((6, 2))
    tau[:, 0] = [0.0, 3 * band, 0.5 * band, -0.5 * band, -3 * band, 0.0]
    np.testing.assert_array_equal(robot.load_direction(tau)[:, 0], [0, 1, 1, 1, -1, -1])
    q = np.full((6, 2), 0.3)
    link = robot.link_angles(q, tau)
    np.testing.assert_allclose(link[:, 0], 0.3 - 0.001 * np.array([0, 1, 1, 1, -1, -1]))
    np.testing.assert_array_equal(link[:, 1], q[:, 1])     # a joint without play: as read
    with pytest.raises(RobotModelError, match="one joint backlash or 2"):
        dataclasses.replace(robot, joint_backlash=[0.001, 0.001, 0.001])
    with pytest.raises(RobotModelError, match="backlash must be finite and non-negative"):
        dataclasses.replace(robot, joint_backlash=float("nan"))
