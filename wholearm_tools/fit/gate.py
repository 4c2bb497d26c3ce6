"""The one report gate: is a selected primitive determined by its contacts?

A contact's position is known only up to the kinematic errors of the arm that touched it:
encoder noise, joint offsets and link-length errors.  The policy states them as one standard
deviation ``sigma_kin`` of a contact's position, a fraction of the robot's reach (or the measured
noise, when that is larger).  Under that model the parameters of a primitive fitted to ``n``
contacts have the Gauss-Newton covariance ``sigma_kin^2 (J^T J)^-1`` on the type's minimal
parameterisation (lengths in units of the support's RMS spread, so one number speaks for every
type; the support is the fit's data, each tip centre and both ends of each contacting link, so a
link contact counts over the link's length, not only at its point of touch).  A primitive
reaches the map when

* its worst-determined parameter combination has a standard deviation of at most
  ``max_rel_std`` of its support's size, and
* it still has without any one of its contacts (the influence of a single contact): every
  contact's reading is inferred (tip or side, which link), so a primitive that one contact
  alone determines rests on one inference, and that contact's residual cannot show whether it
  is wrong.  For the same reason it needs at least ``dof + 2`` contacts: on ``dof + 1``, the
  others less any one fit exactly, and a reading taken the wrong way bends the fit without
  leaving a residual that tells;
* its **evidence** holds without any one of its contacts: the description length the map
  gains by it, with its most valuable contact left out of the data, is positive
  (``evidence``, from the inference's score).  Contacts read against eq. (2), or shared with a
  neighbouring primitive, pay for it only all together otherwise;
* a flat primitive (line, plane) also has its **type** determined: its contacts tell it from a
  surface curved at the smallest expected radius ``B``.  The flat model is extended by the
  second-order term of a curved surface through its support, ``1/2 u^T K u`` in the in-plane
  coordinates ``u`` of the contact points, with the curvature ``K`` in units of ``1/B``; the
  curvature's marginal standard deviation (every flat parameter free), with every contact and
  without any one, must also be at most ``max_rel_std``.  Contacts on one small patch, or on
  one narrow strip of a post (a line of tips up its side), fit a tangent plane as well as the
  post itself: the type is then not determined, and neither is reported.  A contact whose
  link lies flat on the primitive (a side reading of it, of any candidate link, within the
  kinematic errors of touching over a longer stretch than a surface curved at ``B`` would
  be: :func:`lying_flat`) leaves its point of touch open along that stretch: the surface may
  be flat along the link or touch it at any one point of it.  Its reading still fixes the
  flat parameters, but it says nothing of the curvature, and the type test leaves it out (an
  arm resting against one point of a post, touched again and again while its outer links
  move, fits the post's tangent plane through every position of its resting link).

The leave-one-out information ``J^T J - j_i^T j_i`` is a rank-one downdate, so the check costs
no refit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wholearm_tools.fit.core import _link_min, _normalise, _raw_from_params, residuals_and_touch
from wholearm_tools.fit.data import FitData
from wholearm_tools.fit.models import MODELS, perp_bases
from wholearm_tools.fit.readings import IntArray, Readings
from wholearm_tools.fit.result import FitResult
from wholearm_tools.fit.solve import sd_and_jacobian, tangent_basis


@dataclass(frozen=True, slots=True)
class GateResult:
    """``worst_std``: the worst parameter combination's standard deviation in units of the
    support's spread with every contact; ``worst_std_loo``: the largest of it over the fits
    without one contact, and ``pivot`` that contact's position in the data (-1 when none is
    needed); ``reason``: why the primitive is not reported ('' when it is)."""

    worst_std: float
    worst_std_loo: float
    pivot: int
    reason: str

    def __bool__(self) -> bool:
        return not self.reason


def _touch_rows(fit: FitResult, data: FitData) -> tuple[np.ndarray, np.ndarray, float] | None:
    """Per-contact rows ``(n, dof)`` of the Jacobian on the type's minimal parameterisation at
    the points where the contacts touch (tip centres, the links' points of least clearance),
    those points, and the support's RMS spread [m]; all in normalised units (the support's
    centroid at the origin, unit RMS spread).  None for degenerate data."""
    m = MODELS[fit.kind]
    nd = _normalise(data)
    if nd is None:
        return None
    th = _raw_from_params(m, fit.params, nd)
    side = float(fit.free_side)
    if m.linear:
        side = 1.0  # lines and planes carry their free side in the normal
    _, t, _ = _link_min(m, th, side, nd.a, nd.b)
    pts = np.vstack([nd.tip, nd.a + t[:, None] * (nd.b - nd.a)]) if len(nd.a) else nd.tip
    _, J = sd_and_jacobian(m.kind, th, pts)
    return J @ tangent_basis(m.kind, th), pts, float(nd.scale)


def _curvature_rows(fit: FitResult, pts: np.ndarray, scale: float, B: float) -> np.ndarray:
    """Per-contact rows ``(n, k)`` of the second-order term ``1/2 u^T K u`` of a surface curved
    through a flat primitive's touch points ``pts`` (normalised units, spread ``scale``):
    ``k = 1`` for a line, ``3`` for a plane (the entries of ``K`` in an orthonormal basis of
    symmetric matrices), ``K`` in units of ``1/B``."""
    if MODELS[fit.kind].dim == 2:
        d = np.asarray(fit.params["direction"], dtype=float)
        tangents = (d / np.linalg.norm(d))[None]
    else:
        nrm = np.asarray(fit.params["normal"], dtype=float)
        e1, e2 = perp_bases((nrm / np.linalg.norm(nrm))[None])
        tangents = np.vstack([e1, e2])
    u = (pts - pts.mean(axis=0)) @ tangents.T
    k = scale / B
    if len(tangents) == 1:
        return k * 0.5 * u ** 2
    return k * np.stack([0.5 * u[:, 0] ** 2, u[:, 0] * u[:, 1] / math.sqrt(2.0),
                         0.5 * u[:, 1] ** 2], axis=1)


def lying_flat(fit: FitResult, readings: Readings, contacts: IntArray, tol: float, B: float
               ) -> NDArray[np.bool_]:
    """Which of ``contacts`` leave their point of touch open along a link lying flat on the
    flat primitive ``fit``: a side reading of theirs (any candidate link) whose axis stays
    within ``tol`` of touching it (clearance ``|sd - radius| <= tol``, linear along the axis)
    over more than ``2 sqrt(2 B tol)``, the chord over which a surface curved at radius ``B``
    stays within ``tol`` of its tangent: the link could then touch such a surface anywhere
    along that stretch.  All False for a curved type."""
    out = np.zeros(len(contacts), dtype=bool)
    if not MODELS[fit.kind].linear or fit.primitive is None or len(contacts) == 0:
        return out
    rows = np.flatnonzero(np.isin(readings.contact, contacts) & ~readings.sphere)
    if len(rows) == 0:
        return out
    prim = fit.primitive
    a, b, w = readings.a[rows], readings.b[rows], readings.radius[rows]
    ca = np.asarray(prim.signed_distance(a)) - w
    cb = np.asarray(prim.signed_distance(b)) - w
    # the fraction of the axis where |ca + s (cb - ca)| <= tol
    slope = cb - ca
    with np.errstate(divide="ignore", invalid="ignore"):
        s1, s2 = (-tol - ca) / slope, (tol - ca) / slope
    lo = np.where(slope == 0, np.where(np.abs(ca) <= tol, 0.0, 1.0), np.minimum(s1, s2))
    hi = np.where(slope == 0, np.where(np.abs(ca) <= tol, 1.0, 0.0), np.maximum(s1, s2))
    span = np.clip(np.minimum(hi, 1.0) - np.maximum(lo, 0.0), 0.0, None)
    flat = span * np.linalg.norm(b - a, axis=1) > 2.0 * math.sqrt(2.0 * B * tol)
    return np.isin(contacts, readings.contact[rows[flat]])


def influence(fit: FitResult, data: FitData, residual: ArrayLike) -> np.ndarray:
    """Cook's distance of each row of ``data`` (tips first; ``residual`` in that order): how
    far leaving that contact out would move ``fit``, in units of the fit's own uncertainty,
    ``r_i^2 / (p s^2) * h_ii / (1 - h_ii)^2`` with ``h_ii`` the contact's leverage on the
    type's minimal parameterisation.  A fit bent towards one contact fits that contact
    closely (a small residual) at a large leverage.  Zeros for degenerate data."""
    r = np.asarray(residual, dtype=float)
    touch = _touch_rows(fit, data)
    if touch is None:
        return np.zeros(len(r))
    rows, _, scale = touch
    n, p = rows.shape
    if n <= p:
        return np.zeros(n)
    lev = np.einsum("ij,ij->i", rows @ np.linalg.pinv(rows.T @ rows), rows)
    z = r / scale
    s2 = float(z @ z) / (n - p)
    if s2 <= 0:
        return np.zeros(n)
    return z * z / (p * s2) * lev / np.clip(1.0 - lev, 1e-12, None) ** 2


def added_cost(fit: FitResult, data: FitData, new: int) -> float:
    """The least-squares cost ``sum r^2`` [m^2] that a refit of ``fit`` is predicted to reach
    with row ``new`` of ``data`` (tips first) added to the others, which ``fit`` was fitted
    to: theirs plus ``r^2 / (1 + j (J^T J)^-1 j^T)``, the rise of a linear least-squares
    minimum when one observation with residual ``r`` and Jacobian row ``j`` joins (recursive
    least squares), linearised at ``fit`` on the type's minimal parameterisation.  Where the
    others do not determine ``fit`` (singular ``J^T J``) a new row could be absorbed along the
    free direction: the prediction is then their cost alone."""
    touch = _touch_rows(fit, data)
    r, _ = residuals_and_touch(fit.kind, fit.params, data, fit.free_side)
    r = np.asarray(r, dtype=float)
    others = float(np.sum(np.delete(r, new) ** 2))
    if touch is None:
        return others
    rows, _, _ = touch
    rest = np.delete(rows, new, axis=0)
    try:
        h = float(rows[new] @ np.linalg.solve(rest.T @ rest, rows[new]))
    except np.linalg.LinAlgError:
        return others
    return others + float(r[new]) ** 2 / (1.0 + max(h, 0.0))


def joining_residuals(fit: FitResult, data: FitData, joining: ArrayLike) -> np.ndarray:
    """For each row of ``data`` (tips first) flagged in ``joining``: its residual [m] under
    ``fit`` in units of the spread of that prediction, ``|r| / sqrt(1 + h)`` with ``h = j
    (J^T J)^+ j^T`` the row's leverage over the other rows (those ``fit`` was fitted to), on
    the type's minimal parameterisation, linearised at ``fit``.  A contact of the surface
    has it at the noise level, however far the fit's uncertainty (up a post touched on one
    side, around it) puts the contact from ``fit``; its square is the cost a refit with the
    contact alone added is predicted to rise by (:func:`added_cost`).  A direction the other
    rows leave free gives no room (the pseudo-inverse): a contact that moves the fit along it
    is left to the refit."""
    join = np.asarray(joining, dtype=bool)
    r, _ = residuals_and_touch(fit.kind, fit.params, data, fit.free_side)
    r = np.abs(np.asarray(r, dtype=float)[join])
    touch = _touch_rows(fit, data)
    if touch is None:
        return r
    rows = touch[0]
    rest = rows[~join]
    h = np.einsum("ij,jk,ik->i", rows[join], np.linalg.pinv(rest.T @ rest), rows[join])
    return r / np.sqrt(1.0 + np.maximum(h, 0.0))


def report_gate(fit: FitResult, data: FitData, sigma_kin: float, max_rel_std: float,
                B: float | None = None, open_touch: ArrayLike | None = None,
                evidence: float | None = None) -> GateResult:
    """Whether ``fit`` (on ``data``) may be reported: see the module docstring (the type test
    of a flat primitive needs ``B``; None skips it).  ``open_touch``: per row of ``data``
    (tips first, then links), contacts whose point of touch is open along a link lying flat
    (:func:`lying_flat`), left out of the type test.  ``evidence``: the primitive's
    description-length gain without its most valuable contact, in nats
    (:meth:`wholearm_tools.fit.infer.Scorer.evidence_without_best`; None skips the test)."""
    m = MODELS[fit.kind]
    touch = _touch_rows(fit, data)
    rows, pts, scale = touch if touch is not None else (np.zeros((0, m.dof)), None, 0.0)
    n, dof = rows.shape
    if n <= dof + 1 or scale <= 0:
        return GateResult(math.inf, math.inf, -1,
                          f"{n} contacts cannot determine its {dof} parameters" if n <= dof
                          else f"its {n} contacts, less any one, only just determine its {dof} "
                          "parameters: a contact read the wrong way would not show")
    s = sigma_kin / scale
    H = rows.T @ rows

    def worst(h: np.ndarray) -> float:
        lam = np.linalg.eigvalsh(h)[0]
        return s / math.sqrt(lam) if lam > 0 else math.inf

    w_all = worst(H)
    if not w_all <= max_rel_std:
        return GateResult(w_all, math.inf, -1,
                          "its contacts do not determine every parameter (worst combination "
                          f"{_fmt(w_all)} of its support's size at kinematic errors of "
                          f"{sigma_kin * 1e3:.2g} mm)")
    loo = [worst(H - np.outer(r, r)) for r in rows]
    i = int(np.argmax(loo))
    if not loo[i] <= max_rel_std:
        return GateResult(w_all, loo[i], i,
                          "one of its contacts alone determines it: without it, the worst "
                          f"parameter combination is {_fmt(loo[i])} of its support's size")
    if evidence is not None and not evidence > 0:
        return GateResult(w_all, loo[i], -1,
                          "one of its contacts carries its evidence: without it, the others "
                          f"would fall {-evidence:.1f} nats short of paying for its {dof} "
                          "parameters")
    if B and m.linear:
        curv = _curvature_rows(fit, pts, scale, B)
        if open_touch is not None:
            curv[np.asarray(open_touch, dtype=bool)] = 0.0
        full = np.hstack([rows, curv])

        def worst_curvature(h: np.ndarray) -> float:
            # the curvature block's Schur complement: its information with the flat
            # parameters free
            hff, hfc, hcc = h[:dof, :dof], h[:dof, dof:], h[dof:, dof:]
            try:
                return worst(hcc - hfc.T @ np.linalg.solve(hff, hfc))
            except np.linalg.LinAlgError:
                return math.inf

        Hf = full.T @ full
        c = max(worst_curvature(Hf), *(worst_curvature(Hf - np.outer(r, r)) for r in full))
        if not c <= max_rel_std:
            return GateResult(w_all, loo[i], -1,
                              "its contacts do not tell it from a surface curved at radius B "
                              f"(curvature known to {_fmt(c)} of 1/B)")
    return GateResult(w_all, loo[i], -1, "")


def _fmt(x: float) -> str:
    return "unbounded" if not math.isfinite(x) else f"{x:.2g}"
