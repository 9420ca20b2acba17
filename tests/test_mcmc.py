"""Posterior sampling: the log-posterior, the samplers against known answers, coverage of the
95% posterior intervals, the ArviZ output and the command-line piece.

Known answers: Cullinan's eq. 3 is linear in its constants, so with a flat prior its
posterior is a Student-t centred on the least-squares solution with scale s·√(XᵀX)⁻¹; the
documented priors are wide enough that the difference is far below the Monte Carlo error.
Sárosi's constants are checked against the true values of synthetic data, and the 95%
intervals' coverage is measured over 500 synthetic data sets sampled in one stacked run.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest
from scipy import stats

import pamid
from pamid._fit._spec import CULLINAN, CULLINAN_DYNAMIC, SAROSI, spec_from_model
from pamid._sampling import _arviz, _mcmc, _posterior
from pamid._sampling._mcmc import McmcBudgetWarning, fit_mcmc
from pamid._sampling._posterior import SAROSI_PRIOR, Prior, default_prior, make_log_prob

PROTOCOL = pamid.SarosiProtocol(min_force_N=10.0)
# σ of one averaged point of the virtual bench: five 2 N readings, each quantized to 0.1 N.
SIGMA_TRUE = math.sqrt((2.0**2 + 0.1**2 / 12) / 5)


def _groups(frame):
    return [((g["pressure_kPa"].to_numpy() / 100.0, g["contraction_pct"].to_numpy()),
             g["force_N"].to_numpy()) for _, g in frame.groupby("muscle", sort=True)]


@pytest.fixture(scope="module")
def sarosi_data(theta31):
    frame = pamid.simulate_sarosi_bench(jax.random.key(11), pamid.Sarosi.from_vector(theta31),
                                        PROTOCOL)
    return pamid.pack_muscles(_groups(frame))


@pytest.fixture(scope="module")
def sarosi_post(sarosi_data):
    return fit_mcmc(sarosi_data, key=jax.random.key(3), progress=False)


# --------------------------------------------------------------------------------------
# The log-posterior.


def _walkers(theta, n=8, seed=0):
    rng = np.random.default_rng(seed)
    z0 = np.append(theta, np.log(0.9))
    return z0 + 1e-3 * np.abs(z0) * rng.normal(size=(n, z0.size))


@pytest.mark.parametrize("likelihood", ["normal", "student-t"])
def test_log_posterior_under_jit_and_vmap(sarosi_data, theta31, likelihood):
    lp = make_log_prob(SAROSI, default_prior(SAROSI), likelihood)
    x, y, w = tuple(a[0] for a in sarosi_data.x), sarosi_data.y[0], sarosi_data.w[0]
    z = _walkers(theta31)
    loop = np.array([lp(zi, x, y, w) for zi in z])
    per_walker = jax.jit(jax.vmap(lp, (0, None, None, None)))(z, x, y, w)
    np.testing.assert_allclose(per_walker, loop, rtol=1e-12)
    # vmap over muscles and walkers: the stacked sampler's call, two muscles.
    keep = np.asarray(w) > 0  # the muscle's rows, not the padding of its size class
    data2 = pamid.pack_muscles(
        [((np.asarray(x[0])[keep], np.asarray(x[1])[keep]), np.asarray(y)[keep])] * 2)
    zz = np.stack([z, _walkers(theta31, seed=1)])
    both = _mcmc._stacked_log_prob(lp)(zz, data2.x, data2.y, data2.w)
    assert both.shape == (2, 8)
    np.testing.assert_allclose(both[0], loop, rtol=1e-12)
    # A gradient, for samplers that want one: finite at an interior point.
    g = jax.grad(lp)(jnp.asarray(z[0]), x, y, w)
    assert np.all(np.isfinite(g))


def test_log_posterior_matches_scipy_densities(sarosi_data, theta31):
    """Differences of log-posteriors (constants cancel) against scipy.stats."""
    prior = default_prior(SAROSI)
    keep = np.asarray(sarosi_data.w[0]) > 0  # the rows, not the padding of the size class
    x = tuple(np.asarray(a[0])[keep] for a in sarosi_data.x)
    y, w = np.asarray(sarosi_data.y[0])[keep], np.asarray(sarosi_data.w[0])[keep]
    z1, z2 = _walkers(theta31, n=2, seed=5)

    def reference(z, kind):
        mu = np.asarray(SAROSI.predict(z[:-1], x))
        s = math.exp(z[-1])
        ll = (stats.norm.logpdf(y, mu, s) if kind == "normal"
              else stats.t.logpdf(y, 4.0, mu, s)).sum()
        lprior = stats.norm.logpdf(z[:-1], prior.loc, prior.scale).sum()
        lsig = stats.halfcauchy.logpdf(s, scale=prior.noise_scale_N) + z[-1]  # Jacobian
        return ll + lprior + lsig

    for kind in ("normal", "student-t"):
        lp = make_log_prob(SAROSI, prior, kind, 4.0)
        got = float(lp(z1, x, y, w) - lp(z2, x, y, w))
        np.testing.assert_allclose(got, reference(z1, kind) - reference(z2, kind), rtol=1e-9)


def test_log_posterior_is_minus_inf_never_nan_on_extreme_inputs(sarosi_data, theta31):
    lp = jax.jit(jax.vmap(make_log_prob(SAROSI, default_prior(SAROSI), "student-t"),
                          (0, None, None, None)))
    x, y, w = tuple(a[0] for a in sarosi_data.x), sarosi_data.y[0], sarosi_data.w[0]
    z0 = np.append(theta31, 0.0)
    bad = []
    for j in range(7):
        for v in (np.inf, -np.inf, np.nan, 1e308, -1e308):
            z = z0.copy()
            z[j] = v
            bad.append(z)
    for j, v in ((2, 0.1), (2, -6.0), (6, -20.0), (6, 20.0)):  # a3 > 0, a3 < −5, σ ∉ support
        z = z0.copy()
        z[j] = v
        bad.append(z)
    z = z0.copy()
    z[0], z[4] = 10.0, -20.0  # a1 + a5 < 0: force falling with pressure
    bad.append(z)
    out = np.asarray(lp(np.array(bad), x, y, w))
    assert not np.isnan(out).any()
    assert np.all(out == -np.inf), out
    # Extreme data give −inf too, never NaN; padding with weight 0 never contributes.
    for scale in (1e300, np.inf):
        out = np.asarray(lp(np.array([z0]), x, y * scale, w))
        assert out[0] == -np.inf
    finite = np.asarray(lp(np.array([z0]), x, y.at[-1].set(1e300), w.at[-1].set(0.0)))
    assert np.isfinite(finite[0])


def test_numpy_log_prob_agrees_with_jax(sarosi_data, theta31):
    prior = default_prior(SAROSI)
    x = tuple(np.asarray(a[0]) for a in sarosi_data.x)
    y, w = np.asarray(sarosi_data.y[0]), np.asarray(sarosi_data.w[0])
    z = _walkers(theta31, n=6)
    z[0, 2] = 0.5  # outside the support
    for kind in ("normal", "student-t"):
        f_np = _posterior.numpy_log_prob("sarosi", prior, kind)
        f_jax = jax.vmap(make_log_prob(SAROSI, prior, kind), (0, None, None, None))
        np.testing.assert_allclose(f_np(z, x, y, w), f_jax(z, x, y, w), rtol=1e-11)


def test_engine_sampler_pieces_are_fit_mcmcs(sarosi_data):
    # pamid.engine's log-probabilities are one object per arguments (what is compiled with
    # them is compiled once), and its StackedSampler from its initial_walkers advances every
    # muscle's ensemble as fit_mcmc's stacked sampler does.
    eng = pamid.engine
    prior = default_prior(SAROSI)
    lp = eng.walker_log_prob(SAROSI, prior)
    assert lp is eng.walker_log_prob(SAROSI, prior, "normal", 4) is _mcmc._log_prob(
        SAROSI, prior, "normal", 4.0)
    assert eng.ensemble_log_prob(SAROSI, prior) is eng.ensemble_log_prob(SAROSI, prior)
    ls = pamid.fit_least_squares(sarosi_data)
    start = eng.initial_walkers(jax.random.key(1), ls, prior, lp, sarosi_data, 16, 0.1)
    m = sarosi_data.n_muscles
    assert start.shape == (m, 16, 7)
    walkers = eng.ensemble_log_prob(SAROSI, prior)
    x0 = tuple(a[0] for a in sarosi_data.x)
    lp0 = walkers(jnp.asarray(start[0]), x0, sarosi_data.y[0], sarosi_data.w[0])
    assert lp0.shape == (16,) and np.all(np.isfinite(np.asarray(lp0)))
    sampler = eng.StackedSampler(lp, jax.random.key(2), start, sarosi_data)
    pos, lps, acc = sampler.advance(40, 10)
    assert pos.shape == (m, 4, 16, 7) and lps.shape == (m, 4, 16) and acc.shape == (m,)
    assert np.all(np.isfinite(lps)) and np.all(acc > 0)
    np.testing.assert_array_equal(pos[:, -1], np.asarray(sampler.state.position))


def test_default_priors_follow_the_spec():
    assert default_prior(SAROSI).names == SAROSI.param_names
    static, dynamic = default_prior(CULLINAN), default_prior(CULLINAN_DYNAMIC)
    assert static.names == ("A", "B", "C", "D", "E")
    assert dynamic.names == ("A", "B", "C", "D", "E", "G")
    assert dynamic.lower[5] == 0.0 and static.lower[1] == 0.0  # G ≥ 0, B > 0
    desc = default_prior(SAROSI).describe()
    assert "condition" in desc and "sigma" in desc and "a3" in desc
    import dataclasses

    with pytest.raises(ValueError, match="no default prior"):
        default_prior(dataclasses.replace(SAROSI, name="new-model", model_class=None))
    # The documented prior follows the model class, not its name.
    assert default_prior(dataclasses.replace(SAROSI, name="renamed")) is SAROSI_PRIOR
    # A ForceModel without a documented prior: flat, within its bounds where it has them.

    class Law(pamid.ForceModel):
        a: float = 1.0
        b: float = -0.1
        units = {"a": "N/kPa", "b": "1/%"}
        inputs = ("pressure_kPa", "contraction_pct")
        bounds = {"b": (-5.0, 0.0)}

        def __call__(self, pressure_kPa, contraction_pct):
            return self.a * pressure_kPa * jnp.exp(self.b * contraction_pct)

    flat = default_prior(spec_from_model(Law))
    assert flat.names == ("a", "b") and all(np.isinf(flat.scale))
    assert (flat.lower[1], flat.upper[1]) == (-5.0, 0.0) and np.isinf(flat.lower[0])
    with pytest.raises(ValueError, match="scale must be positive"):
        Prior(names=("a",), loc=(0.0,), scale=(0.0,), lower=(-1.0,), upper=(1.0,))


# --------------------------------------------------------------------------------------
# The samplers.


def test_integrated_time_matches_emcee():
    emcee = pytest.importorskip("emcee")
    rng = np.random.default_rng(0)
    x = np.cumsum(rng.normal(size=(400, 8, 3)), axis=0) * 0.1 + rng.normal(size=(400, 8, 3))
    np.testing.assert_allclose(_mcmc.integrated_time(x),
                               emcee.autocorr.integrated_time(x, quiet=True, tol=0), rtol=1e-10)
    batch = np.stack([x, 2 * x + 1])
    np.testing.assert_allclose(_mcmc.integrated_time(batch)[1], _mcmc.integrated_time(x))


def test_vectorized_diagnostics_match_arviz():
    from arviz_stats.base import array_stats

    rng = np.random.default_rng(1)
    x = rng.normal(size=(3, 8, 101))
    for t in range(1, x.shape[-1]):
        x[..., t] += 0.8 * x[..., t - 1]
    x[0] = np.round(x[0], 1)  # ties, as a walker that rejects its moves makes
    x[1, 2] += 1.5  # one walker off
    np.testing.assert_allclose(_arviz.rhat_rank(x), array_stats.rhat(x), rtol=1e-10)
    np.testing.assert_allclose(_arviz.ess_bulk(x), array_stats.ess(x), rtol=1e-10)
    np.testing.assert_allclose(_arviz.ess_tail(x), array_stats.ess(x, method="tail", prob=0.95),
                               rtol=1e-10)
    np.testing.assert_allclose(_arviz.mcse_mean(x), array_stats.mcse(x), rtol=1e-10)


def test_stacked_stretch_move_samples_known_gaussians():
    """Three ensembles advanced together, each on its own correlated Gaussian of a very
    different scale (the stretch move is affine invariant): means by an ESS-based z-test,
    covariances to 10%."""
    rng = np.random.default_rng(2)
    scales = np.array([1e-3, 1.0, 1e3])
    means, covs = [], []
    for s in scales:
        a = rng.normal(size=(3, 3))
        covs.append(s**2 * (a @ a.T + 0.5 * np.eye(3)))
        means.append(s * rng.normal(size=3))
    means, covs = np.array(means), np.array(covs)
    prec = np.linalg.inv(covs)

    def log_prob(z, mu, p, _):  # the sampler's signature: (z, x, y, w)
        d = z - mu
        return -0.5 * d @ p @ d

    n_walkers = 16
    start = means[:, None] + 0.1 * np.sqrt(np.diagonal(covs, axis1=1, axis2=2))[:, None] * \
        rng.normal(size=(3, n_walkers, 3))
    lp0 = jax.vmap(jax.vmap(log_prob, (0, None, None, None)))(start, means, prec, np.zeros(3))
    state = _mcmc.EnsembleState(jnp.asarray(start), lp0)
    state, pos, _, acc = _mcmc._advance_stacked(log_prob, jax.random.key(0), state, means, prec,
                                                jnp.zeros(3), n_draws=600, thin=5)
    draws = np.moveaxis(np.asarray(pos)[100:], 0, 2)  # (M, W, D, 3)
    x = np.moveaxis(draws, -1, 1)  # (M, 3, W, D)
    z = (x.mean(axis=(-2, -1)) - means) / _arviz.mcse_mean(x)
    assert np.all(np.abs(z) < 4.0), z
    cov = np.array([np.cov(d.reshape(-1, 3).T) for d in draws])
    rel = np.abs(cov - covs) / np.sqrt(np.einsum("mii,mjj->mij", covs, covs))
    assert np.all(rel < 0.1), rel
    rate = np.asarray(acc) / (3000 * n_walkers)
    assert np.all((rate > 0.2) & (rate < 0.8)), rate


def _cullinan_data(seed=4, noise=2.0):
    rng = np.random.default_rng(seed)
    p = np.repeat([100.0, 200.0, 300.0, 414.0], 20)
    y = np.tile(np.linspace(0.0, 45.0, 20), 4)
    truth = np.array([-50.0, 3.0, 5.0, 0.02, 0.05])
    f = np.asarray(pamid.cullinan.cullinan_force(pamid.Cullinan.from_vector(truth), p, y))
    return pamid.pack_muscles([((p, y), f + rng.normal(0.0, noise, p.size))]), p, y


@pytest.mark.parametrize("sampler", ["stacked", "emcee"])
def test_linear_model_posterior_is_the_exact_student_t(sampler):
    """Cullinan's eq. 3 is linear: the posterior of A–E is t_{n−p}(θ̂, s²(XᵀX)⁻¹)."""
    data, p, y = _cullinan_data()
    result = fit_mcmc(data, "cullinan", key=jax.random.key(5), sampler=sampler, progress=False)
    assert result.converged.all() and result.sampler == sampler
    x = np.stack([np.ones_like(p), p, -y, -p * y, -y * y], axis=1)
    f = np.asarray(data.y[0])[: len(p)]  # the rows (the rest pads to the size class)
    theta_hat = np.linalg.lstsq(x, f, rcond=None)[0]
    dof = len(f) - 5
    s2 = np.sum((f - x @ theta_hat) ** 2) / dof
    sd_exact = np.sqrt(s2 * np.diag(np.linalg.inv(x.T @ x)) * dof / (dof - 2))
    z = (result.mean[0, :5] - theta_hat) / result.mcse_mean[0, :5]
    assert np.all(np.abs(z) < 4.0), z
    np.testing.assert_allclose(result.sd[0, :5] / sd_exact, 1.0, atol=0.1)
    assert np.all(result.ess_bulk[0] > 400)


def test_sarosi_posterior_recovers_the_known_constants(sarosi_post, theta31):
    r = sarosi_post
    assert r.converged.all() and r.enough_steps.all()
    assert r.kept_steps >= 50 * r.tau_steps.max()
    truth = np.append(theta31, SIGMA_TRUE)
    z = (r.mean[0] - truth) / np.sqrt(r.sd[0] ** 2 + r.mcse_mean[0] ** 2)
    assert np.all(np.abs(z) < 4.0), z
    # The posterior sd equals the Wald standard error here (nearly linear, flat priors).
    np.testing.assert_allclose(r.sd[0, :6] / r.ls.se[0], 1.0, atol=0.1)
    assert np.all(r.r_hat[0] < 1.05) and np.all(r.ess_bulk[0] > 400)
    assert 0.2 < r.acceptance[0] < 0.8


def test_student_t_likelihood_resists_outliers(theta31):
    frame = pamid.simulate_sarosi_bench(jax.random.key(21), pamid.Sarosi.from_vector(theta31),
                                        PROTOCOL)
    (x, f), = _groups(frame)
    f = f.copy()
    f[[20, 70, 130, 190, 250]] += 80.0  # five readings spoiled
    data = pamid.pack_muscles([(x, f)])
    normal = fit_mcmc(data, key=jax.random.key(6), progress=False)
    robust = fit_mcmc(data, key=jax.random.key(6), likelihood="student-t", progress=False)
    assert normal.converged.all() and robust.converged.all()
    z_robust = np.abs(robust.mean[0, :6] - theta31) / robust.sd[0, :6]
    assert np.all(z_robust < 4.0), z_robust
    # The normal likelihood explains the outliers by a large σ, and its intervals widen;
    # the Student-t keeps σ near the sensor noise and the intervals near the clean ones.
    assert normal.mean[0, 6] > 3 * SIGMA_TRUE
    assert abs(robust.mean[0, 6] / SIGMA_TRUE - 1.0) < 0.2
    assert np.all(robust.sd[0, :6] < 0.5 * normal.sd[0, :6])
    assert robust.to_dict()["likelihood"] == {"kind": "student-t", "nu": 4.0}


def test_short_budget_warns_and_reports_not_converged(sarosi_data):
    with pytest.warns(McmcBudgetWarning, match="raise max_steps to at least"):
        r = fit_mcmc(sarosi_data, key=jax.random.key(7), max_steps=600, progress=False)
    assert not r.converged.any() and not r.enough_steps.any()
    assert r.to_dict()["muscles"][0]["converged"] is False


def test_bad_arguments_are_rejected_by_name(sarosi_data):
    key = jax.random.key(0)
    with pytest.raises(ValueError, match="n_walkers must be even and at least 2 × 7"):
        fit_mcmc(sarosi_data, key=key, n_walkers=12)
    with pytest.raises(ValueError, match="n_walkers must be even"):
        fit_mcmc(sarosi_data, key=key, n_walkers=33)
    with pytest.raises(ValueError, match="unknown likelihood 'cauchy'"):
        fit_mcmc(sarosi_data, key=key, likelihood="cauchy")
    with pytest.raises(ValueError, match="unknown sampler"):
        fit_mcmc(sarosi_data, key=key, sampler="nuts")
    narrow = Prior(names=SAROSI.param_names, loc=(0.0,) * 6, scale=(math.inf,) * 6,
                   lower=(-10.0, 0.0, -1.0, -20.0, 0.0, -300.0),
                   upper=(10.0, 100.0, 0.0, 0.0, 500.0, 0.0))
    with pytest.raises(ValueError, match="outside the prior's support"):
        fit_mcmc(sarosi_data, key=key, prior=narrow)


@pytest.mark.slow
def test_coverage_of_95_percent_posterior_intervals_over_500_data_sets(theta31):
    """500 synthetic data sets at Sárosi's design, sampled together by the stacked sampler.

    Each run is 1000 steps × 16 walkers: about 30 τ kept, shorter than the 50 τ the default
    asks for (hence the warning) but an ESS of several hundred per constant, plenty for a
    95% interval. Coverage must lie within 95% ± 3% for every constant and for σ; with 500
    sets the binomial sd is 1.0%, so the window is ±3 sd. The Wald intervals of the same
    sets are printed beside them: at this design the two should agree closely."""
    n_sets = 500
    constants = pamid.Sarosi.from_vector(jnp.tile(jnp.asarray(theta31), (n_sets, 1)))
    frame = pamid.simulate_sarosi_bench(jax.random.key(2026), constants, PROTOCOL)
    data = pamid.pack_muscles(_groups(frame))
    with pytest.warns(McmcBudgetWarning):
        r = fit_mcmc(data, key=jax.random.key(8), n_walkers=16, min_steps=1000,
                     max_steps=1000, progress=False)
    truth = np.append(theta31, SIGMA_TRUE)
    cov_eti = ((r.eti95[..., 0] <= truth) & (truth <= r.eti95[..., 1])).mean(axis=0)
    cov_hdi = ((r.hdi95[..., 0] <= truth) & (truth <= r.hdi95[..., 1])).mean(axis=0)
    wald = ((r.ls.ci95[..., 0] <= theta31) & (theta31 <= r.ls.ci95[..., 1])).mean(axis=0)
    print("\n95% ETI coverage:", dict(zip(r.var_names, cov_eti.round(3))))
    print("95% HDI coverage:", dict(zip(r.var_names, cov_hdi.round(3))))
    print("Wald coverage, same sets:", dict(zip(r.param_names, wald.round(3))))
    print(f"ESS bulk: min {r.ess_bulk.min():.0f}, median {np.median(r.ess_bulk):.0f}; "
          f"R-hat max {r.r_hat.max():.3f}; τ max {r.tau_steps.max():.0f} steps; "
          f"{r.seconds:.1f} s")
    assert np.all(np.abs(cov_eti - 0.95) <= 0.03), cov_eti
    assert np.all(np.abs(cov_hdi - 0.95) <= 0.03), cov_hdi
    assert np.all(r.r_hat < 1.1) and r.ess_bulk.min() > 100


# --------------------------------------------------------------------------------------
# Output.


def test_to_dict_has_the_least_squares_shape_and_more(sarosi_post):
    d = sarosi_post.to_dict()
    ls = sarosi_post.ls.to_dict()
    # Which least-squares interval to read under correlated residuals: the posterior's
    # own "interval" key says what its intervals are instead.
    # Which least-squares interval each muscle shows, and Wald's beside it: the posterior's
    # ci95 is its own (equal-tailed), the least-squares ones are under "ls".
    ls_only = {"interval_shown", "interval_groups", "residual_lag1", "interval_note",
               "interval"}
    assert set(ls) - ls_only <= set(d)
    assert d["model"] == "sarosi" and d["units"] == ls["units"]
    m, m_ls = d["muscles"][0], ls["muscles"][0]
    assert set(m_ls) - ls_only <= set(m)
    assert list(m["params"]) == list(SAROSI.param_names)
    for name, entry in m["params"].items():
        assert set(m_ls["params"][name]) - {"ci95_wald", "se_wald"} <= set(entry)
        assert {"hdi95", "r_hat", "ess_bulk", "ess_tail", "ls"} <= set(entry)
        assert entry["ci95"][0] < entry["value"] < entry["ci95"][1]
        assert entry["unit"] == SAROSI.param_units[name]
    assert m["sigma_N"]["unit"] == "N"
    json.dumps(d, allow_nan=False)


def test_inference_data_has_every_group_and_matches_the_draws(sarosi_post):
    dt = sarosi_post.to_inference_data(0)
    for group in ("posterior", "sample_stats", "log_likelihood", "posterior_predictive",
                  "observed_data", "constant_data"):
        assert group in dt.children, group
    post = dt["posterior"]
    w, d = sarosi_post.samples.shape[1:3]
    assert post["a3"].shape == (w, d) and post["sigma"].shape == (w, d)
    np.testing.assert_array_equal(post["a3"].values, sarosi_post.samples[0, :, :, 2])
    assert dt["log_likelihood"]["force_N"].shape == (w, d, 300)
    assert dt["posterior_predictive"]["force_N"].shape == (w, d, 300)
    np.testing.assert_array_equal(dt["observed_data"]["force_N"].values,
                                  np.asarray(sarosi_post.data.y[0])[:300])
    # The pointwise log-likelihood sums to the log-posterior less the log-prior.
    lp = sarosi_post.log_prob[0, 0, 0]
    z = sarosi_post.samples[0, 0, 0].copy()
    z[-1] = np.log(z[-1])
    prior = float(_posterior.log_prior(sarosi_post.prior, z[:-1], z[-1]))
    np.testing.assert_allclose(dt["log_likelihood"]["force_N"].values[0, 0].sum() + prior, lp,
                               rtol=1e-10)
    table = sarosi_post.summary(0)
    assert {"mean", "sd", "hdi95_lb", "hdi95_ub", "eti95_lb", "eti95_ub", "r_hat", "ess_bulk",
            "ess_tail"} <= set(table.columns)
    np.testing.assert_allclose(table["ess_bulk"].to_numpy(float), sarosi_post.ess_bulk[0],
                               rtol=1e-8)
    np.testing.assert_allclose(table["ess_tail"].to_numpy(float), sarosi_post.ess_tail[0],
                               rtol=1e-8)
    np.testing.assert_allclose(table["eti95_lb"].to_numpy(float), sarosi_post.eti95[0, :, 0])


@pytest.mark.parametrize("engine", ["netcdf4", "netcdf3-folder"])
def test_inference_data_round_trips_through_netcdf(sarosi_post, tmp_path, monkeypatch, engine):
    from pamid._report import _mcmc as report_mcmc
    from pamid.report import save_netcdf

    if engine == "netcdf4":
        if report_mcmc.netcdf_engine() is None:
            pytest.skip("no NetCDF-4 engine (h5netcdf or netCDF4) installed")
        names = save_netcdf(sarosi_post, tmp_path)
    else:
        monkeypatch.setattr(report_mcmc, "netcdf_engine", lambda: None)
        with pytest.warns(UserWarning, match="no NetCDF-4 engine"):
            names = save_netcdf(sarosi_post, tmp_path)
    assert len(names) == 1
    back = _arviz.load_inference_data(tmp_path / names[0])
    orig = sarosi_post.to_inference_data(0)
    for group in ("posterior", "sample_stats", "log_likelihood", "posterior_predictive",
                  "observed_data", "constant_data"):
        a, b = orig[group].to_dataset(), back[group].to_dataset()
        assert set(a.data_vars) == set(b.data_vars), group
        for v in a.data_vars:
            np.testing.assert_array_equal(a[v].values, b[v].values)
    assert back["posterior"].attrs["model"] == "sarosi"
    assert back["posterior"].attrs["sample_dims"] == ["chain", "draw"]
    assert back["posterior"]["a1"].attrs["units"] == "N/bar"


def test_emcee_path_posterior_is_from_emcee_after_burn_in():
    az = pytest.importorskip("arviz")
    data, _, _ = _cullinan_data(seed=9)
    r = fit_mcmc(data, "cullinan", key=jax.random.key(10), sampler="emcee", max_steps=3000,
                 progress=False)
    ref = az.from_emcee(r.samplers[0], var_names=list(CULLINAN.param_names) + ["log_sigma"])
    burn = r.burn_steps // r.thin
    ours = r.to_inference_data(0, predictive=False)["posterior"]
    for name in CULLINAN.param_names:
        np.testing.assert_array_equal(ours[name].values,
                                      ref["posterior"][name].values[burn:].T)
    np.testing.assert_allclose(np.log(ours["sigma"].values),
                               ref["posterior"]["log_sigma"].values[burn:].T, rtol=1e-14)


# --------------------------------------------------------------------------------------
# Command line.


def _fit_parser():
    """The options of ``pamid fit`` that ``run_mcmc_fit`` reads, plus the MCMC ones."""
    from pamid._commands.mcmc import add_mcmc_arguments

    p = argparse.ArgumentParser()
    p.add_argument("data")
    p.add_argument("--model", default="sarosi")
    p.add_argument("--json", action="store_true")
    p.add_argument("--out")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--max-plots", type=int, default=6, dest="max_plots")
    p.add_argument("--intervals", default="wald,profile")
    p.add_argument("--solver", default="gauss-newton")
    add_mcmc_arguments(p)
    return p


@pytest.fixture(scope="module")
def one_muscle_csv(theta31, tmp_path_factory):
    frame = pamid.simulate_sarosi_bench(jax.random.key(11), pamid.Sarosi.from_vector(theta31),
                                        PROTOCOL)
    path = tmp_path_factory.mktemp("mcmc") / "one.csv"
    frame.to_csv(path, index=False)
    return path


@pytest.mark.slow
def test_run_mcmc_fit_writes_json_netcdf_and_plots(one_muscle_csv, tmp_path, capsys):
    from pamid._commands.mcmc import run_mcmc_fit

    out = tmp_path / "out"
    args = _fit_parser().parse_args([str(one_muscle_csv), "--method", "mcmc", "--out", str(out),
                                     "--seed", "3"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the NetCDF-3 fallback warns where h5netcdf is absent
        payload, code = run_mcmc_fit(args, pamid.load_bench(one_muscle_csv))
    assert code == 0
    printed = capsys.readouterr().out
    assert "HDI low" in printed and "Wald low" in printed and "profile low" in printed
    assert payload["source"] == str(one_muscle_csv)
    entry = payload["muscles"][0]["params"]["a3"]
    assert {"hdi95", "r_hat", "ess_bulk", "ls"} <= set(entry) and "ci95_profile" in entry["ls"]
    assert json.loads((out / "fit.json").read_text())["model"] == "sarosi"
    for name in payload["plots"]:
        assert (out / name).stat().st_size > 10_000, name
    assert len(payload["plots"]) == 3 and len(payload["netcdf"]) == 1
    back = _arviz.load_inference_data(out / payload["netcdf"][0])
    assert "posterior_predictive" in back.children


def test_run_mcmc_fit_json_mode_prints_nothing(one_muscle_csv, capsys):
    from pamid._commands.mcmc import run_mcmc_fit

    args = _fit_parser().parse_args([str(one_muscle_csv), "--method", "mcmc", "--json",
                                     "--max-steps", "600", "--intervals", "wald"])
    with pytest.warns(McmcBudgetWarning):
        payload, code = run_mcmc_fit(args, pamid.load_bench(one_muscle_csv))
    assert code == 1 and capsys.readouterr().out == ""
    assert payload["muscles"][0]["converged"] is False
    json.dumps(payload, allow_nan=False)


def test_pamid_fit_method_mcmc_when_wired(one_muscle_csv, tmp_path, cli_env):
    """End to end through ``pamid fit --method mcmc``, once the option is wired in."""
    cmd = [sys.executable, "-m", "pamid._cli"]
    helptext = subprocess.run(cmd + ["fit", "--help"], capture_output=True, text=True).stdout
    if "--method" not in helptext:
        pytest.skip("pamid fit has no --method yet")
    env = cli_env
    res = subprocess.run(cmd + ["fit", str(one_muscle_csv), "--method", "mcmc", "--json",
                                "--max-steps", "6000", "--intervals", "wald"],
                         capture_output=True, text=True, env=env, timeout=600)
    assert res.returncode == 0, res.stderr
    payload = json.loads(res.stdout)
    assert payload["solver"].startswith("mcmc")
    bad = subprocess.run(cmd + ["fit", str(one_muscle_csv), "--method", "mcmc", "--walkers", "3"],
                         capture_output=True, text=True, env=env, timeout=600)
    assert bad.returncode == 2 and "--walkers" in bad.stderr


def test_bench_input_keeps_muscle_names(tmp_path, theta31):
    # One muscle, the shapes of the other tests: compiled code is reused.
    frame = pamid.simulate_sarosi_bench(jax.random.key(12), pamid.Sarosi.from_vector(theta31),
                                        PROTOCOL, muscle_ids=["left"])
    path = tmp_path / "left.csv"
    pd.DataFrame(frame).to_csv(path, index=False)
    r = fit_mcmc(pamid.load_bench(path), key=jax.random.key(13), progress=False)
    assert r.muscles == ("left",) and r.converged.all()
    assert [m["muscle"] for m in r.to_dict()["muscles"]] == ["left"]
    assert isinstance(r.params(0), pamid.Sarosi)


def test_bounds_restrict_the_start_and_the_posterior(sarosi_data, theta31):
    # a3's upper bound at 1.5 × its true value (a3 < 0: below it): the data would cross it.
    cap = 1.5 * theta31[2]
    lower = (-np.inf, -np.inf, -3.0, -np.inf, -np.inf, -np.inf)
    upper = (np.inf, np.inf, cap, np.inf, np.inf, np.inf)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", McmcBudgetWarning)
        r = fit_mcmc(sarosi_data, key=jax.random.key(8), max_steps=1000, progress=False,
                     bounds=(lower, upper))
    assert r.ls.theta[0, 2] == pytest.approx(cap)  # the start: fitted within the bounds
    assert r.ls.status_of(0) == "at_bound"
    a3 = r.samples[0, :, :, 2]
    assert a3.max() < cap and a3.min() > -3.0  # every draw inside (the support is open)
    prior = r.to_dict()["prior"]["a3"]
    assert f"restricted to (-3, {cap:g}) by the bounds" in prior
    with pytest.raises(ValueError, match="a3: .* lies outside the support of its prior"):
        fit_mcmc(sarosi_data, key=jax.random.key(8), progress=False,
                 bounds=(lower[:2] + (-9.0,) + lower[3:], upper[:2] + (-8.0,) + upper[3:]))
