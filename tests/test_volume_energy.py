"""PAM volume (Chou & Hannaford's braid), closed-system pressure and stiffness (Cullinan
Section V) and the ideal compressor's energy (Cullinan Section VII, eq. 13–14), against
hand calculations, closed forms, finite differences and numerical quadrature.

The muscle constants are those of tests/test_joint.py (see there for how they were chosen).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.integrate

import pamid  # noqa: F401  (switches float64 on)
from pamid._models._cullinan import Cullinan
from pamid._models._energy import (
    R_AIR_J_PER_KG_K,
    ROOM_TEMPERATURE_K,
    air_mass_kg,
    compressor_work_J,
    trajectory_energy_J,
)
from pamid._models._joint import (
    CULLINAN_CABLE_COMPLIANCE_MM_PER_N,
    JointGeometry,
    closed_system_stiffness,
    closed_system_torque_Nm,
    joint_torque_Nm,
    muscle_state,
)
from pamid._models._volume import (
    PamVolume,
    braid_volume_mm3,
    closed_system_pressure_kPa,
    sleeve_pam_volume,
    traditional_pam_volume,
    volume_mm3,
)

A, B, C, D, E, G = -10.0, 4.0, 2.0, 0.05, 0.07, 0.05
TRAD = Cullinan(A, B, C, D, E, G)
RIGID = JointGeometry(40.0, 1.2)
CABLE = JointGeometry(40.0, 1.2, CULLINAN_CABLE_COMPLIANCE_MM_PER_N)
TRAD_VOL = traditional_pam_volume()
SLEEVE_VOL = sleeve_pam_volume()
L0, D0, THETA0 = 190.0, 40.0, math.radians(30.0)  # the defaults of traditional_pam_volume()
P_ATM = 101.325
ELEMENT_MM = 30.0  # the default element of sleeve_pam_volume()
RT = R_AIR_J_PER_KG_K * ROOM_TEMPERATURE_K


# ----------------------------------------------------------------------------------------
# Volume
# ----------------------------------------------------------------------------------------


def test_braid_volume_at_rest_is_the_cylinder():
    assert float(braid_volume_mm3(TRAD_VOL, 0.0)) == pytest.approx(
        math.pi * D0**2 / 4 * L0, rel=1e-14
    )
    assert float(volume_mm3(TRAD_VOL, 0.0)) == pytest.approx(
        math.pi * D0**2 / 4 * L0 + 5000.0, rel=1e-14
    )


def test_braid_volume_is_chou_and_hannaford():
    b = L0 / math.cos(THETA0)
    n = L0 * math.tan(THETA0) / (math.pi * D0)
    assert float(TRAD_VOL.fibre_length_mm) == pytest.approx(b, rel=1e-14)
    assert float(TRAD_VOL.turns) == pytest.approx(n, rel=1e-14)
    for y in (0.0, 10.0, 30.0, 48.0):
        length = L0 - y
        theta = math.acos(length / b)
        diameter = b * math.sin(theta) / (n * math.pi)
        expected = length * (b**2 - length**2) / (4 * math.pi * n**2)
        assert float(braid_volume_mm3(TRAD_VOL, y)) == pytest.approx(expected, rel=1e-12)
        assert expected == pytest.approx(math.pi * diameter**2 / 4 * length, rel=1e-12)


def test_volume_grows_with_contraction_up_to_the_maximum_braid_angle():
    y_max = float(TRAD_VOL.max_contraction_mm)
    assert y_max == pytest.approx(L0 - L0 / math.cos(THETA0) / math.sqrt(3), rel=1e-14)
    y = np.linspace(0.0, y_max, 200)
    for vol in (TRAD_VOL, SLEEVE_VOL):
        v = np.asarray(volume_mm3(vol, y))
        assert np.all(np.diff(v) > 0)
        # At θ = 54.74° the braid stops growing; the sleeve still gains the element's area.
        slope = jax.grad(lambda yy, vol=vol: volume_mm3(vol, yy))(y_max)
        element_area = math.pi / 4 * float(vol.element_diameter_mm) ** 2
        assert float(slope) == pytest.approx(element_area, abs=1e-8)
    # The braid alone has its maximum volume at θ = 54.74°.
    assert float(jax.grad(lambda yy: braid_volume_mm3(TRAD_VOL, yy))(y_max)) == pytest.approx(
        0.0, abs=1e-8
    )


def test_sleeve_volume_is_traditional_minus_the_element():
    y = np.linspace(0.0, 60.0, 13)
    element = math.pi * ELEMENT_MM**2 / 4 * (L0 - y)
    np.testing.assert_allclose(
        volume_mm3(SLEEVE_VOL, y), np.asarray(volume_mm3(TRAD_VOL, y)) - element, rtol=1e-13
    )


def test_volume_is_positive_even_with_a_thick_element():
    thick = PamVolume(L0, D0, THETA0, 0.0, 39.0)
    y = np.linspace(0.0, float(thick.max_contraction_mm), 50)
    assert np.all(np.asarray(volume_mm3(thick, y)) > 0)


def test_volume_slope_by_grad_matches_closed_form_and_finite_differences():
    y = jnp.array([0.0, 12.0, 30.0, 45.0])
    slope = jax.vmap(jax.grad(lambda yy: volume_mm3(SLEEVE_VOL, yy)))(y)
    b2 = (L0 / math.cos(THETA0)) ** 2
    length = L0 - np.asarray(y)
    closed = math.pi * D0**2 / 4 * (3 * length**2 - b2) / (b2 - L0**2) + math.pi * ELEMENT_MM**2 / 4
    np.testing.assert_allclose(slope, closed, rtol=1e-12)
    h = 1e-4
    fd = (volume_mm3(SLEEVE_VOL, y + h) - volume_mm3(SLEEVE_VOL, y - h)) / (2 * h)
    np.testing.assert_allclose(slope, fd, rtol=1e-8)


def test_bad_volume_geometry_is_rejected():
    with pytest.raises(ValueError, match="rest_braid_angle_rad must be in"):
        PamVolume(L0, D0, math.radians(55.0))
    with pytest.raises(ValueError, match="active_length_mm must be > 0"):
        PamVolume(0.0, D0, THETA0)
    with pytest.raises(ValueError, match="dead_volume_mm3 must be >= 0"):
        PamVolume(L0, D0, THETA0, -1.0)
    with pytest.raises(ValueError, match="element_diameter_mm must be smaller"):
        PamVolume(L0, D0, THETA0, 0.0, 40.0)


# ----------------------------------------------------------------------------------------
# Closed-system pressure and stiffness
# ----------------------------------------------------------------------------------------


def test_closed_system_pressure_keeps_pv_constant():
    y = np.array([10.0, 20.0, 24.0, 30.0, 40.0])
    p = np.asarray(closed_system_pressure_kPa(TRAD_VOL, 24.0, 300.0, y))
    assert p[2] == pytest.approx(300.0, rel=1e-14)
    v = np.asarray(volume_mm3(TRAD_VOL, y))
    np.testing.assert_allclose((p + P_ATM) * v, (300.0 + P_ATM) * v[2], rtol=1e-13)
    assert np.all(np.diff(p) < 0)  # the volume grows, so the pressure falls
    adiabatic = np.asarray(closed_system_pressure_kPa(TRAD_VOL, 24.0, 300.0, y, 1.4))
    np.testing.assert_allclose(
        (adiabatic + P_ATM) * v**1.4, (300.0 + P_ATM) * v[2] ** 1.4, rtol=1e-13
    )


def test_bad_gas_arguments_are_rejected():
    with pytest.raises(ValueError, match="polytropic_n must be > 0"):
        closed_system_pressure_kPa(TRAD_VOL, 24.0, 300.0, 30.0, 0.0)
    with pytest.raises(ValueError, match="p0_kPa is a gauge pressure"):
        closed_system_pressure_kPa(TRAD_VOL, 24.0, -200.0, 30.0)
    with pytest.raises(ValueError, match="p_atm_kPa must be > 0"):
        closed_system_stiffness(TRAD, TRAD, RIGID, TRAD_VOL, 0.0, 300.0, 300.0, p_atm_kPa=0.0)


def test_sealed_torque_at_the_set_point_is_the_isobaric_torque():
    for geometry in (RIGID, CABLE):
        sealed = closed_system_torque_Nm(TRAD, TRAD, geometry, TRAD_VOL, 0.2, 350.0, 200.0, 0.2)
        open_ = joint_torque_Nm(TRAD, TRAD, geometry, 0.2, 350.0, 200.0)
        assert float(sealed) == pytest.approx(float(open_), rel=1e-12)


def test_closed_system_stiffness_by_hand():
    """−dT/dβ sealed = isobaric − r²·Σ (B − D·y_i)·dP_i/dy_i, with dP/dy = −(P + P_atm)·V′/V."""
    beta0, p1, p2 = 0.1, 350.0, 250.0
    result = closed_system_stiffness(TRAD, TRAD, RIGID, TRAD_VOL, beta0, p1, p2)
    r = 40.0
    y1, y2 = r * (0.6 + beta0), r * (0.6 - beta0)

    def dp_dy(p, y):
        v = float(volume_mm3(TRAD_VOL, y))
        dv = float(jax.grad(lambda yy: volume_mm3(TRAD_VOL, yy))(y))
        return -(p + P_ATM) * dv / v

    isobaric = r / 1000 * r * (2 * C + D * (p1 + p2) + 2 * E * r * 1.2)
    extra = -r / 1000 * r * ((B - D * y1) * dp_dy(p1, y1) + (B - D * y2) * dp_dy(p2, y2))
    assert float(result.isobaric_Nm_per_rad) == pytest.approx(isobaric, rel=1e-12)
    assert float(result.derivative_Nm_per_rad) == pytest.approx(isobaric + extra, rel=1e-10)
    assert extra > 0.5 * isobaric  # sealing stiffens the joint substantially


@pytest.mark.parametrize("direction", [1, -1])
def test_closed_system_regression_approaches_the_derivative(direction):
    tiny = closed_system_stiffness(
        TRAD, TRAD, CABLE, TRAD_VOL, 0.0, 300.0, 300.0, (0.01, 0.02, 0.03), direction
    )
    np.testing.assert_allclose(tiny.regression_Nm_per_rad, tiny.derivative_Nm_per_rad, rtol=1e-4)
    paper = closed_system_stiffness(
        TRAD, TRAD, CABLE, TRAD_VOL, 0.0, 300.0, 300.0, direction=direction
    )
    assert paper.regression_Nm_per_rad.shape == (3,)
    assert float(paper.regression_mean_Nm_per_rad) == pytest.approx(
        float(paper.regression_Nm_per_rad.mean()), rel=1e-14
    )
    # "approximately linear, even for larger deflections" (Cullinan Section V)
    np.testing.assert_allclose(paper.regression_Nm_per_rad, paper.derivative_Nm_per_rad, rtol=0.05)


def test_closed_system_derivative_with_cable_stretch_matches_finite_differences():
    def sealed(beta):
        return closed_system_torque_Nm(TRAD, TRAD, CABLE, SLEEVE_VOL, 0.15, 380.0, 220.0, beta)

    h = 1e-6
    fd = -(sealed(0.15 + h) - sealed(0.15 - h)) / (2 * h)
    result = closed_system_stiffness(TRAD, TRAD, CABLE, SLEEVE_VOL, 0.15, 380.0, 220.0)
    assert float(result.derivative_Nm_per_rad) == pytest.approx(float(fd), rel=1e-7)


def test_sleeve_gains_more_stiffness_from_sealing_than_traditional():
    """Cullinan Section V: the sleeve PAM's smaller volume raises the closed-system stiffness."""
    beta0 = jnp.array([-0.3, 0.0, 0.3])
    trad = closed_system_stiffness(TRAD, TRAD, CABLE, TRAD_VOL, beta0, 300.0, 300.0)
    sleeve = closed_system_stiffness(TRAD, TRAD, CABLE, SLEEVE_VOL, beta0, 300.0, 300.0)
    assert trad.regression_Nm_per_rad.shape == (3, 3)
    assert np.all(trad.regression_mean_Nm_per_rad > trad.isobaric_Nm_per_rad)
    assert np.all(sleeve.regression_mean_Nm_per_rad > trad.regression_mean_Nm_per_rad)
    adiabatic = closed_system_stiffness(
        TRAD, TRAD, CABLE, TRAD_VOL, beta0, 300.0, 300.0, polytropic_n=1.4
    )
    assert np.all(adiabatic.derivative_Nm_per_rad > trad.derivative_Nm_per_rad)


# ----------------------------------------------------------------------------------------
# Compressor work, eq. 13–14
# ----------------------------------------------------------------------------------------


def eq13_by_quadrature(p1, v1, p2, v2):
    """Cullinan eq. 13 integrated numerically, in SI (kPa gauge and mm³ in)."""
    p_atm = P_ATM * 1e3
    pm1, pm2 = p1 * 1e3 + p_atm, p2 * 1e3 + p_atm
    vm1, vm2 = v1 * 1e-9, v2 * 1e-9
    m1 = pm1 * vm1 / RT
    dm = pm2 * vm2 / RT - m1
    vc1, vc2 = dm * RT / p_atm, dm * RT / pm1
    first, _ = scipy.integrate.quad(lambda v: dm * RT / v - p_atm, vc1, vc2, epsabs=0, epsrel=1e-13)
    second, _ = scipy.integrate.quad(
        lambda v: (dm + m1) * RT / v - p_atm, vc2 + vm1, vm2, epsabs=0, epsrel=1e-13
    )
    return -first - second


def exergy_J(p_kPa, v_mm3):
    """Isothermal exergy of air at (P, V) against the atmosphere: P·V·ln(P/P0) − (P − P0)·V."""
    p, p0, v = p_kPa * 1e3 + P_ATM * 1e3, P_ATM * 1e3, v_mm3 * 1e-9
    return p * v * math.log(p / p0) - (p - p0) * v


STEPS = [  # (P1 kPa, V1 mm³, P2 kPa, V2 mm³)
    (0.0, 240_000.0, 300.0, 240_000.0),  # fill at constant volume
    (100.0, 300_000.0, 350.0, 420_000.0),  # pressure and volume rise
    (400.0, 450_000.0, 380.0, 520_000.0),  # the volume grows faster than the pressure falls
    (250.0, 400_000.0, 400.0, 380_000.0),  # the muscle shrinks but still needs air
]


@pytest.mark.parametrize("step", STEPS)
def test_eq14_equals_eq13_by_quadrature_and_the_isothermal_minimum(step):
    p1, v1, p2, v2 = step
    assert (p2 + P_ATM) * v2 > (p1 + P_ATM) * v1  # every step needs air
    w = float(compressor_work_J(p1, v1, p2, v2))
    assert w == pytest.approx(eq13_by_quadrature(*step), rel=1e-10)
    # Eq. 13 is reversible and isothermal: its work is the change of the air's exergy, the
    # least work any isothermal compressor can do.
    assert w == pytest.approx(exergy_J(p2, v2) - exergy_J(p1, v1), rel=1e-10)


def test_compressor_work_by_hand_for_a_constant_volume_fill():
    # From atmosphere to 300 kPa gauge in 240 cm³: W = P2·V·ln(P2/P0) − (P2 − P0)·V.
    p2, v = 401.325e3, 240e-6
    expected = p2 * v * math.log(p2 / 101.325e3) - 300e3 * v
    assert float(compressor_work_J(0.0, 240_000.0, 300.0, 240_000.0)) == pytest.approx(
        expected, rel=1e-12
    )


def test_exhausting_costs_nothing_and_gradients_stay_finite():
    # Δm < 0 (pressure falls) and Δm = 0 (P·V unchanged, the muscle shrinks).
    assert float(compressor_work_J(300.0, 300_000.0, 200.0, 300_000.0)) == 0.0
    v2 = (300.0 + P_ATM) * 300_000.0 / (350.0 + P_ATM)
    assert float(compressor_work_J(300.0, 300_000.0, 350.0, v2 * (1 - 1e-12))) == 0.0
    grad = jax.grad(compressor_work_J, argnums=(0, 2))(300.0, 300_000.0, 200.0, 300_000.0)
    assert all(float(g) == 0.0 for g in grad)
    grad = jax.grad(compressor_work_J, argnums=2)(100.0, 300_000.0, 350.0, 420_000.0)
    h = 1e-4
    fd = (
        compressor_work_J(100.0, 300_000.0, 350.0 + h, 420_000.0)
        - compressor_work_J(100.0, 300_000.0, 350.0 - h, 420_000.0)
    ) / (2 * h)
    assert float(grad) == pytest.approx(float(fd), rel=1e-7)


def test_air_mass_by_hand():
    assert float(air_mass_kg(300.0, 240_000.0)) == pytest.approx(
        401.325e3 * 240e-6 / (287.05 * 293.15), rel=1e-14
    )


# ----------------------------------------------------------------------------------------
# Energy along a trajectory (Fig. 8)
# ----------------------------------------------------------------------------------------

SINE = 0.2 * jnp.sin(jnp.linspace(0.0, 2 * jnp.pi, 81))  # one cycle, amplitude 0.2 rad
_energy = trajectory_energy_J  # jitted inside, after its argument checks


def test_holding_still_costs_nothing_after_the_first_step():
    result = _energy(TRAD, RIGID, TRAD_VOL, jnp.full(6, 0.1), 15.0, 50.0)
    work = np.asarray(result.step_work_J)
    assert np.all(work[0] > 0)
    np.testing.assert_array_equal(work[1:], 0.0)
    # The first step fills each muscle from the atmosphere: its exergy at (P, V).
    v1 = float(volume_mm3(TRAD_VOL, 40.0 * 0.7))
    assert work[0, 0] == pytest.approx(exergy_J(float(result.p1_kPa[0]), v1), rel=1e-10)
    assert float(result.total_J) == pytest.approx(work.sum(), rel=1e-14)


def test_trajectory_pressures_give_the_torque_and_stiffness():
    result = _energy(TRAD, RIGID, TRAD_VOL, SINE, 20.0, 50.0)
    assert bool(result.feasible.all())
    torque = joint_torque_Nm(TRAD, TRAD, RIGID, SINE, result.p1_kPa, result.p2_kPa)
    np.testing.assert_allclose(torque, 20.0, rtol=1e-11)
    state = muscle_state(TRAD, TRAD, RIGID, SINE, result.p1_kPa, result.p2_kPa)
    assert np.all(np.asarray(state.f2_N) > 0)  # both in tension, as eq. 6 assumes


def test_energy_rises_with_stiffness_and_is_lower_with_sleeve_volumes():
    """Cullinan Fig. 8: more stiffness costs more air; the sleeve PAM's smaller volume less."""
    stiffness = jnp.array([40.0, 45.0, 50.0, 55.0])
    trad = jax.vmap(lambda k: _energy(TRAD, RIGID, TRAD_VOL, SINE, 20.0, k))(stiffness)
    sleeve = jax.vmap(lambda k: _energy(TRAD, RIGID, SLEEVE_VOL, SINE, 20.0, k))(stiffness)
    assert bool(trad.feasible.all())
    assert np.all(np.diff(np.asarray(trad.total_J)) > 0)
    assert np.all(np.diff(np.asarray(sleeve.total_J)) > 0)
    assert np.all(np.asarray(sleeve.total_J) < np.asarray(trad.total_J))
    d_energy = jax.grad(lambda k: _energy(TRAD, RIGID, TRAD_VOL, SINE, 20.0, k).total_J)(45.0)
    assert float(d_energy) > 0


def test_infeasible_steps_are_flagged():
    # 90 N·m/rad needs P1 + P2 = (1000·90/40² − 2C − 2E·r·β_range)/D = 910.6 kPa > 2·414 kPa.
    result = _energy(TRAD, RIGID, TRAD_VOL, SINE, 20.0, 90.0)
    assert not bool(result.feasible.any())
    low = _energy(TRAD, RIGID, TRAD_VOL, SINE, 20.0, 35.0)  # P2 < 0 near β = −0.2 rad
    assert bool(low.feasible.any()) and not bool(low.feasible.all())


def test_bad_trajectory_arguments_are_rejected():
    with pytest.raises(ValueError, match="beta_traj_rad must be a 1-D trajectory"):
        trajectory_energy_J(TRAD, RIGID, TRAD_VOL, jnp.zeros((2, 3)), 10.0, 50.0)
    with pytest.raises(ValueError, match="p_max_kPa must be > 0"):
        trajectory_energy_J(TRAD, RIGID, TRAD_VOL, SINE, 10.0, 50.0, p_max_kPa=0.0)
    with pytest.raises(ValueError, match="temperature_K must be > 0"):
        compressor_work_J(0.0, 1.0, 100.0, 1.0, temperature_K=-1.0)
