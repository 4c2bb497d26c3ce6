"""``wholearm export``: meshes (and drawings of planar maps) of a map.json."""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import click

from cli.options import (
    InputFile,
    check_output_file,
    json_option,
    overwrite_option,
    result,
    stage,
    status,
)

MESH_FORMATS = ("ply", "stl", "obj", "gltf", "glb", "vtp")
DRAWING_FORMATS = ("svg", "png")


@click.command("export")
@click.argument("map_file", type=InputFile())
@click.option("-f", "--format", "formats", multiple=True, default=("ply",), show_default=True,
              type=click.Choice(MESH_FORMATS + DRAWING_FORMATS, case_sensitive=False),
              help="Output format (repeatable); svg/png draw planar maps.")
@click.option("-o", "--output", "--output-dir", "output_dir",
              type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Output folder [default: the map's folder].")
@click.option("--resolution", type=click.FloatRange(min=1e-5), default=0.005,
              show_default=True, help="Largest edge length along curved directions, metres.")
@click.option("--height", type=click.FloatRange(min=1e-5), default=0.1, show_default=True,
              help="Height of the strips extruded from planar maps, metres.")
@click.option("--no-unexplained", is_flag=True,
              help="Leave out the surface through contacts no primitive explains.")
@overwrite_option
@json_option
def command(map_file: Path, formats: tuple[str, ...], output_dir: Path | None,
            resolution: float, height: float, no_unexplained: bool, overwrite: bool,
            as_json: bool) -> None:
    """Write one mesh file per format next to MAP_FILE, e.g. out/map.json → out/map.ply."""
    from wholearm_tools.errors import WholearmError

    try:
        _export(map_file, formats, output_dir, resolution, height, no_unexplained, overwrite,
                as_json)
    except WholearmError as exc:  # also when the command is used outside the wholearm group
        raise click.ClickException(str(exc)) from None


def _export(map_file: Path, formats: tuple[str, ...], output_dir: Path | None,
            resolution: float, height: float, no_unexplained: bool, overwrite: bool,
            as_json: bool) -> None:
    from wholearm_tools.mapfile import read_map
    from wholearm_tools.mesh.export import (
        export_drawing,
        export_mesh,
        map_meshes,
        map_scene_metadata,
    )

    formats = tuple(dict.fromkeys(f.lower() for f in formats))
    folder = output_dir if output_dir is not None else map_file.parent
    if not folder.is_dir():
        raise click.ClickException(f"{folder}: output folder does not exist")
    outputs = [(fmt, folder / f"{map_file.stem}.{fmt}") for fmt in formats]
    for _, out in outputs:
        check_output_file(out, overwrite)
    surface_map = read_map(map_file)
    drawings = [fmt for fmt in formats if fmt in DRAWING_FORMATS]
    if drawings and not surface_map.planar:
        raise click.ClickException(
            f"{map_file}: {'/'.join(drawings)} drawings need a planar map (this map is 3-D)")
    parts = []
    if any(fmt in MESH_FORMATS for fmt in formats):
        with stage("meshing the map"):
            parts = map_meshes(surface_map, resolution=resolution, height=height,
                               include_unexplained=not no_unexplained)
        if all(part.mesh.is_empty for part in parts):
            raise click.ClickException(f"{map_file}: the map has nothing to mesh")
    created: list[Path] = []
    try:
        for fmt, out in outputs:
            existed = out.exists()
            if fmt in DRAWING_FORMATS:
                export_drawing(surface_map, out, format=fmt, resolution=resolution)
            else:
                export_mesh(parts, out, format=fmt, frame=surface_map.frame,
                            metadata=map_scene_metadata(surface_map))
            if not existed:
                created.append(out)
    except BaseException:
        for out in created:  # all or nothing for the files this run created
            with contextlib.suppress(OSError):
                out.unlink()
        raise
    if as_json:
        result(json.dumps({"map": str(map_file), "outputs": {f: str(o) for f, o in outputs},
                           "surfaces": [part.name for part in parts],
                           "vertices": sum(part.mesh.n_vertices for part in parts),
                           "triangles": sum(part.mesh.n_triangles for part in parts)}))
    else:
        for _, out in outputs:
            status(f"wrote {out}")
