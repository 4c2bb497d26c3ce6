"""Link identification and tip/link labels on a short simulated planar run (3 links, 2 walls,
a post).  Thresholds are what a user relies on, looser than the benchmark's targets because
the run is short (about a dozen contacts)."""

from __future__ import annotations

import numpy as np
import pytest

from wholearm_tools.classify import swept_map, tip_probability
from wholearm_tools.contacts import detect_contacts, match_events
from wholearm_tools.geometry.bounded import Arc2D, Segment2D
from wholearm_tools.robot import RobotModel
from wholearm_tools.sim.simulator import simulate


@pytest.fixture(scope="module")
def run():
    robot = RobotModel.from_spec({"joints": [
        {"origin": [0, 0, 0], "radius": 0.02, "limits": [-3, 3]},
        {"origin": [0.5, 0, 0], "radius": 0.015, "limits": [-2.5, 2.5]},
        {"origin": [0.35, 0, 0], "radius": 0.01, "limits": [-2.5, 2.5]}],
        "tip": {"offset": [0.2, 0, 0], "radius": 0.012}}, name="three_link")
    obstacles = [Segment2D([0.0, 0.7], [1, 0], (-1.5, 1.5), free_side=-1, surface_id=0),
                 Segment2D([0.95, 0.0], [0, 1], (-1.5, 1.5), free_side=1, surface_id=1),
                 Arc2D([0.3, -0.45], 0.08, free_side=1, surface_id=2)]
    return simulate(robot, obstacles, duration=60, seed=0, home=[0.2, 0.6, 0.4]).run


LINK_MIN = {"lab_sharp": 0.95, "well_junction": 0.8}
LABELLED_MIN = {"lab_sharp": 0.6, "well_junction": 0.0}


def test_links_are_identified(run):
    c = detect_contacts(run.log, run.robot)
    m = match_events(c, run.truth)
    assert len(c) >= 8
    assert np.all(m >= 0), "every detection is a true contact"
    assert np.mean(c.link == run.truth.contact_link[m]) >= 0.95
    assert len(set(m.tolist())) == run.truth.n_contacts, "no true contact is missed"


def test_labels_agree_with_truth_and_offline_beats_causal(run):
    """Tip and body contacts are labelled right and offline P_T is closer to the truth than
    causal.  Joint-sphere contacts of the inner link (kind ``joint``) are *not* asserted: eq. (2)
    gives them P_T ~ 0.1 on this run (the body ahead of link 0 is never swept, so the map cannot
    rule it out) — the open issue in docs/method.md."""
    B = 0.02
    c = detect_contacts(run.log, run.robot)
    m = match_events(c, run.truth)
    truth_tip = run.truth.is_tip[m]
    kind = np.asarray(run.truth.contact_kind)[m]
    grid = swept_map(run.robot, run.log.q, B=B)
    off = tip_probability(run, c, B, grid=grid)
    cau = tip_probability(run, c, B, grid=grid, causal=True)
    for cl in (off, cau):
        assert np.all((cl.p_tip >= 0) & (cl.p_tip <= 1))
        assert np.all(cl.variance > 0)
    plain = kind != "joint"
    assert plain.sum() >= 6
    labelled = plain & (off.label != "ambiguous")
    assert labelled.sum() >= 0.9 * plain.sum()
    assert np.all((off.label == "tip")[labelled] == truth_tip[labelled])
    err_off = np.mean(np.abs(off.p_tip - truth_tip))
    err_cau = np.mean(np.abs(cau.p_tip - truth_tip))
    assert err_off < err_cau


@pytest.mark.parametrize("name", ["lab_sharp", "well_junction"])
def test_bundled_scenario_short_run(name):
    """A short run of a bundled scenario: every true contact found, links mostly right, labels
    right where given (the benchmark measures the full-length numbers).  On the first 20 s of
    well_junction the map is still too sparse to label anything: every contact is ambiguous,
    which is the honest answer (it still enters the fit, with low weight)."""
    from wholearm_tools.sim.scenarios import load_scenario

    run = load_scenario(name).simulate(seed=0, duration=20).run
    B = 0.02
    c = detect_contacts(run.log, run.robot)
    m = match_events(c, run.truth)
    assert len(c) >= 5
    assert np.all(m >= 0)
    assert np.mean(c.link == run.truth.contact_link[m]) >= LINK_MIN[name]
    off = tip_probability(run, c, B)
    labelled = off.label != "ambiguous"
    truth_tip = run.truth.is_tip[m]
    assert labelled.mean() >= LABELLED_MIN[name]
    if labelled.any():
        assert np.mean((off.label == "tip")[labelled] == truth_tip[labelled]) >= 0.85
