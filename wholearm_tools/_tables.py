"""Row tables on disk: CSV, or Parquet by the ``.parquet`` suffix (typed columns, via pyarrow).

Rows are dicts of column name to value as the CSV holds it (``str`` or a number; ``""`` for an
empty cell).  In Parquet, a column whose cells all read as integers is ``int64``, one whose
cells all read as numbers is ``float64``, anything else ``string``; empty cells are nulls.
Reading either format gives the same rows (numbers as their shortest round-trip text), so a
reader written for the CSV reads the Parquet file unchanged.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from wholearm_tools._io import atomic_output
from wholearm_tools.errors import InputError

#: key of the JSON metadata in a Parquet file's schema
META_KEY = b"wholearm"


def is_parquet(path: str | Path) -> bool:
    return Path(path).suffix.lower() == ".parquet"


def write_rows(path: str | Path, fields: Sequence[str], rows: Sequence[Mapping[str, Any]],
               meta: Mapping[str, Any] | None = None) -> None:
    """Write ``rows`` (columns ``fields``, in order) to ``path`` atomically; ``meta`` (JSON) is
    stored in a Parquet file's schema metadata and not in a CSV."""
    if is_parquet(path):
        _write_parquet(path, fields, rows, meta)
        return
    with atomic_output(path, "w") as fh:
        fh.write(csv_text(fields, rows))


def csv_text(fields: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> str:
    """``rows`` as CSV text with header ``fields`` (``\n`` line ends)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(fields), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return buf.getvalue()


def csv_rows(text: str) -> list[dict[str, str]]:
    """The rows of CSV ``text`` (header line first), every cell as text."""
    return list(csv.DictReader(io.StringIO(text)))


def read_rows(path: str | Path) -> list[dict[str, str]]:
    """Rows of a CSV or Parquet table, every cell as text (``""`` where empty)."""
    path = Path(path)
    if not is_parquet(path):
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise InputError(f"{path}: cannot read ({exc.strerror})") from None
        return csv_rows(text)
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except pa.ArrowInvalid as exc:
        raise InputError(f"{path}: not a readable Parquet file ({exc})") from None
    columns = {name: [_text(v) for v in table.column(name).to_pylist()]
               for name in table.column_names}
    return [{name: col[i] for name, col in columns.items()} for i in range(table.num_rows)]


def read_meta(path: str | Path) -> dict[str, Any]:
    """The JSON metadata of a Parquet table (empty for a CSV or a file without it)."""
    if not is_parquet(path):
        return {}
    import pyarrow.parquet as pq

    raw = (pq.read_schema(path).metadata or {}).get(META_KEY)
    return json.loads(raw) if raw else {}


def _text(value: Any) -> str:
    if value is None:
        return ""
    return repr(value) if isinstance(value, float) else str(value)


def _write_parquet(path: str | Path, fields: Sequence[str], rows: Sequence[Mapping[str, Any]],
                   meta: Mapping[str, Any] | None) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrays = {name: _typed([row.get(name, "") for row in rows]) for name in fields}
    table = pa.table(arrays)
    if meta:
        table = table.replace_schema_metadata({META_KEY: json.dumps(dict(meta)).encode()})
    with atomic_output(path, "wb") as fh:
        pq.write_table(table, fh)


def _typed(cells: list[Any]) -> Any:
    """One column as a pyarrow array: int64, float64 or string (see the module docstring)."""
    import pyarrow as pa

    if all(_empty(c) for c in cells):
        return pa.nulls(len(cells), type=pa.string())
    for parse, kind in ((_integer, pa.int64()), (float, pa.float64())):
        try:
            return pa.array([None if _empty(c) else parse(c) for c in cells], type=kind)
        except (TypeError, ValueError):
            pass
    return pa.array([None if _empty(c) else str(c) for c in cells], type=pa.string())


def _empty(cell: Any) -> bool:
    return cell is None or (isinstance(cell, str) and cell == "")


def _integer(cell: Any) -> int:
    """``int`` of an integer or of integer text; a float or other text raises ValueError."""
    if isinstance(cell, (bool, float)):
        raise ValueError(f"not an integer: {cell!r}")
    return int(cell)
