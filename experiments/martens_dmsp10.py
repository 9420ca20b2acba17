#!/usr/bin/env python
"""Sárosi's model fitted to a measured force map: Festo DMSP-10-250 (Martens & Boblan 2017).

Data: ``shared/data/martens_dmsp10_250.csv`` next to the repository (17 pressures × 5 lengths;
a force of exactly 0 marks a length the muscle cannot hold and is dropped as censored).
The script fits eq. 2.1 with pamid (Wald, profile and curve-bootstrap intervals), shows the
residual against contraction and pressure, and compares pamid's constants with the DMSP-10
constants quoted in the data README (fitted by others to a different muscle of the type).
It does not tune the model: the residual is reported as it is.

    .venv/bin/python experiments/martens_dmsp10.py [--out DIR] [--data CSV]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

import jax
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

import pamid  # noqa: E402
from pamid.io import save_figure_atomic, write_text_atomic  # noqa: E402

NAME = "martens_dmsp10"
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "martens_dmsp10_250.csv"
NAMES = ("a1", "a2", "a3", "a4", "a5", "a6")
UNITS = ("N/bar", "N", "1/%", "N/(bar·%)", "N/bar", "N")
QUOTED = np.array([-9.2194029, 203.7012413, -0.34221042, -3.2255991, 109.2038216, -208.372034])
SEED = 20261121


def rmse(r):
    return float(np.sqrt(np.mean(np.square(r))))


def residual_structure(p_bar, kappa, res):
    """Mean and RMS of the residual per contraction level, and its dependence on pressure
    within each level (a quadratic in p: eq. 2.1 is affine in p at fixed κ)."""
    rows = []
    for kv in np.unique(kappa):
        m = kappa == kv
        row = {
            "kappa_pct": float(kv),
            "n": int(m.sum()),
            "mean_N": float(res[m].mean()),
            "rms_N": rmse(res[m]),
            "min_N": float(res[m].min()),
            "max_N": float(res[m].max()),
        }
        if m.sum() >= 4:
            c = np.polyfit(p_bar[m], res[m], 2)
            fitted = np.polyval(c, p_bar[m])
            ss = np.sum((res[m] - res[m].mean()) ** 2)
            row["quadratic_in_p_N_per_bar2"] = float(c[0])
            row["share_of_residual_variance_explained_by_quadratic_in_p"] = (
                float(1 - np.sum((res[m] - fitted) ** 2) / ss) if ss > 0 else None
            )
        rows.append(row)
    return rows


def per_pressure(theta, p_bar, kappa, res):
    """Mean residual per pressure level and the pressure offset (actual − nominal) that
    would explain it (−mean residual / ∂F/∂p), plus the share of the residual sum of squares
    that the level means carry (levels with at least 2 points)."""
    prm = pamid.Sarosi.from_vector(theta)
    dfdp = np.asarray(
        jax.vmap(jax.grad(lambda p, k: pamid.sarosi.sarosi_force(prm, p, k)))(
            jax.numpy.asarray(p_bar), jax.numpy.asarray(kappa)
        )
    )  # N/bar
    rows, ss_between, ss_total = [], 0.0, 0.0
    for pv in np.unique(p_bar):
        m = p_bar == pv
        mean = float(res[m].mean())
        rows.append(
            {
                "pressure_kPa": float(pv * 100),
                "n": int(m.sum()),
                "mean_residual_N": mean,
                "spread_within_N": float(np.ptp(res[m])),
                "pressure_offset_kPa": float(-mean / dfdp[m].mean() * 100),
            }
        )
        if m.sum() >= 2:
            ss_between += m.sum() * mean**2
            ss_total += float(np.sum(res[m] ** 2))
    return rows, ss_between / ss_total


def sign_runs(res_sorted):
    s = np.sign(res_sorted)
    s = s[s != 0]
    return int(1 + np.sum(s[1:] != s[:-1])), int(len(s))


def plot_data_vs_model(frame, censored, theta, path):
    fig, axes = plt.subplots(1, 2, figsize=(14, 6), constrained_layout=True, sharey=True)
    pressures = np.unique(np.concatenate([frame["pressure_kPa"], censored["pressure_kPa"]]))
    cmap = plt.cm.viridis
    norm = matplotlib.colors.Normalize(pressures.min(), pressures.max())
    kk = np.linspace(0, 21, 300)
    for ax, (label, th) in zip(
        axes, (("pamid fit to this map", theta), ("constants quoted in the data README", QUOTED))
    ):
        prm = pamid.Sarosi.from_vector(th)
        for p_kpa in pressures:
            c = cmap(norm(p_kpa))
            g = frame[frame["pressure_kPa"] == p_kpa]
            ax.plot(g["contraction_pct"], g["force_N"], "o", color=c, ms=6)
            f = np.asarray(pamid.sarosi.sarosi_force(prm, p_kpa / 100, kk))
            ax.plot(kk, np.where(f > -60, f, np.nan), "-", color=c, lw=1)
        ax.plot(
            censored["contraction_pct"],
            censored["force_N"],
            "x",
            color="gray",
            ms=6,
            label="censored (F = 0 in the table: length not holdable)",
        )
        ax.plot([], [], "o", color="k", label="measured (Martens & Boblan 2017, table A2)")
        ax.plot([], [], "-", color="k", lw=1, label="Sárosi eq. 2.1")
        ax.set_title(f"DMSP-10-250: data vs model — {label}")
        ax.set_xlabel("contraction κ [%] (l0 = 250 mm)")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylim(-60, 600)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    axes[0].set_ylabel("force F [N]")
    sm = plt.cm.ScalarMappable(norm=norm, cmap=cmap)
    fig.colorbar(sm, ax=axes, label="gauge pressure p [kPa]", shrink=0.9)
    save_figure_atomic(fig, path, dpi=130)
    plt.close(fig)


def plot_residuals(p_kpa, kappa, res_fit, res_quoted, path):
    fig, axes = plt.subplots(2, 2, figsize=(13, 8.5), constrained_layout=True)
    for row, (res, label) in enumerate(((res_fit, "pamid fit"), (res_quoted, "quoted constants"))):
        ax = axes[row, 0]
        sc = ax.scatter(kappa, res, c=p_kpa, cmap="viridis", s=30)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlabel("contraction κ [%]")
        ax.set_ylabel("residual F_model − F_measured [N]")
        ax.set_title(f"{label}: residual vs contraction (RMSE {rmse(res):.2f} N)")
        fig.colorbar(sc, ax=ax, label="pressure p [kPa]")
        ax.grid(alpha=0.3)
        ax = axes[row, 1]
        sc = ax.scatter(p_kpa, res, c=kappa, cmap="plasma", s=30)
        for kv in np.unique(kappa):
            m = kappa == kv
            o = np.argsort(p_kpa[m])
            ax.plot(p_kpa[m][o], res[m][o], "-", lw=0.6, color=plt.cm.plasma(kv / kappa.max()))
        ax.axhline(0, color="k", lw=0.6)
        ax.set_xlabel("gauge pressure p [kPa]")
        ax.set_ylabel("residual F_model − F_measured [N]")
        ax.set_title(f"{label}: residual vs pressure (lines join equal κ)")
        fig.colorbar(sc, ax=ax, label="contraction κ [%]")
        ax.grid(alpha=0.3)
    save_figure_atomic(fig, path, dpi=130)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "out" / NAME)
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--n-bootstrap", type=int, default=1000)
    args = ap.parse_args(argv)
    if not args.data.is_file():
        print(f"{NAME}: data file {args.data} not found; skipping (nothing to do).")
        return 0
    t0 = time.time()
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", pamid.CensoredRowsWarning)
        bench = pamid.load_bench(args.data)
    messages = [str(w.message) for w in caught if issubclass(w.category, pamid.CensoredRowsWarning)]
    raw = pd.read_csv(args.data)
    censored = raw[raw["force_N"] == 0]
    frame = bench.frame
    n_rows = len(raw)
    fd = pamid.bench_to_fit_data(bench)
    curve = np.asarray(fd.curve[0])
    n_curves = int(curve.max()) + 1
    pts_per_curve = np.bincount(curve[curve >= 0])

    fit = pamid.fit_least_squares(
        bench,
        intervals=("wald", "profile", "bootstrap"),
        n_bootstrap=args.n_bootstrap,
        key=jax.random.key(SEED),
    )
    theta = fit.theta[0]
    p_kpa = frame["pressure_kPa"].to_numpy()
    p_bar = p_kpa / 100.0
    kappa = frame["contraction_pct"].to_numpy()
    force = frame["force_N"].to_numpy()
    force_of = pamid.sarosi.sarosi_force
    res_fit = np.asarray(force_of(pamid.Sarosi.from_vector(theta), p_bar, kappa)) - force
    res_q = np.asarray(force_of(pamid.Sarosi.from_vector(QUOTED), p_bar, kappa)) - force
    r_q = float(np.corrcoef(force, res_q + force)[0, 1])

    # Censored rows: a muscle that cannot hold the length should have a model force ≤ 0 there.
    pc = censored["pressure_kPa"].to_numpy() / 100
    kc = censored["contraction_pct"].to_numpy()
    f_cens_fit = np.asarray(pamid.sarosi.sarosi_force(pamid.Sarosi.from_vector(theta), pc, kc))
    f_cens_q = np.asarray(pamid.sarosi.sarosi_force(pamid.Sarosi.from_vector(QUOTED), pc, kc))

    print(f"Martens & Boblan DMSP-10-250 force map: {args.data}")
    print(
        f"rows {n_rows}, censored (F = 0) dropped {bench.n_censored}, fitted {len(frame)}"
        + (f"  [loader: {messages[0]}]" if messages else "")
    )
    print(
        f"curves (pressure levels with data) {n_curves}; points per curve "
        f"{sorted(pts_per_curve.tolist())}; contraction levels "
        + ", ".join(f"{k:g} % ({int((kappa == k).sum())})" for k in np.unique(kappa))
    )
    print(
        f"pamid fit: RMSE {fit.rmse_N[0]:.3f} N, R = {fit.r[0]:.6f}, dof {int(fit.dof[0])}, "
        f"converged {bool(fit.converged[0])}, profile ok {bool(np.all(fit.profile_ok[0]))}, "
        f"bootstrap: {n_curves} curves resampled, {args.n_bootstrap} replicates, "
        f"{fit.bootstrap_converged[0]:.1%} converged"
    )
    print(
        f"quoted DMSP-10 constants on this map: RMSE {rmse(res_q):.2f} N, R = {r_q:.5f}, "
        f"max |residual| {np.abs(res_q).max():.1f} N, mean residual {res_q.mean():+.1f} N"
    )
    print()
    hdr = (
        f"{'':3} {'unit':10} {'pamid':>11} {'Wald 95% CI':>24} {'profile 95% CI':>24} "
        f"{'bootstrap 95% CI':>24} {'quoted':>11} {'(q-θ̂)/se':>9}  quoted inside"
    )
    print(hdr)
    comp = []
    digits = (3, 2, 4, 4, 2, 2)
    for j, nm in enumerate(NAMES):
        d = digits[j]
        ivs = {
            "wald": fit.ci95[0, j],
            "profile": fit.ci95_profile[0, j],
            "bootstrap": fit.ci95_bootstrap[0, j],
        }
        inside = [k for k, (lo, hi) in ivs.items() if lo <= QUOTED[j] <= hi]
        z = (QUOTED[j] - theta[j]) / fit.se[0, j]
        print(
            f"{nm:3} {UNITS[j]:10} {theta[j]:11.{d}f} "
            + " ".join(f"{'(' + f'{lo:.{d}f}, {hi:.{d}f}' + ')':>24}" for lo, hi in ivs.values())
            + f" {QUOTED[j]:11.{d}f} {z:9.1f}  {', '.join(inside) if inside else 'none'}"
        )
        comp.append(
            {
                "name": nm,
                "unit": UNITS[j],
                "pamid": float(theta[j]),
                "se": float(fit.se[0, j]),
                **{f"{k}_ci95": [float(v) for v in iv] for k, iv in ivs.items()},
                "quoted": float(QUOTED[j]),
                "quoted_minus_pamid_in_se": float(z),
                "quoted_inside": inside,
            }
        )
    print()

    struct = residual_structure(p_bar, kappa, res_fit)
    print("pamid residual (model − measured) by contraction level:")
    print(
        f"  {'κ [%]':>6} {'n':>3} {'mean [N]':>9} {'RMS [N]':>8} {'min':>7} {'max':>7} "
        f"{'quadratic-in-p share':>20}"
    )
    for r in struct:
        share = r.get("share_of_residual_variance_explained_by_quadratic_in_p")
        print(
            f"  {r['kappa_pct']:6.1f} {r['n']:3d} {r['mean_N']:9.3f} {r['rms_N']:8.3f} "
            f"{r['min_N']:7.2f} {r['max_N']:7.2f} "
            f"{f'{share:.2f}' if share is not None else '-':>20}"
        )
    levels, share_levels = per_pressure(theta, p_bar, kappa, res_fit)
    print("pamid residual by pressure level (levels with 2–4 points):")
    print(
        f"  {'p [kPa]':>8} {'n':>2} {'mean [N]':>9} {'within-level range [N]':>22} "
        f"{'offset actual−nominal p [kPa]':>30}"
    )
    for r in levels:
        if r["n"] >= 2:
            print(
                f"  {r['pressure_kPa']:8.2f} {r['n']:2d} {r['mean_residual_N']:9.3f} "
                f"{r['spread_within_N']:22.3f} {r['pressure_offset_kPa']:30.2f}"
            )
    print(f"  share of the residual sum of squares carried by the level means: {share_levels:.2f}")
    m0 = kappa == 0
    runs_p, n_p = sign_runs(res_fit[m0][np.argsort(p_kpa[m0])])
    print(
        f"  κ = 0 row ordered by pressure: {runs_p} sign runs in {n_p} residuals "
        f"(independent noise would give about {1 + (n_p - 1) / 2:.0f})"
    )
    i_max = int(np.argmax(f_cens_fit))
    print(
        f"censored rows: pamid's model predicts F > 10 N at {int((f_cens_fit > 10).sum())} of "
        f"{len(pc)} (max {f_cens_fit.max():.1f} N at p = {pc[i_max] * 100:g} kPa, "
        f"κ = {kc[i_max]:g} %); quoted constants at "
        f"{int((f_cens_q > 10).sum())} (max {f_cens_q.max():.1f} N)"
    )
    print(f"runtime {time.time() - t0:.1f} s; outputs in {out}")

    plot_data_vs_model(frame, censored, theta, out / "data_vs_model.png")
    plot_residuals(p_kpa, kappa, res_fit, res_q, out / "residuals.png")
    result = {
        "experiment": NAME,
        "date": "2026-11-21",
        "data": str(args.data),
        "rows": n_rows,
        "censored_dropped": int(bench.n_censored),
        "fitted_rows": int(len(frame)),
        "curves": n_curves,
        "points_per_curve": pts_per_curve.tolist(),
        "fit": fit.to_dict(),
        "bootstrap_replicates": args.n_bootstrap,
        "bootstrap_converged_fraction": float(fit.bootstrap_converged[0]),
        "quoted_constants": {
            "values": QUOTED.tolist(),
            "rmse_N": rmse(res_q),
            "r": r_q,
            "max_abs_residual_N": float(np.abs(res_q).max()),
            "mean_residual_N": float(res_q.mean()),
        },
        "comparison": comp,
        "residual_by_contraction": struct,
        "kappa0_sign_runs": {"runs": runs_p, "n": n_p},
        "residual_by_pressure": levels,
        "share_of_residual_ss_in_pressure_level_means": share_levels,
        "censored_check": {
            "pamid_predicts_above_10N": int((f_cens_fit > 10).sum()),
            "pamid_max_N": float(f_cens_fit.max()),
            "quoted_predicts_above_10N": int((f_cens_q > 10).sum()),
            "quoted_max_N": float(f_cens_q.max()),
            "n_censored": int(len(pc)),
        },
        "residuals": [
            {
                "pressure_kPa": float(a),
                "contraction_pct": float(b),
                "force_N": float(c),
                "residual_fit_N": float(d),
                "residual_quoted_N": float(e),
            }
            for a, b, c, d, e in zip(p_kpa, kappa, force, res_fit, res_q)
        ],
        "runtime_s": time.time() - t0,
    }
    write_text_atomic(out / f"{NAME}.json", json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
