"""Bounded meshes of fitted primitives, their files and the Foxglove overlay.

Pure geometry (numpy, scipy) in :mod:`.extent`, :mod:`.tessellate` and :mod:`.triangle_mesh`;
names and colours of the surfaces in :mod:`.style`; trimesh, pyvista, matplotlib and mcap are
imported only inside the functions that write files (:mod:`.export`, :mod:`.overlay`), open3d
only where free-form surfaces are reconstructed (:mod:`.unexplained`).
"""

from wholearm_tools.mesh.export import (
    DEFAULT_HEIGHT,
    DRAWING_FORMATS,
    MESH_FORMATS,
    SurfaceMesh,
    export_drawing,
    export_map,
    export_mesh,
    map_mesh,
    map_meshes,
    primitive_mesh,
)
from wholearm_tools.mesh.extent import angular_range, full_extent, support_extent
from wholearm_tools.mesh.overlay import scene_update, write_overlay
from wholearm_tools.mesh.tessellate import DEFAULT_RESOLUTION, extrude, polyline, tessellate
from wholearm_tools.mesh.triangle_mesh import TriangleMesh, merge_meshes
from wholearm_tools.mesh.unexplained import SurfaceReconstruction, unexplained_mesh

__all__ = [
    "DEFAULT_HEIGHT", "DEFAULT_RESOLUTION", "DRAWING_FORMATS", "MESH_FORMATS",
    "SurfaceMesh", "SurfaceReconstruction", "TriangleMesh", "angular_range", "export_drawing",
    "export_map", "export_mesh",
    "extrude", "full_extent", "map_mesh", "map_meshes", "merge_meshes", "polyline",
    "primitive_mesh", "scene_update", "support_extent", "tessellate", "unexplained_mesh",
    "write_overlay",
]
