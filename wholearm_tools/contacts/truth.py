"""Scoring helpers: pair detected contacts with ground-truth contacts (simulated runs only)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.contacts.detect import Contacts
from wholearm_tools.logs.records import GroundTruth


def match_truth(contacts: Contacts, truth: GroundTruth, max_lag: float = 0.1,
                lead: float = 0.005) -> NDArray[np.int64]:
    """Index of the ground-truth contact each detected contact corresponds to, -1 if none.

    A detection at ``t_d`` matches the latest unmatched truth contact with
    ``t_d - max_lag <= t_true <= t_d + lead`` (detection lags the touch by the velocity filter
    and the stop test).  Matching is one-to-one, in time order.

    Returns ``(M,) int``.
    """
    out = np.full(len(contacts), -1, dtype=np.int64)
    used = np.zeros(truth.n_contacts, dtype=bool)
    tt = np.asarray(truth.contact_t)
    for k, td in enumerate(np.asarray(contacts.t)):
        cand = np.flatnonzero((tt >= td - max_lag) & (tt <= td + lead) & ~used)
        if cand.size:
            j = int(cand[np.argmax(tt[cand])])
            out[k] = j
            used[j] = True
    return out
