"""Free decays: the virtual decay bench, the decay-file loader (bad files by message), peak
detection under encoder steps and noise, ζ recovered by the logarithmic decrement (Cullinan
eq. 8–11) and by the trajectory fit, Coulomb friction found, eq. 12, and ``pamid damping``."""

from __future__ import annotations

import argparse
import json
import math

import jax
import numpy as np
import pandas as pd
import pytest
import scipy.signal

import pamid
from pamid._commands.dynamics import register
from pamid._data._decay_file import load_decay
from pamid._decays._analysis import (
    analyze_decays,
    decrement_estimate,
    find_extrema,
    log_decrement_to_zeta,
    moment_of_inertia_eq12,
)
from pamid._sim._oscillator import DampedOscillator, oscillator_response
from pamid._virtual._decay import DecayProtocol, coulomb_decay, simulate_decays

J = 0.46  # kg·m², Cullinan's arm with two 1.2 kg weights
K = 88.0  # N·m/rad, Cullinan Fig. 7
F_N = math.sqrt(K / J) / (2 * math.pi)  # ≈ 2.2 Hz
STEP = 2 * math.pi / 4096  # 12-bit absolute encoder (CUI AMT203)


def decays(zeta, *, seed=0, coulomb=0.0, **protocol):
    osc = DampedOscillator.from_modal(zeta, F_N, J, equilibrium_rad=0.0123)
    settings = {"n_trials": 3, "deflections_deg": (9.0, 6.0, -8.0), "noise_sd_rad": 0.5 * STEP,
                "hold_s": 0.3, **protocol}
    return simulate_decays(jax.random.key(seed), osc, DecayProtocol(**settings),
                           coulomb_Nm=coulomb)


def write(frame, tmp_path, name="decay.csv"):
    path = tmp_path / name
    frame.to_csv(path, index=False)
    return path


# --------------------------------------------------------------------------------------
# Eq. 10 and eq. 12
# --------------------------------------------------------------------------------------


def test_eq_10_inverts_the_decrement_of_a_viscous_decay():
    zeta = np.array([0.01, 0.05, 0.2, 0.7])
    delta = 2 * np.pi * zeta / np.sqrt(1 - zeta**2)  # ln(x_n / x_{n+1}) over one period
    np.testing.assert_allclose(log_decrement_to_zeta(delta), zeta, rtol=1e-14)


def test_moment_of_inertia_eq_12_corrected():
    # Each part alone: a rod about its end, a cylinder about a diameter, a point mass.
    assert moment_of_inertia_eq12(3.0, 1.0, 0.0, 0.0, 0.0, 0.0) == pytest.approx(1.0)
    assert moment_of_inertia_eq12(0.0, 0.0, 2.0, 0.0, 0.0, 0.5) == pytest.approx(0.5)
    assert moment_of_inertia_eq12(0.0, 0.0, 1.0, 0.4, 0.6, 0.0) == pytest.approx(0.04)
    # Consistent units: doubling every length quadruples J0 (the printed form would not).
    args = (0.5, 0.5, 2.4, 0.08, 0.03, 0.42)
    doubled = (0.5, 1.0, 2.4, 0.16, 0.06, 0.84)
    assert moment_of_inertia_eq12(*doubled) == pytest.approx(4 * moment_of_inertia_eq12(*args))


# --------------------------------------------------------------------------------------
# Virtual decay bench
# --------------------------------------------------------------------------------------


def test_virtual_decay_without_friction_is_the_closed_form():
    t = np.arange(3001) / 1000.0
    osc = DampedOscillator.from_modal(0.05, F_N, J, equilibrium_rad=0.01)
    piecewise = coulomb_decay(J, float(osc.stiffness_Nm_per_rad), float(osc.damping_Nms_per_rad),
                              0.01, 0.0, 0.17, 0.0, t)
    closed = np.asarray(oscillator_response(osc, 0.17, 0.0, t)[0])
    np.testing.assert_allclose(piecewise, closed, atol=1e-14)


def test_virtual_decay_with_coulomb_friction_loses_a_fixed_amplitude_and_sticks():
    """Pure Coulomb friction: every half cycle loses 2·T_c/k, and the arm sticks for good."""
    t = np.arange(20001) / 1000.0
    tc = 0.5
    beta = coulomb_decay(J, K, 0.0, 0.0, tc, 0.1, 0.0, t)
    peaks = np.sort(np.concatenate([scipy.signal.find_peaks(beta)[0],
                                    scipy.signal.find_peaks(-beta)[0]]))
    amplitude = np.abs(beta[peaks])  # sampled at 1 kHz: within 1e-5 rad of the true extremum
    assert len(amplitude) == 8
    np.testing.assert_allclose(amplitude[:-1] - amplitude[1:], 2 * tc / K, atol=2e-5)
    assert abs(beta[-1]) <= tc / K and np.ptp(beta[-2000:]) == 0.0


def test_virtual_decay_table_format():
    frame = decays(0.05, angle_unit="deg", pressures_kPa=(250.0, 300.0), temperature_C=21.0,
                   n_trials=2, duration_s=1.0)
    assert list(frame.columns) == ["trial", "time_s", "angle_deg", "pressure1_kPa",
                                   "pressure2_kPa", "temperature_C"]
    assert len(frame) == 2 * 1301
    # Encoder steps of 360/4096 degrees; the hold at the deflection comes first.
    steps = frame["angle_deg"].to_numpy() / (360 / 4096)
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)
    with pytest.raises(ValueError, match="angle_unit must be"):
        DecayProtocol(angle_unit="grad")


# --------------------------------------------------------------------------------------
# Peaks, troughs and the decrement
# --------------------------------------------------------------------------------------


def test_peaks_on_coarse_encoder_plateaus():
    """An 8-bit encoder: long plateaus at every extremum, one extremum each, at the right time."""
    t = np.arange(4001) / 1000.0
    wd = 2 * np.pi * 2.0
    clean = 0.3 * np.exp(-0.3 * t) * np.cos(wd * t)
    q = 2 * np.pi / 256
    e = find_extrema(t, np.round(clean / q) * q)
    assert e.quantum_rad == pytest.approx(q)
    times, _, kinds = e.used
    assert np.all(kinds[1:] == -kinds[:-1])
    # Extrema of e^(−σt)·cos(ω_d t) fall at ω_d·t = jπ − atan(σ/ω_d).
    j = np.round((wd * times + np.arctan(0.3 / wd)) / np.pi)
    np.testing.assert_allclose(times, (j * np.pi - np.arctan(0.3 / wd)) / wd, atol=4e-3)


@pytest.mark.parametrize("zeta", [0.02, 0.05, 0.1])
def test_zeta_recovered_within_2_percent_with_quantization_and_noise(zeta, tmp_path):
    data = load_decay(write(decays(zeta, seed=int(zeta * 1000)), tmp_path))
    report = analyze_decays(data, J)
    for est, fit in zip(report.decrement, report.fits, strict=True):
        assert est.zeta == pytest.approx(zeta, rel=0.02)
        assert est.zeta_ci95[0] < est.zeta < est.zeta_ci95[1]
        assert est.stiffness_Nm_per_rad == pytest.approx(K, rel=0.005)
        assert est.damping_Nms_per_rad == pytest.approx(2 * zeta * math.sqrt(K * J), rel=0.03)
        assert est.log_decrement_eq8 == pytest.approx(est.log_decrement, rel=0.03)
        assert est.equilibrium_rad == pytest.approx(0.0123, abs=STEP / 4)
        assert fit.converged
        assert fit.derived["zeta"] == pytest.approx(zeta, rel=0.02)
        assert fit.derived["stiffness_Nm_per_rad"] == pytest.approx(K, rel=0.005)
        assert fit.params["equilibrium_rad"] == pytest.approx(0.0123, abs=STEP / 4)
        assert est.amplitude_dependence["amplitude_dependent"] is False
    assert report.pooled.zeta == pytest.approx(zeta, rel=0.01)
    assert report.pooled_fit["zeta"] == pytest.approx(zeta, rel=0.01)


def test_decrement_intervals_cover_the_truth():
    """95 % intervals of ζ over 40 noisy, quantized decays: coverage near nominal."""
    hits = []
    for seed in range(40):
        frame = decays(0.05, seed=seed, n_trials=1, deflections_deg=(7.0,), noise_sd_rad=STEP)
        est = decrement_estimate(frame["time_s"].to_numpy(), frame["angle_rad"].to_numpy(), J)
        hits.append(est.zeta_ci95[0] <= 0.05 <= est.zeta_ci95[1])
    assert 0.85 <= np.mean(hits) <= 1.0


def test_coulomb_friction_is_found_and_measured(tmp_path):
    data = load_decay(write(decays(0.05, coulomb=0.1, seed=5), tmp_path))
    report = analyze_decays(data, J, fit=False)
    pooled = report.pooled.amplitude_dependence
    assert pooled["amplitude_dependent"] is True
    assert pooled["coulomb_Nm"] == pytest.approx(0.1, rel=0.1)
    assert pooled["zeta_viscous"] == pytest.approx(0.05, rel=0.05)
    assert pooled["log_decrement_late"] > pooled["log_decrement_early"]
    assert pooled["slope_per_rad"] < 0
    assert "Coulomb" in pooled["note"]
    # The viscous decrement alone is biased upwards by the hidden friction.
    assert report.pooled.zeta > 0.055


# --------------------------------------------------------------------------------------
# Decay files: bad input by message
# --------------------------------------------------------------------------------------


def good_frame():
    return decays(0.05, n_trials=2, duration_s=2.0, hold_s=0.0)


@pytest.mark.parametrize("edit, message", [
    (lambda f: f.drop(columns="time_s"), r"missing required column: time_s"),
    (lambda f: f.drop(columns="angle_rad"), r"missing required column: angle_rad \(or angle_deg"),
    (lambda f: f.assign(angle_deg=f["angle_rad"]), r"column 'angle_deg'.*both angle_rad and"),
    (lambda f: f.rename(columns={"angle_rad": "angle_grad"}),
     r"column 'angle_grad'.*unknown unit 'grad' for angle; accepted units: rad, deg"),
    (lambda f: f.rename(columns={"time_s": "time_ms"}), r"column 'time_ms'.*unknown unit 'ms'"),
    (lambda f: f.rename(columns={"angle_rad": "Angle_Rad"}), r"units are case-sensitive"),
    (lambda f: f.astype({"angle_rad": object}).assign(
        angle_rad=lambda g: g["angle_rad"].where(g.index != 6, "abc")),
     r"column 'angle_rad', row 7 \(line 8\): 'abc' is not a number"),
    (lambda f: f.assign(angle_rad=lambda g: g["angle_rad"].where(g.index != 9, np.nan)),
     r"column 'angle_rad', row 10 \(line 11\): empty cell"),
    (lambda f: f.assign(time_s=lambda g: g["time_s"].where(g.index != 2502, 0.5)),
     r"column 'time_s', row 2503 \(line 2504\): time_s 0.5 s is not later than .* of trial '2'"),
    (lambda f: f.assign(pressure1_kPa=-200.0), r"column 'pressure1_kPa', row 1.*negative absolute"),
    (lambda f: f.iloc[:2001 + 10], r"trial '2' has 10 samples; a decay needs at least 20"),
])
def test_bad_decay_files_by_message(edit, message, tmp_path):
    path = write(edit(good_frame()), tmp_path)
    with pytest.raises(pamid.BenchDataError, match=message) as info:
        load_decay(path)
    assert str(path) in str(info.value)


def test_missing_and_empty_files(tmp_path):
    with pytest.raises(pamid.BenchDataError, match="file not found"):
        load_decay(tmp_path / "nope.csv")
    (tmp_path / "empty.csv").write_bytes(b"")
    with pytest.raises(pamid.BenchDataError, match=r"empty.csv: the file is empty"):
        load_decay(tmp_path / "empty.csv")
    (tmp_path / "header.csv").write_text("trial,time_s,angle_rad\n")
    with pytest.raises(pamid.BenchDataError, match="no data rows"):
        load_decay(tmp_path / "header.csv")


def test_no_oscillation_found_names_file_column_and_trial(tmp_path):
    frame = good_frame()
    second = frame["trial"] == 2
    rng = np.random.default_rng(0)
    frame.loc[second, "angle_rad"] = np.round(0.01 + 3e-4 * rng.normal(size=second.sum()), 4)
    data = load_decay(write(frame, tmp_path))
    with pytest.raises(pamid.BenchDataError,
                       match=r"decay.csv, column 'angle_rad', row 2002: trial '2': no oscillation "
                             r"found") as info:
        analyze_decays(data, J)
    assert info.value.column == "angle_rad" and info.value.row == 2002


def test_loader_converts_degrees_and_pressures(tmp_path):
    frame = decays(0.05, n_trials=1, duration_s=1.0, angle_unit="deg",
                   pressures_kPa=(2.5, 3.0), temperature_C=22.0)
    frame = frame.rename(columns={"pressure1_kPa": "pressure1_bar",
                                  "pressure2_kPa": "pressure2_bar"}).drop(columns="trial")
    data = load_decay(write(frame, tmp_path))
    assert data.trials == ("1",) and not data.has_trial_column
    assert data.angle_unit_in_file == "deg"
    np.testing.assert_allclose(data.frame["angle_rad"], np.deg2rad(frame["angle_deg"]))
    np.testing.assert_allclose(data.frame["pressure1_kPa"], 250.0)
    np.testing.assert_allclose(data.frame["pressure2_kPa"], 300.0)
    assert list(data.frame.columns) == ["trial", "time_s", "angle_rad", "pressure1_kPa",
                                        "pressure2_kPa", "temperature_C", "source_row"]


# --------------------------------------------------------------------------------------
# pamid damping
# --------------------------------------------------------------------------------------


def run_cli(argv, capsys):
    parser = argparse.ArgumentParser(prog="pamid")
    register(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    code = args.func(args)
    return code, capsys.readouterr()


KEYS = ("log_decrement", "log_decrement_ci95", "zeta", "zeta_ci95", "frequency_Hz",
        "frequency_Hz_ci95", "natural_frequency_Hz", "stiffness_Nm_per_rad",
        "stiffness_Nm_per_rad_ci95", "damping_Nms_per_rad", "damping_Nms_per_rad_ci95",
        "log_decrement_eq8", "log_decrement_eq9_endpoints", "amplitude_dependence")


def test_cli_damping_json(tmp_path, capsys):
    path = write(decays(0.05, seed=11), tmp_path)
    out = tmp_path / "out"
    code, cap = run_cli(["damping", str(path), "--inertia", "0.46", "--json", "--out", str(out)],
                        capsys)
    assert code == 0
    payload = json.loads(cap.out)  # exactly one JSON object
    assert cap.err == ""
    assert payload["n_trials"] == 3 and [t["trial"] for t in payload["trials"]] == ["1", "2", "3"]
    for block in (*payload["trials"], payload["pooled"]):
        for key in KEYS:
            assert key in block, key
        fit = block["trajectory_fit"]
        for key in ("zeta", "zeta_ci95", "stiffness_Nm_per_rad", "damping_Nms_per_rad",
                    "converged"):
            assert key in fit, key
        assert block["zeta"] == pytest.approx(0.05, rel=0.02)
        assert fit["zeta"] == pytest.approx(0.05, rel=0.02)
    assert sorted(payload["plots"]) == ["decay_1.png", "decay_2.png", "decay_3.png",
                                        "decrement.png"]
    assert (out / "decay_1.png").stat().st_size > 10_000
    assert json.loads((out / "damping.json").read_text())["n_trials"] == 3


def test_cli_damping_text_and_bad_inertia(tmp_path, capsys):
    path = write(decays(0.05, seed=12, n_trials=1), tmp_path)
    code, cap = run_cli(["damping", str(path), "--inertia", "0.46", "--no-fit"], capsys)
    assert code == 0
    assert "log decrement (eq. 9)" in cap.out and "trajectory fit" not in cap.out
    assert "amplitude dependence" in cap.out
    with pytest.raises(ValueError, match="--inertia must be positive"):
        run_cli(["damping", str(path), "--inertia", "0"], capsys)
    with pytest.raises(pamid.BenchDataError, match="file not found"):
        run_cli(["damping", str(tmp_path / "missing.csv"), "--inertia", "0.46"], capsys)


def test_decay_frame_round_trips_through_parquet(tmp_path):
    frame = decays(0.05, n_trials=2, duration_s=1.5)
    path = tmp_path / "decay.parquet"
    frame.to_parquet(path, index=False)
    data = load_decay(path)
    assert data.trials == ("1", "2")
    pd.testing.assert_series_equal(data.frame["angle_rad"], frame["angle_rad"],
                                   check_names=False)
