"""``wholearm robot``: the chain and capsules of a URDF, the capsule URDF written back, and the
shared rig options (--robot, --base-link, --tip-link, --package-path, --effort, --stiffness)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from cli.main import cli
from cli.options import RigOptions
from wholearm_tools.robot import load_urdf_chain


def run(*args: str):
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_robot_prints_the_chain_and_writes_the_capsules(mesh_urdf: Path, tmp_path) -> None:
    out = tmp_path / "capsules.urdf"
    res = run("robot", mesh_urdf, "--package-path", mesh_urdf.parent / "share", "--tip-link",
              "tool", "--write-capsules", out)
    assert res.exit_code == 0, res.output
    assert "chain 'base_link' → 'tool', 3 revolute joints" in res.stdout
    assert "link 0 (upper, joint 'pan'): length 0.3000 m, radius 0.0283 m" in res.stdout
    assert "not modelled: link 'finger_link' (behind joint 'finger'" in res.stdout
    back = load_urdf_chain(out)
    assert back.robot.joint_names == ("pan", "lift", "elbow")
    np.testing.assert_allclose(back.robot.link_radii, [0.0282843, 0.0180278, 0.0141421],
                               rtol=1e-5)
    again = run("robot", mesh_urdf, "--package-path", mesh_urdf.parent / "share", "--tip-link",
                "tool", "--write-capsules", out)
    assert again.exit_code == 1
    assert "already exists (use --overwrite" in again.output


def test_robot_json_and_the_ambiguous_branch(mesh_urdf: Path) -> None:
    res = run("robot", mesh_urdf, "--package-path", mesh_urdf.parent / "share")
    assert res.exit_code == 1
    lines = res.output.strip().splitlines()
    assert lines[0].startswith("Error: ")
    assert "choose the chain's end with --tip-link" in lines[0]
    res = run("robot", mesh_urdf, "--package-path", mesh_urdf.parent / "share", "--tip-link",
              "finger_link", "--json")
    assert res.exit_code == 0, res.output
    info = json.loads(res.stdout)
    assert info["joints"] == ["pan", "lift", "elbow", "finger"]
    assert [link["method"] for link in info["links"]] == ["mesh"] * 4
    assert info["links"][0]["radius"] > 0.028


def test_rig_options_reach_read_run() -> None:
    rig = RigOptions(Path("arm.urdf"), None, "tool", (Path("share"),), "position", (5.0,),
                     (0.001, 0.002), (0.003,))
    assert rig.read_kwargs() == {"robot": "arm.urdf", "base_link": None, "tip_link": "tool",
                                 "package_paths": ("share",), "effort": "position",
                                 "stiffness": 5.0, "joint_compliance": (0.001, 0.002),
                                 "joint_backlash": 0.003}
    res = run("contacts", "--help")
    for option in ("--robot", "--base-link", "--tip-link", "--package-path", "--effort",
                   "--stiffness", "--joint-compliance", "--joint-backlash"):
        assert option in res.output
    res = run("contacts", __file__, "--B", "0.02", "--effort", "position", "--stiffness", "a,b")
    assert res.exit_code == 2
    assert "expected a number or comma-separated numbers" in res.output
    res = run("contacts", __file__, "--B", "0.02", "--joint-compliance", "-0.001")
    assert res.exit_code == 2
    assert "expected non-negative compliance values" in res.output
    res = run("contacts", __file__, "--B", "0.02", "--joint-backlash", "0.001,x")
    assert res.exit_code == 2
    assert "expected a number or comma-separated numbers" in res.output
    learn = RigOptions(compliance="auto")
    assert learn.learn_compliance
    assert learn.read_kwargs(maps=True)["joint_compliance"] is None
    res = run("contacts", __file__, "--B", "0.02", "--joint-compliance", "auto")
    assert res.exit_code == 2
    assert "--joint-compliance auto learns the drives' compliance from a fitted map" in res.output
    assert RigOptions(backlash="auto").learning() == {"learn_backlash": True}
    res = run("contacts", __file__, "--B", "0.02", "--joint-backlash", "auto")
    assert res.exit_code == 2
    assert "--joint-backlash auto learns the drives' play from a fitted map" in res.output


def test_robot_with_a_log_takes_the_branch_it_drives(mesh_urdf: Path, tmp_path) -> None:
    from wholearm_tools.logs import JointLog, Run, write_run
    from wholearm_tools.robot import RobotModel

    names = ("pan", "lift", "elbow", "gripper_finger")
    logged = RobotModel.from_spec({"joints": [
        {"name": n, "radius": 0.01, "origin": [0.1 * (i > 0), 0, 0]}
        for i, n in enumerate(names)], "tip": {"offset": [0.1, 0, 0]}})
    t = np.arange(5) * 0.01
    log = JointLog(names, t, np.zeros((5, 4)), np.zeros((5, 4)))
    path = tmp_path / "rig.mcap"
    write_run(path, Run(robot=logged, log=log))
    res = run("robot", mesh_urdf, "--package-path", mesh_urdf.parent / "share", "--log", path)
    assert res.exit_code == 0, res.output
    assert "chain 'base_link' → 'tool'" in res.stdout
    assert "log joint 'gripper_finger' ignored: not in the URDF" in res.stdout
