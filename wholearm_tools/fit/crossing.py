"""Whether the robot's own motion crossed a fitted surface *between* its contacts.

:func:`~wholearm_tools.fit.core.sweep_violation` looks next to each contact (within
``sweep_near``), which catches a surface pushed a few millimetres into the robot's path.  It
misses a primitive held up by two distant clusters of contacts: repeated touches at one spot
and one contact half a metre away fit a line exactly, and the arm sweeps back and forth across
that line in between, far from either cluster.  A surface the robot touched cannot be passed
through where its contacts say it is, so this module finds the cuts that lie *within* the
support:

* a curve (2-D line or circle): the cuts split the support, ordered along the curve, into
  pieces; the primitive stands only if one uncut piece would determine it by itself (enough
  contacts over enough length).  A wall with a doorway the arm went through keeps its contacts
  on either side as long as one side holds a fit's worth of them;
* a plane: cuts inside the convex hull of its support points (in the plane) rule it out.  A
  flat wall with an opening the arm passed through, touched all round the opening, would go
  too: not seen in the bundled scenarios, documented in docs/method.md.

* a cylinder the robot is outside of (``free_side`` > 0, a post): cuts within the axial
  range and the arc its support covers rule it out.  A post is solid: the arm goes round it or
  over its top, never through it (paper_spatial seed 5, 180 s: a tilted cylinder through link
  contacts on both posts, 45 cm apart, 268 mm RMS from the post it was matched to).

* a sphere the robot is outside of (a ball): cuts within the cap its support covers (no
  farther from the support's mean direction, seen from the centre, than the farthest support
  point) rule it out, for the same reason (paper_spatial seed 1, 240 s, with tip probes: a
  sphere r 0.72 m through link contacts on a post and on the ball, 0.5 m apart).

Other types (cone, torus) and enclosures (free space inside) are not checked here: a bore's
wall is crossed through a junction's window, inside the region its contacts surround.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.fit.data import Sweep

FloatArray = NDArray[np.float64]

#: primitive types :func:`crossed_between` checks
CHECKED = ("line", "circle", "plane")

#: solid bodies (free side outside) :func:`crossed_between` checks: a post and a ball
SOLIDS = ("cylinder", "sphere")

#: fewer cuts than this inside a support are ignored (a capsule grazing the surface within the
#: tolerance on a noisy log)
MIN_CUTS = 3


def cut_feet(primitive: Any, free_side: float, sweep: Sweep, tol: float) -> FloatArray:
    """Feet on the surface (closest points) of the sweep capsules that penetrate it deeper
    than ``tol``, shape ``(k, d)``."""
    if len(sweep) == 0:
        return np.zeros((0, sweep.dim))
    clear, t = primitive.segment_signed_distance(sweep.a, sweep.b, free_side=float(free_side))
    deep = np.flatnonzero(np.asarray(clear) - sweep.radius < -tol)
    if deep.size == 0:
        return np.zeros((0, sweep.dim))
    x = sweep.a[deep] + np.asarray(t)[deep, None] * (sweep.b[deep] - sweep.a[deep])
    return np.asarray(primitive.closest_point(x), dtype=float).reshape(-1, sweep.dim)


#: primitive types with an inside (negative signed distance) that can enclose the robot
ENCLOSURES = ("circle", "sphere", "cylinder")


def escaped_share(kind: str, primitive: Any, free_side: float, base: FloatArray,
                  n_cuts: int, n_capsules: int) -> float | None:
    """Share ``n_cuts / n_capsules`` of the sweep capsules that cut through an enclosure
    holding the robot's base (a circle, sphere or cylinder with free space inside and the base
    inside it), or None when the primitive is no such enclosure.

    A bore the robot stands in bounds nearly all its motion; the arm leaves it only through
    openings (well_junction's main bore: 13-15 % of the capsules, the ones in the branch). A
    circle through two clusters of wall contacts that happens to hold the base has most of
    the arm's motion outside it (lab_circle seed 15, 20 s: 77 %)."""
    if kind not in ENCLOSURES or free_side > 0 or n_capsules == 0:
        return None
    if float(primitive.signed_distance(np.asarray(base, dtype=float)[None])[0]) >= 0:
        return None
    return n_cuts / n_capsules


def sweep_objection(kind: str, params: dict[str, Any], primitive: Any, free_side: float,
                    support: FloatArray, sweep: Sweep, base: FloatArray | None, *, tol: float,
                    need: int, min_span: float, min_cuts: int, max_escaped: float
                    ) -> str | None:
    """Why the robot's own motion rules a fitted primitive out, or None: an enclosure holding
    the base that more than ``max_escaped`` of the capsules cut through
    (:func:`escaped_share`), or a line, circle or plane crossed between its contacts
    (:func:`crossed_between`, with ``need``, ``min_span`` and ``min_cuts``).  ``tol``: the
    depth a capsule must cut to count."""
    if kind not in CHECKED and kind not in ENCLOSURES:
        return None
    feet = cut_feet(primitive, free_side, sweep, tol)
    share = (None if base is None else
             escaped_share(kind, primitive, free_side, base, len(feet), len(sweep)))
    if share is not None and share > max_escaped:
        return (f"it would enclose the robot's base, yet {100 * share:.0f} % of the robot's "
                "motion went through it")
    return crossed_between(kind, params, support, feet, need=need, min_span=min_span,
                           min_cuts=min_cuts, free_side=free_side)


def _covered_arc(angles: FloatArray) -> tuple[float, float]:
    """``(start, span)`` [rad] of the arc that points at ``angles`` on a circle cover: from the
    end of the largest gap between neighbours, all the way round but that gap."""
    order = np.sort(np.mod(angles, 2 * np.pi))
    gaps = np.diff(np.concatenate([order, order[:1] + 2 * np.pi]))
    return float(order[(int(np.argmax(gaps)) + 1) % len(order)]), 2 * np.pi - float(gaps.max())


def _along(kind: str, params: dict[str, Any], support: FloatArray, feet: FloatArray
           ) -> tuple[FloatArray, FloatArray]:
    """Curve coordinates [m] of the support points and of the cut feet inside the support's
    extent (a circle's coordinate starts after its largest gap between support points)."""
    if kind == "line":
        d = np.asarray(params["direction"], dtype=float)
        d = d / np.linalg.norm(d)
        s, f = support @ d, feet @ d
        return s, f[(f > s.min()) & (f < s.max())]
    c = np.asarray(params["center"], dtype=float)
    r = float(np.asarray(params["radius"], dtype=float))
    ang = np.arctan2(support[:, 1] - c[1], support[:, 0] - c[0])
    start, span = _covered_arc(ang)
    s = np.mod(ang - start, 2 * np.pi)
    f = np.mod(np.arctan2(feet[:, 1] - c[1], feet[:, 0] - c[0]) - start, 2 * np.pi)
    return r * s, r * f[f < span]


def _within_post_support(params: dict[str, Any], support: FloatArray, feet: FloatArray
                         ) -> NDArray[np.bool_]:
    """Which ``feet`` on a cylinder lie within the axial range of its ``support`` and the
    arc it covers (outside the largest angular gap between support points)."""
    from wholearm_tools.fit.models import perp_bases

    p0 = np.asarray(params["point"], dtype=float)
    a = np.asarray(params["axis"], dtype=float)
    a = a / np.linalg.norm(a)
    u, v = perp_bases(a[None])
    s_sup, s_ft = (support - p0) @ a, (feet - p0) @ a
    start, span = _covered_arc(np.arctan2((support - p0) @ v[0], (support - p0) @ u[0]))
    ang_ft = np.arctan2((feet - p0) @ v[0], (feet - p0) @ u[0])
    on_arc = np.mod(ang_ft - start, 2 * np.pi) <= span
    return on_arc & (s_ft >= s_sup.min()) & (s_ft <= s_sup.max())


def _within_cap(params: dict[str, Any], support: FloatArray, feet: FloatArray
                ) -> NDArray[np.bool_]:
    """Which ``feet`` on a sphere lie within the cap its ``support`` covers (seen from the
    centre, no farther from the support's mean direction than its farthest point)."""
    c = np.asarray(params["center"], dtype=float)

    def unit(x: FloatArray) -> FloatArray:
        d = x - c
        return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)

    u = unit(support)
    m = u.mean(axis=0)
    m /= max(float(np.linalg.norm(m)), 1e-12)
    return unit(feet) @ m >= float(np.min(u @ m))


def crossed_between(kind: str, params: dict[str, Any], support: FloatArray, feet: FloatArray,
                    *, need: int, min_span: float, min_cuts: int,
                    free_side: float | None = None) -> str | None:
    """Why the cuts ``feet`` rule the primitive out, or None when they do not.

    ``support``: the primitive's support points on its surface ``(S, d)``; ``need`` and
    ``min_span``: the contacts and the length one uncut piece of a curve's support needs;
    ``min_cuts``: fewer cuts inside the support than this are ignored (a capsule grazing the
    surface within the tolerance on a noisy log); ``free_side``: the primitive's (a cylinder
    or sphere is checked only when it is > 0, a post or a ball).
    """
    support = np.asarray(support, dtype=float)
    feet = np.asarray(feet, dtype=float)
    if len(support) < 2 or len(feet) == 0:
        return None
    if kind in SOLIDS and free_side is not None and free_side > 0:
        within = _within_post_support if kind == "cylinder" else _within_cap
        inside = int(np.count_nonzero(within(params, support, feet)))
        if inside < min_cuts:
            return None
        return (f"the robot passed through it {inside} times inside the region its contacts "
                "span, and its contacts put the robot outside it")
    if kind not in CHECKED:
        return None
    if kind == "plane":
        from scipy.spatial import Delaunay, QhullError

        from wholearm_tools.fit.models import perp_bases

        n = np.asarray(params["normal"], dtype=float)
        e1, e2 = perp_bases((n / np.linalg.norm(n))[None])
        basis = np.stack([e1[0], e2[0]], axis=1)
        try:
            hull = Delaunay(support @ basis)
        except QhullError:  # support points on a line: no region between them
            return None
        inside = int(np.count_nonzero(hull.find_simplex(feet @ basis) >= 0))
        if inside < min_cuts:
            return None
        return f"the robot passed through it {inside} times inside the region its contacts span"
    s, cuts = _along(kind, params, support, feet)
    if len(cuts) < min_cuts:
        return None
    cuts = np.sort(cuts)
    piece = np.searchsorted(cuts, s)            # which gap between cuts each contact lies in
    best_n, best_span = 0, 0.0
    for k in np.unique(piece):
        sk = s[piece == k]
        if len(sk) > best_n or (len(sk) == best_n and np.ptp(sk) > best_span):
            best_n, best_span = len(sk), float(np.ptp(sk))
    if best_n >= need and best_span >= min_span:
        return None
    return (f"the robot passed through it {len(cuts)} times between its contacts, and no "
            f"uncut stretch holds enough of them (at most {best_n} over "
            f"{1e3 * best_span:.0f} mm)")
