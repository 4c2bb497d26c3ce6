"""MuJoCo scene (MJCF) of a robot and its environment, built from the toolkit's own records.

Robot (from :class:`~wholearm_tools.robot.model.RobotModel`, never by hand): body ``i`` sits at
``origins[i]`` in its parent with a hinge about ``axes[i]`` (range = joint limits, viscous
``damping``, Coulomb ``frictionloss``, reflected rotor inertia ``armature``) and one capsule geom,
joint ``i`` → joint ``i + 1`` (the tip for the last link) of radius ``link_radii[i]``, with the
mass of its volume at ``density``.  The capsule's round ends are the joint spheres (radii
decrease outward, so each joint sphere belongs to the inner link, as in the kinematic engine);
a tip sphere larger than the last link's radius is its own geom.  One torque motor per joint,
limited to the effort limit.  Robot geoms collide with the environment only (no self contact,
as in the kinematic engine).

Environment: each obstacle type (``geometry.bounded.OBSTACLE_TYPES``) has a builder in
:data:`GEOM_BUILDERS`.  Convex solids are MuJoCo primitives, whose contacts are exact: planes
(half-spaces), posts and 2-D circles (cylinders; 2-D shapes are extruded along z so a planar arm
meets them), spheres, boxes behind bounded plane patches and 2-D segments.  A concave wall (a
bore, the inside of a 2-D circle, a junction of two bores) is tiled with convex pieces: the wall
is cut into cells of its (angle, axial) parameters; a cell whose points all lie on the
obstacle's boundary (its exact clearance is zero there) becomes the convex hull of its points
and of the same points pushed ``thickness`` into the material; cells crossing the edge of the
wall (a junction's lip: wall points inside the other bore are free space, not wall) are halved
down to a smallest size, and their hull is taken over the wall points plus the edge itself,
found by bisection along the cell's sample lines.  Points pushed into the material are pulled
back until they are in the material, and smaller cells are thinner (at an acute lip the
material is a thin wedge, and a deep hull would reach across the other bore).  Any cell whose
hull deviates more than ``max_deviation`` is halved again; runs of whole cells are merged
along the wall into one stave when the merged hull deviates no more (fewer geoms: the broad
phase and the kinematics cost grow with their number).  Tile vertices lie on the ideal
surface, so the simulated solid sticks into the ideal free space by at most the sagitta of a
cell; the angular cell size keeps it below ``max_deviation``.  The
measured deviation of every tiled surface (largest clearance of a point on a tile face: solid
in ideal free space; largest depth of an ideal wall point no tile covers: free space the ideal
does not have) is returned with the scene and recorded in the ground truth.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from wholearm_tools.errors import InputError
from wholearm_tools.robot.model import RobotModel
from wholearm_tools.sim.collision import SurfaceRow, _surface_table

FloatArray = NDArray[np.float64]

#: robot geoms collide with environment geoms only: contype & conaffinity of the other side
ROBOT_BITS = ("1", "2")
ENV_BITS = ("2", "1")


class PhysicsModelError(InputError):
    """An environment the physics engine cannot build (the message names the obstacle)."""


@dataclass(frozen=True, slots=True)
class SceneOptions:
    """What the MJCF needs beyond the robot and the environment.

    timestep : physics step [s]
    gravity : gravity along -z (9.81 m/s²) or none
    friction : Coulomb friction coefficient between the arm and the environment
    solref : MuJoCo contact ``(timeconst [s], dampratio)``: stiffness and damping of the soft
        contact (dampratio < 1 rebounds)
    density : mass density of the links [kg/m³]
    armature : (n,) reflected rotor inertia of each joint [kg m²]
    frictionloss : (n,) Coulomb joint friction torque [N m]
    damping : (n,) viscous joint friction [N m s/rad]
    thickness : depth of the tiles of concave walls [m]
    max_deviation : largest sagitta of a tile of a concave wall [m]
    margin : pairs closer than this are listed as inactive contacts (no force), so that how far
        a contact separated is known (MuJoCo 4 environment geoms: ``margin`` 0, ``gap`` this)
    """

    timestep: float
    gravity: bool
    friction: float
    solref: tuple[float, float]
    density: float
    armature: tuple[float, ...]
    frictionloss: tuple[float, ...]
    damping: tuple[float, ...]
    thickness: float = 0.03
    max_deviation: float = 3e-4
    margin: float = 1e-3


@dataclass(frozen=True, slots=True, eq=False)
class Scene:
    """A built scene.

    xml : the MJCF text (meshes inline, nothing else to load)
    link_geoms : geom name of every link's capsule, in link order
    tip_geom : geom name of the tip sphere, or None when the last capsule's end is the tip
    env_geoms : geom name → surface id (row of ``collision.surface_dicts``)
    deviation : surface id → measured deviation of the simulated surface from the ideal [m]
        (primitives: 0)
    """

    xml: str
    link_geoms: tuple[str, ...]
    tip_geom: str | None
    env_geoms: dict[str, int]
    deviation: dict[int, float]
    tiles: int = 0


@dataclass
class _Geom:
    attrs: dict[str, str]
    surface: int
    vertices: FloatArray | None = None  # convex mesh (world frame) when not a primitive


@dataclass
class _Context:
    """What obstacle builders share: robot workspace, surface rows, options."""

    base: FloatArray
    reach: float
    planar: bool
    height: float  # half-height of extruded 2-D obstacles
    options: SceneOptions
    rows: tuple[SurfaceRow, ...]
    deviation: dict[int, float] = field(default_factory=dict)

    def row_of(self, obstacle: int, primitive: int = 0) -> int:
        rows = [r.id for r in self.rows if r.obstacle == obstacle]
        return rows[primitive]


def _f(values: Any) -> str:
    return " ".join(f"{float(v):.10g}" for v in np.atleast_1d(np.asarray(values, dtype=float)))


def _zaxis_quat(z: FloatArray) -> str:
    """Quaternion (w x y z) turning the local z axis onto unit ``z``."""
    from scipy.spatial.transform import Rotation

    z = np.asarray(z, dtype=float) / np.linalg.norm(z)
    ref = np.array([0.0, 0.0, 1.0])
    axis = np.cross(ref, z)
    s = float(np.linalg.norm(axis))
    c = float(ref @ z)
    if s < 1e-12:
        quat = np.array([1.0, 0.0, 0.0, 0.0]) if c > 0 else np.array([0.0, 1.0, 0.0, 0.0])
        return _f(quat)
    xyzw = Rotation.from_rotvec(axis / s * np.arctan2(s, c)).as_quat()
    return _f(np.r_[xyzw[3], xyzw[:3]])


def _matrix_quat(R: FloatArray) -> str:
    from scipy.spatial.transform import Rotation

    xyzw = Rotation.from_matrix(R).as_quat()
    if xyzw[3] < 0:
        xyzw = -xyzw
    return _f(np.r_[xyzw[3], xyzw[:3]])


# ------------------------------------------------------------------------------ primitives


def _lift(p: FloatArray) -> FloatArray:
    """A 2-D point or direction as 3-D (z = 0); 3-D unchanged."""
    p = np.asarray(p, dtype=float)
    return np.r_[p, 0.0] if p.shape == (2,) else p


def _plane(point: FloatArray, normal: FloatArray, surface: int) -> _Geom:
    """Half-space whose solid is on the ``-normal`` side."""
    return _Geom({"type": "plane", "size": "0 0 1", "pos": _f(_lift(point)),
                  "quat": _zaxis_quat(_lift(normal))}, surface)


def _cylinder(centre: FloatArray, axis: FloatArray, radius: float, half: float,
              surface: int) -> _Geom:
    return _Geom({"type": "cylinder", "size": _f([radius, half]), "pos": _f(_lift(centre)),
                  "quat": _zaxis_quat(_lift(axis))}, surface)


def _box(centre: FloatArray, axes: FloatArray, half: FloatArray, surface: int) -> _Geom:
    """Box with local axes the rows of ``axes (3, 3)``."""
    return _Geom({"type": "box", "size": _f(half), "pos": _f(centre),
                  "quat": _matrix_quat(np.asarray(axes).T)}, surface)


def _surface(obs: Any, k: int, ctx: _Context) -> list[_Geom]:
    prim = obs.primitive
    builder = SURFACE_BUILDERS.get(prim.kind)
    if builder is None:
        raise PhysicsModelError(
            f"obstacle {k} (surface {obs.surface_id!r}): a {prim.kind} surface is not supported "
            f"by the physics engine (supported: {', '.join(sorted(SURFACE_BUILDERS))})")
    return builder(obs, k, ctx)


def _surface_plane(obs: Any, k: int, ctx: _Context) -> list[_Geom]:
    p = obs.primitive.params()
    return [_plane(p["point"], obs.free_side * np.asarray(p["normal"]), ctx.row_of(k))]


def _surface_line(obs: Any, k: int, ctx: _Context) -> list[_Geom]:
    line = obs.primitive
    return [_plane(line.point, obs.free_side * line.normal, ctx.row_of(k))]


def _surface_sphere(obs: Any, k: int, ctx: _Context) -> list[_Geom]:
    p = obs.primitive.params()
    if obs.free_side < 0:
        raise PhysicsModelError(f"obstacle {k}: the inside of a sphere (free_side -1) is not "
                                "supported by the physics engine")
    return [_Geom({"type": "sphere", "size": _f(p["radius"]), "pos": _f(p["center"])},
                  ctx.row_of(k))]


def _post_or_bore(obs: Any, k: int, ctx: _Context, point: FloatArray, axis: FloatArray,
                  radius: float, s_range: tuple[float, float], caps: bool = True
                  ) -> list[_Geom]:
    """A solid post (free outside) as a cylinder, a bore (free inside) as tiles (with its
    closed ends when ``caps``; the ends of an extruded 2-D circle are not surfaces)."""
    s0, s1 = s_range
    if not np.isfinite(s0) or not np.isfinite(s1):
        # an open end: cut the cylinder where the robot cannot reach
        centre = point + ((ctx.base - point) @ axis) * axis
        t0 = (centre - point) @ axis
        far = ctx.reach + radius + 1.0
        s0 = max(s0, t0 - far)
        s1 = min(s1, t0 + far)
    if obs.free_side > 0:
        centre = point + 0.5 * (s0 + s1) * axis
        return [_cylinder(centre, axis, radius, 0.5 * (s1 - s0), ctx.row_of(k))]
    return _tile_cylinder(obs, ctx, point, axis, radius, (s0, s1), ctx.row_of(k), caps)


def _surface_cylinder(obs: Any, k: int, ctx: _Context) -> list[_Geom]:
    c = obs.primitive
    return _post_or_bore(obs, k, ctx, c.point, c.axis, c.radius, (-np.inf, np.inf))


def _surface_circle(obs: Any, k: int, ctx: _Context) -> list[_Geom]:
    c = obs.primitive
    return _post_or_bore(obs, k, ctx, _lift(c.center) - [0, 0, ctx.height], np.array(
        [0.0, 0.0, 1.0]), c.radius, (0.0, 2 * ctx.height), caps=False)


def _cylinder_section(obs: Any, k: int, ctx: _Context) -> list[_Geom]:
    if obs.angle_range is not None:
        raise PhysicsModelError(f"obstacle {k}: a cylinder section with an angle range is not "
                                "supported by the physics engine")
    return _post_or_bore(obs, k, ctx, obs.point, obs.axis, obs.radius, obs.s_range)


def _arc(obs: Any, k: int, ctx: _Context) -> list[_Geom]:
    if obs.angle_range is not None:
        raise PhysicsModelError(f"obstacle {k}: an arc with an angle range is not supported by "
                                "the physics engine")
    return _post_or_bore(obs, k, ctx, _lift(obs.center) - [0, 0, ctx.height],
                         np.array([0.0, 0.0, 1.0]), obs.radius, (0.0, 2 * ctx.height),
                         caps=False)


def _deep(thickness: float | None, ctx: _Context) -> float:
    return 2.0 * (ctx.reach + 1.0) if thickness is None else float(thickness)


def _plane_patch(obs: Any, k: int, ctx: _Context) -> list[_Geom]:
    depth = _deep(obs.thickness, ctx)
    n = obs.free_side * obs.normal
    centre = obs.center - 0.5 * depth * n
    axes = np.stack([obs.u, np.cross(n, obs.u), n])
    return [_box(centre, axes, np.r_[obs.half_extents, 0.5 * depth], ctx.row_of(k))]


def _segment2d(obs: Any, k: int, ctx: _Context) -> list[_Geom]:
    depth = _deep(obs.thickness, ctx)
    n = _lift(obs.free_side * obs.normal)
    d = _lift(obs.direction)
    s0, s1 = obs.s_range
    centre = _lift(obs.point) + 0.5 * (s0 + s1) * d - 0.5 * depth * n
    axes = np.stack([d, np.cross(n, d), n])  # right-handed; the second axis is +-z
    return [_box(centre, axes, np.array([0.5 * (s1 - s0), ctx.height, 0.5 * depth]),
                 ctx.row_of(k))]


def _junction(obs: Any, k: int, ctx: _Context) -> list[_Geom]:
    out = []
    for i, (cyl, rng) in enumerate(((obs.main, obs.main_range),
                                    (obs.branch, obs.branch_range))):
        out += _tile_cylinder(obs, ctx, cyl.point, cyl.axis, cyl.radius, rng, ctx.row_of(k, i))
    return out


SURFACE_BUILDERS: dict[str, Callable[[Any, int, _Context], list[_Geom]]] = {
    "plane": _surface_plane,
    "line": _surface_line,
    "sphere": _surface_sphere,
    "cylinder": _surface_cylinder,
    "circle": _surface_circle,
}
"""Builders of unbounded ``Surface`` obstacles by primitive kind."""

GEOM_BUILDERS: dict[str, Callable[[Any, int, _Context], list[_Geom]]] = {
    "surface": _surface,
    "plane_patch": _plane_patch,
    "segment2d": _segment2d,
    "cylinder_section": _cylinder_section,
    "arc": _arc,
    "cylinder_junction": _junction,
}
"""Builders by obstacle type name (``geometry.bounded.OBSTACLE_TYPES``): obstacle, index,
context → geoms."""


# ------------------------------------------------------------------------------ tiling


def _clearance_3d(obs: Any) -> Callable[[FloatArray], FloatArray]:
    dim = getattr(obs, "dim", 3)
    return lambda P: np.asarray(obs.clearance(P[:, :dim]), dtype=float).reshape(-1)


def _tile_cylinder(obs: Any, ctx: _Context, point: FloatArray, axis: FloatArray,
                   radius: float, s_range: tuple[float, float], surface: int,
                   caps: bool = True) -> list[_Geom]:
    """Tiles of the wall of a bore (free inside) and of its end caps, where the robot reaches.

    Only wall points where the obstacle's own clearance is zero are wall: a junction's points
    inside the other bore drop out (see the module docstring)."""
    from wholearm_tools.geometry.base import perpendicular

    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    point = np.asarray(point, dtype=float)
    e1 = np.asarray(perpendicular(axis))
    e2 = np.cross(axis, e1)
    clear = _clearance_3d(obs)
    near = ctx.reach + 0.05
    t_base = float((ctx.base - point) @ axis)
    rho_base = float(np.linalg.norm(ctx.base - point - t_base * axis))
    half = np.sqrt(max(near**2 - max(rho_base - radius, 0.0) ** 2, 0.0))
    s0 = max(float(s_range[0]), t_base - half)
    s1 = min(float(s_range[1]), t_base + half)
    tiles: list[_Geom] = []
    if s1 <= s0:
        return tiles
    n_ang = int(np.ceil(np.pi / np.sqrt(2.0 * ctx.options.max_deviation / radius)))
    n_ax = max(1, int(np.ceil((s1 - s0) / 0.08)))

    def wall(u: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
        radial = np.cos(u)[:, None] * e1 + np.sin(u)[:, None] * e2
        return point + v[:, None] * axis + radius * radial, radial

    tiles += _tile_patch(wall, (0.0, 2 * np.pi), (s0, s1), n_ang, n_ax, clear, ctx, surface)
    for end, sign in ((float(s_range[0]), -1.0), (float(s_range[1]), 1.0)):
        if not caps or not np.isfinite(end) or not (t_base - near <= end <= t_base + near):
            continue

        def cap(u: FloatArray, r: FloatArray, end: float = end, sign: float = sign
                ) -> tuple[FloatArray, FloatArray]:
            radial = np.cos(u)[:, None] * e1 + np.sin(u)[:, None] * e2
            pts = point + end * axis + r[:, None] * radial
            return pts, np.broadcast_to(sign * axis, pts.shape)

        tiles += _tile_patch(cap, (0.0, 2 * np.pi), (0.0, radius), max(8, n_ang // 4), 4,
                             clear, ctx, surface)
    return tiles


def _tile_patch(param: Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]],
                u_range: tuple[float, float], v_range: tuple[float, float], n_u: int, n_v: int,
                clear: Callable[[FloatArray], FloatArray], ctx: _Context, surface: int,
                sub: int = 3, min_depth: int = 1, max_depth: int = 6) -> list[_Geom]:
    """Convex tiles of the part of a parametric wall ``param(u, v) -> (points, outward
    normals)`` that is the obstacle's boundary and within reach (see the module docstring).

    Cells crossing the wall's edge are halved at least ``min_depth`` times; any cell whose hull
    sticks more than ``max_deviation`` into the ideal free space is halved again, at most
    ``max_depth`` times."""
    opts = ctx.options
    tiles: list[_Geom] = []
    worst = 0.0
    grid = np.linspace(0.0, 1.0, sub + 1)
    gu, gv = np.meshgrid(grid, grid, indexing="ij")
    gu, gv = gu.ravel(), gv.ravel()
    idx = np.arange(len(gu)).reshape(sub + 1, sub + 1)
    lines = np.array([(idx[i, j], idx[i + 1, j]) for i in range(sub) for j in range(sub + 1)]
                     + [(idx[i, j], idx[i, j + 1]) for i in range(sub + 1) for j in range(sub)])
    eps = 1e-9

    def on_wall(P: FloatArray) -> NDArray[np.bool_]:
        return np.abs(clear(P)) <= eps

    def tile(uu: FloatArray, vv: FloatArray, on: NDArray[np.bool_], depth: float
             ) -> tuple[FloatArray, Any] | None:
        """Hull of the cell's wall points, the wall's edge and the points pushed inward."""
        from scipy.spatial import ConvexHull, QhullError

        keep = np.stack([uu[on], vv[on]], axis=1)
        cross = lines[on[lines[:, 0]] != on[lines[:, 1]]]
        if len(cross):
            # the wall's edge inside this cell: bisect every sample line that crosses it
            a = np.where(on[cross[:, 0]], cross[:, 0], cross[:, 1])
            b = np.where(on[cross[:, 0]], cross[:, 1], cross[:, 0])
            lo = np.stack([uu[a], vv[a]], axis=1)
            hi = np.stack([uu[b], vv[b]], axis=1)
            for _ in range(14):  # to 1e-4 of the cell: microns
                mid = 0.5 * (lo + hi)
                ok = on_wall(param(mid[:, 0], mid[:, 1])[0])[:, None]
                lo, hi = np.where(ok, mid, lo), np.where(ok, hi, mid)
            keep = np.vstack([keep, lo])
        P, N = param(keep[:, 0], keep[:, 1])
        t = np.full(len(P), depth)
        for _ in range(16):
            inside = clear(P + t[:, None] * N) < -eps
            if inside.all():
                break
            t = np.where(inside, t, 0.5 * t)
        t = np.where(clear(P + t[:, None] * N) < -eps, t, 0.0)
        V = np.vstack([P, P[t > 0] + t[t > 0, None] * N[t > 0]])
        if len(V) < 4 or np.linalg.svd(V - V.mean(axis=0), compute_uv=False)[-1] < 1e-7:
            return None  # flat or degenerate (Qhull would fail, slowly)
        try:
            hull = ConvexHull(V)
        except (QhullError, ValueError):
            return None
        return (V, hull) if hull.volume > 1e-12 else None

    def cell(u0: float, u1: float, v0: float, v1: float, level: int) -> bool:
        """Tile one cell (halving it where needed); True when it is a whole-wall cell that
        :func:`merge` may join with its neighbours along ``v`` (nothing emitted yet)."""
        nonlocal worst
        uu, vv = u0 + gu * (u1 - u0), v0 + gv * (v1 - v0)
        P, _ = param(uu, vv)
        if np.min(np.linalg.norm(P - ctx.base, axis=1)) > ctx.reach + 0.05 + np.ptp(P, 0).max():
            return False
        on = on_wall(P)
        if not on.any():
            return False
        # smaller cells are thinner too: where the material is a wedge (a lip), a deep hull
        # would reach across the other bore's free space
        depth = max(opts.thickness / 2**level, min(opts.thickness, 0.004))
        built = None if (not on.all() and level < min_depth) else tile(uu, vv, on, depth)
        deviation = np.inf
        if built is not None:
            V, hull = built
            deviation = _hull_intrusion(V, hull, clear)
            if not on.all():
                deviation = max(deviation, _uncovered_depth(param, (u0, u1), (v0, v1), on_wall,
                                                            hull))
        if deviation > opts.max_deviation and level < max_depth:
            um, vm = 0.5 * (u0 + u1), 0.5 * (v0 + v1)
            for a, b in ((u0, um), (um, u1)):
                for c, d in ((v0, vm), (vm, v1)):
                    cell(a, b, c, d, level + 1)
            return False
        if built is None:
            return False
        worst = max(worst, deviation)
        if level == 0 and on.all():
            return True
        tiles.append(_Geom({"type": "mesh"}, surface, built[0][built[1].vertices]))
        return False

    def merge(u0: float, u1: float, v0: float, v1: float) -> bool:
        """One tile for a run of whole-wall cells along ``v`` (a straight stave of a cylinder,
        a strip of a flat cap), if it deviates no more than its cells."""
        nonlocal worst
        uu, vv = u0 + gu * (u1 - u0), v0 + gv * (v1 - v0)
        built = tile(uu, vv, np.ones(len(uu), dtype=bool), opts.thickness)
        if built is None:
            return False
        deviation = _hull_intrusion(*built, clear)
        if deviation > opts.max_deviation:
            return False
        worst = max(worst, deviation)
        tiles.append(_Geom({"type": "mesh"}, surface, built[0][built[1].vertices]))
        return True

    du = (u_range[1] - u_range[0]) / n_u
    dv = (v_range[1] - v_range[0]) / n_v
    for i in range(n_u):
        u0, u1 = u_range[0] + i * du, u_range[0] + (i + 1) * du
        whole = [cell(u0, u1, v_range[0] + j * dv, v_range[0] + (j + 1) * dv, 0)
                 for j in range(n_v)]
        j = 0
        while j < n_v:
            if not whole[j]:
                j += 1
                continue
            end = j
            while end + 1 < n_v and whole[end + 1]:
                end += 1
            v0, v1 = v_range[0] + j * dv, v_range[0] + (end + 1) * dv
            if not merge(u0, u1, v0, v1):
                for jj in range(j, end + 1):  # emit the cells one by one
                    merge(u0, u1, v_range[0] + jj * dv, v_range[0] + (jj + 1) * dv)
            j = end + 1
    ctx.deviation[surface] = max(ctx.deviation.get(surface, 0.0), worst)
    return tiles


def _hull_intrusion(V: FloatArray, hull: Any, clear: Callable[[FloatArray], FloatArray]
                    ) -> float:
    """Largest clearance of a point on the hull's faces (solid in ideal free space), sampled at
    the vertices, edge midpoints and four points inside every face."""
    tri = V[hull.simplices]  # (F, 3, 3)
    w = np.array([[1, 0, 0], [0.5, 0.5, 0], [0, 0.5, 0.5], [0.5, 0, 0.5],
                  [1 / 3, 1 / 3, 1 / 3], [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6],
                  [1 / 6, 1 / 6, 2 / 3]])
    pts = np.einsum("sk,fkd->fsd", w, tri).reshape(-1, 3)
    return float(max(0.0, clear(pts).max()))


def _uncovered_depth(param: Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]],
                     u: tuple[float, float], v: tuple[float, float],
                     on_wall: Callable[[FloatArray], NDArray[np.bool_]], hull: Any) -> float:
    """Largest distance outside this tile's hull (its face planes) of a wall point of the cell:
    free space the ideal wall does not have, where the tile ends at the wall's edge."""
    g = np.linspace(0.0, 1.0, 9)
    gu, gv = np.meshgrid(u[0] + g * (u[1] - u[0]), v[0] + g * (v[1] - v[0]), indexing="ij")
    P, _ = param(gu.ravel(), gv.ravel())
    P = P[on_wall(P)]
    if not len(P):
        return 0.0
    eq = hull.equations
    return float(max(0.0, (P @ eq[:, :3].T + eq[:, 3]).max(axis=1).max()))


# ------------------------------------------------------------------------------ scene


def build_scene(robot: RobotModel, obstacles: Sequence[Any], options: SceneOptions) -> Scene:
    """The MJCF scene of ``robot`` among ``obstacles`` (see the module docstring).

    Raises
    ------
    PhysicsModelError
        An obstacle type or shape the engine cannot build (the message names it).
    """
    n = robot.dof
    for name in ("armature", "frictionloss", "damping"):
        if len(getattr(options, name)) != n:
            raise InputError(f"expected {n} {name} values, got {getattr(options, name)}")
    rows = _surface_table(tuple(obstacles))
    # 2-D obstacles are extruded along z just far enough for a planar arm (which stays in z = 0)
    height = 2.0 * max(float(robot.link_radii.max()), robot.tip_radius) + 0.05
    ctx = _Context(base=robot.joint_positions(np.zeros(n))[0], reach=robot.reach,
                   planar=robot.planar, height=height, options=options, rows=rows)
    geoms: list[_Geom] = []
    for k, obs in enumerate(obstacles):
        type_name = getattr(obs, "type_name", type(obs).__name__)
        builder = GEOM_BUILDERS.get(type_name)
        if builder is None:
            raise PhysicsModelError(
                f"obstacle {k} of type {type_name!r} is not supported by the physics engine "
                f"(supported: {', '.join(sorted(GEOM_BUILDERS))})")
        geoms += builder(obs, k, ctx)

    root = ET.Element("mujoco", model=robot.name)
    ET.SubElement(root, "compiler", angle="radian", autolimits="true")
    ET.SubElement(root, "option", timestep=_f(options.timestep),
                  gravity="0 0 -9.81" if options.gravity else "0 0 0",
                  integrator="implicitfast", cone="elliptic", impratio="10")
    default = ET.SubElement(root, "default")
    ET.SubElement(default, "geom", friction=_f([options.friction, 0.005, 0.0001]),
                  solref=_f(options.solref), condim="3")
    asset = ET.SubElement(root, "asset")
    world = ET.SubElement(root, "worldbody")
    env_geoms: dict[str, int] = {}
    tiles = 0
    for i, g in enumerate(geoms):
        name = f"env{i}"
        attrs = dict(g.attrs)
        if g.vertices is not None:
            centre = g.vertices.mean(axis=0)
            ET.SubElement(asset, "mesh", name=f"tile{i}",
                          vertex=_f((g.vertices - centre).ravel()))
            attrs.update(type="mesh", mesh=f"tile{i}", pos=_f(centre))
            tiles += 1
        ET.SubElement(world, "geom", name=name, contype=ENV_BITS[0], conaffinity=ENV_BITS[1],
                      margin="0", gap=_f(options.margin), **attrs)
        env_geoms[name] = g.surface

    parent = world
    link_geoms = []
    for i in range(n):
        origin = robot.origins[i]
        body = ET.SubElement(parent, "body", name=f"link{i}", pos=_f(origin[:3, 3]),
                             quat=_matrix_quat(origin[:3, :3]))
        ET.SubElement(body, "joint", name=robot.joint_names[i], type="hinge",
                      axis=_f(robot.axes[i]), range=_f([robot.lower[i], robot.upper[i]]),
                      damping=_f(options.damping[i]), frictionloss=_f(options.frictionloss[i]),
                      armature=_f(options.armature[i]))
        end = robot.origins[i + 1][:3, 3] if i + 1 < n else robot.tip_offset
        geom = {"name": f"link{i}", "size": _f(robot.link_radii[i]),
                "density": _f(options.density), "contype": ROBOT_BITS[0],
                "conaffinity": ROBOT_BITS[1]}
        if np.linalg.norm(end) < 1e-9:
            geom["type"] = "sphere"
        else:
            geom.update(type="capsule", fromto=_f(np.r_[np.zeros(3), end]))
        ET.SubElement(body, "geom", **geom)
        link_geoms.append(f"link{i}")
        parent = body
    tip_geom = None
    if robot.tip_radius > robot.link_radii[-1]:
        tip_geom = "tip"
        ET.SubElement(parent, "geom", name="tip", type="sphere", pos=_f(robot.tip_offset),
                      size=_f(robot.tip_radius), density=_f(options.density),
                      contype=ROBOT_BITS[0], conaffinity=ROBOT_BITS[1])
    ET.SubElement(parent, "site", name="tip", pos=_f(robot.tip_offset))
    actuator = ET.SubElement(root, "actuator")
    for i, name in enumerate(robot.joint_names):
        limit = float(robot.effort_limits[i])
        ET.SubElement(actuator, "motor", name=name, joint=name, gear="1",
                      ctrlrange=_f([-limit, limit]))
    ET.indent(root)
    deviation = {r.id: float(ctx.deviation.get(r.id, 0.0)) for r in rows}
    return Scene(xml=ET.tostring(root, encoding="unicode"), link_geoms=tuple(link_geoms),
                 tip_geom=tip_geom, env_geoms=env_geoms, deviation=deviation, tiles=tiles)
