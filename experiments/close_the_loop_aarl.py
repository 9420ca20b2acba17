#!/usr/bin/env python
"""Closing the loop on the measured AARL 10 mm file: what Sárosi eq. 2.1 misses, and whether
one set of constants holds for every length.

Data: ``../shared/data/aarl_festo10mm_isometric.csv`` next to the repository (isometric
tests of cut Festo 10 mm tube, 6 muscles of resting length 83–382 mm, 4 clamped lengths ×
3 repeats each, a pulsed valve stepping the pressure up to ≈ 620 kPa and down; see the data
README). If the file is absent the script prints "skipped: file absent" and exits 0.

Per muscle and pooled over the muscles:

1. the baseline: Sárosi eq. 2.1 fitted per muscle (``pamid.fit_least_squares``; Wald and
   cluster-robust 95 % intervals), RMSE and max error;
2. ``pamid.diagnose`` on all muscles at once (one selection of effects, constants per
   muscle) and on each muscle alone: what is selected, its constants with 95 % intervals,
   RMSE, max error and CV RMSE before and after, and what stays unexplained;
3. per-bin tables of the residual before and after: by contraction level and pressure bin,
   by time since the last pressure step, by repeat;
4. the length study (``pamid.length_study``): one fit per muscle against
   constants smooth in l0 and one set for every length, by CV RMSE on held-out trials;
5. plots: force against pressure per contraction level (inflating/deflating marked) before
   and after; residual against time since the last step; residual against repeat; the
   constants against l0.

Nothing is tuned to the file: a selection of a bookkeeping column (``src_row``, the row
number in the source file) is reported as what it is, not as a physical effect.

    .venv/bin/python experiments/close_the_loop_aarl.py [--out DIR] [--data CSV] [--quick]

``--quick``: the first and last muscle of the file, 2200 evenly spaced rows of each, for the
baseline and the diagnoses; the length study on all six muscles at 2200 rows each: the
test's and the notebook's run.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

import pamid  # noqa: E402
from pamid.io import json_ready, save_figure_atomic, write_text_atomic  # noqa: E402
from pamid.sarosi import sarosi_force  # noqa: E402

NAME = "close_the_loop_aarl"
ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "aarl_festo10mm_isometric.csv"
#: Columns of the file that are bookkeeping, not a physical quantity (data README).
BOOKKEEPING = {"src_row": "the row number in the source file",
               "source_row": "the row number in this file"}
#: Rows per muscle of a quick run: one in about 4–5 (every 8th row would be too coarse for
#: the curve finder to match the repeats of a setting: 0.15 s between samples).
QUICK_ROWS_PER_MUSCLE = 2200
PRESSURE_BIN_KPA = 100.0
TIME_BINS_S = (0.0, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, np.inf)
LEVEL_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")
MIN_BIN_ROWS = 20  # the bin named as the worst left must hold at least this many rows
PLOT_EVERY = 12  # rows drawn as points in the residual plots (all rows are in the tables)
POINTS_EVERY = 4  # ... and in the force plot


def rmse(r) -> float:
    r = np.asarray(r, float)
    return float(np.sqrt(np.mean(r**2))) if len(r) else float("nan")


def subset(bench, muscles=None, rows_per_muscle: int | None = None):
    """The bench restricted to some muscles and, with ``rows_per_muscle``, to that many rows
    of each, evenly spaced in file order (every muscle the same count, so that the batched
    fits of one muscle and of several share their compiled programs)."""
    frame = bench.frame
    if muscles is not None:
        frame = frame[frame["muscle"].isin(muscles)]
    if rows_per_muscle is not None:
        keep = []
        for _, idx in frame.groupby("muscle", sort=False).indices.items():
            pick = np.round(np.linspace(0, len(idx) - 1, min(rows_per_muscle, len(idx))))
            keep.append(idx[np.unique(pick.astype(int))])
        frame = frame.iloc[np.sort(np.concatenate(keep))]
    frame = frame.reset_index(drop=True)
    kept = tuple(m for m in bench.muscles if m in set(frame["muscle"]))
    return bench.with_frame(frame, muscles=kept,
                            l0_mm={m: bench.l0_mm.get(m) for m in kept})


# ------------------------------------------------------------------------------------------
# 1. baseline


def baseline(bench) -> tuple[dict, np.ndarray]:
    """Sárosi eq. 2.1 per muscle: constants with Wald and cluster (CR3 by curve) intervals,
    RMSE, max error; and the model force of every row."""
    fit = pamid.fit_least_squares(bench, intervals=("wald", "cluster"))
    frame = bench.frame
    model = np.empty(len(frame))
    out = {}
    for i, m in enumerate(bench.muscles):
        rows = (frame["muscle"] == m).to_numpy()
        model[rows] = np.asarray(sarosi_force(
            fit.params(i), frame["pressure_kPa"].to_numpy()[rows] / 100.0,
            frame["contraction_pct"].to_numpy()[rows]))
        r = frame["force_N"].to_numpy()[rows] - model[rows]
        out[m] = {
            "n": int(fit.n[i]), "rmse_N": float(fit.rmse_N[i]),
            "max_error_N": float(np.abs(r).max()),
            "converged": bool(fit.converged[i]), "residual_lag1": float(fit.residual_lag1[i]),
            "l0_mm": bench.l0_mm.get(m),
            "params": {name: {"value": float(fit.theta[i, j]), "unit": fit.param_units[name],
                              "ci95": [float(v) for v in fit.ci95[i, j]],
                              "ci95_cluster": [float(v) for v in fit.ci95_cluster[i, j]]}
                       for j, name in enumerate(fit.param_names)},
        }
    return out, model


# ------------------------------------------------------------------------------------------
# 2. diagnosis


def effect_kind(name: str) -> str:
    if not name.startswith("covariate:"):
        return "library effect"
    column = name.split(":", 1)[1]
    if column in BOOKKEEPING:
        return f"bookkeeping column ({BOOKKEEPING[column]}): not physical"
    return "generic smooth function of a covariate: not a library effect"


def diagnosis_summary(d) -> dict:
    first = d.steps[0]["candidates"] if d.steps else []
    return {
        "muscles": list(d.groups), "n": d.n,
        "selected": [{"effect": e, "kind": effect_kind(e)} for e in d.selected],
        "dropped": d.dropped,
        "rmse_before_N": d.rmse_before, "rmse_after_N": d.rmse_after,
        "max_error_before_N": d.max_error_before, "max_error_after_N": d.max_error_after,
        "cv_rmse_before_N": d.cv_rmse_before, "cv_rmse_after_N": d.cv_rmse_after,
        "constants": d.constants, "unexplained": d.unexplained,
        "first_step_candidates": [
            {k: c.get(k) for k in ("effect", "delta_bic", "cv_rmse", "significant",
                                   "unphysical")} for c in first],
        "steps": [{"added": s["added"], "rmse_before_N": s["rmse_before"],
                   "cv_rmse_before_N": s["cv_rmse_before"]} for s in d.steps],
    }


def bookkeeping_reading(frame: pd.DataFrame, column: str) -> dict:
    """How a bookkeeping column relates to time within its trial: the correlation of the
    column with ``time_s`` inside each trial (median, min)."""
    r = [np.corrcoef(g[column], g["time_s"])[0, 1] for _, g in frame.groupby(["muscle", "trial"])
         if len(g) > 2 and g[column].std() > 0 and g["time_s"].std() > 0]
    return {"column": column, "trials": len(r), "median_corr_with_time_s": float(np.median(r)),
            "min_corr_with_time_s": float(np.min(r))}


# ------------------------------------------------------------------------------------------
# 3. per-bin tables


def with_levels(table: pd.DataFrame) -> pd.DataFrame:
    """Adds ``level`` (0, 1, … the muscle's clamped contractions in increasing order) and
    ``pressure_bin_kPa`` (lower edge of a 100 kPa bin)."""
    out = table.copy()
    kappa = out["contraction_pct"].round(1)
    out["level"] = kappa.groupby(out["muscle"]).rank(method="dense").astype(int) - 1
    out["pressure_bin_kPa"] = (np.floor(out["pressure_kPa"] / PRESSURE_BIN_KPA)
                               * PRESSURE_BIN_KPA).astype(int)
    return out


RESIDUALS = {"before": "residual_before_N", "after_pooled": "residual_after_pooled_N",
             "after_per_muscle": "residual_after_per_muscle_N"}


def bin_table(table: pd.DataFrame, by: list[str]) -> list[dict]:
    rows = []
    for key, g in table.groupby(by, sort=True, observed=True):
        key = key if isinstance(key, tuple) else (key,)
        row = {b: (k.item() if hasattr(k, "item") else (str(k) if isinstance(k, pd.Interval)
                                                        else k)) for b, k in zip(by, key)}
        row["n"] = int(len(g))
        for label, col in RESIDUALS.items():
            if col in g:
                row[f"rmse_{label}_N"] = rmse(g[col])
                row[f"mean_{label}_N"] = float(g[col].mean())
        rows.append(row)
    return rows


def bin_tables(table: pd.DataFrame) -> dict:
    out = {
        "by_level_and_pressure": bin_table(table, ["level", "pressure_bin_kPa"]),
        "by_muscle_level_and_pressure": bin_table(table, ["muscle", "level", "pressure_bin_kPa"]),
        "by_repeat": bin_table(table, ["repeat"]) if "repeat" in table else [],
        "by_muscle_and_repeat": (bin_table(table, ["muscle", "repeat"])
                                 if "repeat" in table else []),
    }
    if "time_since_step_s" in table:
        t = table.assign(time_since_step_bin_s=pd.cut(table["time_since_step_s"],
                                                      TIME_BINS_S, right=False))
        out["by_time_since_step"] = bin_table(t, ["time_since_step_bin_s"])
    return out


# ------------------------------------------------------------------------------------------
# 5. plots


def plot_force_vs_pressure(table: pd.DataFrame, baseline_params: dict, out: Path) -> Path:
    muscles = list(dict.fromkeys(table["muscle"]))
    fig, axes = plt.subplots(len(muscles), 2, figsize=(11, 2.9 * len(muscles) + 0.8),
                             squeeze=False, sharex=True)
    p_grid = np.linspace(0.0, table["pressure_kPa"].max(), 200)
    for i, m in enumerate(muscles):
        rows = table[table["muscle"] == m]
        prm = pamid.Sarosi(**{k: v["value"] for k, v in baseline_params[m]["params"].items()})
        for col, (title, resid) in enumerate((("before: Sárosi eq. 2.1", "residual_before_N"),
                                               ("after: with the pooled selection",
                                                "residual_after_pooled_N"))):
            ax = axes[i, col]
            for lev, g in rows.groupby("level"):
                colour = LEVEL_COLOURS[lev % len(LEVEL_COLOURS)]
                pts = g.iloc[::POINTS_EVERY]
                for sign, marker in ((1, "^"), (-1, "v")):
                    s = pts[pts["direction"] == sign]
                    ax.scatter(s["pressure_kPa"], s["force_N"], s=9, marker=marker,
                               color=colour, alpha=0.5, linewidths=0)
                if col == 0:  # eq. 2.1 over the pressures measured at this level
                    kappa = float(g["contraction_pct"].median())
                    p = p_grid[(p_grid >= g["pressure_kPa"].min())
                               & (p_grid <= g["pressure_kPa"].max())]
                    ax.plot(p, np.asarray(sarosi_force(prm, p / 100.0, kappa)),
                            color=colour, lw=1.4)
                else:
                    fitted = g["force_N"] - g[resid]
                    for (_, sign), c in g.assign(fitted=fitted).groupby(["trial", "direction"]):
                        ax.plot(c["pressure_kPa"], c["fitted"], color=colour, lw=0.6,
                                ls="-" if sign > 0 else "--", alpha=0.7)
            r = rows[resid]
            ax.set_title(f"{m} (l0 = {rows['l0_mm'].iloc[0]:.0f} mm) — {title}\n"
                         f"RMSE {rmse(r):.1f} N, max |error| {np.abs(r).max():.0f} N",
                         fontsize=8.5)
            ax.set_ylabel("force [N]")
            ax.grid(alpha=0.3)
        kappas = ", ".join(f"{k:.1f}" for k in sorted(rows.groupby("level")["contraction_pct"]
                                                       .median()))
        axes[i, 0].text(0.02, 0.96, f"κ = {kappas} %", transform=axes[i, 0].transAxes,
                        fontsize=7.5, va="top")
    for ax in axes[-1]:
        ax.set_xlabel("pressure [kPa]")
    n_levels = int(table["level"].max()) + 1
    handles = [Line2D([], [], color=LEVEL_COLOURS[k], lw=2, label=f"contraction level {k}")
               for k in range(n_levels)]
    handles += [Line2D([], [], marker="^", ls="", color="k", label="data, inflating"),
                Line2D([], [], marker="v", ls="", color="k", label="data, deflating"),
                Line2D([], [], color="k", lw=1.4, label="eq. 2.1 (before)"),
                Line2D([], [], color="k", lw=0.8, label="after, inflating"),
                Line2D([], [], color="k", lw=0.8, ls="--", label="after, deflating")]
    fig.legend(handles=handles, loc="lower center", ncol=5, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.6 / (2.9 * len(muscles) + 0.8) + 0.02, 1, 1))
    path = out / "force_vs_pressure_before_after.png"
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)
    return path


def _binned(x, r, edges):
    mids, med, lo, hi, rms = [], [], [], [], []
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (x >= a) & (x < b)
        if sel.sum() < 5:
            continue
        mids.append(np.median(x[sel]))
        med.append(np.median(r[sel]))
        lo.append(np.percentile(r[sel], 10))
        hi.append(np.percentile(r[sel], 90))
        rms.append(rmse(r[sel]))
    return map(np.asarray, (mids, med, lo, hi, rms))


def plot_time_since_step(table: pd.DataFrame, out: Path) -> Path | None:
    if "time_since_step_s" not in table:
        return None
    x = np.maximum(table["time_since_step_s"].to_numpy(), 1e-3)
    edges = np.geomspace(1e-3, max(x.max(), 2e-3) * 1.001, 16)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    both = np.r_[table["residual_before_N"], table["residual_after_pooled_N"]]
    lim = np.percentile(np.abs(both), 99.5)
    for ax, (title, col) in zip(axes, (("before: Sárosi eq. 2.1", "residual_before_N"),
                                       ("after: with the pooled selection",
                                        "residual_after_pooled_N"))):
        r = table[col].to_numpy()
        ax.scatter(x[::PLOT_EVERY], r[::PLOT_EVERY], s=3, color="0.6", alpha=0.3, linewidths=0,
                   label="residual (every 12th row)")
        mids, med, lo, hi, rms = _binned(x, r, edges)
        ax.fill_between(mids, lo, hi, color="tab:blue", alpha=0.2, label="10–90 % per bin")
        ax.plot(mids, med, color="tab:blue", lw=1.8, label="median per bin")
        ax.plot(mids, rms, color="tab:red", lw=1.4, ls="--", label="RMSE per bin")
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xscale("log")
        ax.set_ylim(-lim, lim)
        ax.set_xlabel("time since the last pressure step [s] (log; 0 drawn at 1 ms)")
        ax.set_title(f"{title}: RMSE {rmse(r):.1f} N", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("residual: data − model [N]")
    axes[0].legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    path = out / "residual_vs_time_since_step.png"
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_repeat(table: pd.DataFrame, out: Path) -> Path | None:
    if "repeat" not in table:
        return None
    repeats = sorted(table["repeat"].unique())
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    ax = axes[0]
    data_b = [table.loc[table["repeat"] == k, "residual_before_N"] for k in repeats]
    data_a = [table.loc[table["repeat"] == k, "residual_after_pooled_N"] for k in repeats]
    pos = np.arange(len(repeats))
    for data, shift, colour, label in ((data_b, -0.18, "tab:blue", "before"),
                                       (data_a, 0.18, "tab:orange", "after (pooled selection)")):
        bp = ax.boxplot(data, positions=pos + shift, widths=0.3, showfliers=False,
                        patch_artist=True)
        for patch in bp["boxes"]:
            patch.set_facecolor(colour)
            patch.set_alpha(0.5)
        ax.plot([], [], color=colour, lw=6, alpha=0.5, label=label)
    ax.set_xticks(pos, [str(k) for k in repeats])
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xlabel("repeat (0 = first trial at a clamped length)")
    ax.set_ylabel("residual: data − model [N]")
    ax.set_title("box: 25–75 %, line: median, whiskers: 1.5 IQR", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax = axes[1]
    for k, (m, g) in enumerate(table.groupby("muscle", sort=False)):
        colour = LEVEL_COLOURS[k % len(LEVEL_COLOURS)]
        mb = g.groupby("repeat")["residual_before_N"].mean()
        ma = g.groupby("repeat")["residual_after_pooled_N"].mean()
        ax.plot(mb.index, mb.values, color=colour, ls="--", marker="o", ms=3)
        ax.plot(ma.index, ma.values, color=colour, ls="-", marker="s", ms=3,
                label=f"{m} (l0 {g['l0_mm'].iloc[0]:.0f} mm)")
    ax.plot([], [], color="k", ls="--", label="before")
    ax.plot([], [], color="k", ls="-", label="after")
    ax.axhline(0, color="k", lw=0.6)
    ax.set_xticks(repeats)
    ax.set_xlabel("repeat")
    ax.set_ylabel("mean residual per muscle [N]")
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path = out / "residual_vs_repeat.png"
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)
    return path


def plot_constants_vs_l0(study, base: dict, out: Path) -> Path:
    l0 = np.asarray(study.l0_mm)
    grid = np.linspace(l0.min(), l0.max(), 100)
    along = study.constants_at(grid)
    fig, axes = plt.subplots(2, 3, figsize=(11, 6.2))
    for ax, dep in zip(axes.ravel(), study.dependence):
        vals = np.array([base[m]["params"][dep.name]["value"] for m in study.muscles])
        ci = np.array([base[m]["params"][dep.name]["ci95_cluster"] for m in study.muscles])
        ax.errorbar(l0, vals, yerr=[vals - ci[:, 0], ci[:, 1] - vals], fmt="o", color="k",
                    ms=4, capsize=3, label="one fit per muscle (cluster 95 %)")
        ax.plot(grid, along[dep.name], color="tab:blue",
                label=f"constants {study.form} in l0")
        ax.set_title(f"{dep.name} [{dep.unit}]", fontsize=9)
        ax.set_xlabel("resting length l0 [mm]")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(f"Sárosi eq. 2.1 constants against l0 — best by CV: {study.best}", fontsize=10)
    fig.tight_layout()
    path = out / "constants_vs_l0.png"
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)
    return path


# ------------------------------------------------------------------------------------------
# report


def _g(x) -> str:
    return "—" if x is None else f"{x:.4g}"


def _pair(v) -> str:
    return f"[{_g(v[0])}, {_g(v[1])}]"


def _fmt_ci(c: dict) -> str:
    lo, hi = c.get("ci95") or (None, None)
    return f"{_g(c['value'])} [{_g(lo)}, {_g(hi)}] {c['unit']}"


def report(summary: dict) -> str:
    L = []
    s = summary
    L.append(f"Closing the loop on {s['file']} ({s['mode']} run)")
    L.append(f"{s['n_muscles_in_file']} muscles, {s['n_rows_in_file']} rows in the file; "
             f"diagnosed: {len(s['muscles'])} muscle(s), {s['n_rows_diagnosed']} rows")
    L.append("")
    L.append("1. Baseline: Sárosi eq. 2.1 per muscle")
    L.append(f"   {'muscle':<18} {'l0 [mm]':>7} {'n':>6} {'RMSE [N]':>9} {'max [N]':>8} "
             f"{'lag-1':>6}")
    for m, b in s["baseline"].items():
        L.append(f"   {m:<18} {b['l0_mm']:>7.0f} {b['n']:>6} {b['rmse_N']:>9.2f} "
                 f"{b['max_error_N']:>8.1f} {b['residual_lag1']:>6.2f}")
    L.append("")
    L.append("2. pamid.diagnose")
    head = (f"   {'fit':<22} {'selected':<50} {'RMSE':>6} {'→':>1} {'after':>6} "
            f"{'max':>6} {'→':>1} {'after':>6} {'CV':>6} {'→':>1} {'after':>6}")
    L.append(head)
    for label, d in [("pooled (all muscles)", s["diagnosis_pooled"]),
                     *[(m, d) for m, d in s["diagnosis_per_muscle"].items()]]:
        sel = ", ".join(e["effect"] for e in d["selected"]) or "—"
        L.append(f"   {label[:22]:<22} {sel[:50]:<50} {d['rmse_before_N']:>6.2f}   "
                 f"{d['rmse_after_N']:>6.2f} {d['max_error_before_N']:>6.1f}   "
                 f"{d['max_error_after_N']:>6.1f} {d['cv_rmse_before_N']:>6.2f}   "
                 f"{d['cv_rmse_after_N']:>6.2f}")
    L.append("   what the pooled selection is:")
    for e in s["diagnosis_pooled"]["selected"]:
        L.append(f"     {e['effect']}: {e['kind']}")
    for b in s.get("bookkeeping", []):
        L.append(f"     {b['column']} runs with time inside each trial: correlation with "
                 f"time_s {b['median_corr_with_time_s']:.5f} (median over {b['trials']} "
                 f"trials, min {b['min_corr_with_time_s']:.4f}); selecting it says the "
                 "residual changes with time since the trial began (the pressure program's "
                 "phase), not that the row number matters")
    L.append("   constants of the pooled selection (95 % Wald):")
    for c in s["diagnosis_pooled"]["constants"]:
        for eff, consts in c["effects"].items():
            L.append(f"     {c['muscle']}, {eff}: "
                     + "; ".join(f"{k} = {_fmt_ci(v)}" for k, v in consts.items()))
    L.append("   unexplained after the pooled selection: "
             + (", ".join(s["diagnosis_pooled"]["unexplained"]) or "nothing"))
    L.append("   first-step candidates (ΔBIC, CV RMSE, significant, why not):")
    for c in s["diagnosis_pooled"]["first_step_candidates"]:
        why = c["unphysical"] or ""
        L.append(f"     {c['effect']:<32} {c['delta_bic']:>10.0f} {c['cv_rmse']:>7.2f} "
                 f"{'yes' if c['significant'] else 'no ':>4}  {why[:90]}")
    L.append("")
    L.append("3. Residual by bin (RMSE [N]: before → pooled selection → per-muscle selection)")
    L.append(f"   {'level':>5} {'p bin [kPa]':>11} {'n':>6} {'before':>7} {'pooled':>7} "
             f"{'per-m.':>7} {'mean before':>11} {'mean after':>10}")
    for r in s["bins"]["by_level_and_pressure"]:
        L.append(f"   {r['level']:>5} {r['pressure_bin_kPa']:>11} {r['n']:>6} "
                 f"{r['rmse_before_N']:>7.2f} {r['rmse_after_pooled_N']:>7.2f} "
                 f"{r.get('rmse_after_per_muscle_N', float('nan')):>7.2f} "
                 f"{r['mean_before_N']:>11.2f} {r['mean_after_pooled_N']:>10.2f}")
    for key, label in (("by_time_since_step", "time since step [s]"), ("by_repeat", "repeat")):
        rows = s["bins"].get(key) or []
        if not rows:
            continue
        L.append(f"   {label:<22} {'n':>6} {'before':>7} {'pooled':>7} {'per-m.':>7} "
                 f"{'mean before':>11} {'mean after':>10}")
        col = "time_since_step_bin_s" if key == "by_time_since_step" else "repeat"
        for r in rows:
            L.append(f"   {str(r[col]):<22} {r['n']:>6} {r['rmse_before_N']:>7.2f} "
                     f"{r['rmse_after_pooled_N']:>7.2f} "
                     f"{r.get('rmse_after_per_muscle_N', float('nan')):>7.2f} "
                     f"{r['mean_before_N']:>11.2f} {r['mean_after_pooled_N']:>10.2f}")
    L.append("")
    ls = s["length_study"]
    L.append(f"4. Length study ({len(ls['muscles'])} muscles, l0 "
             f"{min(ls['l0_mm']):.0f}–{max(ls['l0_mm']):.0f} mm, {ls['n']} rows, CV on held-out "
             f"{ls['cv']}, {ls['n_folds']} folds)")
    L.append(f"   {'option':<14} {'k':>4} {'RMSE':>7} {'CV RMSE':>8} {'LOO-length':>10} "
             f"{'max':>7} {'BIC':>10}")
    for o in ls["options"]:
        loo = "—" if o["loo_length_rmse_N"] is None else f"{o['loo_length_rmse_N']:.2f}"
        L.append(f"   {o['name']:<14} {o['n_params']:>4} {o['rmse_N']:>7.2f} "
                 f"{o['cv_rmse_N']:>8.2f} {loo:>10} {o['max_error_N']:>7.1f} {o['bic']:>10.0f}")
    L.append(f"   smooth form chosen by CV: {ls['form']} (g = {ls['g_of_l0']}); best: {ls['best']}")
    L.append(f"   {'constant':<8} {'at l0_ref':>10} {'slope':>10} {'95 % (pooled fit)':>24} "
             f"{'95 % (cluster)':>24} {'95 % (across muscles)':>24}")
    for dep in ls["dependence"]:
        cl = dep["slope_ci95_cluster"]
        cl = "—" if cl is None else _pair(cl)
        L.append(f"   {dep['name']:<8} {dep['value']:>10.4g} {dep['slope']:>10.4g} "
                 f"{_pair(dep['slope_ci95']):>24} {cl:>24} "
                 f"{_pair(dep['slope_ci95_between']):>24}")
    L.append("   " + ls["verdict"])
    L.append("")
    L.append("5. What stays unexplained")
    for line in s["unexplained_text"]:
        L.append("   - " + line)
    return "\n".join(L)


def unexplained_text(s: dict) -> list[str]:
    d = s["diagnosis_pooled"]
    out = []
    kinds = [e["kind"] for e in d["selected"]]
    if not any(k == "library effect" for k in kinds):
        out.append("No library effect (hysteresis, transient, drift, softening, compliance, "
                   "sensor offset, temperature) was selected; those that lowered the BIC had "
                   "constants past a physical bound (see the candidate list) or did not "
                   "predict held-out trials better.")
    if any(k.startswith("bookkeeping") for k in kinds):
        out.append("The selection includes a bookkeeping column: it stands for time within "
                   "the trial, i.e. where in the up-and-down pressure program a sample lies, "
                   "and says that something that depends on the program's phase is missing "
                   "from eq. 2.1 — not what it is.")
    out.append(f"RMSE {d['rmse_before_N']:.2f} → {d['rmse_after_N']:.2f} N, max error "
               f"{d['max_error_before_N']:.0f} → {d['max_error_after_N']:.0f} N with the pooled "
               f"selection: {100 * (1 - d['rmse_after_N'] / d['rmse_before_N']):.0f} % of the "
               "RMSE is removed, the rest is not.")
    worst = max((r for r in s["bins"]["by_level_and_pressure"] if r["n"] >= MIN_BIN_ROWS),
                key=lambda r: r["rmse_after_pooled_N"])
    out.append(f"Largest RMSE left in a bin: level {worst['level']}, {worst['pressure_bin_kPa']}–"
               f"{worst['pressure_bin_kPa'] + PRESSURE_BIN_KPA:.0f} kPa: "
               f"{worst['rmse_after_pooled_N']:.1f} N (mean {worst['mean_after_pooled_N']:+.1f} N, "
               f"n = {worst['n']}).")
    tb = s["bins"].get("by_time_since_step") or []
    if tb:
        first, last = tb[0], tb[-1]
        out.append(f"Against time since the last step: RMSE after "
                   f"{first['rmse_after_pooled_N']:.1f} N in {first['time_since_step_bin_s']} s "
                   f"against {last['rmse_after_pooled_N']:.1f} N in "
                   f"{last['time_since_step_bin_s']} s (mean "
                   f"{first['mean_after_pooled_N']:+.1f} and "
                   f"{last['mean_after_pooled_N']:+.1f} N).")
    out.append("Covariates the residual still depends on (pooled): "
               + (", ".join(d["unexplained"]) or "none"))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DATA), help="the AARL 10 mm file")
    ap.add_argument("--out", default=str(ROOT / "experiments" / "out" / NAME))
    ap.add_argument("--quick", action="store_true",
                    help="2 muscles, 2200 rows each (length study: 6 muscles, 2200 rows each)")
    args = ap.parse_args(argv)
    data = Path(args.data)
    if not data.is_file():
        print(f"skipped: file absent ({data})")
        return 0
    t0 = time.perf_counter()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    bench = pamid.load_bench(data)
    per = QUICK_ROWS_PER_MUSCLE if args.quick else None
    chosen = [bench.muscles[0], bench.muscles[-1]] if args.quick else list(bench.muscles)
    diag_bench = subset(bench, chosen, per)
    def say(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)

    say(f"baseline fits of {len(chosen)} muscle(s)")
    base, _ = baseline(diag_bench)
    say("pamid.diagnose on all diagnosed muscles at once")
    d_all = pamid.diagnose(diag_bench)
    table = d_all.table.rename(columns={"residual_after_N": "residual_after_pooled_N"})
    per_muscle = {}
    after_own = []
    for m in chosen:
        say(f"pamid.diagnose on {m} alone")
        d_m = pamid.diagnose(subset(diag_bench, [m], per))
        per_muscle[m] = diagnosis_summary(d_m)
        after_own.append(d_m.table[["muscle", "source_row", "residual_after_N"]])
    own = pd.concat(after_own).rename(columns={"residual_after_N": "residual_after_per_muscle_N"})
    table = with_levels(table.merge(own, on=["muscle", "source_row"], how="left"))

    say("length study on every muscle")
    len_bench = diag_bench if len(chosen) == len(bench.muscles) else subset(bench, None, per)
    study = pamid.length_study(len_bench)

    pooled = diagnosis_summary(d_all)
    summary = {
        "file": str(data), "mode": "quick" if args.quick else "full",
        "command": "experiments/close_the_loop_aarl.py" + (" --quick" if args.quick else ""),
        "n_rows_in_file": len(bench.frame), "n_muscles_in_file": len(bench.muscles),
        "l0_mm": dict(bench.l0_mm), "muscles": chosen, "rows_per_muscle": per,
        "n_rows_diagnosed": len(diag_bench.frame),
        "baseline": base,
        "diagnosis_pooled": pooled,
        "diagnosis_per_muscle": per_muscle,
        "bookkeeping": [bookkeeping_reading(diag_bench.frame, e["effect"].split(":", 1)[1])
                        for e in pooled["selected"] if e["kind"].startswith("bookkeeping")
                        and e["effect"].split(":", 1)[1] in diag_bench.frame],
        "bins": bin_tables(table),
        "length_study": study.to_dict(),
    }
    summary["unexplained_text"] = unexplained_text(summary)
    plots = [plot_force_vs_pressure(table, base, out), plot_time_since_step(table, out),
             plot_repeat(table, out),
             plot_constants_vs_l0(study, base if len_bench is diag_bench else
                                  baseline(len_bench)[0], out)]
    summary["plots"] = [p.name for p in plots if p is not None]
    summary["seconds"] = time.perf_counter() - t0
    text = report(json_ready(summary))
    write_text_atomic(out / "report.txt", text + "\n")
    write_text_atomic(out / "summary.json", json.dumps(json_ready(summary), indent=2) + "\n")
    print(text)
    print(f"\nwrote {out}/summary.json, report.txt and {len(summary['plots'])} plots "
          f"({summary['seconds']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
