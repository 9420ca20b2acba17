"""Sárosi's force law (eq. 2.1), its stiffness (eq. 2.7–2.9), its inverse, and the damping
from a hysteresis loop (eq. 2.3–2.10), each against a known answer: numbers worked out by
hand from Table 3-1, closed forms, finite differences, and numerical quadrature."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate
from sarosi_np import force_np

import pamid

# Table 3-1, as printed in the summary (p in bar, κ in %, F in N).
A1, A2, A3 = -4.35572689, 281.2237983, -0.32866293
A4, A5, A6 = -9.27034945, 302.2010663, -263.691854
L0_M = 0.4  # DMSP-20-400N


def force_by_hand(p, k):
    """Eq. 2.1 in plain Python."""
    return (A1 * p + A2) * math.exp(A3 * k) + A4 * k * p + A5 * p + A6



# ----------------------------------------------------------------------------------------
# Table 3-1 and eq. 2.1
# ----------------------------------------------------------------------------------------


def test_float64_is_on():
    assert jax.config.jax_enable_x64
    assert pamid.sarosi.sarosi_force(pamid.sarosi.table_3_1(), 3.0, 10.0).dtype == jnp.float64


def test_table_3_1_matches_the_summary(theta31, ci31):
    np.testing.assert_array_equal(pamid.sarosi.table_3_1().to_vector(), theta31)
    for j, name in enumerate(pamid.Sarosi.names):
        assert pamid.sarosi.TABLE_3_1[name]["value"] == theta31[j]
        assert tuple(pamid.sarosi.TABLE_3_1[name]["ci95"]) == tuple(ci31[j])
    assert pamid.sarosi.TABLE_3_1_L0_MM == 400.0


def test_sarosi_vector_round_trip(theta31):
    prm = pamid.Sarosi.from_vector(theta31)
    assert float(prm.a3) == A3
    np.testing.assert_array_equal(prm.to_vector(), theta31)
    batch = pamid.Sarosi.from_vector(np.tile(theta31, (4, 1)))
    assert batch.a1.shape == (4,)
    assert batch.to_vector().shape == (4, 6)


@pytest.mark.parametrize(
    ("p_bar", "kappa_pct", "expected_N"),
    [
        (0.0, 0.0, 17.5319443),  # a2 + a6
        (5.0, 0.0, 1506.75864135),  # (5·a1 + a2) + 5·a5 + a6
        (3.0, 10.0, None),
        (1.0, 25.0, None),
        (6.0, 3.5, None),
    ],
)
def test_force_eq_2_1_by_hand(sarosi31, p_bar, kappa_pct, expected_N):
    by_hand = force_by_hand(p_bar, kappa_pct)
    if expected_N is not None:
        assert by_hand == pytest.approx(expected_N, rel=1e-13)
    got = float(pamid.sarosi.sarosi_force(sarosi31, p_bar, kappa_pct))
    assert got == pytest.approx(by_hand, rel=1e-13, abs=1e-11)


def test_force_broadcasts_over_pressure_and_contraction(sarosi31):
    p = np.array([1.0, 3.0, 5.0])[:, None]
    k = np.linspace(0.0, 25.0, 7)[None, :]
    got = np.asarray(pamid.sarosi.sarosi_force(sarosi31, p, k))
    assert got.shape == (3, 7)
    expected = [[force_by_hand(pi, ki) for ki in k[0]] for pi in p[:, 0]]
    np.testing.assert_allclose(got, expected, rtol=1e-13)


def test_force_slope_is_eq_2_8(sarosi31):
    for p, k in [(0.0, 0.0), (2.0, 7.0), (5.0, 20.0)]:
        eq_2_8 = (A1 * p + A2) * A3 * math.exp(A3 * k) + A4 * p
        slope = float(pamid.sarosi.sarosi_force_slope(sarosi31, p, k))
        assert slope == pytest.approx(eq_2_8, rel=1e-13)
        autodiff = jax.grad(pamid.sarosi.sarosi_force, argnums=2)(sarosi31, p, k)
        assert float(autodiff) == pytest.approx(eq_2_8, rel=1e-13)


# ----------------------------------------------------------------------------------------
# Stiffness, eq. 2.7–2.9
# ----------------------------------------------------------------------------------------

P_GRID, K_GRID = np.meshgrid(np.linspace(0.0, 6.0, 13), np.linspace(0.0, 30.0, 31), indexing="ij")


def test_stiffness_autodiff_equals_eq_2_9_on_a_grid(sarosi31):
    auto = np.asarray(pamid.sarosi.sarosi_stiffness(sarosi31, P_GRID, K_GRID, L0_M))
    closed = np.asarray(pamid.sarosi.sarosi_stiffness_eq_2_9(sarosi31, P_GRID, K_GRID, L0_M))
    assert auto.shape == closed.shape == P_GRID.shape
    np.testing.assert_allclose(auto, closed, rtol=1e-12)


def test_stiffness_by_hand(sarosi31):
    # k = dF/dl = −(100/l0)·[(a1·p + a2)·a3·e^(a3·κ) + a4·p], at p = 5 bar, κ = 0, l0 = 0.4 m.
    # (5·a1 + a2)·a3 = 259.44516385 × (−0.32866293) = −85.27002…; a4·5 = −46.35174725;
    # their sum × (−100/0.4) = 32905.4387… N/m.
    by_hand = -(100.0 / 0.4) * ((5 * A1 + A2) * A3 + A4 * 5)
    assert by_hand == pytest.approx(32905.4387, abs=1e-3)
    for fn in (pamid.sarosi.sarosi_stiffness, pamid.sarosi.sarosi_stiffness_eq_2_9):
        assert float(fn(sarosi31, 5.0, 0.0, 0.4)) == pytest.approx(by_hand, rel=1e-13)


@pytest.mark.parametrize("l0_m", [0.4, 0.25])
def test_stiffness_is_central_difference_of_force_in_length(sarosi31, l0_m):
    """k = dF/dl with κ = 100·(l0 − l)/l0: a finite difference of eq. 2.1 in metres."""

    def force_at_length(p, length_m):
        return force_np(np.asarray(sarosi31.to_vector()), p, 100.0 * (l0_m - length_m) / l0_m)

    h = 1e-6  # m
    length = l0_m * (1.0 - K_GRID / 100.0)
    fd = (force_at_length(P_GRID, length + h) - force_at_length(P_GRID, length - h)) / (2 * h)
    auto = np.asarray(pamid.sarosi.sarosi_stiffness(sarosi31, P_GRID, K_GRID, l0_m))
    np.testing.assert_allclose(auto, fd, rtol=1e-7)


def test_stiffness_is_positive_for_table_3_1(sarosi31):
    # A real muscle pulls harder when stretched: dF/dl > 0 everywhere on the working range.
    for fn in (pamid.sarosi.sarosi_stiffness, pamid.sarosi.sarosi_stiffness_eq_2_9):
        k = np.asarray(fn(sarosi31, P_GRID, K_GRID, L0_M))
        assert np.all(k > 0)
    # And the stiffness grows with pressure (Sárosi, Figure 3-2).
    k = np.asarray(pamid.sarosi.sarosi_stiffness(sarosi31, P_GRID, K_GRID, L0_M))
    assert np.all(np.diff(k, axis=0) > 0)


# ----------------------------------------------------------------------------------------
# The inverse: pressure for a force
# ----------------------------------------------------------------------------------------


def test_pressure_for_force_round_trip(sarosi31):
    p = np.linspace(0.5, 6.0, 12)[:, None]
    k = np.linspace(0.0, 25.0, 11)[None, :]
    force = pamid.sarosi.sarosi_force(sarosi31, p, k)
    back = np.asarray(pamid.sarosi.sarosi_pressure_for_force(sarosi31, force, k))
    np.testing.assert_allclose(back, np.broadcast_to(p, back.shape), rtol=1e-12)
    # p = 0 comes back to within rounding of the force.
    f0 = pamid.sarosi.sarosi_force(sarosi31, 0.0, 4.0)
    zero = pamid.sarosi.sarosi_pressure_for_force(sarosi31, f0, 4.0)
    assert abs(float(zero)) < 1e-12


def test_pressure_for_force_by_hand(sarosi31):
    force, k = 400.0, 8.0
    e = math.exp(A3 * k)
    by_hand = (force - A2 * e - A6) / (A1 * e + A4 * k + A5)
    got = float(pamid.sarosi.sarosi_pressure_for_force(sarosi31, force, k))
    assert got == pytest.approx(by_hand, rel=1e-13)
    assert force_by_hand(got, k) == pytest.approx(force, rel=1e-13)


def test_pressure_for_force_vmap_and_grad(sarosi31):
    forces = jnp.array([50.0, 200.0, 600.0, 1200.0])
    kappas = jnp.array([15.0, 10.0, 5.0, 0.0])
    vmapped = jax.vmap(pamid.sarosi.sarosi_pressure_for_force, in_axes=(None, 0, 0))(
        sarosi31, forces, kappas
    )
    np.testing.assert_allclose(
        vmapped, pamid.sarosi.sarosi_pressure_for_force(sarosi31, forces, kappas), rtol=1e-14
    )
    for f, k in zip(forces, kappas, strict=True):
        p = pamid.sarosi.sarosi_pressure_for_force(sarosi31, f, k)
        dF_dp = jax.grad(pamid.sarosi.sarosi_force, argnums=1)(sarosi31, p, k)
        dF_dk = jax.grad(pamid.sarosi.sarosi_force, argnums=2)(sarosi31, p, k)
        dp_dF, dp_dk = jax.grad(pamid.sarosi.sarosi_pressure_for_force,
                                argnums=(1, 2))(sarosi31, f, k)
        # Inverse function theorem, and the implicit function theorem at constant force.
        assert float(dp_dF) == pytest.approx(1.0 / float(dF_dp), rel=1e-12)
        assert float(dp_dk) == pytest.approx(-float(dF_dk) / float(dF_dp), rel=1e-10)


# ----------------------------------------------------------------------------------------
# Eq. 2.3: ∫F dκ, and the damping of eq. 2.4–2.10
# ----------------------------------------------------------------------------------------


def quad_force(theta, p, kmin, kmax):
    value, _ = scipy.integrate.quad(
        lambda k: force_np(theta, p, k), kmin, kmax, epsabs=0.0, epsrel=1e-13, limit=200
    )
    return value


def eq_2_3_as_printed(theta, p, kmin, kmax):
    """Eq. 2.3 with the summary's typo: κ_max² in the lower-limit bracket."""
    a1, a2, a3, a4, a5, a6 = theta

    def bracket(k, k_sq):
        e = math.exp(a3 * k)
        return (
            2 * a1 * p * e + 2 * a3 * a6 * k + 2 * a2 * e + 2 * a3 * a5 * p * k + a3 * a4 * p * k_sq
        ) / (2 * a3)

    return bracket(kmax, kmax**2) - bracket(kmin, kmax**2)


@pytest.mark.parametrize(
    ("p", "kmin", "kmax"), [(1.0, 0.0, 20.0), (3.0, 2.0, 18.0), (5.0, 0.0, 25.0), (0.0, 5.0, 10.0)]
)
def test_force_integral_eq_2_3_against_quadrature(sarosi31, theta31, p, kmin, kmax):
    reference = quad_force(theta31, p, kmin, kmax)
    got = float(pamid.sarosi.sarosi_force_integral(sarosi31, p, kmin, kmax))
    assert got == pytest.approx(reference, rel=1e-11)
    # The reversed interval is the negative; an empty one is zero.
    assert float(pamid.sarosi.sarosi_force_integral(sarosi31, p, kmax, kmin)) == pytest.approx(-got)
    assert float(pamid.sarosi.sarosi_force_integral(sarosi31, p, kmin, kmin)) == 0.0
    if p != 0.0:
        # The printed eq. 2.3 (κ_max² in the lower bracket) gives a different, wrong answer.
        typo = eq_2_3_as_printed(theta31, p, kmin, kmax)
        assert abs(typo - reference) > 1e-3 * abs(reference)


@pytest.mark.parametrize(
    ("p", "kmin", "kmax", "kc", "l0", "mass", "offset"),
    [(4.0, 0.0, 20.0, 5.0, 0.4, 20.0, 24.0), (2.0, 1.0, 15.0, 10.0, 0.25, 5.0, 6.0)],
)
def test_hysteresis_damping_against_quadrature(theta31, p, kmin, kmax, kc, l0, mass, offset):
    """Upper branch = lower branch + a constant offset: ζ = ΔU/U0 by quadrature, c = ζ·2√(km)."""
    lower_theta = theta31
    upper_theta = theta31 + np.array([0, 0, 0, 0, 0, offset])
    upper, lower = pamid.Sarosi(*upper_theta), pamid.Sarosi(*lower_theta)
    got = pamid.sarosi.hysteresis_damping(upper, lower, p, kmin, kmax, kc, l0, mass)

    u0 = l0 / 100.0 * quad_force(upper_theta, p, kmin, kmax)  # J: l0[m]/100 · ∫F dκ[%]
    u_lower = l0 / 100.0 * quad_force(lower_theta, p, kmin, kmax)
    delta_u = u0 - u_lower
    assert delta_u == pytest.approx(l0 / 100.0 * offset * (kmax - kmin), rel=1e-10)
    zeta = delta_u / u0
    a1, a2, a3, a4, _, _ = upper_theta
    k = -(100.0 / l0) * ((a1 * p + a2) * a3 * math.exp(a3 * kc) + a4 * p)
    c_cr = 2.0 * math.sqrt(k * mass)
    expected = {
        "U0_J": u0,
        "delta_U_J": delta_u,
        "zeta": zeta,
        "stiffness_N_per_m": k,
        "c_critical_Ns_per_m": c_cr,
        "c_Ns_per_m": zeta * c_cr,
    }
    assert set(got) == set(expected)
    for name, value in expected.items():
        assert float(got[name]) == pytest.approx(value, rel=1e-10), name
    assert 0.0 < float(got["zeta"]) < 1.0


# ----------------------------------------------------------------------------------------
# Every public model function under jit, vmap (inputs and constants) and grad (constants)
# ----------------------------------------------------------------------------------------


def _shifted(prm: pamid.Sarosi, da6: float) -> pamid.Sarosi:
    return pamid.Sarosi(prm.a1, prm.a2, prm.a3, prm.a4, prm.a5, prm.a6 + da6)


def _damping_c(prm, p, kmin, kmax, kc):
    out = pamid.sarosi.hysteresis_damping(_shifted(prm, 24.0), prm, p, kmin, kmax, kc, 0.4, 20.0)
    return out["c_Ns_per_m"]


# name -> (function of (params, *inputs) with a scalar result, batch of inputs)
_P = [1.0, 2.5, 4.0, 6.0]  # bar
_K = [0.0, 5.0, 12.0, 20.0]  # %
_L0 = [0.4, 0.4, 0.25, 0.3]  # m
_F = [100.0, 300.0, 500.0, 50.0]  # N
_KMIN, _KMAX, _KC = [0.0, 2.0, 0.0, 5.0], [20.0, 15.0, 10.0, 18.0], [5.0, 3.0, 8.0, 10.0]
CASES = {
    "sarosi_force": (pamid.sarosi.sarosi_force, (_P, _K)),
    "sarosi_force_slope": (pamid.sarosi.sarosi_force_slope, (_P, _K)),
    "sarosi_stiffness": (pamid.sarosi.sarosi_stiffness, (_P, _K, _L0)),
    "sarosi_stiffness_eq_2_9": (pamid.sarosi.sarosi_stiffness_eq_2_9, (_P, _K, _L0)),
    "sarosi_pressure_for_force": (pamid.sarosi.sarosi_pressure_for_force, (_F, _K)),
    "sarosi_force_integral": (pamid.sarosi.sarosi_force_integral, (_P, _KMIN, _KMAX)),
    "hysteresis_damping": (_damping_c, (_P, _KMIN, _KMAX, _KC)),
}


def _batched_constants(theta31):
    factors = 1.0 + 0.01 * np.array([-1.5, -0.5, 0.5, 1.5])
    return theta31[None, :] * factors[:, None]


@pytest.mark.parametrize("name", sorted(CASES))
def test_jit_matches_eager(name, sarosi31):
    fn, inputs = CASES[name]
    for args in zip(*inputs, strict=True):
        eager = fn(sarosi31, *args)
        jitted = jax.jit(fn)(sarosi31, *args)
        assert jitted.shape == ()
        np.testing.assert_allclose(jitted, eager, rtol=1e-14)


@pytest.mark.parametrize("name", sorted(CASES))
def test_vmap_over_inputs(name, sarosi31):
    fn, inputs = CASES[name]
    arrays = [jnp.asarray(a) for a in inputs]
    in_axes = (None,) + (0,) * len(arrays)
    vmapped = jax.jit(jax.vmap(fn, in_axes=in_axes))(sarosi31, *arrays)
    loop = [fn(sarosi31, *args) for args in zip(*inputs, strict=True)]
    np.testing.assert_allclose(vmapped, loop, rtol=1e-13)
    # Called on the arrays directly, every function broadcasts the same way.
    np.testing.assert_allclose(fn(sarosi31, *arrays), loop, rtol=1e-13)


@pytest.mark.parametrize("name", sorted(CASES))
def test_vmap_over_batched_constants(name, theta31):
    fn, inputs = CASES[name]
    thetas = _batched_constants(theta31)
    batch = pamid.Sarosi.from_vector(thetas)
    args = [a[1] for a in inputs]  # one input point, four sets of constants
    vmapped = jax.vmap(fn, in_axes=(0,) + (None,) * len(args))(batch, *args)
    loop = [fn(pamid.Sarosi.from_vector(t), *args) for t in thetas]
    assert vmapped.shape == (4,)
    np.testing.assert_allclose(vmapped, loop, rtol=1e-13)
    # Both at once: constants and inputs batched together.
    arrays = [jnp.asarray(a) for a in inputs]
    both = jax.vmap(fn)(batch, *arrays)
    loop = [fn(pamid.Sarosi.from_vector(t), *a) for t, *a in zip(thetas, *inputs, strict=True)]
    np.testing.assert_allclose(both, loop, rtol=1e-13)


@pytest.mark.parametrize("name", sorted(CASES))
def test_constants_with_a_leading_axis_broadcast(name, theta31):
    """Sarosi's docstring: fields may carry leading batch dimensions, one set per muscle."""
    fn, inputs = CASES[name]
    thetas = _batched_constants(theta31)
    arrays = [jnp.asarray(a) for a in inputs]
    got = fn(pamid.Sarosi.from_vector(thetas), *arrays)
    loop = [fn(pamid.Sarosi.from_vector(t), *a) for t, *a in zip(thetas, *inputs, strict=True)]
    np.testing.assert_allclose(got, loop, rtol=1e-13)


@pytest.mark.parametrize("name", sorted(CASES))
def test_grad_wrt_constants_matches_finite_differences(name, theta31):
    fn, inputs = CASES[name]
    args = [a[2] for a in inputs]
    grad = jax.jit(jax.grad(lambda prm: fn(prm, *args)))(pamid.Sarosi(*theta31))
    assert isinstance(grad, pamid.Sarosi)
    auto = np.asarray(grad.to_vector())

    def value(theta):
        return float(fn(pamid.Sarosi.from_vector(theta), *args))

    fd = np.empty(6)
    for j in range(6):
        h = 1e-6 * abs(theta31[j])
        step = np.zeros(6)
        step[j] = h
        fd[j] = (value(theta31 + step) - value(theta31 - step)) / (2 * h)
    scale = np.max(np.abs(auto))
    np.testing.assert_allclose(auto, fd, rtol=1e-6, atol=1e-9 * scale)


def test_grad_of_force_wrt_constants_is_the_design_row(theta31):
    """∂F/∂(a1…a6) = (p·e, e, (a1·p + a2)·κ·e, κ·p, p, 1), e = exp(a3·κ)."""
    p, k = 3.0, 12.0
    grad = jax.grad(pamid.sarosi.sarosi_force)(pamid.Sarosi(*theta31), p, k)
    e = math.exp(A3 * k)
    expected = [p * e, e, (A1 * p + A2) * k * e, k * p, p, 1.0]
    np.testing.assert_allclose(grad.to_vector(), expected, rtol=1e-13)


def test_hysteresis_damping_whole_output_under_jit_and_grad(theta31):
    upper, lower = pamid.Sarosi(*(theta31 + [0, 0, 0, 0, 0, 24.0])), pamid.Sarosi(*theta31)
    args = (4.0, 0.0, 20.0, 5.0, 0.4, 20.0)
    eager = pamid.sarosi.hysteresis_damping(upper, lower, *args)
    jitted = jax.jit(pamid.sarosi.hysteresis_damping)(upper, lower, *args)
    for name in eager:
        np.testing.assert_allclose(jitted[name], eager[name], rtol=1e-14)
    # ζ does not depend on the mass; c grows with √m.
    damping = pamid.sarosi.hysteresis_damping
    g_mass = jax.grad(lambda m: damping(upper, lower, *args[:5], m)["zeta"])(20.0)
    assert float(g_mass) == 0.0
    dc_dm = jax.grad(lambda m: damping(upper, lower, *args[:5], m)["c_Ns_per_m"])
    assert float(dc_dm(20.0)) == pytest.approx(float(eager["c_Ns_per_m"]) / (2 * 20.0), rel=1e-12)
    # The gradient of ζ reaches both branches: the lower one through ΔU only.
    g_upper, g_lower = jax.grad(
        lambda u, lo: pamid.sarosi.hysteresis_damping(u, lo, *args)["zeta"], argnums=(0, 1)
    )(upper, lower)
    assert np.all(np.isfinite(g_upper.to_vector())) and np.all(np.isfinite(g_lower.to_vector()))
    # ζ = 1 − ∫F_a/∫F_f, so ∂ζ/∂a6(lower) = −(κmax − κmin)/∫F_f.
    integral_upper = float(pamid.sarosi.sarosi_force_integral(upper, 4.0, 0.0, 20.0))
    assert float(g_lower.a6) == pytest.approx(-20.0 / integral_upper, rel=1e-12)
