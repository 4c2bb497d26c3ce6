"""Robust fits with no start: a consensus start, the inliers' noise, the loss capped at an
outlier cost.

A robust loss only discounts outliers once the fit is near the inliers and its scale is the
inliers' noise: started from a least-squares fit that the outliers have already pulled away
(and whose residual spread they inflate), pseudo-Huber or Cauchy settle in the wrong place.
So :func:`consensus_start`

1. draws sets of ``dof + 1`` contacts and turns each into a hypothesis with the type's quick
   algebraic guess (:attr:`Model.quick_init`; for a cylinder the coarse-to-fine axis scan of
   :func:`wholearm_tools.fit.models._scan_axes`, which finds an axis from a partial arc where
   local normals and principal axes cannot).  One contact more than the degrees of freedom:
   a cylinder through five points is exactly determined and has several solutions, a nearly
   flat one among them;
2. scores each hypothesis by the ``h``-th smallest absolute residual of all contacts,
   ``h = (n + dof + 1) // 2`` (least median of squares: no tolerance in metres is needed,
   and up to half the contacts may be outliers), and stops sampling once a clean set has been
   drawn with probability :data:`CONFIDENCE` given the inlier share seen so far, and not before
   :data:`MIN_TRIALS` sets (the share is measured at the best hypothesis's own scale, which a
   wrong hypothesis inflates); when there are no more than :data:`MIN_TRIALS` sets, each is
   tried once;
3. takes as inliers the contacts within :data:`CUTOFF` robust standard deviations of the best
   hypothesis, the scale being the least-median one (``1.4826 (1 + 5 / (n - dof))`` times the
   score, Rousseeuw and Leroy 1987), so the tolerance comes from the data;
4. fits the inliers by least squares (from the hypothesis or the quick guess on all the
   inliers, whichever fits them better), re-estimates the noise on the inliers' residuals
   (``1.4826`` times their median absolute value) and re-selects the inliers at
   :data:`CUTOFF` of it, until the inlier set stops changing.

:func:`robust_fit` then minimises the robust loss, with its scale in units of that noise,
capped at the cost of an outlier (see there).  Residuals are weighted (``sqrt(W_i) r_i``), as
in the fit.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wholearm_tools.fit.models import InitContext, Model

#: probability that at least one drawn set is outlier-free when sampling stops
CONFIDENCE = 0.999
#: inliers are within this many robust standard deviations of the fit
CUTOFF = 2.5
#: sets drawn at least and at most
MIN_TRIALS, MAX_TRIALS = 30, 300
#: rounds of inlier least squares / noise re-estimation / inlier re-selection at most
_ROUNDS = 6
#: smallest noise scale (normalised units): exact data still give a positive loss scale
_SIGMA_FLOOR = 1e-9


@dataclass(frozen=True)
class ConsensusStart:
    """Outcome of :func:`consensus_start` (normalised units, contacts in fit order).

    ``th``: least-squares fit of the inliers (raw parameters); ``inliers (n,)`` bool;
    ``sigma``: robust noise estimate on the inliers' weighted residuals; ``trials``: sets
    drawn.
    """

    th: np.ndarray
    inliers: np.ndarray
    sigma: float
    trials: int


def _take(nd: Any, keep: np.ndarray) -> Any:
    """The normalised data ``nd`` (``core._Norm``) restricted to contacts ``keep`` (bool)."""
    nt = len(nd.tip)
    kt, kl = keep[:nt], keep[nt:]
    return replace(nd, tip=nd.tip[kt], tip_w=nd.tip_w[kt], tip_wt=nd.tip_wt[kt], a=nd.a[kl],
                   b=nd.b[kl], link_w=nd.link_w[kl], link_wt=nd.link_wt[kl])


def _context(nd: Any, side: float) -> InitContext:
    return InitContext(nd.tip, nd.tip_w, nd.a, nd.b, nd.link_w, side)


def _guesses(m: Model, ctx: InitContext) -> list[np.ndarray]:
    """The type's quick algebraic guesses (finite ones) from the contacts of ``ctx``."""
    try:
        cands = m.quick_init(ctx) if m.quick_init else m.init(ctx)[:1]
    except (np.linalg.LinAlgError, ValueError, IndexError):
        return []
    return [c for c in cands if np.all(np.isfinite(c))]


def _abs_z(m: Model, th: np.ndarray, side: float, nd: Any) -> np.ndarray:
    """Absolute weighted residuals ``|sqrt(W) r|`` of every contact of ``nd`` under ``th``."""
    from wholearm_tools.fit.core import _link_t  # (core imports this module)
    from wholearm_tools.fit.models import signed_distance_np

    rt = (side * signed_distance_np(m, th, nd.tip) - nd.tip_w if len(nd.tip) else np.zeros(0))
    rl = _link_t(m, th, side, nd.a, nd.b)[0] - nd.link_w if len(nd.a) else np.zeros(0)
    return np.abs(np.sqrt(np.concatenate([nd.tip_wt, nd.link_wt]))
                  * np.concatenate([rt, rl]))


def consensus_start(m: Model, nd: Any, side: float, rng: np.random.Generator,
                    max_iter: int = 200) -> ConsensusStart | None:
    """Consensus start for a robust fit of type ``m`` to normalised data ``nd`` on free side
    ``side`` (steps 1-4 of the module docstring); None when there are too few contacts to
    sample (fewer than ``dof + 2``) or no hypothesis could be formed."""
    from wholearm_tools.fit.core import _solve_fast  # (core imports this module)

    n = len(nd.tip) + len(nd.a)
    p = m.dof
    size = p + 1
    if n < size + 1:
        return None
    h = (n + p + 1) // 2
    correction = 1.4826 * (1.0 + 5.0 / (n - p))
    best_score, best_th = math.inf, None
    # few contacts: every set once, in order (random draws would repeat sets)
    every = (iter(itertools.combinations(range(n), size))
             if math.comb(n, size) <= MIN_TRIALS else None)
    needed, trials = MAX_TRIALS, 0
    while trials < max(MIN_TRIALS, min(needed, MAX_TRIALS)):
        chosen = next(every, None) if every is not None else rng.choice(n, size, replace=False)
        if chosen is None:
            break
        trials += 1
        pick = np.zeros(n, dtype=bool)
        pick[list(chosen)] = True
        for th in _guesses(m, _context(_take(nd, pick), side)):
            z = _abs_z(m, th, side, nd)
            score = float(np.partition(z, h - 1)[h - 1])
            if not score < best_score:
                continue
            best_score, best_th = score, th
            share = float(np.mean(z <= CUTOFF * correction * score))
            miss = 1.0 - share ** size
            needed = (MIN_TRIALS if miss <= 0.0 else
                      math.ceil(math.log(1.0 - CONFIDENCE) / math.log(miss)) if miss < 1.0
                      else MAX_TRIALS)
    if best_th is None:
        return None

    th = best_th
    sigma = max(correction * best_score, _SIGMA_FLOOR)
    inl = _abs_z(m, th, side, nd) <= CUTOFF * sigma
    for rnd in range(_ROUNDS):
        if int(inl.sum()) < p + 1:
            break
        sub = _take(nd, inl)
        start = th
        if rnd == 0:  # the hypothesis or the quick guess on all its inliers, then warm
            starts = [th, *_guesses(m, _context(sub, side))]
            start = min(starts, key=lambda c: float(np.sum(_abs_z(m, c, side, sub) ** 2)))
        sol = _solve_fast(m, sub, start, side, "linear", 1.0, max_iter)
        if not sol.success:
            break
        th = sol.th
        z = _abs_z(m, th, side, nd)
        sigma = max(1.4826 * float(np.median(z[inl])), _SIGMA_FLOOR)
        new = z <= CUTOFF * sigma
        if np.array_equal(new, inl):
            break
        inl = new
    return ConsensusStart(np.asarray(th, dtype=float), inl, float(sigma), trials)


@dataclass(frozen=True)
class RobustFit:
    """Outcome of :func:`robust_fit` (normalised units).

    ``th``: the fit; ``inliers (n,)``: the contacts read as inliers at the end (the others
    count at the outlier cost); ``sigma``: the noise scale; ``delta``: the loss scale;
    ``cost``: the capped objective; ``success``, ``status``, ``iterations``: of the solves.
    """

    th: np.ndarray
    inliers: np.ndarray
    sigma: float
    delta: float
    cost: float
    success: bool
    status: str
    iterations: int


def robust_fit(m: Model, nd: Any, side: float, loss: str, loss_scale: float,
               noise: float | None, rng: np.random.Generator, max_iter: int = 200
               ) -> RobustFit | None:
    """Robust fit of type ``m`` to normalised data ``nd`` with no start.

    From :func:`consensus_start`, minimises the robust loss ``rho`` (scale ``delta =
    loss_scale * sigma``, ``sigma`` the inliers' noise or the given ``noise``) capped at the
    outlier cost ``rho(CUTOFF sigma)``: each contact is read as an inlier (cost ``rho(z)``)
    or an outlier (the cap), whichever costs less.  Reading the contacts at fixed parameters
    and refitting the inliers at fixed readings each lower the capped sum, so the two
    alternate until the readings stop changing.  A loss that keeps growing with the residual
    (pseudo-Huber) lets every outlier pull with the force ``delta``: on a partial arc, where
    the radius is weakly determined, fifty of them move it by many noise levels; the cap
    removes that pull.  None when no consensus could be formed.
    """
    from wholearm_tools.fit.core import _solve_fast, rho_np  # (core imports this module)

    cs = consensus_start(m, nd, side, rng, max_iter)
    if cs is None:
        return None
    sigma = noise if noise is not None else cs.sigma
    delta = loss_scale * sigma
    cap = CUTOFF * sigma
    th, inl = cs.th, cs.inliers
    success, status, iterations = False, "not_run", 0
    for _ in range(_ROUNDS):
        if int(inl.sum()) < m.dof + 1:
            break
        sol = _solve_fast(m, _take(nd, inl), th, side, loss, delta, max_iter)
        iterations += sol.iterations
        if not sol.success:  # keep the last converged round, if any
            if not success:
                status = sol.status
            break
        success, status = True, sol.status
        th = sol.th
        new = _abs_z(m, th, side, nd) <= cap
        if np.array_equal(new, inl):
            break
        inl = new
    z = np.minimum(_abs_z(m, th, side, nd), cap)
    cost = float(np.sum(rho_np(z, loss, delta)))
    return RobustFit(np.asarray(th, dtype=float), inl, float(sigma), float(delta), cost,
                     success, status, iterations)
