"""Pairing detections with true contact events (the benchmarks' scoring)."""

import numpy as np

from wholearm_tools.contacts import Contacts, match_events
from wholearm_tools.logs.records import GroundTruth


def _contacts(t, t_end, link, n=3, t_settle=None):
    m = len(t)
    return Contacts(np.asarray(t, float), np.asarray(link), np.zeros(m, int), np.zeros((m, n)),
                    np.zeros((m, n)), np.asarray(t_end, float), np.ones(n), np.ones(n),
                    t_settle=t_settle)


def _truth(t, t_end, link, kind):
    m = len(t)
    return GroundTruth(surfaces=(), contact_t=np.asarray(t, float),
                       contact_link=np.asarray(link), contact_kind=np.asarray(kind),
                       contact_point=np.zeros((m, 3)), contact_surface=np.zeros(m, int),
                       contact_s=np.ones(m), contact_t_end=np.asarray(t_end, float))


def test_a_stop_held_by_two_contacts_pairs_the_detection_with_the_one_on_its_link():
    # the tip touched at 1.0 s and slid, the elbow touched at 1.48 s, the arm stopped and was
    # released at 2.5 s; the detector named the tip's link from 1.5 s on
    truth = _truth([1.0, 1.48], [2.5, 2.5], [2, 1], ["tip", "joint"])
    assert match_events(_contacts([1.5], [2.5], [2]), truth).tolist() == [0]
    # named the elbow's link instead: it measured the elbow contact
    assert match_events(_contacts([1.5], [2.5], [1]), truth).tolist() == [1]


def test_pairing_takes_as_many_pairs_as_it_can_before_the_larger_overlap():
    # detection 0 overlaps both events, detection 1 only the second: pairing detection 0 with
    # the second event (the larger overlap) would leave detection 1 unpaired
    truth = _truth([1.0, 2.0], [2.2, 3.0], [2, 2], ["body", "tip"])
    det = _contacts([1.9, 2.6], [3.0, 3.0], [2, 2])
    assert match_events(det, truth).tolist() == [0, 1]


def test_a_detection_far_from_every_true_event_stays_unpaired():
    truth = _truth([1.0], [1.4], [1], ["body"])
    det = _contacts([1.05, 5.0], [1.4, 5.3], [1, 1])
    assert match_events(det, truth).tolist() == [0, -1]


def test_a_detection_pairs_with_the_contact_on_its_link_held_where_it_measured():
    # the elbow (link 1) touched at 1.0 s and the arm slid along it; the tip (link 2) stopped
    # it at 2.3 s, where the detection settled and named link 2.  The elbow's event overlaps the
    # detection far longer, but the detection measured the tip's contact
    truth = _truth([1.0, 2.3], [2.8, 2.6], [1, 2], ["body", "tip"])
    assert match_events(_contacts([1.02], [2.8], [2], t_settle=[2.4]), truth).tolist() == [1]
    # settled before the tip touched: the tip's contact is not what it measured
    assert match_events(_contacts([1.02], [2.8], [2], t_settle=[2.0]), truth).tolist() == [0]


def test_a_second_detection_of_one_contact_is_a_repeat_not_a_concurrent_contact():
    # the tip (link 2) touched at 1.0 s and held until 3.0 s; the elbow (link 1) touched at
    # 2.0 s while it held; chatter split the tip's contact into two detections, both naming
    # link 2 and settling while the tip touched.  The second is a repeat of the tip's contact:
    # it matches nothing, and the elbow's contact, which no detection named, is not found
    truth = _truth([1.0, 2.0], [3.0, 3.0], [2, 1], ["tip", "joint"])
    det = _contacts([1.0, 2.1], [2.0, 3.0], [2, 2], t_settle=[1.5, 2.5])
    assert match_events(det, truth).tolist() == [0, -1]
    # the same second detection naming the elbow's link measured the elbow's contact
    det = _contacts([1.0, 2.1], [2.0, 3.0], [2, 1], t_settle=[1.5, 2.5])
    assert match_events(det, truth).tolist() == [0, 1]
