"""The antagonistic joint of Cullinan eq. 3–7: torque, stiffness, available torque and the
maximum isobaric stiffness, against hand calculations, the closed forms, finite differences
and a brute-force grid search.

Test constants. Cullinan prints no values for A–G, so the muscle below is chosen to fit the
paper's traditional joint: r = 40 mm, β_range = 1.2 rad (±0.6 rad), and at least 15 N·m at
the limits at 414 kPa, i.e. F(414 kPa, y = r·β_range = 48 mm) ≥ 375 N:

    F(414, 48) = −10 + 4·414 − (2 + 0.05·414 + 0.07·48)·48 = 395.12 N  →  15.80 N·m,

positive over the whole range at 414 kPa (F falls with y). Its isobaric stiffness with both
muscles at 414 kPa is 83.4 N·m/rad, close to the 88 N·m/rad of Cullinan Fig. 7.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

import pamid  # noqa: F401  (switches float64 on)
from pamid._models._cullinan import Cullinan
from pamid._models._joint import (
    CULLINAN_CABLE_COMPLIANCE_MM_PER_N,
    JointGeometry,
    available_torque_Nm,
    closed_system_stiffness,
    contractions_mm,
    joint_stiffness_eq7_Nm_per_rad,
    joint_stiffness_Nm_per_rad,
    joint_torque_eq6_Nm,
    joint_torque_Nm,
    max_isobaric_stiffness,
    muscle_state,
    pressures_for_torque_stiffness_kPa,
)
from pamid._models._volume import traditional_pam_volume

A, B, C, D, E, G = -10.0, 4.0, 2.0, 0.05, 0.07, 0.05  # N, N/kPa, N/mm, N/(kPa·mm), N/mm², N·s/mm
TRAD = Cullinan(A, B, C, D, E, G)
R_MM, BETA_RANGE = 40.0, 1.2
P_MAX = 414.0
RIGID = JointGeometry(R_MM, BETA_RANGE)
CABLE = JointGeometry(R_MM, BETA_RANGE, CULLINAN_CABLE_COMPLIANCE_MM_PER_N)


def force_by_hand(p, y, v=0.0):
    """Cullinan eq. 3 in plain Python."""
    return A + B * p - (C + D * p + E * y) * y - G * v


def eq6_as_printed(beta, p1, p2, beta_dot=0.0):
    """Cullinan eq. 6 exactly as printed, with "− 2Erβ_range" inside the bracket (N·m)."""
    r = R_MM
    bracket = (
        (p1 - p2) * (B - D * r * BETA_RANGE / 2)
        - beta * r * (2 * C + D * (p2 + p1) - 2 * E * r * BETA_RANGE)
        - 2 * G * beta_dot * r
    )
    return r / 1000 * bracket


# ----------------------------------------------------------------------------------------
# eq. 5 and the muscle state
# ----------------------------------------------------------------------------------------


def test_contractions_eq5_at_the_limits():
    y1, y2 = contractions_mm(RIGID, jnp.array([-0.6, 0.0, 0.6]))
    np.testing.assert_allclose(y1, [0.0, 24.0, 48.0], atol=1e-12)
    np.testing.assert_allclose(y2, [48.0, 24.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(y1 + y2, R_MM * BETA_RANGE)


def test_muscle_state_with_rigid_cables_is_eq3_at_eq5():
    beta = np.linspace(-0.6, 0.6, 5)
    s = muscle_state(TRAD, TRAD, RIGID, beta, 300.0, 150.0, 0.2, tensile_only=False)
    y1, y2 = R_MM * (0.6 + beta), R_MM * (0.6 - beta)
    np.testing.assert_array_equal(s.y1_mm, y1)
    np.testing.assert_array_equal(s.y2_mm, y2)
    v = R_MM * 0.2
    np.testing.assert_allclose(s.f1_N, [force_by_hand(300.0, y, v) for y in y1], rtol=1e-13)
    np.testing.assert_allclose(s.f2_N, [force_by_hand(150.0, y, -v) for y in y2], rtol=1e-13)


def test_cable_stretch_solves_the_implicit_contraction():
    beta = np.array([-0.5, 0.0, 0.4])
    s = muscle_state(TRAD, TRAD, CABLE, beta, 414.0, 200.0)
    c = CULLINAN_CABLE_COMPLIANCE_MM_PER_N
    for b, y1, f1 in zip(beta, np.asarray(s.y1_mm), np.asarray(s.f1_N), strict=True):
        y_geom = R_MM * (0.6 + b)
        exact = scipy.optimize.brentq(
            lambda y, y_geom=y_geom: y - y_geom - c * max(force_by_hand(414.0, y), 0.0),
            y_geom - 5.0,
            y_geom + 5.0,
            xtol=1e-14,
        )
        assert y1 == pytest.approx(exact, abs=1e-11)
        assert y1 > y_geom  # the stretched cable makes the muscle contract further
        assert f1 == pytest.approx(force_by_hand(414.0, y1), rel=1e-13)


# ----------------------------------------------------------------------------------------
# eq. 4 and eq. 6: the sign error
# ----------------------------------------------------------------------------------------


def test_eq6_corrected_equals_eq3_to_5_composed():
    beta, p1, p2, beta_dot = np.meshgrid(
        np.linspace(-0.6, 0.6, 7), [0.0, 150.0, 414.0], [0.0, 200.0, 414.0], [-1.0, 0.0, 0.5]
    )
    composed = joint_torque_Nm(TRAD, TRAD, RIGID, beta, p1, p2, beta_dot, tensile_only=False)
    closed = joint_torque_eq6_Nm(TRAD, RIGID, beta, p1, p2, beta_dot)
    np.testing.assert_allclose(closed, composed, rtol=1e-12, atol=1e-11)


def test_eq6_as_printed_disagrees_with_eq3_to_5():
    beta = np.array([-0.6, -0.3, 0.3, 0.6])
    composed = joint_torque_Nm(TRAD, TRAD, RIGID, beta, 300.0, 300.0, tensile_only=False)
    printed = eq6_as_printed(beta, 300.0, 300.0)
    # The difference is r·β·r·4·E·r·β_range (in N·m: 0.04·β·40·4·0.07·40·1.2 = 21.504·β).
    np.testing.assert_allclose(printed - composed, 21.504 * beta, rtol=1e-12)
    assert np.all(np.abs(printed - composed) > 6.0)


def test_torque_by_hand_with_one_muscle_slack():
    # β = 0.5, P2 = 0: muscle 2 (y2 = 4 mm) has F2 = −10 − (2 + 0.28)·4 < 0, so it is slack.
    beta = 0.5
    f1 = force_by_hand(250.0, R_MM * 1.1)
    f2 = force_by_hand(0.0, R_MM * 0.1)
    assert f2 < 0
    assert float(joint_torque_Nm(TRAD, TRAD, RIGID, beta, 250.0, 0.0)) == pytest.approx(
        0.04 * f1, rel=1e-13
    )
    assert float(
        joint_torque_Nm(TRAD, TRAD, RIGID, beta, 250.0, 0.0, tensile_only=False)
    ) == pytest.approx(0.04 * (f1 - f2), rel=1e-13)


# ----------------------------------------------------------------------------------------
# eq. 7 and the stiffness by differentiation
# ----------------------------------------------------------------------------------------


def test_eq7_by_hand():
    k = joint_stiffness_eq7_Nm_per_rad(TRAD, RIGID, 414.0, 414.0)
    # −(0.04 m)·(40 mm)·(2·2 + 0.05·828 + 2·0.07·40·1.2) N/mm = −83.392 N·m/rad
    assert float(k) == pytest.approx(-83.392, rel=1e-14)


@pytest.mark.parametrize("p1, p2", [(414.0, 414.0), (300.0, 120.0), (80.0, 250.0)])
def test_eq7_equals_grad_of_eq6_and_of_the_composition(p1, p2):
    eq7 = float(joint_stiffness_eq7_Nm_per_rad(TRAD, RIGID, p1, p2))
    for beta in (-0.4, 0.0, 0.35):
        by_eq6 = jax.grad(lambda b: joint_torque_eq6_Nm(TRAD, RIGID, b, p1, p2))(beta)
        by_composition = jax.grad(
            lambda b: joint_torque_Nm(TRAD, TRAD, RIGID, b, p1, p2, tensile_only=False)
        )(beta)
        by_jvp = joint_stiffness_Nm_per_rad(TRAD, TRAD, RIGID, beta, p1, p2, tensile_only=False)
        assert float(by_eq6) == pytest.approx(eq7, abs=1e-10)
        assert float(by_composition) == pytest.approx(eq7, abs=1e-10)
        assert float(by_jvp) == pytest.approx(eq7, abs=1e-10)
        # The printed eq. 6 has another slope: −r²(2C + D(P1+P2) − 2Erβ_range).
        by_printed = jax.grad(lambda b: eq6_as_printed(b, p1, p2))(beta)
        assert abs(float(by_printed) - eq7) > 10.0


def test_stiffness_with_cable_stretch_matches_finite_differences():
    beta = np.array([-0.45, 0.0, 0.2, 0.5])
    k = joint_stiffness_Nm_per_rad(TRAD, TRAD, CABLE, beta, 414.0, 300.0)
    h = 1e-6
    fd = (
        joint_torque_Nm(TRAD, TRAD, CABLE, beta + h, 414.0, 300.0)
        - joint_torque_Nm(TRAD, TRAD, CABLE, beta - h, 414.0, 300.0)
    ) / (2 * h)
    np.testing.assert_allclose(k, fd, rtol=1e-7)
    # The cables act in series with the muscles, so the joint is softer than with rigid ones.
    rigid = joint_stiffness_Nm_per_rad(TRAD, TRAD, RIGID, beta, 414.0, 300.0)
    assert np.all(np.abs(k) < np.abs(rigid))


def test_stiffness_broadcasts_and_works_under_jit_and_vmap():
    beta = jnp.linspace(-0.5, 0.5, 4)
    p1 = jnp.array([[100.0], [414.0]])
    k = joint_stiffness_Nm_per_rad(TRAD, TRAD, CABLE, beta, p1, 200.0)
    assert k.shape == (2, 4)
    jitted = jax.jit(lambda b: joint_stiffness_Nm_per_rad(TRAD, TRAD, CABLE, b, p1, 200.0))
    np.testing.assert_allclose(jitted(beta), k, rtol=1e-13)
    mapped = jax.vmap(
        lambda b: joint_stiffness_Nm_per_rad(TRAD, TRAD, CABLE, b, p1[:, 0], 200.0), out_axes=1
    )(beta)
    np.testing.assert_allclose(mapped, k, rtol=1e-13)


# ----------------------------------------------------------------------------------------
# Available torque (Fig. 4)
# ----------------------------------------------------------------------------------------


def test_available_torque_meets_the_papers_15_Nm_at_the_limits():
    limits = jnp.array([-0.6, 0.6])
    rigid = available_torque_Nm(TRAD, RIGID, limits)
    # At +0.6 rad muscle 1 is at y1 = 48 mm: 0.04 m · 395.12 N.
    assert float(rigid.toward_positive_Nm[1]) == pytest.approx(0.04 * 395.12, rel=1e-13)
    assert float(rigid.toward_negative_Nm[0]) == pytest.approx(0.04 * 395.12, rel=1e-13)
    stretched = available_torque_Nm(TRAD, CABLE, limits)
    assert float(stretched.toward_positive_Nm[1]) >= 15.0
    assert float(stretched.toward_positive_Nm[1]) < float(rigid.toward_positive_Nm[1])


def test_available_torque_is_mirror_symmetric_and_positive():
    beta = jnp.linspace(-0.6, 0.6, 13)
    t = available_torque_Nm(TRAD, CABLE, beta)
    np.testing.assert_allclose(t.toward_positive_Nm, t.toward_negative_Nm[::-1], rtol=1e-12)
    assert np.all(np.asarray(t.toward_positive_Nm) > 15.0)
    assert np.all(np.diff(np.asarray(t.toward_positive_Nm)) < 0)  # less force when contracted


# ----------------------------------------------------------------------------------------
# Maximum isobaric stiffness (Fig. 5)
# ----------------------------------------------------------------------------------------

_max_stiffness = max_isobaric_stiffness  # jitted inside, after its argument checks


def test_max_isobaric_stiffness_at_rest_with_no_torque_is_both_at_p_max():
    r = _max_stiffness(TRAD, RIGID, 0.0, 0.0)
    assert bool(r.feasible)
    assert float(r.p1_kPa) == pytest.approx(P_MAX, abs=1e-9)
    assert float(r.p2_kPa) == pytest.approx(P_MAX, abs=1e-9)
    assert float(r.stiffness_Nm_per_rad) == pytest.approx(83.392, rel=1e-12)


@pytest.mark.parametrize("geometry", [RIGID, CABLE], ids=["rigid", "cable"])
def test_max_isobaric_stiffness_matches_a_grid_search(geometry):
    betas = np.array([-0.5, -0.2, 0.0, 0.3, 0.55])
    torques = np.array([0.0, 10.0, 20.0])
    result = _max_stiffness(TRAD, geometry, betas[:, None], torques[None, :])
    assert result.stiffness_Nm_per_rad.shape == (5, 3)

    grid = np.linspace(0.0, P_MAX, 415)  # 1 kPa steps
    b, p1, p2 = np.meshgrid(betas, grid, grid, indexing="ij")
    torque_grid = np.asarray(jax.jit(joint_torque_Nm)(TRAD, TRAD, geometry, b, p1, p2))
    stiff_grid = -np.asarray(jax.jit(joint_stiffness_Nm_per_rad)(TRAD, TRAD, geometry, b, p1, p2))
    for i in range(len(betas)):
        for j, tau in enumerate(torques):
            near = np.abs(torque_grid[i] - tau) < 0.08  # ≈ the torque change of one grid step
            found = bool(result.feasible[i, j])
            assert found == bool(near.any()), (betas[i], tau)
            if not found:
                assert np.isnan(result.stiffness_Nm_per_rad[i, j])
                assert np.isnan(result.p1_kPa[i, j]) and np.isnan(result.p2_kPa[i, j])
                continue
            best = stiff_grid[i][near].max()
            assert float(result.stiffness_Nm_per_rad[i, j]) == pytest.approx(best, abs=0.15)
            assert float(result.stiffness_Nm_per_rad[i, j]) >= best - 0.1


BETAS6 = jnp.linspace(-0.55, 0.5, 6)  # one shape for several tests: one compilation


def test_max_isobaric_stiffness_satisfies_its_constraints():
    r = _max_stiffness(TRAD, CABLE, BETAS6, 12.0)
    assert bool(r.feasible.all())
    torque = joint_torque_Nm(TRAD, TRAD, CABLE, BETAS6, r.p1_kPa, r.p2_kPa)
    np.testing.assert_allclose(torque, 12.0, atol=1e-9)
    p1, p2 = np.asarray(r.p1_kPa), np.asarray(r.p2_kPa)
    assert np.all((p1 >= -1e-9) & (p1 <= P_MAX + 1e-9) & (p2 >= -1e-9) & (p2 <= P_MAX + 1e-9))
    assert np.all(np.isclose(np.maximum(p1, p2), P_MAX, atol=1e-9))  # one muscle at P_max


def test_max_isobaric_stiffness_vmap_equals_broadcasting():
    broadcast = _max_stiffness(TRAD, CABLE, BETAS6, 10.0)
    mapped = jax.vmap(lambda b: max_isobaric_stiffness(TRAD, CABLE, b, 10.0))(BETAS6)
    np.testing.assert_allclose(mapped.stiffness_Nm_per_rad, broadcast.stiffness_Nm_per_rad)
    np.testing.assert_array_equal(mapped.feasible, broadcast.feasible)


def test_max_isobaric_stiffness_gradient_in_torque():
    def k(tau):
        return _max_stiffness(TRAD, CABLE, 0.25, tau).stiffness_Nm_per_rad

    h = 1e-3
    fd = (k(10.0 + h) - k(10.0 - h)) / (2 * h)
    assert float(jax.grad(k)(10.0)) == pytest.approx(float(fd), rel=1e-6)


def test_max_isobaric_stiffness_unreachable_torque_is_nan():
    # ±100 N·m is beyond the joint at any angle (at most 66 N·m, at the far limit).
    torque = jnp.array([100.0, -100.0, 100.0, -100.0, 100.0, -100.0])
    r = _max_stiffness(TRAD, RIGID, BETAS6, torque)
    assert not bool(r.feasible.any())
    assert np.all(np.isnan(r.stiffness_Nm_per_rad))


# ----------------------------------------------------------------------------------------
# Pressures from torque and stiffness (eq. 6 and eq. 7 inverted)
# ----------------------------------------------------------------------------------------


def test_pressures_for_torque_and_stiffness_invert_eq6_and_eq7():
    beta = np.linspace(-0.3, 0.3, 7)
    p1, p2 = pressures_for_torque_stiffness_kPa(TRAD, RIGID, beta, 20.0, 50.0)
    np.testing.assert_allclose(joint_torque_eq6_Nm(TRAD, RIGID, beta, p1, p2), 20.0, rtol=1e-12)
    np.testing.assert_allclose(
        joint_stiffness_eq7_Nm_per_rad(TRAD, RIGID, p1, p2), -50.0, rtol=1e-12
    )


# ----------------------------------------------------------------------------------------
# Bad arguments
# ----------------------------------------------------------------------------------------


def test_bad_geometry_is_rejected():
    with pytest.raises(ValueError, match="beta_range_rad must be > 0"):
        JointGeometry(40.0, 0.0)
    with pytest.raises(ValueError, match="pulley_radius_mm must be > 0"):
        JointGeometry(-40.0, 1.2)
    with pytest.raises(ValueError, match="cable_compliance_mm_per_N must be >= 0"):
        JointGeometry(40.0, 1.2, -0.001)


def test_bad_pressure_limits_and_deflections_are_rejected():
    with pytest.raises(ValueError, match="p_max_kPa must be > 0"):
        available_torque_Nm(TRAD, RIGID, 0.0, p_max_kPa=0.0)
    with pytest.raises(ValueError, match="p_max_kPa must be > 0"):
        max_isobaric_stiffness(TRAD, RIGID, 0.0, 5.0, p_max_kPa=-1.0)
    vol = traditional_pam_volume()
    with pytest.raises(ValueError, match="direction must be"):
        closed_system_stiffness(TRAD, TRAD, RIGID, vol, 0.0, 300.0, 300.0, direction=0)
    with pytest.raises(ValueError, match="deflections_deg must be > 0"):
        closed_system_stiffness(TRAD, TRAD, RIGID, vol, 0.0, 300.0, 300.0, (3.0, -5.0))
    with pytest.raises(ValueError, match="n_samples must be >= 2"):
        closed_system_stiffness(TRAD, TRAD, RIGID, vol, 0.0, 300.0, 300.0, n_samples=1)


def test_geometry_under_jit_skips_the_value_checks():
    # Traced values cannot be checked; construction inside jit must still work.
    torque = jax.jit(lambda r: joint_torque_Nm(TRAD, TRAD, JointGeometry(r, 1.2), 0.1, 300, 200))
    assert float(torque(40.0)) == pytest.approx(
        float(joint_torque_Nm(TRAD, TRAD, RIGID, 0.1, 300, 200)), rel=1e-14
    )
