"""Every way a log can be unusable gives one LogFormatError naming the file; fix-ups warn."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from mcap_ros2.writer import Writer as Ros2Writer

from wholearm_tools.errors import LogFormatError
from wholearm_tools.logs import LogWarning, Run, read_joint_log, read_run, write_run
from wholearm_tools.logs.records import JointLog
from wholearm_tools.logs.schemas import FLOAT64_MULTI_ARRAY, JOINT_STATE, ROS2_DEFINITIONS
from wholearm_tools.robot import RobotModel, robot_to_urdf

from .conftest import REAL_50, make_log

NAMES = ("joint_1", "joint_2", "joint_3")


def write_states(path, stamps, positions, names=NAMES, *, velocity=None, log_times=None,
                 extra=()):
    """A JointState log written with the stock mcap_ros2 writer; ``extra`` adds
    ``(topic, schema_name, message, log_time)`` messages."""
    with open(path, "wb") as handle:
        writer = Ros2Writer(handle)
        schemas = {name: writer.register_msgdef(name, ROS2_DEFINITIONS[name])
                   for name in (JOINT_STATE, FLOAT64_MULTI_ARRAY)}
        for i, (stamp, q) in enumerate(zip(stamps, positions, strict=True)):
            sec, nanosec = divmod(int(stamp), 10**9)
            msg = {"header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": ""},
                   "name": list(names), "position": list(q),
                   "velocity": [] if velocity is None else list(velocity[i]), "effort": []}
            log_time = int(stamp) if log_times is None else int(log_times[i])
            writer.write_message("/joint_states", schemas[JOINT_STATE], msg, log_time=log_time)
        for topic, schema_name, msg, log_time in extra:
            writer.write_message(topic, schemas[schema_name], msg, log_time=log_time)
        writer.finish()


def test_not_mcap_and_empty(tmp_path):
    text = tmp_path / "notes.mcap"
    text.write_text("hello, this is not a log\n")
    with pytest.raises(LogFormatError, match=r"notes\.mcap: not an MCAP file"):
        read_run(text)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(LogFormatError, match=r"empty\.mcap: empty file"):
        read_joint_log(empty)
    with pytest.raises(LogFormatError, match=r"missing\.mcap: cannot read log"):
        read_joint_log(tmp_path / "missing.mcap")


def test_truncated_mid_chunk_reads_messages_before_the_cut(tmp_path, robot):
    run = Run(robot=robot, log=make_log(n=400))
    path = tmp_path / "run.mcap"
    write_run(path, run, chunk_size=4000)
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.warns(LogWarning, match=r"cut\.mcap: file is truncated"):
        back = read_run(cut)
    n = back.log.n_samples
    assert 50 < n < 400
    np.testing.assert_array_equal(back.log.q, run.log.q[:n])
    np.testing.assert_array_equal(back.log.tau_cmd, run.log.tau_cmd[:n])
    cut.write_bytes(data[:200])  # inside the first chunk
    with pytest.raises(LogFormatError, match=r"cut\.mcap: truncated MCAP file with no readable"):
        read_run(cut)


def test_corrupt_chunk(tmp_path, run):
    path = tmp_path / "run.mcap"
    write_run(path, run)
    with path.open("rb") as handle:
        chunk = make_reader(handle).get_summary().chunk_indexes[0]
    data = bytearray(path.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle:middle + 40] = b"\xff" * 40  # inside the compressed chunk data
    path.write_bytes(bytes(data))
    with pytest.raises(LogFormatError, match=r"run\.mcap: corrupt chunk"):
        read_run(path)
    data = bytearray(path.read_bytes())
    data[30:34] = b"\xff\xff\xff\x7f"  # the header record's length
    path.write_bytes(bytes(data))
    with pytest.raises(LogFormatError, match=r"run\.mcap: (corrupt|truncated)"):
        read_run(path)


def test_missing_topics(tmp_path, run):
    path = tmp_path / "run.mcap"
    write_run(path, run)
    with pytest.raises(LogFormatError, match=r"run\.mcap: no JointState topic '/arm/joints'; "
                                             r"JointState topics: \['/joint_states'"):
        read_run(path, joint_topic="/arm/joints")
    with pytest.raises(LogFormatError, match=r"run\.mcap: no command topic '/effort_cmd'"):
        read_run(path, command_topic="/effort_cmd")
    only_strings = tmp_path / "strings.mcap"
    with only_strings.open("wb") as handle:
        writer = Ros2Writer(handle)
        schema = writer.register_msgdef("std_msgs/msg/String", ROS2_DEFINITIONS[
            "std_msgs/msg/String"])
        writer.write_message("/chatter", schema, {"data": "hi"}, log_time=1)
        writer.finish()
    with pytest.raises(LogFormatError, match=r"strings\.mcap: no JointState topic \(expected "
                                             r"/joint_states\); topics: \['/chatter'\]"):
        read_joint_log(only_strings)


@pytest.mark.skipif(not REAL_50.exists(), reason="real logs not available")
def test_several_joint_topics_need_a_choice_and_real_logs_have_no_urdf():
    with pytest.raises(LogFormatError, match=r"prismax_airbot_50\.mcap: no /joint_states and "
                                             r"several JointState topics .*--joint-topic"):
        read_joint_log(REAL_50)
    with pytest.raises(LogFormatError, match=r"prismax_airbot_50\.mcap: no URDF on "
                                             r"/robot_description and no robot given"):
        read_run(REAL_50, joint_topic="/robot/arm_left_follow/joint_states")


def test_commands_required(tmp_path, robot):
    path = tmp_path / "run.mcap"
    write_run(path, Run(robot=robot, log=make_log(commands=False)))
    assert read_run(path).log.tau_cmd is None
    with pytest.raises(LogFormatError, match=r"run\.mcap: no commanded torques"):
        read_run(path, require_commands=True)


def test_no_urdf_and_no_robot(tmp_path, robot):
    path = tmp_path / "bare.mcap"
    write_states(path, [1, 2, 3], np.zeros((3, 3)))
    with pytest.raises(LogFormatError, match=r"bare\.mcap: no URDF on /robot_description and no "
                                             r"robot given"):
        read_run(path)
    assert read_run(path, robot=robot).log.n_samples == 3
    urdf = tmp_path / "robot.urdf"
    urdf.write_text(robot_to_urdf(robot))
    assert read_run(path, robot=urdf).robot.joint_names == NAMES


def test_joint_names_matched_by_name(tmp_path, robot):
    path = tmp_path / "run.mcap"
    write_states(path, [1, 2, 3], np.arange(9.0).reshape(3, 3), names=("joint_3", "joint_1",
                                                                      "joint_2"))
    back = read_run(path, robot=robot)
    np.testing.assert_array_equal(back.log.q[0], [1.0, 2.0, 0.0])
    other = RobotModel.from_spec({"joints": [{"name": n, "radius": 0.01} for n in
                                             ("joint_1", "elbow", "wrist")],
                                  "tip": {"offset": [0.1, 0, 0]}})
    with pytest.raises(LogFormatError, match=r"run\.mcap: topic '/joint_states' lacks joints "
                                             r"\['elbow', 'wrist'\]"):
        read_run(path, robot=other)
    two = RobotModel.from_spec({"joints": [{"name": n, "radius": 0.01, "origin": [0.2, 0, 0]}
                                           for n in ("joint_1", "joint_2")],
                                "tip": {"offset": [0.1, 0, 0]}})
    with pytest.warns(LogWarning, match=r"ignoring joints not in the robot: \['joint_3'\]"):
        assert read_run(path, robot=two).log.q.shape == (3, 2)


def test_nan_positions(tmp_path, robot):
    q = make_log().q.copy()
    q[5, 1] = np.nan
    log = make_log()
    bad = JointLog(log.joint_names, log.t, q, log.qd, t0_ns=log.t0_ns)
    path = tmp_path / "nan.mcap"
    write_run(path, Run(robot=robot, log=bad))
    with pytest.raises(LogFormatError, match=r"nan\.mcap: topic '/joint_states': 1 NaN "
                                             r"positions \(first: joint 'joint_2' at "
                                             r"t = 0\.050000 s\)"):
        read_run(path)
    q[5, 1] = np.inf
    path = tmp_path / "inf.mcap"
    write_run(path, Run(robot=robot, log=JointLog(log.joint_names, log.t, q, log.qd,
                                                  t0_ns=log.t0_ns)))
    with pytest.raises(LogFormatError, match=r"inf\.mcap: topic '/joint_states': 1 infinite "
                                             r"positions \(first: joint 'joint_2'"):
        read_run(path)


def test_out_of_order_stamps_are_sorted_and_repeats_dropped(tmp_path):
    stamps = np.array([100, 300, 200, 400, 400, 500, 500]) * 10**6
    q = np.arange(21.0).reshape(7, 3)
    path = tmp_path / "jitter.mcap"
    write_states(path, stamps, q, log_times=np.arange(7))
    with pytest.warns(LogWarning) as record:
        log = read_joint_log(path)
    messages = " | ".join(str(w.message) for w in record)
    assert "2 messages out of time order; sorted by stamp" in messages
    assert "dropped 2 messages repeating an earlier stamp (kept the first)" in messages
    np.testing.assert_allclose(log.t, [0.0, 0.1, 0.2, 0.3, 0.4])
    np.testing.assert_array_equal(log.q[:, 0], [0.0, 6.0, 3.0, 9.0, 15.0])
    assert log.t0_ns == 100 * 10**6


def test_zero_stamps_fall_back_to_log_time(tmp_path):
    path = tmp_path / "nostamp.mcap"
    write_states(path, [0, 0, 0], np.zeros((3, 3)), log_times=[10**9, 2 * 10**9, 3 * 10**9])
    with pytest.warns(LogWarning, match="zero header stamps; using MCAP log times"):
        log = read_joint_log(path)
    np.testing.assert_allclose(log.t, [0.0, 1.0, 2.0])


def test_velocity_differentiated_when_missing(tmp_path):
    path = tmp_path / "pos.mcap"
    t = np.array([0.0, 0.1, 0.25, 0.3, 0.5])
    q = np.stack([t**2, 3 * t, np.zeros_like(t)], axis=1)
    write_states(path, (t * 1e9).round().astype(np.int64), q)
    log = read_joint_log(path)
    np.testing.assert_allclose(log.qd[:, 1], 3.0)
    np.testing.assert_allclose(log.qd[1:-1, 0], 2 * t[1:-1], rtol=0.2)  # non-uniform central
    np.testing.assert_allclose(log.qd, np.gradient(q, t, axis=0))


def test_float64_multiarray_commands_held_onto_states(tmp_path, robot):
    stamps = np.arange(1, 7) * 10**8
    extra = [("/joint_commands", FLOAT64_MULTI_ARRAY,
              {"layout": {"dim": [], "data_offset": 0}, "data": [k, -k, 2.0 * k]}, int(t))
             for k, t in ((1.0, 2.5e8), (2.0, 4e8))]
    path = tmp_path / "cmd.mcap"
    write_states(path, stamps, np.zeros((6, 3)), extra=extra)
    log = read_run(path, robot=robot, require_commands=True).log
    np.testing.assert_array_equal(log.tau_cmd[:, 0], [0.0, 0.0, 1.0, 2.0, 2.0, 2.0])
    np.testing.assert_array_equal(log.tau_cmd[3], [2.0, -2.0, 4.0])
    assert log.q_cmd is None
    wrong = [("/joint_commands", FLOAT64_MULTI_ARRAY,
              {"layout": {"dim": [], "data_offset": 0}, "data": [1.0, 2.0]}, 1)]
    write_states(path, stamps, np.zeros((6, 3)), extra=wrong)
    with pytest.raises(LogFormatError, match=r"cmd\.mcap: command topic '/joint_commands' "
                                             r"carries 2 values per message, expected 3"):
        read_run(path, robot=robot)


def test_joint_state_commands_on_another_topic_zero_order_hold(tmp_path, robot):
    stamps = np.arange(1, 6) * 10**8
    path = tmp_path / "cmd.mcap"
    with open(path, "wb") as handle:
        writer = McapWriter(handle)
        writer.start("ros2", "test")
        schema = writer.register_schema(JOINT_STATE, "ros2msg",
                                        ROS2_DEFINITIONS[JOINT_STATE].encode())
        state = writer.register_channel("/joint_states", "cdr", schema)
        cmd = writer.register_channel("/arm/effort", "cdr", schema)
        from wholearm_tools.logs import cdr

        rows = cdr.encode_joint_states(stamps, NAMES, np.ones((5, 3)))
        cmd_rows = cdr.encode_joint_states(np.array([2, 4]) * 10**8, NAMES[::-1],
                                           np.full((2, 3), 9.0), None,
                                           np.array([[3.0, 2.0, 1.0], [6.0, 5.0, 4.0]]))
        for i, s in enumerate(stamps.tolist()):
            writer.add_message(state, s, rows[i].tobytes(), s)
        for i, s in enumerate([2 * 10**8, 4 * 10**8]):
            writer.add_message(cmd, s, cmd_rows[i].tobytes(), s)
        writer.finish()
    log = read_run(path, robot=robot, command_topic="/arm/effort").log
    np.testing.assert_array_equal(log.tau_cmd, [[0, 0, 0], [1, 2, 3], [1, 2, 3], [4, 5, 6],
                                                [4, 5, 6]])
    np.testing.assert_array_equal(log.q_cmd[0], [1.0, 1.0, 1.0])  # measured before 1st command
    np.testing.assert_array_equal(log.q_cmd[1:], 9.0)
    assert read_run(path, robot=robot).log.tau_cmd is None  # not on the default topic


def test_robot_description_must_be_a_valid_urdf(tmp_path):
    from wholearm_tools.errors import RobotModelError

    path = tmp_path / "badurdf.mcap"
    with open(path, "wb") as handle:
        writer = Ros2Writer(handle)
        s = writer.register_msgdef("std_msgs/msg/String", ROS2_DEFINITIONS["std_msgs/msg/String"])
        j = writer.register_msgdef(JOINT_STATE, ROS2_DEFINITIONS[JOINT_STATE])
        writer.write_message("/robot_description", s, {"data": "<robot name='x'/>"}, log_time=0)
        writer.write_message("/joint_states", j, {"header": {}, "name": ["a"],
                                                  "position": [0.0]}, log_time=1)
        writer.finish()
    with pytest.raises(RobotModelError, match=r"badurdf\.mcap /robot_description"):
        read_run(path)


def test_lz4_and_uncompressed_chunks_read_back(tmp_path, run):
    for compression in ("lz4", "none"):
        path = tmp_path / f"{compression}.mcap"
        write_run(path, run, compression=compression, chunk_size=2000)
        back = read_run(path)
        np.testing.assert_array_equal(back.log.q, run.log.q)


def test_a_chunk_whose_declared_size_is_wrong_is_corrupt(tmp_path, run):
    path = tmp_path / "run.mcap"
    write_run(path, run)
    with path.open("rb") as handle:
        start = make_reader(handle).get_summary().chunk_indexes[0].chunk_start_offset
    data = bytearray(path.read_bytes())
    size = int.from_bytes(data[start + 25:start + 33], "little")
    data[start + 25:start + 33] = (size + 16).to_bytes(8, "little")  # plausible, but wrong
    path.write_bytes(bytes(data))
    with pytest.raises(LogFormatError, match=r"run\.mcap: corrupt chunk"):
        read_run(path)
    data[start + 25:start + 33] = (2**40).to_bytes(8, "little")
    path.write_bytes(bytes(data))
    with pytest.raises(LogFormatError, match=r"run\.mcap: corrupt chunk \(\d+ compressed bytes "
                                             r"declare 1099511627776 bytes"):
        read_run(path)


def test_efforts_missing_from_some_messages_are_told_from_nan_efforts(tmp_path, robot):
    stamps = np.arange(1, 7) * 10**8

    def command(i: int, effort: list[float]) -> tuple:
        return ("/joint_commands", JOINT_STATE,
                {"header": {"stamp": {"sec": 0, "nanosec": int(stamps[i])}, "frame_id": ""},
                 "name": list(NAMES), "position": [], "velocity": [], "effort": effort},
                int(stamps[i]))

    path = tmp_path / "partial.mcap"
    write_states(path, stamps, np.zeros((6, 3)),
                 extra=[command(0, [1.0, 2.0, 3.0]), command(2, [])])
    with pytest.raises(LogFormatError, match=r"partial\.mcap: command topic '/joint_commands' "
                                             r"has efforts in some messages or joints only "
                                             r"\(3 of 6 missing\)"):
        read_run(path, robot=robot)
    write_states(path, stamps, np.zeros((6, 3)),
                 extra=[command(0, [1.0, np.nan, 3.0]), command(2, [1.0, 2.0, 3.0])])
    with pytest.raises(LogFormatError, match=r"partial\.mcap: command topic '/joint_commands': "
                                             r"1 NaN commanded torques \(effort; first: joint "
                                             r"'joint_2' at t = 0\.000000 s\)"):
        read_run(path, robot=robot)


def test_velocities_never_logged_are_differentiated_without_a_warning(tmp_path):
    import warnings

    path = tmp_path / "pos.mcap"
    write_states(path, np.arange(1, 6) * 10**8, np.zeros((5, 3)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_joint_log(path)


def test_a_log_or_urdf_that_is_not_a_regular_file_is_refused_unopened(tmp_path, run):
    import os

    fifo = tmp_path / "run.mcap"
    os.mkfifo(fifo)
    with pytest.raises(LogFormatError, match=r"run\.mcap: not a regular file"):
        read_run(fifo)  # opening a FIFO would block
    from wholearm_tools.errors import RobotModelError

    path = tmp_path / "ok.mcap"
    write_run(path, run)
    urdf = tmp_path / "robot.urdf"
    os.mkfifo(urdf)
    with pytest.raises(RobotModelError, match=r"robot\.urdf: not a regular file"):
        read_run(path, robot=urdf)


def test_other_formats_are_named_but_their_bytes_never_shown(tmp_path):
    pdf = tmp_path / "run.mcap"
    pdf.write_bytes(b"%PDF-1.4\n" + b"secret" * 10)
    with pytest.raises(LogFormatError, match=r"run\.mcap: not an MCAP file \(it looks like a "
                                             r"PDF\)") as info:
        read_run(pdf)
    assert "secret" not in str(info.value)
