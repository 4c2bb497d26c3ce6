"""The inference loop's parameters, in one frozen record.

Every number the reconstruction uses to decide what the contacts show lives here, with what it
means; nothing in :mod:`wholearm_tools.fit.infer` or :mod:`wholearm_tools.fit.gate` is a module
constant.  The defaults are the method's, stated in physical terms (probabilities, noise
levels, sigmas); none is tuned to a scenario.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from wholearm_tools.errors import InputError


@dataclass(frozen=True, slots=True)
class FitPolicy:
    """What the inference loop assumes and how hard it searches.

    The score (negative log-likelihood in nats, :mod:`wholearm_tools.fit.infer`)
    ------------------------------------------------------------------------
    outlier_prior : prior probability that a detected contact is on no surface the map will
        hold (a false detection, a surface touched too rarely to fit); an unexplained contact
        costs ``-log(outlier_prior) + log(L / (sqrt(2 pi) sigma))`` against an explained one's
        ``-log(prior of its reading) + z^2 / 2``, with ``L`` the scene size.
    bic : cost of each primitive parameter, ``bic * log(N) / 2`` (BIC: 1).
    k_sigma : a reading farther than ``k_sigma`` noise sigmas from a hypothesis does not join
        it in growth (the score itself is continuous).
    sweep_tol_sigmas, sweep_tol_min : the robot's sweep contradicts a hypothesis where it cuts
        into the surface deeper than ``max(sweep_tol_sigmas * sigma, sweep_tol_min)`` [m].

    The search (proposals never accept or reject; they only offer hypotheses)
    -----------------------------------------------------------------------
    max_seeds : seed contacts per round (farthest-point sampled).
    seed_extra : a seed's neighbourhood is its ``dof + 2 + seed_extra`` nearest contacts, cut
        to the consensus of ``consensus_trials`` random minimal sets (RANSAC).
    seed_accept : once the noise level is estimated, a seed whose fit is poorer than this many
        sigmas (dof-corrected RMS) loses its worst contact, one at a time.
    seed_extend : a seed fit its contacts do not determine (by the report gate's measure) tries
        up to this many further nearest contacts, one at a time.
    proposal_iterations : solver iterations of every fit a seed makes and of a refit from
        scratch: a type that does not describe its contacts does not converge in them, and is
        not worth finishing (refits warm-started from a selected primitive get 200).
    minimal_set_iterations : solver iterations of a consensus hypothesis (a minimal set fitted
        exactly).  It only has to be close enough for the inlier test: the hypothesis is the
        solver's iterate after these iterations, converged or not, and the consensus it finds
        is refitted starting from it.
    solve_precision : every fit the search makes is solved until a step would move its
        residual vector by less than this fraction of the scale it is judged at (in norm).
        For a scored proposal that scale is the noise sigma: the score would then change by
        less than ``solve_precision**2 / 2`` nats, and the parameters lie within
        ``solve_precision`` standard deviations (Mahalanobis) of the least-squares optimum.
        For a minimal set's hypothesis it is the consensus inlier tolerance (30 sigmas).
    influence_limit : a selected primitive's member whose Cook's distance exceeds this is
        proposed as an outlier (the primitive refitted without it, and so on down that chain):
        1 is the classical mark of a contact that alone moves the fit out of its own 50 %
        confidence region (``math.inf``: no such proposals).
    rounds : most proposal rounds (seeds among the contacts the selected hypotheses leave
        unexplained, refits, unions, re-readings); the loop ends earlier once a round proposes
        nothing new.  A hypothesis the last round brings into the selection gets no proposals
        of its own.
    em_rounds : most assign -> refit -> select iterations.
    neighbours : contacts per contact in the growth graph.

    The noise
    ---------
    noise : contact noise sigma [m]; None estimates it from the residuals (floored at the
        encoder resolution the pipeline passes).

    The report gate (:mod:`wholearm_tools.fit.gate`)
    ----------------------------------------------
    kinematic_error : the stated kinematic error model, as the standard deviation of a
        contact's position from encoder noise, joint offsets and link-length errors, in
        units of the robot's reach (of the scene size without a robot): 5e-4 is 0.5 mm on a
        1 m arm.
    max_rel_std : a reported primitive's worst-determined parameter combination, under that
        error model, must have a standard deviation of at most this fraction of the size of
        its support, with all its contacts and without any one of them (a primitive one
        inferred contact alone determines rests on that contact's reading).

    Types
    -----
    min_radius_over_b : the smallest admissible radius of a curved primitive, in units of B (the
        smallest expected curvature radius).
    max_radius_ratio : the largest, in units of the support's RMS spread.
    """

    outlier_prior: float = 0.05
    bic: float = 1.0
    k_sigma: float = 3.0
    sweep_tol_sigmas: float = 5.0
    sweep_tol_min: float = 2e-3
    max_seeds: int = 16
    seed_extra: int = 6
    seed_accept: float = 2.5
    seed_extend: int = 12
    consensus_trials: int = 12
    proposal_iterations: int = 30
    minimal_set_iterations: int = 10
    solve_precision: float = 0.1
    influence_limit: float = 1.0
    rounds: int = 4
    em_rounds: int = 6
    neighbours: int = 6
    noise: float | None = None
    kinematic_error: float = 5e-4
    max_rel_std: float = 0.2
    min_radius_over_b: float = 0.5
    max_radius_ratio: float = 50.0

    def __post_init__(self) -> None:
        if not 0.0 < self.outlier_prior < 1.0:
            raise InputError(f"outlier_prior must be in (0, 1), got {self.outlier_prior}")
        for name in ("bic", "k_sigma", "sweep_tol_sigmas", "kinematic_error", "max_rel_std",
                     "max_radius_ratio"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"{name} must be a positive number, got {value!r}")
        for name in ("max_seeds", "consensus_trials", "proposal_iterations",
                     "minimal_set_iterations", "rounds", "em_rounds", "neighbours"):
            if int(getattr(self, name)) < 1:
                raise InputError(f"{name} must be at least 1, got {getattr(self, name)!r}")
        if not (math.isfinite(self.solve_precision) and self.solve_precision >= 0):
            raise InputError(f"solve_precision must be a non-negative number, got "
                             f"{self.solve_precision!r}")
        if not self.influence_limit > 0:
            raise InputError(f"influence_limit must be positive, got {self.influence_limit!r}")
        if self.noise is not None and not (math.isfinite(self.noise) and self.noise > 0):
            raise InputError(f"noise must be a positive length, got {self.noise!r}")
