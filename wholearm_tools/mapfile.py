"""The reconstructed map: in-memory records and the ``map.json`` file format (version 1).

Units metres/radians, frame = robot base frame.  Planar maps use 2-vectors in the arm's plane.
The format is documented in ``docs/map-format.md``; reading refuses other formats and versions
with a clear :class:`~wholearm_tools.errors.InputError`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools._io import write_text_atomic
from wholearm_tools.errors import InputError

MAP_FORMAT = "wholearm-map"
MAP_VERSION = 1


def _jsonable(value: Any) -> Any:
    """numpy arrays/scalars → lists/floats, recursively; non-finite floats → None."""
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    return value


def jsonable(value: Any) -> Any:
    """``value`` made JSON-ready the way map.json writes it: numpy arrays and scalars become
    lists and numbers, non-finite floats ``null``."""
    return _jsonable(value)


def _arrays(params: Mapping[str, Any]) -> dict[str, Any]:
    """JSON params → floats for scalars and read-only arrays for vectors."""
    out: dict[str, Any] = {}
    for key, value in params.items():
        if isinstance(value, (list, tuple)):
            arr = np.array(value, dtype=float)
            arr.setflags(write=False)
            out[key] = arr
        elif value is None:
            out[key] = float("nan")
        else:
            out[key] = float(value)
    return out


@dataclass(frozen=True, eq=False)
class MappedPrimitive:
    """One fitted primitive of the map.

    ``params`` and ``ci95`` use the map.json parameter names (``ci95[name]`` is the half-width of
    the 95 % interval, same shape as the parameter); ``extent`` describes the region the
    supporting contacts cover (see ``wholearm_tools.mesh.extent``); ``support`` counts tip and
    link contacts assigned to it.
    """

    id: int
    kind: str
    params: dict[str, Any]
    ci95: dict[str, Any] = field(default_factory=dict)
    covariance: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 0)))
    support: dict[str, int] = field(default_factory=lambda: {"tip": 0, "link": 0})
    rms_residual: float = float("nan")
    extent: dict[str, Any] = field(default_factory=dict)

    @property
    def primitive(self) -> Any:
        """The geometry object (``wholearm_tools.geometry``) these parameters describe."""
        from wholearm_tools.geometry.base import primitive_type

        return primitive_type(self.kind).from_params(self.params)

    def to_json(self) -> dict[str, Any]:
        return _jsonable({
            "id": self.id, "type": self.kind, "params": self.params, "ci95": self.ci95,
            "covariance": np.asarray(self.covariance), "support": self.support,
            "rms_residual": self.rms_residual, "extent": self.extent,
        })

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> MappedPrimitive:
        return cls(
            id=int(data["id"]), kind=str(data["type"]), params=_arrays(data["params"]),
            ci95=_arrays(data.get("ci95", {})),
            covariance=np.array(data.get("covariance", []), dtype=float),
            support={k: int(v) for k, v in data.get("support", {}).items()},
            rms_residual=float(data["rms_residual"]) if data.get("rms_residual") is not None
            else float("nan"),
            extent=dict(data.get("extent", {})),
        )


@dataclass(frozen=True, eq=False)
class SurfaceMap:
    """A reconstructed environment: primitives plus a summary of the contacts behind them.

    ``unexplained`` holds contact points (tip contacts and link-contact estimates) no primitive
    explains, shape ``(K, d)``; the mesher builds a free-form surface for them.
    """

    planar: bool
    B: float
    primitives: tuple[MappedPrimitive, ...]
    contacts: dict[str, int] = field(default_factory=dict)
    unexplained: NDArray[np.float64] = field(default_factory=lambda: np.zeros((0, 3)))
    frame: str = "base_link"
    meta: dict[str, Any] = field(default_factory=dict)

    @property
    def dim(self) -> int:
        return 2 if self.planar else 3

    def to_json(self) -> dict[str, Any]:
        return _jsonable({
            "format": MAP_FORMAT, "version": MAP_VERSION, "frame": self.frame,
            "planar": self.planar, "B": self.B,
            "primitives": [p.to_json() for p in self.primitives],
            "contacts": self.contacts, "unexplained": np.asarray(self.unexplained),
            "meta": self.meta,
        })

    @classmethod
    def from_json(cls, data: Any, source: str = "map.json") -> SurfaceMap:
        """Validate and load the JSON of a map; every error names ``source`` and the field."""
        if not isinstance(data, Mapping) or data.get("format") != MAP_FORMAT:
            raise InputError(f"{source}: not a wholearm map (expected \"format\": "
                             f"\"{MAP_FORMAT}\")")
        if data.get("version") != MAP_VERSION:
            raise InputError(f"{source}: map version {data.get('version')!r} is not supported "
                             f"(this wholearm reads version {MAP_VERSION})")
        for key in ("planar", "B", "primitives"):
            if key not in data:
                raise InputError(f"{source}: malformed map (no field {key!r})")
        if not isinstance(data["planar"], bool):
            raise InputError(f"{source}: field 'planar' must be true or false, got "
                             f"{_shown(data['planar'])}")
        planar = data["planar"]
        dim = 2 if planar else 3
        B = data["B"]
        if (isinstance(B, bool) or not isinstance(B, (int, float)) or not math.isfinite(B)
                or not 0 < B <= MAX_LENGTH):
            raise InputError(f"{source}: field 'B' must be a positive length in metres (at "
                             f"most {MAX_LENGTH:g}), got {_shown(B)}")
        if not isinstance(data["primitives"], list):
            raise InputError(f"{source}: field 'primitives' must be a list")
        primitives = tuple(_primitive(p, i, dim, source)
                           for i, p in enumerate(data["primitives"]))
        for name in ("contacts", "meta"):
            if not isinstance(data.get(name, {}), Mapping):
                raise InputError(f"{source}: field {name!r} must be an object")
        try:
            unexplained = np.array(data.get("unexplained", []), dtype=float).reshape(-1, dim)
        except (TypeError, ValueError) as exc:
            raise InputError(f"{source}: field 'unexplained' must be a list of {dim}-D points "
                             f"({type(exc).__name__})") from None
        try:
            contacts = {str(k): int(v) for k, v in data.get("contacts", {}).items()}
        except (TypeError, ValueError) as exc:
            raise InputError(f"{source}: field 'contacts' must hold counts "
                             f"({type(exc).__name__})") from None
        _check_lengths(unexplained, f"{source}: field 'unexplained'")
        return cls(planar=planar, B=float(B), primitives=primitives, contacts=contacts,
                   unexplained=unexplained, frame=str(data.get("frame", "base_link")),
                   meta=dict(data.get("meta", {})))


#: largest coordinate or length a map may hold [m]: far beyond any arm's reach, small enough
#: that meshes and reports stay finite
MAX_LENGTH = 1e3


def _shown(value: Any) -> str:
    """A value from an input file, shown short (never more than 40 characters)."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _check_lengths(values: Any, where: str) -> None:
    """InputError unless every number in ``values`` is finite and within ±MAX_LENGTH."""
    arr = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{where} holds a non-finite number")
    if arr.size and float(np.max(np.abs(arr))) > MAX_LENGTH:
        raise InputError(f"{where} holds {float(np.max(np.abs(arr))):.3g}, beyond "
                         f"{MAX_LENGTH:g} m")


def _numbers(value: Any) -> list[float]:
    """Every number inside a JSON value (lists and objects walked; strings and bools not)."""
    out: list[float] = []
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, Mapping):
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
        elif isinstance(item, (int, float)) and not isinstance(item, bool):
            out.append(float(item))
        elif item is None:
            out.append(float("nan"))
    return out


def _primitive(data: Any, index: int, dim: int, source: str) -> MappedPrimitive:
    """One validated primitive of a map: known type of the map's dimension, parameters that
    build the geometry, finite bounded parameters and extent."""
    from wholearm_tools.geometry.base import primitive_type

    where = f"{source}: primitives[{index}]"
    if not isinstance(data, Mapping):
        raise InputError(f"{where} must be an object")
    kind = data.get("type")
    where = f"{where} ({kind})" if isinstance(kind, str) else where
    try:
        cls = primitive_type(str(kind))
        if cls.dim != dim:
            raise InputError(f"a {cls.dim}-D type in a {dim}-D map")
        if not isinstance(data.get("params"), Mapping):
            raise InputError("no 'params' object")
        if not isinstance(data.get("extent", {}), Mapping):
            raise InputError("'extent' must be an object")
        _check_lengths(_numbers(data["params"]), "'params'")
        _check_lengths(_numbers(data.get("extent", {})), "'extent'")
        prim = MappedPrimitive.from_json(data)
        prim.primitive  # noqa: B018 - builds the geometry, which validates every parameter
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"{where}: malformed ({type(exc).__name__}: {exc})") from None
    return prim


def write_map(path: str | Path, surface_map: SurfaceMap) -> None:
    """Write ``surface_map`` as map.json, atomically."""
    text = json.dumps(surface_map.to_json(), indent=1, sort_keys=False)
    write_text_atomic(path, text + "\n")


def read_map(path: str | Path) -> SurfaceMap:
    """Read a map.json file (a regular file of bounded size, UTF-8, bounded nesting);
    malformed files and other versions raise InputError naming the file and the field."""
    from wholearm_tools._io import load_json, read_text_input

    path = Path(path)
    text = read_text_input(path, "map")
    return SurfaceMap.from_json(load_json(text, str(path), "JSON"), source=str(path))
