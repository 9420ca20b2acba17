"""G (Cullinan eq. 3) fitted through the joint simulator to decays (pamid._decays._joint_fit)."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import pamid
from pamid._decays._joint_fit import fit_joint_decays
from pamid._models._cullinan_presets import traditional_volume
from pamid._sim._joint_sim import JointArm, joint_equilibrium_rad, simulate_joint_arm

J = 0.46  # kg·m², Cullinan eq. 12 with two 1.2 kg masses
M = 11.0  # N·m, Cullinan Fig. 6
G_TRUE = 0.3  # N·s/mm, the traditional preset
ENCODER_STEP = 2.0 * np.pi / 4096  # one step of a 12-bit encoder


def make_arm(g=G_TRUE):
    muscle = eqx.tree_at(lambda m: m.G, pamid.cullinan.traditional_pam(), jnp.asarray(g, float))
    geometry = pamid.cullinan.traditional_joint()
    p1, p2 = pamid.cullinan.pressures_for_torque_stiffness_kPa(muscle, geometry, 0.0, M, 60.0)
    return JointArm(muscle, muscle, geometry, traditional_volume(), J, M, 0.0, p1, p2)


@pytest.fixture(scope="module")
def decays():
    arm = make_arm()
    eq = float(joint_equilibrium_rad(arm))
    angle0 = eq + np.deg2rad([3.0, 5.0, 8.0])
    run = simulate_joint_arm(arm, jnp.asarray(angle0), duration_s=3.0, sample_rate_Hz=200.0)
    rng = np.random.default_rng(20190520)
    y = np.asarray(run.angle_rad) + ENCODER_STEP * rng.standard_normal(run.angle_rad.shape)
    y = np.round(y / ENCODER_STEP) * ENCODER_STEP  # the encoder reads whole steps
    # Wrong start: G doubled (the arm given to the fit carries it), angles 0.6° off.
    start = {"beta0": angle0 + 0.01}
    fit = fit_joint_decays(make_arm(2.0 * G_TRUE), run.time_s, y, start=start)
    return np.asarray(run.time_s), y, angle0, start, fit


def test_recovers_g_from_a_wrong_start(decays):
    _, _, angle0, _, fit = decays
    assert fit.names == ("G", "beta0", "beta_dot0")
    assert fit.converged.all()
    assert np.all(np.isfinite(fit.se)) and np.all(fit.se > 0)
    assert np.all(np.isfinite(fit.ci95))
    g, ci = fit.column("G"), fit.ci95[:, 0]
    np.testing.assert_allclose(g, G_TRUE, rtol=0.05)
    assert np.all((ci[:, 0] <= G_TRUE) & (G_TRUE <= ci[:, 1])), ci
    np.testing.assert_allclose(fit.column("beta0"), angle0, atol=3 * ENCODER_STEP)
    # Residuals at the noise level (Gaussian sd one step plus the reading's rounding).
    assert np.all(fit.rmse_rad < 1.3 * ENCODER_STEP)
    # Pooled G: inside the trials' range of values, narrower interval, covers the truth.
    assert fit.G_pooled == pytest.approx(G_TRUE, rel=0.05)
    lo, hi = fit.G_pooled_ci95
    assert lo <= G_TRUE <= hi
    assert hi - lo < np.min(ci[:, 1] - ci[:, 0])
    assert fit.to_dict()["trials"][0]["converged"]


def test_batch_equals_single_trial_fits(decays):
    t, y, _, start, fit = decays
    arm = make_arm(2.0 * G_TRUE)
    for i in range(y.shape[0]):
        one = fit_joint_decays(arm, t, y[i], start={"beta0": start["beta0"][i]})
        assert one.converged[0]
        np.testing.assert_allclose(one.values[0], fit.values[i], rtol=1e-7, atol=1e-10)
        np.testing.assert_allclose(one.se[0], fit.se[i], rtol=1e-6)


def test_bad_arguments():
    arm = make_arm()
    t = np.linspace(0.0, 1.0, 11)
    y = np.zeros((2, 11))
    with pytest.raises(ValueError, match="must include"):
        fit_joint_decays(arm, t, y, fit=("G", "beta0"))
    with pytest.raises(ValueError, match="distinct parameters"):
        fit_joint_decays(arm, t, y, fit=("G", "beta0", "beta_dot0", "k"))
    with pytest.raises(ValueError, match="uniformly"):
        fit_joint_decays(arm, t**2, y)
    with pytest.raises(ValueError, match="method"):
        fit_joint_decays(arm, t, y, method="newton")
