"""Writing a reconstruction's output set (map.json, contacts.csv) into a folder."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from wholearm_tools.contact_table import write_contact_table
from wholearm_tools.mapfile import write_map


def write_reconstruction(out_dir: str | Path, rec: Any) -> dict[str, Path]:
    """Write ``map.json`` and ``contacts.csv`` of ``rec`` (a
    :class:`~wholearm_tools.pipeline.Reconstruction`) into ``out_dir`` (created if needed)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"map": out / "map.json", "contacts": out / "contacts.csv"}
    write_map(paths["map"], rec.surface_map)
    write_contact_table(paths["contacts"], rec.table)
    return paths
