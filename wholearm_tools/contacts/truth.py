"""Scoring helpers: pair detected contacts with ground-truth contacts (simulated runs only)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linear_sum_assignment

from wholearm_tools.contacts.detect import Contacts
from wholearm_tools.logs.records import GroundTruth


def match_events(contacts: Contacts, truth: GroundTruth, tol: float = 0.05,
                 min_duration: float = 0.05) -> NDArray[np.int64]:
    """Index of the ground-truth contact event each detected contact corresponds to, -1 if none
    (:func:`pair_events` on the detections' intervals, links and settled times)."""
    return pair_events(contacts.t, contacts.t_end, contacts.link, truth,
                       at=contacts.t_settle, tol=tol, min_duration=min_duration)


def _event_spans(truth: GroundTruth, min_duration: float) -> tuple[np.ndarray, np.ndarray]:
    """Each true event's ``[start, end]`` (``min_duration`` long where its end is unknown)."""
    ts = np.asarray(truth.contact_t, dtype=float)
    te = np.asarray(truth.contact_t_end, dtype=float)
    return ts, np.where(np.isfinite(te), np.maximum(te, ts), ts + min_duration)


def in_contact_at(at: ArrayLike, link: ArrayLike, truth: GroundTruth, tol: float = 0.05,
                  min_duration: float = 0.05) -> NDArray[np.bool_]:
    """``(M, E)``: which true events were on each detection's named ``link`` and in contact
    (within ``tol``) at ``at``, the time it settled — the contacts its configuration
    measured."""
    ts, te = _event_spans(truth, min_duration)
    ta = np.asarray(at, dtype=float).reshape(-1)[:, None]
    return ((np.asarray(link).reshape(-1)[:, None] == np.asarray(truth.contact_link)[None, :])
            & (ts[None, :] - tol <= ta) & (ta <= te[None, :] + tol))


def arm_stops(truth: GroundTruth) -> list[NDArray[np.int64]]:
    """The arm's stops against contact: the true events that stopped it, grouped by the
    configuration they settled in (the arm can be held by two contacts at once, and one
    configuration shows one stop).  A stop is detected when a detection pairs with any of its
    events."""
    stopped = np.flatnonzero(np.asarray(truth.contact_stopped, dtype=bool))
    q = np.asarray(truth.contact_q, dtype=float)
    if len(stopped) == 0:
        return []
    if q.shape[1] == 0:         # no configurations recorded: each event its own stop
        return [np.array([j]) for j in stopped]
    _, group = np.unique(np.round(q[stopped], 9), axis=0, return_inverse=True)
    group = np.asarray(group).reshape(-1)
    return sorted((stopped[group == g] for g in range(int(group.max()) + 1)),
                  key=lambda events: int(events[0]))


def pair_events(t: ArrayLike, t_end: ArrayLike | None, link: ArrayLike | None,
                truth: GroundTruth, *, at: ArrayLike | None = None, tol: float = 0.05,
                min_duration: float = 0.05) -> NDArray[np.int64]:
    """Index of the ground-truth contact event each detection corresponds to, -1 if none.

    A detection spans ``[t, t_end]`` (first obstruction to release; a moment where ``t_end``
    is not known) and a true event ``[contact_t, contact_t_end]`` (``min_duration`` long where
    its end is unknown); they may pair when the intervals overlap, or come within ``tol``
    seconds of each other (the velocity filter delays a detection's start a little).  Pairing
    is one to one, as many pairs as possible, then the largest total overlap, where a pair
    whose true event is on the link the detection names counts ``tol`` more: of two contacts
    held at one stop, the detection measured the one on its link.  So a detection that spans
    two true events (two links obstructed one after the other) matches only one of them, and
    a second detection within one true event (a contact split in two) matches nothing.

    ``at`` is when each detection measured its configuration (the sample it settled at).  A
    detection is a reading "link ``l`` touched at this configuration": a true event on link
    ``l`` that was in contact then (within ``tol``) is the one it measured, and that pair comes
    before any difference of overlap — the arm is often held by a second contact that began
    earlier and overlaps the detection longer (a body contact the arm slid along before the
    tip stopped it).  Such a detection pairs with no other: when another detection has that
    contact (the contact split in two), it is a repeat and matches nothing, not a contact of
    another link held at the same time, which it did not name.

    Parameters
    ----------
    t : (M,) float; t_end : (M,) float or None (NaN entries: a moment at ``t``)
    link : (M,) int or None (no link preference); at : (M,) float or None

    Returns
    -------
    (M,) int
    """
    ds = np.asarray(t, dtype=float).reshape(-1)
    m = ds.shape[0]
    out = np.full(m, -1, dtype=np.int64)
    if m == 0 or truth.n_contacts == 0:
        return out
    de = ds if t_end is None else np.asarray(t_end, dtype=float).reshape(-1)
    de = np.where(np.isfinite(de), np.maximum(de, ds), ds)
    ts, te = _event_spans(truth, min_duration)
    overlap = (np.minimum(de[:, None], te[None, :]) - np.maximum(ds[:, None], ts[None, :])
               + tol)
    feasible = overlap > 0
    # as many pairs as possible (each pair's base gain exceeds what the other terms can add
    # up to in any pairing); then the events each detection measured on its link; then the
    # largest total overlap, a true event on the link the detection names counting ``tol``
    # more; remaining ties go to the nearest start
    same_link = np.zeros(overlap.shape, dtype=bool)
    if link is not None:
        same_link = (np.asarray(link).reshape(-1)[:, None]
                     == np.asarray(truth.contact_link)[None, :])
    measured = np.zeros_like(same_link)
    if at is not None and link is not None:
        measured = in_contact_at(at, link, truth, tol, min_duration)
        # a detection whose link was in contact where it settled measured that contact: it
        # pairs with it or, when another detection of the same contact has it, with nothing
        # (a repeat), never with a concurrent contact of another link it did not name
        feasible &= measured | ~measured.any(axis=1, keepdims=True)
    bonus = float(np.max(overlap)) + tol      # more than any difference of overlap
    span = min(overlap.shape) * (float(np.max(overlap)) + 2 * tol + bonus) + 1.0
    gain = np.where(feasible, span + bonus * measured + overlap + tol * same_link
                    - 1e-6 * np.abs(ds[:, None] - ts[None, :]), 0.0)
    rows, cols = linear_sum_assignment(gain, maximize=True)
    keep = feasible[rows, cols]
    out[rows[keep]] = cols[keep]
    return out
