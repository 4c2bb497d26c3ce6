"""Contact detection and link identification from joint velocities and commanded torques."""

from wholearm_tools.contacts.detect import (
    Contacts,
    DetectionParams,
    detect_contacts,
)
from wholearm_tools.contacts.truth import arm_stops, in_contact_at, match_events, pair_events

__all__ = ["Contacts", "DetectionParams", "arm_stops", "detect_contacts", "in_contact_at",
           "match_events", "pair_events"]
