"""The readings of each contact: where on the robot it may have touched, with prior weights.

Joint signals say *when* the arm was obstructed and, up to a rigid group, *which link*; eq. (2)
says how likely the outer sphere (the tip, or the joint sphere at the link's outer end) rather
than the link's side made the contact.  Neither is certain, so a contact enters the fit as a
small mixture of **readings**, each one geometric hypothesis about the contact:

* a *sphere* reading: the centre ``P`` of the outer sphere of link ``l`` and its radius ``w``
  (the contact lies ``w`` from ``P``): residual ``s sd(P) - w``;
* a *side* reading: the axis segment ``a b`` of link ``l`` and its radius ``w`` (the surface is
  tangent to the side): residual ``min_t s sd(a + t (b - a)) - w``.

A sphere reading is stored as a segment of zero length, so both kinds share one residual.  The
prior of a reading is the link's prior (from the joint signals and the swept map) times ``P_T``
for the sphere and ``1 - P_T`` for the side; the fit's assignment step turns it into a
posterior (:mod:`wholearm_tools.fit.infer`).  The fourth reading, *outlier* (the contact lies on
no surface of the map), has a prior of its own in the inference policy.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wholearm_tools._arrays import read_only
from wholearm_tools.classify.tip import ClassifyParams
from wholearm_tools.errors import InputError
from wholearm_tools.fit.data import FitData, FreeSpace

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: tip probabilities are kept this far from 0 and 1: eq. (2) computed from a finite swept map
#: is never certain, and a reading with prior 0 could not be revised by any evidence.  The same
#: doubt eq. (2) keeps on the boundary the robot's sweep rules out (its default ``swept_doubt``)
P_TIP_CLIP = ClassifyParams().swept_doubt


@dataclass(frozen=True, slots=True, eq=False)
class Readings:
    """``R`` readings of ``M`` contacts, sorted by contact (columnar, read-only).

    Parameters
    ----------
    contact : (R,) int, the contact each reading belongs to (0..M-1, non-decreasing)
    link : (R,) int, the link the reading puts the contact on
    sphere : (R,) bool, sphere reading (else side reading)
    log_prior : (R,) float, log of the reading's prior probability (per contact they sum to 1)
    a, b : (R, d) float, the segment (``a == b`` for a sphere reading)
    radius : (R,) float, ``w``
    n_contacts : int, ``M``
    """

    contact: IntArray
    link: IntArray
    sphere: NDArray[np.bool_]
    log_prior: FloatArray
    a: FloatArray
    b: FloatArray
    radius: FloatArray
    n_contacts: int
    _starts: IntArray = field(init=False, repr=False, default=None)  # type: ignore[assignment]
    _fit_position: IntArray = field(init=False, repr=False,
                                    default=None)  # type: ignore[assignment]

    def __post_init__(self) -> None:
        r = np.asarray(self.contact).shape[0]
        for name, dtype in (("contact", np.int64), ("link", np.int64), ("sphere", bool),
                            ("log_prior", float), ("radius", float)):
            arr = read_only(getattr(self, name), dtype).reshape(-1)
            if arr.shape != (r,):
                raise InputError(f"expected reading {name} of shape ({r},), got {arr.shape}")
            object.__setattr__(self, name, arr)
        a, b = read_only(self.a), read_only(self.b)
        if a.ndim != 2 or a.shape != b.shape or a.shape[0] != r or a.shape[1] not in (2, 3):
            raise InputError(f"expected reading segments of shape ({r}, 2|3), got {a.shape}, "
                             f"{b.shape}")
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))
                and np.all(np.isfinite(self.radius)) and np.all(self.radius >= 0)):
            raise InputError("reading geometry must be finite with radius >= 0")
        if r and (np.any(np.diff(self.contact) < 0) or self.contact[0] < 0
                  or self.contact[-1] >= self.n_contacts):
            raise InputError("readings must be sorted by contact, within 0..n_contacts-1")
        if r and len(np.unique(self.contact)) != self.n_contacts:
            raise InputError("every contact needs at least one reading")
        object.__setattr__(self, "a", a)
        object.__setattr__(self, "b", b)
        starts = np.flatnonzero(np.r_[True, np.diff(self.contact) > 0]) if r else np.zeros(0, int)
        object.__setattr__(self, "_starts", read_only(starts, np.int64))
        object.__setattr__(self, "_fit_position", self.fit_order(self.sphere))

    def __len__(self) -> int:
        return int(self.contact.shape[0])

    @property
    def dim(self) -> int:
        return int(self.a.shape[1])

    @property
    def starts(self) -> IntArray:
        """Index of each contact's first reading, ``(M,)`` (for ``np.*.reduceat``)."""
        return self._starts

    def points(self) -> FloatArray:
        """One representative point per reading: the sphere centre or the segment midpoint."""
        return 0.5 * (self.a + self.b)

    def fit_data(self, index: ArrayLike | None = None, weight: ArrayLike | None = None,
                 free_points: ArrayLike | FreeSpace | None = None) -> FitData:
        """The fitter's input for readings ``index`` (all by default), sphere readings as tips
        and side readings as links, each with ``weight`` (default 1); residual ``k`` of the
        given readings is row ``fit_order(sphere[index])[k]`` of a fit on it."""
        idx = np.arange(len(self)) if index is None else np.asarray(index, dtype=np.int64)
        w = np.ones(len(idx)) if weight is None else np.broadcast_to(
            np.asarray(weight, dtype=float), idx.shape)
        sph = self.sphere[idx]
        return FitData.create(
            tip_points=self.a[idx[sph]], tip_radius=self.radius[idx[sph]], tip_weight=w[sph],
            link_a=self.a[idx[~sph]], link_b=self.b[idx[~sph]],
            link_radius=self.radius[idx[~sph]], link_weight=w[~sph],
            free_points=free_points, dim=self.dim)

    @staticmethod
    def fit_order(sphere: NDArray[np.bool_]) -> IntArray:
        """Positions, in the fit's residual order (tips first), of readings with these
        ``sphere`` flags: ``residuals[fit_order(s)]`` is back in the given order."""
        sph = np.asarray(sphere, dtype=bool)
        pos = np.empty(len(sph), dtype=np.int64)
        n_tip = int(np.count_nonzero(sph))
        pos[sph] = np.arange(n_tip)
        pos[~sph] = n_tip + np.arange(len(sph) - n_tip)
        return pos

    def from_fit_rows(self, values: ArrayLike) -> FloatArray:
        """Per-reading values from the rows of a fit on :meth:`fit_data` of every reading
        (tips first, then links)."""
        return np.asarray(values)[self._fit_position]


def readings_from_contacts(
    link: ArrayLike, p_tip: ArrayLike, sphere_center: ArrayLike, sphere_radius: ArrayLike,
    seg_a: ArrayLike, seg_b: ArrayLike, side_radius: ArrayLike,
    candidates: dict[int, list[tuple[int, float, FloatArray, float, FloatArray, FloatArray,
                                     float, float]]] | None = None,
) -> Readings:
    """Readings of ``M`` contacts.

    Parameters
    ----------
    link, p_tip : (M,) the detected link and its tip probability (eq. 2)
    sphere_center, sphere_radius, seg_a, seg_b, side_radius : that link's geometry at the
        contact (the outer sphere and the side)
    candidates : for contacts whose link the joint signals could not tell (a rigid group),
        ``{contact: [(link, prior, centre, sphere radius, a, b, side radius, p_tip), ...]}``
        over every candidate link (the detected one included); others have prior 1 on their
        detected link.

    Returns
    -------
    Readings, two per (contact, candidate link): the sphere and the side.
    """
    link = np.asarray(link, dtype=np.int64).reshape(-1)
    m = link.shape[0]
    p = np.clip(np.asarray(p_tip, dtype=float).reshape(m), P_TIP_CLIP, 1.0 - P_TIP_CLIP)
    P = np.asarray(sphere_center, dtype=float).reshape(m, -1)
    rows: list[tuple] = []
    for i in range(m):
        cands = (candidates or {}).get(i)
        if not cands:
            cands = [(int(link[i]), 1.0, P[i], float(np.asarray(sphere_radius)[i]),
                      np.asarray(seg_a, dtype=float)[i], np.asarray(seg_b, dtype=float)[i],
                      float(np.asarray(side_radius)[i]), float(p[i]))]
        total = sum(c[1] for c in cands)
        for lk, prior, c, wc, a, b, wl, pt in cands:
            pt = float(np.clip(pt, P_TIP_CLIP, 1.0 - P_TIP_CLIP))
            share = prior / total
            if share <= 0:
                continue
            rows.append((i, lk, True, np.log(share * pt), c, c, wc))
            rows.append((i, lk, False, np.log(share * (1.0 - pt)), a, b, wl))
    d = P.shape[1] if m else np.asarray(seg_a).reshape(0, -1).shape[1]
    if not rows:
        z = np.zeros((0, d))
        return Readings(np.zeros(0, int), np.zeros(0, int), np.zeros(0, bool), np.zeros(0), z,
                        z, np.zeros(0), 0)
    cols = list(zip(*rows, strict=True))
    return Readings(
        contact=np.array(cols[0]), link=np.array(cols[1]), sphere=np.array(cols[2]),
        log_prior=np.array(cols[3]), a=np.array(cols[4], dtype=float).reshape(len(rows), d),
        b=np.array(cols[5], dtype=float).reshape(len(rows), d), radius=np.array(cols[6]),
        n_contacts=m)
