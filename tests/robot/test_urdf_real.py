"""Real-style URDFs: mesh and box collisions fitted with covering capsules, branches reduced
to one chain, package:// meshes, and the descriptions that cannot work refused in one line."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from wholearm_tools.errors import RobotModelError
from wholearm_tools.robot import RobotModel, load_urdf, robot_from_urdf, robot_to_urdf
from wholearm_tools.robot.urdf import MAX_URDF_BYTES, RobotWarning, load_urdf_chain

ARM = ("pan", "lift", "elbow")
DATASETS = Path(__file__).resolve().parents[2] / "datasets"


def load_arm(path: Path, **options):
    with pytest.warns(RobotWarning, match=r"finger_link.*not modelled"):
        return load_urdf_chain(path, package_paths=[path.parent / "share"], **options)


def test_mesh_and_box_links_get_covering_capsules(mesh_urdf: Path) -> None:
    chain = load_arm(mesh_urdf, tip_link="tool")
    robot = chain.robot
    assert robot.joint_names == ARM
    # upper: a 0.04 x 0.04 x 0.3 box along the pan → lift axis: corners at sqrt(2) * 0.02
    # fore: a 0.25 x 0.03 x 0.02 box: sqrt(0.015² + 0.01²); hand: the 0.2 x 0.04 x 0.04 box
    # scaled by 0.5: sqrt(2) * 0.01
    np.testing.assert_allclose(robot.link_radii, [np.hypot(0.02, 0.02), np.hypot(0.015, 0.01),
                                                  np.hypot(0.01, 0.01)], rtol=1e-6)  # float32 STL
    np.testing.assert_allclose(robot.tip_offset, [0.1, 0.0, 0.0])
    np.testing.assert_allclose(robot.joint_positions(np.zeros(3)),
                               [[0, 0, 0.1], [0, 0, 0.4], [0.25, 0, 0.4], [0.35, 0, 0.4]],
                               atol=1e-12)
    assert [f.method for f in chain.fits] == ["mesh", "mesh", "mesh"]
    assert all(f.over_cover > 1.0 for f in chain.fits)
    assert (robot.lower[2], robot.upper[2]) == (-np.pi, np.pi)  # continuous joint
    assert chain.chain.not_modelled == (("finger_link", "finger"),)


def test_capsule_covers_every_mesh_vertex_in_any_pose(mesh_urdf: Path) -> None:
    import trimesh

    robot = load_arm(mesh_urdf, tip_link="tool").robot
    upper = trimesh.load(mesh_urdf.parent / "share/arm_description/meshes/upper.stl").vertices
    q = np.random.default_rng(0).uniform(-2, 2, size=(5, 3))
    frames = robot.frames(q)
    a, b = robot.link_segments(q)
    for k in range(q.shape[0]):
        pts = (upper + np.array([0, 0, 0.15])) @ frames[k, 0, :3, :3].T + frames[k, 0, :3, 3]
        ab = b[k, 0] - a[k, 0]
        s = np.clip((pts - a[k, 0]) @ ab / (ab @ ab), 0, 1)
        dist = np.linalg.norm(pts - (a[k, 0] + s[:, None] * ab), axis=1)
        assert dist.max() <= robot.link_radii[0] + 1e-12
        assert dist.max() == pytest.approx(robot.link_radii[0])  # and no larger than needed


def test_branch_without_tip_link_is_ambiguous(mesh_urdf: Path) -> None:
    with pytest.raises(RobotModelError, match=re.escape(
            "branches at link 'hand'; choose the chain's end with --tip-link: 'tool' (3 joints, "
            "last 'elbow'); 'finger_link' (4 joints, last 'finger')")):
        load_urdf_chain(mesh_urdf, package_paths=[mesh_urdf.parent / "share"])


def test_log_joints_pick_the_branch_they_drive(mesh_urdf: Path) -> None:
    chain = load_arm(mesh_urdf, joints=[*ARM, "gripper_finger"])
    assert chain.chain.tip == "tool"
    assert chain.ignored_log_joints([*ARM, "finger", "gripper_finger", "tool_joint"]) == {
        "finger": "URDF joint off the chain", "gripper_finger": "not in the URDF",
        "tool_joint": "fixed joint in the URDF"}


def test_chain_to_a_link_without_tip_frame_ends_at_its_farthest_point(mesh_urdf: Path) -> None:
    chain = load_urdf_chain(mesh_urdf, package_paths=[mesh_urdf.parent / "share"],
                            tip_link="finger_link")
    assert chain.robot.joint_names == (*ARM, "finger")
    # the finger box spans x 0..0.04, y and z ±0.005: its far corners are the tip
    assert np.linalg.norm(chain.robot.tip_offset) == pytest.approx(np.sqrt(0.04**2 + 5e-5))
    assert "farthest from joint 'finger'" in chain.tip_note


def test_base_link_starts_the_chain_and_joints_above_it_are_refused(mesh_urdf: Path) -> None:
    chain = load_arm(mesh_urdf, base_link="upper", tip_link="tool")
    assert chain.robot.joint_names == ("lift", "elbow")
    np.testing.assert_allclose(chain.robot.joint_positions(np.zeros(2))[0], [0, 0, 0.3])
    with pytest.raises(RobotModelError, match="log joint 'pan' moves the chain's base 'upper'"):
        chain.ignored_log_joints(["pan", "lift", "elbow"])


def test_package_paths_resolve_meshes_and_name_the_missing_package(mesh_urdf: Path) -> None:
    with pytest.raises(RobotModelError, match=r"link 'upper': mesh 'package://arm_description/"
                                              r"meshes/upper.stl' not found: package "
                                              r"'arm_description' is not in the --package-path"):
        load_urdf_chain(mesh_urdf, tip_link="tool")
    direct = load_arm(mesh_urdf, tip_link="tool")  # folder holding the package
    pkg = mesh_urdf.parent / "share" / "arm_description"
    with pytest.warns(RobotWarning):
        itself = load_urdf_chain(mesh_urdf, tip_link="tool", package_paths=[pkg])
    np.testing.assert_array_equal(direct.robot.link_radii, itself.robot.link_radii)


def test_capsule_urdf_written_back_reads_as_the_same_robot(mesh_urdf: Path, tmp_path) -> None:
    chain = load_arm(mesh_urdf, tip_link="tool")
    text = robot_to_urdf(chain.robot, notes=[f.describe() for f in chain.fits])
    assert "capsule fitted to the collision geometry of upper" in text
    back = load_urdf_chain_text(text, tmp_path)
    assert [f.method for f in back.fits] == ["capsule"] * 3
    q = np.random.default_rng(2).uniform(-1, 1, size=(4, 3))
    np.testing.assert_allclose(back.robot.joint_positions(q), chain.robot.joint_positions(q),
                               atol=1e-8)
    np.testing.assert_allclose(back.robot.link_radii, chain.robot.link_radii, rtol=1e-8)


def load_urdf_chain_text(text: str, folder: Path):
    path = folder / "capsules.urdf"
    path.write_text(text)
    return load_urdf_chain(path)


@pytest.mark.parametrize("name", ["lab_circle", "lab_sharp", "paper_planar", "paper_spatial",
                                  "well_junction"])
def test_bundled_capsule_urdfs_round_trip_exactly(name: str) -> None:
    robot = load_urdf(DATASETS / f"{name}.urdf")
    back = robot_from_urdf(robot_to_urdf(robot))
    for attr in ("origins", "axes", "tip_offset", "link_radii", "lower", "upper",
                 "velocity_limits", "effort_limits"):
        np.testing.assert_array_equal(getattr(back, attr), getattr(robot, attr), err_msg=attr)
    assert back.tip_radius == robot.tip_radius


def _capsule_arm(last_offset: str) -> str:
    return f"""<robot name="hand_made"><link name="base"/>
      <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
        <axis xyz="0 0 1"/><limit lower="-1" upper="1"/></joint>
      <link name="l1"><collision><geometry><cylinder radius="0.02" length="0.3"/></geometry>
        </collision></link>
      <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
        <origin xyz="0.3 0 0"/><axis xyz="0 0 1"/><limit lower="-1" upper="1"/></joint>
      <link name="l2"><collision><geometry><sphere radius="0.02"/></geometry></collision></link>
      {last_offset}</robot>"""


def test_zero_length_last_link_is_refused_before_any_computation() -> None:
    with pytest.raises(RobotModelError, match=r"chain ends at joint 'j2' with no tip: its link "
                                              r"'l2' has zero length"):
        robot_from_urdf(_capsule_arm(""), source="hand.urdf")
    tip = """<joint name="tip" type="fixed"><parent link="l2"/><child link="t"/>
               <origin xyz="0.2 0 0"/></joint><link name="t"/>"""
    assert robot_from_urdf(_capsule_arm(tip)).dof == 2
    with pytest.raises(RobotModelError, match="the last link has zero length"):
        RobotModel.from_spec({"joints": [{"radius": 0.02}], "tip": {"offset": [0, 0, 0]}})


def test_xacro_is_named() -> None:
    text = """<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">
      <xacro:include filename="$(find arm)/arm.xacro"/></robot>"""
    with pytest.raises(RobotModelError, match=r"arm.urdf.xacro: a xacro file .*expand it first"):
        robot_from_urdf(text, source="arm.urdf.xacro")
    with pytest.raises(RobotModelError, match="a xacro file"):
        robot_from_urdf(text, source="arm.urdf")


@pytest.mark.parametrize("doctype", [
    '<!DOCTYPE r [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">]>',
    '<!DOCTYPE r [<!ENTITY x SYSTEM "file:///etc/passwd">]>',
    '<!DOCTYPE r SYSTEM "http://example.com/robot.dtd">',
])
def test_hostile_xml_is_refused(doctype: str) -> None:
    with pytest.raises(RobotModelError, match=r"evil.urdf: refused: the URDF declares a DOCTYPE"):
        robot_from_urdf(f'{doctype}<robot name="r"><link name="&b;"/></robot>',
                        source="evil.urdf")


def test_oversized_urdf_is_refused(tmp_path) -> None:
    path = tmp_path / "huge.urdf"
    with path.open("wb") as handle:
        handle.truncate(MAX_URDF_BYTES + 1)
    with pytest.raises(RobotModelError, match=r"huge.urdf: URDF of 16.0 MiB exceeds the 16 MiB"):
        load_urdf(path)


def test_unknown_links_and_unsupported_chain_joints_are_named(mesh_urdf: Path) -> None:
    with pytest.raises(RobotModelError, match=r"no link 'gripper' \(--tip-link\); links: "
                                              "base_link, upper"):
        load_urdf_chain(mesh_urdf, tip_link="gripper")
    with pytest.raises(RobotModelError, match="link 'upper' is not below the base link 'fore'"):
        load_urdf_chain(mesh_urdf, base_link="fore", tip_link="upper")


def test_joints_at_one_point_are_refused() -> None:
    wrist = """<joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
        <axis xyz="1 0 0"/><limit lower="-1" upper="1"/></joint>
      <link name="l3"><collision><geometry><sphere radius="0.02"/></geometry></collision></link>
      <joint name="tip" type="fixed"><parent link="l3"/><child link="t"/>
        <origin xyz="0.2 0 0"/></joint><link name="t"/>"""
    with pytest.raises(RobotModelError, match=r"wrist.urdf: joints 'j2' and 'j3' sit at one "
                                              r"point \(link 'l2' has zero length\)"):
        robot_from_urdf(_capsule_arm(wrist), source="wrist.urdf")
