"""Free decays with candidate effects: the exact JAX Coulomb-friction decay against pamid's
NumPy reference and the linear oscillator, its gradients against finite differences, and the
batched, cross-validated fit of effect sets on virtual decays with known answers."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pamid._decays._analysis import (
    find_extrema,
    fit_decay_trajectories,
    pooled_decrement_estimate,
)
from pamid._decays._coulomb import (
    FIT_NAMES,
    coulomb_response,
    fit_decay_models,
    fold_labels,
)
from pamid._sim._oscillator import DampedOscillator, oscillator_response
from pamid._virtual._decay import DecayProtocol, coulomb_decay, simulate_decays

J = 0.46  # kg·m², Cullinan's arm with two 1.2 kg weights
K = 88.0  # N·m/rad, Cullinan Fig. 7
OMEGA = math.sqrt(K / J)  # ≈ 13.8 rad/s, f_n ≈ 2.2 Hz
STEP = 2 * math.pi / 4096  # 12-bit absolute encoder (CUI AMT203)
EQ = 0.0123
T = np.arange(6001) / 1000.0
SETS = [(), ("coulomb_friction",), ("drift",), ("coulomb_friction", "drift")]


def numpy_reference(zeta, tc, deflection, rate0, t=T):
    damping = 2.0 * zeta * math.sqrt(K * J)  # Cullinan eq. 11
    return coulomb_decay(J, K, damping, EQ, tc, EQ + deflection, rate0, t)


def jax_response(zeta, tc, deflection, rate0, t=T, **kw):
    return np.asarray(coulomb_response(zeta, OMEGA, EQ + deflection, rate0, EQ, tc / K, t, **kw))


# --------------------------------------------------------------------------------------
# The model
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "zeta, tc, deflection, rate0",
    [
        (0.05, 0.1, 0.15, 0.0),  # Cullinan's arm, the friction of test_decay.py
        (0.02, 0.5, 0.10, 0.0),  # light damping, strong friction: sticks after ~1.9 s
        (0.20, 0.3, -0.12, 0.4),  # released moving (away from the centre first)
        (0.05, 0.1, 0.15, -0.5),  # released moving towards the centre
        (0.00, 0.5, 0.10, 0.0),  # pure Coulomb friction: sticks after 7 half cycles
        (0.10, 2.0, 0.10, 0.0),  # sticks in the third half cycle
        (0.10, 10.0, 0.10, 0.0),  # k·|β − β_eq| ≤ T_c at release: never moves
    ],
)
def test_equals_the_numpy_half_cycle_reference(zeta, tc, deflection, rate0):
    expected = numpy_reference(zeta, tc, deflection, rate0)
    got = jax_response(zeta, tc, deflection, rate0)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-10)


def test_sticks_where_the_reference_sticks():
    """Sticking before the end: both hold the same angle from the same sample on."""
    expected = numpy_reference(0.02, 0.5, 0.10, 0.0)
    got = jax_response(0.02, 0.5, 0.10, 0.0)
    still = np.nonzero(np.diff(expected) == 0.0)[0]
    first = still[0]
    assert 500 < first < 3000  # stuck well before the end of the 6 s record
    assert np.all(np.diff(expected[first:]) == 0.0) and np.all(np.diff(got[first + 1 :]) == 0.0)
    assert abs(got[-1] - EQ) <= 0.5 / K  # inside the dead band k·|β − β_eq| ≤ T_c


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.5, 1.0, 1.5])
def test_no_friction_is_the_linear_oscillator(zeta):
    osc = DampedOscillator.from_modal(zeta, OMEGA / (2 * math.pi), J, equilibrium_rad=EQ)
    expected = np.asarray(oscillator_response(osc, EQ + 0.15, 0.3, T)[0])
    np.testing.assert_allclose(jax_response(zeta, 0.0, 0.15, 0.3), expected, rtol=0, atol=1e-12)


def test_drift_moves_the_centre_of_the_linear_decay():
    """β(t) = β_eq + r·t + u(t), u the linear decay from u(0) = β0 − β_eq, u̇(0) = β̇0 − r."""
    r = 0.01
    osc = DampedOscillator.from_modal(0.05, OMEGA / (2 * math.pi), J, equilibrium_rad=0.0)
    expected = EQ + r * T + np.asarray(oscillator_response(osc, 0.15, 0.3 - r, T)[0])
    got = np.asarray(coulomb_response(0.05, OMEGA, EQ + 0.15, 0.3, EQ, 0.0, T, drift_rad_s=r))
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)


def test_too_few_half_cycles_give_nan_not_a_wrong_angle():
    got = jax_response(0.05, 0.1, 0.15, 0.0, max_half_cycles=4)  # 4 half cycles ≈ 0.9 s
    assert np.isfinite(got[:800]).all() and np.isnan(got[1000:]).all()


def test_vmap_over_parameter_sets_equals_a_loop():
    zetas = jnp.array([0.02, 0.05, 0.1])
    shifts = jnp.array([0.0, 0.1, 0.5]) / K
    batch = jax.vmap(lambda z, s: coulomb_response(z, OMEGA, EQ + 0.1, 0.0, EQ, s, T[:3000]))(
        zetas, shifts
    )
    for i in range(3):
        np.testing.assert_allclose(
            batch[i],
            coulomb_response(zetas[i], OMEGA, EQ + 0.1, 0.0, EQ, shifts[i], T[:3000]),
            rtol=0,
            atol=1e-15,
        )


def _loss(theta, t):
    zeta, omega, a0, r0, eq, shift, drift = theta
    return jnp.sum(coulomb_response(zeta, omega, a0, r0, eq, shift, t, drift_rad_s=drift) ** 2)


_grad = jax.jit(jax.grad(_loss))


@pytest.mark.parametrize("shift", [0.0, 0.1 / K])
def test_gradient_matches_finite_differences(shift):
    """Every parameter, with and without friction (at u_c = 0 too: fits start there), over
    samples that include half-cycle boundaries but no sticking."""
    t = jnp.linspace(0.01, 2.5, 200)
    theta = jnp.array([0.05, OMEGA, EQ + 0.15, -0.02, EQ, shift, 1e-3])
    grad = np.asarray(_grad(theta, t))
    assert np.isfinite(grad).all()
    for i, name in enumerate(FIT_NAMES):
        h = 1e-6 * max(abs(float(theta[i])), 1e-2)
        up = float(_loss(theta.at[i].add(h), t))
        down = float(_loss(theta.at[i].add(-h), t))
        fd = (up - down) / (2 * h)
        assert grad[i] == pytest.approx(fd, rel=1e-5, abs=1e-8), name


def test_gradient_is_finite_when_the_arm_sticks():
    t = jnp.linspace(0.01, 2.5, 200)
    theta = jnp.array([0.10, OMEGA, EQ + 0.1, 0.0, EQ, 2.0 / K, 0.0])  # sticks at ~0.6 s
    assert np.ptp(np.asarray(coulomb_response(*theta[:6], t))[-100:]) == 0.0
    assert np.isfinite(np.asarray(_grad(theta, t))).all()


# --------------------------------------------------------------------------------------
# Cross-validation folds
# --------------------------------------------------------------------------------------


def test_folds_are_interleaved_contiguous_blocks():
    labels = fold_labels(1003, 5)
    counts = np.bincount(labels)
    assert counts.sum() == 1003 and set(counts.tolist()) <= {200, 201}  # every sample once
    starts = np.r_[0, np.nonzero(np.diff(labels))[0] + 1]
    assert len(starts) == 20 and labels[starts].tolist() == [0, 1, 2, 3, 4] * 4
    shuffled = fold_labels(1003, 5, jax.random.key(1))
    assert np.bincount(shuffled, minlength=5).min() >= 4 * 50  # four blocks per fold
    assert not np.array_equal(shuffled, labels)
    with pytest.raises(ValueError, match="too short for 5 folds"):
        fold_labels(19, 5)


# --------------------------------------------------------------------------------------
# The batched fit on virtual decays
# --------------------------------------------------------------------------------------


def trials(frame):
    out = []
    for _, g in frame.groupby("trial", sort=True):
        t, y = g["time_s"].to_numpy(), g["angle_rad"].to_numpy()
        e = find_extrema(t, y)
        out.append((t, y, e, pooled_decrement_estimate([e], J)))
    return out


def virtual(coulomb, seed, **protocol):
    osc = DampedOscillator.from_modal(0.05, OMEGA / (2 * math.pi), J, equilibrium_rad=EQ)
    settings = {
        "n_trials": 3,
        "deflections_deg": (9.0, 6.0, -8.0),
        "duration_s": 3.0,
        "sample_rate_Hz": 500.0,
        "noise_sd_rad": 0.5 * STEP,
        **protocol,
    }
    return simulate_decays(jax.random.key(seed), osc, DecayProtocol(**settings), coulomb_Nm=coulomb)


DRIFT = 2e-3  # rad/s, ≈ 4 encoder steps over the record
EXACT = {
    "zeta": 0.04,
    "omega_n_rad_s": OMEGA,
    "angle0_rad": EQ + 0.14,
    "rate0_rad_s": 0.0,
    "equilibrium_rad": EQ,
    "coulomb_shift_rad": 0.08 / K,
    "drift_rad_s": -5e-3,
}


def drifting(seed=7):
    """A friction-free decay read by an encoder whose zero drifts at DRIFT (the drift added
    before the noise and the quantization, as the virtual bench adds those)."""
    frame = virtual(0.0, seed, n_trials=1, encoder_bits=None, noise_sd_rad=0.0)
    noise = 0.5 * STEP * np.asarray(jax.random.normal(jax.random.key(seed), (len(frame),)))
    angle = frame["angle_rad"] + DRIFT * frame["time_s"] + noise
    return frame.assign(angle_rad=np.round(angle / STEP) * STEP)


def exact_trial():
    """Noise-free, unquantized samples of the model itself with friction and drift."""
    t = np.arange(1501) / 500.0
    y = np.asarray(
        coulomb_response(*(EXACT[n] for n in FIT_NAMES[:6]), t, drift_rad_s=EXACT["drift_rad_s"])
    )
    e = find_extrema(t, y)
    return [(t, y, e, pooled_decrement_estimate([e], J))]


@pytest.fixture(scope="module")
def fitted():
    """One batched call: 3 trials with T_c = 0.1 N·m, 3 without, 1 drifting, 1 exact."""
    data = trials(virtual(0.1, 5)) + trials(virtual(0.0, 6)) + trials(drifting()) + exact_trial()
    columns = [list(c) for c in zip(*data, strict=True)]
    return data, {f.effects: f for f in fit_decay_models(*columns, J, SETS)}


FRICTION, NO_FRICTION, DRIFTING, EXACT_TRIAL = [0, 1, 2], [3, 4, 5], 6, 7


def test_every_lane_converged_with_the_layout_asked_for(fitted):
    _, fits = fitted
    for effects, fit in fits.items():
        assert fit.effects == effects
        for trial in fit.trials:
            assert trial.converged and trial.cv_converged
            assert trial.n_params == 5 + len(effects)
            assert trial.n == len(trial.time_s) == len(trial.residual_rad)
            assert trial.sse == pytest.approx(float(np.sum(trial.residual_rad**2)), rel=1e-12)
            assert trial.rmse_rad == pytest.approx(math.sqrt(trial.sse / trial.n))
            if "coulomb_friction" not in effects:
                assert trial.params["coulomb_Nm"] == 0.0 and "coulomb_Nm" not in trial.params_ci95
            if "drift" not in effects:
                assert trial.params["drift_rad_s"] == 0.0 and "drift_rad_s" not in (
                    trial.params_ci95
                )


def test_exact_model_data_give_back_the_parameters(fitted):
    """On noise-free samples of the model itself, friction + drift fit to the truth."""
    _, fits = fitted
    trial = fits[("coulomb_friction", "drift")].trials[EXACT_TRIAL]
    assert trial.rmse_rad < 1e-9
    # The window starts at the first extremum (t0 > 0): compare the parameters that do
    # not depend on where the clock starts.
    for name in ("zeta", "omega_n_rad_s", "coulomb_shift_rad", "drift_rad_s"):
        assert trial.params[name] == pytest.approx(EXACT[name], rel=1e-6, abs=1e-9), name
    centre_at_t0 = EXACT["equilibrium_rad"] + EXACT["drift_rad_s"] * trial.t0_s
    assert trial.params["equilibrium_rad"] == pytest.approx(centre_at_t0, abs=1e-9)
    assert fits[()].trials[EXACT_TRIAL].rmse_rad > 1e3 * trial.rmse_rad


def test_hidden_coulomb_friction_is_recovered(fitted):
    _, fits = fitted
    base, coulomb = fits[()], fits[("coulomb_friction",)]
    for i in FRICTION:
        low, high = coulomb.trials[i].params_ci95["coulomb_Nm"]
        assert low < 0.1 < high and high - low < 0.02
        assert coulomb.trials[i].sse < 0.5 * base.trials[i].sse
        assert coulomb.trials[i].cv_rmse_rad < 0.8 * base.trials[i].cv_rmse_rad


def test_no_friction_is_not_found_where_there_is_none(fitted):
    _, fits = fitted
    base, coulomb = fits[()], fits[("coulomb_friction",)]
    for i in NO_FRICTION:
        low, high = coulomb.trials[i].params_ci95["coulomb_Nm"]
        assert low < 0.0 < high and high - low < 0.01
        assert coulomb.trials[i].cv_rmse_rad > 0.995 * base.trials[i].cv_rmse_rad


def test_drift_is_recovered(fitted):
    _, fits = fitted
    trial = fits[("drift",)].trials[DRIFTING]
    low, high = trial.params_ci95["drift_rad_s"]
    assert low < DRIFT < high
    assert trial.cv_rmse_rad < fits[()].trials[DRIFTING].cv_rmse_rad
    for effects, trials in ((("drift",), NO_FRICTION), (SETS[3], FRICTION)):
        for i in trials:  # no drift there: with the right model, intervals about 0
            low, high = fits[effects].trials[i].params_ci95["drift_rad_s"]
            assert low < 0.0 < high


def test_one_trial_alone_equals_its_lane_in_the_batch(fitted):
    data, fits = fitted
    columns = [list(c) for c in zip(*data, strict=True)]
    base = fit_decay_trajectories(*columns, J)  # as fit_decay_models made it (compiled)
    alone = fit_decay_models(*[[c] for c in data[FRICTION[0]]], J, SETS, baseline=base[:1])
    for fit in alone:
        a, b = fit.trials[0], fits[fit.effects].trials[FRICTION[0]]
        for name in FIT_NAMES:
            assert a.params[name] == pytest.approx(b.params[name], rel=1e-9, abs=1e-15), name
        assert a.sse == pytest.approx(b.sse, rel=1e-9)
        assert a.cv_rmse_rad == pytest.approx(b.cv_rmse_rad, rel=1e-9)
        np.testing.assert_allclose(a.residual_rad, b.residual_rad, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "sets, message",
    [
        ([("friction",)], r"unknown decay effect 'friction'; accepted effects: coulomb_friction"),
        ([("covariate:temperature_C",)], r"covariates are not available for decays"),
        ([("drift", "drift")], r"names an effect twice"),
        ([], r"at least one effect set"),
        (["drift"], r"a tuple of effect names, e.g. \('drift',\)"),
    ],
)
def test_bad_effect_sets_by_message(sets, message):
    with pytest.raises(ValueError, match=message):
        fit_decay_models([], [], [], [], J, sets)


def test_baseline_of_another_length_by_message(fitted):
    data, _ = fitted
    with pytest.raises(ValueError, match=r"baseline holds 0 fits for 1 trials"):
        fit_decay_models(*[[c] for c in data[0]], J, SETS, baseline=[])
