"""From a logged run to a map: detect → classify (B) → fit-and-grow → SurfaceMap.

``reconstruct(run, B=...)`` is the public entry point the CLI and notebooks share.  It is pure:
it reads nothing and writes nothing (see ``write_reconstruction`` for the outputs).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools._parallel import one_blas_thread, worker_pool
from wholearm_tools.contact_table import ContactTable
from wholearm_tools.errors import InputError
from wholearm_tools.logs.records import Run
from wholearm_tools.mapfile import MappedPrimitive, SurfaceMap
from wholearm_tools.robot.model import RobotModel

#: most maps learning the drives makes (the first at the readings)
LEARNING_PASSES = 3

#: primitive types tried by fit-and-grow, by workspace dimension
KINDS_BY_DIM = {2: ("line", "circle"), 3: ("plane", "sphere", "cylinder", "cone", "torus")}


@dataclass(frozen=True, slots=True)
class ReconstructParams:
    """Options of :func:`reconstruct`.

    B : smallest expected surface curvature radius [m] (dilation of the robot in eq. 2)
    causal : classify with the map as the robot saw it live instead of the whole run's map
    kinds : primitive types to consider (default: all of the run's dimension)
    loss : robust loss of the fits ("linear", "huber", "cauchy")
    noise : residual noise level [m]; None estimates it
    free_hints : number of robot poses sampled as free-space hints for the fits
    use_sweep : score hypotheses against the B-dilated swept map (the free-space term)
    workers : processes for the seed fits (None: every core, at most 8); the map does not
        depend on it
    learn_compliance, learn_backlash : learn the drives' compliance, play, from a first map
        made at the readings (:func:`wholearm_tools.calibration.estimate_drives`), then
        reconstruct at the links' angles; for encoders on the motor side of drives whose
        stiffness, play is not known (a known one is given on the robot instead)
    """

    B: float = 0.02
    causal: bool = False
    kinds: tuple[str, ...] | None = None
    loss: str = "huber"
    noise: float | None = None
    free_hints: int = 400
    use_sweep: bool = True
    workers: int | None = None
    learn_compliance: bool = False
    learn_backlash: bool = False

    def __post_init__(self) -> None:
        if not (np.isfinite(self.B) and self.B > 0):
            raise InputError(f"B must be a positive length in metres, got {self.B}")
        if self.workers is not None and not (int(self.workers) == self.workers >= 1):
            raise InputError(f"workers must be a positive integer, got {self.workers!r}")


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """Everything one reconstruction produced, for the exporters and the report."""

    run: Run
    params: ReconstructParams
    contacts: Any            # wholearm_tools.contacts.Contacts
    classification: Any      # wholearm_tools.classify.Classification
    table: ContactTable
    fits: tuple[Any, ...]    # wholearm_tools.fit.FitResult per primitive, in map order
    surface_map: SurfaceMap
    timings: dict[str, float] = field(default_factory=dict)
    messages: tuple[str, ...] = ()

    @property
    def planar(self) -> bool:
        return self.run.robot.planar


def contact_table(robot: RobotModel, contacts: Any, classification: Any) -> ContactTable:
    """Per-contact fit geometry from detected and classified contacts.

    A contact on link ``n`` is either on the sphere at the outer end of the link (the tip for the
    last link, a joint for inner links; centre = that joint's position at the contact
    configuration, radius ``robot.contact_radius(n, tip=True)``) or on the link's side (segment
    joint n → joint n + 1, radius ``link_radii[n]``).  Ambiguous contacts are used as the likelier
    class; their large variance keeps their weight low.
    """
    m = len(contacts)
    link = np.asarray(contacts.link, dtype=np.int64)
    seg_a, seg_b, tip_radius, link_radius = _link_geometry(robot, contacts.q, link)
    p_tip = np.asarray(classification.p_tip, dtype=float)
    label = np.asarray(classification.label)
    used_as_tip = np.where(label == "ambiguous", p_tip >= 0.5, label == "tip")
    return ContactTable(
        t=contacts.t, link=link, p_tip=p_tip, label=label, variance=classification.variance,
        used_as_tip=used_as_tip, tip_center=seg_b, tip_radius=tip_radius, seg_a=seg_a,
        seg_b=seg_b, link_radius=link_radius, primitive=np.full(m, -1),
        residual=np.full(m, np.nan), t_settle=contacts.t_settle, t_end=contacts.t_end,
        p_link=contacts.p_link,
    )


def _link_geometry(robot: RobotModel, q: NDArray[np.float64], link: NDArray[np.int64]
                   ) -> tuple[NDArray, NDArray, NDArray, NDArray]:
    """Link ``link[i]`` at configuration ``q[i]``: its axis ``seg_a → seg_b`` (joint ``n`` to
    joint ``n + 1``; ``seg_b`` is also the centre of its outer sphere), the outer sphere's
    radius (tip or joint) and the link's radius."""
    m, dim = len(link), robot.dim
    pts = robot.joint_positions(q) if m else np.zeros((0, robot.dof + 1, 3))
    rows = np.arange(m)
    return (pts[rows, link, :dim], pts[rows, link + 1, :dim],
            np.array([robot.contact_radius(int(k), tip=True) for k in link]),
            robot.link_radii[link] if m else np.zeros(0))


def free_space_hints(robot: RobotModel, q: NDArray[np.float64], count: int) -> NDArray:
    """Points the robot occupied during the run (free space), subsampled evenly: ``(K, d)``."""
    if len(q) == 0 or count <= 0:
        return np.zeros((0, robot.dim))
    idx = np.unique(np.linspace(0, len(q) - 1, min(count, len(q))).round().astype(int))
    a, b = robot.link_segments(q[idx])
    mid = 0.5 * (a + b)
    return np.concatenate([a, mid, b], axis=1).reshape(-1, 3)[:, : robot.dim]


#: smallest geometric noise level assumed for contacts [m] when the log gives none
DEFAULT_NOISE_FLOOR = 1e-5


#: fixed-point rounds of a joint's noise scale at rest, and the fewest samples at rest it needs
_REST_ROUNDS = 10
_REST_MIN = 50


def position_noise_floor(robot: RobotModel, q: NDArray[np.float64]) -> float:
    """Geometric resolution of a contact from the log's encoder noise [m].

    Per joint, the white-noise scale of the measured positions is the MAD of their second
    differences divided by ``sqrt(6)``; a point at the robot's reach moves by
    ``reach * sqrt(sum sigma_j^2)``.  Floored at :data:`DEFAULT_NOISE_FLOOR` / 10.

    Smooth motion cancels in second differences only where the log rate is high against the
    arm's accelerations: at the 50 Hz many rigs log at, a controller's transients reach them
    and the scale over the whole log is motion, not noise.  So the scale is also taken over
    the joint's samples at rest (both first differences within ``3 sqrt 2`` scales, down to a
    fixed point) and the smaller kept: the contacts are read at rest.  A quantised encoder
    held still reads a constant (a MAD of zero) where motion dithers its counts, so the figure
    at rest is floored at one count's MAD scale: it takes out the motion, not the quantisation
    the whole log shows."""
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or len(q) < 5:
        return DEFAULT_NOISE_FLOOR
    d2 = np.diff(q, n=2, axis=0)

    def scale(x: NDArray[np.float64]) -> float:
        return float(1.4826 * np.median(np.abs(x - np.median(x))) / np.sqrt(6.0))

    sig = np.array([scale(c) for c in d2.T])
    # a quantised signal at rest has zero MAD: count one quantum step as the noise then
    steps = np.abs(np.diff(q, axis=0))
    quantum = np.array([np.min(c[c > 0]) if np.any(c > 0) else 0.0 for c in steps.T])
    sig = np.maximum(sig, quantum / np.sqrt(12.0))
    # the MAD scale of one-count second differences (above quantum / sqrt 12)
    count = 1.4826 * quantum / np.sqrt(6.0)
    for j in range(q.shape[1]):
        s = sig[j]
        for _ in range(_REST_ROUNDS):
            still = steps[:, j] <= 3.0 * np.sqrt(2.0) * s
            rest = still[1:] & still[:-1]
            if np.count_nonzero(rest) < _REST_MIN:
                break
            nxt = min(sig[j], max(scale(d2[rest, j]), count[j]))
            if not nxt < 0.95 * s:   # settled (within the estimate's own precision)
                break
            s = nxt
        sig[j] = s
    return float(max(float(robot.reach) * float(np.sqrt(np.sum(sig * sig))),
                     DEFAULT_NOISE_FLOOR / 10))


#: repeated contacts lie within this many position noise floors of each other (fit_table)
DUPLICATE_TOL = 3.0


def duplicate_groups(table: ContactTable, tol: float) -> NDArray[np.int64]:
    """Group id of each contact: contacts made on the same link, used the same way, in the same
    configuration (tip centre and link axis within ``tol`` metres) share a group, ``(M,) int``.

    Exploration strategies return to the same configuration again and again (a joint limit, a
    retreat pose); counted separately, such repeats would outvote everything else in the fits
    and in model selection although they carry the information of one contact.
    """
    m = len(table)
    group = np.full(m, -1, dtype=np.int64)
    key = np.hstack([table.tip_center, table.seg_a, table.seg_b])
    g = 0
    for i in range(m):
        if group[i] >= 0:
            continue
        same = ((group < 0) & (table.link == table.link[i])
                & (table.used_as_tip == table.used_as_tip[i])
                & (np.max(np.abs(key - key[i]), axis=1) <= tol))
        group[same] = g
        g += 1
    return group


def fit_data_from_table(table: ContactTable, free_points: NDArray | None = None,
                        rows: NDArray | None = None) -> Any:
    """The fitter's input (tips first, then links) and the table row of each fit contact.

    ``rows`` restricts the fit to these table rows (e.g. one per group of duplicates).
    """
    from wholearm_tools.fit import FitData

    use = np.zeros(len(table), dtype=bool)
    use[np.arange(len(table)) if rows is None else np.asarray(rows, dtype=int)] = True
    tips = np.flatnonzero(table.used_as_tip & use)
    links = np.flatnonzero(~table.used_as_tip & use)
    from wholearm_tools.fit.data import MIN_WEIGHT

    # 1/sigma^2 from the classification, relative to the best contact and floored so that
    # ambiguous contacts still count a little (the robust loss and the segmentation's residual
    # test take care of wrongly labelled ones)
    weight = 1.0 / table.variance
    weight = np.maximum(weight / weight.max(), MIN_WEIGHT) if len(weight) else weight
    data = FitData.create(
        tip_points=table.tip_center[tips], tip_radius=table.tip_radius[tips],
        tip_weight=weight[tips], link_a=table.seg_a[links], link_b=table.seg_b[links],
        link_radius=table.link_radius[links], link_weight=weight[links],
        free_points=free_points, dim=table.dim,
    )
    return data, np.concatenate([tips, links])


def fit_table(table: ContactTable, *, planar: bool, B: float, kinds: tuple[str, ...] | None = None,
              loss: str = "huber", noise: float | None = None,
              free_points: NDArray | None = None, meta: dict[str, Any] | None = None,
              noise_floor: float = DEFAULT_NOISE_FLOOR, merge_duplicates: bool = True,
              swept: Any = None, base: NDArray | None = None, workers: int | None = None,
              candidates: LinkCandidates | None = None, reach: float | None = None,
              policy: Any = None,
              ) -> tuple[SurfaceMap, tuple[Any, ...], ContactTable, tuple[str, ...]]:
    """The inference loop over a contact table → (map, fits, table with assignments, messages).

    Repeated contacts (same link, same configuration within ``DUPLICATE_TOL * noise_floor``)
    are one contact (see :func:`duplicate_groups`) and share its assignment.  Each contact enters as
    its readings (:mod:`wholearm_tools.fit.readings`: sphere or side of each candidate link,
    ``candidates`` from :func:`link_candidates`); :func:`wholearm_tools.fit.infer.infer`
    selects the primitives; each is refitted with the robust ``loss`` on its contacts and
    passes :func:`wholearm_tools.fit.gate.report_gate` (kinematic errors of ``policy.
    kinematic_error`` of ``reach``, or of the scene size without a robot; its evidence without
    its most valuable contact, ``Inference.evidence``) or is not reported.
    ``swept`` (where the robot has been, e.g. :class:`SweptTest` of the swept map) and
    ``base`` are the free-space evidence; ``free_points`` (robot positions) tell a closed
    primitive's side.  ``workers``: processes for the seed proposals (None: every core, at
    most 8; the map does not depend on it).  Poor data never raise: the map is then empty (or
    short) and ``messages`` say why.
    """
    from wholearm_tools.fit import fit_primitive
    from wholearm_tools.fit.core import with_noise_floor
    from wholearm_tools.fit.data import FreeSpace
    from wholearm_tools.fit.gate import lying_flat, report_gate
    from wholearm_tools.fit.infer import DEFAULT_KINDS, infer, reading_posterior
    from wholearm_tools.fit.models import MODELS
    from wholearm_tools.fit.policy import FitPolicy
    from wholearm_tools.fit.readings import readings_from_contacts
    from wholearm_tools.mesh import support_extent

    policy = policy or FitPolicy(noise=noise)
    dim = 2 if planar else 3
    if table.dim != dim:
        raise InputError(f"contacts are {table.dim}-D but the map is {dim}-D")
    kinds = tuple(kinds or DEFAULT_KINDS[dim])
    bad = [k for k in kinds if k not in MODELS or MODELS[k].dim != dim]
    if bad:
        raise InputError(f"primitive type(s) {', '.join(map(repr, bad))} cannot be fitted to "
                         f"{dim}-D contacts (choose from {', '.join(DEFAULT_KINDS[dim])})")
    messages: list[str] = []
    m_all = len(table)
    group = (duplicate_groups(table, DUPLICATE_TOL * noise_floor) if merge_duplicates
             else np.arange(m_all))
    _, first = np.unique(group, return_index=True)
    reps = np.sort(first)
    if len(reps) < m_all:
        messages.append(f"{m_all - len(reps)} repeated contacts (same configuration) counted "
                        f"once: {len(reps)} distinct of {m_all}")
    slot = {int(r): k for k, r in enumerate(reps)}
    cands: dict[int, list] = {}
    if candidates is not None:
        for j in range(len(candidates.contact)):
            k = slot.get(int(candidates.contact[j]))
            if k is None:
                continue
            row = int(candidates.contact[j])
            own = int(candidates.link[j]) == int(table.link[row])
            cands.setdefault(k, []).append((
                int(candidates.link[j]), float(candidates.prior[j]), candidates.tip_center[j],
                float(candidates.tip_radius[j]), candidates.seg_a[j], candidates.seg_b[j],
                float(candidates.link_radius[j]),
                float(table.p_tip[row]) if own else float(candidates.p_tip[j])))
    rd = readings_from_contacts(table.link[reps], table.p_tip[reps], table.tip_center[reps],
                                table.tip_radius[reps], table.seg_a[reps], table.seg_b[reps],
                                table.link_radius[reps], cands)
    need = min(MODELS[k].dof for k in kinds) + 2
    if rd.n_contacts < need:
        messages.append(f"too few distinct contacts to fit a primitive: {rd.n_contacts} given, "
                        f"at least {need} needed (a {kinds[0]} has {MODELS[kinds[0]].dof} "
                        "parameters and must explain more contacts than that)")
    # one FreeSpace for the search and the report's fits
    free_points = FreeSpace.of(_with_contact_hints(table, free_points), table.dim)
    with one_blas_thread(), worker_pool(workers) as pool:
        inf = infer(rd, kinds=kinds, policy=policy, B=float(B), noise_floor=noise_floor,
                    swept=swept, base=base, free_points=free_points, reach=reach,
                    executor=pool)
    sigma = inf.sigma
    id_scale = reach if reach else inf.extent
    sigma_kin = max(sigma, policy.kinematic_error * id_scale)

    assignment = np.full(m_all, -1, dtype=np.int64)
    residual = np.full(m_all, np.nan)
    used_as_tip = table.used_as_tip.copy()
    primitives: list[MappedPrimitive] = []
    fits: list[Any] = []
    for k, h in enumerate(inf.selected):
        members = np.flatnonzero(inf.assignment == k)
        idx = inf.reading[members]
        post = np.maximum(inf.posterior[idx], 0.05)
        data = rd.fit_data(idx, post, free_points)
        fit = h.fit
        if loss != "linear":
            robust = fit_primitive(h.kind, data, loss=loss, noise=sigma,
                                   initial=dict(h.fit.params), free_side=h.fit.free_side)
            if robust:
                fit = robust
        # the intervals the map states are those of the error model the gate judges it by:
        # contacts off by sigma_kin, or by the fit's own residuals where they are larger
        fit = with_noise_floor(fit, data, sigma_kin)
        open_touch = np.empty(len(idx), dtype=bool)
        open_touch[rd.fit_order(rd.sphere[idx])] = lying_flat(
            fit, rd, members, policy.k_sigma * sigma_kin, float(B))
        gate = report_gate(fit, data, sigma_kin, policy.max_rel_std, B=float(B),
                           open_touch=open_touch, evidence=float(inf.evidence[k]))
        if not gate:
            messages.append(f"a {h.kind} on {len(members)} contacts not reported: "
                            f"{gate.reason}")
            continue
        pid = len(primitives)
        order = rd.fit_order(rd.sphere[idx])
        res_m = fit.residuals[order]
        rows = reps[members]
        for row, r, sph in zip(rows, res_m, rd.sphere[idx], strict=True):
            dup = group == group[row]
            assignment[dup] = pid
            residual[dup] = r
            used_as_tip[dup] = bool(sph)
        prim = fit.primitive
        a, b = rd.a[idx], rd.b[idx]
        _, t = prim.segment_signed_distance(a, b, free_side=fit.free_side)
        support = np.asarray(prim.closest_point(a + np.asarray(t)[:, None] * (b - a)))
        ci95 = {key: (np.asarray(hi, dtype=float) - np.asarray(lo, dtype=float)) / 2
                for key, (lo, hi) in fit.ci95.items()}
        dup_all = np.isin(group, group[rows])
        primitives.append(MappedPrimitive(
            id=pid, kind=fit.kind, params=dict(fit.params), ci95=ci95,
            covariance=np.asarray(fit.covariance if fit.covariance is not None else
                                  np.zeros((0, 0))),
            support={"tip": int(np.sum(used_as_tip[dup_all])),
                     "link": int(np.sum(~used_as_tip[dup_all]))},
            rms_residual=float(fit.rms_residual),
            extent=support_extent(fit.kind, fit.params, support)))
        fits.append(fit)
    if rd.n_contacts >= need and not primitives:
        messages.append("no primitive both explains more contacts than it has parameters and "
                        "is determined by them")
    # the classification after the fit: each contact's posterior over its readings under its
    # primitive, at the kinematic error sigma_kin (as the gate): readings whose residuals differ
    # by less than the arm's kinematic errors (a tip at the seam of its link's side and an
    # equal sphere) are not told apart by the map and keep their prior odds (eq. 2)
    post_kin = reading_posterior(rd, np.nan_to_num(inf.residual, nan=0.0), sigma_kin)
    p_map = table.p_tip.copy()
    link_map = table.link.copy()
    for k, row in enumerate(reps):
        rows_k = np.flatnonzero(rd.contact == k)
        if assignment[row] < 0:
            continue
        dup = group == group[row]
        p_map[dup] = float(np.sum(post_kin[rows_k][rd.sphere[rows_k]]))
        link_map[dup] = int(rd.link[inf.reading[k]])
    from wholearm_tools.classify.tip import labels_from_p_tip

    unexplained_rows = np.flatnonzero(assignment < 0)
    unexplained = table.tip_center[unexplained_rows[used_as_tip[unexplained_rows]]]
    counts = {"count": m_all, "tip": int(np.sum(table.label == "tip")),
              "link": int(np.sum(table.label == "link")),
              "ambiguous": int(np.sum(table.label == "ambiguous")),
              "unexplained": len(unexplained_rows)}
    table = dataclasses.replace(table, used_as_tip=used_as_tip).with_assignment(assignment,
                                                                                 residual)
    table = table.with_map_classification(np.clip(p_map, 0.0, 1.0), labels_from_p_tip(p_map),
                                          link_map)
    counts.update({f"{k}_map": int(np.sum(table.label_map == k))
                   for k in ("tip", "link", "ambiguous")})
    moved = int(np.sum(table.link_by_map != table.link))
    if moved:
        messages.append(f"{moved} contact(s) put on another link of their rigid group: the "
                        "fitted map holds only that link's reading (link_by_map)")
    surface_map = SurfaceMap(planar=planar, B=float(B), primitives=tuple(primitives),
                             contacts=counts, unexplained=unexplained,
                             meta={**dict(meta or {}), "noise": sigma,
                                   "kinematic_error": sigma_kin})
    return surface_map, tuple(fits), table, tuple(messages)


class SweptTest:
    """Where the robot has been: ``SweptTest(map)(points)`` is True inside a cell of the swept
    map (:func:`wholearm_tools.classify.swept.swept_map`) whose centre was inside the robot."""

    def __init__(self, smap: Any) -> None:
        self.map = smap
        self.resolution = float(smap.resolution)

    def __call__(self, points: NDArray) -> NDArray[np.bool_]:
        from wholearm_tools.classify.swept import NEVER

        return np.asarray(self.map.first_at(points)) < NEVER


@dataclass(frozen=True, slots=True, eq=False)
class LinkCandidates:
    """The links a contact may have been on where the joint signals cannot tell (a rigid
    group), one row per (contact, link): ``contact`` (R,) table row, ``link`` (R,), ``prior``
    (R,) the link's share from the signals and the swept map, and the link's geometry at the
    contact as in :class:`ContactTable` (``tip_center``, ``tip_radius``, ``seg_a``, ``seg_b``,
    ``link_radius``), and ``p_tip`` (R,) eq. (2) for that link (0.5 where not evaluated)."""

    contact: NDArray[np.int64]
    link: NDArray[np.int64]
    prior: NDArray[np.float64]
    tip_center: NDArray[np.float64]
    tip_radius: NDArray[np.float64]
    seg_a: NDArray[np.float64]
    seg_b: NDArray[np.float64]
    link_radius: NDArray[np.float64]
    p_tip: NDArray[np.float64]


def link_candidates(robot: RobotModel, contacts: Any,
                    tip_probability: Any = None) -> LinkCandidates:
    """Every link with a non-zero ``contacts.link_prior`` of the contacts that have more than
    one, with its geometry at the contact configuration (see :func:`contact_table`) and its
    tip probability ``tip_probability(contacts on those links) -> (R,)`` (eq. 2 evaluated as
    if the joint signals had named that link; 0.5 without it)."""
    prior = np.asarray(contacts.link_prior, dtype=float).reshape(len(contacts), -1)
    open_ = (prior > 0).sum(axis=1) > 1
    contact, link = np.nonzero((prior > 0) & open_[:, None])
    seg_a, seg_b, tip_radius, link_radius = _link_geometry(robot, contacts.q[contact], link)
    p_tip = np.full(len(contact), 0.5)
    if tip_probability is not None and len(contact):
        moved = dataclasses.replace(contacts.select(contact), link=link,
                                    link_prior=np.eye(contacts.n_joints)[link])
        p_tip = np.asarray(tip_probability(moved), dtype=float)
    return LinkCandidates(
        contact=contact.astype(np.int64), link=link.astype(np.int64),
        prior=prior[contact, link], tip_center=seg_b, tip_radius=tip_radius, seg_a=seg_a,
        seg_b=seg_b, link_radius=link_radius, p_tip=p_tip)


def _with_contact_hints(table: ContactTable, free_points: NDArray | None) -> NDArray | None:
    """Free-space hints plus, for every contact, two points on the contacting link's axis just
    behind its outer end (1.5 and 3 contact radii inwards): the robot itself was there, right
    in front of the surface, which tells the free side of the surface locally (a tip on a
    bore wall of radius R fits a cylinder of radius R - 2w seen from outside just as well)."""
    if len(table) == 0:
        return free_points
    d = table.seg_a - table.seg_b
    length = np.maximum(np.linalg.norm(d, axis=1), 1e-12)
    w = np.maximum(table.tip_radius, table.link_radius)
    pts = [table.seg_b + np.minimum(k * w / length, 0.5)[:, None] * d for k in (1.5, 3.0)]
    own = np.concatenate(pts, axis=0)
    if free_points is None or len(free_points) == 0:
        return own
    return np.concatenate([np.asarray(free_points, dtype=float), own], axis=0)


def reconstruct(run: Run, B: float = 0.02, *, progress: Callable[[str], None] | None = None,
                **options: Any) -> Reconstruction:
    """Detect, classify and fit a logged run.

    Parameters
    ----------
    run : Run (from ``wholearm_tools.logs.read_run`` or the simulator)
    B : float, smallest expected surface curvature radius [m]
    progress : called with the name of each step as it starts (for a status line)
    **options : fields of :class:`ReconstructParams`

    Returns
    -------
    Reconstruction; a run where nothing could be fitted still returns one (with no primitives
    and messages saying why): the CLI decides whether that is an error.
    """
    params = ReconstructParams(B=B, **options)
    with one_blas_thread():
        if not (params.learn_compliance or params.learn_backlash):
            return _reconstruct(run, params, progress)
        return _learning_drives(run, params, progress)


def _learning_drives(run: Run, params: ReconstructParams,
                     progress: Callable[[str], None] | None) -> Reconstruction:
    """The map at the readings, then in turn the drives' compliance and/or play that put the
    map's contacts on its primitives and the map again at the links' angles under them: a
    map made at a closer drive model holds more of the contacts, which tell the model
    better.  Stops when every learned value moves by less than its standard error, after at
    most :data:`LEARNING_PASSES` maps."""
    from wholearm_tools.calibration import estimate_drives

    learn = {"compliance": params.learn_compliance, "backlash": params.learn_backlash}
    for what, on in learn.items():
        if on and np.any(getattr(run.robot, f"joint_{what}") > 0):
            raise InputError(f"the drives' {what} is given: it cannot be learned as well")
    rec = _reconstruct(run, params, progress)
    timings = dict(rec.timings)
    estimate = None
    for _ in range(LEARNING_PASSES - 1):
        new = estimate_drives(rec, **learn)
        if not new.readings:
            break
        moved = estimate is None or any(
            np.any(np.abs(getattr(new, w) - getattr(estimate, w)) > getattr(new, f"{w}_std"))
            for w in new.learned)
        estimate = new
        if not moved:
            break
        robot = dataclasses.replace(run.robot, joint_compliance=estimate.compliance,
                                    joint_backlash=estimate.backlash)
        rec = _reconstruct(dataclasses.replace(run, robot=robot), params, progress)
        timings = {k: timings.get(k, 0.0) + v for k, v in rec.timings.items()}
    if estimate is None:
        what = " and ".join(w for w, on in learn.items() if on)
        return dataclasses.replace(rec, messages=(
            *rec.messages, f"the drives' {what} was not learned: no reported primitive "
            "holds the contacts it would be learned from"))
    meta = {**rec.surface_map.meta, **{f"joint_{w}_std": getattr(estimate, f"{w}_std").tolist()
                                       for w in estimate.learned}}
    return dataclasses.replace(
        rec, surface_map=dataclasses.replace(rec.surface_map, meta=meta), timings=timings,
        messages=(*rec.messages, estimate.describe()))


def _reconstruct(run: Run, params: ReconstructParams,
                 progress: Callable[[str], None] | None) -> Reconstruction:
    from wholearm_tools.classify import ClassifyParams, tip_probability
    from wholearm_tools.contacts import detect_contacts

    say = progress or (lambda _: None)
    timings: dict[str, float] = {}
    clock = time.perf_counter()
    say("detecting contacts")
    contacts = detect_contacts(run.log, run.robot)
    timings["detect"] = time.perf_counter() - clock
    clock = time.perf_counter()
    say(f"classifying {len(contacts)} contacts (eq. 2)")
    classification = tip_probability(run, contacts, params.B, causal=params.causal)
    timings["classify"] = time.perf_counter() - clock
    table = contact_table(run.robot, contacts, classification)
    clock = time.perf_counter()
    # where the links were (the drives' readings less the transmissions' deflection and
    # play); the resolution of a contact is the encoders' (a deflection subtracted from the
    # torques is no quantised reading: its rest would show no noise)
    q_link = run.robot.link_angles(run.log.q, run.log.tau_cmd)
    hints = free_space_hints(run.robot, q_link, params.free_hints)
    floor = position_noise_floor(run.robot, np.asarray(run.log.q))
    meta = {"source": run.source, "causal": params.causal, "duration": run.log.duration}
    if q_link is not run.log.q:
        meta["joint_compliance"] = run.robot.joint_compliance.tolist()
        meta["joint_backlash"] = run.robot.joint_backlash.tolist()
    if len(table) == 0:
        surface_map = SurfaceMap(planar=run.robot.planar, B=params.B, primitives=(),
                                 contacts={"count": 0}, meta=meta,
                                 unexplained=np.zeros((0, run.robot.dim)))
        fits: tuple[Any, ...] = ()
        messages: tuple[str, ...] = ("no contacts detected in the run",)
    else:
        from wholearm_tools.classify.swept import swept_map

        say(f"fitting primitives to {len(table)} contacts")
        # the other candidate links' readings are judged with the lean the run's stops need,
        # measured once over all of them (a property of the run, not of the few re-read)
        same_run = ClassifyParams(driving_lean=classification.meta["driving_lean"])
        swept = (SweptTest(swept_map(run.robot, q_link, B=params.B))
                 if params.use_sweep else None)
        surface_map, fits, table, messages = fit_table(
            table, planar=run.robot.planar, B=params.B, kinds=params.kinds, loss=params.loss,
            noise=params.noise, free_points=hints, meta=meta, noise_floor=floor, swept=swept,
            base=run.robot.base, workers=params.workers,
            candidates=link_candidates(
                run.robot, contacts,
                lambda c: tip_probability(run, c, params.B, causal=params.causal,
                                          params=same_run).p_tip),
            reach=float(run.robot.reach))
    timings["fit"] = time.perf_counter() - clock
    return Reconstruction(run=run, params=params, contacts=contacts,
                          classification=classification, table=table, fits=fits,
                          surface_map=surface_map, timings=timings, messages=messages)

