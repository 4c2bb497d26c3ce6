"""Single-primitive fits with CasADi/IPOPT (eq. 3 of the paper, tip and link residuals).

Problem
-------
For tip contact ``i`` (sphere centre ``P_i``, radius ``w_i``) and link contact ``j`` (axis segment
``a_j b_j``, capsule radius ``w_j``), with ``s`` the free side (+1 free space outside / on the
normal side, -1 inside) and ``sd`` the signed distance of the primitive::

    r_i = s * sd(P_i)                     - w_i
    r_j = s * sd(a_j + t_j (b_j - a_j))   - w_j      t_j in [0, 1] latent

    minimise  sum_i W_i rho(r_i) + sum_j W_j rho(r_j)   over (theta, t)

``s * sd`` is the clearance; because the robot is always on the free side, it is smooth where the
data are (the unsigned distance is not, at the surface).  The latent ``t_j`` is constrained to be
a stationary point of the clearance along the link (``d clearance / d t_j = 0``), i.e. the
tangency point, so that a link touching the surface gives information: without the constraint
any surface *crossing* the offset of a segment would give a zero residual.  Links whose least
clearance lies at an end point (always so for lines and planes, and inside concave surfaces) or
along a flat stretch have ``t_j`` fixed there instead; the active set is checked against an exact
numeric minimisation after each solve and the solve repeated when it changed.

Numerics
--------
Data are normalised (centroid at the origin, unit RMS spread) and weights to mean 1.  The NLP is
one vectorised MX graph per ``(kind, loss, tip bucket, link bucket, max_iter)``, expanded to SX,
built once and cached; the data are parameters.  Sizes are padded to buckets (duplicate contacts
with zero weight) so that segmentation re-uses a handful of graphs.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from wholearm_tools.errors import InputError
from wholearm_tools.fit.data import FitData, FreeSpace
from wholearm_tools.fit.models import (
    CA_OPS,
    MODELS,
    InitContext,
    Model,
    signed_distance_np,
)
from wholearm_tools.fit.result import FitResult
from wholearm_tools.geometry.base import segment_min_numeric

LOSSES = ("linear", "huber", "cauchy")
_SUCCESS = ("Solve_Succeeded", "Solved_To_Acceptable_Level")
_T_EDGE = 1e-6
_FLAT = 1e-6


def _bucket(n: int) -> int:
    """Padded problem size: 0, then 4, 6, 8, 12, 16, 24, ... (<= 1.5x the request)."""
    if n == 0:
        return 0
    b = 4
    while b < n:
        b = b * 3 // 2 if (b & (b - 1)) == 0 else (b // 3) * 4
    return b


def _rho_ca(z: Any, loss: str, delta: Any) -> Any:
    if loss == "linear":
        return 0.5 * z * z
    u = z / delta
    if loss == "huber":  # smooth (pseudo-)Huber: quadratic near 0, linear in the tails
        return delta * delta * (ca.sqrt(1.0 + u * u) - 1.0)
    return 0.5 * delta * delta * ca.log1p(u * u)  # cauchy


def rho_np(z: np.ndarray, loss: str, delta: float) -> np.ndarray:
    """Numpy loss ``rho(z)`` (same definitions as the NLP)."""
    if loss == "linear":
        return 0.5 * z * z
    u = z / delta
    if loss == "huber":
        return delta * delta * (np.sqrt(1.0 + u * u) - 1.0)
    return 0.5 * delta * delta * np.log1p(u * u)


def _irls_weight(z: np.ndarray, loss: str, delta: float) -> np.ndarray:
    """``rho'(z) / z`` — the effective Gauss-Newton weight of a robust loss."""
    if loss == "linear":
        return np.ones_like(z)
    u = z / delta
    if loss == "huber":
        return 1.0 / np.sqrt(1.0 + u * u)
    return 1.0 / (1.0 + u * u)


def _symbols(kind: str, nt: int, nl: int) -> dict[str, Any]:
    """Vectorised symbolic residuals of a problem shape (data are in the parameter vector)."""
    m = MODELS[kind]
    d = m.dim
    th = ca.MX.sym("theta", m.n_raw)
    t = ca.MX.sym("t", nl)
    sizes = [nt * d, nt, nt, nl * d, nl * d, nl, nl, nl, nl, 1, 1]
    P = ca.MX.sym("p", sum(sizes))
    parts, k = [], 0
    for s_ in sizes:
        parts.append(P[k:k + s_])
        k += s_
    tp, tw, tsw, la, lb, lw, lsw, mask, tfix, side, delta = parts
    ths = [th[i] for i in range(m.n_raw)]
    zs = []
    if nt:
        T = ca.reshape(tp, nt, d)
        cl = side * m.sd(CA_OPS, [T[:, j] for j in range(d)], ths)
        zs.append(tsw * (cl - tw))
    stat = []
    if nl:
        A = ca.reshape(la, nl, d)
        B = ca.reshape(lb, nl, d)
        L = [A[:, j] + t * (B[:, j] - A[:, j]) for j in range(d)]
        cl = side * m.sd(CA_OPS, L, ths)
        zs.append(lsw * (cl - lw))
        dcl = ca.jtimes(cl, t, ca.DM.ones(nl))
        stat.append(mask * dcl + (1.0 - mask) * (t - tfix))
    return {"x": ca.vertcat(th, t), "th": th, "P": P, "z": ca.vertcat(*zs), "stat": stat,
            "eq": m.eq(ths), "ineq": m.ineq(ths), "delta": delta}


#: iterations a start cut off by a short ``max_iter`` may take to finish (see fit_primitive)
_FINISH_ITER = 200


@functools.lru_cache(maxsize=128)
def _problem(kind: str, loss: str, nt: int, nl: int, max_iter: int) -> Any:
    """Build (once) the IPOPT solver for a problem shape and loss."""
    S = _symbols(kind, nt, nl)
    f = ca.sum1(_rho_ca(S["z"], loss, S["delta"]))
    g = ca.vertcat(*S["eq"], *S["ineq"], *S["stat"])
    opts = {
        "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
        "ipopt.max_iter": max_iter, "ipopt.tol": 1e-12, "ipopt.acceptable_tol": 1e-9,
        "ipopt.acceptable_iter": 10, "ipopt.mu_strategy": "adaptive", "expand": True,
    }
    return ca.nlpsol(f"fit_{kind}_{loss}_{nt}_{nl}", "ipopt",
                     {"x": S["x"], "p": S["P"], "f": f, "g": g}, opts)


@functools.lru_cache(maxsize=128)
def _jacobians(kind: str, nt: int, nl: int) -> tuple[Any, Any, int, int]:
    """(x, p) -> (z, dz/dtheta) and theta -> d eq/d theta for a problem shape, plus the
    numbers of equality and inequality constraints."""
    m = MODELS[kind]
    S = _symbols(kind, nt, nl)
    zjac = ca.Function("zjac", [S["x"], S["P"]], [S["z"], ca.jacobian(S["z"], S["th"])]).expand()
    eq = ca.vertcat(*S["eq"]) if S["eq"] else ca.MX(0, 1)
    geq = ca.Function("geq", [S["th"]], [ca.jacobian(eq, S["th"]) if S["eq"]
                                         else ca.MX(0, m.n_raw)]).expand()
    return zjac, geq, len(S["eq"]), len(S["ineq"])


# --------------------------------------------------------------------------- normalised data


@dataclass(frozen=True)
class _Norm:
    """Data in normalised coordinates plus what is needed to go back to metres."""

    mu: np.ndarray
    scale: float
    tip: np.ndarray
    tip_w: np.ndarray
    tip_wt: np.ndarray
    a: np.ndarray
    b: np.ndarray
    link_w: np.ndarray
    link_wt: np.ndarray
    space: FreeSpace
    weight_mean: float = 1.0  # what the weights were divided by to bring them to mean 1

    @functools.cached_property
    def free(self) -> np.ndarray:
        """Every free-space point, normalised (only a choice between two fitted sides reads
        them all; :func:`_local_hints` reads those near the contacts)."""
        return (self.space.points - self.mu) / self.scale


def _normalise(data: FitData) -> _Norm | None:
    nt, nl = data.n_tip, data.n_link
    c = np.vstack([data.tip_points, data.link_a, data.link_b])
    n = len(c)
    # the column sums as a matrix product: numpy's reduction down the long axis of an
    # (N, d) array costs more than the rest of a small fit; the sum of squares by einsum (a
    # BLAS dot of more than ~10^4 numbers starts threads that spin on a loaded machine)
    mu = (np.ones(n) @ c) / n
    c -= mu
    scale = float(np.sqrt(np.einsum("ij,ij->", c, c) / n))
    if not scale > 1e-12 * (1.0 + float(np.abs(mu).max())):
        return None
    c /= scale
    W = np.concatenate([data.tip_weight, data.link_weight])
    wm = float(W.mean())
    return _Norm(
        mu, scale, c[:nt], data.tip_radius / scale, data.tip_weight / wm, c[nt:nt + nl],
        c[nt + nl:], data.link_radius / scale, data.link_weight / wm, data.free, wm,
    )


def _rank(points: np.ndarray) -> int:
    """Rank of the centred point cloud: singular values above ``1e-7`` of the largest, from
    the eigenvalues of the ``d x d`` scatter matrix (their rounding, ``~1e-8`` of the spread
    after the square root, is below the threshold; an SVD of the ``(N, d)`` cloud costs
    more than the rest of a small fit)."""
    n = len(points)
    if n == 0:
        return 0
    c = points - (np.ones(n) @ points) / n
    ev = np.linalg.eigvalsh(c.T @ c)
    s = np.sqrt(np.maximum(ev, 0.0))
    if s.size == 0 or s[-1] <= 0:
        return 0
    return int(np.sum(s > 1e-7 * s[-1]))


# --------------------------------------------------------------------------- numeric residuals


def _ends_min(v0: np.ndarray, v1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smaller of the end values; t = 0.5 where they tie (a link lying along the surface)."""
    tol = 1e-12 * (1.0 + np.maximum(np.abs(v0), np.abs(v1)))
    t = np.where(v1 < v0 - tol, 1.0, np.where(v0 < v1 - tol, 0.0, 0.5))
    return np.minimum(v0, v1), t


def _closed_form_min(m: Model, th: np.ndarray, side: float, a: np.ndarray, b: np.ndarray,
                     values: bool = True) -> tuple[np.ndarray | None, np.ndarray] | None:
    """Exact least clearance along segments for lines, planes, circles, spheres and cylinders
    (None for the other types).  Lines and planes are linear along a segment, and the distance
    to a centre (or an axis) is convex along it: seen from outside the minimum is the
    projection of the centre (axis) onto the segment, seen from inside it is at an end.
    ``values`` False: only ``t`` is wanted (the clearance is None where it was not needed to
    find ``t``)."""
    def clearance(p: np.ndarray) -> np.ndarray:
        return side * signed_distance_np(m, th, p)

    if m.linear:
        v, t = _ends_min(clearance(a), clearance(b))
        return v, t
    if m.kind not in ("circle", "sphere", "cylinder"):
        return None
    d = b - a
    if side < 0:
        v, t = _ends_min(clearance(a), clearance(b))
        return v, t
    dim = m.dim
    q0 = a - np.asarray(th[:dim], dtype=float)
    if m.kind == "cylinder":
        ax = np.asarray(th[3:6], dtype=float)
        da, qa = d @ ax, q0 @ ax
        A = np.einsum("ij,ij->i", d, d) - da * da
        B = np.einsum("ij,ij->i", q0, d) - qa * da
    else:
        A = np.einsum("ij,ij->i", d, d)
        B = np.einsum("ij,ij->i", q0, d)
    t = np.clip(np.where(A > 1e-300, -B / np.maximum(A, 1e-300), 0.5), 0.0, 1.0)
    return (clearance(a + t[:, None] * d) if values else None), t


def _link_t(m: Model, th: np.ndarray, side: float, a: np.ndarray, b: np.ndarray,
            values: bool = True) -> tuple[np.ndarray | None, np.ndarray, bool]:
    """Least clearance along each link and its t: closed form where the type has one (then
    ``True``), else the sampled and bracketed numeric minimum (``False``).  ``values``
    False: only ``t`` is wanted (see :func:`_closed_form_min`)."""
    exact = _closed_form_min(m, th, side, a, b, values)
    if exact is not None:
        return exact[0], exact[1], True
    val, t = segment_min_numeric(lambda p: side * signed_distance_np(m, th, p), a, b)
    return val, t, False


def _link_min(m: Model, th: np.ndarray, side: float, a: np.ndarray, b: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least clearance along each link: value, t and whether t is a smooth interior minimum
    (closed form where the type has one, else sampling + golden section)."""
    if len(a) == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool)

    def fn(p: np.ndarray) -> np.ndarray:
        return side * signed_distance_np(m, th, p)
    val, t, _ = _link_t(m, th, side, a, b)
    if m.linear:
        return val, t, np.zeros(len(a), dtype=bool)
    h = 1e-3
    tl, tr = np.clip(t - h, 0, 1), np.clip(t + h, 0, 1)
    d = b - a
    fl = fn(a + tl[:, None] * d)
    fr = fn(a + tr[:, None] * d)
    L2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-30)
    curv = (fl + fr - 2.0 * val) / (h * h * L2)
    interior = (t > _T_EDGE) & (t < 1 - _T_EDGE) & (curv > _FLAT)
    return val, t, interior


def _residuals_norm(m: Model, th: np.ndarray, side: float, nd: _Norm
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rt = side * signed_distance_np(m, th, nd.tip) - nd.tip_w if len(nd.tip) else np.zeros(0)
    val, t, interior = _link_min(m, th, side, nd.a, nd.b)
    return rt, val - nd.link_w, t, interior


def _rms_norm(m: Model, sol: _Solve, side: float, nd: _Norm) -> float:
    """Dof-corrected RMS residual of a solve (normalised units)."""
    rt, rl, _, _ = _residuals_norm(m, sol.th, side, nd)
    r = np.concatenate([rt, rl])
    return float(np.sqrt(np.sum(r * r) / max(len(r) - m.dof, 1)))


def _cost_norm(m: Model, th: np.ndarray, side: float, nd: _Norm, loss: str, delta: float
               ) -> float:
    rt, rl, _, _ = _residuals_norm(m, th, side, nd)
    z = np.concatenate([np.sqrt(nd.tip_wt) * rt, np.sqrt(nd.link_wt) * rl])
    return float(np.sum(rho_np(z, loss, delta)))


# --------------------------------------------------------------------------- one solve


@dataclass
class _Solve:
    th: np.ndarray
    t: np.ndarray
    mask: np.ndarray
    status: str
    success: bool
    iterations: int
    cost: float


def _pad(x: np.ndarray, n: int) -> np.ndarray:
    if len(x) == n:
        return x
    reps = np.repeat(x[:1], n - len(x), axis=0)
    return np.concatenate([x, reps], axis=0)


def _solve(m: Model, nd: _Norm, th0: np.ndarray, side: float, loss: str, delta: float,
           max_iter: int) -> _Solve:
    nt, nl = len(nd.tip), len(nd.a)
    bt, bl = _bucket(nt), _bucket(nl)
    solver = _problem(m.kind, loss, bt, bl, max_iter)
    _, _, n_eq, n_ineq = _jacobians(m.kind, bt, bl)
    zt = np.zeros(bt - nt)
    zl = np.zeros(bl - nl)
    fixed = [
        _pad(nd.tip, bt).ravel(order="F"), _pad(nd.tip_w, bt),
        np.concatenate([np.sqrt(nd.tip_wt), zt]),
        _pad(nd.a, bl).ravel(order="F"), _pad(nd.b, bl).ravel(order="F"), _pad(nd.link_w, bl),
        np.concatenate([np.sqrt(nd.link_wt), zl]),
    ]
    lbg = np.concatenate([np.zeros(n_eq), np.zeros(n_ineq), np.zeros(bl)])
    ubg = np.concatenate([np.zeros(n_eq), np.full(n_ineq, np.inf), np.zeros(bl)])
    lbx = np.concatenate([m.lbx, np.zeros(bl)])
    ubx = np.concatenate([m.ubx, np.ones(bl)])
    th = np.clip(np.asarray(th0, float), np.array(m.lbx), np.array(m.ubx))
    _, t, interior = _link_min(m, th, side, nd.a, nd.b)
    iters = 0
    status, ok = "not_run", False
    for _ in range(5):
        mask = np.concatenate([interior.astype(float), zl])
        tfix = _pad(t, bl) if nl else np.zeros(bl)
        p = np.concatenate([*fixed, mask, tfix, [side], [delta]])
        x0 = np.concatenate([th, tfix])
        sol = solver(x0=x0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        st = solver.stats()
        iters += int(st.get("iter_count", 0))
        status = str(st.get("return_status", "unknown"))
        ok = status in _SUCCESS
        x = np.asarray(sol["x"]).ravel()
        if not np.all(np.isfinite(x)):
            ok = False
            status = status if not ok else "non_finite"
            break
        th = x[: m.n_raw]
        t_sol = x[m.n_raw: m.n_raw + nl]
        _, t_new, int_new = _link_min(m, th, side, nd.a, nd.b)
        if not ok or nl == 0:
            t = t_sol
            break
        moved = np.abs(t_new - t_sol) > 1e-5
        if np.array_equal(int_new, interior) and not np.any(moved):
            t = t_sol
            break
        t, interior = t_new, int_new
    cost = _cost_norm(m, th, side, nd, loss, delta)
    return _Solve(th, t, interior, status, ok, iters, cost)


def _solve_robust(m: Model, nd: _Norm, sol: _Solve, side: float, loss: str, delta: float,
                  max_iter: int, rounds: int = 12) -> _Solve:
    """Robust fit by iteratively reweighted least squares from a converged linear fit.

    Each round solves the weighted least-squares NLP with weights ``W_i rho'(z_i) / z_i``
    (:func:`_irls_weight`), which is well scaled whatever ``delta``; a direct IPOPT solve of a
    pseudo-Huber objective with ``delta`` at the noise level (micrometres on simulated data) is
    nearly an L1 problem with a tiny objective and stalls at the iteration limit.  The fixed
    point is a stationary point of the robust objective.  Stops when the parameters move less
    than ``1e-9`` (normalised units); keeps the last converged round.
    """
    cur = sol
    iters = sol.iterations
    for _ in range(rounds):
        rt, rl, _, _ = _residuals_norm(m, cur.th, side, nd)
        zt = np.sqrt(nd.tip_wt) * rt
        zl = np.sqrt(nd.link_wt) * rl
        wt = _irls_weight(zt, loss, delta)
        wl = _irls_weight(zl, loss, delta)
        nd_w = dataclasses.replace(nd, tip_wt=nd.tip_wt * wt, link_wt=nd.link_wt * wl)
        nxt = _solve(m, nd_w, cur.th, side, "linear", 1.0, max_iter)
        iters += nxt.iterations
        if not nxt.success:
            break
        step = float(np.max(np.abs(nxt.th - cur.th)))
        cur = nxt
        if step < 1e-9:
            break
    return _Solve(cur.th, cur.t, cur.mask, cur.status, cur.success, iters,
                  _cost_norm(m, cur.th, side, nd, loss, delta))


def _solve_fast(m: Model, nd: _Norm, th0: np.ndarray, side: float, loss: str, delta: float,
                max_iter: int, precision: float = 0.0) -> _Solve:
    """Levenberg-Marquardt (:mod:`wholearm_tools.fit.solve`, to ``precision``); IPOPT only
    for a solution on a bound or inequality constraint (IPOPT handles the active set)."""
    from wholearm_tools.fit import solve as lm

    res = lm.solve(m, nd, th0, side, loss, delta, max_iter, _link_t, rho_np, _irls_weight,
                   precision)
    finite = bool(np.all(np.isfinite(res.th)))
    if finite and not lm.on_bound(m, res.th):
        interior = (res.t > _T_EDGE) & (res.t < 1 - _T_EDGE)
        status = "Solve_Succeeded" if res.converged else "Maximum_Iterations_Exceeded"
        return _Solve(res.th, res.t, interior, status, res.converged, res.iterations, res.cost)
    sol = _solve(m, nd, res.th if finite else th0, side, "linear", 1.0, max_iter)
    if sol.success and loss != "linear":
        sol = _solve_robust(m, nd, sol, side, loss, delta, max_iter)
    sol.iterations += res.iterations
    return sol


# --------------------------------------------------------------------------- covariance


def _covariance_norm(m: Model, nd: _Norm, sol: _Solve, side: float, loss: str, delta: float,
                     outliers: np.ndarray | None = None, noise: float | None = None
                     ) -> tuple[np.ndarray, float, bool]:
    """Covariance of the raw parameters (normalised units; NaN when not determined), the
    sensitivity (see :attr:`FitResult.sensitivity`, normalised units: divide by the scale)
    and whether the residual variance is ``noise``'s rather than the fit's own.  Contacts
    flagged in ``outliers`` (read as outliers by a robust fit) do not count.  ``noise`` [m],
    when given, is a floor under the residual variance (see :func:`with_noise_floor`)."""
    from wholearm_tools.fit.solve import sd_and_jacobian, tangent_basis

    nt, nl = len(nd.tip), len(nd.a)
    n = nt + nl
    pts = np.vstack([nd.tip, nd.a + sol.t[:, None] * (nd.b - nd.a)]) if nl else nd.tip
    sd, J = sd_and_jacobian(m.kind, sol.th, pts)
    sw = np.sqrt(np.concatenate([nd.tip_wt, nd.link_wt]))
    z = sw * (side * sd - np.concatenate([nd.tip_w, nd.link_w]))
    J = (side * sw)[:, None] * J
    # Gauss-Newton on the minimal parameterisation.  The latent t drop out of the Jacobian: at a
    # stationary t the clearance does not change to first order with t (envelope theorem); at a
    # fixed end point t does not move.
    Bn = tangent_basis(m.kind, sol.th)
    Jm = J @ Bn
    # identifiability: the weakest parameter combination under unit residual noise (no robust
    # down-weighting: a contact the loss discounts still constrains the geometry it touches)
    lam = np.linalg.eigvalsh(Jm.T @ Jm) if Jm.size else np.zeros(1)
    lam_min = float(lam[0]) if lam.size else 0.0
    sens = 1.0 / math.sqrt(lam_min) if lam_min > 0 else math.inf
    nan = np.full((m.n_raw, m.n_raw), np.nan)
    w_rob = _irls_weight(z, loss, delta)
    if outliers is not None:
        w_rob = np.where(outliers, 0.0, w_rob)
        n -= int(np.count_nonzero(outliers))
    if n <= m.dof:
        return nan, sens, False
    H = Jm.T @ (w_rob[:, None] * Jm)
    s2 = float(np.sum(w_rob * z * z) / (n - m.dof))
    # contacts each off by ``noise`` when their reading is the right one (a weight is the
    # probability that it is), in normalised units with the weights brought to mean 1
    floor = (noise / nd.scale) ** 2 / nd.weight_mean if noise is not None else 0.0
    known = floor > s2
    s2 = max(s2, floor)
    try:
        cond = np.linalg.cond(H)
        if not np.isfinite(cond) or cond > 1e14:
            raise np.linalg.LinAlgError
        Hi = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        return nan, sens, False
    return s2 * Bn @ Hi @ Bn.T, sens, known


_Z975 = 1.959963984540054   # two-sided 95 % quantile of the normal


@functools.lru_cache(maxsize=4096)
def _t975(dof: int) -> float:
    """Two-sided 95 % quantile of Student's t with ``dof`` degrees of freedom (the inverse
    of its CDF from scipy.special, which scipy.stats.t.ppf calls: importing scipy.stats
    costs 0.4 s, more than most fits)."""
    from scipy.special import stdtrit

    return float(stdtrit(dof, 0.975))


def _param_map_jacobian(m: Model, th: np.ndarray) -> np.ndarray:
    """d (flattened map params) / d raw, by central differences (normalised units)."""
    def flat(x: np.ndarray) -> np.ndarray:
        return np.concatenate([np.atleast_1d(v) for v in m.to_params(x).values()])
    base = flat(th)
    J = np.zeros((len(base), m.n_raw))
    for i in range(m.n_raw):
        h = 1e-6 * max(1.0, abs(th[i]))
        e = np.zeros(m.n_raw)
        e[i] = h
        J[:, i] = (flat(th + e) - flat(th - e)) / (2 * h)
    return J


def _denormalise(m: Model, params: dict[str, Any], nd: _Norm) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for spec in m.params:
        v = params[spec.name]
        if spec.role == "point":
            out[spec.name] = nd.mu + nd.scale * np.asarray(v, float)
        elif spec.role == "length":
            out[spec.name] = float(v) * nd.scale
        elif spec.role == "direction":
            out[spec.name] = np.asarray(v, float) / np.linalg.norm(v)
        else:
            out[spec.name] = float(v)
    return out


def _labels(m: Model) -> tuple[tuple[str, ...], np.ndarray]:
    labels, scales = [], []
    for spec in m.params:
        s = 1.0 if spec.role in ("direction", "angle") else -1.0
        if spec.size == 1:
            labels.append(spec.name)
            scales.append(s)
        else:
            for i in range(spec.size):
                labels.append(f"{spec.name}[{i}]")
                scales.append(s)
    return tuple(labels), np.array(scales)


# --------------------------------------------------------------------------- free side


def _votes(m: Model, th: np.ndarray, pts: np.ndarray, tol: float) -> tuple[int, int]:
    """(number of points outside, number inside) by more than ``tol`` (normalised)."""
    if len(pts) == 0:
        return 0, 0
    sd = signed_distance_np(m, th, pts)
    return int(np.sum(sd > tol)), int(np.sum(sd < -tol))


def _decide_side(m: Model, nd: _Norm, local: np.ndarray, quick: bool = False
                 ) -> tuple[list[float], list[np.ndarray] | None]:
    """Free-side candidates.  A single side when the free-space hints right behind the contacts
    (:func:`_local_hints`: robot positions and link axes, which are in free space) all lie
    clearly on one side of the initial guess; otherwise both, and :func:`_pick_side` decides
    on the fitted surfaces.  Far hints are not trusted against a guess: an algebraic guess
    from a patch is good near the patch only, and a hint far from it can lie on either side.
    Also the initial guesses made for side +1 on the way (None when none were made), for the
    fit to reuse.  ``local``: :func:`_local_hints` of ``nd``."""
    no_radius = not np.any(nd.tip_w) and not np.any(nd.link_w) and len(nd.a) == 0
    if no_radius and len(nd.space) == 0:
        return [1.0], None  # sharp tip, no links, no hints: the side does not change the fit
    ctx = InitContext(nd.tip, nd.tip_w, nd.a, nd.b, nd.link_w, 1.0)
    init = m.quick_init if quick and m.quick_init else m.init
    cands = init(ctx)
    finite = [c for c in cands if np.all(np.isfinite(c))]
    if not finite:
        return [1.0, -1.0], cands
    if len(local):
        th = min(finite, key=lambda c: _cost_norm(m, c, 1.0, nd, "linear", 1.0))
        out, inn = _votes(m, th, local, 0.05)
        if out + inn == len(local) and (out == 0 or inn == 0):
            return [1.0 if out else -1.0], cands
    return [1.0, -1.0], cands


def _near_radius(tip_w: np.ndarray, link_w: np.ndarray, default: float) -> float:
    w = max(float(np.max(tip_w, initial=0.0)), float(np.max(link_w, initial=0.0)))
    return 3.0 * w if w > 0 else default


def _local_hints(nd: _Norm) -> np.ndarray:
    """Free-space hints (free points, link axes) within three contact radii of the support's
    contact points: the robot right behind the contacts.  Far hints say little about a closed
    primitive's side: the infinite extension of a correct bore crosses the robot's other poses
    next to a junction."""
    sup = np.vstack([nd.tip, nd.a, nd.b])
    if len(sup) == 0:
        return sup
    r = _near_radius(nd.tip_w, nd.link_w, 0.25)
    free = nd.space.points[nd.space.near(sup * nd.scale + nd.mu, r * nd.scale)]
    # the link axes' ends are support points themselves
    return np.vstack([(free - nd.mu) / nd.scale, nd.a, nd.b])


def _pick_side(m: Model, nd: _Norm, fits: dict[float, _Solve], local: np.ndarray) -> float:
    """Choose between the fits made with either free side: converged first, then the fewer
    free-space hints (free points, link axes) on the wrong side of the fitted surface, then the
    lower cost, then the side of the base-frame origin (where the robot stands), then +1.
    ``local``: :func:`_local_hints` of ``nd``."""
    hints = np.vstack([nd.free, nd.a, nd.b])
    origin = (-nd.mu / nd.scale)[None, :]

    def key(side: float) -> tuple[float, ...]:
        f = fits[side]
        out, inn = _votes(m, f.th, local, 0.01)
        wrong_local = inn if side > 0 else out
        out, inn = _votes(m, f.th, hints, 0.01)
        wrong = inn if side > 0 else out
        o_out, o_in = _votes(m, f.th, origin, 0.05)
        o_wrong = float(o_in if side > 0 else o_out)
        return (0.0 if f.success else 1.0, 0.0, float(wrong_local), float(wrong), 0.0, o_wrong,
                -side)

    costs = {sd: fits[sd].cost for sd in fits}
    k = {sd: list(key(sd)) for sd in fits}
    lo = min(costs.values())
    for sd in fits:
        # a side that fits many times worse loses whatever the hints say: the global hints
        # are the whole run's poses, and next to another surface (a junction of two bores)
        # the infinite extension of a correct primitive has the robot on its "wrong" side
        k[sd][1] = 0.0 if costs[sd] <= 10.0 * lo + 1e-14 else 1.0
        # otherwise cost only counts when clearly different
        k[sd][4] = 0.0 if costs[sd] <= 1.5 * lo + 1e-14 else 1.0
    return min(fits, key=lambda sd: tuple(k[sd]))


# --------------------------------------------------------------------------- public API


def fit_primitive(
    kind: str,
    data: FitData,
    *,
    free_side: float | None = None,
    loss: str = "linear",
    loss_scale: float = 2.0,
    noise: float | None = None,
    initial: dict[str, Any] | None = None,
    max_iter: int = 200,
    good_rms: float | None = None,
    covariance: bool = True,
    quick: bool = False,
    precision: float | None = None,
) -> FitResult:
    """Fit one primitive of type ``kind`` to tip and link contacts (eq. 3).

    Parameters
    ----------
    kind : str
        ``"line"``, ``"circle"`` (2-D data) or ``"plane"``, ``"sphere"``, ``"cylinder"``,
        ``"cone"``, ``"torus"`` (3-D data).
    data : FitData
    free_side : +1, -1 or None
        Which side of a closed surface is free space (+1 outside, -1 inside).  None decides
        from ``data.free_points`` and the link axes (which are in free space) against the
        initial guess, or, when they are not conclusive, fits both sides and keeps the one
        with fewer hints on the wrong side, then lower cost, then the side of the base-frame
        origin.  Ignored for lines and planes, whose fitted normal points to free space (an
        ``initial`` line or plane is taken with its normal towards free space).
    loss : "linear", "huber" or "cauchy"
        Robust losses are smooth: pseudo-Huber ``d^2 (sqrt(1 + (z/d)^2) - 1)`` and Cauchy
        ``d^2/2 log(1 + (z/d)^2)`` on weighted residuals ``z = sqrt(W) r``.  With no
        ``initial``, a robust fit starts from a consensus of minimal contact sets and reads
        the contacts beyond 2.5 noise levels of it as outliers, which then count at that
        fixed cost instead of pulling (:func:`wholearm_tools.fit.robust.robust_fit`).
    loss_scale : float
        ``d`` in units of ``noise``.
    noise : float or None
        Residual noise level sigma in metres (used by robust losses); None estimates it: with
        ``initial``, from a linear fit (1.4826 x median absolute weighted residual); without,
        on the consensus inliers.
    initial : dict or None
        Initial map.json parameters; default algebraic guesses (several starts for
        cylinders, cones and tori), or the consensus start for a robust loss.
    max_iter : int
        Iteration limit per solve (Levenberg-Marquardt, and IPOPT where it takes over).
    good_rms : float or None
        An RMS residual [m] (dof-corrected) the caller would accept.  With a short
        ``max_iter``, when no converged start reaches it, the lowest-cost start the limit cut
        off is let finish (up to 200 iterations): a wrong basin converges fast, the right one
        may not (seven link contacts on a post).  None: starts are not finished.
    covariance : bool
        Compute the parameter covariance, the 95 % intervals and the sensitivity (the
        Gauss-Newton information at the optimum).  False skips them for fits whose
        uncertainty nobody reads (proposals that do not reach selection): ``covariance`` is
        then None, ``ci95`` empty and ``sensitivity`` NaN.
    quick : bool
        One start from the type's quick algebraic guess (for a cylinder the coarse axis scan)
        instead of the several careful starts: for the many minimal-set fits of a consensus
        search, whose hypotheses are only tested for inliers.
    precision : float or None
        The residual precision [m] the caller needs: the solver also stops once a step would
        move the (weighted) residual vector by less than this.  None: to working precision.

    Returns
    -------
    FitResult
        Falsy (with ``message``) for too few contacts, degenerate data or no convergence.

    Raises
    ------
    InputError
        Unknown ``kind``, data of the wrong dimension, invalid options.
    """
    if kind not in MODELS:
        raise InputError(f"unknown primitive type {kind!r} (known: {', '.join(sorted(MODELS))})")
    if not isinstance(data, FitData):
        raise InputError(f"data must be a FitData, got {type(data).__name__}")
    m = MODELS[kind]
    if data.dim != m.dim:
        raise InputError(f"a {kind} needs {m.dim}-D data, got {data.dim}-D points")
    if loss not in LOSSES:
        raise InputError(f"loss must be one of {LOSSES}, got {loss!r}")
    if free_side is not None and free_side not in (1, -1):
        raise InputError(f"free_side must be +1, -1 or None, got {free_side!r}")
    if not (loss_scale > 0 and math.isfinite(loss_scale)):
        raise InputError(f"loss_scale must be positive, got {loss_scale!r}")
    if noise is not None and not (noise > 0 and math.isfinite(noise)):
        raise InputError(f"noise must be positive, got {noise!r}")
    if int(max_iter) < 1:
        raise InputError(f"max_iter must be >= 1, got {max_iter!r}")
    if precision is not None and not (precision >= 0 and math.isfinite(precision)):
        raise InputError(f"precision must be a non-negative length, got {precision!r}")

    labels, _ = _labels(m)
    n = data.n_contacts

    def fail(status: str, msg: str) -> FitResult:
        return FitResult(kind=kind, success=False, message=msg, status=status,
                         param_labels=labels, tip_residuals=np.full(data.n_tip, np.nan),
                         link_residuals=np.full(data.n_link, np.nan),
                         link_t=np.full(data.n_link, np.nan))

    if n < m.dof:
        return fail("too_few_contacts",
                    f"too few contacts for a {kind}: {n} given, at least {m.dof} needed")
    nd = _normalise(data)
    if nd is None:
        return fail("degenerate", "degenerate data: all contact points coincide")
    rank = _rank(np.vstack([nd.tip, nd.a, nd.b]))
    if rank < m.min_rank:
        shape = {0: "coincide", 1: "are collinear", 2: "are coplanar"}[rank]
        return fail("degenerate",
                    f"degenerate data for a {kind}: all contact points {shape}")

    # lines and planes: the free side is the side the fitted normal points to
    guesses_plus = None  # the type's initial guesses for side +1, once made
    local = None         # the free-space hints right behind the contacts, once found
    if m.linear and initial is not None:
        sides = [1.0]  # the initial normal points to free space
    elif free_side is not None and not m.linear:
        sides = [float(free_side)]
    else:
        local = _local_hints(nd)
        sides, guesses_plus = _decide_side(m, nd, local, quick)
    fits: dict[float, _Solve] = {}
    deltas: dict[float, float] = {}
    outliers: dict[float, np.ndarray] = {}
    for side in sides:
        if loss != "linear" and initial is None:
            # no start: a consensus of minimal sets gives the inliers, their least-squares
            # fit starts the robust loss, their noise sets its scale (fit.robust)
            from wholearm_tools.fit.robust import robust_fit

            # (a fixed stream: the fit is a function of its data)
            rf = robust_fit(m, nd, side, loss, loss_scale, noise / nd.scale if noise else None,
                            np.random.default_rng(0), max_iter)
            if rf is not None:
                t = _link_t(m, rf.th, side, nd.a, nd.b)[1] if len(nd.a) else np.zeros(0)
                fits[side] = _Solve(rf.th, t, (t > _T_EDGE) & (t < 1 - _T_EDGE), rf.status,
                                    rf.success, rf.iterations, rf.cost)
                deltas[side] = rf.delta
                outliers[side] = ~rf.inliers
                continue
        ctx = InitContext(nd.tip, nd.tip_w, nd.a, nd.b, nd.link_w, side)
        if initial is not None:
            cands = [_raw_from_params(m, initial, nd)]
        else:
            cands = (guesses_plus if side > 0 and guesses_plus is not None else
                     m.quick_init(ctx) if quick and m.quick_init else m.init(ctx))
            cands = cands[:1] if quick else cands
        cands = [c for c in cands if np.all(np.isfinite(c))]
        scored = (cands if len(cands) < 2 else
                  sorted(cands, key=lambda c, s=side: _cost_norm(m, c, s, nd, "linear", 1.0)))
        def consider(sol: _Solve, side: float = side) -> None:
            delta = loss_scale * (noise / nd.scale if noise else 1.0)
            if loss != "linear" and sol.success:
                if noise is None:
                    rt, rl, _, _ = _residuals_norm(m, sol.th, side, nd)
                    z = np.concatenate([np.sqrt(nd.tip_wt) * rt, np.sqrt(nd.link_wt) * rl])
                    delta = loss_scale * max(1.4826 * float(np.median(np.abs(z))), 1e-9)
                sol = _solve_fast(m, nd, sol.th, side, loss, delta, max_iter)
            best = fits.get(side)
            if best is None or (not sol.success, sol.cost) < (not best.success, best.cost):
                fits[side] = sol
                deltas[side] = delta

        prec = (precision or 0.0) / nd.scale
        sols = [_solve_fast(m, nd, th0, side, "linear", 1.0, max_iter, prec)
                for th0 in scored[: max(1, m.starts)]]
        cut = sorted((i for i, s_ in enumerate(sols)
                      if s_.status == "Maximum_Iterations_Exceeded"), key=lambda i: sols[i].cost)
        if (cut and good_rms is not None and max_iter < _FINISH_ITER
                and not any(s_.success and _rms_norm(m, s_, side, nd) * nd.scale <= good_rms
                            for s_ in sols)):
            sols[cut[0]] = _solve_fast(m, nd, sols[cut[0]].th, side, "linear", 1.0,
                                       _FINISH_ITER)
        for sol in sols:
            consider(sol)
    if not fits:
        return fail("not_run", f"no initial guess could be formed for a {kind} from these data")
    side = (next(iter(fits)) if len(fits) == 1 else
            _pick_side(m, nd, fits, _local_hints(nd) if local is None else local))
    return _make_result(m, data, nd, fits[side], side, loss, deltas[side], labels,
                        covariance=covariance, outliers=outliers.get(side),
                        ambiguous=len(fits) > 1 and abs(fits[1.0].cost - fits[-1.0].cost)
                        <= 1e-12 + 1e-6 * max(fits[1.0].cost, fits[-1.0].cost)
                        and len(nd.space) + len(nd.a) == 0)


def _raw_from_params(m: Model, params: dict[str, Any], nd: _Norm) -> np.ndarray:
    """Raw normalised vector from map.json parameters (used for user initial guesses)."""
    def pt(name: str) -> np.ndarray:
        return (np.asarray(params[name], float) - nd.mu) / nd.scale

    def ln(name: str) -> float:
        return float(params[name]) / nd.scale

    def un(name: str) -> np.ndarray:
        v = np.asarray(params[name], float)
        return v / np.linalg.norm(v)
    try:
        if m.kind in ("line", "plane"):
            nrm = un("normal") if m.kind == "plane" else (lambda d: np.array([-d[1], d[0]]))(
                un("direction"))
            return np.concatenate([nrm, [pt("point") @ nrm]])
        if m.kind in ("circle", "sphere"):
            return np.concatenate([pt("center"), [ln("radius")]])
        if m.kind == "cylinder":
            a = un("axis")
            p = pt("point")
            return np.concatenate([p - (p @ a) * a, a, [ln("radius")]])
        if m.kind == "cone":
            return np.concatenate([pt("apex"), un("axis"), [float(params["half_angle"])]])
        return np.concatenate([pt("center"), un("axis"), [ln("major_radius"),
                                                          ln("minor_radius")]])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"initial parameters for a {m.kind} are invalid: {exc}") from None


def _intervals(m: Model, th: np.ndarray, cov_raw: np.ndarray, scale: float,
               params: dict[str, Any], n: int, known: bool = False
               ) -> tuple[np.ndarray, dict[str, tuple[Any, Any]]]:
    """Covariance of the map.json parameters (metres) from that of the raw normalised ones,
    and the 95 % intervals about ``params``: Student's t on ``n - dof`` for a residual
    variance the fit estimated, the normal quantile for a ``known`` (stated) one."""
    Mj = _param_map_jacobian(m, th)
    _, roles = _labels(m)
    D = np.where(roles < 0, scale, 1.0)
    cov = (D[:, None] * (Mj @ cov_raw @ Mj.T)) * D[None, :]
    q = _Z975 if known else _t975(n - m.dof) if n > m.dof else np.nan
    sd = np.sqrt(np.clip(np.diag(cov), 0, None)) * q
    ci95: dict[str, tuple[Any, Any]] = {}
    k = 0
    for spec in m.params:
        v = params[spec.name]
        if spec.size == 1:
            ci95[spec.name] = (float(v - sd[k]), float(v + sd[k]))
        else:
            ci95[spec.name] = (v - sd[k:k + spec.size], v + sd[k:k + spec.size])
        k += spec.size
    return cov, ci95


def _make_result(m: Model, data: FitData, nd: _Norm, sol: _Solve, side: float, loss: str,
                 delta: float, labels: tuple[str, ...], ambiguous: bool,
                 covariance: bool = True, outliers: np.ndarray | None = None) -> FitResult:
    th = sol.th.copy()
    if m.linear and side < 0:  # report lines and planes with the normal towards free space
        th[: m.dim] *= -1.0
        th[m.dim] *= -1.0
        side = 1.0
    rt, rl, t, _ = _residuals_norm(m, th, side, nd)
    rt_m, rl_m = rt * nd.scale, rl * nd.scale
    params = _denormalise(m, m.to_params(th), nd)
    # covariance (normalised raw) -> map params -> metres
    if not covariance:
        cov_raw, sens, known = None, math.nan, False
    elif sol.success:
        cov_raw, sens, known = _covariance_norm(m, nd, sol, side, loss, delta, outliers)
    else:
        cov_raw, sens, known = None, math.inf, False
    cov = ci = None
    if cov_raw is not None:
        n = data.n_contacts - (0 if outliers is None else int(np.count_nonzero(outliers)))
        cov, ci = _intervals(m, th, cov_raw, nd.scale, params, n, known)
    W = np.concatenate([data.tip_weight, data.link_weight])
    W = W / W.mean()
    r_all = np.concatenate([rt_m, rl_m])
    cost = float(np.sum(rho_np(np.sqrt(W) * r_all, loss, delta * nd.scale)))
    rms = float(np.sqrt(np.mean(r_all ** 2))) if r_all.size else float("nan")
    prim, note = None, ""
    if sol.success:
        try:
            from wholearm_tools.geometry import primitive_type

            prim = primitive_type(m.kind).from_params(params)
        except Exception as exc:  # geometry rejects the parameters (e.g. a spindle torus)
            note = f"; geometry object not built: {exc}"
    msg = ("converged" if sol.success else
           f"solver did not converge ({sol.status} after {sol.iterations} iterations)")
    if sol.status == "Maximum_Iterations_Exceeded":
        msg = f"maximum number of iterations reached ({sol.iterations})"
    if ambiguous and sol.success:
        msg += ("; free side not determined by the data (no free-space hints): assumed the "
                "base-frame origin is in free space")
    if outliers is not None and np.any(outliers):
        msg += (f"; {int(np.count_nonzero(outliers))} of {len(outliers)} contacts read as "
                "outliers of the consensus")
    return FitResult(
        kind=m.kind, success=sol.success, message=msg + note, status=sol.status,
        iterations=sol.iterations, cost=cost, params=params, free_side=float(side),
        covariance=cov, param_labels=labels, ci95=ci or {}, tip_residuals=rt_m,
        link_residuals=rl_m, link_t=t, rms_residual=rms, primitive=prim,
        sensitivity=sens / nd.scale, scale=nd.scale,
    )


def with_noise_floor(fit: FitResult, data: FitData, noise: float) -> FitResult:
    """``fit`` (of ``data``) with its covariance and 95 % intervals taken at a residual
    variance of at least ``noise`` [m] squared: the position error of a contact that a stated
    error model gives (the arm's kinematic errors), where the fit's own residuals say less.

    A fit's own residuals see only the scatter of its contacts about it: not the errors they
    share (a joint offset, a link-length error, the compliance of the contact, which shift
    contacts alike), and, from the ``n - dof`` residuals of a few contacts that a family of
    primitives fits nearly exactly, hardly the scatter.  The intervals would state a precision
    the arm cannot give.  They use the larger of the two variances, with the normal quantile
    where ``noise``'s is used (it is stated, not estimated from these residuals).  The
    parameters are unchanged; a robust fit's covariance, where the floor applies (its
    residuals are then all small), is recomputed with every contact at full weight."""
    if fit.covariance is None or not fit.success or not fit.params:
        return fit
    m = MODELS[fit.kind]
    n = data.n_contacts
    nd = _normalise(data)
    if nd is None or n <= m.dof:
        return fit
    th = _raw_from_params(m, fit.params, nd)
    t = _link_t(m, th, fit.free_side, nd.a, nd.b, values=False)[1] if len(nd.a) else np.zeros(0)
    sol = _Solve(th, t, np.ones(len(t), bool), fit.status, True, fit.iterations, fit.cost)
    cov_raw, _, known = _covariance_norm(m, nd, sol, fit.free_side, "linear", 1.0, noise=noise)
    if not known:    # the fit's own residuals say more than the floor: keep its covariance
        return fit
    cov, ci95 = _intervals(m, th, cov_raw, nd.scale, fit.params, n, known)
    return dataclasses.replace(fit, covariance=cov, ci95=ci95)


def other_side(fit: FitResult) -> FitResult:
    """``fit`` as a start on the other side of its contacts' spheres: a line's or plane's
    normal (the side it points to is free space) reversed, a curved primitive's free side
    flipped (the bore around a post of the same axis, the cavity around a ball)."""
    m = MODELS[fit.kind]
    if m.linear:
        key = "normal" if "normal" in fit.params else "direction"
        return dataclasses.replace(fit, params={**fit.params,
                                                key: -np.asarray(fit.params[key], float)})
    return dataclasses.replace(fit, free_side=-fit.free_side)


def residuals(kind: str, params: dict[str, Any], data: FitData, free_side: float
              ) -> np.ndarray:
    """Residuals ``clearance - w`` (tips then links, metres) of ``data`` under a primitive given
    by its map.json parameters — the quantity the fit minimises."""
    return residuals_and_touch(kind, params, data, free_side)[0]


def residuals_and_touch(kind: str, params: dict[str, Any], data: FitData, free_side: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`residuals`, and where along each link (``t`` in [0, 1], ``(Nl,)``) it touches."""
    m = MODELS[kind]
    nd = _Norm(np.zeros(m.dim), 1.0, data.tip_points, data.tip_radius, data.tip_weight,
               data.link_a, data.link_b, data.link_radius, data.link_weight, data.free)
    th = _raw_from_params(m, params, nd)
    rt, rl, t, _ = _residuals_norm(m, th, float(free_side), nd)
    return np.concatenate([rt, rl]), t


def cost(kind: str, params: dict[str, Any], data: FitData, free_side: float,
         loss: str = "linear", delta: float = 1.0) -> float:
    """Objective value of a primitive on ``data`` (same definition as :attr:`FitResult.cost`)."""
    r = residuals(kind, params, data, free_side)
    W = np.concatenate([data.tip_weight, data.link_weight])
    W = W / W.mean()
    return float(np.sum(rho_np(np.sqrt(W) * r, loss, delta)))


def consensus(kind: str, data: FitData, anchor: int, tol: float, rng: np.random.Generator,
              trials: int = 24) -> np.ndarray:
    """Largest set of contacts of ``data`` within ``tol`` metres of a primitive guessed
    algebraically (the type's initial guesses, either free side) from ``dof + 1`` contacts that
    include ``anchor``; contact indices, sorted (RANSAC, no solver: cheap).

    Used for seeds whose neighbourhood mixes surfaces (next to the intersection of two bores)
    or contacts whose classification is wrong: a least-squares seed is then pulled by the
    outliers and trimming its worst residual removes good contacts.
    """
    m = MODELS[kind]
    n = data.n_contacts
    nd = _normalise(data)
    if nd is None or n <= m.dof:
        return np.zeros(0, dtype=int)
    nt = data.n_tip
    others = np.delete(np.arange(n), anchor)
    best = np.zeros(0, dtype=int)
    best_key = (0, -np.inf)
    tol_n = tol / nd.scale
    for _ in range(trials):
        sub = np.sort(np.concatenate([[anchor], rng.choice(others, m.dof, replace=False)]))
        ti, li = sub[sub < nt], sub[sub >= nt] - nt
        for side in ([1.0] if m.linear else [1.0, -1.0]):
            ctx = InitContext(nd.tip[ti], nd.tip_w[ti], nd.a[li], nd.b[li], nd.link_w[li], side)
            try:
                guess = m.quick_init(ctx) if m.quick_init else m.init(ctx)[:1]
                cands = [c for c in guess if np.all(np.isfinite(c))]
            except (np.linalg.LinAlgError, ValueError, IndexError):
                continue
            for th in cands:
                rt, rl, _, _ = _residuals_norm(m, th, side, nd)
                r = np.abs(np.concatenate([rt, rl]))
                inl = np.flatnonzero(r <= tol_n)
                if anchor not in inl:
                    continue
                key = (len(inl), -float(np.sum(np.minimum(r, tol_n) ** 2)))
                if key > best_key:
                    best, best_key = inl, key
        if len(best) == n:  # every contact agrees: no trial can do better
            break
    return best
