"""wholearm_tools: offline analysis of whole-arm tactile exploration runs.

Heavy dependencies (mcap, casadi, open3d, pyvista, matplotlib) are imported by the modules that
use them, so ``import wholearm_tools`` stays fast.
"""

from wholearm_tools.errors import WholearmError

__version__ = "0.1.0"
__all__ = ["WholearmError", "__version__"]
