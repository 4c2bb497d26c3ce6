"""The fit result record."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

FloatArray = np.ndarray


@dataclass(frozen=True, slots=True)
class FitResult:
    """Outcome of one primitive fit.  Falsy when the fit failed; :attr:`message` says why.

    Attributes
    ----------
    kind : str
        Primitive type (map.json name).
    success : bool
    message : str
        Why the fit failed, or notes on a successful one (e.g. an ambiguous free side).
    status : str
        IPOPT return status (``"Solve_Succeeded"``...) or ``"not_run"`` / ``"degenerate"`` /
        ``"too_few_contacts"`` when the solver was not called.
    iterations : int
        IPOPT iterations, summed over the active-set rounds of the best start.
    cost : float
        Final objective ``sum_i weight_i * rho(r_i)`` in metres^2 (``rho(r) = r^2 / 2`` for the
        linear loss; weights normalised to mean 1).
    params : dict[str, ndarray | float]
        map.json parameters (metres, radians).
    free_side : float
        +1 when free space is outside the closed shape / on the normal side, -1 otherwise.
        Lines and planes are reported with the normal pointing to free space (always +1).
    covariance : (P, P) float or None
        Covariance of the flattened parameters (order :attr:`param_labels`), weighted
        Gauss-Newton ``s^2 B (B^T J^T W J B)^-1 B^T`` on the minimal parameterisation
        (``B`` spans the tangent space of the unit-vector/gauge constraints), scaled by the
        residual variance ``s^2 = sum w r^2 / (n - dof)``.  NaN when ``n <= dof``.
    param_labels : tuple[str, ...]
        ``"center[0]"``, ``"radius"``... naming the rows of :attr:`covariance`.
    ci95 : dict[str, (lower, upper)]
        95 % intervals per parameter (Student t with ``n - dof`` degrees of freedom).
    tip_residuals : (Nt,) float
        ``clearance - w`` of each tip contact (metres; negative = penetration).
    link_residuals : (Nl,) float
        ``min_t clearance(a + t (b - a)) - w`` of each link contact.
    link_t : (Nl,) float
        Latent contact position along each link at the optimum, in [0, 1].
    rms_residual : float
        Root mean square of all residuals (unweighted, metres).
    primitive : geometry object or None
        The fitted :class:`wholearm_tools.geometry.Primitive` (None when the fit failed).
    sensitivity : float
        Identifiability [1/m]: the standard deviation of the worst-determined combination of the
        parameters (lengths in units of :attr:`scale`, unit vectors and angles as they are), per
        metre of residual noise, from the unweighted-loss Gauss-Newton information
        ``(J^T W J)^-1`` on the minimal parameterisation.  ``noise * sensitivity`` well below 1
        means the support constrains every degree of freedom; ``inf`` when some combination is
        not constrained at all (e.g. link contacts that all touch at one common point).
    scale : float
        RMS spread of the support about its centroid [m] (the normalisation length).
    """

    kind: str
    success: bool
    message: str
    status: str
    iterations: int = 0
    cost: float = float("nan")
    params: dict[str, Any] = field(default_factory=dict)
    free_side: float = 1.0
    covariance: FloatArray | None = None
    param_labels: tuple[str, ...] = ()
    ci95: dict[str, tuple[Any, Any]] = field(default_factory=dict)
    tip_residuals: FloatArray = field(default_factory=lambda: np.zeros(0))
    link_residuals: FloatArray = field(default_factory=lambda: np.zeros(0))
    link_t: FloatArray = field(default_factory=lambda: np.zeros(0))
    rms_residual: float = float("nan")
    primitive: Any = None
    sensitivity: float = float("inf")
    scale: float = float("nan")

    def __bool__(self) -> bool:
        return bool(self.success)

    @property
    def residuals(self) -> FloatArray:
        """All residuals in contact order (tips then links), shape ``(N,)``."""
        return np.concatenate([self.tip_residuals, self.link_residuals])

    @property
    def n_contacts(self) -> int:
        return len(self.tip_residuals) + len(self.link_residuals)

    def to_map_entry(self) -> dict[str, Any]:
        """JSON-ready primitive entry of map.json (without ``id`` and ``extent``)."""
        def js(v: Any) -> Any:
            return np.asarray(v).tolist() if np.ndim(v) else float(v)
        return {
            "type": self.kind,
            "params": {k: js(v) for k, v in self.params.items()},
            "ci95": {k: [js(lo), js(hi)] for k, (lo, hi) in self.ci95.items()},
            "covariance": None if self.covariance is None else self.covariance.tolist(),
            "support": {"tip": len(self.tip_residuals), "link": len(self.link_residuals)},
            "rms_residual": float(self.rms_residual),
            "free_side": float(self.free_side),
        }

    def __repr__(self) -> str:
        if not self.success:
            return f"FitResult({self.kind}, failed: {self.message})"
        ps = ", ".join(f"{k}={np.round(v, 6).tolist() if np.ndim(v) else round(float(v), 6)}"
                       for k, v in self.params.items())
        return (f"FitResult({self.kind}, {ps}, rms={self.rms_residual:.3g}, "
                f"n={self.n_contacts}, status={self.status})")
