"""Parameter validation and frame helpers shared by the extent and tessellation code."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError

FloatArray = NDArray[np.float64]

TWO_PI = 2.0 * math.pi

#: dimension of the points and vectors of each primitive kind (lines exist in 2-D and 3-D)
KIND_DIMS: dict[str, tuple[int, ...]] = {
    "line": (2,), "circle": (2,), "plane": (3,), "sphere": (3,), "cylinder": (3,),
    "cone": (3,), "torus": (3,),
}


def check_kind(kind: str) -> None:
    if kind not in KIND_DIMS:
        raise InputError(f"unknown primitive type {kind!r} (known: {', '.join(sorted(KIND_DIMS))})")


def vector(params: Mapping[str, Any], name: str, kind: str, dims: tuple[int, ...]) -> FloatArray:
    """``params[name]`` as a finite float vector with a length in ``dims``."""
    try:
        value = params[name]
    except KeyError:
        raise InputError(f"{kind} parameters lack {name!r} (got {sorted(params)})") from None
    arr = np.asarray(value, dtype=float)
    if arr.ndim != 1 or arr.shape[0] not in dims or not np.all(np.isfinite(arr)):
        raise InputError(f"{kind} parameter {name!r} must be a finite vector of length "
                         f"{' or '.join(map(str, dims))}, got {value!r}")
    return arr


def unit_vector(params: Mapping[str, Any], name: str, kind: str,
                dims: tuple[int, ...]) -> FloatArray:
    arr = vector(params, name, kind, dims)
    norm = float(np.linalg.norm(arr))
    if norm < 1e-12:
        raise InputError(f"{kind} parameter {name!r} must be non-zero, got {arr.tolist()}")
    return arr / norm


def scalar(params: Mapping[str, Any], name: str, kind: str, *, positive: bool = True,
           upper: float | None = None) -> float:
    try:
        value = float(params[name])
    except KeyError:
        raise InputError(f"{kind} parameters lack {name!r} (got {sorted(params)})") from None
    except (TypeError, ValueError):
        raise InputError(f"{kind} parameter {name!r} must be a number, got "
                         f"{params[name]!r}") from None
    if not math.isfinite(value) or (positive and value <= 0.0) or \
            (upper is not None and value >= upper):
        bound = f" and below {upper:g}" if upper is not None else ""
        raise InputError(f"{kind} parameter {name!r} must be positive{bound}, got {value!r}")
    return value


def perpendicular_basis(axis: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Deterministic unit vectors ``(e1, e2)`` with ``(e1, e2, axis)`` right-handed orthonormal.

    ``e1`` is the world axis least aligned with ``axis``, made orthogonal to it; ``e2 = axis × e1``.
    """
    axis = axis / np.linalg.norm(axis)
    seed = np.zeros(3)
    seed[int(np.argmin(np.abs(axis)))] = 1.0
    e1 = seed - float(seed @ axis) * axis
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    return e1, e2


def as_support_points(points: Any, dim: int, kind: str) -> FloatArray:
    arr = np.asarray(points, dtype=float)
    if arr.ndim == 1 and arr.size == dim:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise InputError(f"expected {kind} support points of shape (N, {dim}), "
                         f"got {np.shape(points)}")
    if arr.shape[0] == 0:
        raise InputError(f"cannot bound a {kind} without support points (got 0 points)")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{kind} support points contain NaN or infinite values")
    return arr
