"""Fit-and-grow segmentation (Leonardis, Gupta & Bajcsy 1995) of tip and link contacts.

1. **Seeds**: up to ``max_seeds`` seed contacts spread by farthest-point sampling (the first one
   drawn with ``rng``); each seed region is the seed's ``dof + 2`` nearest contacts for each
   type (small, so that a seed rarely straddles two surfaces) (link
   contacts are placed at their segment midpoints for neighbourhood purposes only; their
   residuals are always the true link residuals).
2. **Seed fits**: every allowed type (cheap ones first) is fitted to every seed region; a type is
   kept for a seed when its dof-corrected RMS residual is below ``seed_accept * sigma``.
3. **Noise level** ``sigma``: given, or the 10th percentile of the best dof-corrected seed RMS
   residuals divided by its expected value 0.325 sigma (seeds that straddle two surfaces fit
   badly, those inside one fit at the noise level), floored at ``noise_floor`` (the pipeline
   derives it from the encoder noise) and at ``1e-6`` of the scene size.
4. **Growth**: a hypothesis absorbs every contact connected to it (k-nearest-neighbour graph)
   through contacts whose residual is within ``k_sigma * sigma``; it is refitted (warm
   start) and grown again until its support stops changing; a refit whose RMS exceeds
   ``1.5 sigma`` (``sqrt(chi2)`` level) stops the growth.  Up to two more rounds seed among
   the contacts no hypothesis covers; there a 3-D seed that fits but does not determine its
   type (link contacts of one joint's sweep, all in one plane) takes further nearest contacts
   one at a time, refitted from the last solution, until it is determined (``extend_seeds``).
5. **Selection** by description length (in nats): a contact left unexplained costs
   ``log(extent / sigma)`` (its position coded at the noise precision), an explained one
   ``z^2 / 2`` (``z`` = residual / sigma) and a primitive ``dof / 2 * log(N)`` (BIC).
   Hypotheses are selected greedily by their saving in description length given those already
   selected, until no saving is positive, so a plane beats a huge sphere on planar data (same
   residuals, fewer parameters) and a second primitive on the same surface saves nothing.
   Only **admissible** hypotheses take part: radii within ``[min_radius, max_radius_ratio x
   support spread]`` (a circle shrinking onto the point where all its link contacts meet, or a
   huge sphere that is really a plane, is not a primitive) and a support that constrains every
   degree of freedom: the standard deviation of the worst-determined parameter combination
   (:attr:`FitResult.sensitivity` x ``sigma``, in units of the support's spread) must stay below
   ``max_rel_std`` (at noise ``max(sigma, id_noise x scene size)``, 1e-4 by default; 1e-3
   also rejects the weakly determined posts of paper_spatial, which then come out as planes).
   A circle or sphere whose inside is free space must hold the robot's ``base``: the arm
   reaches every contact from its base through free space, so it cannot be enclosed by a
   closed surface its base lies outside of (a ring of contacts in a bore fits a sphere as well
   as the bore's cylinder).  Link contacts that all touch
   at one point (every contact of the first link starts at the base), or tangent lines from one
   point to a circle, leave a direction free and are rejected here.
6. **Assignment**: sigma is re-estimated from every contact's smallest residual under the
   selected primitives, as the fixed point of the RMS of the residuals within ``k_sigma x
   sigma`` corrected for that truncation (a MAD of the gated residuals is biased low); while
   the best seeds fit at the encoder floor, sigma never exceeds ``FLOOR_CAP x noise_floor``
   (in the seed estimate too); every contact goes to the selected primitive with the
   smallest residual within ``k_sigma * sigma``; each primitive is refitted on its contacts;
   contacts explained by none are unexplained (``-1``).
"""

from __future__ import annotations

import contextlib
import math
import multiprocessing
from collections.abc import Callable, Iterator
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from wholearm_tools._parallel import available_cores, process_pool
from wholearm_tools.errors import InputError
from wholearm_tools.fit.core import (
    consensus,
    fit_primitive,
    free_space_violation,
    residuals,
    sweep_tolerance,
    sweep_violation,
)
from wholearm_tools.fit.crossing import MIN_CUTS, SOLIDS, crossed_between, cut_feet
from wholearm_tools.fit.data import FitData, Sweep
from wholearm_tools.fit.models import MODELS
from wholearm_tools.fit.result import FitResult

#: radius-like parameters checked against ``min_radius`` / ``max_radius_ratio``
RADII = {"circle": ("radius",), "sphere": ("radius",), "cylinder": ("radius",),
         "torus": ("minor_radius", "major_radius")}

#: default candidate types per dimension, cheapest first
DEFAULT_KINDS = {2: ("line", "circle"), 3: ("plane", "sphere", "cylinder", "cone", "torus")}


@dataclass(frozen=True, slots=True)
class Segmentation:
    """Result of :func:`segment`.

    Attributes
    ----------
    primitives : tuple[FitResult, ...]
        The selected primitives, each fitted on its own contacts.
    assignment : (N,) int
        Index into :attr:`primitives` of each contact (tips first, then links); -1 unexplained.
    noise : float
        The noise level sigma used (metres).
    description_length : float
        Total description length of the selected model (nats).
    """

    primitives: tuple[FitResult, ...]
    assignment: np.ndarray
    noise: float
    description_length: float
    #: scene size (metres) and ``max_rel_std`` used for identifiability (see :func:`segment`)
    extent: float = 0.0
    max_rel_std: float = math.inf

    def determined(self, fit: FitResult, id_noise: float, scale: float | None = None) -> bool:
        """Whether every parameter of ``fit`` is determined by its contacts at noise
        ``max(noise, id_noise x scale)`` (the identifiability rule of :func:`segment`; ``scale``
        defaults to the scene size)."""
        sigma_id = max(self.noise, id_noise * (self.extent if scale is None else scale))
        return bool(fit.sensitivity * sigma_id <= self.max_rel_std)

    def __post_init__(self) -> None:
        self.assignment.flags.writeable = False

    @property
    def unexplained(self) -> np.ndarray:
        """Contact indices explained by no primitive."""
        return np.flatnonzero(self.assignment < 0)

    def members(self, k: int) -> np.ndarray:
        """Contact indices assigned to primitive ``k``."""
        return np.flatnonzero(self.assignment == k)


@dataclass
class _Hyp:
    kind: str
    fit: FitResult
    members: np.ndarray  # sorted contact indices


def rms_dof(fit: FitResult) -> float:
    """Dof-corrected RMS residual of ``fit``: sqrt(sum r^2 / (n - dof)), n - dof at least 1."""
    r = fit.residuals
    dof = MODELS[fit.kind].dof
    return float(np.sqrt(np.sum(r * r) / max(len(r) - dof, 1)))


def _noise_estimate(best: np.ndarray, calibrated: bool) -> float:
    """Noise level from the best dof-corrected RMS of each seed, ``(K,)``.

    A seed of ``dof + 2`` contacts inside one surface has RMS ``sigma * sqrt(chi2_2 / 2)``:
    its 10th percentile is ``0.325 sigma`` and the best of K seeds sits near the 1/K quantile
    ``sqrt(-ln(1 - 1/K)) sigma``.  Both estimates agree within a small factor when the seeds
    are clean; when most seeds straddle two surfaces (next to a junction) the percentile
    measures the mismatch, and the best seed is used instead (the second look after selection
    raises an estimate that is too low)."""
    if best.size == 0:
        return 0.0
    if not calibrated:
        return float(np.percentile(best, 10))
    pct = float(np.percentile(best, 10)) / 0.325
    low = float(np.min(best)) / math.sqrt(-math.log(1.0 - 1.0 / max(best.size, 2)))
    return pct if pct <= 3.0 * low else low


#: noise estimates never exceed this multiple of the encoder floor while the best seeds fit at
#: (twice) the floor: a few mixed seeds next to a junction must not widen the tolerances until
#: one bore's hypothesis swallows the other's contacts
FLOOR_CAP = 2.5


def _floor_cap(noise_floor: float, low: float) -> float:
    """Upper bound of sigma: ``FLOOR_CAP x noise_floor`` when the best-seed estimate ``low``
    is within twice the floor, else none."""
    if noise_floor > 0 and low <= 2.0 * noise_floor:
        return FLOOR_CAP * noise_floor
    return math.inf


def _truncated_sigma(r: np.ndarray, start: float, k: float, rounds: int = 30) -> float:
    """Noise level from residuals ``r`` of which only those within ``k sigma`` are inliers:
    the fixed point of ``sigma = rms(r[|r| <= k sigma]) / sqrt(c(k))``, where ``c(k)`` is the
    variance ratio of a normal truncated at ``k`` (so the gate does not bias the estimate low,
    as a MAD of the gated residuals does).  Starts at ``start``; contacts of other surfaces,
    far outside the gate, do not count."""
    r = np.abs(np.asarray(r, dtype=float))
    r = r[np.isfinite(r)]
    if r.size == 0 or not start > 0:
        return float(start)
    phi = math.exp(-0.5 * k * k) / math.sqrt(2 * math.pi)
    mass = math.erf(k / math.sqrt(2))
    ratio = 1.0 - 2.0 * k * phi / mass
    s = float(start)
    for _ in range(rounds):
        inl = r[r <= k * s]
        if inl.size < 3:
            break
        nxt = math.sqrt(float(np.mean(inl * inl)) / ratio)
        if not nxt > 0:
            break
        if abs(nxt - s) <= 1e-6 * s:
            s = nxt
            break
        s = nxt
    return s


def _best_seed_sigma(best: np.ndarray) -> float:
    """Noise level implied by the best seed alone (its RMS sits near the ``1/K`` quantile)."""
    if best.size == 0:
        return math.inf
    return float(np.min(best)) / math.sqrt(-math.log(1.0 - 1.0 / max(best.size, 2)))


def _farthest_points(X: np.ndarray, k: int, rng: np.random.Generator) -> list[int]:
    n = len(X)
    first = int(rng.integers(n))
    order = [first]
    dmin = np.linalg.norm(X - X[first], axis=1)
    while len(order) < min(k, n):
        i = int(np.argmax(dmin))
        if dmin[i] <= 0:
            break
        order.append(i)
        dmin = np.minimum(dmin, np.linalg.norm(X - X[i], axis=1))
    return order


@contextlib.contextmanager
def seed_pool(workers: int | None = None) -> Iterator[Executor | None]:
    """A process pool for :func:`segment`'s seed fits, shut down on exit; ``None`` (fit in this
    process) for one worker or inside a daemonic process (a Dask or multiprocessing worker,
    which may not start children).

    ``workers`` None: every core this process may use, at most 8, or one in a process that is
    itself a worker of a pool (``wholearm compare`` runs one reconstruction per core already).
    Workers are forked where the platform can (they start in milliseconds, with the CasADi
    solvers already built), else spawned."""
    if workers is None:
        nested = multiprocessing.parent_process() is not None
        n = 1 if nested else min(available_cores(), 8)
    else:
        n = int(workers)
    if n < 1:
        raise InputError(f"workers must be at least 1, got {workers!r}")
    if n == 1 or multiprocessing.current_process().daemon:
        yield None
        return
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("fork" if "fork" in methods else None)
    with process_pool(n, mp_context=ctx) as pool:  # workers ignore Ctrl-C; stopped on error
        yield pool


@dataclass(frozen=True)
class _SeedConfig:
    """What every seed fit of one :func:`segment` pass shares (picklable: seed fits may run in
    worker processes)."""

    sizes: dict[str, int]
    cheap: tuple[str, ...]
    costly: tuple[str, ...]
    trim_ok: bool
    sigma: float
    accept: float
    max_iter: int
    ransac_tol: float
    key: int
    extend: int = 0
    max_sensitivity: float = math.inf


@dataclass(frozen=True)
class _SeedJob:
    """One seed: its contact, its nearest contacts (global indices, nearest first) and their
    fit data (the contacts of ``near`` in ascending index order)."""

    seed: int
    trim: int
    near: np.ndarray
    data: FitData


def _seed_job(s: int, trim: int, order: np.ndarray, data: FitData, cfg: _SeedConfig) -> _SeedJob:
    near = order[s, :max(cfg.sizes.values()) + trim + (cfg.extend if trim else 0)]
    return _SeedJob(s, trim, near, data.take(near))


def _fit_seed(cfg: _SeedConfig, job: _SeedJob) -> list[tuple[str, np.ndarray, FitResult]]:
    """Every cheap type fitted at one seed, and the costly ones where no cheap type fits in the
    consensus pass (``trim`` > 0): ``(kind, members, fit)`` with global member indices.

    Each type is fitted to the ``dof + 2`` contacts nearest the seed; in the consensus pass the
    neighbourhood starts ``trim`` contacts larger, is cut to the RANSAC consensus of the type
    and then loses its worst-fitting contact (never the seed) while the fit is poor: near the
    intersection of two surfaces the nearest contacts mix both.  The random draws come from a
    generator seeded by ``(cfg.key, seed, trim)``, so the result does not depend on which
    process fits which seed, nor in which order."""
    rng = np.random.default_rng([cfg.key, job.seed, job.trim])
    glob = np.sort(job.near)

    def take(members: np.ndarray) -> FitData:
        return job.data.take(np.searchsorted(glob, members))

    def one(kind: str, trim: int) -> tuple[np.ndarray, FitResult]:
        size = cfg.sizes[kind]
        members = np.sort(job.near[:size])
        if trim and cfg.trim_ok:
            nb = np.sort(job.near[:size + trim])
            inl = consensus(kind, take(nb), int(np.flatnonzero(nb == job.seed)[0]),
                            cfg.ransac_tol, rng)
            if len(inl) >= size:
                members = nb[inl]
        if len(members) <= MODELS[kind].dof:
            return members, fit_primitive(kind, take(members[:0]))
        # (the cheap types only: a cone or torus cut off at a seed rarely gets there)
        good = (cfg.accept * cfg.sigma if math.isfinite(cfg.sigma) and kind in cfg.cheap
                else None)
        f = fit_primitive(kind, take(members), max_iter=cfg.max_iter, good_rms=good)
        while (cfg.trim_ok and len(members) > size and f
               and rms_dof(f) > cfg.accept * cfg.sigma):
            r = np.abs(f.residuals)
            r[members == job.seed] = -1.0
            keep = np.delete(members, int(np.argmax(r)))
            g = fit_primitive(kind, take(keep), max_iter=cfg.max_iter,
                              free_side=f.free_side, initial=f.params)
            if not g:
                g = fit_primitive(kind, take(keep), max_iter=cfg.max_iter)
            if not g:
                break
            members, f = keep, g
        if cfg.trim_ok and trim and f and f.sensitivity > cfg.max_sensitivity:
            members, f = extend(kind, members, f)
        return members, f

    def extend(kind: str, members: np.ndarray, f: FitResult) -> tuple[np.ndarray, FitResult]:
        # a seed that fits but does not determine its primitive (link contacts of one joint's
        # sweep: every tangent line in one plane, a family of cylinders fits them) takes the
        # next nearest contacts one at a time, each refit from the last solution, while the
        # fit stays good, until they determine it: refitting from a member of the family moves
        # along it to the one the new contact also touches, where a fresh fit to the larger
        # neighbourhood falls into another minimum
        if rms_dof(f) > cfg.accept * cfg.sigma:
            return members, f
        for c in job.near[cfg.sizes[kind] + job.trim:]:
            if c in members:
                continue
            cand = np.sort(np.append(members, c))
            g = fit_primitive(kind, take(cand), max_iter=cfg.max_iter, free_side=f.free_side,
                              initial=f.params)
            if g and rms_dof(g) <= 1.5 * cfg.sigma:
                members, f = cand, g
                if f.sensitivity <= cfg.max_sensitivity:
                    break
        return members, f

    fits = [(k, *one(k, job.trim)) for k in cfg.cheap]
    # (only in the consensus pass: before it, most seeds next to an intersection straddle two
    # surfaces, and a torus fits almost any such small mix)
    if cfg.costly and job.trim and not any(f and rms_dof(f) <= cfg.accept * cfg.sigma
                                           for _, _, f in fits):
        fits += [(k, *one(k, 0)) for k in cfg.costly]
    return fits


def complete_support(fit: FitResult, members: np.ndarray, data: FitData,
                     candidates: np.ndarray, sigma: float, reach: float = 0.02,
                     starts: int = 8, min_new: int = 2, outlier_tol: float | None = None,
                     ) -> tuple[FitResult, np.ndarray]:
    """``fit`` (on the contacts ``members`` of ``data``) grown by those of ``candidates`` that
    one refit explains with it.  Returns the fit and its members, unchanged unless at least
    ``min_new`` contacts join.

    A fit its contacts do not determine can be bent to pass through any one more contact, so
    the first one taken decides where it goes: each of the ``starts`` candidates nearest to it
    (within ``reach`` metres) is tried as the first, then the others join nearest first while
    the refit's dof-corrected RMS residual stays at most 1.5 ``sigma`` (the chi-square level;
    it stops when none of the three nearest left joins); the start that gathers the most
    contacts wins (then the lowest RMS).

    Growth takes the contacts within a few sigma of a hypothesis.  One that its contacts do
    not determine - link bodies touching a post along one side - predicts the rest of its
    surface millimetres off, so it never reaches the contacts that would determine it: on
    paper_spatial (seed 0) a post r 0.06 m was fitted from nine link contacts 3 mm and 0.7 mm
    from the truth, too weakly determined to report, while the post's tips and joint contacts
    on its other side stayed unexplained.

    Bent that far, the fit can also pass through a wrong contact: a member (taken or its own)
    that the refit without it leaves more than ``outlier_tol`` metres (default 5 ``sigma``)
    off is dropped again (:func:`drop_bending`).  On paper_spatial (seed 1, 240 s, tip
    probes) a body contact used as a tip, 1.3 mm off post 2, had bent it to a radius 16 % too
    large."""
    cand = np.asarray(candidates, dtype=np.int64)
    if cand.size == 0:
        return fit, members
    r = np.abs(residuals(fit.kind, fit.params, data.take(cand), fit.free_side))
    cand = cand[r <= reach][np.argsort(r[r <= reach])]

    def refit(f: FitResult, idx: np.ndarray) -> FitResult | None:
        out = fit_primitive(f.kind, data.take(idx), free_side=f.free_side,
                            initial=dict(f.params))
        return out if out and rms_dof(out) <= 1.5 * sigma else None

    def gather(f: FitResult, m: np.ndarray, left: np.ndarray) -> tuple[FitResult, np.ndarray]:
        while left.size:
            rl = np.abs(residuals(f.kind, f.params, data.take(left), f.free_side))
            for c in left[np.argsort(rl)][:3]:  # the nearest few: farther ones fit worse
                g = refit(f, np.union1d(m, [c]))
                if g is not None:
                    f, m = g, np.union1d(m, [c])
                    left = left[left != c]
                    break
            else:
                break
        return f, m

    best_fit, best_members = fit, members
    for first in cand[:starts]:
        m = np.union1d(members, [first])
        f = refit(fit, m)
        if f is None:
            continue
        f, m = gather(f, m, cand[cand != first])
        if len(m) > len(best_members) or (len(m) == len(best_members) and best_fit is not fit
                                         and rms_dof(f) < rms_dof(best_fit)):
            best_fit, best_members = f, m
    if len(best_members) - len(members) < min_new:
        return fit, members
    f, m = best_fit, best_members
    taken = m
    tol = 5.0 * sigma if outlier_tol is None else outlier_tol
    while True:
        f_out, m_out = drop_bending(f, m, data, tol)
        if len(m_out) == len(m):
            break
        # the fit without them is another one: it may take contacts the bent one could not
        # (each contact is taken once at most, so this ends)
        f, m = gather(f_out, m_out, cand[~np.isin(cand, taken)])
        taken = np.union1d(taken, m)
    if len(m) - len(members) < min_new:
        return fit, members
    return f, m


def drop_bending(fit: FitResult, members: np.ndarray, data: FitData, tol: float,
                 min_keep: int | None = None) -> tuple[FitResult, np.ndarray]:
    """``fit`` without the members that bend it: the refit without such a member leaves it
    more than ``tol`` off (its deletion residual) and explains the others at least twice as
    well (dof-corrected RMS).  The worst goes first, one at a time, while more than
    ``min_keep`` (default ``dof + 2``) remain.

    A fit its contacts barely determine bends to pass through a wrong contact as well (a body
    contact taken as a tip): its residual there is small, but the fit without it is the
    surface, and leaves it far off.  (A contact that only determines the fit - without it the
    refit drifts along a family of solutions - also has a large deletion residual, but the
    others fit no better without it.)"""
    keep_at_least = MODELS[fit.kind].dof + 2 if min_keep is None else min_keep
    while len(members) > keep_at_least:
        worst, worst_r, worst_fit = -1, tol, None
        for i, g in _without_each(fit, members, data):
            if not g or rms_dof(g) > 0.5 * rms_dof(fit):
                continue  # (the others do not agree any better without it)
            r = abs(float(residuals(fit.kind, g.params, data.take(members[i:i + 1]),
                                    fit.free_side)[0]))
            if r > worst_r:
                worst, worst_r, worst_fit = i, r, g
        if worst_fit is None:
            break
        fit, members = worst_fit, np.delete(members, worst)
    return fit, members


def pinning_contact(fit: FitResult, members: np.ndarray, data: FitData,
                    determined: Callable[[FitResult], bool]) -> int | None:
    """Position in ``members`` of a contact without which ``fit`` is no longer
    ``determined`` (None: no single contact pins it).

    Every contact's class (tip or link body) and link are inferred, never measured, so a fit
    that only one contact determines rests on one inference: if that contact is wrong, its
    residuals cannot show it (the others leave that direction free) and the fit is confidently
    wrong."""
    for i, g in _without_each(fit, members, data):
        if not g or not determined(g):
            return i
    return None


def _without_each(fit: FitResult, members: np.ndarray, data: FitData
                  ) -> Iterator[tuple[int, FitResult]]:
    """``(i, refit)`` of ``fit`` on ``members`` without ``members[i]``, for each ``i`` (warm
    start from ``fit``, computed as they are asked for)."""
    for i in range(len(members)):
        yield i, fit_primitive(fit.kind, data.take(np.delete(members, i)),
                               free_side=fit.free_side, initial=dict(fit.params))


def segment(
    data: FitData,
    kinds: tuple[str, ...] | list[str] | None = None,
    *,
    noise: float | None = None,
    k_sigma: float = 3.0,
    seed_size: int | None = None,
    max_seeds: int = 16,
    neighbours: int = 6,
    min_support: int | None = None,
    seed_accept: float = 2.5,
    seed_max_iter: int = 30,
    trim_extra: int = 7,
    extend_seeds: int = 12,
    noise_floor: float = 0.0,
    min_radius: float = 0.0,
    max_radius_ratio: float = 50.0,
    max_rel_std: float = 0.2,
    id_noise: float = 1e-4,
    max_free_violation: float = 0.25,
    sweep: Sweep | None = None,
    sweep_near: float = 0.015,
    base: ArrayLike | None = None,
    rng: int | np.random.Generator | None = 0,
    executor: Executor | None = None,
) -> Segmentation:
    """Segment contacts into primitives by fit-and-grow with description-length selection.

    Parameters
    ----------
    data : FitData
        All contacts (tips and links) with weights and free-space hints.
    kinds : sequence of str or None
        Candidate types, cheapest first; default line, circle (2-D) or plane, sphere, cylinder,
        cone, torus (3-D).
    noise : float or None
        Residual noise level sigma (metres); None estimates it from the seed fits.
    k_sigma : float
        Growth/assignment threshold in units of sigma, on the residuals themselves: a contact
        is explained or it is not, whatever its classification weight (the weights act in the
        fits; inflating the tolerance of uncertain contacts let whole other surfaces in).
    seed_size : int or None
        Contacts per seed region; default ``dof + 2`` of each type.
    max_seeds : int
        Number of seed regions.
    trim_extra : int
        Seeds that fit poorly start this many contacts larger and drop their worst contact
        until they fit or reach the seed size (mixed neighbourhoods next to an intersection).
    extend_seeds : int
        A 3-D seed of the later rounds (among contacts no hypothesis covers) that fits well
        but does not determine its primitive tries
        up to this many further nearest contacts, one at a time, each refitted from the last
        solution and kept while the fit stays good, until it is determined.
    neighbours : int
        Neighbours per contact in the adjacency graph used for growth.
    min_support : int or None
        Fewest contacts a reported primitive may have; default ``dof + 2`` of its type (two
        redundant contacts; description length decides beyond that).
    noise_floor : float
        Smallest noise level (metres) the estimate may take (measurement resolution).
    min_radius : float
        Smallest admissible radius (metres) of circles, spheres, cylinders and tori (the
        pipeline passes ``B / 2``: B is the smallest expected curvature radius).
    max_radius_ratio : float
        Largest admissible radius in units of the support's RMS spread.
    max_rel_std : float
        Largest standard deviation of the worst-determined parameter combination, in units of
        the support's spread, at noise ``max(sigma, id_noise x scene size)``.
    id_noise : float
        See ``max_rel_std``.
    max_free_violation : float
        Largest fraction of the free-space hints next to a primitive's contacts that may lie on
        its occupied side (see :func:`~wholearm_tools.fit.core.free_space_violation`).
    sweep : Sweep or None
        The robot's capsules over the run.  A primitive that the sweep cuts into (deeper than
        ``max(5 sigma, 2 mm)``) within ``sweep_near`` metres of its own contacts, more than
        twice and in more than 1 % of the capsules checked, next to more than 15 % of those
        contacts or between them, is not admissible: the robot was there, so no surface is
        (see :class:`~wholearm_tools.fit.core.SweepCheck`; a true surface is cut only past the
        edge of its support, through a junction's window).
    sweep_near : float
        See ``sweep``.
    base : (d,) point or None
        The robot's base; see ``max_rel_std``.
    rng : seed or Generator
        Picks the first seed; the result is deterministic for a given seed.
    executor : concurrent.futures.Executor or None
        Runs the seed fits (most of the time of a segmentation), e.g. a process pool from
        :func:`seed_pool`; None fits them here.  The result does not depend on it.

    Returns
    -------
    Segmentation
    """
    if not isinstance(data, FitData):
        raise InputError(f"data must be a FitData, got {type(data).__name__}")
    kinds = tuple(DEFAULT_KINDS[data.dim] if kinds is None else kinds)
    for k in kinds:
        if k not in MODELS or MODELS[k].dim != data.dim:
            raise InputError(f"type {k!r} cannot be fitted to {data.dim}-D data")
    if not (k_sigma > 0 and max_seeds >= 1 and neighbours >= 1):
        raise InputError("k_sigma, max_seeds and neighbours must be positive")
    if noise is not None and not (noise > 0 and math.isfinite(noise)):
        raise InputError(f"noise must be positive, got {noise!r}")
    rng = np.random.default_rng(rng)
    n = data.n_contacts
    seed_sizes = {k: int(seed_size or MODELS[k].dof + 2) for k in kinds}
    empty = Segmentation((), np.full(n, -1), float(noise or 0.0), 0.0)
    if n < min(seed_sizes.values()):
        return empty

    X = data.contact_points()
    allpts = np.vstack([data.tip_points, data.link_a, data.link_b])
    extent = float(np.linalg.norm(allpts.max(axis=0) - allpts.min(axis=0)))
    D = np.linalg.norm(X[:, None, :] - X[None, :, :], axis=2)
    order = np.argsort(D, axis=1)
    adj = np.zeros((n, n), dtype=bool)
    rows = np.repeat(np.arange(n), min(neighbours, n - 1))
    adj[rows, order[:, 1:neighbours + 1].ravel()] = True
    adj |= adj.T

    def min_sup(kind: str) -> int:
        return int(min_support or MODELS[kind].dof + 2)

    # ---- seed fits
    # cheap types first; the costly ones (cone, torus) are tried at a seed only when no cheaper
    # type explains it (they fit almost anything small and are the slowest solves)
    cheap = tuple(k for k in kinds if MODELS[k].dof <= 5) or kinds
    costly = tuple(k for k in kinds if k not in cheap)

    def seeds_at(points: list[int], trim: int, extend: bool = False,
                 ) -> list[list[tuple[str, np.ndarray, FitResult]]]:
        cfg = _SeedConfig(seed_sizes, cheap, costly, trim_ok, float(sigma_seed), seed_accept,
                          seed_max_iter, ransac_tol, key, extend_seeds if extend else 0,
                          max_rel_std / sigma_id if trim_ok and extend else math.inf)
        jobs = [_seed_job(s, trim if trim_ok else 0, order, data, cfg) for s in points]
        if executor is None or len(jobs) < 2:
            return [_fit_seed(cfg, job) for job in jobs]
        return list(executor.map(_fit_seed, [cfg] * len(jobs), jobs))

    # first pass (untrimmed) gives the noise estimate
    trim_ok = False
    sigma_seed = np.inf
    seeds = _farthest_points(X, max_seeds, rng)
    key = int(rng.integers(2**63))  # each seed job draws from its own generator (see _fit_seed)
    ransac_tol = math.inf  # (no consensus before the noise level is known)
    seed_fits = seeds_at(seeds, 0)

    if noise is None:
        best = [min((rms_dof(f) for _, _, f in fits if f), default=np.inf)
                for fits in seed_fits]
        finite = np.array([b for b in best if np.isfinite(b)])
        # seeds have dof + 2 contacts: the dof-corrected RMS of a seed inside one surface is
        # sigma * sqrt(chi2_2 / 2), whose 10th percentile is sqrt(-ln 0.9) = 0.325 sigma (a low
        # quantile: in sparse scenes most seeds straddle two surfaces; the consensus pass
        # below lowers the estimate when nearly all of them do, as next to a junction)
        est = _noise_estimate(finite, seed_size is None)
        sigma_seed_low = _best_seed_sigma(finite)
        sigma = max(min(est, _floor_cap(noise_floor, sigma_seed_low)), float(noise_floor),
                    1e-6 * extent)
    else:
        sigma = float(noise)
        sigma_seed_low = math.inf
    sigma_id = max(sigma, id_noise * extent)
    sigma_seed = sigma
    base_pt = None if base is None else np.asarray(base, dtype=float).reshape(data.dim)
    trim_ok = True
    # inlier tolerance of the algebraic (RANSAC) seed guesses: well above the noise, well
    # below the misfit of a contact from another surface or with the wrong label
    ransac_tol = max(10.0 * k_sigma * sigma, 1e-3 * extent)

    def admissible(fit: FitResult, members: np.ndarray | None = None) -> bool:
        """Radii in range and every degree of freedom constrained by the support."""
        if not fit:
            return False
        for name in RADII.get(fit.kind, ()):
            r = float(fit.params[name])
            if r < min_radius or r > max_radius_ratio * fit.scale:
                return False
        if fit.sensitivity * sigma_id > max_rel_std:
            return False
        if (noise_floor > 0 and len(fit.link_residuals) >= len(fit.tip_residuals)
                and fit.n_contacts > MODELS[fit.kind].dof + 1
                and rms_dof(fit) < 1e-3 * noise_floor):
            # measured contacts carry encoder noise; link contacts fitted a thousand times
            # tighter are an identity of the kinematics (one link's axis always tangent to a
            # sphere about an inner joint), not a surface
            return False
        if 2 * int(np.sum(fit.link_t <= 1e-6)) > fit.n_contacts:
            # most of the support are link contacts touching at their inner end: that point
            # is the joint the link turns about, which does not move when the link turns, so
            # a contact there would have stopped the previous link, not this one (an artefact:
            # a line through the elbow positions of tangent link contacts)
            return False
        if (base_pt is not None and fit.kind in ("circle", "sphere") and fit.free_side < 0
                and fit.primitive is not None
                and float(fit.primitive.signed_distance(base_pt[None])[0]) > 0):
            return False
        if members is None:
            return True
        sub = data.take(members)
        if free_space_violation(fit.kind, fit.params, fit.free_side, sub) > max_free_violation:
            return False
        if sweep is None or fit.primitive is None:
            return True
        return _sweep_ok(fit, sub)

    def _sweep_ok(fit: FitResult, sub: FitData) -> bool:
        prim = fit.primitive
        pts = [sub.tip_points]
        if sub.n_link:
            _, t = prim.segment_signed_distance(sub.link_a, sub.link_b, free_side=fit.free_side)
            pts.append(sub.link_a + np.asarray(t)[:, None] * (sub.link_b - sub.link_a))
        support = np.asarray(prim.closest_point(np.vstack(pts)))
        tol = sweep_tolerance(sigma)
        if sweep_violation(prim, fit.free_side, support, sweep, near=sweep_near,
                           tol=tol).rules_out():
            return False
        if fit.kind in SOLIDS and fit.free_side > 0:
            # a post or ball the robot passed through where its contacts are: the contacts of
            # two surfaces (a post and the ball beside it) fit a huge sphere, which taking
            # their contacts would keep their own surfaces from being selected
            feet = cut_feet(prim, fit.free_side, sweep, tol)
            return crossed_between(fit.kind, fit.params, support, feet, need=0, min_span=0.0,
                                   min_cuts=MIN_CUTS, free_side=fit.free_side) is None
        return True

    def zres(kind: str, fit: FitResult) -> np.ndarray:
        return residuals(kind, fit.params, data, fit.free_side) / sigma

    def grow(kind: str, fit: FitResult, members: np.ndarray) -> _Hyp | None:
        for _ in range(25):
            z = np.abs(zres(kind, fit))
            inl = z <= k_sigma
            # connected component(s) of inliers touching the current members
            reach = np.zeros(n, dtype=bool)
            frontier = members[inl[members]]
            reach[frontier] = True
            while frontier.size:
                nxt = np.flatnonzero(adj[frontier].any(axis=0) & inl & ~reach)
                reach[nxt] = True
                frontier = nxt
            new = np.flatnonzero(reach)
            if np.array_equal(new, members) or new.size < MODELS[kind].dof + 1:
                break
            refit = fit_primitive(kind, data.take(new), free_side=fit.free_side,
                                  initial=fit.params)
            if not refit or rms_dof(refit) > 2.0 * sigma:
                break
            fit, members = refit, new
        if members.size < min_sup(kind) or not admissible(fit, members):
            return None
        return _Hyp(kind, fit, members)

    # ---- growth
    hyps: list[_Hyp] = []
    seen: set[tuple[str, bytes]] = set()
    covered = np.zeros(n, dtype=bool)

    def grow_all(seeds: list[int], seed_fits: list) -> None:
        for s, fits in zip(seeds, seed_fits, strict=True):
            if covered[s]:
                continue
            for kind, members, f in fits:
                if not f or rms_dof(f) > seed_accept * sigma:
                    continue
                h = grow(kind, f, members)
                if h is None:
                    continue
                key = (kind, h.members.tobytes())
                if key in seen:
                    continue
                seen.add(key)
                hyps.append(h)
                covered[h.members] = True

    # seeds the first pass could not use are refitted with trimming (mixed neighbourhoods)
    redo = [i for i, fits in enumerate(seed_fits)
            if not any(f and rms_dof(f) <= seed_accept * sigma for _, _, f in fits)]
    if redo:
        again = seeds_at([seeds[i] for i in redo], trim_extra)
        for i, fits in zip(redo, again, strict=True):
            seed_fits[i] = fits
        if noise is None:
            # the consensus seeds are often the only clean ones: lower the estimate to them
            best = [min((rms_dof(f) for _, _, f in fits if f), default=np.inf)
                    for fits in seed_fits]
            finite = np.array([b for b in best if np.isfinite(b)])
            if finite.size:
                sigma_seed_low = min(sigma_seed_low, _best_seed_sigma(finite))
                sigma = max(min(sigma, _noise_estimate(finite, seed_size is None),
                                _floor_cap(noise_floor, sigma_seed_low)),
                            float(noise_floor),
                            1e-6 * extent)
                sigma_id = max(sigma, id_noise * extent)
    grow_all(seeds, seed_fits)
    # second round: seeds among the contacts no hypothesis covers (a second surface whose
    # contacts the farthest-point seeds missed, e.g. a lateral branch next to a main bore)
    for _ in range(2):
        left = np.flatnonzero(~covered)
        if left.size < min(seed_sizes.values()):
            break
        extra = [int(left[i]) for i in _farthest_points(X[left], max_seeds // 2, rng)]
        n_before = len(hyps)
        # (3-D only: the contacts of a planar arm's link lie in the plane of the primitive,
        # no sweep plane leaves a family; extended circles of lab_sharp took the contacts
        # of a small line and then were too weakly determined to report)
        grow_all(extra, seeds_at(extra, trim_extra, extend=data.dim == 3))
        if len(hyps) == n_before:
            break

    # ---- selection by description length
    c_unexplained = math.log(max(extent / sigma, math.e))
    cur = np.full(n, c_unexplained)
    costs = []
    for h in hyps:
        z = zres(h.kind, h.fit)
        e = np.full(n, np.inf)
        e[h.members] = 0.5 * z[h.members] ** 2
        costs.append(e)
    chosen: list[int] = []
    while True:
        best_gain, best_k = 0.0, -1
        for k, h in enumerate(hyps):
            if k in chosen:
                continue
            gain = float(np.sum(np.maximum(cur - costs[k], 0.0)))
            gain -= 0.5 * MODELS[h.kind].dof * math.log(n)
            if gain > best_gain:
                best_gain, best_k = gain, k
        if best_k < 0:
            break
        chosen.append(best_k)
        cur = np.minimum(cur, costs[best_k])

    # ---- assignment, simplification, merging, final refits
    def dl(kind: str, fit: FitResult, members: np.ndarray) -> float:
        z = zres(kind, fit)[members]
        e = np.minimum(0.5 * z * z, c_unexplained)  # a contact costs at most "unexplained"
        return float(np.sum(e)) + 0.5 * MODELS[kind].dof * math.log(n)

    def refit_on(kind: str, idx: np.ndarray, prev: FitResult | None) -> FitResult:
        if prev is not None and prev.kind == kind:
            return fit_primitive(kind, data.take(idx), free_side=prev.free_side,
                                 initial=prev.params)
        return fit_primitive(kind, data.take(idx))

    def simplest(h: _Hyp) -> _Hyp:
        """A type with fewer parameters that codes the same contacts shorter replaces h."""
        best, best_dl = h, dl(h.kind, h.fit, h.members)
        for k in kinds:
            if MODELS[k].dof >= MODELS[h.kind].dof:
                continue
            f = refit_on(k, h.members, None)
            if admissible(f, h.members) and (d_ := dl(k, f, h.members)) <= best_dl:
                best, best_dl = _Hyp(k, f, h.members), d_
        return best

    final = [simplest(hyps[k]) for k in chosen]
    if noise is None and final:
        # second look at the noise level, before merging: the residuals of the contacts the
        # selected primitives explain (the seed estimate is biased low: best seed of several
        # types)
        R = np.min(np.stack([np.abs(residuals(h.kind, h.fit.params, data, h.fit.free_side))
                             for h in final]), axis=0)
        sigma = max(_truncated_sigma(R, sigma, k_sigma), float(noise_floor), 1e-6 * extent)
        sigma = min(sigma, _floor_cap(noise_floor, sigma_seed_low))
        sigma_id = max(sigma, id_noise * extent)
    merged = True
    while merged and len(final) > 1:  # two primitives where one explains the data -> one
        merged = False
        for i in range(len(final)):
            for j in range(i + 1, len(final)):
                hi_, hj = final[i], final[j]
                union = np.union1d(hi_.members, hj.members)
                base = dl(hi_.kind, hi_.fit, hi_.members) + dl(hj.kind, hj.fit, hj.members)
                for k in dict.fromkeys(sorted((hi_.kind, hj.kind), key=lambda k: MODELS[k].dof)):
                    prev = hi_.fit if hi_.kind == k else hj.fit
                    f = refit_on(k, union, prev)
                    if admissible(f, union) and dl(k, f, union) < base:
                        final = [h for m_, h in enumerate(final) if m_ not in (i, j)]
                        final.append(_Hyp(k, f, union))
                        merged = True
                        break
                if merged:
                    break
            if merged:
                break

    assignment = np.full(n, -1)
    for _ in range(2):
        if not final:
            break
        Z = np.stack([np.abs(zres(h.kind, h.fit)) for h in final])
        best_i = np.argmin(Z, axis=0)
        ok = Z[best_i, np.arange(n)] <= k_sigma
        assignment = np.where(ok, best_i, -1)
        kept = []
        for i, h in enumerate(final):
            idx = np.flatnonzero(assignment == i)
            if idx.size < min_sup(h.kind):
                continue
            refit = refit_on(h.kind, idx, h.fit)
            if admissible(refit, idx):
                kept.append(_Hyp(h.kind, refit, idx))
            elif admissible(h.fit, idx):
                kept.append(_Hyp(h.kind, h.fit, idx))
        final = kept
    if final:
        Z = np.stack([np.abs(zres(h.kind, h.fit)) for h in final])
        best_i = np.argmin(Z, axis=0)
        ok = Z[best_i, np.arange(n)] <= k_sigma
        assignment = np.where(ok, best_i, -1)
    dl = float(np.sum(np.where(assignment >= 0, 0.0, c_unexplained)))
    for i, h in enumerate(final):
        idx = assignment == i
        z = zres(h.kind, h.fit)[idx]
        dl += float(np.sum(0.5 * z * z)) + 0.5 * MODELS[h.kind].dof * math.log(n)
    return Segmentation(tuple(h.fit for h in final), assignment.astype(int), sigma, dl,
                        extent, max_rel_std)
