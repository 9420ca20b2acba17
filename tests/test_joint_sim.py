"""The antagonistic joint with its arm under gravity, valves shut (pamid._sim._joint_sim)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import pamid
from pamid._models._cullinan_presets import traditional_volume
from pamid._sim._joint_sim import (
    JointArm,
    gravity_moment_Nm,
    joint_arm_torque_Nm,
    joint_equilibrium_rad,
    simulate_joint_arm,
)

J = 0.46  # kg·m², Cullinan eq. 12 with two 1.2 kg masses
M = 11.0  # N·m, Cullinan Fig. 6: "11 Nm static torque at 0 rad"


def make_arm(p_sum_stiffness=60.0, polytropic_n=1.0, gravity=M, g_damper=None):
    muscle = pamid.cullinan.traditional_pam()
    if g_damper is not None:
        muscle = eqx.tree_at(lambda m: m.G, muscle, jnp.asarray(g_damper, float))
    geometry = pamid.cullinan.traditional_joint()
    p1, p2 = pamid.cullinan.pressures_for_torque_stiffness_kPa(muscle, geometry, 0.0, gravity,
                                                      p_sum_stiffness)
    return JointArm(muscle, muscle, geometry, traditional_volume(), J, gravity, 0.0, p1, p2,
                    polytropic_n=polytropic_n)


def test_gravity_moment_of_cullinans_arm():
    # Two 1.2 kg masses at 0.45 m and a 0.3 kg, 0.5 m rod: 9.81·(0.075 + 1.08) N·m.
    assert float(gravity_moment_Nm(0.3, 0.5, 2.4, 0.45)) == pytest.approx(9.81 * 1.155)


def test_rk4_matches_dop853():
    arm = make_arm(polytropic_n=1.4)
    run = simulate_joint_arm(arm, 0.12, -0.3, duration_s=2.0, sample_rate_Hz=1000.0)
    torque = jax.jit(lambda b, v: joint_arm_torque_Nm(arm, b, v))

    def rhs(_, y):
        return [y[1], float(torque(y[0], y[1])) / J]

    t = np.asarray(run.time_s)
    ref = solve_ivp(rhs, (0.0, 2.0), [0.12, -0.3], method="DOP853", rtol=1e-10, atol=1e-12,
                    t_eval=t)
    err = np.max(np.abs(np.asarray(run.angle_rad) - ref.y[0]))
    assert err < 1e-8, err
    assert np.ptp(np.asarray(run.angle_rad)) > 0.1  # it really moved


def test_settles_at_the_static_solution_batched():
    # Two arms (stiffnesses 40 and 80 N·m/rad) × three releases, one call; more G to settle.
    arms = jax.vmap(lambda k: make_arm(k, g_damper=1.5))(jnp.array([40.0, 80.0]))
    arms = jax.tree_util.tree_map(lambda x: x[:, None], arms)
    angle0 = jnp.array([[0.15, -0.1, 0.05]])
    run = simulate_joint_arm(arms, angle0, duration_s=6.0, sample_rate_Hz=500.0)
    assert run.angle_rad.shape == (2, 3, 3001)
    eq = joint_equilibrium_rad(arms)
    assert eq.shape == (2, 1) and np.all(np.isfinite(eq))
    np.testing.assert_allclose(run.angle_rad[..., -1], jnp.broadcast_to(eq, (2, 3)), atol=1e-9)
    np.testing.assert_allclose(run.rate_rad_s[..., -1], 0.0, atol=1e-8)
    # Torque balance with pamid's own closed-system torque (valves shut at 0 rad).
    for i in range(2):
        arm = jax.tree_util.tree_map(lambda x, i=i: x[i, 0], arms)
        beta = float(eq[i, 0])
        sealed = pamid.cullinan.closed_system_torque_Nm(arm.muscle1, arm.muscle2, arm.geometry,
                                               arm.volume, 0.0, arm.p1_kPa, arm.p2_kPa, beta)
        assert float(sealed) == pytest.approx(M * np.cos(beta), abs=1e-9)
    # Sealed pressures: at the seal angle they are the set pressures; later they follow V.
    arm0 = jax.tree_util.tree_map(lambda x: x[0, 0], arms)
    run0 = simulate_joint_arm(arm0, 0.0, duration_s=0.01)
    assert float(run0.pressure1_kPa[0]) == pytest.approx(float(arm0.p1_kPa), rel=1e-9)
    assert float(run0.pressure2_kPa[0]) == pytest.approx(float(arm0.p2_kPa), rel=1e-9)


def test_batch_equals_single_runs():
    arm = make_arm()
    angle0 = jnp.array([0.1, -0.05, 0.2])
    batch = simulate_joint_arm(arm, angle0, 0.0, duration_s=1.0)
    for i, a0 in enumerate(angle0):
        one = simulate_joint_arm(arm, a0, 0.0, duration_s=1.0)
        np.testing.assert_allclose(batch.angle_rad[i], one.angle_rad, rtol=0, atol=1e-13)


def test_gradients_match_finite_differences():
    arm = make_arm()

    def final_angle(p1, g_damper, angle0):
        a = eqx.tree_at(lambda m: (m.p1_kPa, m.muscle1), arm,
                        (p1, eqx.tree_at(lambda m: m.G, arm.muscle1, g_damper)))
        return simulate_joint_arm(a, angle0, duration_s=0.4, sample_rate_Hz=250.0
                                  ).angle_rad[-1]

    x = (arm.p1_kPa, jnp.asarray(0.3), jnp.asarray(0.1))
    grads = jax.jit(jax.grad(final_angle, argnums=(0, 1, 2)))(*x)
    final_angle = jax.jit(final_angle)
    for i, h in enumerate((1e-3, 1e-5, 1e-6)):
        up = list(x)
        dn = list(x)
        up[i] = x[i] + h
        dn[i] = x[i] - h
        fd = (final_angle(*up) - final_angle(*dn)) / (2 * h)
        assert float(grads[i]) == pytest.approx(float(fd), rel=1e-5, abs=1e-9), i
    # Equilibrium: implicit-function gradient against finite differences.
    deq = jax.grad(lambda p: joint_equilibrium_rad(eqx.tree_at(lambda m: m.p1_kPa, arm, p)))(
        arm.p1_kPa)
    h = 1e-3
    fd = (joint_equilibrium_rad(eqx.tree_at(lambda m: m.p1_kPa, arm, arm.p1_kPa + h))
          - joint_equilibrium_rad(eqx.tree_at(lambda m: m.p1_kPa, arm, arm.p1_kPa - h))) / (2 * h)
    assert float(deq) == pytest.approx(float(fd), rel=1e-6)
    assert float(deq) > 0  # more pressure in muscle 1 turns the joint towards +β


def test_bad_substeps():
    with pytest.raises(ValueError, match="substeps"):
        simulate_joint_arm(make_arm(), 0.0, substeps=0)
