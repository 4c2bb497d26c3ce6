"""A small real-style URDF built in tmp_path: STL mesh collisions, a package:// path, a branch
(a tool frame and a moving finger below the last link)."""

from __future__ import annotations

from pathlib import Path

import pytest

ARM_JOINTS = ("pan", "lift", "elbow")

URDF = """<?xml version="1.0"?>
<robot name="mesh_arm">
  <link name="base_link">
    <collision><geometry><mesh filename="meshes/base.stl"/></geometry></collision>
  </link>
  <joint name="pan" type="revolute">
    <parent link="base_link"/><child link="upper"/>
    <origin xyz="0 0 0.1" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="5" velocity="2"/>
  </joint>
  <link name="upper">
    <collision><origin xyz="0 0 0.15"/>
      <geometry><mesh filename="package://arm_description/meshes/upper.stl"/></geometry>
    </collision>
  </link>
  <joint name="lift" type="revolute">
    <parent link="upper"/><child link="fore"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="5" velocity="2"/>
  </joint>
  <link name="fore">
    <collision><origin xyz="0.125 0 0"/>
      <geometry><box size="0.25 0.03 0.02"/></geometry></collision>
  </link>
  <joint name="elbow" type="continuous">
    <parent link="fore"/><child link="hand"/>
    <origin xyz="0.25 0 0"/><axis xyz="0 1 0"/>
  </joint>
  <link name="hand">
    <collision><origin xyz="0.05 0 0"/>
      <geometry><mesh filename="meshes/hand.stl" scale="0.5 0.5 0.5"/></geometry></collision>
  </link>
  <joint name="tool_joint" type="fixed">
    <parent link="hand"/><child link="tool"/><origin xyz="0.1 0 0"/>
  </joint>
  <link name="tool"/>
  <joint name="finger" type="revolute">
    <parent link="hand"/><child link="finger_link"/>
    <origin xyz="0.06 0.01 0"/><axis xyz="0 0 1"/>
    <limit lower="0" upper="1" effort="1" velocity="1"/>
  </joint>
  <link name="finger_link">
    <collision><origin xyz="0.02 0 0"/><geometry><box size="0.04 0.01 0.01"/></geometry></collision>
  </link>
</robot>
"""


@pytest.fixture
def mesh_urdf(tmp_path: Path) -> Path:
    """The URDF above with its STL meshes: ``upper`` a 0.04 x 0.04 x 0.3 box found through
    ``package://arm_description`` (folder ``tmp_path/share``), ``hand`` a 0.2 x 0.04 x 0.04 box
    scaled by 0.5, and a base block."""
    import trimesh

    (tmp_path / "meshes").mkdir()
    package = tmp_path / "share" / "arm_description" / "meshes"
    package.mkdir(parents=True)
    trimesh.creation.box(extents=(0.1, 0.1, 0.05)).export(tmp_path / "meshes" / "base.stl")
    trimesh.creation.box(extents=(0.04, 0.04, 0.3)).export(package / "upper.stl")
    trimesh.creation.box(extents=(0.2, 0.04, 0.04)).export(tmp_path / "meshes" / "hand.stl")
    path = tmp_path / "arm.urdf"
    path.write_text(URDF)
    return path
