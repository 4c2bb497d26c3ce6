"""The swept occupancy map: where the robot's capsules have been, and since when.

One raster pass over the run stores, for every cell of a regular grid (2-D xy grid for planar
robots, 3-D voxels otherwise), the index of the first log sample at which the cell centre was
inside the robot.  That single ``first`` field answers every question the classifier asks:

* offline map (the whole run): cell swept ⇔ ``first < N``;
* causal map as the robot saw it at sample ``i``: cell swept ⇔ ``first <= i``;
* the replay of the paper's Figure 4: the same test for a growing ``i``.

A cell counts as swept only when its centre lies inside a capsule (never when it merely
overlaps one), so the free space is under-estimated rather than over-estimated: a cell holding
a surface is never called free because the robot touched it.

Poses are subsampled so that no point of the robot moves by more than ``step`` between two
rasterised poses (``step`` = half the smallest link radius, at least half a cell): consecutive
capsules overlap and the union covers the swept volume.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from wholearm_tools.errors import InputError
from wholearm_tools.robot.model import RobotModel

FloatArray = NDArray[np.float64]
NEVER = np.iinfo(np.int32).max
"""``first`` value of a cell the robot never swept."""

#: default cell budgets (dense int32 grids: 4 bytes per cell)
MAX_CELLS_2D = 4_000_000
MAX_CELLS_3D = 8_000_000
#: smallest 3-D cell is the robot's reach divided by this
REACH_CELLS_3D = 150
#: largest gap (samples) between rasterised poses of one capsule
MAX_POSE_GAP = 100
#: candidate cells tested per vectorised chunk of poses when rasterising
_CHUNK_CANDIDATES = 16_000
#: smallest B as a fraction of the robot's reach: one count of a 20-bit joint encoder seen at
#: full reach; no log resolves a curvature radius below it
B_MIN_REACH_FRACTION = 2 * np.pi / 2**20
#: largest grid built at an explicitly given resolution (int32 cells: 256 MB)
MAX_GRID_CELLS = 64_000_000


def check_B(B: float, robot: RobotModel, *, what: str = "B") -> float:  # noqa: N802
    """``B`` as a float after checking it lies between the encoder level and the robot's reach.

    Below ``B_MIN_REACH_FRACTION * reach`` no log resolves it (and the swept map's cells would
    be vanishingly small); above the reach, the robot dilated by B covers more than all the
    space it can explore.  ``what`` names B in the message (``--B``, or a file's field).
    """
    try:
        value = float(B)
    except (TypeError, ValueError):
        raise InputError(f"{what} must be a length in metres, got {B!r}") from None
    reach = float(robot.reach)
    floor = B_MIN_REACH_FRACTION * reach
    if not np.isfinite(value) or value <= 0:
        raise InputError(f"{what} must be a positive length in metres, got {value:g}")
    if value < floor:
        raise InputError(f"{what} = {value:g} m is below {floor:.2g} m, what the joint encoders "
                         f"resolve at the robot's reach ({reach:.3g} m)")
    if value > reach:
        raise InputError(f"{what} = {value:g} m is larger than the robot's reach ({reach:.3g} m)"
                         "; B is the smallest curvature radius the arm can explore")
    return value


@dataclass(frozen=True, slots=True, eq=False)
class SweptMap:
    """First-sweep sample index on a regular grid.

    Parameters
    ----------
    origin : (d,) float, centre of cell ``(0, ..., 0)`` [m]
    resolution : float, cell edge [m]
    first : (nx, ny[, nz]) int32, first log sample at which the cell was inside the robot
        (:data:`NEVER` if never)
    n_samples : int, number of log samples the map was built from
    """

    origin: FloatArray
    resolution: float
    first: NDArray[np.int32]
    n_samples: int

    def __post_init__(self) -> None:
        origin = np.array(self.origin, dtype=float)
        if origin.shape != (self.first.ndim,):
            raise InputError(f"expected origin of shape ({self.first.ndim},), got {origin.shape}")
        if not self.resolution > 0:
            raise InputError(f"resolution must be > 0, got {self.resolution}")
        origin.setflags(write=False)
        object.__setattr__(self, "origin", origin)
        self.first.setflags(write=False)

    @property
    def dim(self) -> int:
        return int(self.first.ndim)

    def swept(self, until: int | None = None) -> NDArray[np.bool_]:
        """Boolean grid of cells swept at or before sample ``until`` (all samples if None)."""
        if until is None:
            return self.first != NEVER
        return self.first <= until

    def cells(self, points: ArrayLike) -> NDArray[np.int64]:
        """Integer cell coordinates of ``points (..., d)`` (may be out of the grid)."""
        p = np.asarray(points, dtype=float)
        return np.floor((p - self.origin) / self.resolution + 0.5).astype(np.int64)

    def first_at(self, points: ArrayLike) -> NDArray[np.int64]:
        """``first`` of the cell holding each point, :data:`NEVER` outside the grid."""
        c = self.cells(points)
        return self._lookup(c)

    def _lookup(self, c: NDArray[np.int64]) -> NDArray[np.int64]:
        shape = np.array(self.first.shape)
        inside = np.all((c >= 0) & (c < shape), axis=-1)
        out = np.full(c.shape[:-1], NEVER, dtype=np.int64)
        cc = c[inside]
        out[inside] = self.first[tuple(cc.T)]
        return out

    def first_within(self, points: ArrayLike, radius: float) -> NDArray[np.int64]:
        """Earliest ``first`` over the cells whose centre lies within ``radius`` of each point.

        ``points (..., d)`` → ``(...)`` int; :data:`NEVER` where no such cell was swept (or
        ``radius <= 0``).  This is the swept map dilated by ``radius``, evaluated exactly at the
        query points without dilating the whole grid.
        """
        p = np.asarray(points, dtype=float)
        batch = p.shape[:-1]
        p = p.reshape(-1, self.dim)
        out = np.full(p.shape[0], NEVER, dtype=np.int64)
        if radius <= 0 or p.shape[0] == 0:
            return out.reshape(batch)
        reach = int(np.ceil(radius / self.resolution + 0.5 * np.sqrt(self.dim)))
        axes = [np.arange(-reach, reach + 1)] * self.dim
        offs = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, self.dim)
        lim = radius / self.resolution + 0.5 * np.sqrt(self.dim)
        offs = offs[np.sum(offs**2, axis=1) <= lim**2]
        base = self.cells(p)
        res = self.resolution
        shape = np.array(self.first.shape)
        strides = np.array([int(np.prod(shape[i + 1:])) for i in range(self.dim)])
        flat = self.first.reshape(-1)
        ovec = offs * res
        o2 = np.sum(ovec**2, axis=1)
        flat_offs = offs @ strides
        # points whose whole ball of cells lies in the grid: flat indices, no bounds checks
        inside = np.all((base - reach >= 0) & (base + reach < shape), axis=1)
        chunk = max(1, 200_000 // offs.shape[0])  # (chunk, K) blocks stay in cache
        for s in range(0, p.shape[0], chunk):
            sl = slice(s, s + chunk)
            # |centre - p|^2 with centre = origin + (base + off) * res, expanded around the
            # point's own cell: |d0|^2 + 2 d0.o + |o|^2 (one matrix product per block)
            d0 = self.origin + base[sl] * res - p[sl]
            dist2 = np.sum(d0**2, axis=1)[:, None] + 2.0 * (d0 @ ovec.T) + o2[None]
            ok = inside[sl]
            f = np.empty(dist2.shape, dtype=np.int64)
            f[ok] = flat[(base[sl][ok] @ strides)[:, None] + flat_offs[None]]
            if not ok.all():
                f[~ok] = self._lookup(base[sl][~ok][:, None, :] + offs[None])
            f[dist2 > radius**2] = NEVER
            out[sl] = f.min(axis=1)
        return out.reshape(batch)


def default_resolution(robot: RobotModel, B: float | None = None,
                       extent: ArrayLike | None = None) -> float:
    """Cell size: ``min(B / 2, smallest robot radius)``, enlarged to fit the cell budget.

    In 3-D the cell is at least ``reach / 150`` (a few mm for a 1 m arm): finer voxels cost
    the cube of the refinement and change no label in the benchmark.

    ``extent (d,)`` is the size of the box to cover (default: ``2 * reach`` per axis).
    """
    radii = [float(r) for r in robot.link_radii if r > 0]
    res = min(radii) if radii else robot.reach / 100
    if B is not None and B > 0:
        res = min(res, B / 2)
    dim = robot.dim
    if dim == 3:
        res = max(res, robot.reach / REACH_CELLS_3D)
    ext = np.full(dim, 2 * robot.reach) if extent is None else np.asarray(extent, float)
    budget = MAX_CELLS_2D if dim == 2 else MAX_CELLS_3D
    cells = float(np.prod(ext / res + 1))
    if cells > budget:
        res *= (cells / budget) ** (1 / dim) * 1.01
    return float(res)


def _robot_parts(robot: RobotModel) -> tuple[FloatArray, list[tuple[int, int, float]]]:
    """Capsules to rasterise as (start point row, end point row, radius) on joint_positions."""
    n = robot.dof
    parts = [(i, i + 1, float(robot.link_radii[i])) for i in range(n) if robot.link_radii[i] > 0]
    if robot.tip_radius > robot.link_radii[-1]:
        parts.append((n, n, robot.tip_radius))
    return np.array([p[2] for p in parts]), parts


def pose_subsample(points: FloatArray, step: float) -> NDArray[np.int64]:
    """Sample indices such that no robot point moves more than ``step`` between kept ones.

    ``points (N, K, d)`` are the joint and tip positions (the displacement of a rigid segment is
    largest at an end).  The first and last samples are always kept.
    """
    N = points.shape[0]
    if N <= 2:
        return np.arange(N)
    disp = np.max(np.linalg.norm(np.diff(points, axis=0), axis=-1), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(disp)])
    bucket = np.floor(cum / step).astype(np.int64)
    keep = np.flatnonzero(np.diff(bucket)) + 1
    # a jump larger than one step needs its predecessor too so the gap is bridged
    keep = np.union1d(keep, np.maximum(keep - 1, 0))
    return np.union1d([0, N - 1], keep).astype(np.int64)


def swept_map(robot: RobotModel, q: ArrayLike, *, B: float | None = None,
              resolution: float | None = None, margin: float | None = None) -> SweptMap:
    """Rasterise the robot's capsules over a joint trajectory into a :class:`SweptMap`.

    Parameters
    ----------
    robot : RobotModel
    q : (N, n) float, joint positions of every log sample (the map's sample clock)
    B : float, optional; sets the default resolution (``B / 2``) and the margin
    resolution : float, optional cell edge [m]
    margin : float, optional padding of the bounding box beyond the swept robot [m]
    """
    if B is not None:
        B = check_B(B, robot)
    q = robot.check_q(q)
    if q.ndim != 2:
        raise InputError(f"expected q of shape (N, {robot.dof}), got {q.shape}")
    if margin is not None and not (np.isfinite(margin) and 0 <= margin <= robot.reach):
        raise InputError(f"margin must be between 0 and the robot's reach ({robot.reach:.3g} "
                         f"m), got {margin!r}")
    dim = robot.dim
    pts = _joint_positions(robot, q)[..., :dim]
    radii, parts = _robot_parts(robot)
    rmax = float(radii.max()) if radii.size else 0.0
    pad = (margin if margin is not None else (B or 0.0) + rmax) + 1e-9
    lo = pts.reshape(-1, dim).min(axis=0) - rmax - pad
    hi = pts.reshape(-1, dim).max(axis=0) + rmax + pad
    res = float(resolution) if resolution is not None else default_resolution(robot, B, hi - lo)
    if not (np.isfinite(res) and res > 0):
        raise InputError(f"resolution must be a positive length, got {resolution}")
    cells = float(np.prod(np.ceil((hi - lo) / res) + 1))
    if cells > MAX_GRID_CELLS:
        raise InputError(f"a swept map of {res:g} m cells over {np.round(hi - lo, 3).tolist()} m "
                         f"needs {cells:.3g} cells (at most {MAX_GRID_CELLS:,}); use a coarser "
                         "resolution")
    cached = _cache_get(q, robot, res, lo, hi)
    if cached is not None:
        return cached
    smap = _build(robot, q, pts, parts, lo, hi, res)
    _cache_put(q, robot, smap)
    return smap


#: recently built maps: (robot, fingerprint of q, map).  Detection (rigid groups) and the
#: classification of the same log ask for the same map; building it twice would double the cost.
_CACHE: list[tuple[RobotModel, tuple[object, ...], SweptMap]] = []
_CACHE_SIZE = 2


def _fingerprint(q: FloatArray) -> tuple[object, ...]:
    return (q.shape, hash(np.ascontiguousarray(q).tobytes()))


#: joint positions of recently mapped trajectories: each caller asks for the map of the same
#: log with its own resolution or margin, and the forward kinematics of every sample is the
#: larger part of finding that a cached map serves
_POSITIONS: list[tuple[RobotModel, tuple[object, ...], FloatArray]] = []


def _joint_positions(robot: RobotModel, q: FloatArray) -> FloatArray:
    key = _fingerprint(q)
    for crobot, ckey, pts in _POSITIONS:
        if crobot is robot and ckey == key:
            return pts
    pts = robot.joint_positions(q)
    pts.setflags(write=False)
    _POSITIONS.insert(0, (robot, key, pts))
    del _POSITIONS[_CACHE_SIZE:]
    return pts


def _cache_get(q: FloatArray, robot: RobotModel, res: float, lo: FloatArray, hi: FloatArray
               ) -> SweptMap | None:
    """A cached map of the same robot and trajectory, same cell size, covering ``lo..hi``."""
    key = _fingerprint(q)
    for crobot, ckey, smap in _CACHE:
        if crobot is robot and ckey == key and abs(smap.resolution - res) <= 1e-12 * res:
            top = smap.origin + (np.array(smap.first.shape) - 1) * res
            if np.all(smap.origin <= lo + 1e-12) and np.all(top >= hi - 1e-12):
                return smap
    return None


def _cache_put(q: FloatArray, robot: RobotModel, smap: SweptMap) -> None:
    _CACHE.insert(0, (robot, _fingerprint(q), smap))
    del _CACHE[_CACHE_SIZE:]


def _build(robot: RobotModel, q: FloatArray, pts: FloatArray,
           parts: list[tuple[int, int, float]], lo: FloatArray, hi: FloatArray, res: float
           ) -> SweptMap:
    shape = tuple(int(s) for s in np.ceil((hi - lo) / res).astype(int) + 1)
    first = np.full(shape, NEVER, dtype=np.int32)
    smap = SweptMap(lo, res, first, int(q.shape[0]))
    if not parts:
        return smap
    first.setflags(write=True)
    for a_row, b_row, r in parts:
        # each capsule is subsampled at its own pace: an inner link moves far less than the tip,
        # so it needs far fewer rasterised poses (half its own radius, at least half a cell, apart)
        keep = pose_subsample(pts[:, [a_row, b_row]], max(0.5 * r, 0.5 * res))
        # ... and at least every MAX_POSE_GAP samples, so a slowly creeping link still gets
        # first-sweep times close to the truth (the causal map depends on them)
        regular = np.arange(0, q.shape[0], MAX_POSE_GAP)
        ends = pts[:, [a_row, b_row]]
        moved = np.max(np.linalg.norm(np.diff(ends[regular], axis=0), axis=-1), axis=1)
        keep = np.union1d(keep, regular[1:][moved > 0.25 * res])
        _raster_capsules(first, lo, res, pts[keep, a_row], pts[keep, b_row], r, keep)
    first.setflags(write=False)
    return smap


def _raster_capsules(first: NDArray[np.int32], origin: FloatArray, res: float, a: FloatArray,
                     b: FloatArray, r: float, sample: NDArray[np.int64]) -> None:
    """Mark cells whose centre is within ``r`` of segment ``a[k]-b[k]`` with ``sample[k]``.

    Poses are processed in time order and a cell keeps its first (smallest) sample.  Candidate
    cells come from a ball stencil around seed points spaced ``h`` along the axis (radius
    ``sqrt(r² + (h/2)²)`` covers the capsule slab of each seed; ``h = 1.4 r`` minimises the
    overlap); candidates that already hold an earlier sample are dropped before the exact
    point-to-segment test, which is where most of the time would go otherwise.
    """
    dim = first.ndim
    length = float(np.max(np.linalg.norm(b - a, axis=1))) if a.shape[0] else 0.0
    h = max(res, 1.4 * r)
    n_ax = max(1, int(np.ceil(length / h))) + 1
    s = np.linspace(0.0, 1.0, n_ax)
    lim = np.sqrt(r * r + 0.25 * h * h) / res + 0.5 * np.sqrt(dim)
    reach = int(np.ceil(lim))
    axes = [np.arange(-reach, reach + 1)] * dim
    offs = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, dim)
    offs = offs[np.sum(offs**2, axis=1) <= lim**2]
    shape = np.array(first.shape)
    strides = np.array([int(np.prod(shape[k + 1:])) for k in range(dim)], dtype=np.int64)
    offs_flat = offs @ strides
    flat = first.reshape(-1)
    per_pose = n_ax * offs.shape[0]
    # small chunks: the poses of one chunk are tested against the marks of the chunks before
    # it, and consecutive poses overlap, so a chunk of thousands of poses re-tests the same
    # cells thousands of times (16 000 candidates per chunk: 2.3x faster than 2 000 000 on a
    # 3-D run, the same map)
    chunk = max(1, _CHUNK_CANDIDATES // per_pose)
    for c0 in range(0, a.shape[0], chunk):
        aa, bb = a[c0:c0 + chunk], b[c0:c0 + chunk]
        P = aa.shape[0]
        seeds = aa[:, None, :] + s[None, :, None] * (bb - aa)[:, None, :]  # (P, A, d)
        base = np.floor((seeds - origin) / res + 0.5).astype(np.int64)
        # a seed whose whole stencil lies inside the grid needs no per-candidate bounds test
        inside = np.all((base - reach >= 0) & (base + reach < shape), axis=-1)   # (P, A)
        idx = ((base @ strides)[:, :, None] + offs_flat[None, None]).reshape(P, -1)
        valid = np.repeat(inside, offs.shape[0], axis=1)
        if not np.all(inside):
            cand = (base[:, :, None, :] + offs[None, None]).reshape(P, -1, dim)
            valid = np.all((cand >= 0) & (cand < shape), axis=-1)
            idx = np.where(valid, idx, 0)
        t_pose = sample[c0:c0 + chunk].astype(np.int64)
        valid &= t_pose[:, None] < flat[idx]
        pi, ci = np.nonzero(valid)          # row-major: in time order
        if pi.shape[0] == 0:
            continue
        fi = idx[pi, ci]
        cell = np.stack(np.unravel_index(fi, first.shape), -1)
        rel = origin + cell * res - aa[pi]
        ab = (bb - aa)[pi]
        u = np.clip(np.sum(rel * ab, -1) / np.maximum(np.sum(ab * ab, -1), 1e-300), 0.0, 1.0)
        ok = np.sum((rel - u[:, None] * ab) ** 2, -1) <= r * r
        fi = fi[ok]
        t = t_pose[pi[ok]]
        fi, first_pos = np.unique(fi, return_index=True)
        t = t[first_pos].astype(np.int32)
        flat[fi] = np.minimum(flat[fi], t)
