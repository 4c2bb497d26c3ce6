"""inspect_log and ``wholearm inspect`` on a written run and on a real rig log."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner

from cli.inspect import command
from wholearm_tools.errors import LogFormatError
from wholearm_tools.logs import inspect_log, write_run

from .conftest import REAL_50, REAL_TOPICS


def test_inspect_written_run(tmp_path, run):
    path = tmp_path / "run.mcap"
    write_run(path, run, profile="json")
    info = inspect_log(path)
    assert info["profile"] == "json"
    assert info["joint_topic"] == "/joint_states"
    assert info["joints"] == ["joint_1", "joint_2", "joint_3"]
    assert info["urdf"]
    assert info["robot"]["joints"] == info["joints"]
    assert info["commands"] == {"topic": "/joint_commands", "schema":
                                "sensor_msgs/msg/JointState", "torques": True, "positions": True}
    assert info["ground_truth"]["contacts"] == 3
    assert (info["ground_truth"]["tip"], info["ground_truth"]["body"]) == (2, 1)
    topics = {t["topic"]: t for t in info["topics"]}
    assert topics["/joint_states"]["messages"] == 20
    assert topics["/joint_states"]["rate_hz"] == pytest.approx(100.0)
    assert info["duration_s"] == pytest.approx(0.19)
    assert info["metadata"]["wholearm"]["scenario"] == "wall"
    # metadata values are text in the file; numbers come out typed, versions stay text
    assert info["metadata"]["wholearm"]["format_version"] == 1
    assert isinstance(info["metadata"]["wholearm"]["tool_version"], str)

    result = CliRunner().invoke(command, [str(path)])
    assert result.exit_code == 0, result.output
    assert "profile:   json" in result.output
    assert "* joints on /joint_states: joint_1, joint_2, joint_3 (velocity)" in result.output
    assert "truth:     3 contacts (2 tip, 1 body), 1 surfaces" in result.output
    assert "commands:  /joint_commands" in result.output
    result = CliRunner().invoke(command, [str(path), "--json"])
    assert result.exit_code == 0
    assert json.loads(result.output)["ground_truth"]["by_kind"] == {"body": 1, "joint": 1,
                                                                    "tip": 1}
    # a physics run's truth also lists touches that did not stop the arm: said apart
    slid = dataclasses.replace(run, truth=dataclasses.replace(
        run.truth, contact_stopped=np.array([True, False, True])))
    write_run(path, slid, profile="json")
    assert inspect_log(path)["ground_truth"]["stopped"] == 2
    result = CliRunner().invoke(command, [str(path)])
    assert "truth:     3 contacts (2 tip, 1 body, 2 stopped the arm), 1 surfaces" in result.output


def test_inspect_errors_are_log_format_errors(tmp_path):
    path = tmp_path / "x.mcap"
    path.write_text("nope")
    result = CliRunner().invoke(command, [str(path)])
    assert result.exit_code != 0
    assert isinstance(result.exception, LogFormatError)
    assert "not an MCAP file" in str(result.exception)


@pytest.mark.skipif(not REAL_50.exists(), reason="real logs not available")
def test_inspect_real_log():
    info = inspect_log(REAL_50)
    assert info["profile"] == "ros2"
    assert info["joint_topic"] is None  # four JointState topics, no /joint_states
    assert set(info["joint_topics"]) == set(REAL_TOPICS)
    assert not info["urdf"]
    assert info["commands"] is None
    assert info["ground_truth"] is None
    for topic in REAL_TOPICS:
        jt = info["joint_topics"][topic]
        assert len(jt["joints"]) == 7
        assert 40 < jt["rate_hz"] < 60
        assert jt["velocity"] == ("follow" in topic)
    assert info["duration_s"] == pytest.approx(74.7, abs=0.1)
    assert "log_stamps" in info["attachments"]
    result = CliRunner().invoke(command, [str(REAL_50), "--joint-topic", REAL_TOPICS[0]])
    assert result.exit_code == 0, result.output
    assert f"* joints on {REAL_TOPICS[0]}: shoulder_pan" in result.output
    assert "URDF:      no" in result.output
    assert "sensor_msgs/msg/CameraInfo" in result.output
    result = CliRunner().invoke(command, [str(REAL_50), "--joint-topic", "/nope"])
    assert isinstance(result.exception, LogFormatError)
