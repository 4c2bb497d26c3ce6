"""Swept occupancy map and tip probability (the paper's eqs. 1 and 2)."""

from wholearm_tools.classify.swept import NEVER, SweptMap, default_resolution, swept_map
from wholearm_tools.classify.tip import (
    LABELS,
    Classification,
    ClassifyParams,
    TipEvaluator,
    tip_probability,
    tip_probability_history,
)

__all__ = ["LABELS", "NEVER", "Classification", "ClassifyParams", "SweptMap", "TipEvaluator",
           "default_resolution", "swept_map", "tip_probability", "tip_probability_history"]
