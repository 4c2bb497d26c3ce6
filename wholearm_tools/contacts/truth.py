"""Scoring helpers: pair detected contacts with ground-truth contacts (simulated runs only)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.contacts.detect import Contacts
from wholearm_tools.logs.records import GroundTruth


def match_truth(contacts: Contacts, truth: GroundTruth, max_lag: float = 0.1,
                lead: float = 0.005) -> NDArray[np.int64]:
    """Index of the ground-truth contact each detected contact corresponds to, -1 if none.

    A detection at ``t_d`` matches, among the unmatched truth contacts with
    ``t_d - max_lag <= t_true <= t_d + lead``, the one closest to ``t_d - lag`` where ``lag`` is
    the run's median detection lag (the velocity filter and the stop test delay every detection
    by about the same time; this pairs the two rows of a quick two-stage contact in order).
    Matching is one-to-one, in time order.

    Returns ``(M,) int``.
    """
    out = np.full(len(contacts), -1, dtype=np.int64)
    used = np.zeros(truth.n_contacts, dtype=bool)
    tt = np.asarray(truth.contact_t)
    td_all = np.asarray(contacts.t)
    # typical detection lag: median over detections of the lag to the latest truth in window
    lags = []
    for td in td_all:
        cand = tt[(tt >= td - max_lag) & (tt <= td + lead)]
        if cand.size:
            lags.append(td - cand.max())
    lag = float(np.median(lags)) if lags else 0.0
    for k, td in enumerate(td_all):
        cand = np.flatnonzero((tt >= td - max_lag) & (tt <= td + lead) & ~used)
        if cand.size:
            j = int(cand[np.argmin(np.abs(td - lag - tt[cand]))])
            out[k] = j
            used[j] = True
    return out
