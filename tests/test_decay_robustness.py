"""Extreme, degenerate and bad inputs of the decay analysis and the simulators: angles of
1e-300 … 1e308 rad, growing oscillations, honest intervals, NaN in a model JSON, bad option
values (one line, exit 2, before any computation), and no raw NumPy warning anywhere."""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

from pamid._cli import main
from pamid._data._decay_file import load_decay
from pamid._decays._analysis import analyze_decays

ZETA, F_N, J = 0.05, 2.2, 0.46


def decay_file(path, amplitude=0.1, zeta=ZETA, f_n=F_N, time_factor=1.0, offset=0.0):
    """A decay sampled at 1 kHz for 4 s from the closed form A·e^(−ζω t)·cos(ω_d t)."""
    t = np.arange(4001) / 1000.0
    wn = 2 * math.pi * f_n
    wd = wn * math.sqrt(1 - zeta**2)
    y = offset + amplitude * np.exp(-zeta * wn * t) * np.cos(wd * t)
    lines = ["time_s,angle_rad"] + [f"{float(a)!r},{float(b)!r}" for a, b in
                                    zip(t * time_factor, y, strict=True)]
    path.write_text("\n".join(lines) + "\n")
    return path


def cli(argv, capsys):
    code = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if not ln.startswith("[")]  # progress lines
    assert len(lines) == 1, lines
    assert lines[0].startswith("pamid: error: "), lines[0]
    return lines[0]


def all_intervals(d, path=""):
    """(where, estimate, interval) for every ``<name>_ci95`` beside ``<name>`` in a JSON."""
    if isinstance(d, dict):
        for k, v in d.items():
            if k.endswith("_ci95") and k[:-5] in d and not isinstance(d[k[:-5]], dict):
                yield f"{path}{k}", d[k[:-5]], v
            yield from all_intervals(v, f"{path}{k}.")
        if isinstance(d.get("params"), dict) and isinstance(d.get("params_ci95"), dict):
            for k, v in d["params_ci95"].items():
                yield f"{path}params_ci95.{k}", d["params"][k], v
    elif isinstance(d, list):
        for i, v in enumerate(d):
            yield from all_intervals(v, f"{path}{i}.")


def assert_honest(payload):
    n = 0
    for where, value, ci in all_intervals(payload):
        n += 1
        if ci is None:
            continue
        lo, hi = ci
        assert lo <= hi, (where, ci)
        assert lo <= value <= hi, (where, value, ci)
    assert n > 10


# --------------------------------------------------------------------------------------
# Angles of any magnitude (was: OverflowError, "no oscillation", "Singular matrix",
# "overflow encountered in matmul")
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("amplitude", [1e-300, 1e-100, 1e150, 1e155, 1e200, 1e300])
def test_decay_of_any_amplitude_gives_the_same_zeta(tmp_path, amplitude):
    data = load_decay(decay_file(tmp_path / "d.csv", amplitude))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no raw NumPy/JAX warning
        report = analyze_decays(data, J)
    dec, fit = report.decrement[0], report.fits[0]
    assert dec.zeta == pytest.approx(ZETA, rel=1e-4)
    assert dec.natural_frequency_Hz == pytest.approx(F_N, rel=1e-5)
    assert fit.converged and fit.params["zeta"] == pytest.approx(ZETA, rel=1e-6)
    # Angles come back in rad: the first usable peak/trough, and the fit's start, which is
    # the closed form at the time of that extremum.
    first = report.extrema[0].used[1][0]
    assert abs(first) == pytest.approx(0.86 * amplitude, rel=0.02)
    wn = 2 * math.pi * F_N
    t0 = fit.t0_s
    exact = amplitude * math.exp(-ZETA * wn * t0) * math.cos(wn * math.sqrt(1 - ZETA**2) * t0)
    assert fit.params["angle0_rad"] == pytest.approx(exact, rel=1e-6)
    assert fit.rmse_rad < 1e-9 * amplitude


def test_damping_command_at_1e160_rad_is_one_json_object_and_no_warning(tmp_path, capsys):
    path = decay_file(tmp_path / "d.csv", 1e160)
    code, out, err = cli(["damping", path, "--inertia", J, "--json"], capsys)
    assert code == 0
    assert "warning" not in err and "error" not in err
    payload = json.loads(out)
    assert payload["pooled"]["zeta"] == pytest.approx(ZETA, rel=1e-4)
    assert payload["stable"] is True
    assert_honest(payload)


def test_tiny_decay_about_a_large_offset_is_fitted_about_its_equilibrium(tmp_path):
    """1e-12 rad about 1 rad: the fit used to stop at its start (the decrement's ζ, 2e-4
    off), its steps lost against the offset."""
    data = load_decay(decay_file(tmp_path / "d.csv", 1e-12, offset=1.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        report = analyze_decays(data, J)
    fit = report.fits[0]
    assert fit.converged and fit.n_steps > 1
    assert fit.params["zeta"] == pytest.approx(ZETA, rel=2e-5)
    assert fit.params["equilibrium_rad"] == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize("inertia", [1e-300, 1e-12, 1e12, 1e300])
def test_extreme_inertia_scales_k_and_c_without_overflow(tmp_path, inertia):
    data = load_decay(decay_file(tmp_path / "d.csv"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        report = analyze_decays(data, inertia)
    wn = 2 * math.pi * F_N
    dec = report.pooled
    assert dec.stiffness_Nm_per_rad == pytest.approx(inertia * wn**2, rel=1e-4)
    assert dec.damping_Nms_per_rad == pytest.approx(2 * ZETA * inertia * wn, rel=1e-3)
    for name in ("stiffness_Nm_per_rad", "damping_Nms_per_rad"):
        lo, hi = report.fits[0].derived[name + "_ci95"]
        assert lo <= report.fits[0].derived[name] <= hi
        assert math.isfinite(report.pooled_fit[name + "_ci95"][1])


@pytest.mark.parametrize("time_factor", [1e-6, 1e6])
def test_time_scales_from_microseconds_to_megaseconds(tmp_path, time_factor):
    data = load_decay(decay_file(tmp_path / "d.csv", time_factor=time_factor))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        report = analyze_decays(data, J)
    assert report.pooled.zeta == pytest.approx(ZETA, rel=1e-4)
    assert report.pooled.natural_frequency_Hz == pytest.approx(F_N / time_factor, rel=1e-5)
    assert report.fits[0].params["zeta"] == pytest.approx(ZETA, rel=1e-6)


# --------------------------------------------------------------------------------------
# A growing oscillation (was: ζ = −0.040 with the interval [0.0, −0.0398])
# --------------------------------------------------------------------------------------


def test_growing_oscillation_is_reported_unstable_with_honest_intervals(tmp_path, capsys):
    path = decay_file(tmp_path / "grow.csv", 0.01, zeta=-0.04)
    report = analyze_decays(load_decay(path), J)
    dec = report.decrement[0]
    assert dec.grows and not report.stable and report.growing_trials == ["1"]
    assert dec.zeta == pytest.approx(-0.04, rel=1e-3)
    lo, hi = dec.zeta_ci95
    assert lo <= dec.zeta <= hi < 0
    assert "the oscillation grows: the decay model does not apply" in dec.stability
    assert dec.amplitude_dependence["amplitude_dependent"] is None

    code, out, err = cli(["damping", path, "--inertia", J], capsys)
    assert code == 1
    assert "the oscillation grows: the decay model does not apply" in out
    assert "UNSTABLE" in out
    code, out, _ = cli(["damping", path, "--inertia", J, "--json"], capsys)
    assert code == 1
    payload = json.loads(out)
    assert payload["stable"] is False and payload["growing_trials"] == ["1"]
    assert payload["trials"][0]["stable"] is False
    assert_honest(payload)


def test_undamped_noisy_decay_keeps_its_estimate_inside_its_interval(tmp_path, capsys):
    """ζ = 0 with noise: the estimate may fall below 0; its interval used to start at 0."""
    t = np.arange(4001) / 1000.0
    rng = np.random.default_rng(3)
    y = 0.05 * np.cos(2 * math.pi * F_N * t) + rng.normal(0, 2e-4, t.size)
    path = tmp_path / "undamped.csv"
    path.write_text("time_s,angle_rad\n" + "\n".join(f"{a!r},{b!r}" for a, b in
                                                    zip(t.tolist(), y.tolist(), strict=True)))
    code, out, _ = cli(["damping", path, "--inertia", J, "--json"], capsys)
    payload = json.loads(out)
    dec = payload["pooled"]
    lo, hi = dec["zeta_ci95"]
    assert lo < 0 < hi and lo <= dec["zeta"] <= hi  # consistent with no damping
    assert payload["stable"] is True and code == 0
    assert_honest(payload)


def test_overdamped_fit_gives_no_complex_numbers_and_says_why():
    from pamid._decays._analysis import _fit_derived

    out = _fit_derived(np.array([1.5, 10.0, 0.1, 0.0, 0.0]), np.eye(5) * 1e-6, 100, J)
    assert math.isnan(out["log_decrement"]) and out["log_decrement_ci95"] is None
    assert "overdamped" in out["interval_notes"]["log_decrement_ci95"]
    assert out["zeta_ci95"][0] <= 1.5 <= out["zeta_ci95"][1]
    assert out["stiffness_Nm_per_rad"] == pytest.approx(J * 100.0)


# --------------------------------------------------------------------------------------
# check-decays: NaN in the model JSON (was: "gives neither zeta ..."), growing recordings
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("model, message", [
    ('{"zeta": NaN, "natural_frequency_Hz": 2.2}', r"zeta is NaN \(not a number\)"),
    ('{"pooled": {"zeta": 0.05, "natural_frequency_Hz": Infinity}}',
     r"pooled\.natural_frequency_Hz is Infinity"),
    ('{"trials": [{"trial": "1", "zeta": 0.05, "natural_frequency_Hz": 2.2, '
     '"trajectory_fit": {"zeta": NaN}}]}', r"trials\[0\]\.trajectory_fit\.zeta is NaN"),
    ('{"zeta": "0.05", "natural_frequency_Hz": 2.2}', r'zeta is "0.05" \(str, not a number\)'),
    ('{"zeta": 0.05, "natural_frequency_Hz": 1e300}', r"above the recordings' Nyquist"),
])
def test_check_decays_names_the_bad_key_of_the_model_json(tmp_path, capsys, model, message):
    data = decay_file(tmp_path / "d.csv")
    model_path = tmp_path / "model.json"
    model_path.write_text(model)
    code, _, err = cli(["check-decays", data, "--model-json", model_path, "--inertia", J],
                       capsys)
    assert code == 2
    line = error_line(err)
    assert "model.json" in line or "Nyquist" in line
    import re

    assert re.search(message, line), line


def test_check_decays_on_a_growing_recording_exits_1(tmp_path, capsys):
    data = decay_file(tmp_path / "grow.csv", 0.01, zeta=-0.04)
    model = tmp_path / "m.json"
    model.write_text('{"zeta": 0.05, "natural_frequency_Hz": 2.2}')
    code, out, _ = cli(["check-decays", data, "--model-json", model, "--inertia", J], capsys)
    assert code == 1 and "the recorded oscillation grows" in out
    code, out, _ = cli(["check-decays", data, "--model-json", model, "--inertia", J, "--json"],
                       capsys)
    row = json.loads(out)["trials"][0]
    assert row["recorded_stable"] is False
    lo, hi = row["recorded_zeta_ci95"]
    assert lo <= row["recorded_zeta"] <= hi


def test_check_decays_rms_of_tiny_angles_does_not_underflow(tmp_path, capsys):
    data = decay_file(tmp_path / "d.csv", 1e-300)
    model = tmp_path / "m.json"
    model.write_text('{"zeta": 0.06, "natural_frequency_Hz": 2.2}')
    code, out, err = cli(["check-decays", data, "--model-json", model, "--inertia", J,
                          "--json"], capsys)
    assert code == 0 and "warning" not in err
    rms = json.loads(out)["trials"][0]["rms_error_rad"]
    assert 1e-303 < rms < 1e-300


def test_posterior_of_a_noiseless_recording_is_refused_up_front(tmp_path, capsys):
    """It used to sample 20000 steps, print raw NumPy warnings and end in 'attempt to get
    argmax of an empty sequence'."""
    data = decay_file(tmp_path / "d.csv")
    model = tmp_path / "m.json"
    model.write_text('{"zeta": 0.05, "natural_frequency_Hz": 2.2}')
    code, _, err = cli(["check-decays", data, "--model-json", model, "--inertia", J,
                        "--posterior-draws", 10], capsys)
    assert code == 2
    assert "a recording without noise has no posterior to sample" in error_line(err)


# --------------------------------------------------------------------------------------
# diagnose DECAYFILE --inertia 0 (was: "give --inertia")
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("value, shown", [("0", "0"), ("-1", "-1"), ("nan", "nan")])
def test_diagnose_decay_file_says_the_inertia_must_be_positive(tmp_path, capsys, value, shown):
    data = decay_file(tmp_path / "d.csv")
    code, _, err = cli(["diagnose", data, "--inertia", value], capsys)
    assert code == 2
    line = error_line(err)
    assert f"must be positive (> 0 kg·m²), got {shown}" in line and "--inertia" in line
    assert "give --inertia" not in line


def test_check_inertia():
    from pamid._decays._analysis import check_inertia

    assert check_inertia(0.46) == 0.46
    for bad in (0.0, -1.0, math.nan, math.inf, "1", True):
        with pytest.raises(ValueError, match=r"must be positive \(> 0 kg·m²\)"):
            check_inertia(bad)


# --------------------------------------------------------------------------------------
# Bad option values: exit 2, one line naming the option and the accepted range
# --------------------------------------------------------------------------------------

LIFT = ["simulate", "lifting-mass", "--pressure-kPa", "400", "--mass-kg", "50", "--x0-mm",
        "50", "--duration-s", "0.5"]
POS = ["simulate", "positioning", "--target-mm", "15", "--duration-s", "0.5"]


def with_option(base, option, value):
    argv = list(base)
    if option in argv:
        argv[argv.index(option) + 1] = value
    else:
        argv += [option, value]
    return argv


@pytest.mark.parametrize("option, value, accepted", [
    ("--duration-s", "4000", "must be positive and at most 3600 s, got 4000"),
    ("--duration-s", "nan", "must be positive and at most 3600 s, got nan (not a number)"),
    ("--duration-s", "-1e300", "must be positive and at most 3600 s, got -1e+300"),
    ("--sample-rate-Hz", "1e6", "must be positive and at most 100000 Hz, got 1e+06"),
    ("--hysteresis-N-per-bar", "-1", "must be at least 0 N/bar, got -1"),
    ("--hysteresis-N-per-bar", "1e300", "the loop must be at most 128.4 N/bar"),
    ("--pressure-kPa", "-inf", "must lie in [0, 1000] kPa, got -inf"),
    ("--mass-kg", "inf", "must be positive (> 0 kg), got inf"),
    ("--zeta", "-nan", "must lie in [0, 10], got nan (not a number)"),
    ("--l0-mm", "1e300", "must lie in [10, 10000] mm, got 1e+300"),
    ("--v0-mm-s", "1e300", "must lie in [-10000, 10000] mm/s, got 1e+300"),
    ("--gravity", "0", "must be positive (> 0 m/s²), got 0"),
])
def test_lifting_mass_bad_values_are_one_line_with_the_range(capsys, option, value, accepted):
    code, out, err = cli(with_option(LIFT, option, value), capsys)
    assert code == 2 and out == ""
    line = error_line(err)
    assert option in line and accepted in line, line


@pytest.mark.parametrize("mass, message", [
    ("1e-12", "RK4 needs 3.92e+05 steps per sample"),
    ("1e-320", "RK4 needs more than 1e15 steps per sample"),
    ("1e-3", "which no muscle reaches"),
    ("1e6", "it holds at most 853.5 kg"),
])
def test_lifting_mass_impossible_masses_say_why(capsys, mass, message):
    code, _, err = cli(with_option(LIFT, "--mass-kg", mass), capsys)
    assert code == 2 and message in error_line(err)


def test_light_mass_is_resolved_by_rk4_substeps(capsys):
    """10 g on the muscle: f_n ≈ 150 Hz, which one RK4 step per 1 kHz sample turned into
    nonsense; the run now takes enough steps and settles on the static solution."""
    from pamid._sim._lifting_mass import LiftingMass, lifting_mass_equilibrium

    eq_mm = 1000 * float(lifting_mass_equilibrium(LiftingMass(None, 400.0, 0.01, 0.05)))
    argv = with_option(with_option(LIFT, "--mass-kg", "0.01"), "--x0-mm", f"{eq_mm + 0.5}")
    code, out, err = cli(with_option(argv, "--duration-s", "1") + ["--zeta", "0.05",
                                                                   "--json"], capsys)
    assert code == 0 and err == ""
    payload = json.loads(out)
    assert payload["rk4_steps_per_sample"] > 1
    assert payload["final_displacement_mm"] == pytest.approx(eq_mm, abs=1e-6)
    assert payload["equilibrium_displacement_mm"] == pytest.approx(eq_mm, abs=1e-9)


def test_negative_values_in_exponent_form_are_read_as_values(capsys):
    code, out, err = cli(with_option(LIFT, "--x0-mm", "-1e-3") + ["--json"], capsys)
    assert code == 0 and json.loads(out)["x0_mm"] == -1e-3


@pytest.mark.parametrize("argv, accepted", [
    (with_option(POS, "--target-mm", "nan"), "--target-mm must lie in [-20, 20] mm, got nan"),
    (with_option(POS, "--duration-s", "-inf"), "--duration-s must lie in [0.05, 120] s"),
    (with_option(POS, "--muscle", "-1"), "--muscle must be an integer ≥ 0, got -1"),
    (with_option(POS, "--seed", str(2**32)), "--seed must be an integer in [0, 4294967295]"),
    (["damping", "D", "--inertia", "nan"], "--inertia must be positive (> 0 kg·m²), got nan"),
    (["check-decays", "D", "--model-json", "M", "--inertia", "1", "--posterior-draws",
      "99999999999999999999"], "--posterior-draws must be an integer in [0, 100000]"),
    (["check-decays", "D", "--model-json", "M", "--inertia", "-1e300"],
     "--inertia must be positive (> 0 kg·m²), got -1e+300"),
    (["check-decays", "D", "--model-json", "M", "--inertia", "1", "--seed", "-1"],
     "--seed must be an integer in [0, 4294967295], got -1"),
])
def test_other_commands_bad_values_come_before_any_work(tmp_path, capsys, argv, accepted):
    argv = [str(decay_file(tmp_path / "d.csv")) if a == "D" else
            str(tmp_path / "absent.json") if a == "M" else a for a in argv]
    code, out, err = cli(argv, capsys)
    assert code == 2 and out == ""
    assert accepted in error_line(err)


def test_positioning_fit_json_with_nan_names_the_constant(tmp_path, capsys):
    from pamid._models._sarosi import table_3_1_fit_json

    fit = table_3_1_fit_json()
    fit["muscles"][0]["params"]["a3"]["value"] = math.nan
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fit))
    code, _, err = cli(with_option(POS, "--fit", str(path)), capsys)
    assert code == 2
    assert "muscles[0].params.a3.value is NaN (not a number)" in error_line(err)


def test_positioning_draws_that_diverge_are_not_called_settled(tmp_path, capsys):
    """Draws from standard errors of 1e300 diverge; comparisons with NaN used to call them
    settled after one sample (median settling time 0.01 s)."""
    from pamid._models._sarosi import table_3_1_fit_json

    fit = table_3_1_fit_json()
    for entry in fit["muscles"][0]["params"].values():
        entry["se"] = 1e300
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fit))
    code, out, _ = cli(with_option(POS, "--fit", str(path)) + ["--draws", "3", "--json"],
                       capsys)
    assert code == 0
    draws = json.loads(out)["draws"]
    assert draws["n_diverged"] == 3
    assert draws["settling_time_s"]["median"] is None
    assert draws["settling_time_s"]["not_settled"] == 3
