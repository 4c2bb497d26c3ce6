"""Tip probability refined by the fitted map: the surfaces decide where eq. (2) could not."""

from __future__ import annotations

import numpy as np
import pytest

from wholearm_tools.classify.refine import MapSurface, refine_with_map
from wholearm_tools.errors import InputError
from wholearm_tools.geometry import Circle2D, Line2D

WALL = Line2D([0.0, 0.5], [1.0, 0.0])  # y = 0.5, free below (normal +y: free side -1)
SUPPORT = np.array([[x, 0.5] for x in np.linspace(-0.2, 0.2, 9)])
SURF = [MapSurface(WALL, -1.0, 1e-3, SUPPORT)]


def _contact(tip_y, link_y_end, w_tip=0.02, w_link=0.01):
    """A link from (-0.3, link_y_end) ending in a tip sphere at (0, tip_y)."""
    return {"tip_center": np.array([[0.0, tip_y]]), "tip_radius": np.array([w_tip]),
            "seg_a": np.array([[-0.3, link_y_end]]), "seg_b": np.array([[0.0, tip_y]]),
            "link_radius": np.array([w_link])}


def test_tip_touching_a_fitted_wall_becomes_a_tip():
    c = _contact(0.48, 0.40)  # the tip sphere (r 2 cm) touches y = 0.5; the link slopes away
    p = refine_with_map(np.array([0.4]), **c, surfaces=SURF)
    assert p[0] > 0.95  # capped by the 'surface the map does not hold' floor 1/Delta


def test_link_tangent_to_a_fitted_wall_becomes_a_link():
    # the link axis runs 1 cm below the wall over its length: its side touches; the tip does not
    c = {"tip_center": np.array([[0.0, 0.49]]), "tip_radius": np.array([0.005]),
         "seg_a": np.array([[-0.3, 0.49]]), "seg_b": np.array([[0.0, 0.49]]),
         "link_radius": np.array([0.01])}
    p = refine_with_map(np.array([0.5]), **c, surfaces=SURF)
    assert p[0] < 0.05


def test_no_surface_near_either_hypothesis_keeps_the_prior():
    c = _contact(0.10, 0.05)  # 40 cm below the wall
    p = refine_with_map(np.array([0.37]), **c, surfaces=SURF)
    assert p[0] == pytest.approx(0.37)
    # a wall known only far away (support at x = 5 m) says nothing about a contact at x = 0
    far = [MapSurface(WALL, -1.0, 1e-3, SUPPORT + np.array([5.0, 0.0]))]
    p = refine_with_map(np.array([0.37]), **_contact(0.48, 0.40), surfaces=far)
    assert p[0] == pytest.approx(0.37)


def test_hypothesis_that_would_cut_into_a_known_surface_is_ruled_out():
    # the tip sphere touches the wall, but the link's side would then cut 5 mm into a fitted
    # post next to it: the tip reading is impossible, whatever the prior
    post = Circle2D([-0.15, 0.425], 0.05)
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    support = post.center + 0.05 * np.stack([np.cos(ang), np.sin(ang)], 1)
    surfaces = [*SURF, MapSurface(post, 1.0, 1e-3, support)]
    c = {"tip_center": np.array([[0.0, 0.48]]), "tip_radius": np.array([0.02]),
         "seg_a": np.array([[-0.3, 0.48]]), "seg_b": np.array([[0.0, 0.48]]),
         "link_radius": np.array([0.01])}
    assert refine_with_map(np.array([0.9]), **c, surfaces=SURF)[0] > 0.95
    assert refine_with_map(np.array([0.9]), **c, surfaces=surfaces)[0] == 0.0


def test_no_surfaces_and_bad_options():
    c = _contact(0.48, 0.40)
    assert refine_with_map(np.array([0.3]), **c, surfaces=[])[0] == pytest.approx(0.3)
    with pytest.raises(InputError, match="support_radius"):
        refine_with_map(np.array([0.3]), **c, surfaces=SURF, support_radius=0.0)


def test_inside_a_bore_only_the_end_sphere_can_touch():
    """A straight link inside a round bore is closest to the wall at an end: a contact there is
    the end sphere's (tip or joint) even when the sphere is no wider than the link."""
    bore = Circle2D([0.0, 0.0], 0.16)
    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    surfaces = [MapSurface(bore, -1.0, 1e-3, 0.16 * np.stack([np.cos(ang), np.sin(ang)], 1))]
    c = {"tip_center": np.array([[0.14, 0.0]]), "tip_radius": np.array([0.02]),
         "seg_a": np.array([[0.0, 0.02]]), "seg_b": np.array([[0.14, 0.0]]),
         "link_radius": np.array([0.02])}
    assert refine_with_map(np.array([0.4]), **c, surfaces=surfaces)[0] > 0.95


def test_a_link_resting_on_the_lip_between_two_bores_is_a_link_contact():
    """Two bores with free space inside meet at a lip; a straight link inside their union whose
    side rests on the lip touches neither infinite circle, but the union's boundary."""
    main, branch = Circle2D([0.0, 0.0], 0.16), Circle2D([0.2, 0.0], 0.11)

    def ring(c, r):
        ang = np.linspace(0, 2 * np.pi, 24, endpoint=False)
        return np.asarray(c) + r * np.stack([np.cos(ang), np.sin(ang)], 1)

    surfaces = [MapSurface(main, -1.0, 1e-4, ring([0.0, 0.0], 0.16)),
                MapSurface(branch, -1.0, 1e-4, ring([0.2, 0.0], 0.11))]
    xs = np.linspace(0.02, 0.25, 4001)

    def union_clearance(y):
        pts = np.stack([xs, np.full_like(xs, y)], 1)
        return np.max([-main.signed_distance(pts), -branch.signed_distance(pts)], 0).min()

    lo, hi = 0.0, 0.0878  # bisection: the height at which the link's side just touches the lip
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if union_clearance(mid) > 0.01 else (lo, mid)
    y = 0.5 * (lo + hi)
    c = {"tip_center": np.array([[0.25, y]]), "tip_radius": np.array([0.01]),
         "seg_a": np.array([[0.02, y]]), "seg_b": np.array([[0.25, y]]),
         "link_radius": np.array([0.01])}
    assert refine_with_map(np.array([0.5]), **c, surfaces=surfaces)[0] < 0.05
    # either bore alone cannot explain it: the link crosses its infinite circle at the window
    assert refine_with_map(np.array([0.5]), **c, surfaces=surfaces[:1])[0] == pytest.approx(0.5)


def test_the_map_puts_a_contact_on_the_link_whose_reading_touches_it():
    """A rigid group: links 1 (0.3 m, ending at x = 0) and 2 (a 3 cm stub beyond it) moved as
    one, and the signals gave link 1 two to one.  Link 2's end sphere touches the fitted wall
    and link 1's does not (3 cm off): the map puts the contact on link 2, a tip reading.  With
    the wall out of reach of both, the prior stands."""
    from wholearm_tools.classify.refine import link_evidence

    def rows(y_end):  # link 1 from (-0.3, y_end) to (0, y_end), link 2 on to (0.03, y_end)
        return {"tip_center": np.array([[0.0, y_end], [0.03, y_end + 0.03]]),
                "tip_radius": np.array([0.02, 0.02]),
                "seg_a": np.array([[-0.3, y_end], [0.0, y_end]]),
                "seg_b": np.array([[0.0, y_end], [0.03, y_end + 0.03]]),
                "link_radius": np.array([0.01, 0.01])}

    prior = np.array([2 / 3, 1 / 3])
    floor = np.full(2, 1 / 0.15)  # the detected link's 1 / Delta for both rows
    touching = rows(0.5 - 0.02 - 0.03 - 0.0001)  # link 2's sphere 0.1 mm from y = 0.5
    post, p_map = link_evidence(np.array([0, 0]), prior, np.array([0.3, 0.5]), floor=floor,
                                surfaces=SURF, **touching)
    assert post[1] > 0.9
    assert post.sum() == pytest.approx(1.0)
    assert p_map[1] > 0.95
    post, _ = link_evidence(np.array([0, 0]), prior, np.array([0.3, 0.5]), floor=floor,
                            surfaces=SURF, **rows(0.1))
    assert post == pytest.approx(prior)
