"""Coverage of the 95% intervals, measured over many synthetic data sets at Sárosi's design.

Every data set is one "muscle" with the constants of Table 3-1 on the virtual bench with
``SarosiProtocol(min_force_N=10.0)``: 5 pressures, 30 points per sweep, both directions,
five 2 N readings averaged and quantized to 0.1 N. All sets are fitted in one batched call.

With 2000 sets the binomial standard error of a coverage near 0.95 is 0.49 %, so the
window 95 % ± 1.5 % is about ±3 standard errors.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamid

N_SETS = 2000
# Profile intervals for all 2000 sets take ~7–12 s on 2 idle CPU cores (on a loaded machine
# 1000 sets once took 84 s): cheap enough to measure their coverage on every set too.


@pytest.fixture(scope="module")
def design(theta31, split_frame):
    protocol = pamid.SarosiProtocol(min_force_N=10.0)
    assert protocol.pressures_kPa == (100.0, 200.0, 300.0, 400.0, 500.0)
    assert protocol.points_per_curve == 30 and protocol.directions == (1, -1)
    assert protocol.noise_sd_N == 2.0 and protocol.repeats == 5
    constants = pamid.Sarosi.from_vector(jnp.tile(jnp.asarray(theta31), (N_SETS, 1)))
    frame = pamid.simulate_sarosi_bench(jax.random.key(2000), constants, protocol)
    data = pamid.pack_muscles(split_frame(frame))
    assert data.y.shape == (N_SETS, pamid.engine.padded_rows(300, N_SETS))
    return data


@pytest.fixture(scope="module")
def wald_fit(design):
    return pamid.fit_least_squares(design)


def _coverage(ci, theta):
    return np.mean((ci[..., 0] <= theta) & (theta <= ci[..., 1]), axis=0)


@pytest.mark.slow
def test_wald_coverage_at_sarosis_design(wald_fit, theta31):
    assert np.all(wald_fit.converged)
    coverage = _coverage(wald_fit.ci95, theta31)
    print("\nWald 95% coverage over", N_SETS, "sets:", dict(zip(pamid.Sarosi.names, coverage)))
    assert np.all(np.abs(coverage - 0.95) <= 0.015), coverage
    # The standard errors are honest too: the spread of the estimates matches them.
    spread = np.std(wald_fit.theta, axis=0, ddof=1)
    ratio = spread / np.sqrt(np.mean(wald_fit.se**2, axis=0))
    print("sd(estimates) / rms(se):", dict(zip(pamid.Sarosi.names, ratio)))
    assert np.all(np.abs(ratio - 1.0) < 0.06), ratio
    # And the estimates are unbiased to within their Monte Carlo error.
    bias_z = (wald_fit.theta.mean(axis=0) - theta31) / (spread / np.sqrt(N_SETS))
    assert np.all(np.abs(bias_z) < 4.0), bias_z


@pytest.mark.slow
def test_profile_coverage_at_sarosis_design(design, wald_fit, theta31):
    result = pamid.fit_least_squares(design, intervals=("wald", "profile"))
    assert result.ci95_profile.shape == (N_SETS, 6, 2)
    assert np.all(result.profile_ok)
    np.testing.assert_array_equal(result.theta, wald_fit.theta)
    coverage = _coverage(result.ci95_profile, theta31)
    wald = _coverage(result.ci95, theta31)
    print(f"\nprofile 95% coverage over {N_SETS} sets:", dict(zip(pamid.Sarosi.names, coverage)))
    print("Wald coverage on the same sets:", dict(zip(pamid.Sarosi.names, wald)))
    assert np.all(np.abs(coverage - 0.95) <= 0.015), coverage
    # At this noise the model is nearly linear: the two kinds of interval nearly coincide.
    width = result.ci95[..., 1] - result.ci95[..., 0]
    assert np.max(np.abs(result.ci95_profile - result.ci95) / width[..., None]) < 0.01
