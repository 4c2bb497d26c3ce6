"""The robot's sweep crossing a fitted line, circle, plane or post between its contacts."""

from __future__ import annotations

import numpy as np
import pytest

from wholearm_tools.fit.crossing import crossed_between, cut_feet
from wholearm_tools.fit.data import Sweep
from wholearm_tools.geometry import Circle2D, Line2D, Plane


def _sticks(xs, y0: float, y1: float, r: float = 0.01) -> Sweep:
    """Vertical 2-D capsules at ``xs`` from ``y0`` to ``y1``."""
    xs = np.asarray(xs, dtype=float)
    return Sweep(np.c_[xs, np.full(len(xs), y0)], np.c_[xs, np.full(len(xs), y1)],
                 np.full(len(xs), r))


LINE = Line2D([0.0, 0.0], [1.0, 0.0])  # free side +1: y > 0


def _check(kind, params, support, sweep, prim, need=4, min_span=0.01):
    feet = cut_feet(prim, 1.0, sweep, tol=2e-3)
    return crossed_between(kind, params, support, feet, need=need, min_span=min_span,
                           min_cuts=3)


def test_a_line_held_up_by_two_far_clusters_and_crossed_between_them_goes():
    """Three touches within 2 mm and one 0.5 m away determine a line exactly; the arm swept
    across it in between: no surface is there."""
    support = np.array([[0.0, 0.0], [0.001, 0.0], [0.002, 0.0], [0.5, 0.0]])
    params = {"point": [0.0, 0.0], "direction": [1.0, 0.0]}
    crossing = _sticks(np.linspace(0.1, 0.4, 20), -0.1, 0.1)
    why = _check("line", params, support, crossing, LINE)
    assert why is not None
    assert "20 times between its contacts" in why
    assert "at most 3 over 2 mm" in why
    # the same contacts with the arm only on the free side: kept
    assert _check("line", params, support, _sticks(np.linspace(0.1, 0.4, 20), 0.05, 0.2),
                  LINE) is None
    # crossings beyond the last contact (past a wall's corner) do not count
    assert _check("line", params, support, _sticks(np.linspace(0.6, 0.9, 20), -0.1, 0.1),
                  LINE) is None


def test_a_wall_with_a_doorway_the_arm_went_through_stays():
    """Five contacts on either side of a 0.2 m gap that the arm passed through: either side
    determines the line by itself."""
    support = np.c_[np.r_[np.linspace(-0.3, -0.1, 5), np.linspace(0.1, 0.3, 5)], np.zeros(10)]
    params = {"point": [0.0, 0.0], "direction": [1.0, 0.0]}
    door = _sticks(np.linspace(-0.05, 0.05, 30), -0.1, 0.1)
    assert _check("line", params, support, door, LINE) is None
    # with only three contacts on each side neither stretch holds a fit's worth (need 4)
    few = support[[0, 2, 4, 5, 7, 9]]
    assert _check("line", params, few, door, LINE) is not None


def test_fewer_cuts_than_the_minimum_are_ignored():
    support = np.array([[0.0, 0.0], [0.001, 0.0], [0.002, 0.0], [0.5, 0.0]])
    params = {"point": [0.0, 0.0], "direction": [1.0, 0.0]}
    assert _check("line", params, support, _sticks([0.2, 0.3], -0.1, 0.1), LINE) is None


def test_a_circle_is_checked_over_the_arc_its_contacts_cover_only():
    circle = Circle2D([0.0, 0.0], 0.1)
    params = {"center": [0.0, 0.0], "radius": 0.1}
    ang = np.radians([0.0, 1.0, 2.0, 90.0])  # a cluster at 0 deg, one contact at 90 deg
    support = 0.1 * np.c_[np.cos(ang), np.sin(ang)]
    # radial capsules reaching into the circle at 30-60 deg (inside the covered arc)
    a = np.radians(np.linspace(30.0, 60.0, 10))
    into = Sweep(0.2 * np.c_[np.cos(a), np.sin(a)], 0.05 * np.c_[np.cos(a), np.sin(a)],
                 np.full(10, 0.01))
    assert _check("circle", params, support, into, circle) is not None
    # the same at 180-210 deg, outside the covered arc: the circle stands
    b = a + np.pi
    away = Sweep(0.2 * np.c_[np.cos(b), np.sin(b)], 0.05 * np.c_[np.cos(b), np.sin(b)],
                 np.full(10, 0.01))
    assert _check("circle", params, support, away, circle) is None


def test_a_plane_crossed_inside_its_contacts_hull_goes():
    """Tips at one height around a bore fit a horizontal plane; the arm moved up and down
    inside the ring."""
    plane = Plane([0.0, 0.0, 0.0], [0.0, 0.0, 1.0])
    params = {"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}
    ang = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
    support = np.c_[0.15 * np.cos(ang), 0.15 * np.sin(ang), np.zeros(8)]
    xy = np.random.default_rng(0).uniform(-0.05, 0.05, size=(12, 2))
    inside = Sweep(np.c_[xy, np.full(12, -0.2)], np.c_[xy, np.full(12, 0.2)], np.full(12, 0.02))
    why = _check("plane", params, support, inside, plane)
    assert why is not None
    assert "12 times inside" in why
    shift = np.array([0.5, 0.0, 0.0])  # the same capsules beside the ring
    outside = Sweep(inside.a + shift, inside.b + shift, inside.radius)
    assert _check("plane", params, support, outside, plane) is None
    # collinear support spans no region
    assert _check("plane", params, support[[0, 4]], inside, plane) is None


def test_a_post_the_arm_passed_through_between_its_contacts_goes():
    """A tilted cylinder (free side outside: a post) held up by link contacts at two places
    45 cm apart along it; the arm swept through its body in between, which a post does not
    allow.  Capsules beside it, beyond its axial range or off the arc its contacts cover
    leave it; a bore (free space inside) is not checked."""
    from wholearm_tools.geometry import Cylinder

    axis = np.array([0.0, 0.0, 1.0])
    post = Cylinder([0.0, 0.0, 0.0], axis, 0.07)
    params = {"point": np.zeros(3), "axis": axis, "radius": 0.07}
    ang = np.radians([170.0, 180.0, 190.0])
    ring = np.c_[0.07 * np.cos(ang), 0.07 * np.sin(ang)]
    support = np.vstack([np.c_[ring, np.zeros(3)], np.c_[ring, np.full(3, 0.45)]])
    z = np.linspace(0.1, 0.35, 12)

    def through(x0):  # horizontal capsules along y at x = x0, heights z
        return Sweep(np.c_[np.full(12, x0), np.full(12, -0.3), z],
                     np.c_[np.full(12, x0), np.full(12, 0.3), z], np.full(12, 0.02))

    def check(sweep, side=1.0, sup=support):
        feet = cut_feet(post, side, sweep, tol=2e-3)
        return crossed_between("cylinder", params, sup, feet, need=7, min_span=0.01,
                               min_cuts=3, free_side=side)

    why = check(through(-0.05))  # through the body, on the contacts' side
    assert why is not None
    assert "12 times inside the region its contacts span" in why
    assert check(through(0.2)) is None  # beside it
    assert check(through(0.05)) is None  # through the side its contacts do not cover
    lift = np.array([0.0, 0.0, 0.5])
    above = Sweep(through(-0.05).a + lift, through(-0.05).b + lift, np.full(12, 0.02))
    assert check(above) is None  # over its contacts' axial range
    assert check(through(-0.05), side=-1.0) is None  # a bore: crossed through windows


def test_a_ball_the_arm_passed_through_within_its_contacts_goes():
    """A large sphere (free side outside: a ball) held up by contacts on two surfaces half a
    metre apart; the arm swept through its body between them, which a ball does not allow.
    Capsules through the far side of the ball (outside the cap its contacts cover) or beside
    it leave it, and an enclosure (free space inside) is not checked here."""
    from wholearm_tools.geometry import Sphere

    c, r = np.array([0.0, 0.0, 0.0]), 0.7
    ball = Sphere(c, r)
    params = {"center": c, "radius": r}
    ang = np.radians([-25.0, -20.0, -15.0, 15.0, 20.0, 25.0])  # two clusters, 0.5 m apart
    support = r * np.c_[np.sin(ang), np.zeros(6), -np.cos(ang)]  # around the south pole

    def through(z0):  # horizontal capsules along x at height z0, 12 of them along y
        y = np.linspace(-0.1, 0.1, 12)
        return Sweep(np.c_[np.full(12, -0.2), y, np.full(12, z0)],
                     np.c_[np.full(12, 0.2), y, np.full(12, z0)], np.full(12, 0.02))

    def check(sweep, side=1.0):
        feet = cut_feet(ball, side, sweep, tol=2e-3)
        return crossed_between("sphere", params, support, feet, need=6, min_span=0.01,
                               min_cuts=3, free_side=side)

    why = check(through(-0.66))  # through the bottom, between the two clusters
    assert why is not None
    assert "inside the region its contacts span" in why
    assert check(through(0.66)) is None  # through the top, far from its contacts
    assert check(through(-0.8)) is None  # below it
    assert check(through(-0.66), side=-1.0) is None  # an enclosure


@pytest.mark.parametrize("kind", ["sphere", "cylinder"])
def test_other_types_are_not_checked(kind):
    """A bore's wall is crossed through a junction's window, inside its contacts."""
    assert crossed_between(kind, {}, np.zeros((5, 3)), np.zeros((9, 3)), need=5,
                           min_span=0.01, min_cuts=3) is None


def test_an_enclosure_holding_the_base_must_hold_most_of_the_motion():
    from wholearm_tools.fit.crossing import sweep_objection

    bore = Circle2D([0.0, 0.0], 0.3)  # free inside (-1), the base at the centre
    params = {"center": [0.0, 0.0], "radius": 0.3}
    ang = np.linspace(0.0, 2 * np.pi, 40, endpoint=False)
    support = 0.3 * np.c_[np.cos(ang), np.sin(ang)]
    inside = Sweep(np.zeros((40, 2)), 0.2 * np.c_[np.cos(ang), np.sin(ang)], np.full(40, 0.01))
    # 30 of 40 capsules reach out through the wall (between contacts that surround it, so
    # the curve rule alone would rule it out too: give it a wide support gap)
    reach = np.where(np.arange(40) < 30, 0.5, 0.2)[:, None]
    out = Sweep(np.zeros((40, 2)), reach * np.c_[np.cos(ang), np.sin(ang)], np.full(40, 0.01))

    def why(sweep, base, side=-1.0, sup=support):
        return sweep_objection("circle", params, bore, side, sup, sweep, base, tol=2e-3,
                               need=5, min_span=0.01, min_cuts=3, max_escaped=0.5)

    base = np.zeros(2)
    assert why(inside, base) is None
    assert "75 % of the robot's motion went through it" in why(out, base)
    # no base given, or the base outside the circle: only the curve rule applies (the cuts
    # at 0-270 degrees lie outside the contacts at 280-350 degrees)
    few = support[np.arange(40) >= 31]
    assert why(out, None, sup=few) is None
    assert why(out, np.array([1.0, 0.0]), sup=few) is None
