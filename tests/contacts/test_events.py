"""Contact events from per-joint masks: a slide belongs to the stop it ends in, a rebound
joined by a slide is one contact, a stop that follows no motion is none, and the link is the
outermost obstructed joint."""

import numpy as np

from wholearm_tools.contacts.events import segment_events

N, n = 400, 3
MIN_LEN, RELEASE = 10, 20


def _masks():
    obstructed = np.zeros((N, n), bool)
    moving = np.zeros((N, n), bool)
    free_moving = np.zeros((N, n), bool)
    dragging = np.zeros((N, n), bool)
    return obstructed, moving, free_moving, dragging


def test_a_slide_that_ends_in_a_stop_is_one_event_from_the_slide_on():
    obs, mov, free, drag = _masks()
    mov[0:20] = free[0:20] = True            # a first, separate contact
    obs[20:40, :] = True
    mov[40:80] = free[40:80] = True          # free motion
    mov[80:150] = True                       # the tip touches at 80 and slides ...
    drag[80:150, 2] = True                   # ... pushing along its motion
    obs[150:300, :] = True                   # ... until it holds
    events = segment_events(obs, mov, free, MIN_LEN, RELEASE, drag)
    assert [(e.start, e.end, e.link) for e in events] == [(20, 40, 2), (80, 300, 2)]
    # without the slide evidence the event starts where the arm held
    assert segment_events(obs, mov, free, MIN_LEN, RELEASE)[1].start == 150


def test_a_rebound_joined_by_a_slide_is_one_contact():
    obs, mov, free, drag = _masks()
    mov[20:60] = free[20:60] = True
    obs[60:100, :2] = True                   # holds, rebounds and slides back ...
    mov[100:180, :2] = True
    drag[100:180, 1] = True
    obs[180:260, :2] = True                  # ... and holds again
    events = segment_events(obs, mov, free, MIN_LEN, RELEASE, drag)
    assert [(e.start, e.end, e.link) for e in events] == [(60, 260, 1)]
    # a free motion between the two stops makes them two contacts
    free[100:180, :2] = True
    drag[:] = False
    assert len(segment_events(obs, mov, free, MIN_LEN, RELEASE, drag)) == 2


def test_a_load_on_joints_that_did_not_move_is_no_contact():
    obs, mov, free, drag = _masks()
    obs[100:200, 2] = True                   # loaded but held all along (inertia)
    assert segment_events(obs, mov, free, MIN_LEN, RELEASE, drag) == []


def test_the_link_is_the_last_to_stop_even_when_it_slides_on_under_the_load():
    """The inner joints hold against the contact while the wrist keeps turning, slowed, pushing
    along its motion (the tip sliding on the surface): the wrist's link is in contact.  A
    wrist that pushes beyond the free-motion model only for moments as the inner joints come
    to rest (catching up with its reference), or only before they do (another contact, since
    left), does not name its link."""
    obs, mov, free, drag = _masks()
    mov[20:100] = free[20:100] = True        # the approach
    obs[100:300, :2] = True                  # shoulder and elbow held from 100 ...
    mov[100:300, 2] = True                   # ... the wrist slides on under the load
    drag[100:300, 2] = True
    events = segment_events(obs, mov, free, MIN_LEN, RELEASE, drag)
    assert [(e.start, e.end, e.link) for e in events] == [(100, 300, 2)]
    assert segment_events(obs, mov, free, MIN_LEN, RELEASE)[0].link == 1
    # the wrist moves freely once the inner joints are held, after pushing for a moment
    drag[115:300, 2] = False
    free[115:300, 2] = True
    assert segment_events(obs, mov, free, MIN_LEN, RELEASE, drag)[0].link == 1
    # the elbow comes to rest only at 200; the wrist dragged until 180
    obs[100:200, 1] = False
    drag[100:180, 2] = True
    free[100:180, 2] = False
    assert segment_events(obs, mov, free, MIN_LEN, RELEASE, drag)[0].link == 1
