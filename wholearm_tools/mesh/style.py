"""Names and colours of the map's surfaces, written once for every output.

A fitted primitive keeps one name and one colour everywhere it appears: the mesh files (node,
group and cell-array names), the Foxglove overlay and every view of the PDF report.  The colour
depends on the primitive's id only, so the same surface looks the same in all of them and a
reader can match a surface in a 3-D view to its row in a table.
"""

from __future__ import annotations

#: surface colours (RGB in [0, 1], matplotlib's tab10), picked by primitive id modulo 10
PALETTE: tuple[tuple[float, float, float], ...] = (
    (0.122, 0.467, 0.706), (1.000, 0.498, 0.055), (0.173, 0.627, 0.173),
    (0.839, 0.153, 0.157), (0.580, 0.404, 0.741), (0.549, 0.337, 0.294),
    (0.890, 0.467, 0.761), (0.498, 0.498, 0.498), (0.737, 0.741, 0.133),
    (0.090, 0.745, 0.812),
)
#: colour of the free-form surface through the contacts no primitive explains
UNEXPLAINED_COLOUR: tuple[float, float, float] = (0.62, 0.62, 0.62)
#: node / group / entity name of that surface
UNEXPLAINED_NAME = "unexplained"


def surface_colour(primitive_id: int) -> tuple[float, float, float]:
    """RGB colour of primitive ``primitive_id`` (negative ids: the unexplained surface)."""
    if primitive_id < 0:
        return UNEXPLAINED_COLOUR
    return PALETTE[primitive_id % len(PALETTE)]


def surface_name(primitive_id: int, kind: str) -> str:
    """File-safe name of a primitive, e.g. ``primitive-0-cylinder`` (negative ids:
    :data:`UNEXPLAINED_NAME`)."""
    if primitive_id < 0:
        return UNEXPLAINED_NAME
    return f"primitive-{primitive_id}-{kind}"


def surface_label(primitive_id: int, kind: str) -> str:
    """Short label for legends and tables, e.g. ``#0 cylinder``."""
    if primitive_id < 0:
        return "unexplained contacts"
    return f"#{primitive_id} {kind}"
