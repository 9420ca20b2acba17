"""Bayesian fit of free decays and its posterior predictive (pamid._decays._posterior)."""

import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamid
from pamid._decays._posterior import (
    DECAY_NAMES,
    DECAY_SPEC,
    decay_prior,
    decay_windows,
    fit_decay_mcmc,
)
from pamid._sampling._posterior import make_log_prob

ZETA, F_N, J, EQ = 0.05, 2.0, 0.46, 0.01
STEP = 2.0 * math.pi / 4096
RATE = 500.0
PROTOCOL = pamid.DecayProtocol(n_trials=2, deflections_deg=(5.0, 8.0), duration_s=3.0,
                               sample_rate_Hz=RATE, noise_sd_rad=STEP)


def _pairs(key, coulomb_Nm=0.0):
    osc = pamid.DampedOscillator.from_modal(ZETA, F_N, J, EQ)
    frame = pamid.simulate_decays(key, osc, PROTOCOL, coulomb_Nm=coulomb_Nm)
    return [(g["time_s"].to_numpy(), g["angle_rad"].to_numpy())
            for _, g in frame.groupby("trial")]


@pytest.fixture(scope="module")
def posterior():
    pairs = _pairs(jax.random.key(11))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", pamid.McmcBudgetWarning)  # fixed length on purpose
        post = fit_decay_mcmc(pairs, key=jax.random.key(12), n_walkers=16, min_steps=3000,
                              max_steps=3000, check_every=1000, progress=False)
    return post


def test_posterior_means_recover_truth(posterior):
    m = posterior.mcmc
    assert m.samples.shape[0] == 2 and m.samples.shape[-1] == 6
    assert np.all(m.r_hat[:, :5] < 1.1)
    for j, truth in ((0, ZETA), (1, F_N)):
        mean, sd, mcse = m.mean[:, j], m.sd[:, j], m.mcse_mean[:, j]
        assert np.all(m.ess_bulk[:, j] > 100)
        assert np.all(np.isfinite(mcse)) and np.all(mcse < 0.2 * sd)
        # The truth against the posterior: data noise (sd) plus Monte Carlo error (MCSE).
        z_truth = (mean - truth) / np.sqrt(sd**2 + mcse**2)
        assert np.all(np.abs(z_truth) < 4.0), z_truth
        # Flat priors, many samples: the posterior mean sits at the least-squares optimum
        # up to the Monte Carlo error (and a small nonlinearity term, ≪ sd).
        z_ls = (mean - m.ls.theta[:, j]) / np.sqrt(mcse**2 + (0.1 * sd) ** 2)
        assert np.all(np.abs(z_ls) < 4.0), z_ls
    # σ: sensor noise plus quantization, per sample.
    sigma = m.mean[:, -1]
    assert np.all(np.abs(sigma / math.sqrt(STEP**2 + STEP**2 / 12) - 1.0) < 0.15)


def test_log_posterior_finite_at_optimum_and_minus_inf_outside(posterior):
    prior = posterior.prior
    assert prior.upper[1] == RATE / 2  # f_n below Nyquist
    lp = jax.jit(make_log_prob(DECAY_SPEC, prior))
    data = posterior.windows.data
    x, y, w = tuple(a[0] for a in data.x), data.y[0], data.w[0]
    ls = posterior.mcmc.ls
    z0 = jnp.concatenate([jnp.asarray(ls.theta[0]),
                          jnp.log(jnp.asarray([math.sqrt(ls.sse[0] / ls.dof[0])]))])
    assert np.isfinite(float(lp(z0, x, y, w)))
    bad = {
        "zeta < 0": z0.at[0].set(-0.01),
        "zeta > 1": z0.at[0].set(1.5),
        "f_n < 0": z0.at[1].set(-2.0),
        "f_n above Nyquist": z0.at[1].set(RATE),
        "infinite rate": z0.at[3].set(jnp.inf),
        "NaN constant": z0.at[2].set(jnp.nan),
        "huge log sigma": z0.at[5].set(1e4),
    }
    for what, z in bad.items():
        v = float(lp(z, x, y, w))
        assert v == -math.inf, (what, v)
    v = float(lp(z0, x, y.at[3].set(jnp.nan), w))
    assert v == -math.inf, v


def test_prior_describes_support():
    text = decay_prior(1000.0).describe()
    assert set(DECAY_NAMES) <= set(text)
    assert "(0, 1)" in text["zeta"] and "(0, 500)" in text["natural_frequency_Hz"]
    with pytest.raises(ValueError):
        decay_prior(0.0)


def test_predictive_one_batched_call_shape_and_coverage(posterior):
    pred = posterior.predictive(jax.random.key(13), n_draws=200)
    n_max = posterior.windows.data.y.shape[1]
    assert pred.angle_rad.shape == (2, 200, n_max)
    assert pred.mean_rad.shape == (2, 200, n_max)
    assert pred.band.shape == (2, 2, n_max)
    assert np.all(np.isfinite(pred.angle_rad))
    cov = pred.coverage()
    assert cov.shape == (2,)
    # Model right: about 95 % of the recorded samples inside the 95 % band.
    assert np.all((cov > 0.91) & (cov < 0.985)), cov
    # Times are the record's: the first fitted sample is at the window start.
    assert np.allclose(pred.time_s[:, 0], posterior.windows.t0_s)


def test_predictive_figure_is_drawn_by_the_report(posterior, tmp_path):
    # The figure lives with the reporting code (pamid.report), not on the result.
    from matplotlib.figure import Figure

    pred = posterior.predictive(jax.random.key(13), n_draws=50)
    fig = pamid.report.plot_decay_predictive(posterior, pred, 1)
    assert isinstance(fig, Figure) and list(tmp_path.iterdir()) == []
    assert fig.axes[0].get_title().startswith(f"trial {posterior.trials[1]}: ")
    record = (pred.time_s[1], pred.observed_rad[1])
    assert pamid.report.plot_decay_predictive(posterior, pred, 0, tmp_path / "p.png",
                                              title="trial 0", record=record) is None
    assert [p.name for p in tmp_path.iterdir()] == ["p.png"]  # no temporary file left
    assert (tmp_path / "p.png").stat().st_size > 10_000


def test_windows_start_on_a_sample_after_the_first_extremum():
    pairs = _pairs(jax.random.key(14))
    win = decay_windows(pairs)
    assert win.dt_s == pytest.approx(1.0 / RATE)
    assert win.encoder_step_rad == pytest.approx(STEP, rel=1e-6)
    for i, (t, _) in enumerate(pairs):
        assert np.any(np.isclose(t, win.t0_s[i]))
        assert win.n[i] == int((np.asarray(win.data.w[i]) > 0).sum())
