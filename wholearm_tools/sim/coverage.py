"""How well a simulated run covers its environment, from the ground truth alone.

A primitive fit needs contacts spread over the surface, not only many of them.  For every
ground-truth surface this reports the number of contacts by kind and a spread figure suited to
its type:

line      ``extent``: length of the contacts' projection on the line [m]
circle    ``arc``: angle covered around the centre, 360° minus the largest empty gap [deg]
plane     ``extent``: the contacts' extents along two in-plane axes [m] (largest first)
sphere    ``arc``: largest angle between two contact directions seen from the centre [deg]
cylinder  ``arc`` around the axis [deg] and ``axial`` range along it from the axis point [m];
          ``above``/``below`` count the contacts on either side of the axis point (for a well
          junction the axis point is the junction centre)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.logs.records import GroundTruth

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class SurfaceCoverage:
    """Contacts on one ground-truth surface and their spread (see the module docstring)."""

    id: int
    type: str
    count: int
    tip: int
    joint: int
    body: int
    arc: float | None = None
    extent: tuple[float, ...] | None = None
    axial: tuple[float, float] | None = None
    above: int | None = None
    below: int | None = None

    def spread(self) -> str:
        """Short human-readable spread, e.g. ``arc 210° axial -0.20..+0.15 m (5↑ 7↓)``."""
        parts = []
        if self.arc is not None:
            parts.append(f"arc {self.arc:3.0f}°")
        if self.extent is not None:
            parts.append("ext " + "×".join(f"{e:.2f}" for e in self.extent) + " m")
        if self.axial is not None:
            parts.append(f"axial {self.axial[0]:+.2f}..{self.axial[1]:+.2f} m")
        if self.above is not None:
            parts.append(f"({self.above} above, {self.below} below)")
        return " ".join(parts) if self.count else "-"


def _largest_gap_arc(angles: FloatArray) -> float:
    """Angle covered by points on a circle: 360° minus the largest gap between neighbours."""
    if len(angles) < 2:
        return 0.0
    a = np.sort(np.mod(angles, 2 * np.pi))
    gaps = np.diff(np.concatenate([a, [a[0] + 2 * np.pi]]))
    return float(np.degrees(2 * np.pi - gaps.max()))


def _perpendicular(u: FloatArray) -> FloatArray:
    v = np.eye(3)[int(np.argmin(np.abs(u)))]
    v = v - (v @ u) * u
    return v / np.linalg.norm(v)


def surface_coverage(truth: GroundTruth) -> list[SurfaceCoverage]:
    """Coverage of every surface of ``truth``, in surface-id order."""
    out = []
    kinds = np.asarray(truth.contact_kind)
    for surf in truth.surfaces:
        sid = int(surf["id"])
        sel = np.asarray(truth.contact_surface) == sid
        P = np.asarray(truth.contact_point)[sel]
        k = kinds[sel].tolist()
        base: dict[str, Any] = {"id": sid, "type": str(surf["type"]), "count": int(sel.sum()),
                                "tip": k.count("tip"), "joint": k.count("joint"),
                                "body": k.count("body")}
        params = surf["params"]
        kind = surf["type"]
        if len(P) == 0:
            out.append(SurfaceCoverage(**base))
            continue
        if kind == "line":
            d = np.asarray(params["direction"], float)
            d = d / np.linalg.norm(d)
            s = P[:, :2] @ d
            base["extent"] = (float(s.max() - s.min()),)
        elif kind == "circle":
            c = np.asarray(params["center"], float)
            v = P[:, :2] - c
            base["arc"] = _largest_gap_arc(np.arctan2(v[:, 1], v[:, 0]))
        elif kind == "plane":
            n = np.asarray(params["normal"], float)
            n = n / np.linalg.norm(n)
            e1 = _perpendicular(n)
            e2 = np.cross(n, e1)
            X = P - P.mean(axis=0)
            proj = np.stack([X @ e1, X @ e2], axis=1)
            # extents along the principal axes of the contacts
            if len(P) > 1:
                _, _, vt = np.linalg.svd(proj, full_matrices=False)
                proj = proj @ vt.T
            ext = np.ptp(proj, axis=0)
            base["extent"] = tuple(float(e) for e in sorted(ext, reverse=True))
        elif kind == "sphere":
            c = np.asarray(params["center"], float)
            v = P - c
            v = v / np.linalg.norm(v, axis=1, keepdims=True)
            cos = np.clip(v @ v.T, -1.0, 1.0)
            base["arc"] = float(np.degrees(np.arccos(cos.min())))
        elif kind == "cylinder":
            p0 = np.asarray(params["point"], float)
            u = np.asarray(params["axis"], float)
            u = u / np.linalg.norm(u)
            e1 = _perpendicular(u)
            e2 = np.cross(u, e1)
            X = P - p0
            s = X @ u
            base["arc"] = _largest_gap_arc(np.arctan2(X @ e2, X @ e1))
            base["axial"] = (float(s.min()), float(s.max()))
            base["above"] = int(np.count_nonzero(s > 0))
            base["below"] = int(np.count_nonzero(s <= 0))
        out.append(SurfaceCoverage(**base))
    return out


def kind_counts(truth: GroundTruth) -> dict[str, int]:
    """Contacts by kind: ``{"tip": .., "joint": .., "body": ..}``."""
    k = np.asarray(truth.contact_kind).tolist()
    return {name: k.count(name) for name in ("tip", "joint", "body")}
