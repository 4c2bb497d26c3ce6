"""Accuracy of a reconstruction against the simulator's ground truth (pure numpy, no plotting).

What is scored, and how
-----------------------
* **Contacts** — each detected contact is paired with the ground-truth contact event it
  corresponds to (:func:`wholearm_tools.contacts.pair_events`: intervals first obstruction →
  release, one to one, a detection pairing first with the event on its link that was in contact
  where it settled).  Unpaired detections are *false* detections, unpaired truth contacts are
  *missed*.
* **Link identification** — fraction of paired contacts whose detected link is the true link.
* **Tip/link classification** — a 2 × 3 confusion matrix: rows = truth (``tip`` = tip or joint
  sphere, the paper's "tip" class; ``body`` = the link's side), columns = predicted label
  (``tip``, ``link``, ``ambiguous``).  Accuracy is over the decided (non-ambiguous) contacts.
* **P_T calibration** — paired contacts binned by P_T; per bin the mean P_T and the observed
  fraction of true tip contacts (a calibrated P_T lies on the diagonal), plus the Brier score.
* **Primitives** — each fitted primitive is matched to a true surface by majority vote over the
  true surfaces its member contacts touched; a true obstacle made of several surfaces (a
  ``cylinder_junction`` holds the main bore and the lateral under one surface id) is resolved per
  contact by the nearest of its surfaces to the true contact point, and a contact also votes for
  any other true surface within the resolution of its point (a tip in a corner touches both
  walls); a tie goes to the surface nearest the primitive.  Primitives without paired
  member contacts fall back to the true surface nearest to their fitted surface (mean distance of
  surface samples).  Per primitive: type right, size error (radius; torus major radius; cone
  half-angle in degrees), axis/normal angle error (degrees; unsigned for lines, planes, cylinders
  and tori), position error (see :class:`PrimitiveAccuracy`) and the RMS / max distance of the
  fitted surface, sampled over its extent, to the true (unbounded) surface.
* **Surfaces** — which true surfaces were touched, and found (matched by a primitive of the right
  type), or missed.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools._arrays import read_only
from wholearm_tools.errors import InputError

FloatArray = NDArray[np.float64]

#: parameter holding the axis-like direction of each kind
AXIS_PARAM = {"line": "direction", "plane": "normal", "cylinder": "axis", "cone": "axis",
              "torus": "axis"}
#: kinds whose direction is a line (no sign): the angle error is folded into [0, 90] degrees
UNSIGNED_AXIS = {"line", "plane", "cylinder", "torus"}
#: parameter holding the main size of each kind (cone: half-angle, scored in degrees)
SIZE_PARAM = {"circle": "radius", "sphere": "radius", "cylinder": "radius",
              "torus": "major_radius", "cone": "half_angle"}
#: parameter holding the reference position of each kind (lines, planes and cylinders: see
#: :class:`PrimitiveAccuracy`)
CENTRE_PARAM = {"circle": "center", "sphere": "center", "torus": "center", "cone": "apex"}

DEFAULT_BINS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)


def _json(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json(v) for v in value]
    if isinstance(value, np.ndarray):
        return _json(value.tolist())
    if isinstance(value, np.integer | np.bool_):
        return value.item()
    if isinstance(value, float | np.floating):
        value = float(value)
        return value if math.isfinite(value) else None
    return value


# ---------------------------------------------------------------------------------- contacts


@dataclass(frozen=True, slots=True, eq=False)
class ClassificationMetrics:
    """Contact detection, link identification and tip/link classification scores.

    Attributes
    ----------
    n_detected, n_truth, n_matched : int
    n_false : int, detections without a true contact
    n_missed : int, true contacts without a detection
    n_stopped : int, true contacts that stopped the arm (every one on the kinematic engine; a
        physics run also records touches that only slowed or deflected it)
    n_stops, n_stops_found : int, the arm's stops against contact
        (:func:`wholearm_tools.contacts.arm_stops`: the contacts that held one configuration)
        and those a detection paired with
    truth_index : (M,) int, paired truth contact of each detection, -1 none
    link_correct : int, paired contacts whose detected link is the true link
    confusion : (2, 3) int, rows truth ``tip|joint``, ``body``; columns predicted
        ``tip``, ``link``, ``ambiguous``
    bins : (K + 1,) float, P_T bin edges of the calibration
    bin_count : (K,) int; bin_mean_p : (K,) float; bin_tip_fraction : (K,) float (NaN if empty)
    brier : float, mean (P_T - truth)² over paired contacts (NaN without any)
    """

    n_detected: int
    n_truth: int
    n_matched: int
    n_false: int
    n_missed: int
    n_stopped: int
    n_stops: int
    n_stops_found: int
    truth_index: NDArray[np.int64]
    link_correct: int
    confusion: NDArray[np.int64]
    bins: FloatArray
    bin_count: NDArray[np.int64]
    bin_mean_p: FloatArray
    bin_tip_fraction: FloatArray
    brier: float

    ROWS = ("tip", "body")
    COLUMNS = ("tip", "link", "ambiguous")

    @property
    def link_accuracy(self) -> float:
        """Fraction of paired contacts on the right link (NaN when none paired)."""
        return self.link_correct / self.n_matched if self.n_matched else float("nan")

    @property
    def stop_recall(self) -> float:
        """Fraction of the arm's stops against contact that a detection found (what joint
        positions can show; NaN when nothing stopped it)."""
        return self.n_stops_found / self.n_stops if self.n_stops else float("nan")

    @property
    def n_decided(self) -> int:
        return int(self.confusion[:, :2].sum())

    @property
    def class_accuracy(self) -> float:
        """Fraction of decided (tip or link) paired contacts labelled right."""
        right = int(self.confusion[0, 0] + self.confusion[1, 1])
        return right / self.n_decided if self.n_decided else float("nan")

    @property
    def ambiguous_fraction(self) -> float:
        total = int(self.confusion.sum())
        return float(self.confusion[:, 2].sum()) / total if total else float("nan")

    def to_dict(self) -> dict[str, Any]:
        return _json({
            "n_detected": self.n_detected, "n_truth": self.n_truth,
            "n_matched": self.n_matched, "n_false": self.n_false, "n_missed": self.n_missed,
            "n_stopped": self.n_stopped, "n_stops": self.n_stops,
            "n_stops_found": self.n_stops_found,
            "stop_recall": self.stop_recall,
            "link_accuracy": self.link_accuracy, "class_accuracy": self.class_accuracy,
            "ambiguous_fraction": self.ambiguous_fraction,
            "confusion": {"rows": list(self.ROWS), "columns": list(self.COLUMNS),
                          "counts": self.confusion},
            "calibration": {"bins": self.bins, "count": self.bin_count,
                            "mean_p_tip": self.bin_mean_p,
                            "tip_fraction": self.bin_tip_fraction, "brier": self.brier},
        })


def classification_metrics(t: Any, link: Any, p_tip: Any, label: Any, truth: Any, *,
                           t_end: Any = None, t_settle: Any = None,
                           bins: Sequence[float] = DEFAULT_BINS) -> ClassificationMetrics:
    """Score detected and classified contacts against ground truth.

    Parameters
    ----------
    t : (M,) float, detection times [s]; link : (M,) int, detected link
    p_tip : (M,) float, tip probability; label : (M,) str, ``tip``/``link``/``ambiguous``
    truth : GroundTruth
    t_end, t_settle : (M,) float, optional; each detection's release and the time it settled
        (NaN or absent: a moment at ``t``), for the pairing
        (:func:`wholearm_tools.contacts.pair_events`)
    bins : increasing P_T bin edges from 0 to 1 for the calibration
    """
    from wholearm_tools.contacts.truth import arm_stops, pair_events

    t = np.asarray(t, dtype=float).reshape(-1)
    m = t.shape[0]
    link = np.asarray(link, dtype=np.int64).reshape(-1)
    p_tip = np.asarray(p_tip, dtype=float).reshape(-1)
    label = np.asarray(label).astype(str).reshape(-1)
    for name, arr in (("link", link), ("p_tip", p_tip), ("label", label)):
        if arr.shape != (m,):
            raise InputError(f"expected {name} of shape ({m},), got {arr.shape}")
    edges = np.asarray(bins, dtype=float)
    if edges.ndim != 1 or edges.size < 2 or np.any(np.diff(edges) <= 0):
        raise InputError(f"expected increasing P_T bin edges, got {list(bins)}")
    bad = sorted(set(label.tolist()) - set(ClassificationMetrics.COLUMNS))
    if bad:
        raise InputError(f"unknown contact labels {bad} (expected tip, link, ambiguous)")

    idx = pair_events(t, t_end, link, truth, at=t_settle)
    ok = idx >= 0
    j = idx[ok]
    true_tip = np.asarray(truth.is_tip)[j]
    true_link = np.asarray(truth.contact_link)[j]
    confusion = np.zeros((2, 3), dtype=np.int64)
    col = {c: i for i, c in enumerate(ClassificationMetrics.COLUMNS)}
    for is_tip, lab in zip(true_tip, label[ok], strict=True):
        confusion[0 if is_tip else 1, col[lab]] += 1
    p = p_tip[ok]
    y = true_tip.astype(float)
    k = len(edges) - 1
    which = np.clip(np.searchsorted(edges, p, side="right") - 1, 0, k - 1)
    count = np.bincount(which, minlength=k).astype(np.int64)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_p = np.bincount(which, weights=p, minlength=k) / count
        frac = np.bincount(which, weights=y, minlength=k) / count
    brier = float(np.mean((p - y) ** 2)) if p.size else float("nan")
    n_matched = int(ok.sum())
    stops = arm_stops(truth)
    paired = np.zeros(int(truth.n_contacts), dtype=bool)
    paired[j] = True
    return ClassificationMetrics(
        n_detected=m, n_truth=int(truth.n_contacts), n_matched=n_matched,
        n_false=m - n_matched, n_missed=int(truth.n_contacts) - n_matched,
        n_stopped=int(np.count_nonzero(truth.contact_stopped)), n_stops=len(stops),
        n_stops_found=sum(bool(paired[g].any()) for g in stops),
        truth_index=read_only(idx, np.int64), link_correct=int(np.sum(link[ok] == true_link)),
        confusion=read_only(confusion, np.int64), bins=read_only(edges),
        bin_count=read_only(count, np.int64),
        bin_mean_p=read_only(mean_p), bin_tip_fraction=read_only(frac), brier=brier)


# -------------------------------------------------------------------------------- surfaces


@dataclass(frozen=True, slots=True, eq=False)
class TrueSurface:
    """One true surface of the ground truth: ``id``, ``kind``, the geometry object, the id of
    the obstacle it belongs to (contacts name obstacles) and the raw dict."""

    id: int
    kind: str
    primitive: Any
    obstacle_id: Any
    data: dict[str, Any] = field(default_factory=dict)

    @property
    def params(self) -> dict[str, Any]:
        """Parameters under their map.json names (unit vectors normalised)."""
        return dict(self.primitive.params())


def true_surfaces(truth: Any) -> tuple[TrueSurface, ...]:
    """The ground truth's surfaces as geometry objects."""
    from wholearm_tools.geometry.base import primitive_type

    out = []
    for s in truth.surfaces:
        try:
            prim = primitive_type(str(s["type"])).from_params(s["params"])
        except (KeyError, TypeError) as exc:
            raise InputError(f"ground-truth surface {s!r} is malformed ({exc})") from None
        obstacle = s.get("obstacle") or {}
        out.append(TrueSurface(int(s["id"]), str(s["type"]), prim,
                               obstacle.get("surface_id", s["id"]), dict(s)))
    return tuple(out)


def truth_contact_surfaces(truth: Any, surfaces: Sequence[TrueSurface] | None = None
                           ) -> NDArray[np.int64]:
    """Position (in ``surfaces``) of the true surface each true contact touched, ``(M,) int``.

    ``contact_surface`` names the obstacle; an obstacle holding several surfaces (a junction) is
    resolved by the surface nearest to the true contact point.  -1 where nothing fits.
    """
    surfaces = true_surfaces(truth) if surfaces is None else tuple(surfaces)
    return _surfaces_touched(truth, surfaces, 0.0)[0]


def truth_contact_touches(truth: Any, surfaces: Sequence[TrueSurface], resolution: float
                          ) -> NDArray[np.bool_]:
    """Which true surfaces each true contact touched, ``(M, S) bool``: its own
    (:func:`truth_contact_surfaces`) and every other within ``resolution`` of its contact point
    (a tip in a corner touches both walls, whichever the simulator recorded)."""
    return _surfaces_touched(truth, tuple(surfaces), resolution)[1]


def _surfaces_touched(truth: Any, surfaces: tuple[TrueSurface, ...], resolution: float
                      ) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """:func:`truth_contact_surfaces` and :func:`truth_contact_touches` from one set of
    distances."""
    m = int(truth.n_contacts)
    own = np.full(m, -1, dtype=np.int64)
    touches = np.zeros((m, len(surfaces)), dtype=bool)
    if not surfaces or m == 0:
        return own, touches
    points = np.asarray(truth.contact_point, dtype=float)
    dists = np.stack([_surface_distance(s.primitive, points) for s in surfaces], axis=1)
    obstacle_ids = [s.obstacle_id for s in surfaces]
    for k in range(m):
        cand = [i for i, oid in enumerate(obstacle_ids) if oid == truth.contact_surface[k]]
        if not cand:
            cand = list(range(len(surfaces)))
        own[k] = cand[int(np.argmin(dists[k, cand]))]
    touches = dists <= resolution
    touches[np.arange(m), own] = True
    return own, touches


def _surface_distance(prim: Any, points: FloatArray) -> FloatArray:
    dim = 2 if prim.kind in ("line", "circle") else 3
    if points.shape[1] != dim:
        points = points[:, :dim] if points.shape[1] > dim else np.pad(
            points, ((0, 0), (0, dim - points.shape[1])))
    return np.abs(np.asarray(prim.signed_distance(points), dtype=float))


def surface_samples(primitive: Any, resolution: float = 0.01) -> FloatArray:
    """Points on a map primitive (``MappedPrimitive``) over its extent, ``(K, d)``.

    3-D kinds: the vertices of its mesh; 2-D kinds: its polyline, with lines subdivided to
    ``resolution``.  Unbounded primitives without an extent give an empty array.
    """
    from wholearm_tools.mesh import full_extent, polyline, tessellate

    extent = primitive.extent
    if not extent:
        try:
            extent = full_extent(primitive.kind, primitive.params)
        except InputError:
            return np.zeros((0, 2 if primitive.kind in ("line", "circle") else 3))
    if primitive.kind in ("line", "circle"):
        pts = polyline(primitive.kind, primitive.params, extent, resolution)
        if primitive.kind == "line":
            n = max(2, int(np.ceil(np.linalg.norm(pts[1] - pts[0]) / resolution)) + 1)
            w = np.linspace(0.0, 1.0, n)[:, None]
            pts = pts[0] + w * (pts[1] - pts[0])
        return pts
    return np.asarray(tessellate(primitive.kind, primitive.params, extent,
                                 resolution).vertices)


@dataclass(frozen=True, slots=True)
class PrimitiveAccuracy:
    """Accuracy of one fitted primitive against the true surface it was matched to.

    ``position_error`` [m]: centre distance (circle, sphere, torus), apex distance (cone);
    for lines, planes and cylinders the distance from the true line / plane / axis of the fitted
    counterpart's point nearest the centre of the fitted surface samples (the gauge-free part
    of the position).  ``size_*``: radius (circle, sphere, cylinder), major radius (torus) in
    metres, half-angle (cone) in degrees.  ``surface_rms`` / ``surface_max`` [m]: distance of
    the fitted surface, sampled over its extent, to the true unbounded surface.
    Fields that do not apply are None.
    """

    primitive_id: int
    kind: str
    n_support: int
    truth_id: int | None
    truth_kind: str | None
    matched_by: str | None          # "contacts", "distance" or None (no truth surface)
    type_correct: bool
    size_name: str | None = None
    size_fit: float | None = None
    size_true: float | None = None
    size_error: float | None = None
    size_error_pct: float | None = None
    axis_angle_deg: float | None = None
    position_error: float | None = None
    surface_rms: float | None = None
    surface_max: float | None = None
    votes: dict[int, int] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return _json(asdict(self))


@dataclass(frozen=True, slots=True)
class SurfaceRecovery:
    """Whether a true surface was touched and found."""

    truth_id: int
    kind: str
    n_truth_contacts: int
    found_by: tuple[int, ...]    # ids of the primitives of the right type matched to it

    @property
    def touched(self) -> bool:
        return self.n_truth_contacts > 0

    @property
    def found(self) -> bool:
        return bool(self.found_by)

    def to_dict(self) -> dict[str, Any]:
        return _json({"truth_id": self.truth_id, "kind": self.kind,
                      "n_truth_contacts": self.n_truth_contacts, "touched": self.touched,
                      "found": self.found, "found_by": list(self.found_by)})


def _vec(params: Mapping[str, Any], name: str) -> FloatArray:
    return np.asarray(params[name], dtype=float).reshape(-1)


def _angle_deg(u: FloatArray, v: FloatArray, unsigned: bool) -> float:
    c = float(np.dot(u, v) / (np.linalg.norm(u) * np.linalg.norm(v)))
    if unsigned:
        c = abs(c)
    return math.degrees(math.acos(min(1.0, max(-1.0, c))))


def _line_point_distance(p0: FloatArray, d: FloatArray, x: FloatArray) -> float:
    d = d / np.linalg.norm(d)
    r = x - p0
    return float(np.linalg.norm(r - (r @ d) * d))


def primitive_accuracy(primitive: Any, truth: TrueSurface | None, *, matched_by: str | None,
                       n_support: int = 0, votes: Mapping[int, int] | None = None,
                       resolution: float = 0.01) -> PrimitiveAccuracy:
    """Compare one map primitive (``MappedPrimitive``) with a true surface (None: unmatched)."""
    kind = primitive.kind
    base = {"primitive_id": int(primitive.id), "kind": kind, "n_support": int(n_support),
            "votes": dict(votes or {})}
    if truth is None:
        return PrimitiveAccuracy(truth_id=None, truth_kind=None, matched_by=None,
                                 type_correct=False, **base)
    out: dict[str, Any] = {}
    samples = surface_samples(primitive, resolution)
    if len(samples):
        d = _surface_distance(truth.primitive, samples)
        out["surface_rms"] = float(np.sqrt(np.mean(d * d)))
        out["surface_max"] = float(d.max())
    fp, tp = primitive.params, truth.params
    if kind == truth.kind:
        size = SIZE_PARAM.get(kind)
        if size is not None:
            f, t = float(fp[size]), float(tp[size])
            if kind == "cone":
                f, t = math.degrees(f), math.degrees(t)
            out.update(size_name=size, size_fit=f, size_true=t, size_error=f - t,
                       size_error_pct=100.0 * (f - t) / t if t else None)
        axis = AXIS_PARAM.get(kind)
        if axis is not None:
            out["axis_angle_deg"] = _angle_deg(_vec(fp, axis), _vec(tp, axis),
                                               kind in UNSIGNED_AXIS)
        if kind in CENTRE_PARAM:
            name = CENTRE_PARAM[kind]
            out["position_error"] = float(np.linalg.norm(_vec(fp, name) - _vec(tp, name)))
        elif len(samples):
            centre = samples.mean(axis=0)
            if kind == "cylinder":
                p0, a = _vec(fp, "point"), _vec(fp, "axis")
                ref = p0 + ((centre - p0) @ a) * a          # fitted axis point near the data
                out["position_error"] = _line_point_distance(_vec(tp, "point"),
                                                             _vec(tp, "axis"), ref)
            else:                                           # line, plane
                ref = np.asarray(primitive.primitive.closest_point(centre[None]))[0]
                out["position_error"] = float(_surface_distance(truth.primitive, ref[None])[0])
    return PrimitiveAccuracy(truth_id=truth.id, truth_kind=truth.kind, matched_by=matched_by,
                             type_correct=kind == truth.kind, **base, **out)


@dataclass(frozen=True, slots=True, eq=False)
class AccuracyReport:
    """Everything :func:`evaluate` scores; ``to_dict()`` is JSON-ready."""

    classification: ClassificationMetrics
    primitives: tuple[PrimitiveAccuracy, ...]
    surfaces: tuple[SurfaceRecovery, ...]
    #: the labels refined by the fitted map (``label_map``); None before fitting
    classification_map: ClassificationMetrics | None = None

    @property
    def n_found(self) -> int:
        return sum(s.found for s in self.surfaces)

    @property
    def n_touched(self) -> int:
        return sum(s.touched for s in self.surfaces)

    @property
    def missed(self) -> tuple[SurfaceRecovery, ...]:
        """True surfaces the robot touched that no primitive of the right type explains."""
        return tuple(s for s in self.surfaces if s.touched and not s.found)

    def to_dict(self) -> dict[str, Any]:
        return {"classification": self.classification.to_dict(),
                "classification_map": (None if self.classification_map is None
                                       else self.classification_map.to_dict()),
                "primitives": [p.to_dict() for p in self.primitives],
                "surfaces": [s.to_dict() for s in self.surfaces],
                "n_found": self.n_found, "n_touched": self.n_touched}


def match_primitives(primitives: Sequence[Any], member_truth: Sequence[NDArray[np.int64]],
                     surfaces: Sequence[TrueSurface], resolution: float = 0.01
                     ) -> list[tuple[int | None, str | None, dict[int, int]]]:
    """True surface (position in ``surfaces``) of each primitive: majority vote of the true
    surfaces its member contacts touched (``member_truth[i]``: positions, one entry per member
    and surface it touched, -1 ignored), a tie going to the one nearest its surface samples;
    else the nearest true surface to its surface samples.  Returns ``(index | None, how,
    votes)``."""
    out: list[tuple[int | None, str | None, dict[int, int]]] = []
    for prim, members in zip(primitives, member_truth, strict=True):
        votes = Counter(int(v) for v in np.asarray(members).reshape(-1) if v >= 0)
        if votes:
            top = max(votes.values())
            tied = sorted(k for k, n in votes.items() if n == top)
            near = _nearest_surface(prim, surfaces, tied, resolution) if len(tied) > 1 else None
            best = tied[0] if near is None else near
            out.append((best, "contacts", {surfaces[k].id: n for k, n in sorted(votes.items())}))
            continue
        k = _nearest_surface(prim, surfaces, list(range(len(surfaces))), resolution)
        out.append((k, "distance", {}) if k is not None else (None, None, {}))
    return out


def _nearest_surface(prim: Any, surfaces: Sequence[TrueSurface], cands: list[int],
                     resolution: float) -> int | None:
    """Of the true surfaces ``cands``, the nearest to ``prim``'s surface samples (mean
    distance); None without candidates or samples."""
    if not cands:
        return None
    samples = surface_samples(prim, resolution)
    if not len(samples):
        return None
    mean = [float(np.mean(_surface_distance(surfaces[k].primitive, samples))) for k in cands]
    return cands[int(np.argmin(mean))]


def evaluate(rec: Any, *, resolution: float = 0.01) -> AccuracyReport | None:
    """Score a :class:`~wholearm_tools.pipeline.Reconstruction` against its run's ground truth.

    Returns None when the run has no ground truth (real logs).
    """
    truth = rec.run.truth
    if truth is None:
        return None
    table = rec.table
    cls = classification_metrics(table.t, table.link, table.p_tip, table.label, truth,
                                 t_end=table.t_end, t_settle=table.t_settle)
    surfaces = true_surfaces(truth)
    contact_surf, touches = _surfaces_touched(truth, surfaces, resolution)
    idx = cls.truth_index
    prims = rec.surface_map.primitives
    assignment = np.asarray(table.primitive)
    members = [np.nonzero(touches[idx[(assignment == p.id) & (idx >= 0)]])[1]
               if len(surfaces) else np.zeros(0, np.int64) for p in prims]
    matches = match_primitives(prims, members, surfaces, resolution)
    accs = []
    for prim, (k, how, votes) in zip(prims, matches, strict=True):
        n_support = int(sum(prim.support.values())) if prim.support else 0
        accs.append(primitive_accuracy(prim, surfaces[k] if k is not None else None,
                                       matched_by=how, n_support=n_support, votes=votes,
                                       resolution=resolution))
    counts = np.bincount(contact_surf[contact_surf >= 0], minlength=len(surfaces))
    recovery = tuple(
        SurfaceRecovery(truth_id=s.id, kind=s.kind, n_truth_contacts=int(counts[i]),
                        found_by=tuple(a.primitive_id for a in accs
                                       if a.truth_id == s.id and a.type_correct))
        for i, s in enumerate(surfaces))
    cls_map = None
    label_map = np.asarray(getattr(table, "label_map", np.zeros(0))).astype(str)
    if (len(label_map) and len(label_map) == len(table.t) and np.all(label_map != "")
            and np.all(np.isfinite(table.p_tip_map))):
        link_map = np.asarray(getattr(table, "link_by_map", table.link))
        cls_map = classification_metrics(table.t, np.where(link_map >= 0, link_map, table.link),
                                         table.p_tip_map, label_map, truth,
                                         t_end=table.t_end, t_settle=table.t_settle)
    return AccuracyReport(cls, tuple(accs), recovery, cls_map)
