"""The virtual bench for isometric tests and for files as other labs deliver them.

Known answers throughout: noise-free files must show exactly the transient, hysteresis,
softening, drift and compliance that the protocol put in (against Sárosi eq. 2.1 evaluated
here), and noisy files must show the noise and offset the protocol asked for.
"""

from __future__ import annotations

import dataclasses
import warnings

import jax
import numpy as np
import pandas as pd
import pytest

import pamid
from pamid._virtual._isometric import LAB_FILE_KINDS

NOISE_FREE = dict(
    pressure_noise_kPa=0.0,
    force_noise_N=0.0,
    contraction_noise_pct=0.0,
    pressure_resolution_kPa=0.0,
    force_resolution_N=0.0,
    length_resolution_mm=0.0,
)


def static_force(params, frame, offset_kPa=0.0):
    """Sárosi eq. 2.1 at the file's pressure (less the logger's offset) and contraction."""
    return np.asarray(
        pamid.sarosi.sarosi_force(
            params,
            (frame["pressure_kPa"].to_numpy() - offset_kPa) / 100.0,
            frame["contraction_pct"].to_numpy(),
        )
    )


def test_columns_shape_and_trial_labels(sarosi31):
    theta = np.stack([np.asarray(sarosi31.to_vector())] * 2) * np.array([[1.0], [1.03]])
    proto = pamid.IsometricProtocol(sample_s=0.05)
    frame = pamid.simulate_isometric_bench(
        jax.random.key(0), pamid.Sarosi.from_vector(theta), proto, ["A", "B"], [400.0, 250.0]
    )
    assert list(frame.columns) == [
        "muscle", "trial", "time_s", "pressure_kPa", "force_N", "length_mm", "l0_mm",
        "contraction_pct", "direction",
    ]
    n_trials = 4 * 3
    assert proto.samples_per_trial == int(round(proto.trial_duration_s / 0.05)) + 1
    assert len(frame) == 2 * n_trials * proto.samples_per_trial
    labels = [f"k{k}_T{r}" for k in (0, 25, 50, 75) for r in (1, 2, 3)]
    for muscle, l0 in (("A", 400.0), ("B", 250.0)):
        rows = frame[frame["muscle"] == muscle]
        assert list(pd.unique(rows["trial"])) == labels
        assert (rows["l0_mm"] == l0).all()
    assert frame["direction"].dtype == np.int64
    assert set(frame["direction"]) == {1, -1}


def test_time_restarts_at_zero_in_every_trial():
    proto = pamid.IsometricProtocol(sample_s=0.02, time_jitter_s=0.005, repeats=2)
    frame = pamid.simulate_isometric_bench(jax.random.key(1), pamid.sarosi.table_3_1(), proto)
    for _, trial in frame.groupby("trial", sort=False):
        t = trial["time_s"].to_numpy()
        assert t[0] == 0.0
        assert np.all(np.diff(t) > 0)  # the jitter never lets time run backwards
        assert t[-1] == pytest.approx(proto.trial_duration_s, abs=0.005 + 1e-9)
        assert np.abs(t - 0.02 * np.arange(len(t))).max() <= 0.005 + 1e-12
    assert frame["time_s"].diff().lt(0).sum() == frame["trial"].nunique() - 1


def test_every_logged_channel_shows_the_protocols_noise_and_offset(sarosi31):
    """At ambient before the first valve pulse the true state is constant: the spread of
    each channel there is the sensor noise, and the pressure's mean is the offset."""
    proto = pamid.IsometricProtocol(
        sample_s=0.01, rest_s=3.0, pressure_noise_kPa=1.5, force_noise_N=0.8,
        contraction_noise_pct=0.02, pressure_offset_kPa=8.0, pressure_resolution_kPa=0.0,
        force_resolution_N=0.0, length_resolution_mm=0.0,
    )
    frame = pamid.simulate_isometric_bench(jax.random.key(2), sarosi31, proto)
    ambient = frame[frame["time_s"] < proto.rest_s - 0.005]
    assert len(ambient) == 12 * 300
    assert ambient["pressure_kPa"].mean() == pytest.approx(8.0, abs=0.1)
    within = ambient.groupby("trial")[["pressure_kPa", "force_N", "contraction_pct"]]
    sd = np.sqrt(within.var(ddof=1).mean())
    assert sd["pressure_kPa"] == pytest.approx(1.5, rel=0.05)
    assert sd["force_N"] == pytest.approx(0.8, rel=0.05)
    assert sd["contraction_pct"] == pytest.approx(0.02, rel=0.05)
    # The length is what the contraction says: κ = 100·(l0 − l)/l0.
    np.testing.assert_allclose(
        frame["contraction_pct"], 100 * (frame["l0_mm"] - frame["length_mm"]) / frame["l0_mm"],
        atol=1e-8,
    )


def test_quantized_channels_sit_on_their_reading_steps():
    proto = pamid.IsometricProtocol(
        pressure_resolution_kPa=0.766, force_resolution_N=0.683, sample_s=0.05
    )
    frame = pamid.simulate_isometric_bench(jax.random.key(3), pamid.sarosi.table_3_1(), proto)
    for column, step in (("pressure_kPa", 0.766), ("force_N", 0.683)):
        k = frame[column].to_numpy() / step
        np.testing.assert_allclose(k, np.round(k), atol=1e-5)


def test_valve_transient_gain_and_time_constant_are_recovered(sarosi31):
    """Known answer: on the first valve step of a noise-free file, force minus eq. 2.1 is
    g·Δp·exp(−t/τ); a log-linear fit gives back g and τ."""
    gain, tau = 0.08, 0.07
    proto = pamid.IsometricProtocol(
        levels=(0.5,), repeats=1, sample_s=0.005, transient_N_per_kPa=gain,
        transient_tau_s=tau, **NOISE_FREE,
    )
    frame = pamid.simulate_isometric_bench(jax.random.key(4), sarosi31, proto)
    residual = frame["force_N"].to_numpy() - static_force(sarosi31, frame)
    t, p = frame["time_s"].to_numpy(), frame["pressure_kPa"].to_numpy()
    first = np.flatnonzero(np.diff(p) != 0)[0] + 1
    assert t[first] == pytest.approx(proto.rest_s)
    dp = p[first] - p[first - 1]
    assert dp == pytest.approx(62.0)
    window = slice(first, first + 60)  # 0.3 s, ≈ 4 τ
    slope, intercept = np.polyfit(t[window] - t[first], np.log(residual[window]), 1)
    assert -1.0 / slope == pytest.approx(tau, rel=1e-4)
    assert np.exp(intercept) / dp == pytest.approx(gain, rel=1e-4)
    assert np.all(np.abs(residual[: first]) < 1e-6)  # nothing before the first pulse


def test_ramp_transient_is_the_first_order_lag(sarosi31):
    """A ramp of rate r gives g·r·τ·(1 − exp(−t/τ)) during the ramp (the same system)."""
    gain, tau, rate = 0.05, 0.1, 125.0
    proto = pamid.IsometricProtocol(
        program="ramp", levels=(0.25,), repeats=1, sample_s=0.01, ramp_kPa_per_s=rate,
        transient_N_per_kPa=gain, transient_tau_s=tau, **NOISE_FREE,
    )
    frame = pamid.simulate_isometric_bench(jax.random.key(5), sarosi31, proto)
    residual = frame["force_N"].to_numpy() - static_force(sarosi31, frame)
    t = frame["time_s"].to_numpy()
    rising = (t > proto.rest_s) & (t < proto.rest_s + 620.0 / rate)
    expected = gain * rate * tau * (1 - np.exp(-(t[rising] - proto.rest_s) / tau))
    np.testing.assert_allclose(residual[rising], expected, atol=1e-5)
    p = frame["pressure_kPa"].to_numpy()
    np.testing.assert_allclose(p[rising], rate * (t[rising] - proto.rest_s), atol=1e-6)


@pytest.mark.parametrize("program", ["stairs", "ramp"])
def test_direction_marks_inflating_and_deflating(program):
    proto = pamid.IsometricProtocol(program=program, sample_s=0.01, repeats=1, **NOISE_FREE)
    frame = pamid.simulate_isometric_bench(jax.random.key(6), pamid.sarosi.table_3_1(), proto)
    for _, trial in frame.groupby("trial", sort=False):
        p = trial["pressure_kPa"].to_numpy()
        d = trial["direction"].to_numpy()
        first_fall = np.flatnonzero(np.diff(p) < 0)[0] + 1
        assert np.all(d[:first_fall] == 1) and np.all(d[first_fall:] == -1)
        assert p[first_fall - 1] == pytest.approx(620.0)  # it turns at the top
        assert np.all(np.diff(p[:first_fall]) >= 0)
        assert np.all(np.diff(p[first_fall:]) <= 0)


def test_hysteresis_lowers_inflating_and_raises_deflating(sarosi31):
    h = 5.0
    proto = pamid.IsometricProtocol(
        levels=(0.0, 0.5), repeats=1, sample_s=0.02, hysteresis_N_at_3_bar=h, **NOISE_FREE
    )
    frame = pamid.simulate_isometric_bench(jax.random.key(7), sarosi31, proto)
    residual = frame["force_N"].to_numpy() - static_force(sarosi31, frame)
    expected = -frame["direction"].to_numpy() * h * frame["pressure_kPa"].to_numpy() / 300.0
    np.testing.assert_allclose(residual, expected, atol=1e-5)


def test_fraction_levels_reach_zero_force_at_p_max(sarosi31):
    """Level 1 is the free contraction at p_max, where eq. 2.1 gives zero force."""
    proto = pamid.IsometricProtocol(levels=(1.0,), repeats=1, sample_s=0.05, **NOISE_FREE)
    frame = pamid.simulate_isometric_bench(jax.random.key(8), sarosi31, proto)
    top = frame[frame["pressure_kPa"] == 620.0]
    assert len(top) > 100
    np.testing.assert_allclose(top["force_N"], 0.0, atol=1e-6)
    kappa = top["contraction_pct"].iloc[0]
    assert 20.0 < kappa < 40.0  # Table 3-1's muscle contracts about 28 % at 6.2 bar


def test_pct_levels_and_many_muscles_each_with_its_own_constants(sarosi31):
    theta = np.asarray(sarosi31.to_vector()) * np.array([[1.0], [0.9], [1.1]])
    params = pamid.Sarosi.from_vector(theta)
    proto = pamid.IsometricProtocol(
        levels=(0.0, 5.0, 12.5), level_unit="pct", repeats=2, sample_s=0.1, **NOISE_FREE
    )
    frame = pamid.simulate_isometric_bench(jax.random.key(9), params, proto)
    assert sorted(pd.unique(frame["trial"])) == sorted(
        f"k{k}_T{r}" for k in ("0", "5", "12.5") for r in (1, 2)
    )
    for m, (_, rows) in enumerate(frame.groupby("muscle", sort=True)):
        assert set(np.round(rows["contraction_pct"], 9)) == {0.0, 5.0, 12.5}
        np.testing.assert_allclose(
            rows["force_N"], static_force(pamid.Sarosi.from_vector(theta[m]), rows), atol=1e-5
        )


def test_softening_from_repeat_to_repeat(sarosi31):
    s, r = 0.1, 1.5
    proto = pamid.IsometricProtocol(
        levels=(0.25,), repeats=3, sample_s=0.05, softening=s, softening_repeats=r, **NOISE_FREE
    )
    frame = pamid.simulate_isometric_bench(jax.random.key(10), sarosi31, proto)
    ratio = frame["force_N"].to_numpy() / static_force(sarosi31, frame)
    by_trial = {t: ratio[(frame["trial"] == t).to_numpy()] for t in pd.unique(frame["trial"])}
    for repeat, label in enumerate(("k25_T1", "k25_T2", "k25_T3")):
        expected = 1 - s * (1 - np.exp(-repeat / r))
        finite = np.abs(static_force(sarosi31, frame[frame["trial"] == label])) > 1.0
        np.testing.assert_allclose(by_trial[label][finite], expected, rtol=1e-6)


def test_injected_effects_see_elapsed_time_and_compliance(sarosi31):
    drift = pamid.InjectedDrift(N_per_hour=360.0)  # 0.1 N/s
    proto = pamid.IsometricProtocol(
        levels=(0.5,), repeats=2, sample_s=0.05, effects=(drift,), **NOISE_FREE
    )
    frame = pamid.simulate_isometric_bench(jax.random.key(11), sarosi31, proto)
    elapsed = frame["time_s"].to_numpy() + np.where(
        (frame["trial"] == "k50_T2").to_numpy(), proto.trial_duration_s, 0.0
    )
    residual = frame["force_N"].to_numpy() - static_force(sarosi31, frame)
    np.testing.assert_allclose(residual, 0.1 * elapsed, atol=1e-5)

    c = 0.02  # mm/N: the muscle is shorter than the clamp says by c·F
    proto = dataclasses.replace(proto, effects=(pamid.InjectedCompliance(c),))
    frame = pamid.simulate_isometric_bench(jax.random.key(11), sarosi31, proto)
    f = frame["force_N"].to_numpy()
    kappa_true = frame["contraction_pct"].to_numpy() + 100 * c * f / 400.0
    model = pamid.sarosi.sarosi_force(sarosi31, frame["pressure_kPa"].to_numpy() / 100, kappa_true)
    np.testing.assert_allclose(f, np.asarray(model), atol=1e-5)
    assert np.abs(f - static_force(sarosi31, frame)).max() > 10.0  # and it matters

    proto = dataclasses.replace(proto, effects=(pamid.InjectedTemperature(),))
    frame = pamid.simulate_isometric_bench(jax.random.key(11), sarosi31, proto)
    assert "temperature_C" in frame
    assert frame.groupby("trial")["temperature_C"].nunique().max() > 1  # it creeps in a trial


def test_keys_make_results_reproducible_and_different_keys_differ():
    proto = pamid.IsometricProtocol(sample_s=0.05, time_jitter_s=0.01)
    a = pamid.simulate_isometric_bench(jax.random.key(12), pamid.sarosi.table_3_1(), proto)
    b = pamid.simulate_isometric_bench(jax.random.key(12), pamid.sarosi.table_3_1(), proto)
    c = pamid.simulate_isometric_bench(jax.random.key(13), pamid.sarosi.table_3_1(), proto)
    pd.testing.assert_frame_equal(a, b)
    for column in ("pressure_kPa", "force_N", "contraction_pct", "time_s"):
        assert (a[column] != c[column]).mean() > 0.5, column
    for kind in LAB_FILE_KINDS:
        x = pamid.virtual_lab_file(jax.random.key(1), kind, 4000, n_muscles=2)
        y = pamid.virtual_lab_file(jax.random.key(1), kind, 4000, n_muscles=2)
        z = pamid.virtual_lab_file(jax.random.key(2), kind, 4000, n_muscles=2)
        pd.testing.assert_frame_equal(x, y)
        assert not x["force_N"].equals(z["force_N"])


def test_blank_direction_and_dropped_columns():
    frame = pamid.virtual_lab_file(
        jax.random.key(14), "mixed", 8000, n_muscles=4, blank_direction_for=["M0002", "M0004"],
        drop_columns=["length_mm", "l0_mm"],
    )
    assert "length_mm" not in frame and "l0_mm" not in frame
    blank = frame["direction"].isna()
    assert set(frame.loc[blank, "muscle"]) == {"M0002", "M0004"}
    assert not frame.loc[frame["muscle"].isin(["M0001", "M0003"]), "direction"].isna().any()
    # the first half is isometric, the rest sweeps with trials T1, T2, …
    assert frame.loc[frame["muscle"] == "M0001", "trial"].str.startswith("k").all()
    assert frame.loc[frame["muscle"] == "M0003", "trial"].str.fullmatch(r"T\d+").all()
    with pytest.raises(ValueError, match="muscles not in the file.*M9"):
        pamid.simulate_isometric_bench(
            jax.random.key(0), pamid.sarosi.table_3_1(), blank_direction_for=["M9"]
        )
    with pytest.raises(ValueError, match="columns not in the file.*speed"):
        pamid.simulate_isometric_bench(jax.random.key(0), pamid.sarosi.table_3_1(),
                                       drop_columns=["speed"])


@pytest.mark.parametrize("kind", ["isometric_stairs", "isometric_ramp", "sweeps_noisy"])
def test_lab_files_of_100000_rows_for_one_muscle(kind):
    frame = pamid.virtual_lab_file(jax.random.key(15), kind, 100_000)
    assert frame["muscle"].nunique() == 1
    if kind == "sweeps_noisy":
        assert 100_000 - 50 < len(frame) <= 100_000
    else:  # slack rows are left out, the sample interval chosen to come close
        assert len(frame) == pytest.approx(100_000, rel=0.01)
        assert frame["force_N"].min() > -5.0  # no slack muscle pushing
        offset = frame.loc[frame["time_s"] < 1.5, "pressure_kPa"].mean()
        assert offset == pytest.approx(8.0, abs=0.5)


def test_lab_file_without_slack_filter_has_at_most_n_rows():
    frame = pamid.virtual_lab_file(jax.random.key(16), "isometric_stairs", 30_000, min_force_N=None)
    assert 30_000 - 12 < len(frame) <= 30_000


def test_sarosi_protocol_logs_noisy_pressure_and_contraction_in_trials(sarosi31):
    base = pamid.SarosiProtocol(average_repeats=False, repeats=4, min_force_N=10.0)
    noisy = dataclasses.replace(
        base, pressure_noise_kPa=2.0, contraction_noise_pct=0.05, trials=True,
    )
    clean = pamid.simulate_sarosi_bench(jax.random.key(17), sarosi31, base)
    frame = pamid.simulate_sarosi_bench(jax.random.key(17), sarosi31, noisy)
    # the force comes from the true pressure and length, untouched by the other sensors
    np.testing.assert_array_equal(frame["force_N"], clean["force_N"])
    assert "trial" not in clean and list(pd.unique(frame["trial"])) == ["T1", "T2", "T3", "T4"]
    set_point = clean["pressure_kPa"].to_numpy()
    assert np.std(frame["pressure_kPa"] - set_point) == pytest.approx(2.0, rel=0.05)
    dk = frame["contraction_pct"] - clean["contraction_pct"]
    assert np.std(dk) == pytest.approx(0.05, rel=0.05)
    for _, trial in frame.groupby("trial"):
        t = trial["time_s"].to_numpy()
        assert t[0] == 0.0 and np.all(np.diff(t) > 0)
    np.testing.assert_array_equal(frame["cycle"], clean["cycle"])


def test_write_bench_csv_semicolon_and_decimal_comma_round_trip(tmp_path):
    frame = pamid.virtual_lab_file(
        jax.random.key(18), "mixed", 3000, n_muscles=2, blank_direction_for=["M0002"]
    )
    path = pamid.write_bench_csv(frame, tmp_path / "eu.csv", sep=";", decimal=",")
    text = path.read_text()
    header, first = text.splitlines()[:2]
    assert header == ";".join(frame.columns)
    assert "," in first and "." not in first
    assert ";;" in text or text.rstrip().endswith(";")  # the blank direction cells
    back = pd.read_csv(path, sep=";", decimal=",")
    pd.testing.assert_frame_equal(back, frame, check_dtype=False)
    assert back["direction"].isna().sum() == (frame["muscle"] == "M0002").sum()
    plain = pamid.write_bench_csv(frame, tmp_path / "plain.csv")
    pd.testing.assert_frame_equal(pd.read_csv(plain), frame, check_dtype=False)
    with pytest.raises(ValueError, match="other than the decimal mark"):
        pamid.write_bench_csv(frame, tmp_path / "bad.csv", sep=",", decimal=",")
    with pytest.raises(ValueError, match="writes CSV"):
        pamid.write_bench_csv(frame, tmp_path / "bad.parquet")


def test_load_bench_reads_an_isometric_file_when_it_can(tmp_path):
    """The loader learns trials and blank cells elsewhere; assert only once it loads."""
    frame = pamid.virtual_lab_file(jax.random.key(19), "isometric_stairs", 6000, n_muscles=2)
    path = pamid.write_bench_csv(frame, tmp_path / "iso.csv")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bench = pamid.load_bench(path)
    except pamid.BenchDataError as error:
        pytest.skip(f"load_bench does not read this file yet: {error}")
    loaded = bench.frame
    assert len(loaded) == len(frame)
    np.testing.assert_allclose(np.sort(loaded["force_N"]), np.sort(frame["force_N"]))


@pytest.mark.parametrize(
    ("options", "match"),
    [
        (dict(level_unit="mm"), "level_unit must be one of"),
        (dict(program="sine"), "program must be one of"),
        (dict(levels=(0.0, 1.5)), "must lie in 0 … 1"),
        (dict(levels=(0.0, 0.0)), "must differ"),
        (dict(levels=()), "at least one"),
        (dict(levels=(60.0,), level_unit="pct"), "must lie in −10 … 50"),
        (dict(step_kPa=0.0), "step_kPa must be positive"),
        (dict(sample_s=-1.0), "sample_s must be positive"),
        (dict(force_noise_N=-1.0), "force_noise_N must be zero or positive"),
        (dict(time_jitter_s=0.01, sample_s=0.02), "less than half of sample_s"),
        (dict(softening=1.0), "softening must lie in 0 … 1"),
        (dict(repeats=0), "repeats must be a whole number"),
        (dict(hysteresis_form="cubic"), "unknown hysteresis form"),
        (dict(pressure_offset_kPa=float("nan")), "pressure_offset_kPa must be finite"),
    ],
)
def test_protocol_rejects_bad_settings(options, match):
    with pytest.raises(ValueError, match=match):
        pamid.IsometricProtocol(**options)


def test_bad_requests_get_clear_errors():
    with pytest.raises(ValueError, match="unknown kind"):
        pamid.virtual_lab_file(jax.random.key(0), "dynamic", 1000)
    with pytest.raises(ValueError, match="needs n_muscles ≥ 2"):
        pamid.virtual_lab_file(jax.random.key(0), "mixed", 1000)
    with pytest.raises(ValueError, match="do not apply to kind"):
        pamid.virtual_lab_file(jax.random.key(0), "isometric_ramp", 1000, points_per_curve=3)
    with pytest.raises(ValueError, match="too few"):
        pamid.virtual_lab_file(jax.random.key(0), "isometric_stairs", 12, min_force_N=None)
    with pytest.raises(ValueError, match="muscle ids"):
        pamid.simulate_isometric_bench(jax.random.key(0), pamid.sarosi.table_3_1(),
                                       muscle_ids=["a", "b"])
    with pytest.raises(ValueError, match="pressure_noise_kPa must be zero or positive"):
        pamid.SarosiProtocol(pressure_noise_kPa=-1.0)


def test_an_effect_of_ones_own_subclasses_injected():
    """The bench's effects share one base: a user's effect logs a column and adds a force;
    an object that is not one is a TypeError saying what to subclass."""

    from pamid._effects._inject import apply_effects

    @dataclasses.dataclass(frozen=True)
    class Hum(pamid.Injected):
        def columns(self, ctx):
            return {"humidity_pct": 40.0 + 0.0 * ctx["p_bar"]}

        def force_N(self, ctx):
            return 0.1 * ctx["humidity_pct"]

    ctx = {"p_bar": np.array([1.0, 2.0])}
    added, columns = apply_effects([Hum()], ctx, (2,))
    np.testing.assert_allclose(added, 4.0)
    assert list(columns) == ["humidity_pct"]
    with pytest.raises(TypeError, match="subclass pamid.Injected"):
        apply_effects([object()], {}, (2,))
