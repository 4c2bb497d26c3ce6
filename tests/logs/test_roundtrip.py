"""write_run → read_run round trips, determinism, and the stock decoder reading our files."""

from __future__ import annotations

import json

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from wholearm_tools.errors import InputError
from wholearm_tools.logs import Run, read_joint_log, read_run, write_run
from wholearm_tools.logs.records import JointLog
from wholearm_tools.robot import robot_from_urdf

from .conftest import make_log


def assert_logs_equal(a: JointLog, b: JointLog) -> None:
    assert a.joint_names == b.joint_names
    assert a.t0_ns == b.t0_ns
    np.testing.assert_array_equal(a.t, b.t)
    for name in ("q", "qd", "tau_cmd", "q_cmd"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            np.testing.assert_array_equal(x, y, err_msg=name)


@pytest.mark.parametrize("profile", ["ros2", "json"])
@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_round_trip(tmp_path, run, profile, compression):
    path = tmp_path / "run.mcap"
    write_run(path, run, profile=profile, compression=compression, chunk_size=512)
    back = read_run(path)
    assert_logs_equal(run.log, back.log)
    assert back.robot.joint_names == run.robot.joint_names
    np.testing.assert_allclose(back.robot.origins, run.robot.origins)
    assert back.truth is not None
    for name in ("contact_t", "contact_link", "contact_point", "contact_surface", "contact_s"):
        np.testing.assert_array_equal(getattr(back.truth, name), getattr(run.truth, name))
    assert back.truth.contact_kind.tolist() == run.truth.contact_kind.tolist()
    assert back.truth.surfaces == run.truth.surfaces
    assert back.truth.meta == run.truth.meta
    assert back.source == str(path)


@pytest.mark.parametrize("profile", ["ros2", "json"])
def test_round_trip_without_commands_or_truth(tmp_path, robot, profile):
    run = Run(robot=robot, log=make_log(commands=False))
    path = tmp_path / "run.mcap"
    write_run(path, run, profile=profile)
    back = read_run(path)
    assert_logs_equal(run.log, back.log)
    assert back.truth is None
    assert read_joint_log(path).tau_cmd is None


@pytest.mark.parametrize("profile", ["ros2", "json"])
def test_output_is_deterministic(tmp_path, run, profile):
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    write_run(a, run, profile=profile, chunk_size=1000)
    write_run(b, run, profile=profile, chunk_size=1000)
    assert a.read_bytes() == b.read_bytes()
    other = Run(robot=run.robot, log=make_log(t0_ns=5), truth=run.truth)
    write_run(b, other, profile=profile, chunk_size=1000)
    assert a.read_bytes() != b.read_bytes()


def test_stock_decoder_decodes_every_message(tmp_path, run):
    path = tmp_path / "run.mcap"
    write_run(path, run, profile="ros2")
    seen: dict[str, int] = {}
    with path.open("rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        for schema, channel, message in reader.iter_messages():
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
            if channel.message_encoding == "json":
                assert schema.encoding == "jsonschema"
                body = json.loads(message.data)
                assert body["contacts"]["kind"] == ["tip", "body", "joint"]
                continue
            assert schema.encoding == "ros2msg"
        handle.seek(0)
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        states, commands = [], []
        for _, channel, message, decoded in reader.iter_decoded_messages(
                topics=["/joint_states", "/joint_commands", "/robot_description"]):
            if channel.topic == "/robot_description":
                assert robot_from_urdf(decoded.data).joint_names == run.robot.joint_names
                continue
            assert list(decoded.name) == list(run.log.joint_names)
            stamp = decoded.header.stamp.sec * 10**9 + decoded.header.stamp.nanosec
            assert stamp == message.log_time
            (states if channel.topic == "/joint_states" else commands).append(decoded)
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert seen == {"/robot_description": 1, "/wholearm/ground_truth": 1,
                    "/joint_states": 20, "/joint_commands": 20}
    np.testing.assert_array_equal([m.position for m in states], run.log.q)
    np.testing.assert_array_equal([m.velocity for m in states], run.log.qd)
    assert all(len(m.effort) == 0 for m in states)
    np.testing.assert_array_equal([m.effort for m in commands], run.log.tau_cmd)
    np.testing.assert_array_equal([m.position for m in commands], run.log.q_cmd)
    assert all(len(m.velocity) == 0 for m in commands)
    assert metadata["wholearm"]["scenario"] == "wall"
    assert metadata["wholearm"]["seed"] == "11"
    assert metadata["wholearm"]["profile"] == "ros2"


def test_json_profile_schemas_and_fields(tmp_path, run):
    path = tmp_path / "run.mcap"
    write_run(path, run, profile="json")
    with path.open("rb") as handle:
        reader = make_reader(handle)
        summary = reader.get_summary()
        encodings = {c.topic: (c.message_encoding, summary.schemas[c.schema_id].encoding,
                               summary.schemas[c.schema_id].name)
                     for c in summary.channels.values()}
        first = next(m for _, c, m in reader.iter_messages(topics=["/joint_states"]))
    assert encodings["/joint_states"] == ("json", "jsonschema", "sensor_msgs/msg/JointState")
    assert encodings["/robot_description"] == ("json", "jsonschema", "std_msgs/msg/String")
    body = json.loads(first.data)
    assert set(body) == {"header", "name", "position", "velocity", "effort"}
    assert body["position"] == run.log.q[0].tolist()
    assert body["header"]["stamp"]["sec"] * 10**9 + body["header"]["stamp"]["nanosec"] == \
        run.log.t0_ns


def test_write_rejects_bad_arguments(tmp_path, run):
    with pytest.raises(InputError, match="unknown profile 'xml'"):
        write_run(tmp_path / "x.mcap", run, profile="xml")
    with pytest.raises(InputError, match="unknown compression 'gzip'"):
        write_run(tmp_path / "x.mcap", run, compression="gzip")
    assert list(tmp_path.iterdir()) == []


def test_times_off_the_nanosecond_grid_read_back_exactly(tmp_path, run):
    """A simulator's float clock (k * dt, sums of steps) is kept to whole nanoseconds, as the
    log records it, so reconstructing a run in memory and from its file see the same times."""
    log = run.log
    t = np.arange(log.n_samples) * 0.002 + np.linspace(0.0, 3e-10, log.n_samples)
    off = JointLog(log.joint_names, t, log.q, log.qd, t0_ns=log.t0_ns)
    assert np.max(np.abs(off.t - t)) <= 0.5e-9
    path = tmp_path / "run.mcap"
    write_run(path, Run(robot=run.robot, log=off))
    np.testing.assert_array_equal(read_run(path).log.t, off.t)
