"""Fit-and-grow as one inference loop: proposals, one score, selection, assignment, refits.

The map is the set of primitives that best **describes** the contacts (Leonardis, Gupta &
Bajcsy 1995: fit-and-grow with model selection), scored by one negative log-likelihood in nats:

* each contact ``i`` is a mixture of its readings ``r`` (:mod:`wholearm_tools.fit.readings`:
  the sphere or the side of each candidate link, with priors from the link identification and
  eq. (2)'s ``P_T``) and an outlier reading.  Explained by primitive ``k`` it costs
  ``-log sum_r pi_r exp(-z_rk^2 / 2)`` with ``z_rk`` the reading's residual in noise sigmas
  (and ``-log(1 - outlier_prior)``); unexplained, ``-log(outlier_prior) + log(L / (sqrt(2 pi)
  sigma))`` for a scene of size ``L``.  It takes the cheapest;
* each primitive costs its own code length, ``dof * (log(L / sigma) + bic / 2 * log(n_k))``
  for ``n_k`` member contacts (two-part MDL: each parameter to the precision its contacts
  determine it), and its **free-space term**: the robot occupied space where the primitive
  says the surface is.  Each sample point of the region its contacts span (their feet, and
  points every ``B`` along the edges of their minimum spanning tree) that the B-dilated sweep
  cuts into, deeper than the noise, costs as much as one unexplained contact;
* a side reading cannot touch at either end of its link (the inner end is the joint the link
  turns about; at the outer end the link's sphere encloses the cap): its residual there is
  infinite;
* a closed primitive (circle, sphere) whose inside is free space must hold the robot's base
  (the arm reaches every contact from its base through free space).

Proposals (:class:`Hypothesis` records) come from seeds (farthest-point sampled contacts, each
neighbourhood cut to the consensus of random minimal sets of readings), growth (every contact
connected to a hypothesis with a reading within ``k_sigma``), refits on the assigned readings,
a selected one refitted with every unexplained contact within the seeds' tolerance of it,
unions of two selected primitives (as either's type, and for neighbours as a richer one),
every other type on a selected one's contacts, its most influential contact (Cook's distance)
read by each of its other readings and left out (and so on down that chain), any hypothesis
only the sweep rejects refitted on the other side of its readings' spheres, seeds at a
selected one's unexplained neighbours (among its contacts and the unexplained ones; as its
type and richer ones), and new seeds among the contacts left unexplained.
A proposer never accepts or rejects: selection minimises the score (greedy additions, then
single additions, removals and swaps until it stops falling).  Assignment (each contact to its
cheapest primitive and reading, posterior reading weights) and refits alternate with selection
until the score stops falling — the classification is the E-step of the fit.  The noise level
is re-estimated from the assigned residuals at each round, and never exceeds the stated
kinematic error (the report gate's error model): residuals beyond it are contacts on another
surface, not noise, and a noise level that took them in would let one primitive explain the
contacts of two.

What reaches the map is decided once, by :mod:`wholearm_tools.fit.gate`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wholearm_tools.fit.core import fit_primitive, other_side, residuals_and_touch
from wholearm_tools.fit.data import FreeSpace
from wholearm_tools.fit.gate import added_cost, influence, joining_residuals
from wholearm_tools.fit.models import MODELS
from wholearm_tools.fit.policy import FitPolicy
from wholearm_tools.fit.readings import Readings
from wholearm_tools.fit.result import FitResult

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]


class SweptTest(Protocol):
    """Where the robot has been over the run (free space)."""

    resolution: float

    def __call__(self, points: FloatArray) -> NDArray[np.bool_]: ...

#: radius-like parameters of each curved type (checked against the policy's radius bounds)
RADII = {"circle": ("radius",), "sphere": ("radius",), "cylinder": ("radius",),
         "torus": ("minor_radius", "major_radius")}
#: closed types: free space inside means the robot, base included, is inside
CLOSED = ("circle", "sphere")
#: a side reading touching within this fraction of the link's length from one of its ends
_END = 1e-6
#: candidate types per dimension, fewest parameters first
DEFAULT_KINDS = {2: ("line", "circle"), 3: ("plane", "sphere", "cylinder", "cone", "torus")}


@dataclass(eq=False)
class Hypothesis:
    """A proposed primitive: its fit on the readings ``reading`` of contacts ``members``.

    ``res`` (residual of every reading), ``cost`` (each contact's cost when this primitive
    explains it), ``free`` (the sweep's cuts into its support) are filled by the scorer.
    """

    kind: str
    fit: FitResult
    members: IntArray
    reading: IntArray
    origin: str
    res: FloatArray | None = None
    cost: FloatArray | None = None
    free: float = 0.0          # sweep cuts in its support (see Scorer.free_share)
    sigma: float = math.nan

    @property
    def dof(self) -> int:
        return MODELS[self.kind].dof


@dataclass(frozen=True)
class Inference:
    """The result of :func:`infer`.

    ``selected``: the primitives that describe the contacts best; ``assignment (M,)``: the
    primitive of each contact (-1 unexplained); ``reading (M,)``: the reading it is explained
    by (its prior-best where unexplained); ``posterior (R,)``: each reading's posterior
    probability (over the readings of its contact) under the assigned primitive (the prior
    where unexplained); ``sigma``: the noise level; ``score``: the final description length;
    ``extent``: the scene size; ``history``: the score after each round; ``residual (R,)``:
    each reading's residual under its contact's assigned primitive (NaN where unexplained);
    ``evidence``: per selected primitive, its gain in nats without its most valuable contact
    (:meth:`Scorer.evidence_without_best`; positive: no one contact carries it).
    """

    selected: tuple[Hypothesis, ...]
    assignment: IntArray
    reading: IntArray
    posterior: FloatArray
    sigma: float
    score: float
    extent: float
    history: tuple[float, ...] = ()
    messages: tuple[str, ...] = field(default_factory=tuple)
    residual: FloatArray = field(default_factory=lambda: np.zeros(0))
    evidence: FloatArray = field(default_factory=lambda: np.zeros(0))


# --------------------------------------------------------------------------- helpers


def _logsumexp_by_contact(v: FloatArray, starts: IntArray) -> FloatArray:
    """Per contact, ``log sum exp`` of the values of its readings (readings sorted by contact)."""
    mx = np.maximum.reduceat(v, starts)
    n_per = np.diff(np.r_[starts, len(v)])
    return mx + np.log(np.add.reduceat(np.exp(v - np.repeat(mx, n_per)), starts))


def reading_posterior(readings: Readings, residual: FloatArray, sigma: float) -> FloatArray:
    """Posterior probability of each reading over the readings of its contact, from its
    prior and its ``residual`` [m] at noise level ``sigma`` (zero for an infinite residual)."""
    with np.errstate(over="ignore"):    # a residual far beyond sigma: probability zero
        z = np.asarray(residual, dtype=float) / sigma
        v = readings.log_prior - 0.5 * z * z
    lse = _logsumexp_by_contact(v, readings.starts)
    return np.exp(v - lse[readings.contact])


def truncated_sigma(r: ArrayLike, start: float, k: float, rounds: int = 30) -> float:
    """Noise level from residuals of which only those within ``k sigma`` are inliers: the fixed
    point of ``sigma = rms(r[|r| <= k sigma]) / sqrt(c(k))``, ``c(k)`` the variance ratio of a
    normal truncated at ``k`` (a gate biases a plain RMS low)."""
    r = np.abs(np.asarray(r, dtype=float))
    r = r[np.isfinite(r)]
    if r.size == 0 or not start > 0:
        return float(start)
    phi = math.exp(-0.5 * k * k) / math.sqrt(2 * math.pi)
    ratio = 1.0 - 2.0 * k * phi / math.erf(k / math.sqrt(2))
    s = float(start)
    for _ in range(rounds):
        inl = r[r <= k * s]
        if inl.size < 3:
            break
        nxt = math.sqrt(float(np.mean(inl * inl)) / ratio)
        if not nxt > 0 or abs(nxt - s) <= 1e-6 * s:
            s = nxt if nxt > 0 else s
            break
        s = nxt
    return s


def _farthest(X: FloatArray, k: int, rng: np.random.Generator) -> list[int]:
    n = len(X)
    if n == 0:
        return []
    order = [int(rng.integers(n))]
    dmin = np.linalg.norm(X - X[order[0]], axis=1)
    while len(order) < min(k, n):
        i = int(np.argmax(dmin))
        if dmin[i] <= 0:
            break
        order.append(i)
        dmin = np.minimum(dmin, np.linalg.norm(X - X[i], axis=1))
    return order


def _mst_edges(X: FloatArray) -> list[tuple[int, int]]:
    """Edges of the Euclidean minimum spanning tree of ``X`` (Prim, dense: supports are small)."""
    n = len(X)
    if n < 2:
        return []
    inside = np.zeros(n, dtype=bool)
    inside[0] = True
    best = np.linalg.norm(X - X[0], axis=1)
    parent = np.zeros(n, dtype=int)
    edges = []
    for _ in range(n - 1):
        cand = np.where(inside, np.inf, best)
        j = int(np.argmin(cand))
        edges.append((int(parent[j]), j))
        inside[j] = True
        d = np.linalg.norm(X - X[j], axis=1)
        closer = d < best
        parent[closer] = j
        best = np.minimum(best, d)
    return edges


# --------------------------------------------------------------------------- the scorer


class Scorer:
    """Residuals of every reading under a hypothesis, and the description length of a set."""

    def __init__(self, readings: Readings, policy: FitPolicy, sigma: float, extent: float,
                 swept: SweptTest | None, base: FloatArray | None, B: float) -> None:
        self.readings = readings
        self.policy = policy
        self.extent = extent
        self.swept = swept
        self.cell = 0.0 if swept is None else float(getattr(swept, "resolution", 0.0))
        self.base = base
        self.B = B
        self.all_data = readings.fit_data()
        self.n = readings.n_contacts
        self.set_sigma(sigma)

    def set_sigma(self, sigma: float) -> None:
        self.sigma = float(sigma)
        p = self.policy
        self.c_out = (-math.log(p.outlier_prior)
                      + math.log(max(self.extent / (math.sqrt(2 * math.pi) * self.sigma),
                                     math.e)))
        self.c_in = -math.log(1.0 - p.outlier_prior)
        # a parameter coded to the precision its contacts determine it: its range (the scene)
        # over its standard deviation (sigma / sqrt(n_k)), plus the BIC share of the policy
        self.param_cost = math.log(max(self.extent / self.sigma, math.e))
        self.sweep_tol = max(p.sweep_tol_sigmas * self.sigma, p.sweep_tol_min)
        self.sweep_depth = self.sweep_tol + 0.5 * math.sqrt(self.readings.dim) * self.cell

    # ---- per hypothesis
    def residuals(self, h: Hypothesis) -> FloatArray:
        """Residual of every reading under ``h``; infinite for a side reading whose least
        clearance lies at one of the link's ends.  The inner end is the joint the link turns
        about: it does not move when the link turns, so a contact there would have stopped the
        inner link, and the joint signals would have named it (the link in contact is the last
        one to stop).  At the outer end the link's sphere (tip or joint sphere, never thinner
        than the link) encloses the capsule's cap: a contact there is the sphere reading, and
        the side read at the sphere's point would put the surface off by the difference of
        the two radii."""
        if h.res is None:
            r, t = residuals_and_touch(h.kind, h.fit.params, self.all_data, h.fit.free_side)
            h.res = self.readings.from_fit_rows(_sides_at_ends_invalid(r, t,
                                                                       self.all_data.n_tip))
        return h.res

    def score(self, h: Hypothesis) -> Hypothesis:
        """Fill ``h.cost`` and ``h.free`` at the current noise level."""
        if h.sigma == self.sigma and h.cost is not None:
            return h
        res = self.residuals(h)
        z = res / self.sigma
        v = self.readings.log_prior - 0.5 * z * z
        h.cost = self.c_in - _logsumexp_by_contact(v, self.readings.starts)
        h.free = self.free_share(h)
        h.sigma = self.sigma
        return h

    def posterior(self, h: Hypothesis) -> FloatArray:
        """Posterior probability of each reading given that ``h`` explains its contact."""
        return reading_posterior(self.readings, self.residuals(h), self.sigma)

    def best_reading(self, h: Hypothesis) -> IntArray:
        """Each contact's most probable reading under ``h``, ``(M,)`` reading indices."""
        z = self.residuals(h) / self.sigma
        v = self.readings.log_prior - 0.5 * z * z
        out = np.empty(self.n, dtype=np.int64)
        st = self.readings.starts
        ends = np.r_[st[1:], len(v)]
        for i, (s, e) in enumerate(zip(st, ends, strict=True)):
            out[i] = s + int(np.argmax(v[s:e]))
        return out

    def support_points(self, h: Hypothesis) -> FloatArray:
        """Where the member readings touch the primitive (their feet on the surface)."""
        prim = h.fit.primitive
        rd = self.readings
        idx = h.reading
        a, b = rd.a[idx], rd.b[idx]
        _, t = prim.segment_signed_distance(a, b, free_side=h.fit.free_side)
        x = a + np.asarray(t)[:, None] * (b - a)
        return np.asarray(prim.closest_point(x))

    def free_share(self, h: Hypothesis) -> float:
        """Number of sample points of the region a hypothesis' contacts span (their feet, and
        points every ``B`` along the edges of their minimum spanning tree, on the surface) that
        the robot's sweep cuts into: the free-space term.  Infinite for a closed primitive with
        the base outside its free side."""
        prim = h.fit.primitive
        if prim is None:
            return math.inf
        if (self.base is not None and h.kind in CLOSED and h.fit.free_side < 0
                and float(prim.signed_distance(self.base[None])[0]) > 0):
            return math.inf
        if self.swept is None or len(h.members) == 0:
            return 0.0
        feet = self.support_points(h)
        samples = [feet]
        step = max(self.B, 1e-3 * self.extent)
        for i, j in _mst_edges(feet):
            length = float(np.linalg.norm(feet[j] - feet[i]))
            k = min(int(length / step), 16)
            if k >= 1:
                s = (np.arange(1, k + 1) / (k + 1))[:, None]
                samples.append(np.asarray(prim.closest_point(feet[i] + s * (feet[j] - feet[i]))))
        x = np.vstack(samples)
        normal = np.asarray(prim.gradient(x)) * h.fit.free_side
        # a point that deep behind the surface (in its material) lies in a cell whose centre
        # is at least ``sweep_tol`` behind it; the map calls a cell swept only when its centre
        # was inside the robot
        return float(np.count_nonzero(self.swept(x - self.sweep_depth * normal)))

    # ---- sets
    def total(self, chosen: Sequence[Hypothesis]) -> float:
        return (float(np.sum(self.contact_costs(chosen)))
                + sum(self.model_cost(h) for h in chosen))

    def contact_costs(self, chosen: Sequence[Hypothesis]) -> FloatArray:
        """Each contact's cost under the best of ``chosen`` (``c_out`` when none explains it)."""
        cur = np.full(self.n, self.c_out)
        for h in chosen:
            cur = np.minimum(cur, h.cost)
        return cur

    def model_cost(self, h: Hypothesis, n_k: int | None = None) -> float:
        """The primitive's own code length and its free-space term (``n_k``: its member
        count, ``len(h.members)`` unless given).

        Each parameter is coded to the precision its ``n_k`` contacts determine it, ``sigma /
        sqrt(n_k)`` over a range of the scene's size: ``log(L / sigma) + bic / 2 log(n_k)``
        nats (two-part MDL; the second term alone is BIC, which undercharges a primitive
        fitted to few contacts: five parameters would then cost less than two contacts
        explained).  So a primitive pays for itself only by explaining clearly more contacts
        than it has parameters.  Each sample of its support that the sweep cuts is evidence
        against it as strong as a contact's for it (the cost of leaving a contact
        unexplained)."""
        n_k = len(h.members) if n_k is None else n_k
        return h.dof * self.param_price(n_k) + h.free * self.c_out

    def evidence_without_best(self, chosen: Sequence[Hypothesis]) -> FloatArray:
        """Per selected primitive, its description-length gain (what the total would rise by
        without it) once its most valuable contact is left out of the data: each contact's
        share is what it saves under the primitive against its cost under the others.  The
        data less any one contact must still pay for the primitive's parameters (the report
        gate's leave-one-out principle, applied to the evidence): a primitive whose gain one
        contact carries rests on that contact's reading, whatever its determination."""
        out = np.empty(len(chosen))
        for i, h in enumerate(chosen):
            rest = self.contact_costs([c for c in chosen if c is not h])
            share = np.maximum(rest - h.cost, 0.0)
            out[i] = (float(np.sum(share) - np.max(share, initial=0.0))
                      - self.model_cost(h, len(h.members) - 1))
        return out

    def param_price(self, n_k: int) -> float:
        """The code length of one parameter of a primitive of ``n_k`` contacts
        (:meth:`model_cost`)."""
        return self.param_cost + 0.5 * self.policy.bic * math.log(max(n_k, 2))

    def select(self, pool: Sequence[Hypothesis], start: Sequence[Hypothesis] = ()
               ) -> list[Hypothesis]:
        """The subset of ``pool`` of least total description length: greedy additions, then
        single additions and removals while the total falls."""
        chosen = list(start)
        cur = np.full(self.n, self.c_out)
        for h in chosen:
            cur = np.minimum(cur, h.cost)

        def gain(h: Hypothesis, cur: FloatArray) -> float:
            return float(np.sum(np.maximum(cur - h.cost, 0.0))) - self.model_cost(h)

        while True:
            best, best_h = 1e-9, None
            for h in pool:
                if any(h is c for c in chosen):
                    continue
                g = gain(h, cur)
                if g > best:
                    best, best_h = g, h
            if best_h is None:
                break
            chosen.append(best_h)
            cur = np.minimum(cur, best_h.cost)
        # removals: a primitive the others (now) make redundant
        changed = True
        while changed and chosen:
            changed = False
            total = self.total(chosen)
            for h in list(chosen):
                rest = [c for c in chosen if c is not h]
                if self.total(rest) < total - 1e-9:
                    chosen = rest
                    changed = True
                    break
            if not changed:
                # swaps: one out, one in
                for h in list(chosen):
                    rest = [c for c in chosen if c is not h]
                    cur_r = np.full(self.n, self.c_out)
                    for c in rest:
                        cur_r = np.minimum(cur_r, c.cost)
                    for g in pool:
                        if any(g is c for c in chosen):
                            continue
                        if self.total([*rest, g]) < total - 1e-9:
                            chosen = [*rest, g]
                            changed = True
                            break
                    if changed:
                        break
        return chosen

    def assign(self, chosen: Sequence[Hypothesis]) -> IntArray:
        """Each contact's cheapest selected primitive, -1 where the outlier reading is cheaper."""
        if not chosen:
            return np.full(self.n, -1, dtype=np.int64)
        C = np.stack([h.cost for h in chosen])
        k = np.argmin(C, axis=0)
        return np.where(C[k, np.arange(self.n)] < self.c_out, k, -1).astype(np.int64)


# --------------------------------------------------------------------------- proposals


@dataclass(frozen=True)
class _Context:
    """What every proposal of one :func:`infer` call shares (picklable for worker processes)."""

    readings: Readings
    kinds: tuple[str, ...]
    rep: FloatArray             # (M, d) one representative point per contact
    prior_best: IntArray        # (M,) each contact's most probable reading a priori
    order: IntArray             # (M, M) contacts by distance from each contact
    sigma: float
    tol: float                  # consensus inlier tolerance [m]
    min_radius: float
    max_radius_ratio: float
    seed_extra: int
    trials: int                 # minimal sets per seed and type
    key: int
    free: FreeSpace             # free-space points (robot positions)
    max_iter: int               # solver iterations of a seed fit
    accept: float = math.inf    # a seed fit poorer than this many sigmas is trimmed
    sigma_id: float = 0.0       # kinematic error the proposals are judged determined at
    max_rel_std: float = math.inf
    extend: int = 12            # contacts an undetermined seed may try, one at a time
    set_iter: int = 10          # solver iterations of a minimal set's hypothesis
    precision: float = 0.0      # residual precision [m] every proposal fit is solved to
    set_precision: float = 0.0  # ... and every minimal set's hypothesis (tested at ``tol``)


def _neighbourhoods(readings: Readings) -> tuple[IntArray, FloatArray, IntArray]:
    """Each contact's most probable reading a priori ``(M,)``, its point (the contact's
    representative point, ``(M, d)``), and every contact's contacts by distance from it
    ``(M, M)``, itself first."""
    lp = readings.log_prior
    st = readings.starts
    prior_best = np.array([s + int(np.argmax(lp[s:e]))
                           for s, e in zip(st, np.r_[st[1:], len(lp)], strict=True)])
    rep = readings.points()[prior_best]
    D = np.linalg.norm(rep[:, None, :] - rep[None, :, :], axis=2)
    return prior_best, rep, np.argsort(D, axis=1, kind="stable")


def _admissible(ctx_kind: str, fit: FitResult, min_radius: float, max_ratio: float) -> bool:
    if not fit or fit.primitive is None:
        return False
    for name in RADII.get(ctx_kind, ()):
        r = float(fit.params[name])
        if not (min_radius <= r <= max_ratio * fit.scale):
            return False
    return True


def fit_readings(kind: str, readings: Readings, idx: IntArray, weight: ArrayLike | None = None,
                 start: FitResult | None = None,
                 free_points: ArrayLike | FreeSpace | None = None,
                 max_iter: int = 200, covariance: bool = True, quick: bool = False,
                 cold: bool = True, precision: float | None = None,
                 keep_side: bool = True) -> FitResult:
    """Fit ``kind`` to readings ``idx`` (warm from ``start`` when given, and from the type's
    own guesses when that fails unless ``cold`` is False; a start the solver did not finish
    is as good a start as a converged one); ``free_points`` (robot positions:
    free space) tell a closed primitive's free side; ``covariance`` False skips the covariance
    and sensitivity (a proposal that only needs the parameters); ``quick`` starts from the
    type's quick guess only (a minimal set's hypothesis); ``precision`` [m] the residual
    precision the caller needs (:func:`~wholearm_tools.fit.core.fit_primitive`); ``keep_side``
    False decides a closed primitive's free side afresh on these readings' free-space hints
    (both sides fitted from ``start`` where they do not tell) instead of keeping ``start``'s."""
    data = readings.fit_data(idx, weight, free_points)
    if start is not None and start.kind == kind and start.params:
        # from a start the type's guesses only vote on a side left open, and the quick
        # guess votes as well as the careful ones
        f = fit_primitive(kind, data, free_side=start.free_side if keep_side else None,
                          initial=dict(start.params), quick=True,
                          max_iter=max_iter, covariance=covariance, precision=precision)
        if f or not cold:
            return f
    return fit_primitive(kind, data, max_iter=max_iter, covariance=covariance, quick=quick,
                         precision=precision)


def _seeded(kinds: Sequence[str]) -> tuple[str, ...]:
    """The types a seed fits: those of at most five parameters, unless there are none (cones
    and tori: on a seed's few contacts they fit almost any patch, and their guesses are the
    slowest; they are offered as refits of the contacts of selected primitives, where there
    are enough to tell them from the simpler types)."""
    few = tuple(k for k in kinds if MODELS[k].dof <= 5)
    return few or tuple(kinds)


def _seed(ctx: _Context, anchor: int, plain: dict[str, FitResult] | None = None
          ) -> list[tuple[str, IntArray, IntArray, FitResult]]:
    """Hypotheses at one seed contact, per type: its ``dof + 2`` nearest contacts by their most
    probable readings, and the consensus of minimal sets among its ``dof + 2 + seed_extra``
    nearest (RANSAC, with the first fit as its first hypothesis: near the edge of a surface the
    nearest contacts mix two, and ambiguous contacts are read both ways);
    each fitted and polished (:func:`_polish`), and extended where not determined
    (:func:`_extend`); for the types :func:`_seeded` names."""
    rng = np.random.default_rng([ctx.key, anchor])
    rd = ctx.readings
    out: list[tuple[str, IntArray, IntArray, FitResult]] = []
    for kind in _seeded(ctx.kinds):
        m = MODELS[kind]
        near = ctx.order[anchor, :m.dof + 2 + ctx.seed_extra]
        if len(near) < m.dof + 2:
            continue
        # the dof + 2 nearest by their prior readings (small, so rarely two surfaces), fitted
        # and polished
        start = np.sort(near[:m.dof + 2])
        f = (plain[kind] if plain is not None and kind in plain else
             fit_readings(kind, rd, ctx.prior_best[start], free_points=ctx.free,
                          max_iter=ctx.max_iter, precision=ctx.precision))
        polished = _polish(kind, rd, start, ctx.prior_best[start], f, anchor, ctx)
        sel = np.flatnonzero(np.isin(rd.contact, near))
        others = near[near != anchor]
        best_key, best, best_g = (-1, -np.inf), None, None
        # the polished fit of the nearest contacts is the consensus search's first hypothesis:
        # inside a surface it may hold the whole neighbourhood, and no minimal set is drawn
        g: FitResult | None = None
        if polished is not None:
            ext = _extended(kind, rd, *polished, anchor, ctx)
            out.append((kind, *ext))
            g = ext[2]
        for trial in range(ctx.trials + 1):
            if trial > 0:
                # a minimal set (dof + 1 contacts, the anchor among them), each by a reading
                # drawn by its prior, fitted exactly: algebraic guesses from link contacts are
                # too rough.  The hypothesis is the solver's iterate at ``set_iter``, converged
                # or not, solved only as precisely as the inlier test at ``tol`` needs: it is
                # not scored, and its consensus is refitted from it
                pick = np.r_[anchor, rng.choice(others, min(m.dof, len(others)),
                                                replace=False)]
                idx = []
                for c in pick:
                    rs = np.flatnonzero(rd.contact == c)
                    p = np.exp(rd.log_prior[rs])
                    idx.append(int(rng.choice(rs, p=p / p.sum())))
                g = fit_readings(kind, rd, np.array(idx), free_points=ctx.free,
                                 max_iter=ctx.set_iter, covariance=False, quick=True,
                                 precision=ctx.set_precision)
            usable = g is not None and (g or g.status == "Maximum_Iterations_Exceeded")
            found = _consensus(g, rd, sel, near, anchor, ctx.tol) if usable else None
            if found is not None and found[0] > best_key:
                best_key, best, best_g = found[0], found[1:], g
            if best is not None and len(best[0]) == len(near):
                break
        if best is None or len(best[0]) < m.dof + 2:
            continue
        inl, r = best
        members = np.sort(inl)
        reading = np.array([int(sel[rd.contact[sel] == c][np.argmin(r[rd.contact[sel] == c])])
                            for c in members])
        # the consensus is fitted from the hypothesis that found it (within ``tol`` of every
        # member), from the type's own guesses only where that does not converge; its free
        # side is decided on the consensus's hints: the minimal set's few are less telling
        f = fit_readings(kind, rd, reading, start=best_g, free_points=ctx.free,
                         max_iter=ctx.max_iter, precision=ctx.precision, keep_side=False)
        polished = _polish(kind, rd, members, reading, f, anchor, ctx)
        if polished is None:
            continue
        out.append((kind, *_extended(kind, rd, *polished, anchor, ctx)))
    return out


def _consensus(g: FitResult, rd: Readings, sel: IntArray, near: IntArray, anchor: int,
               tol: float) -> tuple[tuple[int, float], IntArray, FloatArray] | None:
    """The contacts of ``near`` within ``tol`` of ``g`` (by their closest reading; rows ``sel``
    hold their readings), ranked by their count, then by the truncated squared residuals, and
    the residuals of ``sel``; None unless the ``anchor`` is among them."""
    r = np.abs(_residuals_of(g, rd, sel))
    best_r = np.full(rd.n_contacts, np.inf)
    np.minimum.at(best_r, rd.contact[sel], r)
    inl = near[best_r[near] <= tol]
    if anchor not in inl:
        return None
    return (len(inl), -float(np.sum(np.minimum(best_r[near], tol) ** 2))), inl, r


def _extended(kind: str, rd: Readings, members: IntArray, reading: IntArray, f: FitResult,
              anchor: int, ctx: _Context) -> tuple[IntArray, IntArray, FitResult]:
    """:func:`_extend` where the seed's fit is not determined and the noise level is known."""
    if math.isfinite(ctx.accept) and f.sensitivity * ctx.sigma_id > ctx.max_rel_std:
        return _extend(kind, rd, members, reading, f, anchor, ctx)
    return members, reading, f


def _extend(kind: str, rd: Readings, members: IntArray, reading: IntArray, f: FitResult,
            anchor: int, ctx: _Context) -> tuple[IntArray, IntArray, FitResult]:
    """A seed fit its contacts do not determine, extended by the next nearest contacts one at a
    time, each refitted from the last solution and kept while the fit stays within 1.5 noise
    sigmas (dof-corrected), until it is determined.  A contact the warm refit cannot take
    (no convergence from the last solution) is passed over, never fitted from scratch.

    Link contacts from one joint's sweep all lie tangent to a family of primitives (every
    tangent line in one plane touches a whole family of cylinders); a fresh fit to a larger
    neighbourhood falls into another member of the family or another minimum, while a refit
    from the last solution slides along the family to the member the new contact touches too."""
    limit = 1.5 * ctx.sigma    # the dof-corrected RMS an extended fit may reach
    for c in ctx.order[anchor, len(members):len(members) + ctx.extend]:
        if c in members:
            continue
        rows = np.flatnonzero(rd.contact == c)
        res = np.abs(_residuals_of(f, rd, rows))
        r_best = int(rows[int(np.argmin(res))])
        cand = np.sort(np.append(members, c))
        cand_reading = np.array([r_best if m_ == c else int(reading[members == m_][0])
                                 for m_ in cand])
        # a refit the linearised prediction puts beyond three times the acceptance limit is
        # not tried (sliding along a family of tangent primitives lowers the refit's cost
        # below the prediction by well under that factor)
        new = int(rd.fit_order(rd.sphere[cand_reading])[int(np.searchsorted(cand, c))])
        cost = added_cost(f, rd.fit_data(cand_reading), new)
        if cost > (3.0 * limit) ** 2 * max(len(cand) - MODELS[kind].dof, 1):
            continue
        g = fit_readings(kind, rd, cand_reading, start=f, free_points=ctx.free,
                         max_iter=ctx.max_iter, cold=False, precision=ctx.precision)
        if g and _admissible(kind, g, ctx.min_radius, ctx.max_radius_ratio) \
                and _rms_dof(g) <= limit:
            members, reading, f = cand, cand_reading, g
            if f.sensitivity * ctx.sigma_id <= ctx.max_rel_std:
                break
    return members, reading, f


def _closest_readings(rd: Readings, rows: IntArray, res: FloatArray
                      ) -> tuple[FloatArray, IntArray]:
    """Each contact's least residual among readings ``rows`` (``res``, absolute) and the
    reading that has it (the first of equals in ``rows``' order): ``(M,)`` each, infinity
    and -1 for contacts without a reading in ``rows``."""
    contact = rd.contact[rows]
    least = np.full(rd.n_contacts, np.inf)
    np.minimum.at(least, contact, res)
    at = np.flatnonzero(res == least[contact])
    first = at[np.unique(contact[at], return_index=True)[1]]
    reading = np.full(rd.n_contacts, -1, dtype=np.int64)
    reading[contact[first]] = rows[first]
    return least, reading


def _polish(kind: str, rd: Readings, members: IntArray, reading: IntArray, f: FitResult,
            anchor: int, ctx: _Context, rounds: int = 12
            ) -> tuple[IntArray, IntArray, FitResult] | None:
    """A consensus fit refined by alternation: each member takes its reading closest to the
    current fit, members farther than ``3.5`` robust sigmas of the fit's own residuals (the
    seed does not know the noise level yet; at least the run's floor) are let go, and the
    rest are refitted from the current solution; until nothing changes.  Once the noise level is
    known (``ctx.accept`` finite), a fit poorer than ``accept`` sigmas then loses its worst
    member, one at a time, down to ``dof + 2``.  The algebraic guess
    that chose the readings is millimetres off, so where a contact's sphere and side readings
    are both within its tolerance the first choice is often the wrong one."""
    m = MODELS[kind]
    for _ in range(rounds):
        if not _admissible(kind, f, ctx.min_radius, ctx.max_radius_ratio):
            return None
        rows = np.flatnonzero(np.isin(rd.contact, members))
        best, closest = _closest_readings(rd, rows, np.abs(_residuals_of(f, rd, rows)))
        choice = closest[members]
        scale = max(1.4826 * float(np.median(best[members])), ctx.sigma)
        keep = members[(best[members] <= 3.5 * scale) | (members == anchor)]
        keep_reading = choice[np.isin(members, keep)]
        if len(keep) < m.dof + 2:
            return None
        if np.array_equal(keep, members) and np.array_equal(keep_reading, reading):
            if not _rms_dof(f) > ctx.accept * ctx.sigma or len(members) <= m.dof + 2:
                return members, reading, f
            # the fit is poor at the noise level: its worst member goes (never the anchor)
            worst = np.where(members == anchor, -1.0, best[members])
            keep = np.delete(members, int(np.argmax(worst)))
            keep_reading = choice[np.isin(members, keep)]
        members, reading = keep, keep_reading
        g = fit_readings(kind, rd, reading, start=f, free_points=ctx.free, max_iter=ctx.max_iter,
                         precision=ctx.precision)
        if not g:
            return None
        f = g
    return (members, reading, f) if _admissible(kind, f, ctx.min_radius,
                                                  ctx.max_radius_ratio) else None


def _captured(kind: str, rd: Readings, f: FitResult, residual: FloatArray, tol: float,
              free: FreeSpace | None, precision: float, members: IntArray | None = None
              ) -> tuple[IntArray, IntArray, FitResult] | None:
    """``f`` refitted from itself on every contact with a reading within ``tol`` of it (the
    seeds' inlier tolerance), each by its closest reading (``residual``: of every reading
    under ``f``; infinite for contacts that may not join).  Returns the contacts, their
    readings and the fit; None when fewer than ``dof + 2`` contacts are that near, when none
    of them is new to ``members`` (``f``'s own), or when the refit fails.

    Growth admits a contact within ``k_sigma`` noise sigmas of the fit it has.  A fit that
    stopped on a neighbouring member of a tangent family (link sides of one joint's sweep
    touch a line of post centres, radius growing along it) fits its members exactly and
    leaves the contacts that pin the right member a few ``k_sigma`` off, where growth never
    takes them; a refit that includes them slides along the family to the member that
    touches them all."""
    near, closest = _closest_readings(rd, np.arange(len(rd)), np.abs(residual))
    cand = np.flatnonzero(near <= tol)
    if len(cand) < MODELS[kind].dof + 2 or (members is not None
                                            and not np.setdiff1d(cand, members).size):
        return None
    g = fit_readings(kind, rd, closest[cand], start=f, free_points=free, precision=precision)
    return (cand, closest[cand], g) if g else None


def _sides_at_ends_invalid(r: FloatArray, t: FloatArray, n_tip: int) -> FloatArray:
    """Residuals ``r`` of fit rows (spheres first, then ``len(t)`` sides touching at fraction
    ``t`` of their length) with the sides that touch at an end set infinite (see
    :meth:`Scorer.residuals`)."""
    r = np.array(r, dtype=float)
    r[n_tip:][(t <= _END) | (t >= 1.0 - _END)] = np.inf
    return r


def _residuals_of(f: FitResult, rd: Readings, rows: IntArray) -> FloatArray:
    """Residuals [m] of readings ``rows`` under fit ``f`` (in the order of ``rows``), infinite
    for a side read where it cannot touch (:meth:`Scorer.residuals`)."""
    data = rd.fit_data(rows)
    r, t = residuals_and_touch(f.kind, f.params, data, f.free_side)
    return _sides_at_ends_invalid(r, t, data.n_tip)[Readings.fit_order(rd.sphere[rows])]


def _plain(ctx: _Context, anchor: int) -> dict[str, FitResult]:
    """Per seeded type, the fit to the ``dof + 2`` contacts nearest ``anchor``, each by its
    most probable reading: the noise estimate's sample (:func:`_noise_from_seeds`, on the
    best dof-corrected RMS of each anchor) and the start of the seed there (:func:`_seed`)."""
    out: dict[str, FitResult] = {}
    for kind in _seeded(ctx.kinds):
        m = MODELS[kind]
        near = np.sort(ctx.order[anchor, :m.dof + 2])
        if len(near) < m.dof + 2:
            continue
        out[kind] = fit_readings(kind, ctx.readings, ctx.prior_best[near],
                                 free_points=ctx.free, max_iter=ctx.max_iter,
                                 precision=ctx.precision)
    return out


def _plain_many(ctx: _Context, anchors: Sequence[int], executor: Executor | None
                ) -> list[dict[str, FitResult]]:
    if executor is None or len(anchors) < 2:
        return [_plain(ctx, a) for a in anchors]
    return list(executor.map(_plain, [ctx] * len(anchors), anchors))


def _noise_from_seeds(best: FloatArray) -> float:
    """Noise level from the best dof-corrected RMS of ``K`` seed fits of ``dof + 2`` contacts.

    A seed inside one surface has RMS ``sigma sqrt(chi2_2 / 2)``: its 10th percentile is
    ``0.325 sigma`` and the best of ``K`` sits near the ``1/K`` quantile ``sqrt(-ln(1 - 1/K))
    sigma``.  Both agree within a small factor when most seeds are clean; when most straddle
    two surfaces (next to a junction) the percentile measures the mismatch, and the best seed
    is used instead."""
    if best.size == 0:
        return 0.0
    pct = float(np.percentile(best, 10)) / 0.325
    low = float(np.min(best)) / math.sqrt(-math.log(1.0 - 1.0 / max(best.size, 2)))
    return pct if pct <= 3.0 * low else low


def _seed_many(ctx: _Context, anchors: Sequence[int], executor: Executor | None,
               plain: Sequence[dict[str, FitResult] | None] | None = None
               ) -> list[list[tuple[str, IntArray, IntArray, FitResult]]]:
    """:func:`_seed` at each anchor (in worker processes when given an executor), from the
    anchors' :func:`_plain` fits where they were made already."""
    starts = list(plain) if plain is not None else [None] * len(anchors)
    if executor is None or len(anchors) < 2:
        return [_seed(ctx, a, p) for a, p in zip(anchors, starts, strict=True)]
    return list(executor.map(_seed, [ctx] * len(anchors), anchors, starts))


# --------------------------------------------------------------------------- the loop


def infer(readings: Readings, *, kinds: Sequence[str] | None = None,
          policy: FitPolicy | None = None, B: float = 0.02, noise_floor: float = 0.0,
          swept: SweptTest | None = None, base: ArrayLike | None = None,
          free_points: ArrayLike | FreeSpace | None = None, reach: float | None = None,
          rng: int | np.random.Generator | None = 0,
          executor: Executor | None = None,
          diagnostics: dict | None = None) -> Inference:
    """Describe ``readings`` by primitives: the loop of the module docstring.

    Parameters
    ----------
    readings : the contacts' readings (:func:`wholearm_tools.fit.readings.readings_from_contacts`)
    kinds : candidate types (default: all of the dimension), fewest parameters first
    policy : :class:`FitPolicy`
    B : smallest expected curvature radius [m] (radius floor, support sampling step)
    noise_floor : smallest noise level [m] (the encoder resolution at the contacts)
    swept : where the robot has been: ``swept(points (K, d)) -> (K,) bool`` (free space), with
        a ``resolution`` attribute (its cell size, 0 when exact); base : the robot's base point
    free_points : (K, d) points the robot occupied, or a :class:`~wholearm_tools.fit.data.FreeSpace`
        of them (free space; a fit's free side)
    reach : the robot's reach [m]: kinematic errors scale with it (the scene size without one)
    rng : seeds the proposals; the result depends on nothing else (not on ``executor``)
    executor : runs the seed proposals (e.g. a process pool)
    diagnostics : a dict that receives the hypothesis pool and the scorer (for study)
    """
    policy = policy or FitPolicy()
    rng = np.random.default_rng(rng)
    dim = readings.dim
    kinds = tuple(DEFAULT_KINDS[dim] if kinds is None else kinds)
    m_all = readings.n_contacts
    base_pt = None if base is None else np.asarray(base, dtype=float).reshape(dim)
    pts_all = np.vstack([readings.a, readings.b])
    extent = float(np.linalg.norm(pts_all.max(axis=0) - pts_all.min(axis=0))) if m_all else 0.0
    empty = Inference((), np.full(m_all, -1), np.zeros(m_all, dtype=np.int64),
                      np.exp(readings.log_prior), float(policy.noise or noise_floor), 0.0,
                      extent, residual=np.full(len(readings), np.nan))
    min_need = min(MODELS[k].dof for k in kinds) + 2
    if m_all < min_need or extent <= 0:
        return empty

    prior_best, rep, order = _neighbourhoods(readings)
    adj = np.zeros((m_all, m_all), dtype=bool)
    kn = min(policy.neighbours, m_all - 1)
    adj[np.repeat(np.arange(m_all), kn), order[:, 1:kn + 1].ravel()] = True
    adj |= adj.T

    # validated and indexed once (unless the caller did), shared by every fit of the search
    free = FreeSpace.of(free_points, dim)
    floor = max(float(noise_floor), 1e-6 * extent)
    sigma = float(policy.noise) if policy.noise else floor
    min_radius = policy.min_radius_over_b * B
    scorer = Scorer(readings, policy, sigma, extent, swept, base_pt, B)
    key = int(rng.integers(2**63))

    # the stated kinematic error: the report gate's error model, and the most noise the
    # inference may assume
    sigma_kin = policy.kinematic_error * (reach or extent)

    def bounded(sig: float) -> float:
        """An estimated noise level held between the run's floor and the kinematic error."""
        return min(max(sig, floor), max(sigma_kin, floor))

    def sigma_id(sig: float) -> float:
        """The kinematic error a proposal is judged determined at (as the report gate)."""
        return max(sig, sigma_kin)

    def context(sig: float, known: bool) -> _Context:
        tol = max(30.0 * sig, 1e-3 * extent)
        return _Context(readings, kinds, rep, prior_best, order, sig, tol,
                        min_radius, policy.max_radius_ratio, policy.seed_extra,
                        policy.consensus_trials, key, free, policy.proposal_iterations,
                        policy.seed_accept if known else math.inf, sigma_id(sig),
                        policy.max_rel_std, policy.seed_extend, policy.minimal_set_iterations,
                        policy.solve_precision * sig, policy.solve_precision * tol)

    def make(kind: str, fit: FitResult, members: IntArray, reading: IntArray,
             origin: str) -> Hypothesis | None:
        if not _admissible(kind, fit, min_radius, policy.max_radius_ratio):
            return None
        return scorer.score(Hypothesis(kind, fit, np.asarray(members), np.asarray(reading),
                                       origin))

    fitted: dict[tuple[str, bytes, object], Hypothesis | None] = {}

    def refit(h: Hypothesis, members: IntArray, origin: str, kind: str | None = None,
              cold: bool = False, reread: tuple[int, int] | None = None,
              flip: bool = False) -> Hypothesis | None:
        """``h`` (or a ``kind`` fitted from scratch, or with ``cold`` ``h``'s own kind from
        scratch, or with ``flip`` from ``h`` on the other side of its readings' spheres)
        refitted on ``members``, each by its most probable reading under ``h`` with
        its posterior as weight (``reread`` ``(k, r)``: member ``k`` by reading ``r`` instead,
        at full weight); once per reading set and start.  A fit from scratch has a seed's
        iteration budget: a type that does not describe these contacts (a cone on a post's,
        degenerating towards the cylinder) does not converge, and is not worth finishing."""
        kind = kind or h.kind
        if len(members) < MODELS[kind].dof + 1:
            return None
        best = scorer.best_reading(h)[members]
        if reread is not None:
            best[reread[0]] = reread[1]
        warm = kind == h.kind and not cold
        # a warm fit is a proposal of its start as much as of its readings
        key_ = (kind, best.tobytes(), (flip, identity(h)[3]) if warm else None)
        if key_ not in fitted:
            weight = np.maximum(scorer.posterior(h)[best], 0.05)
            if reread is not None:
                weight[reread[0]] = 1.0
            start = other_side(h.fit) if flip else h.fit
            f = fit_readings(kind, readings, best, weight, start=start if warm else None,
                             free_points=free,
                             max_iter=200 if warm else policy.proposal_iterations,
                             precision=policy.solve_precision * scorer.sigma)
            fitted[key_] = make(kind, f, members, best, origin)
        return fitted[key_]

    passed: list[Hypothesis] = []   # grown hypotheses that a predicted contact extended

    def least_residual(h: Hypothesis) -> FloatArray:
        """Each contact's least absolute residual under ``h`` over its readings, ``(M,)``."""
        out = np.full(m_all, np.inf)
        np.minimum.at(out, readings.contact, np.abs(scorer.residuals(h)))
        return out

    def grow(h: Hypothesis, rounds: int = 8) -> Hypothesis:
        """Every contact connected to ``h``'s members through contacts with a reading within
        ``k_sigma``, refitted, until the set stops changing; then a neighbour a refit is
        predicted to bring within ``k_sigma`` (:func:`predicted`), where it does, and so on.
        The hypotheses it extends this way go into the pool as well (:func:`add`)."""
        for _ in range(rounds):
            best_r = least_residual(h)
            inl = best_r <= policy.k_sigma * scorer.sigma
            reach = np.zeros(m_all, dtype=bool)
            frontier = h.members[inl[h.members]]
            reach[frontier] = True
            while frontier.size:
                nxt = np.flatnonzero(adj[frontier].any(axis=0) & inl & ~reach)
                reach[nxt] = True
                frontier = nxt
            new = np.flatnonzero(reach)
            if np.array_equal(new, h.members) or len(new) < h.dof + 2:
                g = predicted(h, best_r)
                if g is not None:
                    passed.append(h)   # a proposal too: the pool, not growth, chooses
            else:
                g = refit(h, new, "growth")
            if g is None:
                return h
            h = g
        return h

    def predicted(h: Hypothesis, best_r: FloatArray, tries: int = 3) -> Hypothesis | None:
        """``h`` refitted with one neighbour of its members that is beyond ``k_sigma`` of it
        but within ``k_sigma`` of where the refit is predicted to put it
        (:func:`~wholearm_tools.fit.gate.joining_residuals`: a fit of contacts on one side of
        a post is uncertain up and around it), where the refit then holds every member
        within ``k_sigma``; the neighbours by their predicted residuals, the first ``tries``.
        One at a time: each prediction is for that contact joining alone.  None where none
        is predicted to join, or no refit holds it."""
        limit = policy.k_sigma * scorer.sigma
        cand = np.flatnonzero(adj[h.members].any(axis=0) & np.isfinite(best_r)
                              & (best_r > limit))
        cand = cand[~np.isin(cand, h.members)]
        if not cand.size:
            return None
        rows = scorer.best_reading(h)
        given = np.r_[rows[h.members], rows[cand]]
        at = Readings.fit_order(readings.sphere[given])[len(h.members):]
        joining = np.zeros(len(given), dtype=bool)
        joining[at] = True
        dev = np.empty(len(given))
        dev[joining] = joining_residuals(h.fit, readings.fit_data(given), joining)
        dev = dev[at]
        for k in np.argsort(dev, kind="stable")[:tries]:
            if dev[k] > limit:
                break
            g = refit(h, np.union1d(h.members, cand[k]), "growth")
            if g is None:
                continue
            if np.all(least_residual(g)[g.members] <= limit):
                return g
        return None

    captured: set[tuple[object, ...]] = set()   # (hypothesis, allowed contacts) captured

    def capture(h: Hypothesis, allowed: IntArray) -> Hypothesis | None:
        """``h`` refitted on every contact of ``allowed`` within the seeds' tolerance
        (:func:`_captured`), where that adds contacts to it; once per ``h`` and ``allowed``."""
        key_ = (*identity(h), allowed.tobytes())
        if key_ in captured:
            return None
        captured.add(key_)
        res = np.where(np.isin(readings.contact, allowed), scorer.residuals(h), np.inf)
        got = _captured(h.kind, readings, h.fit, res, context(scorer.sigma, True).tol, free,
                        policy.solve_precision * scorer.sigma, h.members)
        return None if got is None else make(h.kind, got[2], got[0], got[1], "capture")

    pool: list[Hypothesis] = []

    def grow_new(hs: Sequence[Hypothesis | None]) -> list[Hypothesis]:
        """Each new hypothesis grown, unless the pool (or one grown before it) already holds
        one of its type that explains all of its contacts (it would grow into that one)."""
        out: list[Hypothesis] = []
        for h in hs:
            if h is None:
                continue
            if any(g.kind == h.kind and np.all(scorer.score(g).cost[h.members] < scorer.c_out)
                   for g in (*pool, *out)):
                continue
            out.append(grow(h))
        return out

    def identity(h: Hypothesis) -> tuple[object, ...]:
        """A hypothesis' contacts, readings and surface (to 10 µm): the same readings fitted
        on either side of their spheres are two hypotheses."""
        surface = tuple((name, np.round(np.asarray(v, dtype=float), 5).tobytes())
                        for name, v in sorted(h.fit.params.items()))
        return (h.kind, h.members.tobytes(), h.reading.tobytes(), surface)

    seen: set[tuple[object, ...]] = set()   # identities of the pool's hypotheses

    def other_side_of(h: Hypothesis) -> Hypothesis | None:
        """``h`` refitted on its readings from the other side of their spheres, where only
        the sweep rejects ``h`` (it would pay for its parameters but for the cut) and the other
        side clears some of the cut.  The same spheres are tangent to a surface on either side
        of them (a bore and the post inside it, a wall and its mirror beyond the spheres);
        warm fits keep the side they started on, and only the sweep tells the sides apart."""
        if h.origin == "other side" or not h.free > 0 or len(h.members) < h.dof + 2:
            return None
        gain = float(np.sum(scorer.c_out - h.cost[h.members]))
        if gain <= h.dof * scorer.param_price(len(h.members)):
            return None
        g = refit(h, h.members, "other side", flip=True)
        return g if g is not None and g.free < h.free else None

    def add(hs: Sequence[Hypothesis | None]) -> None:
        """New hypotheses into the pool, each with its other side (:func:`other_side_of`),
        and those growth passed on the way (:func:`grow`)."""
        hs = [*hs, *passed]
        passed.clear()
        for h in hs:
            if h is None:
                continue
            k_ = identity(h)
            if k_ not in seen:
                seen.add(k_)
                pool.append(h)
                add([other_side_of(h)])

    # ---- the noise level from plain fits at the seed contacts, then the seeds
    anchors = _farthest(rep, policy.max_seeds, rng)
    plain: list[dict[str, FitResult]] | None = None
    if policy.noise is None:
        plain = _plain_many(context(sigma, False), anchors, executor)
        best = [min((_rms_dof(f) for f in fits.values() if f), default=math.inf)
                for fits in plain]
        # seeds whose nearest contacts straddle two surfaces (a junction, a slot) measure the
        # mismatch, not the noise
        sigma = bounded(_noise_from_seeds(np.array([b for b in best if math.isfinite(b)])))
        scorer.set_sigma(sigma)
        if diagnostics is not None:
            diagnostics["sigma_seeds"] = (sigma, sorted(best))
    add(grow_new([make(k, f, mem, rd_, "seed")
                  for hs in _seed_many(context(sigma, True), anchors, executor, plain)
                  for k, mem, rd_, f in hs]))

    history: list[float] = []
    chosen: list[Hypothesis] = []
    rim_seeded: set[tuple[str, int]] = set()   # (type, contact) rim seeds made (once each)
    messages: list[str] = []
    for _ in range(policy.rounds):
        for _ in range(policy.em_rounds):
            for h in pool:
                scorer.score(h)
            chosen = scorer.select(pool)
            total = scorer.total(chosen)
            history.append(total)
            if len(history) > 1 and total >= history[-2] - 1e-6 * abs(history[-2]):
                break
            # assignment -> refit -> growth
            assign = scorer.assign(chosen)
            new: list[Hypothesis | None] = []
            for i, h in enumerate(chosen):
                mem = np.flatnonzero(assign == i)
                g = refit(h, mem, "refit")
                if g is not None:
                    new.append(grow(g))
            add(new)
            # noise level from the assigned residuals
            if policy.noise is None and chosen:
                R = np.concatenate([np.abs(h.res[scorer.best_reading(h)[assign == i]])
                                    for i, h in enumerate(chosen)])
                s_new = bounded(truncated_sigma(R, scorer.sigma, policy.k_sigma))
                if abs(s_new - scorer.sigma) > 0.05 * scorer.sigma:
                    scorer.set_sigma(s_new)
        # ---- further proposals: unions, simpler types, seeds among unexplained contacts
        assign = scorer.assign(chosen)
        current = scorer.contact_costs(chosen)
        extra: list[Hypothesis | None] = []
        payable: list[tuple[str, ...]] = []   # per selected primitive, the types that could pay
        for i, h in enumerate(chosen):
            mem = np.flatnonzero(assign == i)
            # the same contacts as every other type (BIC decides), and as its own type from
            # scratch where the robot's sweep cuts it: warm refits keep the free side the seed
            # took, and a surface fitted on the wrong side of its contacts' spheres is cut.
            # A richer type is fitted only where it could pay for its extra parameters: on
            # these contacts and their neighbours (where its growth goes first) it can at best
            # explain each exactly (cost c_in) and clear the cut support, a gain of at most
            # ``bound``
            near_mem = np.union1d(mem, np.flatnonzero(adj[mem].any(axis=0)))
            bound = float(np.sum(current[near_mem] - scorer.c_in)) + h.free * scorer.c_out
            payable.append(tuple(k for k in kinds if MODELS[k].dof <= h.dof or bound
                                 > (MODELS[k].dof - h.dof) * scorer.param_price(len(mem))))
            for k in payable[-1]:
                if (k != h.kind or h.free > 0) and len(mem) >= MODELS[k].dof + 2:
                    extra.append(refit(h, mem, "other type" if k != h.kind else "cold refit",
                                       kind=k, cold=True))
            # the same surface on its contacts and every unexplained one within the seeds'
            # tolerance (growth admits only those within k_sigma; contacts another selected
            # primitive explains are that one's)
            extra.extend(grow_new([capture(h, np.union1d(mem, np.flatnonzero(assign < 0)))]))
            # the member with the most influence on it (Cook's distance) read otherwise: by
            # each of its other readings, and as an outlier, and so on down that chain.  A fit
            # bent towards one contact's reading (a side read as the sphere, a contact on an
            # edge or on another surface) fits that contact closely and the others worse, and
            # assignment and warm refits keep it there; without the contact it is fitted from
            # scratch
            g, g_mem = h, mem
            while len(g_mem) > g.dof + 1:
                rows = scorer.best_reading(g)[g_mem]
                cook = _influence(g, rows, scorer.residuals(g)[rows], readings)
                k_ = int(np.argmax(cook))
                if not cook[k_] > policy.influence_limit:
                    break
                for row in np.flatnonzero(readings.contact == g_mem[k_]):
                    u = (refit(g, g_mem, "re-reading", reread=(k_, int(row)))
                         if row != rows[k_] else None)
                    if u is not None:
                        extra.append(grow(u))
                g = refit(g, np.delete(g_mem, k_), "influence", cold=True)
                if g is None:
                    break
                extra.append(grow(g))
                g_mem = g.members
            for j in range(i + 1, len(chosen)):
                other = np.flatnonzero(assign == j)
                union = np.union1d(mem, other)
                # the union as each of the pair's types (warm), near or far: two patches of
                # one wall touched far apart (growth only reaches neighbours) ...
                for hh in (h, chosen[j]):
                    u = refit(hh, union, "union")
                    if u is not None:
                        extra.append(grow(u))
                if not adj[np.ix_(mem, other)].any():
                    continue
                # ... and, for neighbours, as any richer type: two patches of one curved
                # surface (the tangent planes of a post touched from two sides)
                richer = max(h.dof, chosen[j].dof)
                for k in kinds:
                    if k not in (h.kind, chosen[j].kind) and MODELS[k].dof > richer:
                        u = refit(h, union, "union", kind=k)
                        if u is not None:
                            extra.append(grow(u))
        left = np.flatnonzero(assign < 0)
        seeded = _seeded(kinds)
        # seeds at a selected primitive's unexplained neighbours, among its contacts and the
        # unexplained ones, as its type and each richer one that could pay for its extra
        # parameters there.  A fit that settled on the wrong member of a tangent family
        # explains most of a surface's contacts exactly and leaves the rest too far from it
        # for growth; the consensus of minimal sets through one of those finds the member
        # through them all.  A simpler type can read a surface's contacts by other readings (a
        # plane tangent to the elbow spheres that touched a post by their link sides) and leave
        # its other contacts unexplained, too few for a seed of their own
        for i, h in enumerate(chosen):
            mem = np.flatnonzero(assign == i)
            rim = np.array([c for c in left[adj[np.ix_(left, mem)].any(axis=1)]
                            if (h.kind, int(c)) not in rim_seeded], dtype=np.int64)
            if len(rim) == 0 or len(mem) < h.dof + 1:
                continue
            rim_kinds = tuple(k for k in kinds if k == h.kind or (
                k in payable[i] and MODELS[k].dof > h.dof and k in seeded))
            ctx = replace(context(scorer.sigma, True), kinds=rim_kinds,
                          order=_restricted_order(order, np.union1d(mem, left)))
            picks = [int(rim[k]) for k in _farthest(rep[rim], min(2, len(rim)), rng)]
            rim_seeded.update((h.kind, c) for c in picks)
            extra.extend(grow_new([make(k, f, m_, rd_, "rim seed")
                                   for hs in _seed_many(ctx, picks, executor)
                                   for k, m_, rd_, f in hs]))
        n_seeds = min(policy.max_seeds // 2, len(left) // min_need)
        if n_seeds >= 1:
            ctx = replace(context(scorer.sigma, True), order=_restricted_order(order, left))
            picks = [int(left[i]) for i in _farthest(rep[left], n_seeds, rng)]
            extra.extend(grow_new([make(k, f, mem, rd_, "seed")
                                   for hs in _seed_many(ctx, picks, executor)
                                   for k, mem, rd_, f in hs]))
        n_before = len(pool)
        add(extra)
        if len(pool) == n_before:
            break
    for h in pool:
        scorer.score(h)
    chosen = scorer.select(pool)
    history.append(scorer.total(chosen))
    if diagnostics is not None:
        diagnostics.update(pool=pool, scorer=scorer, chosen=chosen)
    assign = scorer.assign(chosen)
    reading = prior_best.copy()
    posterior = np.exp(readings.log_prior)
    residual = np.full(len(readings), np.nan)
    for i, h in enumerate(chosen):
        mem = assign == i
        reading[mem] = scorer.best_reading(h)[mem]
        post = scorer.posterior(h)
        rows = np.isin(readings.contact, np.flatnonzero(mem))
        posterior[rows] = post[rows]
        residual[rows] = h.res[rows]
    return Inference(tuple(chosen), assign, reading, posterior, scorer.sigma, history[-1], extent,
                     tuple(history), tuple(messages), residual,
                     scorer.evidence_without_best(chosen))


def _influence(h: Hypothesis, rows: IntArray, residual: FloatArray, readings: Readings
               ) -> FloatArray:
    """Cook's distance on ``h`` of each of its members, read by ``rows`` with ``residual``."""
    pos = Readings.fit_order(readings.sphere[rows])
    res = np.empty(len(rows))
    res[pos] = residual
    return influence(h.fit, readings.fit_data(rows), res)[pos]


def _restricted_order(order: IntArray, allowed: IntArray) -> IntArray:
    """``order`` with each row keeping only the contacts in ``allowed`` (in the same order),
    padded with the others after them (seed neighbourhoods among unexplained contacts)."""
    ok = np.zeros(order.shape[1], dtype=bool)
    ok[allowed] = True
    keep = ok[order]
    return np.take_along_axis(order, np.argsort(~keep, axis=1, kind="stable"), axis=1)


def _rms_dof(fit: FitResult) -> float:
    r = fit.residuals
    return float(np.sqrt(np.sum(r * r) / max(len(r) - MODELS[fit.kind].dof, 1)))
