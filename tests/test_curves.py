"""The one definition of a curve, of direction and of trials (pamid._data._curves)."""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np
import pandas as pd
import pytest

import pamid
from pamid._data._curves import find_curves

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
AARL = DATA / "aarl_festo10mm_isometric.csv"
MARTENS = DATA / "martens_dmsp10_250.csv"
PARAMS = pamid.Sarosi(-4.36, 281.2, -0.3287, -9.27, 302.2, -263.7)


@pytest.fixture(scope="module")
def sweeps():
    """Sárosi's protocol: 3 cycles × 5 pressures × (contracting, extending) × 30 points."""
    protocol = pamid.SarosiProtocol(repeats=3, average_repeats=False)
    return pamid.simulate_sarosi_bench(jax.random.key(0), PARAMS, protocol)


def _same_partition(a, b) -> bool:
    """Whether two labellings split the rows into the same groups."""
    pairs = pd.DataFrame({"a": a, "b": b}).drop_duplicates()
    return pairs["a"].is_unique and pairs["b"].is_unique


def test_exact_sweeps_one_curve_per_pressure_direction_and_cycle(sweeps):
    c = find_curves(sweeps)
    assert c.curve.max() + 1 == 3 * 5 * 2
    key = sweeps["cycle"].astype(str) + sweeps["pressure_kPa"].astype(str) + sweeps[
        "direction"].astype(str)
    assert _same_partition(c.curve, key)
    assert (c.moving == 0).all()
    assert c.direction_recorded.all()
    np.testing.assert_array_equal(np.unique(c.repeat), [0, 1, 2])  # from the cycle column


def test_direction_derived_from_contraction_order_in_sweeps(sweeps):
    c = find_curves(sweeps.drop(columns=["direction"]))
    np.testing.assert_array_equal(c.direction, sweeps["direction"].to_numpy())
    assert not c.direction_recorded.any()


@pytest.mark.parametrize("kind", ["gaussian", "quantised"])
def test_noisy_pressure_keeps_one_curve_per_held_level(sweeps, kind):
    rng = np.random.default_rng(3)
    noisy = sweeps.drop(columns=["direction"]).copy()
    p = noisy["pressure_kPa"].to_numpy() + rng.normal(0.0, 1.0 if kind == "gaussian" else 0.6,
                                                       len(noisy))
    noisy["pressure_kPa"] = p if kind == "gaussian" else np.round(p)  # 1 kPa resolution
    noisy["contraction_pct"] += rng.normal(0.0, 0.01, len(noisy))
    c = find_curves(noisy)
    assert _same_partition(c.curve, find_curves(sweeps).curve)
    np.testing.assert_array_equal(c.direction, sweeps["direction"].to_numpy())
    # the noise estimate is the noise that was added
    sd = 1.0 if kind == "gaussian" else np.sqrt(0.6**2 + 1 / 12)
    assert c.noise["pressure_kPa"][0] == pytest.approx(sd, rel=0.25)
    levels = np.unique(np.round(c.level, -1))
    np.testing.assert_array_equal(levels, [100, 200, 300, 400, 500])


def _isometric_trial(rng, kappa, p_max=600.0, n_up=300, n_hold=150, n_down=200, noise=0.5,
                     pulses=True):
    """A pressure ramp up, a hold and a ramp down at a held contraction, sampled at 50 Hz,
    with valve pulses (an overshoot and a dip after each step) and sensor noise."""
    up = np.linspace(8.0, p_max, n_up)
    if pulses:
        up = up + 12.0 * np.exp(-((np.arange(n_up) % 25) / 2.0)) - 6.0 * (np.arange(n_up) % 25 == 3)
    p = np.concatenate([up, np.full(n_hold, p_max), np.linspace(p_max, 20.0, n_down)])
    truth = np.concatenate([np.ones(n_up + n_hold), -np.ones(n_down)])
    n = len(p)
    return pd.DataFrame({
        "pressure_kPa": p + rng.normal(0.0, noise, n),
        "contraction_pct": np.full(n, kappa),
        "force_N": np.zeros(n),
        "time_s": np.arange(n) * 0.02,
    }), truth


def test_isometric_trials_direction_from_pressure_order_repeats_and_elapsed_time():
    rng = np.random.default_rng(7)
    parts, truth = [], []
    for kappa in (0.0, 4.0, 8.0):
        for rep in range(3):
            t, d = _isometric_trial(rng, kappa)
            parts.append(t.assign(trial=f"k{kappa:g}_T{rep + 1}"))
            truth.append(d)
    frame = pd.concat(parts, ignore_index=True).assign(muscle="M1")
    truth = np.concatenate(truth)
    c = find_curves(frame)
    assert (c.moving == 1).all()
    # inflating and deflating: two curves per trial, pulses and noise notwithstanding
    per_trial = pd.Series(c.curve).groupby(frame["trial"]).nunique()
    assert (per_trial == 2).all()
    # direction: +1 while the pressure rises (and holds after rising), −1 while it falls;
    # the last few samples of the hold may already look like the fall
    assert np.mean(c.direction == truth) > 0.97
    repeat = pd.Series(c.repeat).groupby(frame["trial"], sort=False).first()
    np.testing.assert_array_equal(repeat.to_numpy(), [0, 1, 2] * 3)
    trial = pd.Series(c.trial).groupby(frame["trial"], sort=False).first()
    np.testing.assert_array_equal(trial.to_numpy(), np.arange(9))
    # time restarts per trial; elapsed time runs on
    assert np.all(np.diff(c.elapsed_s) > 0)
    np.testing.assert_allclose(np.unique(np.round(c.level, 6)), [0.0, 4.0, 8.0])
    # the rate is that of the pressure: about (600 − 8) kPa over 300 samples of 20 ms
    rising = (c.direction == 1) & (frame["time_s"].to_numpy() < 5.0)
    assert np.median(c.rate[rising]) == pytest.approx(592.0 / (299 * 0.02), rel=0.15)


def test_a_file_that_mixes_sweeps_and_isometric_trials(sweeps):
    rng = np.random.default_rng(1)
    iso, _ = _isometric_trial(rng, 5.0)
    one = sweeps[sweeps["cycle"] == 1].drop(columns=["cycle", "length_mm", "l0_mm"])
    frame = pd.concat([one.assign(trial="sweep"), iso.assign(trial="iso", muscle=one["muscle"]
                                                            .iloc[0])], ignore_index=True)
    c = find_curves(frame)
    is_iso = (frame["trial"] == "iso").to_numpy()
    assert (c.moving[is_iso] == 1).all() and (c.moving[~is_iso] == 0).all()
    assert len(np.unique(c.curve[~is_iso])) == 10
    assert len(np.unique(c.curve[is_iso])) == 2


def test_blank_direction_cells_are_derived_and_recorded_ones_kept(sweeps):
    frame = sweeps.copy()
    direction = frame["direction"].to_numpy(dtype=float, copy=True)
    blank = np.zeros(len(frame), dtype=bool)
    blank[100:400] = True
    direction[blank] = np.nan
    frame["direction"] = direction
    c = find_curves(frame)
    np.testing.assert_array_equal(c.direction, sweeps["direction"].to_numpy())
    np.testing.assert_array_equal(c.direction_recorded, ~blank)


def test_muscles_are_independent_of_row_interleaving(sweeps):
    a = sweeps[sweeps["cycle"] == 1].assign(muscle="A")
    b = sweeps[sweeps["cycle"] == 2].assign(muscle="B", pressure_kPa=lambda f: f.pressure_kPa + 1)
    alone_a, alone_b = find_curves(a), find_curves(b)
    # rows alternate between the two muscles; each muscle's rows stay in time order
    mixed = pd.concat([a, b]).iloc[np.argsort(np.r_[np.arange(len(a)), np.arange(len(b))],
                                              kind="stable")].reset_index(drop=True)
    c = find_curves(mixed)
    is_a = (mixed["muscle"] == "A").to_numpy()
    np.testing.assert_array_equal(c.curve[is_a], alone_a.curve)
    np.testing.assert_array_equal(c.curve[~is_a], alone_b.curve)
    np.testing.assert_array_equal(c.direction[~is_a], alone_b.direction)


@pytest.mark.skipif(not MARTENS.exists(), reason="measured data not present")
def test_martens_force_map_one_curve_per_pressure_level():
    frame = pd.read_csv(MARTENS)
    frame = frame[frame["force_N"] != 0].reset_index(drop=True)  # censored points
    c = find_curves(frame)
    assert (c.moving == 0).all()
    assert _same_partition(c.curve, frame["pressure_kPa"])


@pytest.mark.skipif(not AARL.exists(), reason="measured data not present")
def test_real_isometric_file_two_curves_per_trial_and_its_direction():
    frame = pd.read_csv(AARL)
    c = find_curves(frame.drop(columns=["direction"]))
    assert (c.moving == 1).all()
    per_trial = pd.Series(c.curve).groupby([frame["muscle"], frame["trial"]]).nunique()
    assert len(per_trial) == 72
    # inflation and deflation (a few fragments of trials, which the source's filter cut,
    # hold valve spikes of 40 kPa in a 500 kPa range and split further)
    assert (per_trial == 2).mean() >= 0.9
    assert np.mean(c.direction == frame["direction"].to_numpy()) > 0.97
    repeat = pd.Series(c.repeat).groupby([frame["muscle"], frame["trial"]]).first()
    tag = repeat.index.get_level_values(1).str.extract(r"_T(\d+)$")[0].astype(int)
    np.testing.assert_array_equal(repeat.to_numpy(), tag.to_numpy() - 8)  # T8, T9, T10


@pytest.mark.parametrize(("kind", "per_trial"),
                         [("isometric_ramp", 2), ("isometric_stairs", 2), ("sweeps_noisy", 10)])
def test_virtual_lab_files_of_100000_rows_keep_their_curves(kind, per_trial):
    """Fast sampling (a one-sample step is mostly noise), noise on every logged channel,
    valve transients, trials restarting time, no direction column: the curves a lab ran."""
    frame = pamid.virtual_lab_file(jax.random.key(1), kind, 100_000)
    c = find_curves(frame.assign(direction=np.nan))
    assert (c.moving == (0 if kind.startswith("sweeps") else 1)).all()
    assert (pd.Series(c.curve).groupby(frame["trial"]).nunique() == per_trial).all()
    assert np.mean(c.direction == frame["direction"].to_numpy()) > 0.98
