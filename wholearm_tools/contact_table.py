"""The per-contact table: detection, classification and fit geometry of every contact.

This is what ``contacts.csv`` holds and what ``wholearm fit contacts.csv`` reads back, so a user
can fit already-classified contacts (or contacts edited by hand) without the log.

Columns (planar runs have only x and y; ``z`` columns are omitted):

``t`` [s], ``link`` (0-based), ``p_tip``, ``label`` (tip/link/ambiguous), ``variance`` [m²],
``used_as`` (tip/link: the residual the fit uses; ambiguous contacts go to the likelier class),
``tip_x, tip_y[, tip_z]`` (centre of the tip sphere, or of the joint sphere at the outer end of
an inner link), ``tip_radius`` [m], ``a_x … b_z`` (link axis segment), ``link_radius`` [m],
``primitive`` (id of the primitive that explains it, -1 none, empty before fitting),
``residual`` [m] (distance to that primitive minus the radius), ``p_tip_map`` / ``label_map``
(the tip probability and label refined by the fitted map: the posterior of the readings in
:func:`wholearm_tools.fit.infer.infer`; empty before fitting), ``link_by_map`` (the link the
fitted map supports where the joint signals could not tell the links of a rigid group apart;
``link`` elsewhere, empty before fitting), ``t_settle`` [s] (when the contact settled, where its
configuration was measured), ``t_end`` [s] (its release; both empty when not known) and
``p_link`` (the probability the joint signals give ``link`` among the links of its rigid group:
1 where they name one link; empty when not known).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from wholearm_tools._arrays import read_only
from wholearm_tools._io import write_text_atomic
from wholearm_tools.errors import InputError

FloatArray = NDArray[np.float64]
LABELS = ("tip", "link", "ambiguous")


@dataclass(frozen=True, slots=True, eq=False)
class ContactTable:
    """``M`` contacts with everything the fit and the report need, columnar.

    Parameters
    ----------
    t : (M,) float; link : (M,) int; p_tip : (M,) float; label : (M,) str
    variance : (M,) float, σ² of the fit residual [m²]
    used_as_tip : (M,) bool, the fit uses the tip residual (else the link residual)
    tip_center : (M, d) float; tip_radius : (M,) float
    seg_a, seg_b : (M, d) float, link axis; link_radius : (M,) float
    primitive : (M,) int, -1 = unexplained (or not fitted yet)
    residual : (M,) float, NaN where unexplained
    p_tip_map : (M,) float, tip probability refined by the fitted map (NaN before fitting)
    label_map : (M,) str, its label (empty before fitting)
    link_by_map : (M,) int, the link refined by the fitted map (-1 before fitting)
    t_settle, t_end : (M,) float, when the contact settled and was released (NaN: not known)
    p_link : (M,) float, probability of ``link`` among its rigid group's links (NaN: not known)
    """

    t: FloatArray
    link: NDArray[np.int64]
    p_tip: FloatArray
    label: NDArray[np.str_]
    variance: FloatArray
    used_as_tip: NDArray[np.bool_]
    tip_center: FloatArray
    tip_radius: FloatArray
    seg_a: FloatArray
    seg_b: FloatArray
    link_radius: FloatArray
    primitive: NDArray[np.int64]
    residual: FloatArray
    p_tip_map: FloatArray | None = None
    label_map: NDArray[np.str_] | None = None
    link_by_map: NDArray[np.int64] | None = None
    t_settle: FloatArray | None = None
    t_end: FloatArray | None = None
    p_link: FloatArray | None = None

    def __post_init__(self) -> None:
        m = np.asarray(self.t).reshape(-1).shape[0]
        for name in ("t_settle", "t_end", "p_link"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.full(m, np.nan))
        if self.link_by_map is None:
            object.__setattr__(self, "link_by_map", np.full(m, -1, dtype=np.int64))
        if self.p_tip_map is None:
            object.__setattr__(self, "p_tip_map", np.full(m, np.nan))
        if self.label_map is None:
            object.__setattr__(self, "label_map", np.full(m, "", dtype="<U9"))
        d = np.asarray(self.tip_center).reshape(m, -1).shape[1] if m else \
            np.asarray(self.tip_center).shape[-1]
        if d not in (2, 3):
            raise InputError(f"contact points must be 2-D or 3-D, got dimension {d}")
        spec = {"t": (float, (m,)), "link": (np.int64, (m,)), "p_tip": (float, (m,)),
                "label": (np.str_, (m,)), "variance": (float, (m,)),
                "used_as_tip": (bool, (m,)), "tip_center": (float, (m, d)),
                "tip_radius": (float, (m,)), "seg_a": (float, (m, d)), "seg_b": (float, (m, d)),
                "link_radius": (float, (m,)), "primitive": (np.int64, (m,)),
                "residual": (float, (m,)), "p_tip_map": (float, (m,)),
                "label_map": (np.str_, (m,)), "link_by_map": (np.int64, (m,)),
                "t_settle": (float, (m,)), "t_end": (float, (m,)), "p_link": (float, (m,))}
        for name, (dtype, shape) in spec.items():
            arr = read_only(getattr(self, name), dtype)
            if arr.size == 0 and 0 in shape:
                arr = read_only(np.zeros(shape), dtype)
            if arr.shape != shape:
                raise InputError(f"expected {name} of shape {shape}, got {arr.shape}")
            object.__setattr__(self, name, arr)
        for name in ("t", "p_tip", "variance", "tip_center", "tip_radius", "seg_a", "seg_b",
                     "link_radius"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise InputError(f"contact column {name} has NaN or infinite values")
        bad = set(self.label.tolist()) - set(LABELS)
        if bad:
            raise InputError(f"unknown contact labels {sorted(bad)}; expected {LABELS}")
        bad = set(self.label_map.tolist()) - {*LABELS, ""}
        if bad:
            raise InputError(f"unknown label_map values {sorted(bad)}; expected {LABELS}")
        if np.any(self.link < 0) or np.any(self.link_by_map < -1):
            raise InputError("contact links must be >= 0")
        pm = self.p_tip_map[np.isfinite(self.p_tip_map)]
        if np.any((pm < 0) | (pm > 1)):
            raise InputError("p_tip_map must lie in [0, 1]")
        if np.any((self.p_tip < 0) | (self.p_tip > 1)):
            raise InputError("p_tip must lie in [0, 1]")
        pl = self.p_link[np.isfinite(self.p_link)]
        if np.any((pl < 0) | (pl > 1)):
            raise InputError("p_link must lie in [0, 1]")
        if np.any(self.variance <= 0):
            raise InputError("variance must be > 0")

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def dim(self) -> int:
        return int(self.tip_center.shape[1])

    def with_assignment(self, primitive: NDArray[np.int64], residual: FloatArray) -> ContactTable:
        """A copy with the fit's per-contact primitive ids and residuals."""
        return replace(self, primitive=primitive, residual=residual)

    def with_map_classification(self, p_tip_map: FloatArray, label_map: NDArray[np.str_],
                                link_by_map: NDArray[np.int64] | None = None) -> ContactTable:
        """A copy with the tip probabilities, labels and links refined by the fitted map
        (``link_by_map`` defaults to ``link``)."""
        return replace(self, p_tip_map=p_tip_map, label_map=label_map,
                       link_by_map=self.link if link_by_map is None else link_by_map)

    # ------------------------------------------------------------------ CSV
    def rows(self) -> tuple[list[str], list[dict[str, str]]]:
        """The CSV header and one dict per contact, every cell as the CSV writes it."""
        axes = "xyz"[: self.dim]
        header = ["t", "link", "p_tip", "label", "variance", "used_as",
                  *[f"tip_{c}" for c in axes], "tip_radius", *[f"a_{c}" for c in axes],
                  *[f"b_{c}" for c in axes], "link_radius", "primitive", "residual",
                  "p_tip_map", "label_map", "link_by_map", "t_settle", "t_end", "p_link"]
        rows = []
        for i in range(len(self)):
            residual = "" if not np.isfinite(self.residual[i]) else f"{self.residual[i]:.9g}"
            p_map = "" if not np.isfinite(self.p_tip_map[i]) else f"{self.p_tip_map[i]:.6f}"
            cells = [
                f"{self.t[i]:.6f}", str(int(self.link[i])), f"{self.p_tip[i]:.6f}",
                str(self.label[i]), f"{self.variance[i]:.9g}",
                "tip" if self.used_as_tip[i] else "link",
                *[f"{v:.9g}" for v in self.tip_center[i]], f"{self.tip_radius[i]:.9g}",
                *[f"{v:.9g}" for v in self.seg_a[i]], *[f"{v:.9g}" for v in self.seg_b[i]],
                f"{self.link_radius[i]:.9g}", str(int(self.primitive[i])), residual,
                p_map, str(self.label_map[i]),
                str(int(self.link_by_map[i])) if self.link_by_map[i] >= 0 else "",
                *["" if not np.isfinite(v) else f"{v:.6f}"
                  for v in (self.t_settle[i], self.t_end[i], self.p_link[i])],
            ]
            rows.append(dict(zip(header, cells, strict=True)))
        return header, rows

    def column_types(self) -> dict[str, str]:
        """The declared type of every column of :meth:`rows` (the Parquet schema)."""
        return table_column_types(self.dim)

    def to_csv(self) -> str:
        from wholearm_tools._tables import csv_text

        return csv_text(*self.rows())

    @classmethod
    def from_csv(cls, text: str, source: str = "contacts.csv") -> ContactTable:
        from wholearm_tools._tables import csv_rows

        return cls.from_rows(csv_rows(text), source)

    @classmethod
    def from_rows(cls, rows: list[dict[str, str]], source: str = "contacts.csv"
                  ) -> ContactTable:
        """From the rows of a contacts table, every cell as text (CSV or Parquet)."""
        if not rows:
            raise InputError(f"{source}: no contacts (empty table or header only)")
        cols = rows[0].keys()
        dim = 3 if "tip_z" in cols else 2
        axes = "xyz"[:dim]
        required = ["t", "link", "p_tip", "label", "variance", "used_as", "tip_radius",
                    "link_radius", *[f"{p}_{c}" for p in ("tip", "a", "b") for c in axes]]
        missing = [c for c in required if c not in cols]
        if missing:
            raise InputError(f"{source}: missing columns {missing}")

        def column(name: str, dtype: type = float) -> NDArray:
            try:
                return np.array([dtype(r[name]) for r in rows])
            except (TypeError, ValueError) as exc:
                raise InputError(f"{source}: bad value in column {name!r} ({exc})") from None

        def optional(name: str) -> FloatArray:
            """A float column that may be absent or empty (NaN)."""
            try:
                return np.array([float(r[name]) if r.get(name) else np.nan for r in rows])
            except (TypeError, ValueError) as exc:
                raise InputError(f"{source}: bad value in column {name!r} ({exc})") from None

        def optional_int(name: str) -> NDArray[np.int64]:
            """An integer column that may be absent or empty (-1)."""
            try:
                return np.array([int(r[name]) if r.get(name) else -1 for r in rows],
                                dtype=np.int64)
            except (TypeError, ValueError) as exc:
                raise InputError(f"{source}: bad value in column {name!r} ({exc})") from None

        def points(prefix: str) -> FloatArray:
            return np.stack([column(f"{prefix}_{c}") for c in axes], axis=1)

        used = column("used_as", str)
        if not set(used.tolist()) <= {"tip", "link"}:
            raise InputError(f"{source}: column 'used_as' must be tip or link")
        # (the column readers name the file themselves; the table's own checks do not)
        fields = {
            "t": column("t"), "link": column("link", int), "p_tip": column("p_tip"),
            "label": column("label", str), "variance": column("variance"),
            "used_as_tip": used == "tip", "tip_center": points("tip"),
            "tip_radius": column("tip_radius"), "seg_a": points("a"), "seg_b": points("b"),
            "link_radius": column("link_radius"),
            "primitive": optional_int("primitive"),
            "residual": optional("residual"), "p_tip_map": optional("p_tip_map"),
            "label_map": np.array([r.get("label_map") or "" for r in rows], dtype="<U9"),
            "link_by_map": optional_int("link_by_map"),
            "t_settle": optional("t_settle"), "t_end": optional("t_end"),
            "p_link": optional("p_link"),
        }
        try:
            return cls(**fields)
        except InputError as exc:
            raise InputError(f"{source}: {exc}") from None


def table_column_types(dim: int) -> dict[str, str]:
    """Declared types of the contact table's columns for ``dim``-D contacts (``int64``,
    ``float64`` or ``string``; see :mod:`wholearm_tools._tables`)."""
    axes = "xyz"[:dim]
    types = {"t": "float64", "link": "int64", "p_tip": "float64", "label": "string",
             "variance": "float64", "used_as": "string"}
    types.update({f"tip_{c}": "float64" for c in axes})
    types["tip_radius"] = "float64"
    types.update({f"{p}_{c}": "float64" for p in ("a", "b") for c in axes})
    types.update({"link_radius": "float64", "primitive": "int64", "residual": "float64",
                  "p_tip_map": "float64", "label_map": "string", "link_by_map": "int64",
                  "t_settle": "float64", "t_end": "float64", "p_link": "float64"})
    return types


def write_contact_table(path: str | Path, table: ContactTable) -> None:
    """Write ``table`` as CSV, atomically."""
    write_text_atomic(path, table.to_csv())


def read_contact_table(path: str | Path) -> ContactTable:
    """Read a contacts table written by :func:`write_contact_table` or ``wholearm contacts``
    (CSV, or Parquet by the ``.parquet`` suffix; or by hand, same columns)."""
    from wholearm_tools._tables import read_rows

    return ContactTable.from_rows(read_rows(path), source=str(path))
