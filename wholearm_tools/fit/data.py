"""The fit input record: tip contacts, link contacts and free-space hints, columnar."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from wholearm_tools.errors import InputError

FloatArray = np.ndarray

#: smallest weight given to an ambiguous contact by :func:`weight_from_tip_probability`
MIN_WEIGHT = 0.05


def weight_from_tip_probability(p_tip: ArrayLike, is_tip: ArrayLike) -> FloatArray:
    """Relative weight (1/sigma^2 up to a common factor) of each contact from its tip probability.

    A contact labelled tip is right with probability ``P_T``, one labelled link with ``1 - P_T``.
    The residual of a wrongly labelled contact is of the order of the link length rather than the
    noise, so the variance of a contact grows as the probability of its label falls:
    ``sigma_i^2 = sigma^2 / P(label correct)``, i.e. ``weight = P(label correct)``, floored at
    :data:`MIN_WEIGHT` so that ambiguous contacts still count, a little.

    Parameters
    ----------
    p_tip : (N,) float in [0, 1]
    is_tip : (N,) bool, the label used for each contact
    """
    p = np.asarray(p_tip, dtype=float)
    lab = np.asarray(is_tip, dtype=bool)
    if p.shape != lab.shape:
        raise InputError(f"p_tip {p.shape} and is_tip {lab.shape} must have the same shape")
    if not np.all(np.isfinite(p)) or np.any((p < 0) | (p > 1)):
        raise InputError("p_tip must be finite probabilities in [0, 1]")
    return np.maximum(np.where(lab, p, 1.0 - p), MIN_WEIGHT)


def _points(x: ArrayLike | None, dim: int, name: str) -> FloatArray:
    if x is None:
        return np.zeros((0, dim))
    arr = np.asarray(x, dtype=float)
    if arr.size == 0:
        return np.zeros((0, dim))
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise InputError(f"expected {name} of shape (N, {dim}), got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contain NaN or infinite values")
    return arr


def _column(x: ArrayLike, n: int, name: str, positive: bool) -> FloatArray:
    arr = np.asarray(x, dtype=float)
    if arr.ndim == 0:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        raise InputError(f"expected {name} of shape ({n},) or a scalar, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contain NaN or infinite values")
    if np.any(arr < 0) or (positive and n and not np.any(arr > 0)):
        raise InputError(f"{name} must be >= 0, got min {arr.min() if n else None}")
    return arr


def _freeze(*arrays: FloatArray) -> None:
    for a in arrays:
        a.flags.writeable = False


class FreeSpace:
    """Points known to be in free space (the robot's positions over a run), validated once and
    shared by every fit made on the run's contacts.  A fit asks which of them lie near its own
    contacts (:meth:`near`); a k-d tree, built on the first such question, answers without
    scanning them all."""

    __slots__ = ("_tree", "points")

    def __init__(self, points: ArrayLike | None, dim: int) -> None:
        self.points = _points(points, dim, "free_points").copy()
        _freeze(self.points)
        self._tree: cKDTree | None = None

    @classmethod
    def of(cls, points: ArrayLike | FreeSpace | None, dim: int) -> FreeSpace:
        """``points`` as a :class:`FreeSpace` (itself when it already is one)."""
        if isinstance(points, FreeSpace):
            if points.dim != dim:
                raise InputError(f"expected free_points of shape (Nf, {dim}), got "
                                 f"{points.points.shape}")
            return points
        return cls(points, dim)

    @property
    def dim(self) -> int:
        return int(self.points.shape[1])

    def __len__(self) -> int:
        return len(self.points)

    def near(self, centres: FloatArray, radius: float) -> NDArray[np.int64]:
        """Indices (ascending) of the points within ``radius`` of any of ``centres (k, d)``."""
        if len(self.points) == 0 or len(centres) == 0:
            return np.zeros(0, dtype=np.int64)
        if self._tree is None:
            self._tree = cKDTree(self.points)
        hit = np.zeros(len(self.points), dtype=bool)
        for ball in self._tree.query_ball_point(np.asarray(centres, dtype=float), radius,
                                                return_sorted=False):
            hit[ball] = True
        return np.flatnonzero(hit)


@dataclass(frozen=True, slots=True)
class FitData:
    """Contacts to fit, columnar.  Build with :meth:`create` (scalars broadcast).

    Attributes
    ----------
    tip_points : (Nt, d) float
        Tip (or joint-sphere) centres in contact.
    tip_radius : (Nt,) float
        Sphere radius ``w`` of each tip contact (0 for a sharp tip).
    tip_weight : (Nt,) float
        Relative weight ``1/sigma_i^2`` (see :func:`weight_from_tip_probability`).
    link_a, link_b : (Nl, d) float
        End points of the link axis segment in contact (the contact point is unknown).
    link_radius : (Nl,) float
        Capsule radius ``w`` of each link contact.
    link_weight : (Nl,) float
    free : FreeSpace
        Points known to be in free space (robot positions); they fix the free side.
        ``free_points`` is their ``(Nf, d)`` array.

    Contact index ``i`` runs over tips first (``0 .. Nt-1``) then links (``Nt .. Nt+Nl-1``).
    """

    tip_points: FloatArray
    tip_radius: FloatArray
    tip_weight: FloatArray
    link_a: FloatArray
    link_b: FloatArray
    link_radius: FloatArray
    link_weight: FloatArray
    free: FreeSpace

    def __post_init__(self) -> None:
        d = self.tip_points.shape[1] if self.tip_points.ndim == 2 else -1
        if d not in (2, 3):
            raise InputError(f"expected points of dimension 2 or 3, got {self.tip_points.shape}")
        nt, nl = len(self.tip_points), len(self.link_a)
        for name, arr, shape in (
            ("link_a", self.link_a, (nl, d)), ("link_b", self.link_b, (nl, d)),
            ("tip_radius", self.tip_radius, (nt,)), ("tip_weight", self.tip_weight, (nt,)),
            ("link_radius", self.link_radius, (nl,)), ("link_weight", self.link_weight, (nl,)),
        ):
            if arr.shape != shape:
                raise InputError(f"expected {name} of shape {shape}, got {arr.shape}")
        if self.free.dim != d:
            raise InputError(f"expected free_points of shape (Nf, {d}), got "
                             f"{self.free_points.shape}")
        _freeze(self.tip_points, self.tip_radius, self.tip_weight, self.link_a, self.link_b,
                self.link_radius, self.link_weight)

    @classmethod
    def create(
        cls,
        tip_points: ArrayLike | None = None,
        tip_radius: ArrayLike = 0.0,
        tip_weight: ArrayLike = 1.0,
        link_a: ArrayLike | None = None,
        link_b: ArrayLike | None = None,
        link_radius: ArrayLike = 0.0,
        link_weight: ArrayLike = 1.0,
        free_points: ArrayLike | FreeSpace | None = None,
        dim: int | None = None,
    ) -> FitData:
        """Validate and build; radii and weights may be scalars.  ``dim`` is inferred from the
        first non-empty point array when not given.  ``free_points`` given as a
        :class:`FreeSpace` is shared, not copied (the many fits of one run)."""
        if dim is None:
            for x in (tip_points, link_a, free_points):
                if isinstance(x, FreeSpace):
                    dim = x.dim
                    break
                if x is not None and np.size(x):
                    dim = int(np.shape(x)[-1])
                    break
        if dim not in (2, 3):
            raise InputError(f"points must be 2-D or 3-D (got dim={dim}); pass dim= for empty data")
        tp = _points(tip_points, dim, "tip_points")
        la = _points(link_a, dim, "link_a")
        lb = _points(link_b, dim, "link_b")
        if la.shape != lb.shape:
            raise InputError(f"link_a {la.shape} and link_b {lb.shape} must have the same shape")
        fp = FreeSpace.of(free_points, dim)
        nt, nl = len(tp), len(la)
        return cls(
            tp.copy(), _column(tip_radius, nt, "tip_radius", False).copy(),
            _column(tip_weight, nt, "tip_weight", True).copy(),
            la.copy(), lb.copy(), _column(link_radius, nl, "link_radius", False).copy(),
            _column(link_weight, nl, "link_weight", True).copy(), fp,
        )

    @property
    def dim(self) -> int:
        return int(self.tip_points.shape[1])

    @property
    def free_points(self) -> FloatArray:
        return self.free.points

    @property
    def n_tip(self) -> int:
        return len(self.tip_points)

    @property
    def n_link(self) -> int:
        return len(self.link_a)

    @property
    def n_contacts(self) -> int:
        return self.n_tip + self.n_link

    def contact_points(self) -> FloatArray:
        """One representative point per contact, ``(N, d)``: tip points then link midpoints."""
        return np.vstack([self.tip_points, 0.5 * (self.link_a + self.link_b)])

    def take(self, index: ArrayLike) -> FitData:
        """The contacts with the given contact indices (tips first, then links)."""
        idx = np.unique(np.asarray(index, dtype=int))
        if idx.size and (idx[0] < 0 or idx[-1] >= self.n_contacts):
            raise InputError(f"contact index out of range 0..{self.n_contacts - 1}")
        ti = idx[idx < self.n_tip]
        li = idx[idx >= self.n_tip] - self.n_tip
        return FitData(
            self.tip_points[ti].copy(), self.tip_radius[ti].copy(), self.tip_weight[ti].copy(),
            self.link_a[li].copy(), self.link_b[li].copy(), self.link_radius[li].copy(),
            self.link_weight[li].copy(), self.free,
        )
