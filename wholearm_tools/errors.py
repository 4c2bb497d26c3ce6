"""One exception tree for the toolkit.

Every error a user can cause derives from :class:`WholearmError`; subclasses also inherit the
matching built-in so callers can catch either.  The CLI turns them into one-line messages.
"""

from __future__ import annotations


class WholearmError(Exception):
    """Base class of every error raised on purpose by wholearm_tools."""


class InputError(WholearmError, ValueError):
    """Invalid input value (shape, range, NaN, unknown name)."""


class LogFormatError(WholearmError, ValueError):
    """A log file that cannot be read as a wholearm run (truncated, missing topics, bad payload)."""


class RobotModelError(WholearmError, ValueError):
    """A robot description (URDF or scenario) that does not describe a supported serial chain."""


class ScenarioError(WholearmError, ValueError):
    """A scenario that does not exist or cannot be parsed."""


class OutputError(WholearmError, OSError):
    """An output that cannot be written (unwritable path, existing output without overwrite)."""


class FitError(WholearmError, RuntimeError):
    """Nothing could be fitted (raised by pipelines; single fits return failed results instead)."""
