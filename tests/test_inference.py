"""pamid's one covariance and rank criterion (``pamid._inference``), against known answers:
the closed-form covariance of a straight-line regression, the inverse of a sub-matrix for
held constants, rank-deficient Jacobians, NumPy and JAX giving the same numbers (the JAX
path under ``jit``, ``vmap`` and ``grad``), and no other place in the package that inverts
a normal matrix or counts a rank."""

from __future__ import annotations

import math
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pamid._control._positioning import sarosi_from_fit_json
from pamid._inference import (
    covariance,
    gram_inverse,
    null_direction,
    numerical_rank,
    standard_errors,
    t_critical,
    unscaled_covariance,
    wald_interval,
)

PACKAGE = Path(__file__).resolve().parents[1] / "pamid"


def _line(n=20, seed=0):
    rng = np.random.default_rng(seed)
    x = np.linspace(0.0, 5.0, n)
    y = 1.5 + 0.7 * x + rng.normal(scale=0.3, size=n)
    return x, y, np.column_stack([np.ones(n), x])


def test_straight_line_covariance_is_the_textbook_one():
    # y = a + b·x: Var(b̂) = s²/Sxx, Var(â) = s²·(1/n + x̄²/Sxx), Cov = −x̄·s²/Sxx
    # (any regression text, e.g. Draper & Smith 1998, eqs. 1.4.4–1.4.6).
    x, y, design = _line()
    n = len(x)
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    sse = float(np.sum((y - design @ coef) ** 2))
    s2 = sse / (n - 2)
    sxx = float(np.sum((x - x.mean()) ** 2))
    expected = s2 * np.array([[1 / n + x.mean() ** 2 / sxx, -x.mean() / sxx],
                              [-x.mean() / sxx, 1 / sxx]])
    cov, full = covariance(design, sse, n - 2)
    assert full
    np.testing.assert_allclose(cov, expected, rtol=1e-12)
    se, _ = standard_errors(design, sse, n - 2)
    np.testing.assert_allclose(se, np.sqrt(np.diag(expected)), rtol=1e-12)
    # Wald-t: t_{0.975, 18} = 2.10092204024096 (tables; SciPy's stdtrit).
    assert float(t_critical(18)) == pytest.approx(2.10092204024096, rel=1e-12)
    lo, hi = wald_interval(coef[1], se[1], n - 2)
    assert hi - lo == pytest.approx(2 * 2.10092204024096 * se[1], rel=1e-12)


def test_badly_scaled_columns_are_still_full_rank():
    # Units must not decide identifiability: columns 1e-8 and 1e6 apart in size.
    x, _, design = _line()
    scaled = design * np.array([1e-8, 1e6])
    inv, rank, full = unscaled_covariance(scaled)
    assert full and rank == 2
    np.testing.assert_allclose(inv, np.linalg.inv(scaled.T @ scaled), rtol=1e-8)


def test_held_constants_have_no_variance_and_the_others_the_sub_inverse():
    rng = np.random.default_rng(1)
    jac = rng.normal(size=(40, 4))
    free = np.array([1.0, 0.0, 1.0, 1.0])
    inv, rank, full = unscaled_covariance(jac, free)
    keep = free > 0
    sub = np.linalg.inv(jac[:, keep].T @ jac[:, keep])
    assert full and rank == 3
    np.testing.assert_allclose(inv[np.ix_(keep, keep)], sub, rtol=1e-10)
    assert np.all(inv[1] == 0) and np.all(inv[:, 1] == 0)


def test_rank_deficient_jacobians_have_no_covariance():
    rng = np.random.default_rng(2)
    jac = rng.normal(size=(30, 3))
    jac[:, 2] = 2.0 * jac[:, 0] - jac[:, 1]  # a combination: rank 2
    inv, rank, full = unscaled_covariance(jac)
    assert not full and rank == 2 and np.all(np.isinf(inv))
    cov, full = covariance(jac, 1.0, 27)
    assert not full and np.all(np.isnan(cov))
    assert np.all(np.isnan(standard_errors(jac, 1.0, 27)[0]))
    ratio, v = null_direction(jac)
    assert ratio < 1e-12
    # 2·J₀ − J₁ − J₂ = 0, in the unit-length columns the criterion reads
    expected = np.array([2.0, -1.0, -1.0]) * np.linalg.norm(jac, axis=0)
    np.testing.assert_allclose(v / v[0], expected / expected[0], atol=1e-10)
    # the combination's constant held: the other two are determined
    inv, rank, full = unscaled_covariance(jac, np.array([1.0, 1.0, 0.0]))
    assert full and rank == 2 and np.all(np.isfinite(inv))
    # fewer rows than constants, and a column the model does not see
    assert int(numerical_rank(rng.normal(size=(2, 4)))) == 2
    blind = rng.normal(size=(10, 3))
    blind[:, 1] = 0.0
    assert int(numerical_rank(blind)) == 2
    # no degrees of freedom: no covariance
    assert np.all(np.isnan(covariance(rng.normal(size=(3, 3)), 1.0, 0)[0]))


def test_numpy_and_jax_agree_under_jit_vmap_and_grad():
    rng = np.random.default_rng(3)
    stack = rng.normal(size=(5, 25, 3)) * np.array([1.0, 1e3, 1e-3])
    free = np.array([1.0, 1.0, 0.0])
    inv_np, rank_np, full_np = unscaled_covariance(stack, free)
    inv_j, rank_j, full_j = jax.jit(jax.vmap(lambda j: unscaled_covariance(j, jnp.asarray(free))))(
        jnp.asarray(stack))
    np.testing.assert_allclose(np.asarray(inv_j), inv_np, rtol=1e-10, atol=0)
    np.testing.assert_array_equal(np.asarray(rank_j), rank_np)
    np.testing.assert_array_equal(np.asarray(full_j), full_np)
    # d trace((JᵀJ)⁻¹)/dJ = −2·J·(JᵀJ)⁻², by automatic differentiation of the SVD path
    j0 = stack[0]
    grad = jax.grad(lambda j: jnp.trace(unscaled_covariance(j)[0]))(jnp.asarray(j0))
    a_inv = np.linalg.inv(j0.T @ j0)
    np.testing.assert_allclose(np.asarray(grad), -2.0 * j0 @ a_inv @ a_inv, rtol=1e-6)


def test_a_hand_written_fit_json_takes_its_t_quantile_from_n():
    # A fit JSON without "se": the standard error is the Wald half-width over t_{0.975, n−6}
    # (positioning's draws), no longer over the normal 1.96.
    names = ("a1", "a2", "a3", "a4", "a5", "a6")
    values = (-9.0, 200.0, -0.3, -3.0, 100.0, -200.0)
    params = {k: {"value": v, "ci95": [v - 2.0, v + 2.0]} for k, v in zip(names, values)}
    _, se = sarosi_from_fit_json({"model": "sarosi", "muscles": [{"n": 16, "params": params}]})
    np.testing.assert_allclose(np.asarray(se), 2.0 / float(t_critical(10)), rtol=1e-12)
    _, se = sarosi_from_fit_json({"model": "sarosi", "muscles": [{"params": params}]})
    np.testing.assert_allclose(np.asarray(se), 2.0 / 1.959963984540054, rtol=1e-12)


def test_no_other_place_inverts_a_normal_matrix_or_counts_a_rank():
    # One covariance and one rank criterion: the ways a second one would be written.
    pattern = re.compile(r"linalg\.(inv|pinv|matrix_rank)\(|stats\.t\.ppf|\b1\.96\b")
    found = [f"{path.relative_to(PACKAGE.parent)}:{i}"
             for path in PACKAGE.rglob("*.py") if path.parent.name != "_inference"
             for i, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
             if pattern.search(line.split("#")[0])]
    assert found == []


def test_the_inverse_from_the_normal_matrix_agrees_with_the_jacobians():
    # The sandwich intervals' bread: the same inverse and the same verdict from A = JᵀJ.
    rng = np.random.default_rng(4)
    stack = rng.normal(size=(4, 40, 3)) * np.array([1e-4, 1.0, 1e5])
    stack[3, :, 2] = 2.0 * stack[3, :, 0] * 1e9 - stack[3, :, 1] * 1e5  # rank 2
    a = np.swapaxes(stack, 1, 2) @ stack
    inv, full = gram_inverse(a)
    ref, _, ref_full = unscaled_covariance(stack)
    np.testing.assert_array_equal(full, ref_full)
    assert list(full) == [True, True, True, False] and np.all(np.isnan(inv[3]))
    np.testing.assert_allclose(inv[:3], ref[:3], rtol=1e-9)


def test_an_interval_is_cut_at_the_physical_bounds_and_says_so():
    from pamid._inference import cut_at_bounds

    assert cut_at_bounds(-0.18, 0.31, (0.0, math.inf)) == (0.0, 0.31, True)
    assert cut_at_bounds(0.02, 0.31, (0.0, math.inf)) == (0.02, 0.31, False)
    assert cut_at_bounds(0.2, 1.4, (0.0, 1.0)) == (0.2, 1.0, True)
    assert cut_at_bounds(-3.0, 2.0) == (-3.0, 2.0, False)  # no bounds: unchanged
    lo, hi, cut = cut_at_bounds(math.nan, math.nan, (0.0, math.inf))
    assert math.isnan(lo) and math.isnan(hi) and not cut  # no interval stays none
