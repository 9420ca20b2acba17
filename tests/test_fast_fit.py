"""The written-out Gauss–Newton for Sárosi eq. 2.1 (``pamid/_solvers/_sarosi.py``), the
default Sárosi solver, against known answers: noiseless data (the constants it was made
from), SciPy's ``least_squares`` and optimistix's Gauss–Newton (the same optimum), a loop of
single fits (the batch), and muscles whose data cannot determine the constants (flagged)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize
from sarosi_np import force_np, jacobian_np

import pamid
from pamid._fit._least_squares import _solve_batch, solve
from pamid._fit._spec import SAROSI
from pamid._solvers import _sarosi as gn
from pamid._solvers import sarosi_variable_projection_start


def design(n_per_pressure=30, pressures_bar=(1.0, 2.0, 3.0, 4.0, 5.0), kappa_max=25.0):
    """Sárosi's design without the simulator: every pressure swept over κ in [0, κ_max]."""
    k = np.tile(np.linspace(0.0, kappa_max, n_per_pressure), len(pressures_bar))
    p = np.repeat(np.asarray(pressures_bar), n_per_pressure)
    return p, k


def muscle(theta, noise_sd, seed, **kwargs):
    p, k = design(**kwargs)
    rng = np.random.default_rng(seed)
    return (p, k), force_np(theta, p, k) + noise_sd * rng.standard_normal(p.shape)


def scipy_optimum(group, theta0):
    (p, k), y = group
    sol = scipy.optimize.least_squares(
        lambda t: force_np(t, p, k) - y,
        theta0,
        jac=lambda t: jacobian_np(t, p, k),
        method="lm",
        x_scale="jac",
        xtol=1e-15,
        ftol=1e-15,
        gtol=1e-15,
    )
    return sol.x


def max_rel(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b)) / np.abs(np.asarray(b))))


def test_reduce_samples_equals_separate_sums_and_maxima():
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((2, 4, 50))
    sums = gn._reduce_samples([jnp.asarray(a), jnp.asarray(a * b)], [jnp.asarray(b)])
    np.testing.assert_allclose(sums[0], a.sum(-1), rtol=1e-13)
    np.testing.assert_allclose(sums[1], (a * b).sum(-1), rtol=1e-13)
    np.testing.assert_array_equal(sums[2], b.max(-1))


def test_subsample_is_evenly_spaced_over_each_lanes_samples():
    n, n_sub = 12, 4
    idx = np.tile(np.arange(n, dtype=float), (3, 1))
    w = np.ones((3, n))
    w[1, 7:] = 0.0  # 7 samples, then padding: stride 2 covers them
    w[2, 3:] = 0.0  # 3 samples: fewer than n_sub, all kept
    (sub,), w_sub = gn._subsample((jnp.asarray(idx),), jnp.asarray(w), n_sub)
    np.testing.assert_array_equal(sub[0], [0, 3, 6, 9])  # stride 3 over 12 samples
    np.testing.assert_array_equal(sub[1], [0, 2, 4, 6])
    np.testing.assert_array_equal(sub[2], [0, 1, 2, 3])
    np.testing.assert_array_equal(w_sub[2], [1, 1, 1, 0])


def test_noiseless_data_give_the_constants_back(theta31):
    thetas = theta31 * np.array([[1.0] * 6, [1.1, 0.9, 1.2, 0.95, 1.05, 0.9]])
    groups = [muscle(t, 0.0, 0) for t in thetas]
    theta, ok, steps = solve(SAROSI, pamid.pack_muscles(groups))
    assert ok.all()
    assert max_rel(theta, thetas) < 1e-9


def test_the_fit_at_a_fixed_a3_gives_the_linear_constants_back(theta31):
    # pamid.engine.sarosi_fit_at_a3, variable projection's inner problem: at the true a3 of
    # noiseless data, the other five constants and S = 0; QR and normal equations agree.
    (p, k), y = muscle(theta31, 0.0, 0)
    w = np.ones_like(y)
    for accurate in (True, False):
        beta, sse = pamid.engine.sarosi_fit_at_a3(theta31[2], p, k, y, w, accurate=accurate)
        assert max_rel(np.asarray(beta), np.delete(theta31, 2)) < 1e-7
        assert float(sse) < 1e-10 * float(np.sum(y * y))
    beta, sse = pamid.engine.sarosi_fit_at_a3(1.5 * theta31[2], p, k, y, w)
    assert float(sse) > 1.0


def test_same_optimum_as_scipy_and_optimistix(small_bench, theta31):
    data = small_bench.data
    theta, ok, _ = solve(SAROSI, data)
    assert ok.all()
    for i, group in enumerate(small_bench.groups):
        # SciPy's lm stops ~1.4e-8 short in a1 (the least well determined constant) even at
        # tolerances of 1e-15; the fixed-point test below shows which one is at the optimum.
        assert max_rel(theta[i], scipy_optimum(group, theta31)) < 5e-8
    # The previous default: optimistix Gauss–Newton from the variable-projection start.
    start = sarosi_variable_projection_start(data.x, data.y, data.w)
    ref, ok_ref, _ = _solve_batch(
        SAROSI, "gauss-newton", start, data.x, data.y, data.w, 100, 1e-10, 1e-10
    )
    assert np.asarray(ok_ref).all()
    assert max_rel(theta, ref) < 1e-10


def test_the_answer_is_a_fixed_point_of_gauss_newton(small_bench):
    """One more Gauss–Newton step (NumPy, least squares on J) moves no constant by more than
    the tolerance asked for."""
    theta, ok, _ = solve(SAROSI, small_bench.data)
    for i, ((p, k), y) in enumerate(small_bench.groups):
        jac = jacobian_np(theta[i], p, k)
        step = np.linalg.lstsq(jac, y - force_np(theta[i], p, k), rcond=None)[0]
        assert np.all(np.abs(step) < 1e-10 * (1 + np.abs(theta[i])))


def test_a_batch_equals_a_loop_of_single_fits(small_bench):
    data = small_bench.data
    theta, ok, steps = solve(SAROSI, data)
    for i, group in enumerate(small_bench.groups):
        one, ok_one, steps_one = solve(SAROSI, pamid.pack_muscles([group]))
        assert max_rel(theta[i], one[0]) < 1e-12
        assert ok[i] == ok_one[0] and steps[i] == steps_one[0]


@pytest.mark.parametrize("factor", [0.5, 0.8, 1.4, 3.0])
def test_converges_from_a_far_start(small_bench, factor):
    """From a3 off by −50 % to +200 % (and the linear constants of Table 3-1 scale): the
    step halving keeps Gauss–Newton on its way to the same optimum."""
    data = small_bench.data
    best, _, _ = solve(SAROSI, data)
    start = best.copy()
    start[:, 2] *= factor
    theta, ok, _ = solve(SAROSI, data, theta0=start)
    assert ok.all()
    assert max_rel(theta, best) < 1e-10


def test_start_is_near_the_optimum(small_bench):
    theta0 = np.asarray(
        gn.sarosi_fast_start(small_bench.data.x, small_bench.data.y, small_bench.data.w)
    )
    best, _, _ = solve(SAROSI, small_bench.data)
    assert np.all(np.abs(theta0[:, 2] / best[:, 2] - 1) < 0.1)


def hard_muscles(theta31):
    good = muscle(theta31, 2.0, 1)
    one_pressure = muscle(theta31, 2.0, 2, pressures_bar=(3.0,))  # a1·p + a2: one value
    (p, k), y = muscle(theta31, 2.0, 3)
    same_kappa = ((p, np.full_like(k, 5.0)), y)  # F = c1·p + c0: four constants too many
    few = ((p[:5], k[:5]), y[:5])  # five samples for six constants
    return [good, one_pressure, same_kappa, few]


def test_muscles_the_data_cannot_determine_are_flagged_not_converged(theta31):
    groups = hard_muscles(theta31)
    result = pamid.fit_least_squares(pamid.pack_muscles(groups))
    assert result.solver == "gauss-newton"
    np.testing.assert_array_equal(result.converged, [True, False, False, False])
    assert max_rel(result.theta[0], scipy_optimum(groups[0], theta31)) < 5e-8
    # The good muscle is fitted exactly as if alone: the others do not disturb it.
    alone = pamid.fit_least_squares(pamid.pack_muscles(groups[:1]))
    assert max_rel(result.theta[0], alone.theta[0]) < 1e-12


def test_a_muscle_without_finite_start_stops_at_once(small_bench):
    data = small_bench.data
    best, _, _ = solve(SAROSI, data)
    start = best.copy()
    start[1] = np.nan
    theta, ok, steps = solve(SAROSI, data, theta0=start)
    np.testing.assert_array_equal(ok, [True, False, True])
    assert steps[1] == 0
    assert max_rel(theta[[0, 2]], best[[0, 2]]) < 1e-12


def test_written_out_statistics_equal_the_jacobian_and_svd(theta31):
    """``sarosi_statistics`` (sums over the samples, unrolled Cholesky) against the generic
    path (``jax.jacfwd``, QR, SVD): the same SSE, R and (JᵀJ)⁻¹, and the same verdict on
    muscles whose constants the data cannot determine (+inf inverse, not full rank)."""
    from pamid._fit._least_squares import _statistics

    groups = hard_muscles(theta31)
    data = pamid.pack_muscles(groups)
    theta, _, _ = solve(SAROSI, data)
    fast = [np.asarray(a) for a in gn.sarosi_statistics(jnp.asarray(theta), *data[:3])]
    ref = [np.asarray(a) for a in _statistics(SAROSI, jnp.asarray(theta), *data[:3])]
    sse, inv, corr, n, full_rank = fast
    np.testing.assert_array_equal(full_rank, ref[4])
    np.testing.assert_array_equal(full_rank, [True, False, False, False])
    np.testing.assert_array_equal(n, ref[3])
    np.testing.assert_allclose(sse, ref[0], rtol=1e-12)
    np.testing.assert_allclose(corr, ref[2], rtol=1e-13)
    assert max_rel(inv[0], ref[1][0]) < 1e-9
    assert np.all(np.isinf(inv[1:]))
    # and against NumPy from the analytic Jacobian
    (p, k), y = groups[0]
    jac = jacobian_np(theta[0], p, k)
    assert max_rel(inv[0], np.linalg.inv(jac.T @ jac)) < 1e-9
    assert corr[0] == pytest.approx(np.corrcoef(y, force_np(theta[0], p, k))[0, 1], rel=1e-13)


def test_a_lane_out_of_passes_returns_its_last_evaluated_point(small_bench):
    """Not the trial step computed in its last pass, which nothing has checked: after one
    pass a lane has only evaluated its start; after a few, a point whose SSE was seen."""
    data = small_bench.data
    start = np.asarray(gn.sarosi_fast_start(data.x, data.y, data.w)) * 1.05
    theta, ok, steps = gn.sarosi_gauss_newton(data.x, data.y, data.w, start, max_steps=1)
    assert not np.any(ok) and np.all(steps == 1)
    np.testing.assert_array_equal(theta, start)
    best, ok_best, _ = solve(SAROSI, data)
    theta3, ok3, _ = gn.sarosi_gauss_newton(data.x, data.y, data.w, start, max_steps=3)
    assert not np.any(ok3) and np.all(ok_best)
    for i, ((p, k), y) in enumerate(small_bench.groups):
        sse_start = np.sum((force_np(start[i], p, k) - y) ** 2)
        sse_3 = np.sum((force_np(np.asarray(theta3[i]), p, k) - y) ** 2)
        assert sse_3 < 0.01 * sse_start  # an accepted point on the way down


def test_a_muscle_eq_2_1_cannot_follow_ends_at_its_best_point():
    """A muscle whose force is Cullinan's quadratic in the contraction with E = 0 (Cullinan
    et al., F = A + B·P − (C + D·P)·y), logged at four contraction levels: eq. 2.1's least
    squares has no finite optimum (its SSE falls all the way to a3 → 0, where a1, a2, a5 and
    a6 grow without bound and cancel). Gauss–Newton, whose accepted steps may raise the SSE
    up to ``GROW_LIMIT``-fold, runs out of passes on that ridge; it returns the lowest-SSE
    point it evaluated (before: its last accepted point, 15.109 N of RMSE against 15.060 N;
    on a bench file of the same law, 290 N from a start of 16 N), never worse than its
    start, and does not claim convergence."""
    p = np.tile(np.linspace(0.0, 6.2, 1000), 4)
    k = np.repeat([0.0, 7.0, 14.0, 21.0], 1000)
    f = -50.0 + 300.0 * p - (10.0 + 8.0 * p) * k
    keep = f > 1.0  # a slack muscle logs no force
    p, k = p[keep], k[keep]
    y = f[keep] + np.random.default_rng(0).normal(scale=15.0, size=p.size)
    x = (jnp.asarray(p[None]), jnp.asarray(k[None]))
    yy, w = jnp.asarray(y[None]), jnp.ones((1, p.size))
    start = np.asarray(gn.sarosi_fast_start(x, yy, w))
    theta, ok, steps = gn.sarosi_gauss_newton(x, yy, w, start, max_steps=100)
    sse = lambda t: float(np.sum((force_np(np.asarray(t), p, k) - y) ** 2))  # noqa: E731
    assert not bool(ok[0]) and int(steps[0]) == 100
    assert sse(theta[0]) < sse(start[0])
    # the best point: no later pass of the same run found a lower SSE
    for more in (60, 80):
        assert sse(theta[0]) <= sse(gn.sarosi_gauss_newton(x, yy, w, start, max_steps=more)[0][0])
