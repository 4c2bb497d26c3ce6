"""The Levenberg-Marquardt path (fit/solve.py) and the CasADi -> numpy translation
(fit/codegen.py)."""

import casadi as ca
import numpy as np
import pytest
from fit_synth import contacts, param_error, perturbed, truth

from wholearm_tools.fit import FitData, core
from wholearm_tools.fit.codegen import numpy_function
from wholearm_tools.fit.models import MODELS, signed_distance_np
from wholearm_tools.fit.solve import follow_links, null_space, solve, symbolic

KINDS = ["line", "circle", "plane", "sphere", "cylinder", "cone", "torus"]


def _lm(kind, data, start, side):
    """LM alone (no IPOPT fallback) from map.json parameters; returns the result and the
    normalisation."""
    m = MODELS[kind]
    nd = core._normalise(data)
    th0 = core._raw_from_params(m, start, nd)
    res = solve(m, nd, th0, side, "linear", 1.0, 200, core._link_t, core.rho_np,
                core._irls_weight)
    return res, nd


def _noisy_problem(kind, seed):
    """A random ``kind`` with 16 tip and 8 link contacts at 3 mm noise, normalised, and a
    perturbed start: (model, normalised data, start, true parameters)."""
    rng = np.random.default_rng(seed)
    p = truth(kind, rng)
    data = contacts(kind, p, 16, 8, 1, rng, noise=0.003)
    m = MODELS[kind]
    nd = core._normalise(data)
    return m, nd, core._raw_from_params(m, perturbed(p), nd), p


def _params(kind, th, nd):
    m = MODELS[kind]
    return core._denormalise(m, m.to_params(th), nd)


def _random_inputs(f, rng, n):
    """Random values for the inputs of ``f``: parameter vectors, and ``n`` columns for the
    point inputs (index >= 1)."""
    out = []
    for k in range(f.n_in()):
        size = f.size1_in(k)
        out.append(rng.normal(size=size) if k == 0 else rng.normal(size=(size, n)))
    return out


@pytest.mark.parametrize("kind", KINDS)
def test_generated_code_equals_casadi(kind):
    rng = np.random.default_rng(3)
    for name, f in symbolic(kind).items():
        n = 40
        points = set(range(1, f.n_in()))
        g = numpy_function(f, points, f"{kind}_{name}")
        for _ in range(5):
            args = _random_inputs(f, rng, n)
            got = g(*args)
            for j in range(n):
                want = f(*[a if k not in points else a[:, j] for k, a in enumerate(args)])
                want = want if isinstance(want, tuple) else (want,)
                for out, w in zip(got, want, strict=True):
                    w = np.asarray(ca.DM(w).nonzeros())
                    v = np.array([np.broadcast_to(x, (n,))[j] for x in out])
                    np.testing.assert_allclose(v, w, rtol=1e-12, atol=1e-12,
                                               err_msg=f"{kind} {name} point {j}")


def test_codegen_rejects_an_operation_it_cannot_translate():
    x = ca.SX.sym("x")
    f = ca.Function("f", [x], [ca.erf(x)])
    with pytest.raises(NotImplementedError, match="no numpy translation"):
        numpy_function(f, {0})


@pytest.mark.parametrize("side", [1, -1])
@pytest.mark.parametrize("kind", KINDS)
def test_noise_free_recovery_through_lm_with_link_contacts(kind, side):
    rng = np.random.default_rng(11)
    p = truth(kind, rng)
    data = contacts(kind, p, 12, 10, side, rng)
    start = perturbed(p)
    if kind in ("line", "plane"):  # the initial normal points to free space
        start["normal" if kind == "plane" else "direction"] = (
            side * start["normal"] if kind == "plane" else side * start["direction"])
    res, nd = _lm(kind, data, start, 1.0 if kind in ("line", "plane") else side)
    assert res.converged
    expected = dict(p, normal=side * p["normal"]) if kind == "plane" else p
    assert param_error(kind, _params(kind, res.th, nd), expected) < 1e-7
    assert res.cost < 1e-20
    assert np.all((res.t >= 0) & (res.t <= 1))


@pytest.mark.parametrize("kind", KINDS)
def test_lm_and_ipopt_agree_on_the_optimum(kind):
    """Noisy tip and link contacts, random primitives: both solvers from the same start reach
    the same parameters and cost."""
    for draw in range(3):
        m, nd, th0, _ = _noisy_problem(kind, [17, draw])
        lm = solve(m, nd, th0, 1.0, "linear", 1.0, 200, core._link_t, core.rho_np,
                   core._irls_weight)
        ip = core._solve(m, nd, th0, 1.0, "linear", 1.0, 200)
        assert lm.converged, draw
        assert ip.success, (draw, ip.status)
        assert lm.cost == pytest.approx(ip.cost, rel=1e-7), draw
        err = param_error(kind, _params(kind, lm.th, nd), _params(kind, ip.th, nd))
        assert err < 1e-6, (draw, err)


def test_robust_lm_lowers_the_robust_objective_below_the_least_squares_fit():
    rng = np.random.default_rng(5)
    p = truth("sphere", rng)
    data = contacts("sphere", p, 30, 0, 1, rng, noise=0.001)
    pts = np.array(data.tip_points)
    pts[:3] += 0.2  # three gross outliers
    bad = FitData.create(pts, 0.02, 1.0)
    m = MODELS["sphere"]
    nd = core._normalise(bad)
    th0 = core._raw_from_params(m, p, nd)
    delta = 2 * 0.001 / nd.scale
    ls = solve(m, nd, th0, 1.0, "linear", 1.0, 200, core._link_t, core.rho_np,
               core._irls_weight)
    rob = solve(m, nd, ls.th, 1.0, "huber", delta, 200, core._link_t, core.rho_np,
                core._irls_weight)
    assert rob.converged
    assert rob.cost < core._cost_norm(m, ls.th, 1.0, nd, "huber", delta)
    assert (param_error("sphere", _params("sphere", rob.th, nd), p)
            < param_error("sphere", _params("sphere", ls.th, nd), p) / 5)


@pytest.mark.parametrize("kind", ["cone", "torus"])
def test_link_points_followed_by_newton_are_the_least_clearance(kind):
    rng = np.random.default_rng(2)
    p = truth(kind, rng)
    data = contacts(kind, p, 0, 30, 1, rng)
    m = MODELS[kind]
    nd = core._normalise(data)
    th = core._raw_from_params(m, p, nd)
    th_moved = core._raw_from_params(m, perturbed(p), nd)
    # from the contact points of the true primitive, follow to those of the moved one
    _, t0, _ = core._link_t(m, th, 1.0, nd.a, nd.b)
    val, t = follow_links(kind, th_moved, 1.0, nd.a, nd.b, t0)
    grid = np.linspace(0.0, 1.0, 20001)
    pts = nd.a[:, None, :] + grid[None, :, None] * (nd.b - nd.a)[:, None, :]
    dense = signed_distance_np(m, th_moved, pts.reshape(-1, 3)).reshape(len(nd.a), -1)
    assert np.all(val <= dense.min(axis=1) + 1e-9)
    assert np.all((t >= 0) & (t <= 1))


@pytest.mark.parametrize("k", [1, 2, 3])
def test_null_space_is_an_orthonormal_basis_of_the_kernel(k):
    rng = np.random.default_rng(k)
    G = rng.normal(size=(k, 7))
    N = null_space(G)
    assert N.shape == (7, 7 - k)
    np.testing.assert_allclose(G @ N, 0.0, atol=1e-12)
    np.testing.assert_allclose(N.T @ N, np.eye(7 - k), atol=1e-12)
    # a repeated row adds no constraint, and no row none
    assert null_space(np.vstack([G, G[:1]])).shape == (7, 7 - k)
    np.testing.assert_allclose(null_space(np.zeros((0, 7))), np.eye(7))


@pytest.mark.parametrize("kind", ["plane", "sphere", "cylinder", "cone"])
def test_a_fit_solved_to_a_precision_stops_within_it_of_the_optimum(kind):
    """Solved to a residual precision ``p`` (normalised units), LM stops in fewer iterations
    and its cost is within ``p**2 / 2`` of the optimum's (the Gauss-Newton decrement it stops
    at), so a score built on the residuals changes by less than that."""
    fewer = 0
    for draw in range(4):
        m, nd, th0, _ = _noisy_problem(kind, [23, draw])
        args = (m, nd, th0, 1.0, "linear", 1.0, 200, core._link_t, core.rho_np,
                core._irls_weight)
        full = solve(*args)
        prec = 0.1 * 0.003 / nd.scale     # a tenth of the noise
        quick = solve(*args, precision=prec)
        assert full.converged, draw
        assert quick.converged, draw
        assert quick.iterations <= full.iterations, draw
        fewer += quick.iterations < full.iterations
        assert full.cost - 1e-15 <= quick.cost <= full.cost + 0.5 * prec**2, draw
    assert fewer >= 1


def test_a_contact_at_the_start_centre_does_not_raise():
    """The distance to a circle is not differentiable at its centre: a start centred on a
    contact gives a non-finite Jacobian, and the fit reports instead of raising."""
    import warnings

    from wholearm_tools.fit import FitData, fit_primitive

    ang = np.linspace(0, 2 * np.pi, 10, endpoint=False)
    tips = np.vstack([np.c_[0.2 * np.cos(ang), 0.2 * np.sin(ang)], [[0.0, 0.0]]])
    data = FitData.create(tips, 0.0, 1.0, np.zeros((0, 2)), np.zeros((0, 2)), 0.0, 1.0, dim=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        res = fit_primitive("circle", data, initial={"center": np.zeros(2), "radius": 0.2},
                            free_side=1)
    assert np.all(np.isfinite(res.params["center"]))
