"""wholearm_tools: offline analysis of whole-arm tactile exploration runs.

The main entry points are re-exported here lazily, so ``import wholearm_tools`` stays fast and
heavy dependencies (mcap, casadi, open3d, pyvista, matplotlib) load only when used::

    import wholearm_tools as wt
    rec = wt.reconstruct(wt.read_run("run.mcap"), B=0.02)
"""

from __future__ import annotations

import importlib
from typing import Any

from wholearm_tools.errors import WholearmError

__version__ = "0.1.0"

_LAZY = {
    "reconstruct": "wholearm_tools.pipeline",
    "Reconstruction": "wholearm_tools.pipeline",
    "read_run": "wholearm_tools.logs",
    "write_run": "wholearm_tools.logs",
    "load_scenario": "wholearm_tools.sim",
    "read_map": "wholearm_tools.mapfile",
    "write_report": "wholearm_tools.report",
}

__all__ = ["WholearmError", "__version__", *_LAZY]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'wholearm_tools' has no attribute {name!r}")
