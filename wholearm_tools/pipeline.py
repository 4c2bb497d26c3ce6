"""From a logged run to a map: detect → classify (B) → fit-and-grow → SurfaceMap.

``reconstruct(run, B=...)`` is the public entry point the CLI and notebooks share.  It is pure:
it reads nothing and writes nothing (see ``write_reconstruction`` for the outputs).
"""

from __future__ import annotations

import dataclasses
import time
from concurrent.futures import Executor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.classify.refine import MapSurface, refine_with_map
from wholearm_tools.contact_table import ContactTable
from wholearm_tools.errors import InputError
from wholearm_tools.fit.crossing import MIN_CUTS
from wholearm_tools.logs.records import Run
from wholearm_tools.mapfile import MappedPrimitive, SurfaceMap
from wholearm_tools.robot.model import RobotModel

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
    use_sweep : reject primitives that the robot's own motion cut through (:func:`robot_sweep`)
    workers : processes for the seed fits (None: every core, at most 8); the map does not
        depend on it
    """

    B: float = 0.02
    causal: bool = False
    kinds: tuple[str, ...] | None = None
    loss: str = "huber"
    noise: float | None = None
    free_hints: int = 400
    use_sweep: bool = True
    workers: int | None = None

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
        residual=np.full(m, np.nan),
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


def robot_sweep(robot: RobotModel, q: NDArray[np.float64], *, step: float = 0.01) -> Any:
    """The robot's volume over the run as capsules (:class:`wholearm_tools.fit.data.Sweep`).

    Poses are kept whenever some joint moved by more than ``step`` radians since the last kept
    one (the arm at rest or creeping adds nothing); each pose gives its link capsules and, when
    it is wider than the last link, the tip sphere.
    """
    from wholearm_tools.fit.data import Sweep

    q = np.asarray(q, dtype=float)
    dim = robot.dim
    if len(q) == 0:
        return Sweep(np.zeros((0, dim)), np.zeros((0, dim)), np.zeros(0))
    keep = [0]
    i, n, window = 0, len(q), 256
    while True:
        # the first later sample that moved more than `step` from the last kept one
        lo = i + 1
        while lo < n:
            hi = min(lo + window, n)
            far = np.flatnonzero(np.max(np.abs(q[lo:hi] - q[i]), axis=1) > step)
            if far.size:
                break
            lo = hi
        if lo >= n:
            break
        i = lo + int(far[0])
        keep.append(i)
    pts = robot.joint_positions(q[keep])[..., :dim]           # (P, n+1, d)
    a = pts[:, :-1].reshape(-1, dim)
    b = pts[:, 1:].reshape(-1, dim)
    r = np.tile(robot.link_radii, len(keep))
    if robot.tip_radius > robot.link_radii[-1]:
        tip = pts[:, -1]
        a, b = np.vstack([a, tip]), np.vstack([b, tip])
        r = np.concatenate([r, np.full(len(keep), robot.tip_radius)])
    return Sweep(a, b, r)


#: smallest geometric noise level assumed for contacts [m] when the log gives none
DEFAULT_NOISE_FLOOR = 1e-5


def position_noise_floor(robot: RobotModel, q: NDArray[np.float64]) -> float:
    """Geometric resolution of a contact from the log's encoder noise [m].

    Per joint, the white-noise scale of the measured positions is the MAD of their second
    differences (smooth motion cancels at the log rate; quantisation counts as noise) divided
    by ``sqrt(6)``; a point at the robot's reach moves by ``reach * sqrt(sum sigma_j^2)``.
    Floored at :data:`DEFAULT_NOISE_FLOOR` / 10.
    """
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or len(q) < 5:
        return DEFAULT_NOISE_FLOOR
    d2 = np.diff(q, n=2, axis=0)
    sig = 1.4826 * np.median(np.abs(d2 - np.median(d2, axis=0)), axis=0) / np.sqrt(6.0)
    # a quantised signal at rest has zero MAD: count one quantum step as the noise then
    steps = np.abs(np.diff(q, axis=0))
    quantum = np.array([np.min(c[c > 0]) if np.any(c > 0) else 0.0 for c in steps.T])
    sig = np.maximum(sig, quantum / np.sqrt(12.0))
    return float(max(float(robot.reach) * float(np.sqrt(np.sum(sig * sig))),
                     DEFAULT_NOISE_FLOOR / 10))


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
              sweep: Any = None, base: NDArray | None = None, workers: int | None = None,
              candidates: LinkCandidates | None = None, reach: float | None = None,
              ) -> tuple[SurfaceMap, tuple[Any, ...], ContactTable, tuple[str, ...]]:
    """Fit-and-grow over a contact table → (map, fits, table with assignments, messages).

    Repeated contacts (same link, same configuration within ``3 * noise_floor``) are fitted
    once (see :func:`duplicate_groups`) and share the assignment of their representative.
    ``sweep`` (:func:`robot_sweep`) rules out primitives the robot's own motion cut through,
    ``base`` (the robot's base point) circles and spheres with free space inside that do not
    hold it.  ``workers``: processes for the seed fits (None: every core, at most 8; the map
    does not depend on it).  ``candidates`` (:func:`link_candidates`): the links each contact
    may have been on when the joint signals left it open, weighed by the fitted map into the
    table's ``link_by_map`` (without: the detected link).  ``reach`` (the robot's reach, m): the
    length the kinematic errors a reported primitive must be determined at scale with
    (:data:`REPORT_ID_NOISE`; without: the scene size).
    Poor data never raise: the map is then empty (or short) and ``messages`` say why.
    """
    from wholearm_tools.fit.segment import seed_pool

    with seed_pool(workers) as pool:
        return _fit_table(table, planar=planar, B=B, kinds=kinds, loss=loss, noise=noise,
                          free_points=free_points, meta=meta, noise_floor=noise_floor,
                          merge_duplicates=merge_duplicates, sweep=sweep, base=base, pool=pool,
                          candidates=candidates, reach=reach)


def _fit_table(table: ContactTable, *, planar: bool, B: float, kinds: tuple[str, ...] | None,
               loss: str, noise: float | None, free_points: NDArray | None,
               meta: dict[str, Any] | None, noise_floor: float, merge_duplicates: bool,
               sweep: Any, base: NDArray | None, pool: Executor | None,
               candidates: LinkCandidates | None = None, reach: float | None = None,
               ) -> tuple[SurfaceMap, tuple[Any, ...], ContactTable, tuple[str, ...]]:
    from wholearm_tools.fit import crossing, fit_primitive, segment
    from wholearm_tools.fit.core import sweep_tolerance
    from wholearm_tools.fit.models import MODELS
    from wholearm_tools.fit.segment import complete_support, drop_bending, pinning_contact
    from wholearm_tools.mesh import support_extent

    dim = 2 if planar else 3
    if table.dim != dim:
        raise InputError(f"contacts are {table.dim}-D but the map is {dim}-D")
    kinds = tuple(kinds or KINDS_BY_DIM[dim])
    bad = [k for k in kinds if k not in MODELS or MODELS[k].dim != dim]
    if bad:
        raise InputError(f"primitive type(s) {', '.join(map(repr, bad))} cannot be fitted to "
                         f"{dim}-D contacts (choose from {', '.join(KINDS_BY_DIM[dim])})")
    messages: list[str] = []
    m_all = len(table)
    group = (duplicate_groups(table, 3.0 * noise_floor) if merge_duplicates
             else np.arange(m_all))
    _, first = np.unique(group, return_index=True)
    reps = np.sort(first)
    if len(reps) < m_all:
        messages.append(f"{m_all - len(reps)} repeated contacts (same configuration) counted "
                        f"once: {len(reps)} distinct of {m_all}")
    free_points = _with_contact_hints(table, free_points)
    data, order = fit_data_from_table(table, free_points, rows=reps)
    need = min(MODELS[k].dof for k in kinds) + 3
    seg = segment(data, kinds=kinds, noise=noise, noise_floor=noise_floor,
                  min_radius=0.5 * float(B), sweep=sweep, base=base, executor=pool)
    if data.n_contacts < need:
        messages.append(f"too few distinct contacts to fit a primitive: {data.n_contacts} "
                        f"given, at least {need} needed (a {kinds[0]} has "
                        f"{MODELS[kinds[0]].dof} parameters and is checked on 3 more)")
    elif not seg.primitives:
        pts = data.contact_points()
        s = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
        if s[0] <= 0 or np.sum(s > 1e-6 * s[0]) < dim - 1:
            messages.append("all contacts are collinear or coincide: no primitive is "
                            "determined by them")
        else:
            messages.append("no primitive both explains enough contacts and is determined by "
                            "them (supports too small, degenerate or not converging)")
    seg_rows = np.full(len(table), -1, dtype=np.int64)
    seg_rows[order] = seg.assignment
    all_fits = list(seg.primitives)
    # second look: unexplained contacts whose class is uncertain, as either class
    extra, swap = _other_interpretation(table, reps, seg_rows, free_points, kinds, seg.noise,
                                        noise_floor, B, sweep, base, pool)
    from wholearm_tools.fit import residuals as fit_residuals

    merged: set[int] = set()
    for fit_x, rows, sub in extra:
        # the same surface as a primitive already found (its other contacts were labelled
        # the other way): those contacts join it
        same = [j for j, p in enumerate(seg.primitives) if p.kind == fit_x.kind and np.all(
            np.abs(fit_residuals(p.kind, p.params, sub, p.free_side)) <= 3.0 * seg.noise)]
        if same:
            seg_rows[np.isin(group, group[rows])] = same[0]
            merged.add(same[0])
        else:
            seg_rows[np.isin(group, group[rows])] = len(all_fits)
            all_fits.append(fit_x)
    swap = np.isin(group, group[swap])
    # a link contact whose least clearance lies at the link's outer end touched with the
    # sphere there: it is a tip contact (tip radius, not link radius) whatever its label - on
    # every primitive, those the second look found included (its switched contacts too)
    used = table.used_as_tip ^ swap
    flip = np.zeros(len(table), dtype=bool)
    for k, fit in enumerate(all_fits):
        rows = reps[(seg_rows[reps] == k) & ~used[reps]]
        if fit.primitive is None or rows.size == 0:
            continue
        _, t = fit.primitive.segment_signed_distance(table.seg_a[rows], table.seg_b[rows],
                                                     free_side=fit.free_side)
        rows = rows[np.asarray(t) >= 1.0 - 1e-6]
        flip[rows[table.tip_radius[rows] != table.link_radius[rows]]] = True
    flip = np.isin(group, group[flip]) & ~used
    if extra:
        switched = int(np.sum(swap & ~flip))  # a switched contact flipped back keeps its class
        detail = [f"{switched} contacts switched between tip and link"] if switched else []
        if merged:
            detail.append(f"{len(extra) - (len(all_fits) - len(seg.primitives))} of them the "
                          "same surface as a primitive already found")
        messages.append(f"{len(extra)} primitive(s) found among unexplained contacts by trying "
                        "ambiguous ones as the other class"
                        + (f" ({', '.join(detail)})" if detail else ""))
    refit_needed: set[int] = set(range(len(seg.primitives), len(all_fits))) | merged
    if np.any(flip):
        refit_needed |= set(seg_rows[flip].tolist())
        messages.append(f"{int(np.sum(flip))} link contacts touching with the link's outer "
                        "end used as tip contacts")
    if np.any(flip | swap):
        table = dataclasses.replace(table, used_as_tip=used ^ flip)
        data, order = fit_data_from_table(table, free_points, rows=reps)
    assign_fit = seg_rows[order]  # primitive of each fit contact, in the (new) fit order
    assignment = np.full(len(table), -1, dtype=np.int64)
    residual = np.full(len(table), np.nan)
    primitives: list[MappedPrimitive] = []
    fits: list[Any] = []
    surfaces: list[Any] = []  # for the map-refined classification
    n_tip = data.n_tip
    groups: list[tuple[Any, NDArray]] = []
    for k, fit in enumerate(all_fits):
        members = np.flatnonzero(assign_fit == k)  # sorted: tips first, then links
        if k in refit_needed:
            again = fit_primitive(fit.kind, data.take(members), free_side=fit.free_side,
                                  initial=dict(fit.params))
            if not again:
                again = fit_primitive(fit.kind, data.take(members), free_side=fit.free_side)
            if not again:
                # (the fit it had was on another set of contacts: the second look's, or before
                # the outer-end contacts were switched to tips)
                messages.append(f"a {fit.kind} on {len(members)} contacts not reported: its "
                                f"refit on them failed ({again.message})")
                continue
            fit = again
        groups.append((fit, members))
    groups, n_merged = _merge_coincident(groups, data, seg.noise)
    if n_merged:
        messages.append(f"{n_merged} primitive(s) merged into another of the same type they "
                        "coincide with once refitted")
    groups, gone = _dissolve_redundant(groups, data, seg.noise)
    for kind, n_in, n_out in gone:
        messages.append(f"a {kind} on {n_in + n_out} contacts not reported: another primitive "
                        f"explains {n_in} of them, too few are left for it ({n_out})")
    # contacts no primitive explains (fit-data indices), which an undetermined one may take
    free = np.setdiff1d(np.arange(data.n_contacts),
                        np.concatenate([m for _, m in groups] or [np.zeros(0, dtype=int)]))
    # the length kinematic errors scale with: the arm's reach (the scene size without a robot)
    id_scale, id_of = (reach, "the robot's reach") if reach else (None, "the scene size")
    # (off by more than the noise and than the kinematic errors a reported primitive must hold
    # at: a few micrometres off a line of four tips is no bending contact)
    bend_tol = max(BENDING_SIGMAS * seg.noise, REPORT_ID_NOISE * (id_scale or seg.extent))

    def weakly_determined(fit: Any, members: NDArray) -> str:
        """Why ``fit`` may not be reported as determined by ``members`` ('' when it may)."""
        if not seg.determined(fit, REPORT_ID_NOISE, id_scale):
            return (f"its contacts do not determine every parameter at {REPORT_ID_NOISE:g} "
                    f"of {id_of}")
        # every class and link is inferred: a primitive that one contact alone determines
        # is confidently wrong when that contact is (a body contact taken as a tip), and its
        # residuals cannot show it; without any one contact, the others must still make a
        # hypothesis fit-and-grow admits
        if pinning_contact(fit, members, data,
                           lambda g: seg.determined(g, PIN_ID_NOISE)) is not None:
            return ("one of its contacts alone determines it: without it the others do not, "
                    f"even at {PIN_ID_NOISE:g} of the scene size")
        return ""
    for fit, members in groups:
        # a wrong contact (a body contact taken as a tip) a barely determined primitive bends
        # through: its own contacts show it, the fit without it leaves it far off
        fit, kept = drop_bending(fit, members, data, bend_tol, min_keep=MODELS[fit.kind].dof + 1)
        if len(kept) < len(members):
            bent = np.setdiff1d(members, kept)
            if len(kept) < MODELS[fit.kind].dof + 2:
                # too few left: the contacts no primitive explains may complete it
                fit, more = complete_support(fit, kept, data, free, seg.noise,
                                             reach=COMPLETE_REACH, outlier_tol=bend_tol)
                if len(more) < MODELS[fit.kind].dof + 2:
                    free = np.union1d(free, bent)
                    messages.append(f"a {fit.kind} on {len(members)} contacts not reported: "
                                    f"without the {len(bent)} that bent it too few are left "
                                    f"({len(kept)})")
                    continue
                free = np.setdiff1d(free, more)
                kept = more
            free = np.union1d(free, np.setdiff1d(bent, kept))
            messages.append(f"{len(bent)} contact(s) that bent a {fit.kind} left out of it")
            members = kept
        if loss != "linear":
            # final refit of the segment with the robust loss, so contacts that the
            # classification got wrong pull less on the parameters
            robust = fit_primitive(fit.kind, data.take(members), loss=loss, noise=seg.noise,
                                   initial=dict(fit.params), free_side=fit.free_side)
            if robust:
                fit = robust
            else:
                messages.append(f"robust refit of a {fit.kind} failed ({robust.message}); "
                                "kept the least-squares fit")
        why = weakly_determined(fit, members)
        if why:
            more, members_more = complete_support(fit, members, data, free, seg.noise,
                                                  reach=COMPLETE_REACH, outlier_tol=bend_tol)
            why_more = (why if len(members_more) == len(members)
                        else weakly_determined(more, members_more))
            if why_more:
                messages.append(f"a {fit.kind} on {len(members)} contacts not reported: "
                                f"{why_more}")
                continue
            messages.append(f"a {fit.kind} on {len(members)} contacts took "
                            f"{len(members_more) - len(members)} unexplained contacts it also "
                            f"explains once refitted (before, {why})")
            free = np.setdiff1d(free, members_more)
            fit, members = more, members_more
        rows = order[members]
        if fit.kind == "plane" and _links_lie_flat(fit.primitive, table.seg_a[rows],
                                                   table.seg_b[rows]):
            messages.append(f"a plane on {len(members)} contacts not reported: the contacting "
                            "links lie flat in it at most of them, so it is the plane they "
                            "moved in, offset by their radius, not a surface they show")
            continue
        if _ends_against_eq2(fit, table.label[rows], table.seg_a[rows], table.seg_b[rows]):
            messages.append(f"a {fit.kind} on {len(members)} contacts not reported: at most of "
                            "them it is touched by the link's outer end, where eq. (2) put no "
                            "contact (labelled link)")
            continue
        support = _support_points(fit, data, members, n_tip)
        why = None if sweep is None else crossing.sweep_objection(
            fit.kind, fit.params, fit.primitive, fit.free_side, support, sweep, base,
            tol=sweep_tolerance(seg.noise), need=MODELS[fit.kind].dof + 2, min_span=0.5 * B,
            min_cuts=MIN_CUTS, max_escaped=ENCLOSURE_MAX_ESCAPED)
        if why:
            messages.append(f"a {fit.kind} on {len(members)} contacts not reported: {why}")
            continue
        pid = len(primitives)
        # duplicates follow their representative
        dup = np.isin(group, group[rows])
        res_of_group = dict(zip(group[rows].tolist(), fit.residuals.tolist(), strict=True))
        assignment[dup] = pid
        residual[dup] = [res_of_group[g] for g in group[dup].tolist()]
        extent = support_extent(fit.kind, fit.params, support)
        surfaces.append(MapSurface(fit.primitive, float(fit.free_side),
                                   max(float(fit.rms_residual), float(seg.noise), noise_floor),
                                   support))
        ci95 = {k: (np.asarray(hi, dtype=float) - np.asarray(lo, dtype=float)) / 2
                for k, (lo, hi) in fit.ci95.items()}
        primitives.append(MappedPrimitive(
            id=pid, kind=fit.kind, params=dict(fit.params), ci95=ci95,
            covariance=np.asarray(fit.covariance if fit.covariance is not None else
                                  np.zeros((0, 0))),
            support={"tip": int(np.sum(table.used_as_tip[dup])),
                     "link": int(np.sum(~table.used_as_tip[dup]))},
            rms_residual=float(fit.rms_residual), extent=extent,
        ))
        fits.append(fit)
    if seg.primitives and not primitives:
        messages.append("no primitive could be fitted")
    unexplained_rows = np.flatnonzero(assignment < 0)
    unexplained = table.tip_center[unexplained_rows[table.used_as_tip[unexplained_rows]]]
    counts = {"count": len(table), "tip": int(np.sum(table.label == "tip")),
              "link": int(np.sum(table.label == "link")),
              "ambiguous": int(np.sum(table.label == "ambiguous")),
              "unexplained": len(unexplained_rows)}
    surface_map = SurfaceMap(planar=planar, B=float(B), primitives=tuple(primitives),
                             contacts=counts, unexplained=unexplained, meta=dict(meta or {}))
    table = table.with_assignment(assignment, residual)
    table = _refine_classification(table, surfaces, float(B), candidates)
    moved = np.flatnonzero(table.link_by_map != table.link)
    if len(moved):
        messages.append(f"{len(moved)} contact(s) put on another link of their rigid group: "
                        "the fitted map holds only that link's reading (link_by_map)")
    surface_map = dataclasses.replace(surface_map, contacts={
        **surface_map.contacts, **{f"{k}_map": int(np.sum(table.label_map == k))
                                   for k in ("tip", "link", "ambiguous")}})
    return surface_map, tuple(fits), table, tuple(messages)


def _refine_classification(table: ContactTable, surfaces: list[Any], B: float,
                           candidates: LinkCandidates | None = None) -> ContactTable:
    """The table with ``p_tip_map`` / ``label_map``: eq. (2) refined by the fitted surfaces
    (:func:`wholearm_tools.classify.refine.refine_with_map`), labelled with the classifier's
    thresholds; and with ``link_by_map``: of the ``candidates`` links of a contact, the one
    whose reading the fitted map supports best (the link's prior share times its two
    hypotheses' likelihoods, :func:`wholearm_tools.classify.refine.link_evidence`).  A
    contact put on another link gets that link's tip probability (eq. (2) was not evaluated
    for it: prior 0.5)."""
    from wholearm_tools.classify.refine import link_evidence
    from wholearm_tools.classify.tip import labels_from_p_tip

    kw = {"support_radius": max(0.1, 5.0 * B)}
    p_map = refine_with_map(table.p_tip, table.tip_center, table.tip_radius, table.seg_a,
                            table.seg_b, table.link_radius, surfaces, **kw)
    link_map = table.link.copy()
    if candidates is not None and len(candidates.contact) and surfaces:
        c = candidates
        own = c.link == table.link[c.contact]
        delta = 0.5 * np.linalg.norm(table.seg_b - table.seg_a, axis=1)
        post, p_rows = link_evidence(
            c.contact, c.prior, np.where(own, table.p_tip[c.contact], 0.5), c.tip_center,
            c.tip_radius, c.seg_a, c.seg_b, c.link_radius,
            1.0 / np.maximum(delta[c.contact], 1e-6), surfaces, **kw)
        for i in np.unique(c.contact):
            rows = np.flatnonzero(c.contact == i)
            best = rows[np.argmax(post[rows])]
            if not own[best]:
                link_map[i] = c.link[best]
                p_map[i] = p_rows[best]
    return table.with_map_classification(p_map, labels_from_p_tip(p_map), link_map)


@dataclass(frozen=True, slots=True, eq=False)
class LinkCandidates:
    """The links a contact may have been on where the joint signals cannot tell (a rigid
    group), one row per (contact, link): ``contact`` (R,) table row, ``link`` (R,), ``prior``
    (R,) the link's share from the signals and the swept map, and the link's geometry at the
    contact as in :class:`ContactTable` (``tip_center``, ``tip_radius``, ``seg_a``, ``seg_b``,
    ``link_radius``)."""

    contact: NDArray[np.int64]
    link: NDArray[np.int64]
    prior: NDArray[np.float64]
    tip_center: NDArray[np.float64]
    tip_radius: NDArray[np.float64]
    seg_a: NDArray[np.float64]
    seg_b: NDArray[np.float64]
    link_radius: NDArray[np.float64]


def link_candidates(robot: RobotModel, contacts: Any) -> LinkCandidates:
    """Every link with a non-zero ``contacts.link_prior`` of the contacts that have more than
    one, with its geometry at the contact configuration (see :func:`contact_table`)."""
    prior = np.asarray(contacts.link_prior, dtype=float).reshape(len(contacts), -1)
    open_ = (prior > 0).sum(axis=1) > 1
    contact, link = np.nonzero((prior > 0) & open_[:, None])
    seg_a, seg_b, tip_radius, link_radius = _link_geometry(robot, contacts.q[contact], link)
    return LinkCandidates(
        contact=contact.astype(np.int64), link=link.astype(np.int64),
        prior=prior[contact, link], tip_center=seg_b, tip_radius=tip_radius, seg_a=seg_a,
        seg_b=seg_b, link_radius=link_radius)


#: identifiability noise (fraction of the robot's reach; of the scene size when the contacts come
#: without a robot) a *reported* primitive must be determined at, also without any one of its
#: contacts: fit-and-grow searches with 1e-4 of the scene size (weakly determined hypotheses may
#: still grow into good ones); what reaches the map must hold at sub-millimetre kinematic
#: errors, which scale with the arm's reach, not with how far a run wandered.  The reach
#: replaced the scene size (which grows with the run: 1.94 m on paper_spatial at 240 s, reach
#: 0.985 m) when the single-contact check came in; first evidence, at the scene size
#: (sensitivity = worst parameter std per unit noise, in support spreads): wrong link-only
#: cylinders beside paper_spatial's posts (47-74 % radius error) 222-487, cylinders and a
#: plane through a ring of bore contacts 797-16000; the right posts and bores 1-174.  At 5e-4
#: (0.3-0.6 mm here) the limit is 330-670: all but the 222 go, the 174 stays; 1e-3 would drop
#: a right post too.
REPORT_ID_NOISE = 5e-4

#: identifiability noise (fraction of the scene size) a reported primitive must still be
#: determined at without any one of its contacts: fit-and-grow's own level for a hypothesis
#: (:func:`wholearm_tools.fit.segment.pinning_contact`)
PIN_ID_NOISE = 1e-4

#: a member of a reported primitive is left out when the refit without it leaves it more than
#: this many sigma (and REPORT_ID_NOISE of the reach, or of the scene size) off and explains the
#: others at least twice as well (:func:`wholearm_tools.fit.segment.drop_bending`)
BENDING_SIGMAS = 5.0

#: how far (metres) a contact may lie from a primitive its contacts do not determine to be
#: tried as one more of its contacts (:func:`wholearm_tools.fit.segment.complete_support`)
COMPLETE_REACH = 0.02


def _other_interpretation(table: ContactTable, reps: NDArray, seg_rows: NDArray,
                          free_points: NDArray | None, kinds: tuple[str, ...], sigma: float,
                          noise_floor: float, B: float, sweep: Any = None,
                          base: NDArray | None = None, pool: Executor | None = None,
                          ) -> tuple[list[tuple[Any, NDArray, Any]], NDArray]:
    """Primitives among the contacts fit-and-grow left unexplained, each one eq. (2) left
    ambiguous offered both as a tip and as a link contact.

    A misclassified contact fits no surface as labelled; offered both ways, a primitive
    explains the right version and leaves the other unexplained (description length counts it
    as such; it costs nothing).  Returns the primitives with the table rows each explains
    (a row explained in both versions takes the one with the smaller residual) and those
    rows' fit data in the version it explains, and, per table row, whether it is now used as
    the other class.  A primitive whose support spans less than B / 2 (the smallest radius a
    primitive may have) is dropped: with classes switched, a cluster of repeated touches at
    one spot fits a primitive through wherever the other class puts them.
    """
    from wholearm_tools.fit import FitData, segment
    from wholearm_tools.fit.core import residuals
    from wholearm_tools.fit.data import MIN_WEIGHT
    from wholearm_tools.fit.models import MODELS
    from wholearm_tools.fit.segment import complete_support

    swap = np.zeros(len(table), dtype=bool)
    left = reps[seg_rows[reps] < 0]
    # only the contacts eq. (2) left ambiguous: a confident label switched takes a cluster of
    # touches at one spot wherever the other class puts it (five link-body touches of a post,
    # P_T 0.15-0.18, tried as joint-sphere contacts spread 5 cm along a line)
    unsure = left[table.label[left] == "ambiguous"]
    least = min(MODELS[k].dof for k in kinds) + 2
    if len(left) < least or unsure.size == 0:
        return [], swap
    rows = np.concatenate([left, unsure])
    as_tip = np.concatenate([table.used_as_tip[left], ~table.used_as_tip[unsure]])
    weight = 1.0 / table.variance
    weight = np.maximum(weight / weight.max(), MIN_WEIGHT)
    tr, lr = rows[as_tip], rows[~as_tip]
    data = FitData.create(
        tip_points=table.tip_center[tr], tip_radius=table.tip_radius[tr],
        tip_weight=weight[tr], link_a=table.seg_a[lr], link_b=table.seg_b[lr],
        link_radius=table.link_radius[lr], link_weight=weight[lr], free_points=free_points,
        dim=table.dim)
    fit_rows = np.concatenate([tr, lr])
    fit_tip = np.concatenate([np.ones(len(tr), bool), np.zeros(len(lr), bool)])
    seg = segment(data, kinds=kinds, noise=max(sigma, noise_floor, 1e-12),
                  noise_floor=noise_floor, min_radius=0.5 * float(B), sweep=sweep, base=base,
                  executor=pool)
    out: list[tuple[Any, NDArray]] = []
    taken = np.zeros(len(table), dtype=bool)
    for k, fit in enumerate(seg.primitives):
        mem = seg.members(k)
        need = MODELS[fit.kind].dof + 2
        if len(np.unique(fit_rows[mem])) < need:
            # both versions of an ambiguous contact can be members and count once: a
            # primitive left with too few contacts takes those of the leftovers (not another
            # version of its own) that one refit also explains
            free = seg.unexplained[~np.isin(fit_rows[seg.unexplained], fit_rows[mem])
                                   & ~taken[fit_rows[seg.unexplained]]]
            fit, mem = complete_support(fit, mem, data, free, seg.noise, reach=COMPLETE_REACH)
        r = np.abs(residuals(fit.kind, fit.params, data, fit.free_side))
        chosen: dict[int, int] = {}
        for i in mem[np.argsort(r[mem], kind="stable")]:
            chosen.setdefault(int(fit_rows[i]), int(i))
        keep = {row: i for row, i in chosen.items() if not taken[row]}
        if len(keep) < need:
            continue
        idx = np.array(sorted(keep), dtype=np.int64)
        versions = np.array([keep[row] for row in idx.tolist()])
        sub = data.take(versions)
        touch = _support_points(fit, sub, np.arange(sub.n_contacts), sub.n_tip)
        if _span(touch) < 0.5 * float(B):
            # a switched class makes a cluster of repeated touches fit anything through
            # wherever the other class puts them: the support must span at least B / 2, the
            # smallest radius a primitive may have (``min_radius``), as a surface patch would
            continue
        taken[idx] = True
        swap[idx] = fit_tip[versions] != table.used_as_tip[idx]
        out.append((fit, idx, sub))
    return out, swap


#: largest share of the robot's sweep capsules that may cut through an enclosure holding its
#: base (the rest of the motion went out through openings): see
#: :func:`wholearm_tools.fit.crossing.escaped_share`
ENCLOSURE_MAX_ESCAPED = 0.5

#: a link lies flat against a plane when its two ends are at the same distance from it to
#: within this angle (the sine of it, per unit link length)
FLAT_LINK_SIN = float(np.sin(np.radians(2.0)))


def _refit_explaining(fit: Any, members: NDArray, data: Any, sigma: float) -> Any | None:
    """``fit`` refitted (warm start) to the contacts ``members``, or None unless it explains
    them all: dof-corrected RMS residual at most 1.5 ``sigma`` (the chi-square level)."""
    from wholearm_tools.fit import fit_primitive
    from wholearm_tools.fit.segment import rms_dof

    again = fit_primitive(fit.kind, data.take(members), free_side=fit.free_side,
                          initial=dict(fit.params))
    return again if again and rms_dof(again) <= 1.5 * sigma else None


def _merge_coincident(groups: list[tuple[Any, NDArray]], data: Any, sigma: float,
                      k_sigma: float = 3.0) -> tuple[list[tuple[Any, NDArray]], int]:
    """Merge primitives of one type that one least-squares fit explains together (its
    dof-corrected RMS residual over the contacts of both at most 1.5 ``sigma``, the chi-square
    level; tried when one's contacts lie within ``10 k_sigma sigma`` of the other, on its free
    side): ``groups`` are (fit, fit-data indices) pairs; returns the new list and how many
    merged away.

    Fit-and-grow merges such pairs itself, but a primitive whose link contacts turn out to
    touch with the link's outer end is refitted afterwards at the tip radius, and only then
    lies on the other: on lab_circle (seed 0) one wall came out as two lines 3 mm apart
    (11 link contacts fitted at the link radius) that coincide once refitted."""
    from wholearm_tools.fit import residuals

    out = list(groups)
    merged = 0
    i = 0
    while i < len(out):
        j = i + 1
        while j < len(out):
            (fi, mi), (fj, mj) = out[i], out[j]
            # (signed residuals: j's contacts on the other side of i are far from it)
            if fi.kind == fj.kind and np.all(np.abs(residuals(
                    fi.kind, fi.params, data.take(mj), fi.free_side)) <= 10 * k_sigma * sigma):
                union = np.union1d(mi, mj)
                both = _refit_explaining(fi, union, data, sigma)
                if both is not None:
                    out[i] = (both, union)
                    del out[j]
                    merged += 1
                    continue
            j += 1
        i += 1
    return out, merged


def _dissolve_redundant(groups: list[tuple[Any, NDArray]], data: Any, sigma: float,
                        k_sigma: float = 3.0
                        ) -> tuple[list[tuple[Any, NDArray]], list[tuple[str, int, int]]]:
    """Drop a primitive when another explains all but fewer than ``dof + 2`` of its contacts
    (within ``k_sigma sigma``, and still within 1.5 ``sigma`` dof-corrected RMS once refitted
    with them): those contacts go to the other, the rest are left unexplained.  Returns the new
    groups and, per primitive dropped, its type and how many contacts went / were left.

    Fit-and-grow weighs such a pair by description length, but the second look (ambiguous
    contacts as the other class) can find a surface after a smaller primitive took a patch of
    it: on paper_spatial seed 1 (240 s, tip probes) a plane through six link contacts of
    post 1 and one stray tip 42 mm off the post, reported beside the post."""
    from wholearm_tools.fit import residuals
    from wholearm_tools.fit.models import MODELS

    out = list(groups)
    gone: list[tuple[str, int, int]] = []
    changed = True
    while changed:
        changed = False
        for i, j in ((i, j) for i in range(len(out)) for j in range(len(out)) if i != j):
            (fi, mi), (fj, mj) = out[i], out[j]
            near = np.abs(residuals(fi.kind, fi.params, data.take(mj), fi.free_side)
                          ) <= k_sigma * sigma
            # (data.take keeps index order, so ``near`` follows the sorted members)
            take, left = np.sort(mj)[near], np.sort(mj)[~near]
            if len(left) >= MODELS[fj.kind].dof + 2 or len(take) == 0:
                continue
            union = np.union1d(mi, take)
            both = _refit_explaining(fi, union, data, sigma)
            if both is None:
                continue
            out[i] = (both, union)
            del out[j]
            gone.append((fj.kind, len(take), len(left)))
            changed = True
            break
    return out, gone


def _ends_against_eq2(fit: Any, label: NDArray, seg_a: NDArray, seg_b: NDArray) -> bool:
    """Whether more than half of a primitive's contacts are labelled link by eq. (2) yet
    touch it with their link's outer end.

    Eq. (2) labels a contact link when the dilated link body, not the tip or joint sphere at
    its outer end, holds the admissible contact region; a primitive that only the outer ends
    touch contradicts it at every such contact. Repeated link-body touches of a post at one
    spot (lab_circle seed 20, lab_sharp seed 20, 20 s runs: four and six touches, P_T 0.02-0.18)
    fit a line through, or tangent at, the links' outer ends wherever those ended up, 63 and
    76 mm RMS from the post; the walls touched at the outer end carry such contacts one in
    seventeen at most."""
    link = np.asarray(label) == "link"
    if fit.primitive is None or 2 * np.count_nonzero(link) <= len(label):
        return False
    _, t = fit.primitive.segment_signed_distance(seg_a[link], seg_b[link],
                                                 free_side=fit.free_side)
    return bool(2 * np.count_nonzero(np.asarray(t) >= 1.0 - 1e-6) > len(label))


def _links_lie_flat(plane: Any, seg_a: NDArray, seg_b: NDArray) -> bool:
    """Whether more than half of the contacting links (segments ``seg_a -> seg_b``) lie flat
    against ``plane``.

    An arm whose joint stays put (a base yaw held while shoulder and elbow move) keeps every
    link in one plane; any contacts it makes, tips or link sides, fit that plane offset by a
    radius as closely as the encoder allows. A real surface is met by links at an angle, or by
    a link lying flat now and then; most of them flat is the arm's own plane of motion."""
    a = np.asarray(seg_a, dtype=float)
    b = np.asarray(seg_b, dtype=float)
    length = np.maximum(np.linalg.norm(b - a, axis=1), 1e-12)
    tilt = np.abs(plane.signed_distance(b) - plane.signed_distance(a)) / length
    return bool(2 * np.count_nonzero(tilt < FLAT_LINK_SIN) > len(a))


def _span(points: NDArray) -> float:
    """Largest distance between two of ``points`` (0 for fewer than two)."""
    from scipy.spatial.distance import pdist

    return float(pdist(np.asarray(points, dtype=float)).max()) if len(points) > 1 else 0.0


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


def _support_points(fit: Any, data: Any, members: NDArray, n_tip: int) -> NDArray:
    """Surface points behind a primitive: tip centres and link points at their latent t,
    each projected onto the fitted surface."""
    prim = fit.primitive
    tips = members[members < n_tip]
    links = members[members >= n_tip] - n_tip
    pts = [data.tip_points[tips]]
    if len(links):
        a, b = data.link_a[links], data.link_b[links]
        _, t = prim.segment_signed_distance(a, b, free_side=fit.free_side)
        pts.append(a + t[:, None] * (b - a))
    points = np.concatenate(pts, axis=0)
    return prim.closest_point(points) if len(points) else points


def reconstruct(run: Run, B: float = 0.02, **options: Any) -> Reconstruction:
    """Detect, classify and fit a logged run.

    Parameters
    ----------
    run : Run (from ``wholearm_tools.logs.read_run`` or the simulator)
    B : float, smallest expected surface curvature radius [m]
    **options : fields of :class:`ReconstructParams`

    Returns
    -------
    Reconstruction; a run where nothing could be fitted still returns one (with no primitives
    and messages saying why): the CLI decides whether that is an error.
    """
    from wholearm_tools.classify import tip_probability
    from wholearm_tools.contacts import detect_contacts

    params = ReconstructParams(B=B, **options)
    timings: dict[str, float] = {}
    clock = time.perf_counter()
    contacts = detect_contacts(run.log, run.robot)
    timings["detect"] = time.perf_counter() - clock
    clock = time.perf_counter()
    classification = tip_probability(run, contacts, params.B, causal=params.causal)
    timings["classify"] = time.perf_counter() - clock
    table = contact_table(run.robot, contacts, classification)
    clock = time.perf_counter()
    hints = free_space_hints(run.robot, np.asarray(run.log.q), params.free_hints)
    floor = position_noise_floor(run.robot, np.asarray(run.log.q))
    meta = {"source": run.source, "causal": params.causal, "duration": run.log.duration}
    if len(table) == 0:
        surface_map = SurfaceMap(planar=run.robot.planar, B=params.B, primitives=(),
                                 contacts={"count": 0}, meta=meta,
                                 unexplained=np.zeros((0, run.robot.dim)))
        fits: tuple[Any, ...] = ()
        messages: tuple[str, ...] = ("no contacts detected in the run",)
    else:
        surface_map, fits, table, messages = fit_table(
            table, planar=run.robot.planar, B=params.B, kinds=params.kinds, loss=params.loss,
            noise=params.noise, free_points=hints, meta=meta, noise_floor=floor,
            sweep=robot_sweep(run.robot, np.asarray(run.log.q)) if params.use_sweep else None,
            base=run.robot.base, workers=params.workers,
            candidates=link_candidates(run.robot, contacts), reach=float(run.robot.reach))
    timings["fit"] = time.perf_counter() - clock
    return Reconstruction(run=run, params=params, contacts=contacts,
                          classification=classification, table=table, fits=fits,
                          surface_map=surface_map, timings=timings, messages=messages)

