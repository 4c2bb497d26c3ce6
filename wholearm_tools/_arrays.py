"""Read-only arrays for the project's frozen records."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray


def read_only(arr: Any, dtype: Any = float) -> NDArray[Any]:
    """A read-only copy of ``arr`` as ``dtype`` (``None``: the dtype numpy infers)."""
    out = np.array(arr, dtype=dtype)
    out.setflags(write=False)
    return out
