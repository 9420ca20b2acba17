"""The simulators: the linear oscillator against its closed form, and Sárosi's lifting mass
(eq. 2.2) against its static solution, SciPy's DOP853, finite differences and itself in a
loop; the ``pamid simulate lifting-mass`` command's JSON."""

from __future__ import annotations

import argparse
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import pamid
from pamid._commands.dynamics import register
from pamid._models._hysteresis import hysteresis_damping
from pamid._sim._lifting_mass import (
    LiftingMass,
    default_zeta,
    hysteresis_branches,
    lifting_mass_damping,
    lifting_mass_equilibrium,
    lifting_mass_force,
    lifting_mass_stiffness,
    simulate_lifting_mass,
    zeta_from_hysteresis,
)
from pamid._sim._oscillator import DampedOscillator, oscillator_response, simulate_oscillator

G = 9.81


# --------------------------------------------------------------------------------------
# Linear oscillator
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("zeta", [0.05, 0.5, 1.0, 2.0])
def test_oscillator_closed_form_solves_the_ode(zeta):
    """The closed form (any ζ, critical damping included) satisfies J·β̈ + c·β̇ + k·u = 0,
    its rate is its derivative, and it starts at the initial state."""
    osc = DampedOscillator.from_modal(zeta, 2.0, 0.46, equilibrium_rad=0.01)

    def angle(t):
        return oscillator_response(osc, 0.15, -0.3, t)[0]

    ts = jnp.linspace(0.0, 3.0, 7)
    a, r = oscillator_response(osc, 0.15, -0.3, ts)
    da = jax.jit(jax.vmap(jax.grad(angle)))(ts)
    dda = jax.jit(jax.vmap(jax.grad(jax.grad(angle))))(ts)
    residual = (osc.inertia_kg_m2 * dda + osc.damping_Nms_per_rad * da
                + osc.stiffness_Nm_per_rad * (a - osc.equilibrium_rad))
    np.testing.assert_allclose(da, r, atol=1e-10)
    np.testing.assert_allclose(residual, 0.0, atol=1e-8)
    np.testing.assert_allclose([a[0], r[0]], [0.15, -0.3], atol=1e-14)


def test_rk4_and_exact_simulation_match_the_analytic_oscillator():
    zeta = jnp.array([0.02, 0.05, 0.5, 1.0, 2.0])
    osc = DampedOscillator.from_modal(zeta, 2.5, 0.46, equilibrium_rad=-0.02)
    column = DampedOscillator.from_modal(zeta[:, None], 2.5, 0.46, equilibrium_rad=-0.02)
    t = np.arange(4001) / 1000.0
    ref_a, ref_r = oscillator_response(column, 0.15, 0.2, t)
    rk4 = simulate_oscillator(osc, 0.15, 0.2, duration_s=4.0, method="rk4")
    exact = simulate_oscillator(osc, 0.15, 0.2, duration_s=4.0)
    assert rk4.angle_rad.shape == (5, 4001)
    np.testing.assert_allclose(rk4.time_s, t, atol=1e-15)
    # RK4 at one step per millisecond: global error O(h⁴), ~1.6e-9 rad here (1e-8 of 0.15).
    assert np.abs(rk4.angle_rad - ref_a).max() < 5e-9
    assert np.abs(rk4.rate_rad_s - ref_r).max() < 1e-7
    assert np.abs(exact.angle_rad - ref_a).max() < 1e-13
    assert np.abs(exact.rate_rad_s - ref_r).max() < 1e-12
    # RK4 is fourth order: halving the step divides the error by ~16.
    err = [float(np.abs(simulate_oscillator(osc, 0.15, 0.2, duration_s=4.0, method="rk4",
                                            substeps=s).angle_rad - ref_a).max()) for s in (1, 2)]
    assert 12 < err[0] / err[1] < 20


def test_oscillator_bad_options_by_message():
    osc = DampedOscillator.from_modal(0.05, 2.0, 0.46)
    with pytest.raises(ValueError, match="method must be 'rk4' or 'exact'"):
        simulate_oscillator(osc, 0.1, duration_s=1.0, method="euler")
    with pytest.raises(ValueError, match="duration_s must be a positive"):
        simulate_oscillator(osc, 0.1, duration_s=-1.0)
    with pytest.raises(ValueError, match="substeps must be a positive integer"):
        simulate_oscillator(osc, 0.1, duration_s=1.0, method="rk4", substeps=0)


# --------------------------------------------------------------------------------------
# Lifting mass, Sárosi eq. 2.2
# --------------------------------------------------------------------------------------


def fig_3_6() -> LiftingMass:
    return LiftingMass(pamid.sarosi.table_3_1(), 400.0, 50.0, default_zeta(), 0.4, G)


def test_equilibrium_is_the_static_solution_of_eq_2_1():
    model = LiftingMass(pressure_kPa=jnp.array([300.0, 400.0, 500.0])[:, None],
                        mass_kg=jnp.array([30.0, 50.0, 70.0]), zeta=0.1)
    s = lifting_mass_equilibrium(model)
    assert s.shape == (3, 3)
    weight = jnp.broadcast_to(model.mass_kg * G, s.shape)
    np.testing.assert_allclose(lifting_mass_force(model, s), weight, rtol=1e-12)
    # By the closed form of eq. 2.1 at κ = 100·s/l0 (independent of pamid's clipping).
    p = np.array([3.0, 4.0, 5.0])[:, None]
    a1, a2, a3, a4, a5, a6 = np.asarray(pamid.sarosi.table_3_1().to_vector())
    k = 100.0 * np.asarray(s) / 0.4
    f = (a1 * p + a2) * np.exp(a3 * k) + a4 * k * p + a5 * p + a6
    np.testing.assert_allclose(f, np.asarray(weight), rtol=1e-12)
    # Restoring: the net upward force falls as the mass rises (stable equilibrium).
    assert bool(jnp.all(lifting_mass_stiffness(model, s) > 0))
    # Out of reach: 0 kPa cannot hold 10 t anywhere in the bracket.
    assert math.isnan(float(lifting_mass_equilibrium(LiftingMass(pressure_kPa=0.0,
                                                                 mass_kg=1e4))))


def test_fig_3_6_reproduction():
    """400 kPa, 50 kg, x0 = 50 mm (Table 3-1, l0 = 400 mm): the run settles on the static
    solution, 49.526 mm and m·g = 490.5 N; Sárosi reports 49.8 mm and 493 N."""
    model = fig_3_6()
    s_eq = float(lifting_mass_equilibrium(model))
    assert s_eq * 1e3 == pytest.approx(49.5257, abs=1e-3)
    run = simulate_lifting_mass(model, 0.050, duration_s=20.0)
    assert float(run.contraction_m[-1]) == pytest.approx(s_eq, abs=1e-9)
    assert float(run.force_N[-1]) == pytest.approx(50.0 * G, abs=1e-4)
    assert abs(s_eq * 1e3 - 49.8) < 0.3 and abs(float(run.force_N[-1]) - 493.0) < 3.0
    # The default ζ: the ±3 N/bar loop of the bundled data set, eq. 2.3–2.5.
    assert float(model.zeta) == pytest.approx(0.04565, abs=1e-4)


def test_damping_is_eq_2_10_with_the_stiffness_of_eq_2_9():
    model = fig_3_6()
    s = jnp.linspace(0.03, 0.07, 5)
    k = pamid.sarosi.sarosi_stiffness_eq_2_9(pamid.sarosi.table_3_1(), 4.0, 100.0 * s / 0.4, 0.4)
    np.testing.assert_allclose(lifting_mass_stiffness(model, s), k, rtol=1e-12)
    np.testing.assert_allclose(lifting_mass_damping(model, s),
                               model.zeta * 2.0 * jnp.sqrt(k * 50.0), rtol=1e-12)


def test_zeta_from_hysteresis_is_eq_2_5():
    muscle = pamid.sarosi.table_3_1()
    upper, lower = hysteresis_branches(muscle, per_bar_N=3.0, constant_N=5.0)
    z = zeta_from_hysteresis(upper, lower, 400.0, 0.0, 20.0)
    ref = hysteresis_damping(upper, lower, 4.0, 0.0, 20.0, 12.0, 0.4, 50.0)["zeta"]
    assert float(z) == pytest.approx(float(ref), rel=1e-12)
    # Loop area by hand: F_f − F_a = 2·(3·p + 5) N over 20 % of contraction.
    u0 = float(pamid.sarosi.sarosi_force_integral(upper, 4.0, 0.0, 20.0))
    assert float(z) == pytest.approx(2 * (3 * 4 + 5) * 20.0 / u0, rel=1e-12)
    no_loop = hysteresis_branches(muscle)
    assert float(zeta_from_hysteresis(*no_loop, 400.0, 0.0, 20.0)) == 0.0


def python_rhs(model: LiftingMass):
    a1, a2, a3, a4, a5, a6 = np.asarray(model.muscle.to_vector())
    p, m = float(model.pressure_kPa) / 100.0, float(model.mass_kg)
    zeta, l0 = float(model.zeta), float(model.l0_m)

    def rhs(t, y):
        k = 100.0 * y[0] / l0
        e = math.exp(a3 * k)
        force = max((a1 * p + a2) * e + a4 * k * p + a5 * p + a6, 0.0)
        stiff = -(100.0 / l0) * ((a1 * p + a2) * a3 * e + a4 * p)
        return [y[1], (force - zeta * 2 * math.sqrt(stiff * m) * y[1]) / m - G]

    return rhs


@pytest.mark.parametrize("pressure, mass, x0", [(400.0, 50.0, 0.050), (300.0, 30.0, 0.060),
                                                (500.0, 70.0, 0.040)])
def test_agrees_with_solve_ivp_dop853(pressure, mass, x0):
    model = LiftingMass(pressure_kPa=pressure, mass_kg=mass, zeta=0.08)
    run = simulate_lifting_mass(model, x0, 0.01, duration_s=3.0)
    ref = solve_ivp(python_rhs(model), (0.0, 3.0), [x0, 0.01], method="DOP853", rtol=1e-10,
                    atol=1e-12, t_eval=np.asarray(run.time_s))
    assert np.abs(np.asarray(run.contraction_m) - ref.y[0]).max() < 1e-9
    assert np.abs(np.asarray(run.velocity_m_per_s) - ref.y[1]).max() < 1e-7


def test_batch_equals_loop_and_vmap():
    pressure = jnp.array([300.0, 400.0, 500.0, 450.0])
    mass = jnp.array([30.0, 50.0, 70.0, 40.0])
    x0 = jnp.array([0.05, 0.045, 0.04, 0.055])
    batch = simulate_lifting_mass(LiftingMass(pressure_kPa=pressure, mass_kg=mass, zeta=0.1),
                                  x0, duration_s=1.0)
    assert batch.contraction_m.shape == (4, 1001)
    for i in range(4):
        one = simulate_lifting_mass(LiftingMass(pressure_kPa=pressure[i], mass_kg=mass[i],
                                                zeta=0.1), x0[i], duration_s=1.0)
        np.testing.assert_allclose(batch.contraction_m[i], one.contraction_m, rtol=0,
                                   atol=1e-14)
        np.testing.assert_allclose(batch.force_N[i], one.force_N, rtol=1e-13)

    def final(p, m, x):
        model = LiftingMass(pressure_kPa=p, mass_kg=m, zeta=0.1)
        return simulate_lifting_mass(model, x, duration_s=1.0).contraction_m[-1]

    np.testing.assert_allclose(jax.jit(jax.vmap(final))(pressure, mass, x0),
                               batch.contraction_m[:, -1], atol=1e-14)


def test_gradients_match_finite_differences():
    def final(theta):
        p, m, zeta, x0 = theta
        model = LiftingMass(pressure_kPa=p, mass_kg=m, zeta=zeta)
        return simulate_lifting_mass(model, x0, duration_s=0.8).contraction_m[-1]

    theta = jnp.array([400.0, 50.0, 0.05, 0.050])
    grad = jax.grad(final)(theta)
    steps = np.array([1e-3, 1e-4, 1e-6, 1e-7])
    fd = [(final(theta.at[i].add(h)) - final(theta.at[i].add(-h))) / (2 * h)
          for i, h in enumerate(steps)]
    np.testing.assert_allclose(grad, fd, rtol=1e-5)
    # The equilibrium's implicit derivative: ds/dm = g / (∂F/∂s).
    model = fig_3_6()
    s = lifting_mass_equilibrium(model)
    dsdm = jax.grad(lambda m: lifting_mass_equilibrium(LiftingMass(mass_kg=m)))(50.0)
    assert float(dsdm) == pytest.approx(-G / float(lifting_mass_stiffness(model, s)), rel=1e-9)


# --------------------------------------------------------------------------------------
# pamid simulate lifting-mass
# --------------------------------------------------------------------------------------


def run_cli(argv, capsys):
    parser = argparse.ArgumentParser(prog="pamid")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    code = args.func(args)
    return code, capsys.readouterr()


def test_cli_lifting_mass_json(tmp_path, capsys):
    out = tmp_path / "out"
    code, cap = run_cli(["simulate", "lifting-mass", "--pressure-kPa", "400", "--mass-kg", "50",
                         "--x0-mm", "50", "--json", "--out", str(out)], capsys)
    assert code == 0
    payload = json.loads(cap.out)  # exactly one JSON object
    for key in ("final_force_N", "final_displacement_mm", "equilibrium_displacement_mm",
                "equilibrium_force_N", "zeta", "zeta_source", "damping_at_equilibrium_Ns_per_m",
                "stiffness_at_equilibrium_N_per_m", "settling", "sarosi_fig_3_6", "plots"):
        assert key in payload, key
    assert payload["final_displacement_mm"] == pytest.approx(49.5257, abs=2e-3)
    assert payload["final_force_N"] == pytest.approx(490.5, abs=0.1)
    assert payload["equilibrium_force_N"] == pytest.approx(490.5)
    assert payload["settling"]["settled"] is True
    assert (out / "lifting_mass.png").stat().st_size > 10_000
    assert json.loads((out / "lifting_mass.json").read_text())["zeta"] == payload["zeta"]
    assert cap.err == ""  # --json: no progress lines


def test_cli_lifting_mass_text_and_constant_zeta(capsys):
    code, cap = run_cli(["simulate", "lifting-mass", "--pressure-kPa", "300", "--mass-kg", "30",
                         "--x0-mm", "40", "--zeta", "0.3", "--duration-s", "3"], capsys)
    assert code == 0
    assert "ζ = 0.3 (given (--zeta))" in cap.out
    assert "static solution" in cap.out and "[pamid] simulating" in cap.err


@pytest.mark.parametrize("argv, message", [
    (["--mass-kg", "-5"], "--mass-kg must be positive"),
    (["--duration-s", "0"], "--duration-s must be positive"),
    (["--x0-mm", "300"], "--x0-mm must lie in"),
    (["--mass-kg", "5000", "--pressure-kPa", "0"], "no static equilibrium"),
])
def test_cli_lifting_mass_bad_options(argv, message, capsys):
    base = {"--pressure-kPa": "400", "--mass-kg": "50", "--x0-mm": "50"}
    for flag, value in zip(argv[::2], argv[1::2], strict=True):
        base[flag] = value
    args = ["simulate", "lifting-mass"] + [x for kv in base.items() for x in kv]
    with pytest.raises(ValueError, match=message):
        run_cli(args, capsys)
