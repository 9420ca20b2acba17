"""Sárosi's positioning rigs (Sections 2.4, 3.3): valve, sliding-mode controller, encoder,
temperature, and the ``pamid simulate positioning`` command function."""

from __future__ import annotations

import argparse
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamid
from pamid._commands.positioning import add_positioning_parser
from pamid._control._positioning import (
    DMSP10_HYSTERESIS_N_PER_BAR,
    PositioningRun,
    linear_rig,
    positioning_metrics,
    rotary_rig,
    sarosi_from_fit_json,
    simulate_positioning,
    single_muscle_rig,
    wald_draws,
)
from pamid._control._sliding_mode import (
    SlidingModeController,
    plain_switching,
    sliding_mode_voltage,
    sliding_surface,
)
from pamid._control._thermal import (
    TABLE_3_2,
    MuscleThermal,
    fit_table_3_2,
    sarosi_at_temperature,
    steady_state_temperature_C,
    temperature_after_C,
)
from pamid._control._valve import (
    RHO_ANR_KG_PER_M3,
    T_ANR_K,
    ProportionalValve,
    orifice_mass_flow_kg_s,
    sonic_conductance_from_nominal_flow,
    valve_mass_flows_kg_s,
    valve_opening,
)
from pamid._models._sarosi import table_3_1_fit_json

LINEAR = SlidingModeController(0.35, 0.015, 2.0)
DURATION_S = 3.0  # one length for every closed-loop run below: one compilation per shape


# --------------------------------------------------------------------------------------
# controller: every voltage band, worked by hand
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("s", "e", "volts"),
    [
        (0.0, 0.0, 5.0),  # at the target, at rest: in position
        (0.5, 0.01, 5.0),  # one count off and moving: inside the precision zone (|e| < 0.015)
        (-0.5, -0.014, 5.0),
        (0.006, 0.02, 5.35),  # two counts off: outside the zone; |s| < λ·ε_s = 0.7: slow
        (-0.006, 0.02, 4.65),  # the sign of s, not of e, picks the direction
        (0.699, 1.0, 5.35),
        (0.7, 1.0, 6.0),  # fast from |s| = λ·ε_s on
        (-0.7, 1.0, 4.0),
        (-12.0, -30.0, 4.0),
    ],
)
def test_voltage_bands(s, e, volts):
    assert float(sliding_mode_voltage(LINEAR, s, e)) == volts


def test_sliding_surface_by_hand():
    # s = λ·e − (q_k − q_{k−1}) = 0.35·0.5 − (1.2 − 1.0) = −0.025
    assert float(sliding_surface(LINEAR, 0.5, 1.0, 1.2)) == pytest.approx(-0.025, abs=1e-15)
    # approaching at 0.1 mm per sample 1 mm away: 0.35 − 0.1 = 0.25 > 0, keep going (slow)
    s = sliding_surface(LINEAR, 1.0, 13.9, 14.0)
    assert float(s) == pytest.approx(0.25) and float(sliding_mode_voltage(LINEAR, s, 1.0)) == 5.35


def test_plain_switching_never_holds():
    plain = plain_switching(LINEAR)
    s = jnp.array([-0.003, 0.0, 0.003])
    np.testing.assert_array_equal(sliding_mode_voltage(plain, s, 0.0), [4.65, 4.65, 5.35])
    np.testing.assert_array_equal(sliding_mode_voltage(LINEAR, s, 0.0), [5.0, 5.0, 5.0])


def test_for_encoder_zones():
    c = SlidingModeController.for_encoder(0.036, 0.3)
    assert float(c.precision_zone) == pytest.approx(1.5 * 0.036)
    assert float(c.slow_band) == pytest.approx(200 * 0.036)


# --------------------------------------------------------------------------------------
# valve
# --------------------------------------------------------------------------------------


def test_orifice_choked_unchoked_and_reverse():
    c, p_up, t = 1e-8, 7e5, 300.0
    choked = c * RHO_ANR_KG_PER_M3 * p_up * math.sqrt(T_ANR_K / t)
    # r = 0.2 < b = 0.3: choked, independent of the downstream pressure
    assert float(orifice_mass_flow_kg_s(c, p_up, 0.2 * p_up, t, t)) == pytest.approx(choked)
    assert float(orifice_mass_flow_kg_s(c, p_up, 0.3 * p_up, t, t)) == pytest.approx(choked)
    # r = 0.65: φ = √(1 − (0.35/0.7)²) = √0.75
    unchoked = float(orifice_mass_flow_kg_s(c, p_up, 0.65 * p_up, t, t))
    assert unchoked == pytest.approx(choked * math.sqrt(0.75))
    # reversed pressures: the same flow, the other way
    assert float(orifice_mass_flow_kg_s(c, 0.65 * p_up, p_up, t, t)) == pytest.approx(-unchoked)
    assert abs(float(orifice_mass_flow_kg_s(c, p_up, p_up, t, t))) < 1e-6 * choked


def test_nominal_flow_round_trip():
    c = sonic_conductance_from_nominal_flow(700.0, 0.3)
    atm = pamid._units.ATMOSPHERE_KPA * 1000.0
    flow = float(orifice_mass_flow_kg_s(c, 6e5 + atm, 5e5 + atm, T_ANR_K, T_ANR_K))
    assert flow / RHO_ANR_KG_PER_M3 * 60_000 == pytest.approx(700.0)


def test_valve_opening_with_overlap():
    valve = ProportionalValve(1e-8, overlap_V=0.3)
    u = jnp.array([4.0, 4.65, 4.7, 5.0, 5.3, 5.35, 6.0, 10.0, 11.0])
    want = [-0.7 / 4.7, -0.05 / 4.7, 0.0, 0.0, 0.0, 0.05 / 4.7, 0.7 / 4.7, 1.0, 1.0]
    np.testing.assert_allclose(valve_opening(valve, u), want, atol=1e-12)


def test_valve_directions_and_closed_centre():
    valve = ProportionalValve(1e-8, overlap_V=0.0)
    args = (4e5, 3e5, 293.0, 293.0, 7e5, 297.0, 1.013e5)
    a, b = valve_mass_flows_kg_s(valve, 5.0, *args)
    assert float(a) == 0.0 and float(b) == 0.0
    a, b = valve_mass_flows_kg_s(valve, 6.0, *args)
    assert float(a) > 0 > float(b)
    a2, _ = valve_mass_flows_kg_s(valve, 7.0, *args)
    assert float(a2) == pytest.approx(2 * float(a))  # opening linear in |u − 5 V|
    a, b = valve_mass_flows_kg_s(valve, 4.0, *args)
    assert float(a) < 0 < float(b)


# --------------------------------------------------------------------------------------
# closed loop
# --------------------------------------------------------------------------------------


def test_closed_valve_holds_mass():
    # a precision zone wider than any surface value: the valve never leaves 5 V
    hold = SlidingModeController(0.35, 1e9, 2e9)
    run = simulate_positioning(linear_rig(), hold, 15.0, duration_s=DURATION_S)
    np.testing.assert_array_equal(run.voltage_V, 5.0)
    assert np.ptp(np.asarray(run.air_A_kg)) == 0.0 and np.ptp(np.asarray(run.air_B_kg)) == 0.0
    # and the rig, released at its balanced state, stays put
    assert np.max(np.abs(np.asarray(run.position))) < 1e-9


@pytest.fixture(scope="module")
def single_runs():
    """The single-muscle rig (Fig. 2-6, 20 kg) to 5 mm with and without the zone, batched."""
    rig = single_muscle_rig()
    both = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), LINEAR, plain_switching(LINEAR))
    return simulate_positioning(rig, both, 5.0, duration_s=DURATION_S)


def test_no_chattering_inside_precision_zone(single_runs):
    m = positioning_metrics(single_runs, 0.0, 0.01)
    zone_settled, plain_settled = np.isfinite(np.asarray(m["settling_time_s"]))
    assert zone_settled
    last_second = np.asarray(single_runs.voltage_V)[:, -100:]
    np.testing.assert_array_equal(last_second[0], 5.0)  # zone: valve shut, no switching
    switches_plain = np.sum(last_second[1, 1:] != last_second[1, :-1])
    assert switches_plain >= 20  # plain switching chatters at the target
    assert not np.any(last_second[1] == 5.0)


def test_quantized_error_bounded_by_one_count(single_runs):
    reading = np.asarray(single_runs.reading)[:, -100:]
    position = np.asarray(single_runs.position)[:, -100:]
    # with the zone, over the last second: the encoder error is at most one count, the true
    # error one count plus the encoder's half count of rounding
    assert np.max(np.abs(5.0 - reading[0])) <= 0.01 + 1e-12
    assert np.max(np.abs(5.0 - position[0])) <= 0.015 + 1e-12
    # readings are whole counts
    np.testing.assert_allclose(reading / 0.01, np.round(reading / 0.01), atol=1e-9)
    # without it the loop hunts over several counts
    assert np.max(np.abs(5.0 - reading[1])) >= 0.03


def test_batch_equals_loop():
    fit = table_3_1_fit_json()
    muscle, se = sarosi_from_fit_json(fit)
    draws = wald_draws(jax.random.key(3), muscle, se, 3)
    batch = simulate_positioning(linear_rig(draws), LINEAR, 15.0, duration_s=DURATION_S)
    for i in range(3):
        one = jax.tree_util.tree_map(lambda a, i=i: a[i], draws)
        loop = simulate_positioning(linear_rig(one), LINEAR, 15.0, duration_s=DURATION_S)
        np.testing.assert_allclose(batch.position[i], loop.position, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(batch.voltage_V[i], loop.voltage_V)


def test_positioning_metrics_by_hand():
    t = 0.01 * jnp.arange(6)
    pos = jnp.array([0.0, 0.5, 1.03, 0.995, 1.0, 1.002])
    reading = jnp.round(pos / 0.01) * 0.01
    volts = jnp.array([6.0, 5.35, 4.65, 5.0, 5.0, 5.0])
    run = PositioningRun(t, jnp.ones(6), pos, reading, volts, volts, volts, volts, volts, volts)
    m = positioning_metrics(run, 0.0, 0.01)
    assert float(m["settling_time_s"]) == pytest.approx(0.03)  # last outside: sample 2
    assert float(m["settling_time_2pct_s"]) == pytest.approx(0.03)  # 1.03 > 1.02
    assert float(m["overshoot"]) == pytest.approx(0.03)
    assert float(m["steady_state_error"]) == pytest.approx(0.002)
    assert float(m["steady_state_error_reading"]) == pytest.approx(0.0, abs=1e-12)
    assert int(m["valve_switches_settled"]) == 0
    assert float(m["reach_time_s"]) == pytest.approx(0.03)  # first inside = last outside + 1


def test_reach_time_before_settling_by_hand():
    # within one count at sample 2, out again at sample 3 (overshoot 3 counts), back at 4
    t = 0.01 * jnp.arange(6)
    pos = jnp.array([[0.0, 0.6, 0.992, 1.03, 1.0, 1.0], [0.0, 0.2, 0.4, 0.6, 0.8, 0.9]])
    reading = jnp.round(pos / 0.01) * 0.01
    v = jnp.full((2, 6), 5.0)
    run = PositioningRun(t, jnp.ones(6), pos, reading, v, v, v, v, v, v)
    m = positioning_metrics(run, 0.0, 0.01)
    np.testing.assert_allclose(m["reach_time_s"][0], 0.02)
    np.testing.assert_allclose(m["settling_time_s"][0], 0.04)
    np.testing.assert_allclose(m["overshoot_reading"][0], 0.03, atol=1e-12)
    assert np.isnan(m["reach_time_s"][1]) and np.isnan(m["settling_time_s"][1])


def test_dmsp10_loop_scaled_by_force_per_bar():
    # h = 3 N/bar × (a1 + a5 of the Martens fit)/(a1 + a5 of Table 3-1)
    #   = 3 × (−3.0515 + 91.4042)/(−4.3557 + 302.2011) = 3 × 88.3526/297.8453 = 0.88992
    assert DMSP10_HYSTERESIS_N_PER_BAR == pytest.approx(0.88992, abs=1e-5)
    assert float(rotary_rig().hysteresis_N_per_bar) == DMSP10_HYSTERESIS_N_PER_BAR


def test_rotary_rig_as_fig_3_13():
    # calibrated to Sárosi Fig. 3-13: 5.004° reached at about 0.8 s, overshoot 0.072° (two
    # counts), then held within one count (0.036°); the model must keep doing so
    run = simulate_positioning(
        rotary_rig(), SlidingModeController.for_encoder(0.036, 0.3), 5.004, duration_s=DURATION_S
    )
    m = {k: float(v) for k, v in positioning_metrics(run, 0.0, 0.036).items()}
    assert 0.6 <= m["reach_time_s"] <= 1.0
    assert m["overshoot_reading"] <= 2 * 0.036 + 1e-9
    assert m["settling_time_s"] <= 1.2
    assert np.max(np.abs(5.004 - np.asarray(run.reading)[-100:])) <= 0.036 + 1e-9
    assert float(rotary_rig().output_per_mm) == pytest.approx(180.0 / (math.pi * 40.0))


# --------------------------------------------------------------------------------------
# temperature
# --------------------------------------------------------------------------------------


def test_thermal_fit_recovers_known_constants():
    truth = MuscleThermal(60.0, 0.3, 2.0)
    freqs = np.array([0.1, 0.25, 0.5, 1.0])
    t_ss = np.asarray(steady_state_temperature_C(truth, freqs))
    table = {f: (t - 1.0, t + 1.0) for f, t in zip(freqs, t_ss, strict=True)}
    got = fit_table_3_2(0.3, 300.0, 24.0, table)
    assert float(got.heat_per_cycle_J) == pytest.approx(60.0, rel=1e-10)
    assert float(got.exchange_W_per_K_Hz) == pytest.approx(2.0, rel=1e-10)


def test_thermal_fit_to_table_3_2():
    th = fit_table_3_2()
    t_ss = np.asarray(steady_state_temperature_C(th, np.array(sorted(TABLE_3_2))))
    assert np.all(np.diff(t_ss) > 0)  # rises with the frequency, as Table 3-2 does
    for f, t in zip(sorted(TABLE_3_2), t_ss, strict=True):
        lo, hi = TABLE_3_2[f]
        assert lo - 2.0 <= t <= hi + 2.0, (f, t)


def test_temperature_after_solves_the_ode():
    th = fit_table_3_2()
    f, t0 = 0.5, -10.0
    assert float(temperature_after_C(th, f, 0.0, t0)) == pytest.approx(t0)
    assert float(temperature_after_C(th, f, 1e6, t0)) == pytest.approx(
        float(steady_state_temperature_C(th, f))
    )
    temp, rate = jax.jvp(lambda t: temperature_after_C(th, f, t, t0), (100.0,), (1.0,))
    rhs = (
        th.heat_per_cycle_J * f
        - (th.convection_W_per_K + th.exchange_W_per_K_Hz * f) * (temp - th.air_C)
    ) / th.heat_capacity_J_per_K
    assert float(rate) == pytest.approx(float(rhs), rel=1e-10)


def test_sarosi_at_temperature(sarosi31):
    same = sarosi_at_temperature(sarosi31, 20.0, -0.01, 20.0)
    np.testing.assert_allclose(same.to_vector(), sarosi31.to_vector())
    warm = sarosi_at_temperature(sarosi31, 30.0, -0.01, 20.0)  # elastic part × 0.9
    p, k = 3.0, 10.0
    f0 = sarosi31.a2 * jnp.exp(sarosi31.a3 * k) + sarosi31.a6
    got = pamid.sarosi.sarosi_force(warm, p, k) - pamid.sarosi.sarosi_force(sarosi31, p, k)
    assert float(got) == pytest.approx(float(-0.1 * f0))


def test_warm_muscle_positions_faster():
    rig = single_muscle_rig(temperature_C=jnp.array([-10.0, 39.0]))
    run = simulate_positioning(rig, LINEAR, 40.0, duration_s=DURATION_S)
    t2 = np.asarray(positioning_metrics(run, 0.0, 0.01)["settling_time_2pct_s"])
    assert np.all(np.isfinite(t2)) and t2[1] < t2[0]


# --------------------------------------------------------------------------------------
# fit JSON and the command function
# --------------------------------------------------------------------------------------


def test_fit_json_errors():
    with pytest.raises(ValueError, match="model 'cullinan'"):
        sarosi_from_fit_json({"model": "cullinan", "muscles": []})
    with pytest.raises(ValueError, match="muscle index 2"):
        sarosi_from_fit_json({"model": "sarosi", "muscles": [{}]}, 2)
    with pytest.raises(ValueError, match="no value for a1"):
        sarosi_from_fit_json({"model": "sarosi", "muscles": [{"params": {}}]})


def _parse(argv):
    parser = argparse.ArgumentParser()
    systems = parser.add_subparsers(dest="system", required=True)
    add_positioning_parser(systems)
    return parser.parse_args(["positioning", *argv])


def test_command_json(tmp_path, capsys, sarosi31):
    fit = {
        "model": "sarosi",
        "muscles": [
            {
                "params": {
                    k: {"value": float(v), "ci95": [float(v) - 1.0, float(v) + 1.0], "se": 0.5}
                    for k, v in zip(
                        pamid.Sarosi.names, np.asarray(sarosi31.to_vector()), strict=True
                    )
                }
            }
        ],
    }
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fit))
    args = _parse(
        [
            "--target-mm",
            "15",
            "--fit",
            str(path),
            "--json",
            "--duration-s",
            str(DURATION_S),
            "--out",
            str(tmp_path / "out"),
        ]
    )
    assert args.func(args) == 0
    d = json.loads(capsys.readouterr().out)
    for key in ("settling_time_s", "overshoot_mm", "steady_state_error_mm"):
        assert key in d
    assert d["settled"] and 0.5 < d["settling_time_s"] < DURATION_S
    assert d["steady_state_error_mm"] <= 0.015
    assert (tmp_path / "out" / "positioning.png").stat().st_size > 0
    assert json.loads((tmp_path / "out" / "positioning.json").read_text())["target_mm"] == 15.0


def test_command_rejects_bad_target():
    args = _parse(["--target-mm", "35"])
    with pytest.raises(ValueError, match="--target-mm"):
        args.func(args)
