"""The virtual joint bench (Cullinan Sections IV–V): reproducible, in torque balance, and its
deflection test measures what :func:`closed_system_stiffness` predicts."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np
import pandas as pd
import pytest

import pamid  # noqa: F401  (switches float64 on)
from pamid._models import _cullinan_presets as cp
from pamid._models._joint import (
    available_torque_Nm,
    closed_system_stiffness,
    closed_system_torque_Nm,
)
from pamid._virtual._joint import (
    DeflectionProtocol,
    JointSweepProtocol,
    deflection_test_stiffness,
    simulate_deflection_test,
    simulate_joint_sweep,
)

QUIET = dict(
    angle_resolution_rad=0.0,
    pressure_noise_sd_kPa=0.0,
    pressure_resolution_kPa=0.0,
    force_noise_sd_N=0.0,
    force_resolution_N=0.0,
)
SWEEP = JointSweepProtocol(test_pressures_kPa=(137.9, 413.7), points_per_ramp=15)
QUIET_SWEEP = dataclasses.replace(SWEEP, **QUIET)
SET_POINTS = ((0.0, 300.0, 300.0), (-0.3, 150.0, 250.0), (0.25, 380.0, 200.0))
QUIET_DEFLECTION = DeflectionProtocol(set_points=SET_POINTS, **QUIET)


@pytest.fixture(scope="module")
def sleeve_sweep():
    return simulate_joint_sweep(jax.random.key(0), cp.sleeve_pam(), cp.sleeve_joint_B(),
                                QUIET_SWEEP)


def test_sweep_is_reproducible_with_a_key():
    a = simulate_joint_sweep(jax.random.key(3), cp.traditional_pam(), cp.traditional_joint(),
                             SWEEP)
    b = simulate_joint_sweep(jax.random.key(3), cp.traditional_pam(), cp.traditional_joint(),
                             SWEEP)
    c = simulate_joint_sweep(jax.random.key(4), cp.traditional_pam(), cp.traditional_joint(),
                             SWEEP)
    pd.testing.assert_frame_equal(a, b)
    assert not np.allclose(a["force1_N"], c["force1_N"])
    assert list(a.columns[:8]) == ["time_s", "test_pressure_kPa", "phase", "direction",
                                   "test_muscle", "angle_rad", "pressure1_kPa",
                                   "pressure2_kPa"]
    assert {"force1_N", "force2_N", "torque_Nm", "test_torque_Nm", "at_limit"} <= set(a)
    assert np.all(np.diff(a["time_s"]) >= 0)
    # Sensors: the encoder reads whole counts, the load cell 0.1 N steps.
    counts = a["angle_rad"] / (2 * np.pi / 4096)
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)


def test_torque_balance_at_every_sample(sleeve_sweep):
    """Unloaded joint: r·(F1 − F2) = 0 wherever the joint is not resting on a limit."""
    free = sleeve_sweep[~sleeve_sweep["at_limit"]]
    assert len(free) > 0.6 * len(sleeve_sweep)
    np.testing.assert_allclose(free["torque_Nm"], 0.0, atol=1e-9)
    # On a limit, the net torque pushes into that limit (the stop carries it).
    stop = sleeve_sweep[sleeve_sweep["at_limit"]]
    assert np.all(np.sign(stop["torque_Nm"]) == np.sign(stop["angle_rad"]))
    np.testing.assert_allclose(np.abs(stop["angle_rad"]), 0.6, rtol=1e-12)


def test_roles_swap_at_zero_and_the_joint_returns(sleeve_sweep):
    for p, g in sleeve_sweep.groupby("test_pressure_kPa"):
        end_of_1 = g[g["phase"] == 1].iloc[-1]
        assert end_of_1["pressure1_kPa"] == end_of_1["pressure2_kPa"] == p
        assert end_of_1["angle_rad"] == pytest.approx(0.0, abs=1e-12)
        # Phase 1 runs towards −β, phase 4 retraces it; without friction the same path.
        one = g[g["phase"] == 1]["angle_rad"].to_numpy()
        four = g[g["phase"] == 4]["angle_rad"].to_numpy()[::-1]
        np.testing.assert_allclose(one, four, atol=1e-12)
        assert np.all(np.diff(one) <= 1e-12)


def test_test_torque_is_the_available_torque_at_the_measured_angle(sleeve_sweep):
    """Fig. 4's solid line lies on the model line of the PAM at the test pressure."""
    g = sleeve_sweep[sleeve_sweep["phase"].isin((1, 4)) & ~sleeve_sweep["at_limit"]]
    model = available_torque_Nm(cp.sleeve_pam(), cp.sleeve_joint_B(),
                                g["angle_rad"].to_numpy(), g["test_pressure_kPa"].to_numpy())
    np.testing.assert_allclose(g["test_torque_Nm"], model.toward_positive_Nm, rtol=1e-10)


def test_hysteresis_separates_the_two_directions():
    proto = dataclasses.replace(QUIET_SWEEP, hysteresis_N=15.0)
    frame = simulate_joint_sweep(jax.random.key(0), cp.sleeve_pam(), cp.sleeve_joint_B(), proto)
    g = frame[frame["test_pressure_kPa"] == 413.7]
    down = g[g["phase"] == 1]
    up = g[g["phase"] == 4].iloc[::-1]
    free = ~(down["at_limit"].to_numpy() | up["at_limit"].to_numpy())
    # Same pressures; moving towards −β the friction holds the joint higher.
    assert np.all(down["angle_rad"].to_numpy()[free] > up["angle_rad"].to_numpy()[free] + 1e-3)
    # The readings include the friction, so the load cells still balance.
    np.testing.assert_allclose(g[~g["at_limit"]]["torque_Nm"], 0.0, atol=1e-9)


@pytest.fixture(scope="module")
def deflection():
    frame = simulate_deflection_test(jax.random.key(1), cp.sleeve_pam(), cp.sleeve_joint_A(),
                                     cp.sleeve_volume(), QUIET_DEFLECTION)
    return frame


def test_deflection_slope_equals_closed_system_stiffness(deflection):
    measured = deflection_test_stiffness(deflection)
    beta0, p1, p2 = (np.array(c) for c in zip(*SET_POINTS))
    model = closed_system_stiffness(cp.sleeve_pam(), cp.sleeve_pam(), cp.sleeve_joint_A(),
                                    cp.sleeve_volume(), beta0, p1, p2)
    got = measured.pivot(index="set_point", columns="deflection_deg",
                         values="stiffness_Nm_per_rad").to_numpy()
    np.testing.assert_allclose(got, np.asarray(model.regression_Nm_per_rad), rtol=1e-8)


def test_deflection_torque_and_pressures_follow_the_sealed_model(deflection):
    for sp, (beta0, p1, p2) in enumerate(SET_POINTS):
        g = deflection[deflection["set_point"] == sp]
        torque = closed_system_torque_Nm(cp.sleeve_pam(), cp.sleeve_pam(), cp.sleeve_joint_A(),
                                         cp.sleeve_volume(), beta0, p1, p2,
                                         g["angle_rad"].to_numpy())
        np.testing.assert_allclose(g["torque_Nm"], torque, rtol=1e-9, atol=1e-9)
        out = g[(g["leg"] == "out") & (g["deflection_deg"] == 8.0)]
        # Towards +β muscle 1 shortens (its volume grows, its pressure falls), muscle 2
        # lengthens; the set point is the first sample.
        assert out["pressure1_kPa"].iloc[0] == pytest.approx(p1)
        assert np.all(np.diff(out["pressure1_kPa"]) < 0)
        assert np.all(np.diff(out["pressure2_kPa"]) > 0)
        assert out["angle_rad"].iloc[-1] - beta0 == pytest.approx(np.deg2rad(8.0))


def test_deflection_is_reproducible_and_noisy_with_a_key():
    proto = DeflectionProtocol(set_points=SET_POINTS[:1])
    args = (cp.traditional_pam(), cp.traditional_joint(), cp.traditional_volume(), proto)
    a = simulate_deflection_test(jax.random.key(5), *args)
    b = simulate_deflection_test(jax.random.key(5), *args)
    c = simulate_deflection_test(jax.random.key(6), *args)
    pd.testing.assert_frame_equal(a, b)
    assert not np.allclose(a["torque_Nm"], c["torque_Nm"])
    # Noise moves the slope by little: within 3 N·m/rad of the noise-free one.
    quiet = simulate_deflection_test(jax.random.key(5), *args[:3],
                                     dataclasses.replace(proto, **QUIET))
    np.testing.assert_allclose(deflection_test_stiffness(a)["stiffness_Nm_per_rad"],
                               deflection_test_stiffness(quiet)["stiffness_Nm_per_rad"],
                               atol=3.0)


def test_friction_stiffens_small_deflections_most():
    """A friction that builds up over 0.5 mm adds apparent stiffness, most at 3°."""
    base = dataclasses.replace(QUIET_DEFLECTION, set_points=SET_POINTS[:1])
    args = (cp.sleeve_pam(), cp.sleeve_joint_B(), cp.sleeve_volume())
    plain = deflection_test_stiffness(simulate_deflection_test(jax.random.key(0), *args, base))
    rough = deflection_test_stiffness(simulate_deflection_test(
        jax.random.key(0), *args,
        dataclasses.replace(base, hysteresis_N=20.0, friction_length_mm=0.5)))
    extra = (rough["stiffness_Nm_per_rad"] - plain["stiffness_Nm_per_rad"]).to_numpy()
    assert np.all(extra > 0)
    assert extra[0] > extra[1] > extra[2]  # 3°, 5°, 8°


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(points_per_ramp=1), "points_per_ramp"),
        (dict(test_pressures_kPa=()), "test_pressures_kPa"),
        (dict(force_noise_sd_N=-1.0), "force_noise_sd_N"),
        (dict(hysteresis_N=-2.0), "hysteresis_N"),
    ],
)
def test_sweep_protocol_rejects_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        JointSweepProtocol(**kwargs)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (dict(direction=0), "direction"),
        (dict(deflections_deg=(3.0, -5.0)), "deflections_deg"),
        (dict(set_points=((0.0, 300.0),)), "set_points"),
        (dict(friction_length_mm=-1.0), "friction_length_mm"),
    ],
)
def test_deflection_protocol_rejects_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DeflectionProtocol(**kwargs)
