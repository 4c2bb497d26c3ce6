"""Run the Khronos glTF validator on exported meshes.

    .venv/bin/python benchmarks/validate_gltf.py                 # every primitive type, 2-D and 3-D
    .venv/bin/python benchmarks/validate_gltf.py out/map.glb ...  # given files

Without file arguments, maps holding every primitive type (plane, sphere, cylinder, cone, torus
with an unexplained free-form surface; planar lines and circles extruded) are exported as .gltf
and .glb into a temporary folder, and every file is validated.  The validator is the npm package
``gltf-validator`` (Khronos), installed on first use into ``~/.cache/wholearm/gltf-validator``
with ``npm``; node runs it.  Prints one line per file (errors, warnings, infos, the first issue
codes) and exits 1 if any file has an error.
"""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

CACHE = Path.home() / ".cache" / "wholearm" / "gltf-validator"
RUNNER = """
const fs = require('fs');
const validator = require('gltf-validator');
(async () => {
  const out = [];
  for (const f of process.argv.slice(2)) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(f)),
                                                 {uri: f, maxIssues: 100});
    out.push({file: f, errors: report.issues.numErrors, warnings: report.issues.numWarnings,
              infos: report.issues.numInfos, hints: report.issues.numHints,
              codes: report.issues.messages.map(m => m.code + ' ' + m.pointer)});
  }
  console.log(JSON.stringify(out));
})();
"""


def validator() -> Path:
    """The folder holding node_modules/gltf-validator (installed with npm when missing)."""
    if not (CACHE / "node_modules" / "gltf-validator").is_dir():
        if shutil.which("npm") is None or shutil.which("node") is None:
            sys.exit("node and npm are needed for the Khronos validator")
        CACHE.mkdir(parents=True, exist_ok=True)
        subprocess.run(["npm", "install", "--silent", "--prefix", str(CACHE), "gltf-validator"],
                       check=True)
    (CACHE / "run.js").write_text(RUNNER)
    return CACHE


def validate(files: list[Path]) -> list[dict]:
    folder = validator()
    res = subprocess.run(["node", str(folder / "run.js"), *map(str, files)], check=True,
                         capture_output=True, text=True, cwd=folder)
    return json.loads(res.stdout)


def sample_maps():
    """A 3-D map with every 3-D primitive type plus unexplained contacts, and a planar map."""
    import wholearm_tools.geometry.primitives  # noqa: F401  (registers the types)
    from wholearm_tools.geometry.base import primitive_type
    from wholearm_tools.mapfile import MappedPrimitive, SurfaceMap
    from wholearm_tools.mesh.extent import support_extent

    shapes = {
        "plane": ({"point": [0.1, 0.2, 0.3], "normal": [0.2, 0.3, 1.0]}, [0.1, 0.2, 0.3]),
        "sphere": ({"center": [0.1, 0.0, 0.5], "radius": 0.2}, [0.3, 0.1, 0.6]),
        "cylinder": ({"point": [0.0, 0.1, 0.0], "axis": [0.0, 0.6, 0.8], "radius": 0.1},
                     [0.1, 0.2, 0.2]),
        "cone": ({"apex": [0.0, 0.0, 1.0], "axis": [0.0, 0.0, -1.0], "half_angle": 0.4},
                 [0.2, 0.0, 0.5]),
        "torus": ({"center": [0.0, 0.0, 0.3], "axis": [1.0, 0.0, 0.0], "major_radius": 0.3,
                   "minor_radius": 0.05}, [0.0, 0.3, 0.3]),
    }
    rng = np.random.default_rng(0)
    prims = []
    for i, (kind, (params, centre)) in enumerate(shapes.items()):
        params = {k: (np.asarray(v, float) / (np.linalg.norm(v) if k in ("normal", "axis")
                                              else 1.0)) if isinstance(v, list) else float(v)
                  for k, v in params.items()}
        prim = primitive_type(kind).from_params(params)
        pts = prim.closest_point(np.asarray(centre) + 0.1 * rng.normal(size=(40, 3)))
        prims.append(MappedPrimitive(i, kind, params, extent=support_extent(kind, params, pts)))
    xy = rng.uniform(-0.05, 0.05, size=(30, 2))
    bump = np.c_[xy + np.array([0.6, 0.0]), 0.8 + 0.01 * np.sin(40 * xy[:, 0])]
    spatial = SurfaceMap(planar=False, B=0.02, primitives=tuple(prims), unexplained=bump)
    line = {"point": np.array([0.5, -0.2]), "direction": np.array([0.0, 1.0])}
    circle = {"center": np.array([0.2, 0.4]), "radius": 0.1}
    t = np.linspace(-0.1, 0.25, 8)
    ang = np.linspace(3.0, 3.0 + math.pi, 12)
    planar = SurfaceMap(planar=True, B=0.02, primitives=(
        MappedPrimitive(0, "line", line, extent=support_extent(
            "line", line, line["point"] + t[:, None] * line["direction"])),
        MappedPrimitive(1, "circle", circle, extent=support_extent(
            "circle", circle, circle["center"] + 0.1 * np.c_[np.cos(ang), np.sin(ang)]))))
    return {"spatial": spatial, "planar": planar}


def main(argv: list[str]) -> int:
    from wholearm_tools.mesh.export import export_map

    if argv:
        files = [Path(a) for a in argv]
        folder = None
    else:
        folder = Path(tempfile.mkdtemp(prefix="wholearm-gltf-"))
        files = [export_map(m, folder / f"{name}.{fmt}")
                 for name, m in sample_maps().items() for fmt in ("gltf", "glb")]
    try:
        results = validate(files)
    finally:
        if folder is not None:
            shutil.rmtree(folder, ignore_errors=True)
    print(f"{'file':<40} {'errors':>6} {'warnings':>8} {'infos':>5} {'hints':>5}  first issues")
    for r in results:
        print(f"{Path(r['file']).name:<40} {r['errors']:>6} {r['warnings']:>8} "
              f"{r['infos']:>5} {r['hints']:>5}  {'; '.join(r['codes'][:3])}")
    return 1 if any(r["errors"] for r in results) else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
