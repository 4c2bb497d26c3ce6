"""Ctrl-C that a library swallows still ends the command and puts no output in place."""

from __future__ import annotations

import os
import signal
import time

import pytest

from wholearm_tools import _interrupt
from wholearm_tools._io import atomic_output


def _press_and_swallow() -> None:
    """Ctrl-C arriving inside code that catches everything (an optional import's guard)."""
    try:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(1.0)        # the handler runs here and raises
    except BaseException:      # what the library does
        pass


def test_a_swallowed_ctrl_c_still_stops_the_output_from_being_put_in_place(tmp_path,
                                                                           monkeypatch):
    previous = signal.getsignal(signal.SIGINT)
    monkeypatch.setattr(_interrupt, "_installed", False)    # restored after the test
    monkeypatch.setattr(_interrupt, "_pressed", False)
    try:
        # Python's own Ctrl-C handling, whatever the test runner inherited (a suite started as
        # a background job ignores SIGINT, and install() then rightly leaves it ignored)
        signal.signal(signal.SIGINT, signal.default_int_handler)
        _interrupt.install()
        assert not _interrupt.pressed()
        _press_and_swallow()
        assert _interrupt.pressed()
        with pytest.raises(KeyboardInterrupt), atomic_output(tmp_path / "x.csv", "w") as fh:
            fh.write("t,link\n")
        assert list(tmp_path.iterdir()) == []
        _interrupt.install()           # a new command starts unpressed
        with atomic_output(tmp_path / "x.csv", "w") as fh:
            fh.write("t,link\n")
        assert (tmp_path / "x.csv").read_text() == "t,link\n"
    finally:
        signal.signal(signal.SIGINT, previous)
