"""The presets for Cullinan's muscles and joints, and the direction of each claim of the paper
(fast checks; ``experiments/cullinan_joint.py`` reports the numbers)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

import pamid
from pamid._models import _cullinan_presets as cp
from pamid._models._energy import trajectory_energy_J
from pamid._models._joint import (
    available_torque_Nm,
    closed_system_stiffness,
    max_isobaric_stiffness,
)
from pamid._units import ATMOSPHERE_KPA
from pamid._virtual._braided import fit_cullinan_presets, simulate_braided_pam_bench

P_MAX = 414.0
PRESSURES = np.asarray(cp.TEST_PRESSURES_KPA)[:, None]
BETA = np.linspace(-0.6, 0.6, 49)[None, :]


@pytest.fixture(scope="module")
def refit():
    return fit_cullinan_presets()


def test_presets_are_the_fit_of_the_virtual_bench(refit):
    result, frames = refit
    assert result.muscles == ("traditional", "sleeve")
    assert result.converged.all()
    for i, stored in enumerate((cp.TRADITIONAL_FIT, cp.SLEEVE_FIT)):
        np.testing.assert_allclose(result.theta[i], [stored[p] for p in "ABCDE"], rtol=1e-8)
    # Eq. 3 cannot follow a braid exactly: the residual is several times the 2 N noise.
    assert np.all(result.rmse_N > 4.0 * 2.0)
    # Eq. 1: the sleeve's extra pull per kPa is about the element's section π·d²/4.
    gain = cp.SLEEVE_FIT["B"] - cp.TRADITIONAL_FIT["B"]
    assert gain == pytest.approx(math.pi * cp.ELEMENT_DIAMETER_MM**2 / 4 * 1e-3, rel=0.05)
    assert isinstance(cp.traditional_pam(), pamid.Cullinan)
    assert float(cp.sleeve_pam().G) > float(cp.traditional_pam().G)  # damping: sleeve greater


def test_static_bench_is_reproducible_with_a_key():
    muscle = cp.traditional_braided_pam()
    a = simulate_braided_pam_bench(jax.random.key(1), muscle)
    b = simulate_braided_pam_bench(jax.random.key(1), muscle)
    c = simulate_braided_pam_bench(jax.random.key(2), muscle)
    pd.testing.assert_frame_equal(a, b)
    assert not np.allclose(a["force_N"], c["force_N"])
    np.testing.assert_allclose(a["length_mm"] + a["contraction_mm"], 190.0)


def test_physical_force_is_chou_hannaford_plus_eq_1():
    """Without a bladder, F = P′·(3L² − b²)/(4πn²) + P′·π·d²/4 (kPa·mm² = 10⁻³ N)."""
    muscle = cp.braided_pam(25.0, bladder_shear_modulus_MPa=0.0)
    v = muscle.volume
    b, n = float(v.fibre_length_mm), float(v.turns)
    p, y = 300.0, np.linspace(0.0, 55.0, 12)
    length = 190.0 - y
    expected = 1e-3 * p * ((3 * length**2 - b**2) / (4 * math.pi * n**2) + math.pi * 25.0**2 / 4)
    np.testing.assert_allclose(cp.braided_pam_force_N(muscle, p, y), expected, rtol=1e-12)
    # The same as eq. 1's split: the braid's pull less P′·A_d, A_d = π·D(y)²/4 − π·d²/4.
    cos_t = length / b
    diameter = b * np.sqrt(1 - cos_t**2) / (n * math.pi)
    d_diameter_dL = -(b / (n * math.pi)) * cos_t / np.sqrt(1 - cos_t**2) / b
    braid = p * (math.pi * length * diameter / 2) * (-d_diameter_dL)
    end_fitting = p * (math.pi * diameter**2 / 4 - math.pi * 25.0**2 / 4)
    np.testing.assert_allclose(cp.braided_pam_force_N(muscle, p, y),
                               1e-3 * (braid - end_fitting), rtol=1e-10)


def test_bladder_stores_no_energy_at_rest_and_resists_contraction():
    muscle = cp.traditional_braided_pam()
    y = jnp.linspace(0.0, 55.0, 12)
    assert float(cp.bladder_energy_Nmm(muscle, 0.0)) == pytest.approx(0.0, abs=1e-9)
    slope = jax.vmap(jax.grad(lambda yy: cp.bladder_energy_Nmm(muscle, yy)))(y)
    assert float(slope[0]) == pytest.approx(0.0, abs=1e-9)
    assert np.all(np.asarray(slope[1:]) > 0)


def test_sleeve_contracts_about_5_percent_further():
    """The check behind d = 30 mm: the free contraction grows by 3.8–4.6 % of L0."""
    import scipy.optimize

    gains = []
    for p in cp.TEST_PRESSURES_KPA:
        free = [
            scipy.optimize.brentq(lambda y, m=m: float(cp.braided_pam_force_N(m, p, y)), 1, 80)
            for m in (cp.traditional_braided_pam(), cp.sleeve_braided_pam())
        ]
        gains.append((free[1] - free[0]) / 190.0)
    assert 0.035 < min(gains) and max(gains) < 0.05


def test_volumes_of_the_presets():
    y = np.linspace(0.0, 55.0, 6)
    trad = np.asarray(pamid.cullinan.pam_volume_mm3(cp.traditional_volume(), y))
    sleeve = np.asarray(pamid.cullinan.pam_volume_mm3(cp.sleeve_volume(), y))
    np.testing.assert_allclose(trad - sleeve, math.pi * 15.0**2 * (190.0 - y), rtol=1e-12)
    assert float(cp.traditional_volume().rest_braid_angle_rad) == pytest.approx(math.pi / 6)


def test_configuration_geometry():
    trad, a, b = cp.traditional_joint(), cp.sleeve_joint_A(), cp.sleeve_joint_B()
    for g in (trad, a, b):
        assert float(g.pulley_radius_mm) == 40.0
        assert (float(g.cable_compliance_mm_per_N)
                == pamid.cullinan.CULLINAN_CABLE_COMPLIANCE_MM_PER_N)
    assert float(b.beta_range_rad) == float(trad.beta_range_rad) == 1.2  # B keeps the range
    assert float(a.beta_range_rad) > 1.2  # A rotates further
    beta_a = cp.config_a_beta_range_rad()
    assert beta_a == pytest.approx(cp.CONFIG_A_BETA_RANGE_RAD, rel=1e-9)
    # The rule: at its limits A offers exactly the traditional joint's limit torque.
    limit_t = available_torque_Nm(cp.traditional_pam(), trad, 0.6, P_MAX).toward_positive_Nm
    limit_a = available_torque_Nm(cp.sleeve_pam(), a, beta_a / 2, P_MAX).toward_positive_Nm
    assert float(limit_a) == pytest.approx(float(limit_t), rel=1e-9)


def test_traditional_joint_has_15_Nm_at_its_limits():
    """Cullinan Section III: ±0.6 rad with at least 15 N·m both ways at the limits, 414 kPa."""
    avail = available_torque_Nm(cp.traditional_pam(), cp.traditional_joint(),
                                np.array([-0.6, 0.6]), P_MAX)
    assert np.all(np.asarray(avail.toward_positive_Nm) >= 15.0)
    assert np.all(np.asarray(avail.toward_negative_Nm) >= 15.0)
    assert float(avail.toward_positive_Nm[1]) < 17.0  # nearly tight, as the paper's design


def _ratio(sleeve_geometry):
    sleeve = available_torque_Nm(cp.sleeve_pam(), sleeve_geometry, BETA, PRESSURES)
    trad = available_torque_Nm(cp.traditional_pam(), cp.traditional_joint(), BETA, PRESSURES)
    return np.asarray(sleeve.toward_positive_Nm) / np.asarray(trad.toward_positive_Nm)


def test_claim_config_a_more_rotation_at_equal_or_greater_torque():
    assert float(cp.sleeve_joint_A().beta_range_rad) / 1.2 - 1 > 0.10  # paper: 14 %
    assert np.min(_ratio(cp.sleeve_joint_A())) >= 0.98  # "equal to or slightly greater"


def test_claim_config_b_more_torque_most_at_the_limits():
    ratio = _ratio(cp.sleeve_joint_B())
    assert np.all(ratio > 1.0)
    assert ratio[-1, -1] > 1.5  # over 50 % at the contracted limit, 414 kPa
    assert np.all(np.diff(ratio[-1]) > 0)  # growing towards the limit


def test_claim_fig5_traditional_stiffest_and_b_stiffer_than_a():
    k = {
        name: float(max_isobaric_stiffness(prm, geom, 0.0, 0.0).stiffness_Nm_per_rad)
        for name, prm, geom in (
            ("traditional", cp.traditional_pam(), cp.traditional_joint()),
            ("A", cp.sleeve_pam(), cp.sleeve_joint_A()),
            ("B", cp.sleeve_pam(), cp.sleeve_joint_B()),
        )
    }
    assert k["traditional"] > k["B"] > k["A"]


def test_claim_fig6_closed_system_stiffer_more_so_for_sleeve():
    ratio = {}
    for name, prm, geom, vol in (
        ("traditional", cp.traditional_pam(), cp.traditional_joint(), cp.traditional_volume()),
        ("A", cp.sleeve_pam(), cp.sleeve_joint_A(), cp.sleeve_volume()),
        ("B", cp.sleeve_pam(), cp.sleeve_joint_B(), cp.sleeve_volume()),
    ):
        s = closed_system_stiffness(prm, prm, geom, vol, 0.0, 300.0, 300.0)
        ratio[name] = float(s.regression_mean_Nm_per_rad / s.isobaric_Nm_per_rad)
    assert ratio["B"] > ratio["A"] > ratio["traditional"] > 1.0


def test_claim_fig8_sleeve_saves_energy_and_a_costs_more_than_b():
    traj = 0.2 * np.sin(2 * np.pi * np.linspace(0.0, 1.0, 101))
    energy = {
        name: trajectory_energy_J(prm, geom, vol, traj, 20.0, 60.0)
        for name, prm, geom, vol in (
            ("traditional", cp.traditional_pam(), cp.traditional_joint(),
             cp.traditional_volume()),
            ("A", cp.sleeve_pam(), cp.sleeve_joint_A(), cp.sleeve_volume()),
            ("B", cp.sleeve_pam(), cp.sleeve_joint_B(), cp.sleeve_volume()),
        )
    }
    assert all(bool(e.feasible.all()) for e in energy.values())
    total = {k: float(e.total_J) for k, e in energy.items()}
    assert total["traditional"] > total["A"] > total["B"] > 0


def test_energy_of_a_zero_motion_trajectory():
    """Holding still costs nothing after the first fill, which costs the air's exergy."""
    beta = np.full(50, 0.1)
    e = trajectory_energy_J(cp.sleeve_pam(), cp.sleeve_joint_B(), cp.sleeve_volume(), beta,
                            20.0, 60.0)
    work = np.asarray(e.step_work_J)
    assert np.all(work[1:] == 0.0)
    assert float(e.total_J) == pytest.approx(work[0].sum(), rel=1e-12)
    # First step: X = P·V·ln(P/P_atm) − (P − P_atm)·V per muscle (absolute P, SI units).
    y1, y2 = pamid.cullinan.contractions_mm(cp.sleeve_joint_B(), 0.1)
    expected = 0.0
    for p_kpa, y in ((e.p1_kPa[0], y1), (e.p2_kPa[0], y2)):
        p = (float(p_kpa) + ATMOSPHERE_KPA) * 1e3
        v = float(pamid.cullinan.pam_volume_mm3(cp.sleeve_volume(), y)) * 1e-9
        expected += p * v * math.log(p / (ATMOSPHERE_KPA * 1e3)) - (p - ATMOSPHERE_KPA * 1e3) * v
    assert work[0].sum() == pytest.approx(expected, rel=1e-9)
    # No torque, no motion, no pressure: nothing at all.
    idle = trajectory_energy_J(cp.sleeve_pam(), cp.sleeve_joint_B(), cp.sleeve_volume(),
                               np.zeros(10), 0.0, 2 * 1.6 * (cp.SLEEVE_FIT["C"] +
                                                          cp.SLEEVE_FIT["E"] * 40 * 1.2))
    np.testing.assert_allclose(idle.p1_kPa, 0.0, atol=1e-9)
    assert float(idle.total_J) == pytest.approx(0.0, abs=1e-12)


def test_physical_force_under_jit_and_vmap():
    y = jnp.linspace(0.0, 50.0, 6)
    eager = cp.braided_pam_force_N(cp.sleeve_braided_pam(), 250.0, y)
    np.testing.assert_allclose(jax.jit(cp.braided_pam_force_N)(cp.sleeve_braided_pam(), 250.0,
                                                                y), eager, rtol=1e-13)
    diameters = jnp.array([0.0, 20.0, 30.0])
    batch = jax.vmap(lambda d: cp.braided_pam_force_N(cp.braided_pam(d), 250.0, y))(diameters)
    assert batch.shape == (3, 6)
    np.testing.assert_allclose(batch[2], eager, rtol=1e-13)
    # Eq. 1: the rows differ by P′·π·d²/4 at every contraction.
    np.testing.assert_allclose(batch[2] - batch[0], 250.0 * math.pi * 30.0**2 / 4 * 1e-3,
                               rtol=1e-10)
