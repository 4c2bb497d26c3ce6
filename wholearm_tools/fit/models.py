"""Fit models: the parameterisation, signed distance and initial guesses of each primitive type.

One :class:`Model` per primitive type, registered in :data:`MODELS` by the map.json type name.
Each model holds, in one place:

* its **raw parameter vector** (what IPOPT optimises) with bounds and equality constraints that
  remove singularities and gauge freedoms: unit vectors are plain 3-vectors constrained to
  ``||n||^2 = 1``; the cylinder's axis point is constrained to be the point of the axis closest to
  the data centroid; radii are bounded below by a small positive number; the cone half-angle lies
  in ``(0, pi/2)``; a torus keeps ``major_radius > minor_radius``;
* its **signed distance** written once against a tiny ``ops`` namespace so the *same* formula is
  evaluated by numpy (residuals, growth, model selection) and built symbolically with CasADi (the
  NLP); the sign conventions are those of :mod:`wholearm_tools.geometry.base` (negative inside
  closed shapes, positive on the normal side of lines and planes);
* the map from raw parameters to the **map.json parameters** (names of ARCHITECTURE.md);
* **initial guesses** from algebraic fits (PCA lines/planes, Kasa circles/spheres, normal-based
  cylinder/cone axes, meridian-circle torus) — a short list of candidates, best first.

All geometry here is in *normalised* coordinates (data centroid at the origin, unit RMS spread);
:mod:`wholearm_tools.fit.core` converts to and from metres.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from types import SimpleNamespace
from typing import Any

import casadi as ca
import numpy as np

from wholearm_tools.geometry.base import segment_min_numeric

FloatArray = np.ndarray

#: numpy backend of the distance formulas
NP_OPS = SimpleNamespace(sqrt=np.sqrt, where=np.where, fmax=np.maximum, sin=np.sin, cos=np.cos)
#: CasADi backend of the distance formulas (elementwise on MX/SX column vectors)
CA_OPS = SimpleNamespace(sqrt=ca.sqrt, where=ca.if_else, fmax=ca.fmax, sin=ca.sin, cos=ca.cos)

_R_MIN = 1e-7  # smallest radius (normalised units)
_A_MIN = 1e-4  # cone half-angle margin from 0 and pi/2


@dataclass(frozen=True)
class ParamSpec:
    """One map.json parameter: ``role`` is ``point`` (shifted and scaled back to metres),
    ``length`` (scaled), ``direction`` or ``angle`` (unchanged)."""

    name: str
    size: int  # 1 for scalars
    role: str


@dataclass(frozen=True)
class Model:
    """Everything the fitter needs to know about one primitive type."""

    kind: str
    dim: int
    dof: int
    n_raw: int
    #: (lower, upper) bounds of the raw vector
    lbx: tuple[float, ...]
    ubx: tuple[float, ...]
    #: signed distance: ``sd(ops, cols, th) -> column``; ``cols`` = d coordinate columns
    sd: Callable[[Any, Sequence[Any], Sequence[Any]], Any]
    #: equality constraints ``g(th) = 0`` (list of scalar expressions; numpy or CasADi)
    eq: Callable[[Sequence[Any]], list[Any]]
    #: inequality constraints ``g(th) >= 0``
    ineq: Callable[[Sequence[Any]], list[Any]]
    #: raw -> map.json parameters (normalised units), numpy
    to_params: Callable[[FloatArray], dict[str, Any]]
    params: tuple[ParamSpec, ...]
    #: initial guesses ``init(ctx) -> list of raw vectors`` (normalised units)
    init: Callable[[InitContext], list[FloatArray]]
    #: minimum rank of the centred contact point cloud for the type to be determined
    min_rank: int
    #: signed distance is linear along a segment (minimum always at an end point)
    linear: bool = False
    #: number of IPOPT starts tried (best initial guesses first)
    starts: int = 1
    #: one cheap initial guess (RANSAC hypotheses); None uses the first of :attr:`init`
    quick_init: Callable[[InitContext], list[FloatArray]] | None = None


@dataclass(frozen=True)
class InitContext:
    """Normalised data handed to the initial-guess functions."""

    tip: FloatArray  # (Nt, d)
    tip_w: FloatArray  # (Nt,)
    a: FloatArray  # (Nl, d)
    b: FloatArray  # (Nl, d)
    link_w: FloatArray  # (Nl,)
    side: float  # +1 / -1

    @property
    def surface_points(self) -> FloatArray:
        """Tip points and link midpoints, shape ``(N, d)`` (rough surface samples)."""
        return np.vstack([self.tip, 0.5 * (self.a + self.b)])

    @property
    def offsets(self) -> FloatArray:
        """Radius of each surface point in :attr:`surface_points` order."""
        return np.concatenate([self.tip_w, self.link_w])

    @property
    def all_points(self) -> FloatArray:
        return np.vstack([self.tip, self.a, self.b])


MODELS: dict[str, Model] = {}


def model(kind: str) -> Model:
    """The fit model registered for ``kind``."""
    return MODELS[kind]


def _register(m: Model) -> Model:
    MODELS[m.kind] = m
    return m


# --------------------------------------------------------------------------- algebraic helpers


def _unit(v: FloatArray) -> FloatArray:
    n = float(np.linalg.norm(v))
    return v / n if n > 0 else np.eye(len(v))[0]


def pca(points: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Centroid, singular values and principal directions (rows, largest first)."""
    c = points.mean(axis=0)
    _, s, vt = np.linalg.svd(points - c, full_matrices=False)
    if vt.shape[0] < points.shape[1]:  # fewer points than dimensions
        _, _, vt_full = np.linalg.svd(
            np.vstack([points - c, np.zeros((points.shape[1], points.shape[1]))]))
        vt = vt_full
        s = np.concatenate([s, np.zeros(points.shape[1] - len(s))])
    return c, s, vt


def kasa(points: FloatArray) -> tuple[FloatArray, float]:
    """Algebraic (Kasa) circle/sphere fit: centre and radius."""
    A = np.hstack([2.0 * points, np.ones((len(points), 1))])
    y = np.einsum("ij,ij->i", points, points)
    sol, *_ = np.linalg.lstsq(A, y, rcond=None)
    c = sol[:-1]
    r2 = sol[-1] + c @ c
    return c, float(np.sqrt(max(r2, 1e-12)))


def kasa_offset(points: FloatArray, offsets: FloatArray, side: float
                ) -> tuple[FloatArray, float]:
    """Algebraic circle/sphere fit of points lying ``side * w_i`` off the surface: centre and
    surface radius ``R``.  ``|x_i - c|^2 = (R + side w_i)^2`` is linear in ``c``,
    ``c0 = R^2 - |c|^2`` and ``R`` once ``c0`` is taken as independent:
    ``|x_i|^2 - w_i^2 = 2 c . x_i + c0 + 2 side R w_i``.  Contact centres of spheres of
    different radii (a tip, a joint) are not on one circle, which a plain Kasa fit assumes."""
    w = np.asarray(offsets, dtype=float)
    A = np.hstack([2.0 * points, np.ones((len(points), 1)), 2.0 * side * w[:, None]])
    y = np.einsum("ij,ij->i", points, points) - w * w
    sol, *_ = np.linalg.lstsq(A, y, rcond=None)
    c = sol[:-2]
    R = float(np.mean(np.linalg.norm(points - c, axis=1) - side * w))
    return c, R


def local_normals(points: FloatArray, k: int = 8) -> FloatArray:
    """Unoriented unit normals from the PCA of each point's ``k`` nearest neighbours."""
    n, d = points.shape
    k = min(k, n)
    dist = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    idx = np.argsort(dist, axis=1)[:, :k]
    nb = points[idx] - points[idx].mean(axis=1, keepdims=True)
    _, _, vt = np.linalg.svd(nb)
    return vt[:, d - 1, :]


def _perp_basis(axis: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`perp_bases` of one axis."""
    u, v = perp_bases(np.asarray(axis, dtype=float)[None])
    return u[0], v[0]


def refine_link_points(ctx: InitContext, sd_np: Callable[[FloatArray], FloatArray],
                       side: float) -> FloatArray:
    """Surface-point estimate per link: the segment point of least clearance under a guess."""
    if len(ctx.a) == 0:
        return np.zeros((0, ctx.tip.shape[1]))
    _, t = segment_min_numeric(lambda p: side * sd_np(p), ctx.a, ctx.b)
    return ctx.a + t[:, None] * (ctx.b - ctx.a)


def _no_constraints(th: Sequence[Any]) -> list[Any]:
    return []


def _unit_constraint(i: int, d: int) -> Callable[[Sequence[Any]], list[Any]]:
    def eq(th: Sequence[Any]) -> list[Any]:
        return [sum(th[i + j] * th[i + j] for j in range(d)) - 1.0]
    return eq


# --------------------------------------------------------------------------- line (2-D)
# raw: n (2, unit normal), c (offset): sd = n . x - c


def _line_sd(ops: Any, X: Sequence[Any], th: Sequence[Any]) -> Any:
    return th[0] * X[0] + th[1] * X[1] - th[2]


def _line_params(th: FloatArray) -> dict[str, Any]:
    n = th[:2] / np.linalg.norm(th[:2])
    return {"point": th[2] * n, "direction": np.array([n[1], -n[0]])}


def _hyperplane_init(ctx: InitContext) -> list[FloatArray]:
    """PCA normals of several point sets: a link touches a line or plane at one of its end
    points, so the tips with the outer link ends, with the inner ends, with the midpoints, and
    all points are tried (the fit keeps the best start)."""
    sets = [ctx.all_points]
    if len(ctx.a):
        sets = [np.vstack([ctx.tip, ctx.b]), np.vstack([ctx.tip, ctx.a]),
                ctx.surface_points, ctx.all_points]
    out = []
    for pts in sets:
        if len(pts) < ctx.tip.shape[1]:
            continue
        _, _, vt = pca(pts)
        n = vt[-1]
        # offset so that the contact centres sit at +w on the free side
        c0 = float(np.mean(pts[: len(ctx.tip)] @ n - ctx.side * ctx.tip_w)) if len(ctx.tip) \
            else float(np.mean(pts @ n))
        out.append(np.concatenate([n, [c0]]))
    return out


_register(Model(
    kind="line", dim=2, dof=2, n_raw=3,
    lbx=(-np.inf,) * 3, ubx=(np.inf,) * 3,
    sd=_line_sd, eq=_unit_constraint(0, 2), ineq=_no_constraints,
    to_params=_line_params,
    params=(ParamSpec("point", 2, "point"), ParamSpec("direction", 2, "direction")),
    init=_hyperplane_init, min_rank=1, linear=True, starts=2,
))


# --------------------------------------------------------------------------- circle / sphere


def _round_sd(d: int) -> Callable[[Any, Sequence[Any], Sequence[Any]], Any]:
    def sd(ops: Any, X: Sequence[Any], th: Sequence[Any]) -> Any:
        q = sum((X[j] - th[j]) * (X[j] - th[j]) for j in range(d))
        return ops.sqrt(q) - th[d]
    return sd


def _round_params(d: int) -> Callable[[FloatArray], dict[str, Any]]:
    def to_params(th: FloatArray) -> dict[str, Any]:
        return {"center": th[:d].copy(), "radius": float(th[d])}
    return to_params


def _round_init(ctx: InitContext) -> list[FloatArray]:
    """Offset Kasa fit (:func:`kasa_offset`) of the tips and the links' least-clearance points,
    alternated from the links' midpoints."""
    d = ctx.tip.shape[1]
    c, r = kasa_offset(ctx.surface_points, ctx.offsets, ctx.side)
    for _ in range(3):  # move link samples to their least-clearance points, refit
        if len(ctx.a) == 0:
            break
        th = np.concatenate([c, [max(r, 10 * _R_MIN)]])
        lp = refine_link_points(ctx, lambda p, th=th: _round_sd(d)(NP_OPS, p.T, th), ctx.side)
        c, r = kasa_offset(np.vstack([ctx.tip, lp]), ctx.offsets, ctx.side)
    return [np.concatenate([c, [max(r, 10 * _R_MIN)]])]


def _round_quick(ctx: InitContext) -> list[FloatArray]:
    c, r = kasa_offset(ctx.surface_points, ctx.offsets, ctx.side)
    return [np.concatenate([c, [max(r, 10 * _R_MIN)]])]


for _kind, _d in (("circle", 2), ("sphere", 3)):
    _register(Model(
        kind=_kind, dim=_d, dof=_d + 1, n_raw=_d + 1,
        lbx=(-np.inf,) * _d + (_R_MIN,), ubx=(np.inf,) * (_d + 1),
        sd=_round_sd(_d), eq=_no_constraints, ineq=_no_constraints,
        to_params=_round_params(_d),
        params=(ParamSpec("center", _d, "point"), ParamSpec("radius", 1, "length")),
        init=_round_init, min_rank=_d, quick_init=_round_quick,
    ))


# --------------------------------------------------------------------------- plane
# raw: n (3, unit), c: sd = n . x - c


def _plane_sd(ops: Any, X: Sequence[Any], th: Sequence[Any]) -> Any:
    return th[0] * X[0] + th[1] * X[1] + th[2] * X[2] - th[3]


def _plane_params(th: FloatArray) -> dict[str, Any]:
    n = th[:3] / np.linalg.norm(th[:3])
    return {"point": th[3] * n, "normal": n}


_register(Model(
    kind="plane", dim=3, dof=3, n_raw=4,
    lbx=(-np.inf,) * 4, ubx=(np.inf,) * 4,
    sd=_plane_sd, eq=_unit_constraint(0, 3), ineq=_no_constraints,
    to_params=_plane_params,
    params=(ParamSpec("point", 3, "point"), ParamSpec("normal", 3, "direction")),
    init=_hyperplane_init, min_rank=2, linear=True, starts=2,
))


# --------------------------------------------------------------------------- cylinder
# raw: p (3, axis point closest to the data centroid = origin), a (3, unit), r


def _axial(X: Sequence[Any], th: Sequence[Any]) -> tuple[Any, Any]:
    """Axial coordinate h and squared length |q|^2 of q = x - th[0:3] along axis th[3:6]."""
    q = [X[j] - th[j] for j in range(3)]
    h = q[0] * th[3] + q[1] * th[4] + q[2] * th[5]
    qq = q[0] * q[0] + q[1] * q[1] + q[2] * q[2]
    return h, qq


def _cyl_sd(ops: Any, X: Sequence[Any], th: Sequence[Any]) -> Any:
    h, qq = _axial(X, th)
    return ops.sqrt(ops.fmax(qq - h * h, 1e-30)) - th[6]


def _cyl_eq(th: Sequence[Any]) -> list[Any]:
    return [th[3] * th[3] + th[4] * th[4] + th[5] * th[5] - 1.0,
            th[0] * th[3] + th[1] * th[4] + th[2] * th[5]]


def _cyl_params(th: FloatArray) -> dict[str, Any]:
    return {"point": th[:3].copy(), "axis": th[3:6] / np.linalg.norm(th[3:6]),
            "radius": float(th[6])}


def _axis_candidates(ctx: InitContext) -> list[FloatArray]:
    """Axis guesses: normal to all local normals (cylinder/cone), then the principal axes."""
    surf = ctx.surface_points
    cands = []
    if len(surf) >= 5:
        nrm = local_normals(surf, k=min(8, len(surf)))
        _, _, vt = np.linalg.svd(nrm - nrm.mean(axis=0))
        cands.append(vt[-1])
        _, _, vt0 = np.linalg.svd(nrm)
        cands.append(vt0[-1])
    _, _, vt = pca(ctx.all_points)
    cands.extend(vt)
    return [_unit(c) for c in cands]


def _cyl_from_axis(ctx: InitContext, axis: FloatArray) -> FloatArray:
    u, v = _perp_basis(axis)
    surf = ctx.surface_points
    uv = np.stack([surf @ u, surf @ v], axis=1)
    c2, r = kasa(uv)
    p = c2[0] * u + c2[1] * v
    p = p - (p @ axis) * axis
    r_surf = max(r - ctx.side * float(np.mean(ctx.offsets)), 10 * _R_MIN)
    return np.concatenate([p, axis, [r_surf]])


def _hemisphere(n: int) -> FloatArray:
    """``n`` unit vectors spread evenly over the upper hemisphere (Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1.0 - i / n
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    rr = np.sqrt(1.0 - z * z)
    return np.stack([rr * np.cos(phi), rr * np.sin(phi), z], axis=1)


_DIRECTIONS = _hemisphere(400)


def _scan_axes(ctx: InitContext, keep: int = 3, min_angle_deg: float = 15.0,
               quick: bool = False) -> list[FloatArray]:
    """Best cylinder axes by direction sampling: for each of 400 directions, the algebraic
    circle fit of the surface samples projected on the perpendicular plane, with the contact
    radii as offsets (``rho_i = r + side * w_i``), scored by the geometric residual; the best
    ``keep`` mutually distinct directions.  Robust to partial arcs where local normals and PCA
    fail, and cheap (vectorised numpy, no solver)."""
    X = ctx.surface_points
    off = ctx.offsets
    if len(X) < 5:
        return []
    A = _DIRECTIONS
    score = _axis_score(X, off, ctx.side, A)
    out: list[FloatArray] = []
    cos_min = np.cos(np.radians(min_angle_deg))
    for k in np.argsort(score):
        if not np.isfinite(score[k]) or len(out) >= keep:
            break
        if all(abs(float(A[k] @ a)) < cos_min for a in out):
            out.append(A[k])
    if quick:  # RANSAC hypotheses: a coarser refinement is plenty for an inlier test
        return [_refine_axis(X, off, ctx.side, a, (0.06, 0.02, 0.007), _LOCAL[:40])
                for a in out]
    return [_refine_axis(X, off, ctx.side, a) for a in out]


def perp_bases(A: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per unit row ``a`` of ``A (K, 3)``: unit ``u, v`` with ``(a, u, v)`` right-handed
    orthonormal, ``u = a x e`` for the axis ``e`` least aligned with ``a`` (cross products
    written out: ``np.cross`` costs more than the arithmetic on these small arrays)."""
    a0, a1, a2 = A[:, 0], A[:, 1], A[:, 2]
    k = np.argmin(np.abs(A), axis=1)
    zero = np.zeros_like(a0)
    U = np.where((k == 0)[:, None], np.stack([zero, a2, -a1], 1),
                 np.where((k == 1)[:, None], np.stack([-a2, zero, a0], 1),
                          np.stack([a1, -a0, zero], 1)))
    U /= np.linalg.norm(U, axis=1, keepdims=True)
    u0, u1, u2 = U[:, 0], U[:, 1], U[:, 2]
    V = np.stack([a1 * u2 - a2 * u1, a2 * u0 - a0 * u2, a0 * u1 - a1 * u0], 1)
    return U, V


def _axis_score(X: FloatArray, off: FloatArray, side: float, A: FloatArray) -> FloatArray:
    """Geometric residual sum of squares of the offset circle fit, with the contact radii as
    offsets (``rho_i = r + side * w_i``), for each axis row of ``A``: the Kasa fit
    ``[2x 2y 1] [cx cy c]^T = x^2 + y^2`` of ``X`` projected on the plane normal to it."""
    U, V = perp_bases(A)
    x = X @ U.T
    y = X @ V.T
    M = np.stack([2 * x, 2 * y, np.ones_like(x)], axis=2)
    MtM = np.einsum("nki,nkj->kij", M, M) + 1e-12 * np.eye(3)
    Mty = np.einsum("nki,nk->ki", M, x * x + y * y)
    sol = np.linalg.solve(MtM, Mty[..., None])[..., 0]
    rho = np.sqrt((x - sol[:, 0]) ** 2 + (y - sol[:, 1]) ** 2)
    r = np.mean(rho - side * off[:, None], axis=0)
    res = rho - side * off[:, None] - r
    score = np.sum(res * res, axis=0)
    score[~np.isfinite(score) | (r <= 0)] = np.inf
    return score


_LOCAL = np.random.default_rng(0).standard_normal((120, 3))


def _refine_axis(X: FloatArray, off: FloatArray, side: float, axis: FloatArray,
                 steps: tuple[float, ...] = (0.06, 0.02, 0.007, 0.0025, 0.0008),
                 local: FloatArray = _LOCAL) -> FloatArray:
    """Local refinement of a sampled axis: shrinking random perturbations (the 400-direction
    lattice is ~5 degrees apart, too coarse for a seed's inlier test)."""
    best = axis
    best_s = float(_axis_score(X, off, side, best[None])[0])
    for step in steps:
        C = best[None] + step * local
        C /= np.linalg.norm(C, axis=1, keepdims=True)
        sc = _axis_score(X, off, side, C)
        k = int(np.argmin(sc))
        if sc[k] < best_s:
            best, best_s = C[k], float(sc[k])
    return best


def _cyl_follow_links(ctx: InitContext, th: FloatArray, rounds: int = 12) -> FloatArray:
    """Refine a cylinder guess for link contacts by alternation: move each link's surface
    sample to its point of least clearance under the guess, refine the axis locally on those
    samples, refit the cross-section; until the samples stop moving.  The scan starts from
    link midpoints, which a link tangent to a post near one end is far from: with mostly link
    contacts that start leaves IPOPT in a wrong basin (r 0.038 for a 0.05 post)."""
    lp_prev = None
    for _ in range(rounds):
        lp = refine_link_points(ctx, lambda p, th=th: _cyl_sd(NP_OPS, p.T, th), ctx.side)
        if lp_prev is not None and float(np.max(np.abs(lp - lp_prev))) < 1e-4:
            break
        lp_prev = lp
        on = replace(ctx, a=lp, b=lp)  # each link as its surface sample
        axis = _refine_axis(on.surface_points, on.offsets, ctx.side, th[3:6],
                            (0.06, 0.02, 0.007), _LOCAL[:40])
        th = _cyl_from_axis(on, axis)
    return th


def _cyl_init(ctx: InitContext) -> list[FloatArray]:
    out = [_cyl_from_axis(ctx, a) for a in [*_scan_axes(ctx), *_axis_candidates(ctx)]]
    if len(ctx.a) <= len(ctx.tip):  # the midpoints are a small share of the samples
        return out
    return [*(_cyl_follow_links(ctx, th) for th in out[:3]), *out]


def _cyl_quick(ctx: InitContext) -> list[FloatArray]:
    return [_cyl_from_axis(ctx, a) for a in _scan_axes(ctx, keep=1, quick=True)]


_register(Model(
    kind="cylinder", dim=3, dof=5, n_raw=7,
    lbx=(-np.inf,) * 6 + (_R_MIN,), ubx=(np.inf,) * 7,
    sd=_cyl_sd, eq=_cyl_eq, ineq=_no_constraints,
    to_params=_cyl_params,
    params=(ParamSpec("point", 3, "point"), ParamSpec("axis", 3, "direction"),
            ParamSpec("radius", 1, "length")),
    init=_cyl_init, min_rank=2, starts=3, quick_init=_cyl_quick,
))


# --------------------------------------------------------------------------- cone
# raw: apex (3), a (3, unit, opening direction), alpha (half angle)


def _cone_sd(ops: Any, X: Sequence[Any], th: Sequence[Any]) -> Any:
    h, qq = _axial(X, th)
    rho = ops.sqrt(ops.fmax(qq - h * h, 1e-30))
    sa, cah = ops.sin(th[6]), ops.cos(th[6])
    front = rho * sa + h * cah
    return ops.where(front > 0, rho * cah - h * sa, ops.sqrt(ops.fmax(qq, 1e-30)))


def _cone_params(th: FloatArray) -> dict[str, Any]:
    return {"apex": th[:3].copy(), "axis": th[3:6] / np.linalg.norm(th[3:6]),
            "half_angle": float(th[6])}


def _cone_fits(X: FloatArray, A: FloatArray) -> tuple[FloatArray, ...]:
    """Algebraic cone fit of points ``X (N, 3)`` about each trial axis direction ``A (K, 3)``.

    About an axis of direction ``a`` through ``(cx, cy)`` in the perpendicular plane, a cone is
    ``rho = k h + m`` (``rho`` distance to the axis, ``h`` axial coordinate), i.e.
    ``x^2 + y^2 = 2 cx x + 2 cy y + k^2 h^2 + 2 k m h + (m^2 - cx^2 - cy^2)``: linear in five
    unknowns for a fixed ``a`` (a cylinder is ``k = 0``).  Returns ``(cx, cy, k, m, score)``
    per direction with ``score`` the sum of squared geometric (meridian) residuals, ``inf``
    where the fit is not a cone opening along ``+a`` (``k <= 0``).
    """
    U, V = perp_bases(A)
    x, y, h = X @ U.T, X @ V.T, X @ A.T  # (N, K)
    M = np.stack([2 * x, 2 * y, h * h, h, np.ones_like(x)], axis=2)  # (N, K, 5)
    MtM = np.einsum("nki,nkj->kij", M, M) + 1e-12 * np.eye(5)
    Mty = np.einsum("nki,nk->ki", M, x * x + y * y)
    sol = np.linalg.solve(MtM, Mty[..., None])[..., 0]  # (K, 5)
    cx, cy = sol[:, 0], sol[:, 1]
    k = np.sqrt(np.maximum(sol[:, 2], 0.0))
    m = sol[:, 3] / np.maximum(2 * k, 1e-12)
    rho = np.sqrt((x - cx) ** 2 + (y - cy) ** 2)
    res = (rho - k * h - m) / np.sqrt(1 + k * k)
    score = np.sum(res * res, axis=0)
    score[~np.isfinite(score) | (sol[:, 2] <= 1e-6)] = np.inf
    return cx, cy, k, m, score


def _cone_raw(ctx: InitContext, axis: FloatArray, cx: float, cy: float, k: float, m: float
              ) -> FloatArray | None:
    """Raw cone vector from one algebraic fit (apex shifted for the contact radii)."""
    if not (k > 1e-3 and np.isfinite(k) and np.isfinite(m)):
        return None
    u, v = _perp_basis(axis)
    alpha = float(np.clip(np.arctan(k), 2 * _A_MIN, np.pi / 2 - 2 * _A_MIN))
    apex = cx * u + cy * v - (m / k) * axis  # rho = 0 at h = -m / k
    # the contact centres lie on the cone offset by w: same axis and angle, apex moved
    w = float(np.mean(ctx.offsets))
    apex = apex + ctx.side * w / np.sin(alpha) * axis
    return np.concatenate([apex, axis, [alpha]])


def _cone_init(ctx: InitContext, keep: int = 3, min_angle_deg: float = 15.0,
               directions: FloatArray | None = None,
               steps: tuple[float, ...] = (0.06, 0.02, 0.007, 0.0025, 0.0008),
               local: FloatArray | None = None) -> list[FloatArray]:
    """Cone guesses by direction sampling: the algebraic fit of :func:`_cone_fits` about each of
    800 directions (both senses of the 400-direction hemisphere: a cone opens one way), the best
    ``keep`` mutually distinct axes refined by shrinking perturbations; then the local-normal /
    principal axes as a fallback."""
    X = ctx.surface_points
    out: list[FloatArray] = []
    local = _LOCAL if local is None else local
    if len(X) >= 6:
        hemi = _DIRECTIONS if directions is None else directions
        dirs = np.vstack([hemi, -hemi])
        *_, score = _cone_fits(X, dirs)
        cos_min = np.cos(np.radians(min_angle_deg))
        chosen: list[FloatArray] = []
        for j in np.argsort(score):
            if not np.isfinite(score[j]) or len(chosen) >= keep:
                break
            if all(float(dirs[j] @ a) < cos_min for a in chosen):
                chosen.append(dirs[j])
        for axis in chosen:
            best_s = float(_cone_fits(X, axis[None])[4][0])
            for step in steps:
                C = axis[None] + step * local
                C /= np.linalg.norm(C, axis=1, keepdims=True)
                sc = _cone_fits(X, C)[4]
                j = int(np.argmin(sc))
                if sc[j] < best_s:
                    axis, best_s = C[j], float(sc[j])
            cx, cy, k, m, _ = _cone_fits(X, axis[None])
            raw = _cone_raw(ctx, axis, float(cx[0]), float(cy[0]), float(k[0]), float(m[0]))
            if raw is not None:
                out.append(raw)
    for ax in _axis_candidates(ctx):
        for sense in (ax, -ax):
            cx, cy, k, m, _ = _cone_fits(X, sense[None])
            raw = _cone_raw(ctx, sense, float(cx[0]), float(cy[0]), float(k[0]), float(m[0]))
            if raw is not None:
                out.append(raw)
    return out


_register(Model(
    kind="cone", dim=3, dof=6, n_raw=7,
    lbx=(-np.inf,) * 6 + (_A_MIN,), ubx=(np.inf,) * 6 + (np.pi / 2 - _A_MIN,),
    sd=_cone_sd, eq=_unit_constraint(3, 3), ineq=_no_constraints,
    to_params=_cone_params,
    params=(ParamSpec("apex", 3, "point"), ParamSpec("axis", 3, "direction"),
            ParamSpec("half_angle", 1, "angle")),
    init=_cone_init, min_rank=3, starts=3,
    quick_init=lambda ctx: _cone_init(ctx, keep=1, directions=_DIRECTIONS[::4],
                                      steps=(0.06, 0.02, 0.007), local=_LOCAL[:40])[:1],
))


# --------------------------------------------------------------------------- torus
# raw: centre (3), a (3, unit), R (major), r (minor); constraint R - r >= 0


def _torus_sd(ops: Any, X: Sequence[Any], th: Sequence[Any]) -> Any:
    h, qq = _axial(X, th)
    rho = ops.sqrt(ops.fmax(qq - h * h, 1e-30))
    return ops.sqrt(ops.fmax((rho - th[6]) * (rho - th[6]) + h * h, 1e-30)) - th[7]


def _torus_ineq(th: Sequence[Any]) -> list[Any]:
    return [th[6] - th[7]]


def _torus_params(th: FloatArray) -> dict[str, Any]:
    return {"center": th[:3].copy(), "axis": th[3:6] / np.linalg.norm(th[3:6]),
            "major_radius": float(th[6]), "minor_radius": float(th[7])}


def _torus_from_axis(ctx: InitContext, axis: FloatArray) -> FloatArray | None:
    """Trial axis: centre from a circle fit of the projected points, then the meridian circle
    (tube cross-section) by a Kasa fit in the (rho, h) half-plane."""
    surf = ctx.surface_points
    u, v = _perp_basis(axis)
    c2, _ = kasa(np.stack([surf @ u, surf @ v], axis=1))
    base = c2[0] * u + c2[1] * v
    h = (surf - base) @ axis
    rho = np.linalg.norm(surf - base - h[:, None] * axis, axis=1)
    (R, h0), r = kasa(np.stack([rho, h], axis=1))
    r = r - ctx.side * float(np.mean(ctx.offsets))
    if not (R > r > _R_MIN):
        return None
    return np.concatenate([base + h0 * axis, axis, [R, r]])


def _torus_init(ctx: InitContext) -> list[FloatArray]:
    out = []
    for ax in _axis_candidates(ctx):
        th = _torus_from_axis(ctx, ax)
        if th is not None:
            out.append(th)
    return out


_register(Model(
    kind="torus", dim=3, dof=7, n_raw=8,
    lbx=(-np.inf,) * 6 + (_R_MIN, _R_MIN), ubx=(np.inf,) * 8,
    sd=_torus_sd, eq=_unit_constraint(3, 3), ineq=_torus_ineq,
    to_params=_torus_params,
    params=(ParamSpec("center", 3, "point"), ParamSpec("axis", 3, "direction"),
            ParamSpec("major_radius", 1, "length"), ParamSpec("minor_radius", 1, "length")),
    init=_torus_init, min_rank=3, starts=3,
))


def signed_distance_np(m: Model, th: FloatArray, points: FloatArray) -> FloatArray:
    """Numpy signed distance of ``points (N, d)`` under raw parameters ``th``."""
    return np.asarray(m.sd(NP_OPS, [points[:, j] for j in range(m.dim)], [float(x) for x in th]),
                      dtype=float).reshape(len(points))
