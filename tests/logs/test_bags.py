"""Bags in: a rosbag2 folder (MCAP storage), a bare .db3 and a ROS 1 .bag, written with rosbags'
own writers, read back through read_run exactly as the MCAP log of the same run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from wholearm_tools.errors import LogFormatError
from wholearm_tools.logs import read_run
from wholearm_tools.logs.records import Run
from wholearm_tools.robot import robot_to_urdf


def _messages(run: Run, ros1: bool, commands: bool = True, measured: float = 0.5):
    """``(topic, msgtype, timestamp, message)`` of the run: states (with ``measured`` times
    the commanded torque as their effort), commands, the URDF."""
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.LATEST)
    t = ts.types
    log = run.log
    stamps = log.t0_ns + np.round(log.t * 1e9).astype(np.int64)
    names = list(log.joint_names)

    def header(i: int, ns: int):
        stamp = t["builtin_interfaces/msg/Time"](sec=int(ns // 10**9), nanosec=int(ns % 10**9))
        extra = {"seq": i} if ros1 else {}
        return t["std_msgs/msg/Header"](stamp=stamp, frame_id="", **extra)

    state = t["sensor_msgs/msg/JointState"]
    out = [("/robot_description", "std_msgs/msg/String", int(stamps[0]),
            t["std_msgs/msg/String"](data=robot_to_urdf(run.robot)))]
    for i, ns in enumerate(stamps.tolist()):
        out.append(("/joint_states", "sensor_msgs/msg/JointState", ns, state(
            header=header(i, ns), name=names, position=np.array(log.q[i]),
            velocity=np.array(log.qd[i]), effort=np.array(log.tau_cmd[i]) * measured)))
        if commands:
            out.append(("/joint_commands", "sensor_msgs/msg/JointState", ns, state(
                header=header(i, ns), name=names, position=np.array(log.q_cmd[i]),
                velocity=np.zeros(0), effort=np.array(log.tau_cmd[i]))))
    return ts, out


def write_rosbag2(run: Run, folder: Path, storage: str, **options) -> Path:
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts, messages = _messages(run, ros1=False, **options)
    plugin = {"mcap": StoragePlugin.MCAP, "sqlite3": StoragePlugin.SQLITE3}[storage]
    with Writer(folder, version=9, storage_plugin=plugin) as writer:
        conns = {}
        for topic, msgtype, ns, msg in messages:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], ns, ts.serialize_cdr(msg, msgtype))
    return folder


def write_ros1(run: Run, path: Path) -> Path:
    from rosbags.rosbag1 import Writer

    ts, messages = _messages(run, ros1=True)
    with Writer(path) as writer:
        conns = {}
        for topic, msgtype, ns, msg in messages:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], ns, ts.serialize_ros1(msg, msgtype))
    return path


def assert_same_run(back: Run, run: Run) -> None:
    assert back.robot.joint_names == run.robot.joint_names
    np.testing.assert_allclose(back.robot.joint_positions(np.zeros(3)),
                               run.robot.joint_positions(np.zeros(3)), atol=1e-9)
    assert back.log.t0_ns == run.log.t0_ns
    np.testing.assert_allclose(back.log.t, run.log.t, atol=1e-9)
    for name in ("q", "qd", "tau_cmd", "q_cmd"):
        np.testing.assert_array_equal(getattr(back.log, name), getattr(run.log, name),
                                      err_msg=name)
    assert back.log.torque_source == "commanded"
    assert back.log.torque_note == "commanded torque (effort[] on /joint_commands)"


def test_rosbag2_folder_with_mcap_storage(run: Run, tmp_path) -> None:
    folder = write_rosbag2(run, tmp_path / "bag", "mcap")
    assert (folder / "metadata.yaml").is_file()
    assert_same_run(read_run(folder), run)


def test_rosbag2_sqlite_folder_and_bare_db3(run: Run, tmp_path) -> None:
    folder = write_rosbag2(run, tmp_path / "bag", "sqlite3")
    assert_same_run(read_run(folder), run)
    (db3,) = folder.glob("*.db3")
    alone = tmp_path / "alone" / "run.db3"
    alone.parent.mkdir()
    alone.write_bytes(db3.read_bytes())
    assert_same_run(read_run(alone), run)


def test_ros1_bag(run: Run, tmp_path) -> None:
    bag = write_ros1(run, tmp_path / "run.bag")
    back = read_run(bag)
    assert_same_run(back, run)
    measured = read_run(bag, effort="measured")
    np.testing.assert_array_equal(measured.log.tau_cmd, run.log.tau_cmd * 0.5)
    assert measured.log.torque_source == "measured"


def test_folder_without_metadata_reads_its_single_log(run: Run, tmp_path) -> None:
    folder = write_rosbag2(run, tmp_path / "bag", "mcap")
    (folder / "metadata.yaml").unlink()
    assert_same_run(read_run(folder), run)
    (tmp_path / "empty").mkdir()
    with pytest.raises(LogFormatError, match=r"empty: a folder, but not a rosbag2 recording"):
        read_run(tmp_path / "empty")


def test_bags_under_other_names_are_named(run: Run, tmp_path) -> None:
    folder = write_rosbag2(run, tmp_path / "bag", "sqlite3")
    (db3,) = folder.glob("*.db3")
    odd = tmp_path / "run.log"
    odd.write_bytes(db3.read_bytes())
    with pytest.raises(LogFormatError, match=r"run.log: an SQLite file: rosbag2 SQLite storage "
                                             r"is read from a file named \*.db3"):
        read_run(odd)
    broken = tmp_path / "broken.bag"
    broken.write_bytes(b"#ROSBAG V2.0\n" + b"\x00" * 20)
    with pytest.raises(LogFormatError, match=r"broken.bag: cannot read the bag"):
        read_run(broken)


def test_contacts_from_measured_effort_in_a_bag_match_the_commanded_run(tmp_path) -> None:
    """A simulated run rewritten as a rosbag2 folder whose only torque evidence is the effort
    on /joint_states: `wholearm contacts FOLDER --effort measured` finds the contacts the MCAP
    with commanded torques gives."""
    import json

    from click.testing import CliRunner

    from cli.main import cli

    mcap = tmp_path / "run.mcap"
    runner = CliRunner()
    res = runner.invoke(cli, ["simulate", "lab_circle", "-o", str(mcap), "--duration", "12",
                              "--seed", "1"])
    assert res.exit_code == 0, res.output
    folder = write_rosbag2(read_run(mcap), tmp_path / "bag", "sqlite3", commands=False,
                           measured=1.0)
    res = runner.invoke(cli, ["contacts", str(folder), "--B", "0.02", "--json"])
    assert res.exit_code == 1
    assert "carries measured effort: use --effort measured" in res.output
    ours = runner.invoke(cli, ["contacts", str(folder), "--B", "0.02", "--json", "--effort",
                               "measured"])
    theirs = runner.invoke(cli, ["contacts", str(mcap), "--B", "0.02", "--json"])
    assert ours.exit_code == 0, ours.output
    got, want = json.loads(ours.stdout)["contacts"], json.loads(theirs.stdout)["contacts"]
    assert len(got) == len(want) >= 3
    assert [(c["t"], c["link"], c["p_tip"]) for c in got] == [
        (c["t"], c["link"], c["p_tip"]) for c in want]
