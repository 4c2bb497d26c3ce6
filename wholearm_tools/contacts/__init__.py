"""Contact detection and link identification from joint velocities and commanded torques."""

from wholearm_tools.contacts.detect import (
    Contacts,
    DetectionParams,
    contact_link_per_sample,
    detect_contacts,
    estimate_noise,
)
from wholearm_tools.contacts.truth import match_truth

__all__ = ["Contacts", "DetectionParams", "contact_link_per_sample", "detect_contacts",
           "estimate_noise", "match_truth"]
