"""Row tables on disk: CSV, or Parquet by the ``.parquet`` suffix (typed columns, via pyarrow).

Rows are dicts of column name to value as the CSV holds it (``str`` or a number; ``""`` for an
empty cell).  Every column has a declared type, one of :data:`COLUMN_TYPES` (``int64``,
``float64``, ``string``): the Parquet schema and the typed rows of ``--json`` outputs follow
the declaration, never the data, so a file's schema is the same for every run; empty cells are
nulls.  Reading either format gives the same rows (numbers as their shortest round-trip text),
so a reader written for the CSV reads the Parquet file unchanged.
"""

from __future__ import annotations

import csv
import io
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from wholearm_tools._io import MAX_TEXT_BYTES, atomic_output, check_input_file, read_text_input
from wholearm_tools.errors import InputError

#: key of the JSON metadata in a Parquet file's schema
META_KEY = b"wholearm"


def is_parquet(path: str | Path) -> bool:
    return Path(path).suffix.lower() == ".parquet"


#: the column types a table can declare
COLUMN_TYPES = ("int64", "float64", "string")


def write_rows(path: str | Path, fields: Sequence[str], rows: Sequence[Mapping[str, Any]],
               types: Mapping[str, str], meta: Mapping[str, Any] | None = None) -> None:
    """Write ``rows`` (columns ``fields``, in order, of declared ``types``) to ``path``
    atomically; ``meta`` (JSON) is stored in a Parquet file's schema metadata and not in a
    CSV."""
    _check_types(fields, types)
    if is_parquet(path):
        _write_parquet(path, fields, rows, types, meta)
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
    """Rows of a CSV or Parquet table, every cell as text (``""`` where empty); a file that is
    not a bounded regular file, not UTF-8, or not a table raises InputError naming it."""
    path = Path(path)
    if not is_parquet(path):
        text = read_text_input(path, "table")
        try:
            return csv_rows(text)
        except csv.Error as exc:
            raise InputError(f"{path}: not a readable CSV table ({exc})") from None
    import pyarrow as pa
    import pyarrow.parquet as pq

    check_input_file(path, "Parquet table", max_bytes=MAX_TEXT_BYTES)
    try:
        table = pq.read_table(path)
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    except pa.ArrowException as exc:
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


def _check_types(fields: Sequence[str], types: Mapping[str, str]) -> None:
    undeclared = [name for name in fields if types.get(name) not in COLUMN_TYPES]
    if undeclared:
        raise ValueError(f"columns without a declared type: {undeclared}")


def typed_cell(cell: Any, kind: str) -> int | float | str | None:
    """One cell as its declared type (``None`` for an empty cell; NaN for a float ``nan``)."""
    if cell is None or (isinstance(cell, str) and cell == ""):
        return None
    if kind == "int64":
        if isinstance(cell, float) or (isinstance(cell, str) and not cell.strip().lstrip(
                "+-").isdigit()):
            raise ValueError(f"not an integer: {cell!r}")
        return int(cell)
    if kind == "float64":
        return float(cell)
    return str(cell)


def typed_rows(fields: Sequence[str], rows: Sequence[Mapping[str, Any]],
               types: Mapping[str, str]) -> list[dict[str, Any]]:
    """``rows`` with every cell converted to its column's declared type (for JSON output)."""
    _check_types(fields, types)
    return [{name: typed_cell(row.get(name, ""), types[name]) for name in fields}
            for row in rows]


def _write_parquet(path: str | Path, fields: Sequence[str], rows: Sequence[Mapping[str, Any]],
                   types: Mapping[str, str], meta: Mapping[str, Any] | None) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    arrow = {"int64": pa.int64(), "float64": pa.float64(), "string": pa.string()}
    schema = pa.schema([(name, arrow[types[name]]) for name in fields])
    if meta:
        schema = schema.with_metadata({META_KEY: json.dumps(dict(meta)).encode()})
    columns = [pa.array([typed_cell(row.get(name, ""), types[name]) for row in rows],
                        type=arrow[types[name]]) for name in fields]
    table = pa.Table.from_arrays(columns, schema=schema)
    with atomic_output(path, "wb") as fh:
        pq.write_table(table, fh)
