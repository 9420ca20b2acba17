"""The hierarchical Bayesian fit of the Bolen law (issue #31, partial pooling): on virtual
populations with a known law and a known spread between muscles, the posterior holds the
law's constants and the spread, and a new muscle's predictive interval is wider than the
noise alone and centred on it. Coverage on held-out virtual muscles is measured in
experiments/pooled_muscles.py --coverage 30 (experiments/README.md §11), not here: it
takes minutes of sampling."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pandas as pd
import pytest

import pamid
from pamid._models._bolen import Bolen2026
from pamid._pooled._hierarchical import THETA_NAMES, fit_hierarchical, predictive_interval
from pamid._virtual._population import simulate_population_bench

L0 = tuple(np.geomspace(80.0, 400.0, 8))
TRUTH = np.array([getattr(Bolen2026(), n) for n in THETA_NAMES])
LOWER = np.array([Bolen2026.bounds[n][0] for n in THETA_NAMES])
UPPER = np.array([Bolen2026.bounds[n][1] for n in THETA_NAMES])


def _population(key, spread):
    frame = simulate_population_bench(key, L0, spread=spread, noise_N=2.0)
    x = (frame["pressure_kPa"].to_numpy(), frame["contraction_pct"].to_numpy() / 100.0,
         frame["l0_mm"].to_numpy(), 1.0 - frame["l620_mm"].to_numpy() / frame["l0_mm"].to_numpy())
    muscle = pd.Categorical(frame["muscle"]).codes
    return x, frame["force_N"].to_numpy(), muscle


@pytest.mark.slow
def test_posterior_holds_the_law_the_spread_and_a_new_muscles_interval():
    # Four stacked populations (one ensemble each): spread τ = 0.1 between muscles.
    data = [_population(jax.random.key(10 + i), 0.1) for i in range(4)]
    x = tuple(np.stack([d[0][j] for d in data]) for j in range(4))
    y = np.stack([d[1] for d in data])
    muscle = np.stack([d[2] for d in data])
    fit = fit_hierarchical(jax.random.key(0), x, y, muscle, 8, np.tile(TRUTH, (4, 1)),
                           lower=LOWER, upper=UPPER, n_burn=800, n_draws=60, thin=5)
    assert fit.theta.shape == (4, 60 * 48, 5) and 0.05 < fit.acceptance < 0.9
    # The noise, and the shape of the law (a0, a1, a3), are pinned by 8 muscles' rows.
    np.testing.assert_allclose(np.median(fit.sigma_N, axis=1), 2.0, rtol=0.1)
    np.testing.assert_allclose(np.median(fit.theta[..., 2:], axis=1),
                               np.broadcast_to(TRUTH[2:], (4, 3)), rtol=0.05)
    # τ from 8 muscles: each population's posterior median within a factor 2 of 0.1, and
    # the scale a of F620 (which the muscles' factors share) within 3 τ/√8.
    tau = np.median(fit.tau, axis=1)
    assert np.all((tau > 0.05) & (tau < 0.2)), tau
    a = np.median(fit.theta[..., 0], axis=1)
    assert np.all(np.abs(a / TRUTH[0] - 1) < 3 * 0.1 / np.sqrt(8)), a

    # A new muscle of the first population: its interval holds the spread between muscles.
    one = dataclasses.replace(fit, theta=fit.theta[0], tau=fit.tau[0],
                              sigma_N=fit.sigma_N[0], scale=fit.scale[0])
    draws = one.to_dict()
    assert len(draws["tau"]) <= 400
    med, low, high = predictive_interval(jax.random.key(2), draws, np.array([620.0]),
                                         np.array([0.0]), np.array([250.0]),
                                         np.array([0.17]))
    law = float(Bolen2026()(620.0, 0.0, 250.0, 0.17))
    assert low[0] < law < high[0]
    # At F ≈ 440 N a spread of 10 % is ±~90 N; the noise alone would be ±4 N.
    assert 0.1 * law < (high[0] - low[0]) / 2 < 0.5 * law
    assert med[0] == pytest.approx(law, rel=0.1)


@pytest.mark.slow
def test_compare_pooled_with_bayes_and_predict(tmp_path):
    """The hierarchical model as a pooled model: every lane sampled, the held-out muscles
    scored by its predictive, and pamid.predict_muscle drawing from its stored posterior."""
    frame = simulate_population_bench(jax.random.key(5), L0, spread=0.05, noise_N=3.0)
    path = tmp_path / "pop.csv"
    frame.to_csv(path, index=False)
    result = pamid.compare_pooled(pamid.load_bench(path), kinds=(), bayes=jax.random.key(0),
                                  sampling={"n_burn": 600, "n_draws": 40})
    model = result.model("bolen2026_hierarchical")
    assert 0.8 <= model.lomo_coverage_95 <= 1.0
    assert model.lomo_rmse_N < 2 * result.model("bolen2026").lomo_rmse_N
    entry = model.to_dict()
    assert set(entry["posterior"]) >= {"theta", "tau", "sigma_N"}
    pred = pamid.predict_muscle(entry, l0_mm=300.0, pressure_kPa=(600.0,),
                                contraction_pct=(0.0,), key=jax.random.key(1))
    law = float(Bolen2026()(600.0, 0.0, 300.0, 0.01 * pred.descriptors["emax_pct"]))
    assert pred.low_N[0] < law < pred.high_N[0]
