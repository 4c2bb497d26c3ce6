"""Ctrl-C while a library that swallows BaseException in its imports (trimesh) is imported."""

import importlib
import sys

import pytest

from wholearm_tools._parallel import interruptible_import

SWALLOWING = '''
import os, signal, time
try:
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.05)
except BaseException:
    pass
'''


def test_a_ctrl_c_swallowed_by_the_library_still_interrupts(tmp_path, monkeypatch):
    for name in ("swallow_a", "swallow_b"):
        (tmp_path / f"{name}.py").write_text(SWALLOWING)
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        importlib.import_module("swallow_a")          # what a plain import does: nothing
        with pytest.raises(KeyboardInterrupt):
            interruptible_import("swallow_b")
    finally:
        sys.modules.pop("swallow_a", None)
        sys.modules.pop("swallow_b", None)
