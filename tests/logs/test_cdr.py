"""The vectorised JointState CDR path against mcap_ros2's own encoder and decoder."""

from __future__ import annotations

import io

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer

from wholearm_tools.logs import LogWarning, cdr, read_joint_log
from wholearm_tools.logs.scan import scan_mcap
from wholearm_tools.logs.schemas import JOINT_STATE, ROS2_DEFINITIONS, STRING

from .conftest import REAL_50, REAL_100, REAL_TOPICS

needs_real = pytest.mark.skipif(not REAL_50.exists(), reason="real logs not available")


def stock_payloads(messages: list[dict], schema_name: str = JOINT_STATE) -> list[bytes]:
    """Encode with mcap_ros2's writer and return the raw CDR payloads."""
    buffer = io.BytesIO()
    writer = Ros2Writer(buffer)
    schema = writer.register_msgdef(schema_name, ROS2_DEFINITIONS[schema_name])
    for i, msg in enumerate(messages):
        writer.write_message("/t", schema, msg, log_time=i, publish_time=i)
    writer.finish()
    buffer.seek(0)
    return [m.data for _, _, m in make_reader(buffer).iter_messages()]


def joint_state(stamp_ns, names, position, velocity, effort, frame_id=""):
    sec, nanosec = divmod(int(stamp_ns), 10**9)
    return {"header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id},
            "name": list(names), "position": list(position), "velocity": list(velocity),
            "effort": list(effort)}


@pytest.mark.parametrize(("names", "nv", "ne", "frame_id"), [
    (("joint_1", "joint_2", "joint_3"), 3, 0, ""),
    (("a", "bb", "ccc", "dddd", "eeeee", "f", "g"), 0, 7, "base_link"),
    (("shoulder_pan",), 1, 1, "xy"),
    (("j",), 0, 0, ""),
])
def test_encoder_bytes_equal_mcap_ros2(names, nv, ne, frame_id):
    rng = np.random.default_rng(1)
    n, k = 9, len(names)
    stamps = np.array([0, 1, 999_999_999, 10**9, 1_769_679_631_698_035_216, 5, 6, 7, 2**40])
    q = rng.normal(size=(n, k))
    qd = rng.normal(size=(n, nv)) if nv else None
    tau = rng.normal(size=(n, ne)) if ne else None
    rows = cdr.encode_joint_states(stamps, names, q, qd, tau, frame_id=frame_id)
    expected = stock_payloads([joint_state(stamps[i], names, q[i],
                                           qd[i] if nv else [], tau[i] if ne else [], frame_id)
                               for i in range(n)])
    assert [bytes(r) for r in rows] == expected


def test_string_payload_equals_mcap_ros2(tmp_path, run):
    from wholearm_tools.logs import write_run
    from wholearm_tools.robot import robot_to_urdf

    path = tmp_path / "run.mcap"
    write_run(path, run)
    with path.open("rb") as handle:
        ours = next(m.data for _, _, m in make_reader(handle).iter_messages(
            topics=["/robot_description"]))
    assert [ours] == stock_payloads([{"data": robot_to_urdf(run.robot)}], STRING)


def test_layout_parse_and_decode_ignore_padding_garbage_and_trailing_bytes():
    names = ("a", "bb", "ccc")
    rows = cdr.encode_joint_states(np.array([5, 10**9 + 7]), names, np.ones((2, 3)),
                                   np.full((2, 3), 2.0), None, frame_id="f")
    layout = cdr.joint_state_layout(rows[0].tobytes())
    assert layout.names == names
    assert layout.counts == (3, 3, 0)
    assert layout.frame_id == "f"
    padding = np.setdiff1d(np.arange(layout.size), layout.structure)
    dirty = np.concatenate([rows, np.full((2, 8), 0xAB, np.uint8)], axis=1)
    dirty[:, padding[(padding >= 12) & (padding < layout.offsets[0])]] = 0xEE
    assert cdr.matches_layout(dirty, layout).all()
    batch = cdr.decode_joint_states(dirty, layout)
    np.testing.assert_array_equal(batch.stamp_ns, [5, 10**9 + 7])
    np.testing.assert_array_equal(batch.position, np.ones((2, 3)))
    np.testing.assert_array_equal(batch.velocity, np.full((2, 3), 2.0))
    assert batch.effort.shape == (2, 0)
    other = cdr.encode_joint_states(np.array([1]), ("a", "bx", "ccc"), np.ones((1, 3)),
                                    np.ones((1, 3)), None, frame_id="f")
    assert not cdr.matches_layout(other, layout).any()
    with pytest.raises(ValueError, match="cut short"):
        cdr.joint_state_layout(rows[0].tobytes()[:40])
    with pytest.raises(ValueError, match="not little-endian CDR"):
        cdr.joint_state_layout(b"\x00\x00\x00\x00" + rows[0].tobytes()[4:])


def stock_columns(path, topic):
    """Every message of ``topic`` decoded by the stock decoder, as NaN-padded columns."""
    stamps, cols = [], {"position": [], "velocity": [], "effort": []}
    names = None
    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        for _, _, _, msg in reader.iter_decoded_messages(topics=[topic], log_time_order=False):
            stamps.append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
            names = names or tuple(msg.name)
            assert tuple(msg.name) == names
            for field, values in cols.items():
                value = getattr(msg, field)
                values.append(list(value) if len(value) else [np.nan] * len(names))
    return names, np.array(stamps), {k: np.array(v) for k, v in cols.items()}


@needs_real
@pytest.mark.parametrize("path", [REAL_50, REAL_100], ids=["50", "100"])
def test_fast_path_equals_stock_decoder_on_real_logs(path):
    scan = scan_mcap(path)
    assert not scan.truncated
    for topic in REAL_TOPICS:
        ours = scan.decoded[topic]
        names, stamps, cols = stock_columns(path, topic)
        assert ours.fast_messages == ours.n_messages == stamps.shape[0] > 1000
        assert ours.names == names
        order = np.argsort(ours.log_time_ns, kind="stable")  # stock reads in log-time order
        np.testing.assert_array_equal(ours.stamp_ns[order], stamps)
        for field, expected in cols.items():
            np.testing.assert_array_equal(getattr(ours, field)[order], expected, err_msg=field)


@needs_real
def test_read_joint_log_on_real_topics_matches_stock():
    for topic in REAL_TOPICS:
        log = read_joint_log(REAL_50, joint_topic=topic)
        names, stamps, cols = stock_columns(REAL_50, topic)
        order = np.argsort(stamps, kind="stable")
        assert log.joint_names == names
        assert log.t0_ns == stamps[order][0]
        np.testing.assert_array_equal(log.q, cols["position"][order])
        np.testing.assert_allclose(log.t, (stamps[order] - stamps[order][0]) * 1e-9)
        if "follow" in topic:
            np.testing.assert_array_equal(log.qd, cols["velocity"][order])
        else:  # leader arms log no velocity: differentiated positions
            np.testing.assert_allclose(log.qd, np.gradient(log.q, log.t, axis=0))
        assert log.tau_cmd is None


def test_mixed_layouts_fall_back_and_match_stock(tmp_path):
    """Different names, lengths, frame ids, trailing bytes and a big-endian message."""
    msgs = []
    for i in range(40):
        names = ("a", "b", "c") if i % 3 else ("a", "b", "c", "extra")
        k = len(names)
        msgs.append(joint_state(1000 + i, names, np.arange(k) + i,
                                np.arange(k) * 0.5 if i % 2 else [], [],
                                frame_id="base" if i % 5 else "x"))
    payloads = stock_payloads(msgs)
    payloads[7] = payloads[7] + b"\x00" * 8  # trailing padding quirk
    path = tmp_path / "mixed.mcap"
    with path.open("wb") as handle:
        writer = McapWriter(handle, chunk_size=700)
        writer.start("ros2", "test")
        schema = writer.register_schema(JOINT_STATE, "ros2msg",
                                        ROS2_DEFINITIONS[JOINT_STATE].encode())
        channel = writer.register_channel("/joint_states", "cdr", schema)
        for i, data in enumerate(payloads):
            writer.add_message(channel, 1000 + i, data, 1000 + i)
        writer.finish()
    cols = scan_mcap(path).decoded["/joint_states"]
    assert cols.names == ("a", "b", "c", "extra")
    assert cols.n_messages == 40
    for i, msg in enumerate(msgs):
        k = len(msg["name"])
        np.testing.assert_array_equal(cols.position[i, :k], msg["position"])
        assert np.isnan(cols.position[i, k:]).all()
        if msg["velocity"]:
            np.testing.assert_array_equal(cols.velocity[i, :k], msg["velocity"])
        else:
            assert np.isnan(cols.velocity[i]).all()
    assert cols.fast_messages == 40
    with pytest.warns(LogWarning, match=r"ignoring joints not in the robot: \['b', 'extra'\]"):
        log = read_joint_log(path, joint_names=("c", "a"))
    np.testing.assert_array_equal(log.q[:, 1], np.arange(40))
    np.testing.assert_array_equal(log.q[:, 0], np.arange(40) + 2)


def test_big_endian_message_goes_through_the_stock_decoder(tmp_path):
    import struct

    little = cdr.encode_joint_states(np.array([10, 20]), ("a", "b", "c"),
                                     np.arange(6.0).reshape(2, 3))
    big = bytearray(b"\x00\x00\x00\x00" + struct.pack(">iI", 0, 15) + struct.pack(">I", 1)
                    + b"\x00\x00\x00\x00" + struct.pack(">I", 3))
    for name in (b"a", b"b", b"c"):
        big += struct.pack(">I", 2) + name + b"\x00\x00\x00"
    big += struct.pack(">I", 3) + struct.pack(">3d", 7.0, 8.0, 9.0) + struct.pack(">II", 0, 0)
    path = tmp_path / "be.mcap"
    with path.open("wb") as handle:
        writer = McapWriter(handle)
        writer.start("ros2", "test")
        schema = writer.register_schema(JOINT_STATE, "ros2msg",
                                        ROS2_DEFINITIONS[JOINT_STATE].encode())
        channel = writer.register_channel("/joint_states", "cdr", schema)
        for i, data in enumerate([little[0].tobytes(), bytes(big), little[1].tobytes()]):
            writer.add_message(channel, i, data, i)
        writer.finish()
    cols = scan_mcap(path).decoded["/joint_states"]
    assert cols.fast_messages == 2
    np.testing.assert_array_equal(cols.stamp_ns, [10, 15, 20])
    np.testing.assert_array_equal(cols.position, [[0, 1, 2], [7, 8, 9], [3, 4, 5]])


def test_decoded_columns_do_not_keep_the_payload_buffer_alive():
    """Every decoded column owns its memory: a view of the payloads (an empty effort field is
    one, as an empty slice counts as contiguous) would keep each decompressed chunk alive
    until the whole log is read (peak memory 5x the decoded arrays on a 1M-message log)."""
    names = ("joint_1", "joint_2", "joint_3")
    q = np.arange(12.0).reshape(4, 3)
    rows = cdr.encode_joint_states(np.arange(4), names, q, q + 1.0, None)
    batch = cdr.decode_joint_states(rows, cdr.joint_state_layout(rows[0].tobytes()))
    assert batch.effort.shape == (4, 0)
    np.testing.assert_array_equal(batch.position, q)
    for column in (batch.stamp_ns, batch.position, batch.velocity, batch.effort):
        chain = []
        while column is not None:
            chain.append(column)
            column = column.base
        assert not any(a is rows or a is rows.base for a in chain)


def _wide_log(tmp_path, n=5000):
    """A multi-chunk ROS 2 log of ``n`` JointState messages (positions and velocities)."""
    from wholearm_tools.logs import JointLog, Run, write_run
    from wholearm_tools.robot import RobotModel

    spec = {"joints": [{"name": f"joint_{i + 1}", "origin": [0.2 * (i > 0), 0, 0],
                        "radius": 0.03} for i in range(3)], "tip": {"offset": [0.1, 0, 0]}}
    robot = RobotModel.from_spec(spec, name="three")
    t = np.arange(n) * 2e-3
    q = np.sin(t[:, None] + np.arange(3))
    log = JointLog(robot.joint_names, t, q, np.cos(t[:, None] + np.arange(3)))
    path = tmp_path / "wide.mcap"
    write_run(path, Run(robot=robot, log=log), chunk_size=16 * 1024)
    return path, log


@pytest.mark.parametrize("hint", ["none", "exact", "too_few", "too_many"])
def test_summary_message_count_is_only_a_sizing_hint(tmp_path, monkeypatch, hint):
    """With the summary's count the columns are filled in place (no blocks kept); a missing,
    short or long count gives exactly the same columns."""
    import wholearm_tools.logs.scan as scan_module

    path, log = _wide_log(tmp_path)
    reference = scan_mcap(path).decoded["/joint_states"]
    real = scan_module._summary_counts
    change = {"none": None, "exact": 0, "too_few": -700, "too_many": 700}[hint]
    monkeypatch.setattr(scan_module, "_summary_counts", lambda handle: {} if change is None else
                        {cid: count + change for cid, count in real(handle).items()})
    cols = scan_mcap(path).decoded["/joint_states"]
    assert cols.names == reference.names == log.joint_names
    assert cols.n_messages == 5000
    for field in ("stamp_ns", "log_time_ns", "position", "velocity"):
        np.testing.assert_array_equal(getattr(cols, field), getattr(reference, field))
    np.testing.assert_array_equal(cols.position, log.q)
    assert cols.effort.shape == (5000, 3)
    assert np.isnan(cols.effort).all()


def test_summary_counts_are_absent_for_a_file_cut_short(tmp_path):
    from wholearm_tools.logs.scan import _summary_counts

    path, _ = _wide_log(tmp_path)
    with path.open("rb") as handle:
        counts = _summary_counts(handle)
    assert 5000 in counts.values()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with cut.open("rb") as handle:
        assert _summary_counts(handle) == {}


def test_joint_log_adopts_frozen_columns_and_copies_writable_ones():
    """The reader hands its read-only columns over (the log is held once); a caller's writable
    array is copied, never frozen under the caller's feet."""
    from wholearm_tools.logs import JointLog

    t = np.arange(4.0)
    q = np.zeros((4, 2))
    frozen = np.ones((4, 2))
    frozen.setflags(write=False)
    log = JointLog(("a", "b"), t, q, frozen)
    assert log.qd is frozen
    assert log.q is not q
    assert not np.shares_memory(log.q, q)
    assert q.flags.writeable
    assert not log.q.flags.writeable
    q[0, 0] = 5.0
    assert log.q[0, 0] == 0.0
    big = np.ones((8, 2))
    big.setflags(write=False)
    view = big[::2]  # read-only, but a view: whoever owns the base could still change it
    assert not np.shares_memory(JointLog(("a", "b"), t, q, view).qd, big)
