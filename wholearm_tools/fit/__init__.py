"""Surface reconstruction: primitive fits from tip and link contacts, and the inference loop.

Public API
----------
:class:`FitData`          the contacts to fit (columnar: tips, links, free-space hints)
:func:`fit_primitive`     one primitive of a given type -> :class:`FitResult`
:func:`residuals`, :func:`cost`   the fitted quantity for given parameters
:func:`readings_from_contacts`   contacts as mixtures of readings -> :class:`Readings`
:func:`infer`             hypotheses, one score, selection -> :class:`Inference`
:func:`report_gate`       covariance under a kinematic error model -> :class:`GateResult`
:func:`influence`         each contact's Cook's distance on a fit
:func:`added_cost`        the cost a fit is predicted to reach with one contact more
:func:`joining_residuals` contacts' residuals in units of their refit's prediction spread
:class:`FitPolicy`        every parameter of the loop in one frozen record
"""

from wholearm_tools.fit.core import LOSSES, cost, fit_primitive, residuals
from wholearm_tools.fit.data import FitData, weight_from_tip_probability
from wholearm_tools.fit.gate import (
    GateResult,
    added_cost,
    influence,
    joining_residuals,
    lying_flat,
    report_gate,
)
from wholearm_tools.fit.infer import Inference, infer
from wholearm_tools.fit.policy import FitPolicy
from wholearm_tools.fit.readings import Readings, readings_from_contacts
from wholearm_tools.fit.result import FitResult

__all__ = [
    "LOSSES",
    "FitData",
    "FitPolicy",
    "FitResult",
    "GateResult",
    "Inference",
    "Readings",
    "added_cost",
    "cost",
    "fit_primitive",
    "infer",
    "influence",
    "joining_residuals",
    "lying_flat",
    "readings_from_contacts",
    "report_gate",
    "residuals",
    "weight_from_tip_probability",
]
