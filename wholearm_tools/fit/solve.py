"""Levenberg-Marquardt on a minimal parameterisation: the fast path of every primitive fit.

The problem is eq. (3) of the paper in normalised coordinates (see :mod:`wholearm_tools.fit.core`):
tip residuals ``s sd(P_i) - w_i`` and link residuals ``min_t s sd(a_j + t (b_j - a_j)) - w_j``.
The latent contact position ``t_j`` along a link is eliminated (variable projection): at the
current parameters it is the exact least-clearance point (closed form for lines, planes,
circles, spheres and cylinders, a bracketed numeric minimum for cones and tori), and by the
envelope theorem the link residual's derivative with respect to the parameters is the signed
distance's derivative at that point.  So the solver only sees the primitive's own parameters.

Unit vectors and gauge freedoms (a cylinder's axis point) are handled as a manifold: each step
lives in the null space of the equality constraints' Jacobian (the tangent space, of the type's
true dimension ``dof``) and is retracted onto the constraints by minimum-norm Newton projection.
Signed distances and their parameter Jacobians come from the type's formula, differentiated by
CasADi and compiled to vectorised numpy (:mod:`wholearm_tools.fit.codegen`).

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

#: relative change of the objective (and step size, normalised units) at which LM stops
_TOL = 1e-12
#: damping limits: beyond the upper one no step lowers the objective (converged or stuck)
_LAMBDA_MIN, _LAMBDA_MAX = 1e-12, 1e10


@dataclass(frozen=True)
class Kernel:
    """Generated numeric functions of one primitive type.

    ``sd_jac(th, X)``: signed distance of the columns of ``X (d, N)`` and its ``n_raw``
    parameter derivatives (each a float or an ``(N,)`` array); ``eq_jac(th)``: the equality
    constraints and their Jacobian's non-zeros (column-major), or None; ``ineq(th)``: the
    inequality constraint values (``>= 0`` is feasible), or None.
    """

    n_raw: int
    n_eq: int
    sd_jac: Any
    eq_jac: Any
    ineq: Any
    lb: np.ndarray
    ub: np.ndarray


@functools.cache
def kernel(kind: str) -> Kernel:
    """The generated functions of primitive type ``kind`` (built once per process)."""
    m = MODELS[kind]
    th = ca.SX.sym("theta", m.n_raw)
    x = ca.SX.sym("x", m.dim)
    ths = [th[i] for i in range(m.n_raw)]
    sd = m.sd(CA_OPS, [x[j] for j in range(m.dim)], ths)
    f = ca.Function(f"{kind}_sd_jac", [th, x], [sd, ca.densify(ca.jacobian(sd, th))])
    sd_jac = numpy_function(f, {1}, f"{kind}_sd_jac")
    eq = m.eq(ths)
    eq_jac = None
    if eq:
        e = ca.vertcat(*eq)
        g = ca.Function(f"{kind}_eq", [th], [e, ca.densify(ca.jacobian(e, th))])
        eq_jac = numpy_function(g, (), f"{kind}_eq")
    ineq = m.ineq(ths)
    ineq_fn = None
    if ineq:
        h = ca.Function(f"{kind}_ineq", [th], [ca.vertcat(*ineq)])
        ineq_fn = numpy_function(h, (), f"{kind}_ineq")
    return Kernel(m.n_raw, len(eq), sd_jac, eq_jac, ineq_fn, np.array(m.lbx, dtype=float),
                  np.array(m.ubx, dtype=float))


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
    return np.broadcast_to(sd, (n,)).astype(float, copy=False), J


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
    if G.shape[0] == 0:
        return np.eye(G.shape[1])
    _, s, vt = np.linalg.svd(G)
    rank = int(np.sum(s > 1e-12 * max(float(s[0]), 1e-300)))
    return vt[rank:].T


def project(kind: str, th: np.ndarray, iterations: int = 8) -> np.ndarray:
    """``th`` moved onto the equality constraints by minimum-norm Newton steps."""
    th = np.array(th, dtype=float)
    for _ in range(iterations):
        e, G = constraints(kind, th)
        if e.size == 0 or float(np.max(np.abs(e))) <= 1e-14:
            break
        try:
            th = th - G.T @ np.linalg.solve(G @ G.T, e)
        except np.linalg.LinAlgError:
            th = th - G.T @ np.linalg.lstsq(G @ G.T, e, rcond=None)[0]
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


@dataclass
class LMResult:
    th: np.ndarray
    t: np.ndarray        # least-clearance position along each link at the solution
    converged: bool
    iterations: int
    cost: float


def solve(m: Model, nd: Any, th0: np.ndarray, side: float, loss: str, delta: float,
          max_iter: int, link_min: Any, rho: Any, irls_weight: Any) -> LMResult:
    """Levenberg-Marquardt from ``th0`` on normalised data ``nd`` (``core._Norm``).

    ``link_min(m, th, side, a, b) -> (value, t, ...)`` gives the least clearance along links,
    ``rho`` and ``irls_weight`` the loss and its reweighting (passed in by
    :mod:`wholearm_tools.fit.core`, which owns their definitions).
    """
    W = np.concatenate([nd.tip_wt, nd.link_wt])
    sw = np.sqrt(W)
    d = nd.tip.shape[1]
    pts_fixed = nd.tip
    ab = nd.b - nd.a

    def evaluate(th: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        if len(nd.a):
            _, t, *_ = link_min(m, th, side, nd.a, nd.b)
            pts = np.vstack([pts_fixed, nd.a + t[:, None] * ab])
        else:
            t = np.zeros(0)
            pts = pts_fixed
        sd, J = sd_and_jacobian(m.kind, th, pts.reshape(-1, d))
        r = side * sd - np.concatenate([nd.tip_w, nd.link_w])
        return r, side * J, t, float(np.sum(rho(sw * r, loss, delta)))

    th = project(m.kind, np.asarray(th0, dtype=float))
    if not feasible(m, th):
        th = np.clip(th, np.asarray(m.lbx) + 1e-9, np.asarray(m.ubx) - 1e-9)
        th = project(m.kind, th)
    r, J, t, cost = evaluate(th)
    if not np.isfinite(cost):
        return LMResult(th, t, False, 0, cost)
    lam = -1.0
    converged = False
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is returned
        B = tangent_basis(m.kind, th)
        Jm = J @ B
        wr = W * irls_weight(sw * r, loss, delta)
        g = Jm.T @ (wr * r)
        H = Jm.T @ (wr[:, None] * Jm)
        dH = np.diag(H).copy()
        if lam < 0:
            lam = 1e-6 * max(float(dH.max(initial=0.0)), 1e-300)
        step_taken = False
        while lam <= _LAMBDA_MAX * max(float(dH.max(initial=0.0)), 1e-300):
            A = H + lam * np.diag(np.maximum(dH, 1e-12 * max(float(dH.max()), 1e-300)))
            try:
                step = np.linalg.solve(A, -g)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            th_new = project(m.kind, th + B @ step)
            if feasible(m, th_new):
                r_new, J_new, t_new, c_new = evaluate(th_new)
                if np.isfinite(c_new) and c_new <= cost:
                    moved = float(np.max(np.abs(th_new - th)))
                    small = moved <= _TOL * (1.0 + float(np.max(np.abs(th))))
                    flat = cost - c_new <= _TOL * max(cost, 1e-300) + 1e-300
                    th, r, J, t, cost = th_new, r_new, J_new, t_new, c_new
                    lam = max(lam / 10.0, _LAMBDA_MIN * max(float(dH.max()), 1e-300))
                    step_taken = True
                    if small or flat:
                        converged = True
                    break
            lam *= 10.0
        if not step_taken or cost <= 1e-30:
            # no step lowers the objective even with the heaviest damping (a gradient step
            # shorter than rounding): a minimum to working precision
            converged = True
        if converged:
            break
    return LMResult(th, t, converged, it, cost)
