"""Scoring helpers: pair detected contacts with ground-truth contacts (simulated runs only)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

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


def match_events(contacts: Contacts, truth: GroundTruth, tol: float = 0.05,
                 min_duration: float = 0.05, at: NDArray[np.float64] | None = None,
                 ) -> NDArray[np.int64]:
    """Index of the ground-truth contact event each detected contact corresponds to, -1 if none.

    A detection spans ``[t, t_end]`` (first obstruction to release) and a true event
    ``[contact_t, contact_t_end]`` (``min_duration`` long where its end is unknown); they may
    pair when the intervals overlap, or come within ``tol`` seconds of each other (the velocity
    filter delays a detection's start a little).  Pairing is one to one, as many pairs as
    possible, then the largest total overlap, where a pair whose true event is on the link the
    detection names counts ``tol`` more: of two contacts held at one stop, the detection
    measured the one on its link.  So a detection that spans two true events (two links
    obstructed one after the other) matches only one of them, and a second detection within
    one true event (a contact split in two) matches nothing.

    ``at`` (``(M,)``, optional) is when each detection measured its configuration (the sample
    it settled at, ``log.t[contacts.index]``).  A detection is a reading "link ``l`` touched
    at this configuration": a true event on link ``l`` that was in contact then (within
    ``tol``) is the one it measured, and that pair comes before any difference of overlap —
    the arm is often held by a second contact that began earlier and overlaps the detection
    longer (a body contact the arm slid along before the tip stopped it).

    Returns ``(M,) int``.
    """
    m = len(contacts)
    out = np.full(m, -1, dtype=np.int64)
    if m == 0 or truth.n_contacts == 0:
        return out
    ts = np.asarray(truth.contact_t, dtype=float)
    te = np.asarray(truth.contact_t_end, dtype=float)
    te = np.where(np.isfinite(te), np.maximum(te, ts), ts + min_duration)
    ds = np.asarray(contacts.t, dtype=float)
    de = np.maximum(np.asarray(contacts.t_end, dtype=float), ds)
    overlap = (np.minimum(de[:, None], te[None, :]) - np.maximum(ds[:, None], ts[None, :])
               + tol)
    feasible = overlap > 0
    # as many pairs as possible (each pair's base gain exceeds what overlaps can add up to in
    # any pairing); among those the largest total overlap, a true event on the link the
    # detection names counting ``tol`` more; remaining ties go to the nearest start
    same_link = (np.asarray(contacts.link)[:, None]
                 == np.asarray(truth.contact_link)[None, :])
    measured = np.zeros_like(same_link)
    if at is not None:
        ta = np.asarray(at, dtype=float)[:, None]
        measured = same_link & (ts[None, :] - tol <= ta) & (ta <= te[None, :] + tol)
    bonus = float(np.max(overlap)) + tol      # more than any difference of overlap
    span = min(overlap.shape) * (float(np.max(overlap)) + 2 * tol + bonus) + 1.0
    gain = np.where(feasible, span + overlap + tol * same_link + bonus * measured
                    - 1e-6 * np.abs(ds[:, None] - ts[None, :]), 0.0)
    rows, cols = linear_sum_assignment(gain, maximize=True)
    keep = feasible[rows, cols]
    out[rows[keep]] = cols[keep]
    return out
