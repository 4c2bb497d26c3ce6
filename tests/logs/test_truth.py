"""Ground truth: event fields round-trip, older files still read, stock ROS 2 readers read it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from wholearm_tools.errors import InputError, LogFormatError
from wholearm_tools.logs import read_run, write_run
from wholearm_tools.logs.reader import ground_truth_from_json
from wholearm_tools.logs.records import GroundTruth, Run
from wholearm_tools.logs.writer import ground_truth_to_json

from .conftest import make_log, make_truth


def event_truth() -> GroundTruth:
    base = make_truth()
    return GroundTruth(
        surfaces=base.surfaces, contact_t=base.contact_t, contact_link=base.contact_link,
        contact_kind=base.contact_kind, contact_point=base.contact_point,
        contact_surface=base.contact_surface, contact_s=base.contact_s, meta=base.meta,
        contact_t_end=[0.09, np.nan, 0.19], contact_force=[12.5, 3.0, np.nan],
        contact_q=[[0.1, 0.2, 0.3], [0.4, np.nan, 0.6], [0.7, 0.8, 0.9]],
        contact_stopped=[True, False, True],
        contact_point_first=[[1.0, 0.1, 0.0], [1.0, -0.25, 0.0], [1.0, 0.3, 0.0]])


@pytest.mark.parametrize("profile", ["ros2", "json"])
def test_event_fields_round_trip(tmp_path: Path, robot, profile: str) -> None:
    truth = event_truth()
    path = tmp_path / "run.mcap"
    write_run(path, Run(robot=robot, log=make_log(), truth=truth), profile=profile)
    back = read_run(path).truth
    assert back is not None
    for name in ("contact_t", "contact_t_end", "contact_force", "contact_q", "contact_point",
                 "contact_point_first", "contact_s"):
        np.testing.assert_array_equal(getattr(back, name), getattr(truth, name))
    assert back.contact_stopped.tolist() == [True, False, True]
    np.testing.assert_allclose(back.contact_duration, [0.04, np.nan, 0.02])


def test_older_truth_without_event_fields_reads_with_defaults() -> None:
    body = ground_truth_to_json(make_truth())
    for key in ("t_end", "force", "q", "stopped", "point_first"):
        del body["contacts"][key]
    truth = ground_truth_from_json(json.dumps(body))
    assert np.isnan(truth.contact_t_end).all()
    assert np.isnan(truth.contact_force).all()
    assert truth.contact_q.shape == (3, 0)
    assert truth.contact_stopped.all()
    np.testing.assert_array_equal(truth.contact_point_first, truth.contact_point)


def test_older_json_truth_channel_still_reads(tmp_path: Path, robot) -> None:
    """Files from before the String channel hold a jsonschema GroundTruth channel."""
    from mcap.well_known import MessageEncoding, SchemaEncoding
    from mcap.writer import Writer

    from wholearm_tools.logs import cdr
    from wholearm_tools.logs.schemas import GROUND_TRUTH, ROS2_DEFINITIONS, json_schema_bytes

    log = make_log()
    path = tmp_path / "old.mcap"
    body = ground_truth_to_json(make_truth())
    for key in ("t_end", "force", "q", "stopped", "point_first"):
        del body["contacts"][key]
    with path.open("wb") as handle:
        w = Writer(handle)
        w.start(profile="ros2", library="old")
        js = w.register_schema("sensor_msgs/msg/JointState", SchemaEncoding.ROS2,
                               ROS2_DEFINITIONS["sensor_msgs/msg/JointState"].encode())
        ch = w.register_channel("/joint_states", MessageEncoding.CDR, js)
        gs = w.register_schema(GROUND_TRUTH, SchemaEncoding.JSONSchema,
                               json_schema_bytes(GROUND_TRUTH))
        gc = w.register_channel("/wholearm/ground_truth", MessageEncoding.JSON, gs)
        w.add_message(gc, 1, json.dumps(body).encode(), 1)
        stamps = log.t0_ns + np.round(log.t * 1e9).astype(np.int64)
        payloads = cdr.encode_joint_states(stamps, log.joint_names, log.q, log.qd, None)
        for stamp, payload in zip(stamps.tolist(), payloads, strict=True):
            w.add_message(ch, stamp, bytes(payload), stamp)
        w.finish()
    truth = read_run(path, robot=robot).truth
    assert truth is not None
    assert truth.contact_link.tolist() == [2, 1, 2]
    assert truth.contact_stopped.all()


def test_malformed_truth_string_names_the_problem() -> None:
    with pytest.raises(LogFormatError, match=r"run\.mcap /wholearm/ground_truth: malformed"):
        ground_truth_from_json("{not json", "run.mcap /wholearm/ground_truth")


def test_event_field_shape_is_checked() -> None:
    base = make_truth()
    with pytest.raises(InputError, match=r"contact_force of shape \(3,\)"):
        GroundTruth(surfaces=base.surfaces, contact_t=base.contact_t,
                    contact_link=base.contact_link, contact_kind=base.contact_kind,
                    contact_point=base.contact_point, contact_surface=base.contact_surface,
                    contact_s=base.contact_s, contact_force=[1.0, 2.0])


def test_event_fields_read_back_from_plain_lists() -> None:
    """JSON readers hand lists back, with null for NaN; no contacts at all is a valid run."""
    empty = GroundTruth(surfaces=(), contact_t=[], contact_link=[], contact_kind=[],
                        contact_point=[], contact_surface=[], contact_s=[], contact_t_end=[],
                        contact_force=[], contact_q=[], contact_stopped=[],
                        contact_point_first=[])
    assert empty.contact_q.shape == (0, 0)
    assert empty.contact_point_first.shape == (0, 3)
    one = GroundTruth(surfaces=(), contact_t=[0.1], contact_link=[0], contact_kind=["tip"],
                      contact_point=[[0, 0, 0]], contact_surface=[0], contact_s=[1.0],
                      contact_t_end=[None], contact_force=[None], contact_q=[[0.1, None]])
    assert np.isnan(one.contact_t_end[0])
    assert np.isnan(one.contact_q[0, 1])
