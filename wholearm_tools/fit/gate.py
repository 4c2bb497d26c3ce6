"""The one report gate: is a selected primitive determined by its contacts?

A contact's position is known only up to the kinematic errors of the arm that touched it:
encoder noise, joint offsets and link-length errors.  The policy states them as one standard
deviation ``sigma_kin`` of a contact's position, a fraction of the robot's reach (or the measured
noise, when that is larger).  Under that model the parameters of a primitive fitted to ``n``
contacts have the Gauss-Newton covariance ``sigma_kin^2 (J^T J)^-1`` on the type's minimal
parameterisation (lengths in units of the support's RMS spread, so one number speaks for every
type).  A primitive reaches the map when

* its worst-determined parameter combination has a standard deviation of at most
  ``max_rel_std`` of its support's size, and
* it still has without any one of its contacts (the influence of a single contact): every
  contact's reading is inferred (tip or side, which link), so a primitive that one contact
  alone determines rests on one inference, and that contact's residual cannot show whether it
  is wrong.

The leave-one-out information ``J^T J - j_i^T j_i`` is a rank-one downdate, so the check costs
no refit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wholearm_tools.fit.core import _link_min, _normalise, _raw_from_params
from wholearm_tools.fit.data import FitData
from wholearm_tools.fit.models import MODELS
from wholearm_tools.fit.result import FitResult
from wholearm_tools.fit.solve import sd_and_jacobian, tangent_basis


@dataclass(frozen=True, slots=True)
class GateResult:
    """``worst_std``: the worst parameter combination's standard deviation in units of the
    support's spread with every contact; ``worst_std_loo``: the largest of it over the fits
    without one contact, and ``pivot`` that contact's position in the data (-1 when none is
    needed); ``reason``: why the primitive is not reported ('' when it is)."""

    worst_std: float
    worst_std_loo: float
    pivot: int
    reason: str

    def __bool__(self) -> bool:
        return not self.reason


def information_rows(fit: FitResult, data: FitData) -> tuple[np.ndarray, float]:
    """Per-contact rows ``(n, dof)`` of the Jacobian on the minimal parameterisation
    (normalised units: the support's centroid at the origin, unit RMS spread) at ``fit``, and
    that spread [m]."""
    m = MODELS[fit.kind]
    nd = _normalise(data)
    if nd is None:
        return np.zeros((0, m.dof)), 0.0
    th = _raw_from_params(m, fit.params, nd)
    side = float(fit.free_side)
    if m.linear:
        side = 1.0  # lines and planes carry their free side in the normal
    _, t, _ = _link_min(m, th, side, nd.a, nd.b)
    pts = np.vstack([nd.tip, nd.a + t[:, None] * (nd.b - nd.a)]) if len(nd.a) else nd.tip
    _, J = sd_and_jacobian(m.kind, th, pts)
    return J @ tangent_basis(m.kind, th), float(nd.scale)


def report_gate(fit: FitResult, data: FitData, sigma_kin: float, max_rel_std: float
                ) -> GateResult:
    """Whether ``fit`` (on ``data``) may be reported: see the module docstring."""
    rows, scale = information_rows(fit, data)
    n, dof = rows.shape
    if n <= dof or scale <= 0:
        return GateResult(math.inf, math.inf, -1,
                          f"{n} contacts cannot determine its {dof} parameters")
    s = sigma_kin / scale
    H = rows.T @ rows

    def worst(h: np.ndarray) -> float:
        lam = np.linalg.eigvalsh(h)[0]
        return s / math.sqrt(lam) if lam > 0 else math.inf

    w_all = worst(H)
    if not w_all <= max_rel_std:
        return GateResult(w_all, math.inf, -1,
                          "its contacts do not determine every parameter (worst combination "
                          f"{_fmt(w_all)} of its support's size at kinematic errors of "
                          f"{sigma_kin * 1e3:.2g} mm)")
    loo = [worst(H - np.outer(r, r)) for r in rows]
    i = int(np.argmax(loo))
    if not loo[i] <= max_rel_std:
        return GateResult(w_all, loo[i], i,
                          "one of its contacts alone determines it: without it, the worst "
                          f"parameter combination is {_fmt(loo[i])} of its support's size")
    return GateResult(w_all, loo[i], -1, "")


def _fmt(x: float) -> str:
    return "unbounded" if not math.isfinite(x) else f"{x:.2g}"
