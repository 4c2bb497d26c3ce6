"""Levenberg-Marquardt on a minimal parameterisation: the fast path of every primitive fit.

The problem is eq. (3) of the paper in normalised coordinates (see :mod:`wholearm_tools.fit.core`):
tip residuals ``s sd(P_i) - w_i`` and link residuals ``min_t s sd(a_j + t (b_j - a_j)) - w_j``.
The latent contact position ``t_j`` along a link is eliminated (variable projection): at the
current parameters it is the exact least-clearance point, and by the envelope theorem the link
residual's derivative with respect to the parameters is the signed distance's derivative at
that point.  So the solver only sees the primitive's own parameters.  Where the type has a
closed-form least clearance (lines, planes, circles, spheres, cylinders) it is evaluated at
every step; otherwise (cones, tori) each ``t_j`` follows the parameters by safeguarded Newton
steps along its link from where it was, and at convergence a global search along every link
checks that no other point has become the least-clearance one (if one has, the iteration goes
on from there).

Unit vectors and gauge freedoms (a cylinder's axis point) are handled as a manifold: each step
lives in the null space of the equality constraints' Jacobian (the tangent space, of the type's
true dimension ``dof``) and is retracted onto the constraints by minimum-norm Newton projection.
Signed distances and their parameter Jacobians come from the type's formula, differentiated by
CasADi and compiled to vectorised numpy (:mod:`wholearm_tools.fit.codegen`).

Damping follows the gain ratio of each step (actual over predicted decrease, Nielsen's update),
and the iteration stops when the Gauss-Newton model predicts a relative decrease below
:data:`FTOL` (the Newton decrement: no evaluation is spent on a step that cannot help), when a
step moves the parameters by less than :data:`XTOL`, or when the cost reaches the rounding floor
of a zero-residual problem.  A caller that needs the residuals only to a stated precision (the
inference's proposals, to a fraction of the noise level; a consensus hypothesis, to a fraction
of its inlier tolerance) also stops once the Gauss-Newton step would move the weighted residual
vector by less than that precision.

Robust losses (pseudo-Huber, Cauchy) are minimised directly: each Gauss-Newton model is built
with the iteratively-reweighted weights ``rho'(z) / z`` and a step is accepted only when it lowers
the robust objective itself.  When the solution ends on a bound (a radius at its floor, a cone
angle at 0 or 90 degrees, a torus whose tube reaches its axis), the caller falls back to IPOPT,
which handles active inequality constraints properly.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from wholearm_tools.fit.codegen import numpy_function
from wholearm_tools.fit.models import CA_OPS, MODELS, Model

#: relative decrease of the objective that the Gauss-Newton model must still promise
FTOL = 1e-10
#: step size (normalised units, relative to the parameters' size) below which LM stops
XTOL = 1e-12
#: cost per residual (normalised units) below which a problem counts as fitted exactly: the
#: residuals are then at the rounding level of coordinates of order 1
_ZERO_COST = 1e-28
#: first damping (relative to the Gauss-Newton matrix's diagonal): starts are close, and the
#: gain ratio raises it quickly where they are not
_MU_START = 1e-4
#: damping limit: beyond it no step lowers the objective (converged, or stuck)
_MU_MAX = 1e10
#: Newton steps per evaluation that move a link's contact point with the parameters
_T_NEWTON = 6
#: global searches along the links (cones, tori) that may restart the iteration
_T_RESTARTS = 3


@dataclass(frozen=True)
class Kernel:
    """Generated numeric functions of one primitive type.

    ``sd_jac(th, X)``: signed distance of the columns of ``X (d, N)`` and its ``n_raw``
    parameter derivatives (each a float or an ``(N,)`` array); ``sd_line(th, X, D)``: the
    signed distance at ``X`` and its first and second derivatives along the columns of ``D``;
    ``eq_jac(th)``: the equality constraints and their Jacobian's non-zeros (column-major), or
    None; ``ineq(th)``: the inequality constraint values (``>= 0`` is feasible), or None.
    """

    n_raw: int
    n_eq: int
    sd_jac: Any
    sd_line: Any
    eq_jac: Any
    ineq: Any
    lb: np.ndarray
    ub: np.ndarray


def symbolic(kind: str) -> dict[str, ca.Function]:
    """The CasADi functions that :func:`kernel` translates: ``sd_jac``, ``sd_line`` and, where
    the type has them, ``eq`` and ``ineq`` (see :class:`Kernel` for their outputs)."""
    m = MODELS[kind]
    th = ca.SX.sym("theta", m.n_raw)
    x = ca.SX.sym("x", m.dim)
    d = ca.SX.sym("d", m.dim)
    ths = [th[i] for i in range(m.n_raw)]
    sd = m.sd(CA_OPS, [x[j] for j in range(m.dim)], ths)
    out = {"sd_jac": ca.Function(f"{kind}_sd_jac", [th, x],
                                 [sd, ca.densify(ca.jacobian(sd, th))])}
    slope = ca.jtimes(sd, x, d)
    out["sd_line"] = ca.Function(f"{kind}_sd_line", [th, x, d],
                                 [sd, slope, ca.jtimes(slope, x, d)])
    eq = m.eq(ths)
    if eq:
        e = ca.vertcat(*eq)
        out["eq"] = ca.Function(f"{kind}_eq", [th], [e, ca.densify(ca.jacobian(e, th))])
    ineq = m.ineq(ths)
    if ineq:
        out["ineq"] = ca.Function(f"{kind}_ineq", [th], [ca.vertcat(*ineq)])
    return out


@functools.cache
def kernel(kind: str) -> Kernel:
    """The generated functions of primitive type ``kind`` (built once per process)."""
    m = MODELS[kind]
    f = symbolic(kind)
    return Kernel(
        m.n_raw, len(m.eq([0.0] * m.n_raw)),
        numpy_function(f["sd_jac"], {1}, f"{kind}_sd_jac"),
        numpy_function(f["sd_line"], {1, 2}, f"{kind}_sd_line"),
        numpy_function(f["eq"], (), f"{kind}_eq") if "eq" in f else None,
        numpy_function(f["ineq"], (), f"{kind}_ineq") if "ineq" in f else None,
        np.array(m.lbx, dtype=float), np.array(m.ubx, dtype=float))


def sd_and_jacobian(kind: str, th: np.ndarray, points: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance ``(N,)`` of ``points (N, d)`` and its parameter Jacobian ``(N, n_raw)``
    under raw parameters ``th`` (normalised units)."""
    k = kernel(kind)
    n = len(points)
    (sd,), jac = k.sd_jac(np.asarray(th, dtype=float), np.ascontiguousarray(points.T))
    J = np.empty((n, k.n_raw))
    for i, col in enumerate(jac):
        J[:, i] = col
    out = np.empty(n)
    out[:] = sd
    return out, J


def constraints(kind: str, th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Equality constraint values ``(n_eq,)`` and Jacobian ``(n_eq, n_raw)`` at ``th``."""
    k = kernel(kind)
    if k.eq_jac is None:
        return np.zeros(0), np.zeros((0, k.n_raw))
    e, g = k.eq_jac(np.asarray(th, dtype=float))
    return np.array(e, dtype=float), np.array(g, dtype=float).reshape(k.n_raw, k.n_eq).T


def tangent_basis(kind: str, th: np.ndarray) -> np.ndarray:
    """Orthonormal basis ``(n_raw, dof)`` of the constraints' tangent space at ``th``."""
    _, G = constraints(kind, th)
    return null_space(G)


def null_space(G: np.ndarray) -> np.ndarray:
    """Orthonormal basis ``(n, n - rank)`` of the null space of ``G (k, n)``, ``k`` small.

    The trailing columns of the complete QR of ``G^T`` (Householder reflections of the rows one
    by one).  For one constraint, and where a row depends on the previous ones (its remaining
    norm, the diagonal of ``R``, below ``1e-12`` of the largest entry), the reflections are
    written out: one reflection costs less than a LAPACK call, and a dependent row is skipped
    so the basis keeps its dimension.
    """
    k, n = G.shape
    if k == 0:
        return np.eye(n)
    A = np.array(G.T, dtype=float)
    big = float(np.max(np.abs(A), initial=0.0))
    if k > 1:
        Q, R = np.linalg.qr(A, mode="complete")
        if np.all(np.abs(np.diagonal(R)) > 1e-12 * big):
            return Q[:, k:]
    Q = np.eye(n)
    col = 0
    for j in range(k):
        x = A[col:, j]
        nx = float(np.sqrt(x @ x))
        if nx <= 1e-12 * big:
            continue
        v = x.copy()
        v[0] += nx if x[0] >= 0 else -nx
        v /= np.sqrt(v @ v)
        A[col:, :] -= 2.0 * np.outer(v, v @ A[col:, :])
        Q[:, col:] -= 2.0 * np.outer(Q[:, col:] @ v, v)
        col += 1
    return Q[:, col:]


def project(kind: str, th: np.ndarray, iterations: int = 8) -> np.ndarray:
    """``th`` moved onto the equality constraints by minimum-norm Newton steps."""
    th = np.array(th, dtype=float)
    for _ in range(iterations):
        e, G = constraints(kind, th)
        if e.size == 0 or float(np.max(np.abs(e))) <= 1e-14:
            break
        GG = G @ G.T
        if len(e) == 1:
            th -= G[0] * (e[0] / GG[0, 0])
            continue
        if len(e) == 2:  # the 2x2 inverse written out
            det = GG[0, 0] * GG[1, 1] - GG[0, 1] * GG[1, 0]
            if abs(det) > 1e-300:
                y = np.array([GG[1, 1] * e[0] - GG[0, 1] * e[1],
                              GG[0, 0] * e[1] - GG[1, 0] * e[0]]) / det
                th -= G.T @ y
                continue
        try:
            th -= G.T @ np.linalg.solve(GG, e)
        except np.linalg.LinAlgError:
            th -= G.T @ np.linalg.lstsq(GG, e, rcond=None)[0]
    return th


def feasible(m: Model, th: np.ndarray) -> bool:
    """Within the raw bounds and the inequality constraints."""
    k = kernel(m.kind)
    if not ((th >= k.lb).all() and (th <= k.ub).all()):  # (False for NaN too)
        return False
    if k.ineq is None:
        return True
    (vals,) = k.ineq(th)
    return min(vals) >= 0.0


def on_bound(m: Model, th: np.ndarray, rel: float = 1e-6) -> bool:
    """Whether ``th`` sits on (within ``rel`` of) a bound or an inequality constraint."""
    lb, ub = np.asarray(m.lbx), np.asarray(m.ubx)
    span = np.maximum(1.0, np.abs(th))
    near = (np.isfinite(lb) & (th - lb <= rel * span)) | (np.isfinite(ub) & (ub - th <= rel * span))
    if np.any(near):
        return True
    k = kernel(m.kind)
    if k.ineq is None:
        return False
    (vals,) = k.ineq(np.asarray(th, dtype=float))
    return bool(np.any(np.asarray(vals, dtype=float) <= rel))


def follow_links(kind: str, th: np.ndarray, side: float, a: np.ndarray, b: np.ndarray,
                 t: np.ndarray, steps: int = _T_NEWTON) -> tuple[np.ndarray, np.ndarray]:
    """Local least clearance along links ``a (N, d) - b (N, d)`` from the positions ``t (N,)``.

    Safeguarded Newton steps on ``c(t) = side * sd(a + t (b - a))``, each link on its own: the
    Newton step where ``c`` is convex along the link, otherwise a move to the end it slopes
    down to; a step that does not lower ``c`` is halved the next time.  Returns the clearance
    ``(N,)`` and ``t (N,)`` (in ``[0, 1]``).
    """
    k = kernel(kind)
    th = np.asarray(th, dtype=float)
    d = b - a
    dT = np.ascontiguousarray(d.T)
    n = len(t)

    def at(tt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        x = a + tt[:, None] * d
        c, c1, c2 = (np.broadcast_to(side * np.asarray(v[0], dtype=float), (n,))
                     for v in k.sd_line(th, np.ascontiguousarray(x.T), dT))
        return c, c1, c2

    t = np.clip(np.asarray(t, dtype=float), 0.0, 1.0)
    c, c1, c2 = at(t)
    scale = np.ones(n)
    for _ in range(steps):
        newton = np.where(c2 > 0.0, -c1 / np.where(c2 > 0.0, c2, 1.0), -np.sign(c1))
        t_new = np.clip(t + scale * newton, 0.0, 1.0)
        move = np.abs(t_new - t)
        if not np.any(move > 1e-13):
            break
        cn, c1n, c2n = at(t_new)
        ok = cn <= c
        t = np.where(ok, t_new, t)
        c, c1, c2 = np.where(ok, cn, c), np.where(ok, c1n, c1), np.where(ok, c2n, c2)
        scale = np.where(ok, 1.0, 0.5 * scale)
    return c, t


@dataclass
class LMResult:
    th: np.ndarray
    t: np.ndarray        # least-clearance position along each link at the solution
    converged: bool
    iterations: int
    cost: float


def solve(m: Model, nd: Any, th0: np.ndarray, side: float, loss: str, delta: float,
          max_iter: int, link_min: Any, rho: Any, irls_weight: Any, precision: float = 0.0
          ) -> LMResult:
    """Levenberg-Marquardt from ``th0`` on normalised data ``nd`` (``core._Norm``).

    ``link_min(m, th, side, a, b, values=True) -> (value, t, exact)`` gives the global least
    clearance along links (``exact`` when it is a closed form, which is then used at every
    step, for ``t`` only: ``values=False``); ``rho`` and
    ``irls_weight`` the loss and its reweighting (passed in by :mod:`wholearm_tools.fit.core`,
    which owns their definitions).  ``precision`` (normalised units): stop once the
    Gauss-Newton step would move the weighted residual vector by less than this (its norm).
    """
    W = np.concatenate([nd.tip_wt, nd.link_wt])
    sw = np.sqrt(W)
    w_off = np.concatenate([nd.tip_w, nd.link_w])
    n_res = len(W)
    zero_cost = _ZERO_COST * max(n_res, 1)
    d = nd.tip.shape[1]
    ab = nd.b - nd.a
    n_link = len(nd.a)

    th = project(m.kind, np.asarray(th0, dtype=float))
    if not feasible(m, th):
        th = np.clip(th, np.asarray(m.lbx) + 1e-9, np.asarray(m.ubx) - 1e-9)
        th = project(m.kind, th)
    exact = True
    t = np.zeros(0)
    if n_link:
        _, t, exact = link_min(m, th, side, nd.a, nd.b)
        if not exact:
            _, t = follow_links(m.kind, th, side, nd.a, nd.b, t)

    def evaluate(th: np.ndarray, t: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        if n_link:
            if exact:
                _, t, _ = link_min(m, th, side, nd.a, nd.b, False)
            else:
                _, t = follow_links(m.kind, th, side, nd.a, nd.b, t)
            pts = np.vstack([nd.tip, nd.a + t[:, None] * ab])
        else:
            pts = nd.tip
        sd, J = sd_and_jacobian(m.kind, th, pts.reshape(-1, d))
        r = side * sd - w_off
        return r, J, t, float(np.sum(rho(sw * r, loss, delta)))

    r, J, t, cost = evaluate(th, t)
    if not np.isfinite(cost):
        return LMResult(th, t, False, 0, cost)
    mu = _MU_START
    nu = 2.0
    converged = False
    restarts = 0
    steps = 0
    for _ in range(max_iter):
        stop = cost <= zero_cost
        if not stop:
            B = tangent_basis(m.kind, th)
            Jm = J @ B
            wr = W if loss == "linear" else W * irls_weight(sw * r, loss, delta)
            g = side * (Jm.T @ (wr * r))
            H = Jm.T @ (wr[:, None] * Jm)
            if not (np.all(np.isfinite(H)) and np.all(np.isfinite(g))):
                break  # a distance not differentiable here (a point on an axis or apex)
            # Marquardt's scaling: the damped system is (H + mu D) s = -g, D = diag(H); in
            # scaled coordinates one eigen-decomposition serves every damping tried
            dH = np.diag(H)
            D = np.maximum(dH, 1e-12 * max(float(dH.max(initial=0.0)), 1e-300))
            sc = 1.0 / np.sqrt(D)
            lam, V = np.linalg.eigh(sc[:, None] * H * sc[None, :])
            lam = np.maximum(lam, 1e-14 * max(float(lam[-1]), 1e-300))
            y = V.T @ (sc * g)
            # Newton decrement: the decrease the undamped Gauss-Newton model still promises
            # (it is half the squared norm of the step's change of the weighted residuals)
            stop = 0.5 * float(np.sum(y * y / lam)) <= max(FTOL * cost, 0.5 * precision**2)
        if not stop:
            step_taken = False
            while mu <= _MU_MAX:
                z = -y / (lam + mu)
                pred = -float(y @ z) - 0.5 * float(lam @ (z * z))
                th_new = project(m.kind, th + B @ (sc * (V @ z)))
                if feasible(m, th_new):
                    r_new, J_new, t_new, c_new = evaluate(th_new, t)
                    if np.isfinite(c_new) and c_new <= cost:
                        moved = float(np.max(np.abs(th_new - th)))
                        gain = (cost - c_new) / pred if pred > 0 else 0.0
                        th, r, J, t, cost = th_new, r_new, J_new, t_new, c_new
                        mu *= max(1.0 / 3.0, 1.0 - (2.0 * gain - 1.0) ** 3)
                        nu = 2.0
                        steps += 1
                        step_taken = True
                        stop = moved <= XTOL * (1.0 + float(np.max(np.abs(th))))
                        break
                mu *= nu
                nu *= 2.0
            if not step_taken:
                # no step lowers the objective even with the heaviest damping (a gradient
                # step shorter than rounding): a minimum to working precision
                stop = True
        if stop and not exact and restarts < _T_RESTARTS:
            # a followed contact point is a local minimum along its link: make sure no
            # other point of the link has become the least-clearance one
            restarts += 1
            val_g, t_g, _ = link_min(m, th, side, nd.a, nd.b)
            cur = side * sd_and_jacobian(m.kind, th, nd.a + t[:, None] * ab)[0]
            jump = val_g < cur - 1e-12 * (1.0 + np.abs(cur))
            if np.any(jump):
                t = np.where(jump, t_g, t)
                r, J, t, cost = evaluate(th, t)
                mu, nu = _MU_START, 2.0
                stop = False
        if stop:
            converged = True
            break
    return LMResult(th, t, converged, steps, cost)
