"""Coverage of the bundled scenarios (ground-truth contacts per surface and their spread)."""

from __future__ import annotations

import numpy as np
import pytest

from wholearm_tools.logs.records import GroundTruth
from wholearm_tools.sim import load_scenario
from wholearm_tools.sim.coverage import kind_counts, surface_coverage


def test_spread_figures_on_a_synthetic_truth() -> None:
    ang = np.radians([0.0, 90.0, 180.0])
    pts = np.stack([np.cos(ang), np.sin(ang), np.zeros(3)], axis=1) * 0.1
    cyl = np.array([[0.1, 0.0, -0.2], [-0.1, 0.0, 0.3], [0.0, 0.1, 0.1]])
    truth = GroundTruth(
        surfaces=({"id": 0, "type": "circle", "params": {"center": [0, 0], "radius": 0.1}},
                  {"id": 1, "type": "cylinder",
                   "params": {"point": [0, 0, 0], "axis": [0, 0, 1], "radius": 0.1}},
                  {"id": 2, "type": "line", "params": {"point": [0, 1], "direction": [1, 0]}}),
        contact_t=np.arange(6.0), contact_link=np.zeros(6, dtype=np.int64),
        contact_kind=np.array(["tip", "body", "joint", "tip", "tip", "body"]),
        contact_point=np.vstack([pts, cyl]), contact_surface=np.array([0, 0, 0, 1, 1, 1]),
        contact_s=np.ones(6))
    circ, cy, line = surface_coverage(truth)
    assert (circ.count, circ.tip, circ.joint, circ.body) == (3, 1, 1, 1)
    assert circ.arc == pytest.approx(180.0)
    assert cy.arc == pytest.approx(180.0)
    assert cy.axial == pytest.approx((-0.2, 0.3))
    assert (cy.above, cy.below) == (2, 1)
    assert line.count == 0
    assert line.spread() == "-"
    assert kind_counts(truth) == {"tip": 3, "joint": 1, "body": 2}


def test_well_junction_default_run_covers_main_bore_and_branch() -> None:
    res = load_scenario("well_junction").simulate()
    main, branch = surface_coverage(res.truth)
    kinds = kind_counts(res.truth)
    assert main.count >= 10
    assert branch.count >= 10
    assert main.arc is not None
    assert main.arc >= 180
    assert branch.arc is not None
    assert branch.arc >= 180
    assert kinds["body"] >= 1
    assert kinds["tip"] >= 10


def _default_run_coverage(name: str) -> tuple[list, dict[str, int]]:
    res = load_scenario(name).simulate()
    return surface_coverage(res.truth), kind_counts(res.truth)


def test_lab_circle_default_run_covers_every_surface() -> None:
    (circle, top, left), kinds = _default_run_coverage("lab_circle")  # 120 s, seed 0
    assert circle.count >= 25
    assert circle.tip >= 8
    assert circle.body >= 15
    assert circle.arc is not None
    assert circle.arc >= 120
    assert top.count >= 10
    assert left.count >= 10
    assert kinds["tip"] >= 30
    assert kinds["body"] >= 20


def test_frontier_unhook_puts_joints_back_outermost_first() -> None:
    from wholearm_tools.sim.collision import Collider
    from wholearm_tools.sim.occupancy import SweptGrid
    from wholearm_tools.sim.strategies import make_strategy

    sc = load_scenario("paper_planar")
    strat = make_strategy("frontier", sc.robot, Collider(sc.robot, sc.obstacles),
                          SweptGrid(sc.robot), rng=0, home_every=1, unhook=True)
    home = sc.home.copy()
    strat.home = home
    q = home + np.array([0.3, -0.4, 0.5])
    first = strat.next_target(q)
    assert first is not None
    np.testing.assert_allclose(first, [q[0], q[1], home[2]])
    second = strat.next_target(first)
    np.testing.assert_allclose(second, [q[0], home[1], home[2]])
    third = strat.next_target(second)
    np.testing.assert_allclose(third, home)


def test_frontier_vary_return_takes_another_posture_where_a_return_was_blocked() -> None:
    """A home return blocked at one place makes the same contact every time it is retried;
    with vary_return the step whose path runs through that place gets another posture for the
    joints it would leave at home, and a path clear of it stays the plain return."""
    from wholearm_tools.sim.collision import Collider
    from wholearm_tools.sim.occupancy import SweptGrid
    from wholearm_tools.sim.strategies import make_strategy

    sc = load_scenario("paper_planar")
    strat = make_strategy("frontier", sc.robot, Collider(sc.robot, sc.obstacles),
                          SweptGrid(sc.robot), rng=0, home_every=1, unhook=True,
                          vary_return=True)
    home = sc.home.copy()
    strat.home = home
    q = home + np.array([0.8, 0.0, 0.0])  # only the base is off home: one return step
    first = strat.next_target(q)
    np.testing.assert_allclose(first, home)
    stop = home + np.array([0.4, 0.0, 0.0])  # blocked half-way
    strat.observe(np.array([q, stop]), np.array([stop]))
    again = strat.next_target(stop + np.array([0.3, 0.0, 0.0]))  # back out, home again
    assert again[0] == home[0]
    assert np.max(np.abs(again[1:] - home[1:])) > 0.01  # another posture past the block
    clear = strat.next_target(home + np.array([-0.8, 0.0, 0.0]))  # the other side: clear
    np.testing.assert_allclose(clear, home)


def test_frontier_probe_links_pushes_the_tip_through_where_an_inner_link_stopped() -> None:
    """After a move stopped by an inner link (the outermost joint short of its target is not
    the last), probe_links puts the tip behind a point of that link in the stopped
    configuration and then pushes it past the point along the link's motion there; a move
    stopped at the last link, or with the option off, is followed as before."""
    from wholearm_tools.sim.collision import Collider
    from wholearm_tools.sim.occupancy import SweptGrid
    from wholearm_tools.sim.strategies import make_strategy

    sc = load_scenario("paper_spatial")

    def strategy(probe: float):
        s = make_strategy("frontier", sc.robot, Collider(sc.robot, sc.obstacles[:1]),  # floor
                          SweptGrid(sc.robot), rng=0, home_every=0, probe_links=probe,
                          probe_depth=0.04)
        s.home = sc.home.copy()
        return s

    q = sc.home.copy()
    target = q + np.array([0.6, 0.3, 0.2, 0.0, 0.0])  # base, shoulder and elbow swing
    stop = q + np.array([0.3, 0.15, 0.1, 0.0, 0.0])  # link 2 (the forearm) stopped
    moving = target - q  # joint-space direction of the move
    back = q + np.array([0.25, 0.12, 0.08, 0.0, 0.0])  # where the retreat left the arm
    strat = strategy(1.0)
    strat.observe(np.array([q, stop]), np.array([stop, target]))
    pre = strat.next_target(back)
    push = strat.next_target(pre)
    a, b = sc.robot.joint_positions(stop)[2:4]  # link 2's axis when it stopped
    axes = sc.robot.joint_axes(stop)

    def along(x):  # the probed point of the link and the link's motion there
        t = np.clip(np.dot(x - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        p = a + t * (b - a)
        v = np.cross(axes[:3], p - sc.robot.joint_positions(stop)[:3]).T @ moving[:3]
        return p, v / np.linalg.norm(v)

    tip_pre = sc.robot.joint_positions(pre)[-1]
    tip_push = sc.robot.joint_positions(push)[-1]
    p, v = along(0.5 * (tip_pre + tip_push))
    assert np.linalg.norm(tip_pre - (p - 0.04 * v)) < 0.01  # behind the link, where it swept
    assert np.linalg.norm(tip_push - (p + 0.04 * v)) < 0.01  # pushed past it
    assert np.dot(tip_push - tip_pre, v) > 0.07

    # the last link stopped: an ordinary move follows (no probe), as with the option off
    for probe, last in ((1.0, True), (0.0, False)):
        s = strategy(probe)
        tgt = target.copy()
        stp = stop.copy()
        if last:
            tgt[4] += 0.4
            stp[4] += 0.2
        s.observe(np.array([q, stp]), np.array([stp, tgt]))
        nxt = s.next_target(back)
        assert s._probe is None
        assert nxt is None or np.linalg.norm(sc.robot.joint_positions(nxt)[-1]
                                             - tip_pre) > 0.01


def test_paper_planar_default_run_touches_every_surface() -> None:
    covs, kinds = _default_run_coverage("paper_planar")  # 180 s, seed 0
    assert len(covs) == 6
    assert all(c.count >= 4 for c in covs)  # a line's 2 parameters and more (the top wall)
    assert sum(c.count >= 10 for c in covs) >= 3
    for post in covs[4:]:
        assert post.arc is not None
        assert post.arc >= 90
    assert kinds["tip"] >= 100
    assert kinds["body"] >= 5


def test_lab_sharp_default_run_covers_both_circles() -> None:
    covs, kinds = _default_run_coverage("lab_sharp")
    c0, c1 = covs[0], covs[1]
    for c in (c0, c1):
        assert c.count >= 10
        assert c.arc is not None
        assert c.arc >= 90
        assert c.body >= 5
    assert all(c.count >= 5 for c in covs)
    assert kinds["tip"] >= 30
    assert kinds["body"] >= 10


def test_paper_spatial_first_minute_touches_plane_and_both_posts() -> None:
    """Without tip probes (the scenario's setting when this was written; the probes spend arm
    time pushing the tip through link contacts, and the bundled run is 240 s for it:
    tests/test_pipeline.py checks what that run reconstructs)."""
    import dataclasses

    sc = load_scenario("paper_spatial")
    sc = dataclasses.replace(sc, strategy_params={**sc.strategy_params, "probe_links": 0.0})
    plane, post1, post2, _sphere = surface_coverage(sc.simulate(duration=60.0).truth)
    assert plane.count >= 10
    for post in (post1, post2):
        assert post.count >= 5
        assert post.arc is not None
        assert post.arc >= 60
    # (the sphere is first touched after 60 s on seed 0: see docs/simulator.md)


def test_frontier_crowding_counts_blocked_tips_near_the_tip_path() -> None:
    from wholearm_tools.sim.collision import Collider
    from wholearm_tools.sim.occupancy import SweptGrid
    from wholearm_tools.sim.strategies import make_strategy

    sc = load_scenario("lab_circle")
    strat = make_strategy("frontier", sc.robot, Collider(sc.robot, sc.obstacles),
                          SweptGrid(sc.robot), rng=0, crowd=1.0, crowd_radius=0.05)
    q = sc.home.copy()
    tip = sc.robot.joint_positions(q)[-1, :2]
    strat.touched = list(tip + np.array([[0.01, 0.0], [0.0, 0.02], [0.5, 0.5]]))
    far = q + np.array([0.0, -1.0])  # moves the tip away: starts next to two blocked tips
    counts = strat._crowding(q, np.array([far]))
    assert counts.tolist() == [2.0]
