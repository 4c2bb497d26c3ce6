"""Tip probability refined by the fitted map: eq. (2) as the prior, the surfaces as evidence.

Eq. (2) weighs where the contact could have happened with the swept map only.  Once primitives
are fitted, each hypothesis also predicts a residual against them:

* **tip** (or the joint sphere at the outer end of an inner link): the sphere touches a fitted
  surface, ``r_T = min_k |s_k sd_k(P) - w_tip|``, and the link's side does not cut into any;
* **link body**: the side is tangent to a fitted surface, ``r_L = min_k |min_t s_k sd_k(L(t)) -
  w_link|`` with the least clearance strictly inside the segment (at its outer end the side
  *is* the end sphere; inside a bore a straight link's least clearance is always at an end),
  and the outer sphere does not cut into any.

With Gaussian residuals of the surface's noise level ``sigma_k`` and a floor ``1 / Delta`` for
"the contact lies on a surface the map does not hold" (``Delta`` = half the link length, the
same scale as the fit variance of :mod:`wholearm_tools.classify.tip`)::

    L_H = max_k N(r_H,k; 0, sigma_k) [support] [no penetration]  +  1 / Delta
    P_map = P_T L_T / (P_T L_T + (1 - P_T) L_L)

A surface counts for a hypothesis only near the region its own contacts cover (the contact's
point on it within ``support_radius`` of one of them): an infinite line or plane fitted to one
wall says nothing about a point far along it; it rules a hypothesis out only right where it is
known (``cut_radius``): next to a junction one bore's extension runs through the other.
Contacts whose two hypotheses touch the same surface in the same place (a sharp tip at the end
of its link) keep their P_T.  The fit weights ambiguous contacts ~1/Δ² against 1/σ0² for
certain ones, so a contact barely moves the surfaces it is then judged against.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError
from wholearm_tools.geometry.base import segment_min_numeric

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class MapSurface:
    """One fitted surface as the refinement sees it.

    primitive : geometry primitive (``signed_distance``, ``segment_signed_distance``)
    free_side : +1 / -1, the side the robot is on
    sigma : residual noise level of its contacts [m]
    support : (K, d) points of the surface its contacts cover
    """

    primitive: object
    free_side: float
    sigma: float
    support: FloatArray


def refine_with_map(p_tip: FloatArray, tip_center: FloatArray, tip_radius: FloatArray,
                    seg_a: FloatArray, seg_b: FloatArray, link_radius: FloatArray,
                    surfaces: Sequence[MapSurface], *, support_radius: float = 0.1,
                    cut_radius: float = 0.015, penetration: float = 3.0) -> FloatArray:
    """Posterior tip probability of ``M`` contacts given the fitted surfaces.

    Parameters
    ----------
    p_tip : (M,) prior tip probability (eq. 2)
    tip_center : (M, d) centre of the outer sphere; tip_radius : (M,) its radius
    seg_a, seg_b : (M, d) the link's axis; link_radius : (M,)
    surfaces : fitted surfaces
    support_radius : a surface speaks for a hypothesis only within this distance [m] of the
        points its own contacts cover
    cut_radius : ... and it rules a hypothesis out (see ``penetration``) only within this
        distance [m] of those points: next to a junction the infinite extension of one bore
        runs through the other, where the robot is
    penetration : a hypothesis is impossible when the other part of the link would cut into a
        surface by more than ``penetration * sigma``

    Returns
    -------
    (M,) float in [0, 1]; equal to ``p_tip`` where no surface speaks for either hypothesis
    """
    p = np.asarray(p_tip, dtype=float).reshape(-1)
    m = p.shape[0]
    if not (support_radius > 0 and cut_radius > 0 and penetration > 0):
        raise InputError("support_radius, cut_radius and penetration must be positive, got "
                         f"{support_radius}, {cut_radius}, {penetration}")
    if m == 0 or not surfaces:
        return p.copy()
    lt, ll = hypothesis_likelihoods(tip_center, tip_radius, seg_a, seg_b, link_radius,
                                    surfaces, support_radius=support_radius,
                                    cut_radius=cut_radius, penetration=penetration)
    return _posterior_tip(p, lt, ll)


def _posterior_tip(p: FloatArray, lt: FloatArray, ll: FloatArray) -> FloatArray:
    num = p * lt
    den = num + (1 - p) * ll
    out = np.where(den > 0, num / np.where(den > 0, den, 1.0), p)
    # one and the same point (sharp tip at the end of its link): nothing to tell apart
    same = np.isclose(lt, ll, rtol=1e-9, atol=0.0)
    return np.clip(np.where(same, p, out), 0.0, 1.0)


def hypothesis_likelihoods(tip_center: FloatArray, tip_radius: FloatArray, seg_a: FloatArray,
                           seg_b: FloatArray, link_radius: FloatArray,
                           surfaces: Sequence[MapSurface], *, support_radius: float = 0.1,
                           cut_radius: float = 0.015, penetration: float = 3.0,
                           floor: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
    """``(L_T, L_L)``: the likelihood of the tip (outer sphere) and of the link-side hypothesis
    of ``M`` contacts given the fitted surfaces, floor ``1 / Delta`` included and zero where
    the other part of the link would cut into a surface (module docstring; the arguments are
    those of :func:`refine_with_map`).  ``floor`` overrides ``1 / Delta`` per contact."""
    P = np.asarray(tip_center, dtype=float)
    m = P.shape[0]
    P = P.reshape(m, -1)
    a = np.asarray(seg_a, dtype=float).reshape(m, -1)
    b = np.asarray(seg_b, dtype=float).reshape(m, -1)
    wt = np.asarray(tip_radius, dtype=float).reshape(m)
    wl = np.asarray(link_radius, dtype=float).reshape(m)
    if floor is None:
        floor = 1.0 / np.maximum(0.5 * np.linalg.norm(b - a, axis=1), 1e-6)
    floor = np.asarray(floor, dtype=float).reshape(m)
    like_t = np.zeros(m)
    like_l = np.zeros(m)
    ok_t = np.ones(m, dtype=bool)
    ok_l = np.ones(m, dtype=bool)
    for view in _views(surfaces):
        sig = view.sigma
        clear_tip = view.clearance(P) - wt
        clear_seg, t = view.segment_clearance(a, b)
        clear_link = clear_seg - wl
        x_link = a + t[:, None] * (b - a)
        # the side touches only where its least clearance is inside the segment: at the outer
        # end it is the end sphere (the tip / joint reading), at the inner end the joint the
        # link turns about (which would have stopped the link before); inside a concave
        # surface (a bore) the least clearance of a straight link is always at an end
        side = (t > 1e-6) & (t < 1.0 - 1e-6)
        # ... or the whole side lies flush (a link along a wall: both ends equally close)
        ends = view.clearance(np.vstack([a, b]))
        side |= np.abs(ends[:m] - ends[m:]) <= sig
        d_t = view.support_distance(P)
        d_l = view.support_distance(x_link)
        near_t = d_t <= support_radius
        near_l = d_l <= support_radius
        # the other part of the link may not cut into the surface (right where it is known)
        ok_t &= (clear_link > -penetration * sig) | (d_l > cut_radius)
        ok_l &= (clear_tip > -penetration * sig) | (d_t > cut_radius)
        gauss = 1.0 / (np.sqrt(2 * np.pi) * sig)
        like_t = np.maximum(like_t, np.where(near_t, gauss * np.exp(-0.5 * (clear_tip / sig)
                                                                    ** 2), 0.0))
        like_l = np.maximum(like_l, np.where(near_l & side,
                                             gauss * np.exp(-0.5 * (clear_link / sig) ** 2),
                                             0.0))
    return (like_t + floor) * ok_t, (like_l + floor) * ok_l


def link_evidence(contact: NDArray[np.int64], prior: FloatArray, p_tip: FloatArray,
                  tip_center: FloatArray, tip_radius: FloatArray, seg_a: FloatArray,
                  seg_b: FloatArray, link_radius: FloatArray, floor: FloatArray,
                  surfaces: Sequence[MapSurface], **kwargs: float
                  ) -> tuple[FloatArray, FloatArray]:
    """The fitted map's say on *which link* made a contact the joint signals left open.

    Each of ``R`` rows is one candidate link of contact ``contact[r]``, with its prior
    ``prior[r]`` (the link's share from the signals and the swept map), the tip probability
    of its two hypotheses ``p_tip[r]`` and its geometry at the contact (arguments of
    :func:`refine_with_map`).  The evidence of a candidate is
    ``prior (P_T L_T + (1 - P_T) L_L)``; ``floor`` (per row) must be the same for every row of
    one contact, so that a contact no surface speaks for keeps its prior.

    Returns ``(post, p_map)``: each row's posterior among its contact's rows, and its map
    refined tip probability.
    """
    contact = np.asarray(contact, dtype=np.int64).reshape(-1)
    r = contact.shape[0]
    prior = np.asarray(prior, dtype=float).reshape(r)
    p = np.asarray(p_tip, dtype=float).reshape(r)
    if r == 0:
        return prior.copy(), p.copy()
    lt, ll = hypothesis_likelihoods(tip_center, tip_radius, seg_a, seg_b, link_radius,
                                    surfaces, floor=floor, **kwargs)
    ev = prior * (p * lt + (1 - p) * ll)
    total = np.bincount(contact, ev)[contact]
    post = np.where(total > 0, ev / np.where(total > 0, total, 1.0), prior)
    return post, _posterior_tip(p, lt, ll)


def _support_distance(prim: object, x: FloatArray, support: FloatArray) -> FloatArray:
    """Distance from the point of the surface closest to each ``x`` to the nearest of the
    surface's ``support`` points (``inf`` without any)."""
    support = np.asarray(support, dtype=float)
    if support.size == 0:
        return np.full(len(x), np.inf)
    foot = np.asarray(prim.closest_point(x))                            # type: ignore[attr-defined]
    d2 = ((foot[:, None, :] - support[None, :, :]) ** 2).sum(-1)
    return np.sqrt(d2.min(axis=1))


#: surface types that enclose the arm when their free side is inside
_ENCLOSING = ("circle", "sphere", "cylinder", "cone", "torus")


class _View:
    """Fitted surfaces as the refinement queries them: one surface, or (:class:`_Enclosure`)
    several bounding one free space; a point's clearance is the largest of its clearances on
    each one's free side."""

    def __init__(self, *surfaces: MapSurface) -> None:
        self.surfaces = tuple(surfaces)
        self.sigma = max(max(float(s.sigma) for s in surfaces), 1e-9)

    def clearance(self, x: FloatArray) -> FloatArray:
        return np.max([float(s.free_side) * np.asarray(s.primitive.signed_distance(x))  # type: ignore[attr-defined]
                       for s in self.surfaces], axis=0)

    def segment_clearance(self, a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
        s = self.surfaces[0]
        val, t = s.primitive.segment_signed_distance(  # type: ignore[attr-defined]
            a, b, free_side=float(s.free_side))
        return np.asarray(val), np.asarray(t)

    def support_distance(self, x: FloatArray) -> FloatArray:
        """Distance from the surface point closest to each ``x`` to the nearest point the
        surface's own contacts cover (the smallest over an enclosure's members)."""
        return np.min([_support_distance(s.primitive, x, s.support) for s in self.surfaces],
                      axis=0)


class _Enclosure(_View):
    """Several fitted enclosures (bores whose inside is free) as the one free space they bound
    together — at a junction the arm stands in one bore and reaches into the other, and a link
    resting on the lip between them touches the union's boundary, not either infinite
    cylinder.  The union has no closed-form segment distance: it is minimised numerically."""

    def segment_clearance(self, a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray]:
        val, t = segment_min_numeric(self.clearance, a, b)
        return np.asarray(val), np.asarray(t)


def _views(surfaces: Sequence[MapSurface]) -> list[_View]:
    """Each fitted surface on its own, except that two or more enclosures with free space inside
    become one :class:`_Enclosure`."""
    inside = [s for s in surfaces if float(s.free_side) < 0
              and getattr(s.primitive, "kind", "") in _ENCLOSING]
    if len(inside) < 2:
        return [_View(s) for s in surfaces]
    return [_Enclosure(*inside), *(_View(s) for s in surfaces if s not in inside)]
