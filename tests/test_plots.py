"""Plots a person can read on any file: bounded legends and points, the right axes for
sweeps and for isometric tests, both directions drawn, model lines at the held levels."""

from __future__ import annotations

from pathlib import Path

import jax
import matplotlib.colors
import numpy as np
import pandas as pd
import pytest

import pamid
from pamid._data._curves import find_curves
from pamid._fit._spec import SAROSI
from pamid._report._plot import (
    MAX_LINES,
    MAX_LISTED,
    MAX_POINTS,
    _level_groups,
    every_kth,
    plot_fit,
    plot_residuals,
)
from pamid._virtual._isometric import virtual_lab_file

REAL_FILE = Path(__file__).resolve().parents[2] / "shared" / "data" / "aarl_festo10mm_isometric.csv"
MAX_LEGEND = 8


def _load(tmp_path_factory, frame: pd.DataFrame, name: str) -> pd.DataFrame:
    """The frame written to CSV and read back by the loader, as the CLI plots it."""
    path = tmp_path_factory.mktemp("plots") / name
    frame.to_csv(path, index=False)
    bench = pamid.load_bench(path, keep_censored=True)
    return bench.for_muscle(bench.muscles[0])


@pytest.fixture(scope="module")
def sweeps_100k(tmp_path_factory):
    # Sárosi's sweeps, repeats kept, 1 kPa of noise on the logged pressure: with the old
    # rounding to 1 kPa every sample was its own "level".
    frame = virtual_lab_file(jax.random.key(0), "sweeps_noisy", 100_000)
    return _load(tmp_path_factory, frame, "sweeps_100k.csv")


@pytest.fixture(scope="module")
def isometric_100k(tmp_path_factory):
    frame = virtual_lab_file(jax.random.key(1), "isometric_stairs", 100_000)
    return _load(tmp_path_factory, frame, "isometric_100k.csv")


def _main_axes(fig):
    """The axes with a force label (data against model), left to right."""
    return [ax for ax in fig.axes if ax.get_ylabel() == "force F [N]"]


def _residual_axes_below(fig, ax):
    return [a for a in fig.axes if a is not ax and a.get_shared_x_axes().joined(a, ax)
            and a.get_ylabel().startswith("residual")]


def _points(ax) -> int:
    return sum(len(line.get_xdata()) for line in ax.get_lines()
               if line.get_linestyle() in ("None", "none", "") and line.get_marker() == "o")


def _model_lines(ax):
    return [line for line in ax.get_lines() if line.get_linestyle() == "-"
            and len(line.get_xdata()) > 2]


def _legend_labels(fig) -> list[str]:
    labels = [t.get_text() for leg in fig.legends for t in leg.get_texts()]
    for ax in fig.axes:
        if ax.get_legend() is not None:
            labels += [t.get_text() for t in ax.get_legend().get_texts()]
    return labels


def _fills(ax) -> set[str]:
    return {"open" if str(line.get_markerfacecolor()) in ("none", "white") else "filled"
            for line in ax.get_lines() if line.get_marker() == "o"}


def _check_bounded(fig):
    for ax in fig.axes:
        assert _points(ax) <= MAX_POINTS
        legend = ax.get_legend()
        if legend is not None:
            assert len(legend.get_texts()) <= MAX_LEGEND
    for legend in fig.legends:
        assert len(legend.get_texts()) <= MAX_LEGEND


# --------------------------------------------------------------------------------------
# The subsample
# --------------------------------------------------------------------------------------


def test_every_kth_keeps_every_group_with_the_smallest_stride():
    groups = np.array([0] * 10 + [1] + [2] * 5)
    keep, k = every_kth(groups, max_points=8)
    # k = 2 would keep 5 + 1 + 3 = 9 rows; k = 3 keeps 4 + 1 + 2 = 7
    assert k == 3
    np.testing.assert_array_equal(keep, [0, 3, 6, 9, 10, 11, 14])


def test_every_kth_interleaved_groups_and_small_tables():
    groups = np.tile([5, 7], 50)  # two groups whose rows alternate
    keep, k = every_kth(groups, max_points=20)
    assert k == 5 and len(keep) == 20
    np.testing.assert_array_equal(keep[:4], [0, 1, 10, 11])
    keep, k = every_kth(np.zeros(30), max_points=100)
    assert k == 1 and len(keep) == 30


def test_level_groups_merge_noise_but_not_a_spread_of_levels():
    # set points read through noise are one level each
    group, n = _level_groups(np.array([100.0, 100.4, 99.8, 200.0, 200.3, 300.0, 99.9]))
    assert n == 3
    np.testing.assert_array_equal(group, [0, 0, 0, 1, 1, 2, 0])
    # levels every 5 kPa from 0 to 600 (gaps below 2 % of the range) do not chain into one
    # group: groups of 3 levels (within 12 kPa), 41 of them, binned into MAX_LINES
    group, n = _level_groups(np.arange(0.0, 601.0, 5.0))
    assert n == MAX_LINES == 20
    assert np.all(np.diff(group) >= 0) and group[0] == 0 and group[-1] == 19


# --------------------------------------------------------------------------------------
# Sweeps: force against contraction per pressure level
# --------------------------------------------------------------------------------------


def test_noisy_sweeps_draw_bounded_legend_and_points(sweeps_100k, theta31, tmp_path):
    fig = plot_fit(sweeps_100k, SAROSI, theta31, tmp_path / "fit.png", "Sárosi eq. 2.1 — M1")
    assert (tmp_path / "fit.png").stat().st_size > 10_000
    _check_bounded(fig)
    (ax,) = _main_axes(fig)
    (axr,) = _residual_axes_below(fig, ax)
    assert axr.get_xlabel() == "contraction κ [%]"
    # every k-th sample of each curve, k the smallest stride that keeps ≤ MAX_POINTS
    keep, k = every_kth(find_curves(sweeps_100k).curve)
    assert k > 1 and f"every {k}th of 100,000 samples shown" in ax.get_title()
    assert _points(ax) == len(keep) > MAX_POINTS * 0.8
    labels = _legend_labels(fig)
    assert labels[:5] == ["100 kPa", "200 kPa", "300 kPa", "400 kPa", "500 kPa"]
    assert {"contracting (filled)", "extending (open)"} <= set(labels)
    assert _fills(ax) == {"filled", "open"}
    # one model line per pressure level, at the held level: Table 3-1 at 100…500 kPa
    lines = _model_lines(ax)
    assert len(lines) == 5
    for line, p_kpa in zip(lines, (100.0, 200.0, 300.0, 400.0, 500.0), strict=True):
        kappa, force = line.get_xdata(), line.get_ydata()
        expected = pamid.sarosi.sarosi_force(pamid.Sarosi(*theta31), p_kpa / 100.0, kappa)
        # held at the median of the noisy pressure (1 kPa noise, thousands of samples):
        # within 0.2 kPa of the set point, and eq. 2.1 changes by < 3.1 N per kPa here
        np.testing.assert_allclose(force, expected, atol=0.2 * 3.1)
        # along the contraction range of that pressure's samples
        at = (sweeps_100k["pressure_kPa"] - p_kpa).abs() < 10.0
        assert kappa[0] == pytest.approx(sweeps_100k.loc[at, "contraction_pct"].min())
        assert kappa[-1] == pytest.approx(sweeps_100k.loc[at, "contraction_pct"].max())


def test_noisy_sweeps_residual_plot(sweeps_100k, theta31, tmp_path):
    fig = plot_residuals(sweeps_100k, SAROSI, theta31, tmp_path / "res.png", "Residuals — M1")
    _check_bounded(fig)
    xlabels = [ax.get_xlabel() for ax in fig.axes]
    assert xlabels == ["contraction κ [%] (moving)", "held pressure p [kPa] (level of the curve)",
                       "elapsed time [h] (trials end to end)", "fitted force [N]"]
    labels = _legend_labels(fig)
    # five trials: listed by name, with both directions
    assert labels == ["contracting (filled)", "extending (open)", "trial T1", "trial T2",
                      "trial T3", "trial T4", "trial T5"]
    assert "th of 100,000 samples shown" in fig.get_suptitle()


# --------------------------------------------------------------------------------------
# Isometric tests: force against pressure per contraction level
# --------------------------------------------------------------------------------------


def test_isometric_file_gets_force_against_pressure(isometric_100k, theta31, tmp_path):
    fig = plot_fit(isometric_100k, SAROSI, theta31, tmp_path / "fit.png", "M1")
    _check_bounded(fig)
    (ax,) = _main_axes(fig)
    (axr,) = _residual_axes_below(fig, ax)
    assert axr.get_xlabel() == "pressure p [kPa]"
    assert ax.get_title().startswith("isometric tests")
    labels = _legend_labels(fig)
    assert {"inflating (filled)", "deflating (open)"} <= set(labels)
    assert _fills(ax) == {"filled", "open"}
    # the four clamped lengths, listed; a model line at each, along the pressure
    levels = isometric_100k.groupby("trial")["contraction_pct"].median().unique()
    lines = _model_lines(ax)
    assert len(lines) == len(np.unique(np.round(levels, 6))) == 4 <= MAX_LISTED
    model = pamid.Sarosi(*theta31)
    for line in lines:
        p_kpa, force = line.get_xdata(), line.get_ydata()
        errors = [np.max(np.abs(force - pamid.sarosi.sarosi_force(model, p_kpa / 100.0, k)))
                  for k in levels]
        assert min(errors) < 1e-6


def test_isometric_residuals_against_pressure_and_held_contraction(isometric_100k, theta31,
                                                                   tmp_path):
    fig = plot_residuals(isometric_100k, SAROSI, theta31, tmp_path / "res.png", "M1")
    _check_bounded(fig)
    assert [ax.get_xlabel() for ax in fig.axes][:2] == [
        "pressure p [kPa] (moving)", "held contraction κ [%] (level of the curve)"]
    labels = _legend_labels(fig)
    # 12 trials (4 lengths × 3): coloured by repeat, not listed one by one
    assert labels == ["inflating (filled)", "deflating (open)", "repeat 1 of a setting",
                      "repeat 2 of a setting", "repeat 3 of a setting"]


def test_many_levels_get_a_colour_bar_not_a_legend(theta31, tmp_path):
    # 40 pressure levels, one short sweep each
    kappa = np.linspace(0.0, 10.0, 12)
    p = np.repeat(np.linspace(50.0, 600.0, 40), len(kappa))
    k = np.tile(kappa, 40)
    frame = pd.DataFrame({
        "muscle": "M", "pressure_kPa": p, "contraction_pct": k,
        "force_N": np.asarray(pamid.sarosi.sarosi_force(pamid.Sarosi(*theta31), p / 100.0, k)),
    })
    fig = plot_fit(frame, SAROSI, theta31, tmp_path / "fit.png", "M")
    _check_bounded(fig)
    (ax,) = _main_axes(fig)
    assert len(_model_lines(ax)) <= 20
    colour_bars = [a for a in fig.axes if a.get_ylabel().startswith("pressure p [kPa]")]
    assert len(colour_bars) == 1
    assert not any(label.endswith("kPa") for label in _legend_labels(fig))


def test_a_file_that_mixes_sweeps_and_isometric_tests_gets_both(tmp_path_factory, theta31,
                                                                 tmp_path):
    a = virtual_lab_file(jax.random.key(2), "isometric_stairs", 8_000, repeats=1)
    b = virtual_lab_file(jax.random.key(3), "sweeps_noisy", 8_000, repeats=1)
    shared = [c for c in a.columns if c in b.columns]
    a, b = a[shared].copy(), b[shared].copy()
    b["muscle"] = a["muscle"].iloc[0]
    a["trial"] = "iso_" + a["trial"].astype(str)
    b["trial"] = "sweep_" + b["trial"].astype(str)
    frame = _load(tmp_path_factory, pd.concat([a, b], ignore_index=True), "mixed.csv")
    fig = plot_fit(frame, SAROSI, theta31, tmp_path / "fit.png", "M1")
    _check_bounded(fig)
    axes = _main_axes(fig)
    assert [ax.get_title().split(":")[0] for ax in axes] == ["sweeps", "isometric tests"]
    assert [_residual_axes_below(fig, ax)[0].get_xlabel() for ax in axes] == [
        "contraction κ [%]", "pressure p [kPa]"]
    fig = plot_residuals(frame, SAROSI, theta31, tmp_path / "res.png", "M1")
    assert [ax.get_xlabel() for ax in fig.axes][:2] == ["contraction κ [%]", "pressure p [kPa]"]


# --------------------------------------------------------------------------------------
# Maps logged by hand: the view chosen by the data
# --------------------------------------------------------------------------------------


def _hand_logged_map(theta31, seed: int = 3, scattered: bool = False) -> pd.DataFrame:
    """60 points logged by hand on a 300 mm muscle: three lengths held within ±2 mm while
    the pressure goes up and down (15 kPa of scatter), forces from Table 3-1 with 8 N of
    noise; ``scattered``: length and pressure anywhere (neither held)."""
    rng = np.random.default_rng(seed)
    if scattered:
        length = rng.uniform(250.0, 290.0, 60)
        p = rng.uniform(100.0, 600.0, 60)
    else:
        length = np.repeat([285.0, 270.0, 255.0], 20) + rng.uniform(-2.0, 2.0, 60)
        p = np.tile(np.r_[np.linspace(100, 600, 10), np.linspace(600, 100, 10)], 3)
        p = p + rng.normal(0.0, 15.0, 60)
    kappa = 100.0 * (300.0 - length) / 300.0
    force = np.asarray(pamid.sarosi.sarosi_force(pamid.Sarosi(*theta31), p / 100.0, kappa))
    return pd.DataFrame({"pressure_kPa": np.round(p, 1), "force_N": np.round(
        force + rng.normal(0.0, 8.0, 60), 1), "length_mm": np.round(length, 1), "l0_mm": 300})


def _line_colour(line) -> tuple:
    return tuple(np.round(matplotlib.colors.to_rgba(line.get_color()), 6))


def test_hand_logged_isometric_map_gets_force_against_pressure(tmp_path_factory, theta31,
                                                               tmp_path):
    """Was: force against contraction at two "held" pressures, most points on no line."""
    frame = _load(tmp_path_factory, _hand_logged_map(theta31), "hand.csv")
    fig = plot_fit(frame, SAROSI, theta31, tmp_path / "fit.png", "hand-logged map")
    _check_bounded(fig)
    (ax,) = _main_axes(fig)
    (axr,) = _residual_axes_below(fig, ax)
    assert axr.get_xlabel() == "pressure p [kPa]"
    assert "held contractions" in ax.get_title()
    # one model line per held length, at that length's median contraction
    lines = _model_lines(ax)
    assert len(lines) == 3
    model = pamid.Sarosi(*theta31)
    levels = frame.groupby(np.round(frame["length_mm"] / 15))["contraction_pct"].median()
    for line, kappa in zip(lines, sorted(levels), strict=True):
        p_kpa, force = line.get_xdata(), line.get_ydata()
        np.testing.assert_allclose(force, pamid.sarosi.sarosi_force(model, p_kpa / 100.0,
                                                                    kappa), atol=1e-6)
    # every measured point lies on the span of the model line of its own level (colour)
    spans = {_line_colour(line): (line.get_xdata().min(), line.get_xdata().max())
             for line in lines}
    points = [line for line in ax.get_lines() if line.get_marker() == "o"
              and line.get_linestyle() in ("None", "none", "")]
    assert sum(len(line.get_xdata()) for line in points) == 60
    for line in points:
        lo, hi = spans[_line_colour(line)]
        assert np.all((line.get_xdata() >= lo) & (line.get_xdata() <= hi))
    # both directions, from the order of the pressure within each length
    assert _fills(ax) == {"filled", "open"}
    # and measured against predicted, every point
    (axp,) = [a for a in fig.axes if a.get_ylabel() == "measured force F [N]"]
    assert axp.get_xlabel() == "model force F̂ [N]" and _points(axp) == 60


def test_scattered_map_gets_force_against_pressure_per_contraction_bin(tmp_path_factory,
                                                                      theta31, tmp_path):
    frame = _load(tmp_path_factory, _hand_logged_map(theta31, scattered=True), "scatter.csv")
    fig = plot_fit(frame, SAROSI, theta31, tmp_path / "fit.png", "scattered map")
    (ax,) = _main_axes(fig)
    assert "per contraction bin" in ax.get_title()
    assert _residual_axes_below(fig, ax)[0].get_xlabel() == "pressure p [kPa]"
    assert len(_model_lines(ax)) == 4


# --------------------------------------------------------------------------------------
# The real file
# --------------------------------------------------------------------------------------


def test_real_isometric_file(tmp_path):
    if not REAL_FILE.exists():
        pytest.skip(f"{REAL_FILE} is not here")
    bench = pamid.load_bench(REAL_FILE)
    fit = pamid.fit_least_squares(bench)
    frame = bench.for_muscle(bench.muscles[0])
    fig = plot_fit(frame, fit.spec, fit.theta[0], tmp_path / "fit.png",
                   f"Sárosi eq. 2.1 fit — {bench.muscles[0]}")
    _check_bounded(fig)
    (ax,) = _main_axes(fig)
    (axr,) = _residual_axes_below(fig, ax)
    assert axr.get_xlabel() == "pressure p [kPa]"
    assert len(_model_lines(ax)) == 4  # four clamped lengths per muscle
    assert {"inflating (filled)", "deflating (open)"} <= set(_legend_labels(fig))
    assert _fills(ax) == {"filled", "open"}
    fig = plot_residuals(frame, fit.spec, fit.theta[0], tmp_path / "res.png", "residuals")
    _check_bounded(fig)
    assert fig.axes[2].get_xlabel() == "elapsed time [s] (trials end to end)"
    # 12 trials: the trials' time restarts, elapsed time runs on across them
    elapsed = fig.axes[2].get_lines()
    assert max(np.max(line.get_xdata()) for line in elapsed if len(line.get_xdata())) > 200.0


# --------------------------------------------------------------------------------------
# The diagnosis plots
# --------------------------------------------------------------------------------------


def test_diagnosis_plots_of_a_big_table_are_subsampled_per_curve(tmp_path):
    from pamid._diagnose._api import Diagnosis
    from pamid.report import plot_diagnosis_residuals as plot_diagnosis
    from pamid.report import plot_diagnosis_time_order as plot_time_order

    table = virtual_lab_file(jax.random.key(4), "sweeps_noisy", 100_000, n_muscles=2)
    table["group"] = table["muscle"]
    # a residual the effect removes: ±3 N by direction before, noise after
    rng = np.random.default_rng(0)
    table["residual_before_N"] = 3.0 * table["direction"] + rng.normal(0.0, 1.0, len(table))
    table["residual_after_N"] = rng.normal(0.0, 1.0, len(table))
    covs = {c: {"p_value": 0.5} for c in ("pressure_kPa", "contraction_pct", "direction")}
    d = Diagnosis(path="big.csv", kind="bench", model="sarosi", n=len(table), n_groups=2,
                  rmse_before=3.2, rmse_after=1.0, max_error_before=8.0, max_error_after=4.0,
                  cv_rmse_before=3.2, cv_rmse_after=1.0, selected=["hysteresis"], dropped=[],
                  candidates=[], steps=[], constants=[], groups=["M0001", "M0002"],
                  residual_before={"covariates": covs}, residual_after={"covariates": covs},
                  unexplained=[], table=table)
    fig = plot_diagnosis(d, tmp_path / "res.png")
    assert (tmp_path / "res.png").stat().st_size > 10_000
    for ax in fig.axes[:3]:
        drawn = sum(len(line.get_xdata()) for line in ax.get_lines() if line.get_marker() == ".")
        assert MAX_POINTS * 0.8 < drawn <= MAX_POINTS
    assert "samples shown" in fig.get_suptitle() and "sarosi, 2 muscles" in fig.get_suptitle()
    fig = plot_time_order(d, tmp_path / "time.png")
    (before,) = [line for line in fig.axes[0].get_lines() if len(line.get_xdata()) > 2]
    x = np.asarray(before.get_xdata())
    assert len(x) <= MAX_POINTS
    # every curve of both muscles keeps samples
    curve = find_curves(table).curve + 1000 * pd.factorize(table["muscle"])[0]
    assert set(np.unique(curve[x])) == set(np.unique(curve))
