"""Surface reconstruction: primitive fits from tip and link contacts, and fit-and-grow.

Public API
----------
:class:`FitData`          the contacts to fit (columnar: tips, links, free-space hints)
:func:`fit_primitive`     one primitive of a given type, CasADi/IPOPT -> :class:`FitResult`
:func:`residuals`, :func:`cost`   the fitted quantity for given parameters
:func:`segment`           fit-and-grow segmentation -> :class:`Segmentation`
"""

from wholearm_tools.fit.core import LOSSES, cost, fit_primitive, residuals
from wholearm_tools.fit.data import FitData, weight_from_tip_probability
from wholearm_tools.fit.result import FitResult
from wholearm_tools.fit.segment import Segmentation, segment

__all__ = [
    "LOSSES",
    "FitData",
    "FitResult",
    "Segmentation",
    "cost",
    "fit_primitive",
    "residuals",
    "segment",
    "weight_from_tip_probability",
]
