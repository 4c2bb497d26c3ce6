"""Ctrl-C that no library can swallow.

Python answers a Ctrl-C by raising KeyboardInterrupt wherever the program is, and a library
may catch it (``except BaseException`` around an optional import) or turn it into another
error (raised inside a class body's ``__set_name__``, it comes out as a RuntimeError).  The
command would then carry on and write its outputs, or end with a traceback.  The command line
installs a handler (:func:`install`) that remembers the press before raising: the process
ends as interrupted all the same (:func:`pressed`), and no output is put in place after it
(:func:`check`, called by the atomic writers just before each rename).  Standard library only:
it is imported before anything else.
"""

from __future__ import annotations

import signal
import threading
from types import FrameType

_installed = False
_pressed = False


def remember() -> None:
    """Record that Ctrl-C was pressed (for handlers that hold the interrupt for a moment);
    only in a process that installed the handler (:func:`install`): a library user's own
    Ctrl-C handling is left alone."""
    global _pressed
    _pressed = _pressed or _installed


def _handler(signum: int, frame: FrameType | None) -> None:
    remember()
    raise KeyboardInterrupt


def install() -> None:
    """Make SIGINT remembered as well as raised, from now on (a no-op outside the main
    thread, where signal handlers cannot be set, and where Ctrl-C is ignored: Python keeps an
    inherited SIG_IGN, and so does this)."""
    global _installed, _pressed
    if threading.current_thread() is not threading.main_thread():
        return
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:   # nohup, a background job
        return
    _installed, _pressed = True, False
    signal.signal(signal.SIGINT, _handler)


def release() -> None:
    """Give SIGINT back its default action (the command is done: a late Ctrl-C then ends the
    process quietly, as it would any program)."""
    if _installed and threading.current_thread() is threading.main_thread() and \
            signal.getsignal(signal.SIGINT) is _handler:
        signal.signal(signal.SIGINT, signal.SIG_DFL)


def pressed() -> bool:
    """Whether Ctrl-C was pressed since :func:`install`."""
    return _pressed


def check() -> None:
    """Raise KeyboardInterrupt if Ctrl-C was pressed, even if the first one was swallowed."""
    if _pressed:
        raise KeyboardInterrupt
