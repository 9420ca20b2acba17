#!/usr/bin/env python
"""Least-squares intervals (Wald, profile) beside posterior intervals (MCMC), per constant.

Three data sets, Sárosi's eq. 2.1:

* ``synthetic-2N``: the virtual bench at Sárosi's protocol (5 pressures, 30 points per sweep,
  both directions, five 2 N readings averaged), truth = Table 3-1: the test suite's design.
* ``synthetic-21.5N``: the same with 21.5 N per reading, the noise at which the fit's R
  matches the R = 0.9996 the summary reports (experiments/README.md, section 1). The model
  is less linear over a wider posterior, so Wald, profile and posterior may differ more.
* ``martens``: the measured DMSP-10-250 map in ``../shared/data`` (40 points after the
  censored rows are dropped; dof 34).

For each: least squares with Wald-t and profile-t intervals; the posterior (documented
weakly informative priors, normal likelihood, noise σ sampled) from pamid's stacked
ensembles run until 50 autocorrelation times are kept; its mean, 95% equal-tailed interval
(ETI) and 95% HDI; widths relative to Wald; R-hat and bulk ESS. For the synthetic sets,
which interval holds the truth. Also the posterior of Martens' constants under the
Student-t likelihood (ν = 4), as a check of sensitivity to the noise model.

    .venv/bin/python experiments/ls_vs_mcmc.py [--out DIR] [--data CSV] [--seed N]

Writes ``ls_vs_mcmc.json`` (every number), ``intervals.png`` (all intervals of every
constant, centred on the least-squares value and scaled by the Wald half-width),
``martens_pair.png`` and ``martens_predictive.png`` to ``experiments/out/ls_vs_mcmc/``.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path

import jax
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import pamid  # noqa: E402
from pamid import fit_mcmc  # noqa: E402
from pamid.io import save_figure_atomic, write_text_atomic  # noqa: E402

NAME = "ls_vs_mcmc"
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "martens_dmsp10_250.csv"
SEED = 20261121
NAMES = ("a1", "a2", "a3", "a4", "a5", "a6")
KINDS = ("wald", "profile", "eti", "hdi")
COLORS = {"wald": "tab:blue", "profile": "tab:cyan", "eti": "tab:red", "hdi": "tab:orange"}


def synthetic(noise_sd, seed):
    theta = np.asarray(pamid.sarosi.table_3_1().to_vector())
    protocol = pamid.SarosiProtocol(min_force_N=10.0, noise_sd_N=noise_sd)
    frame = pamid.simulate_sarosi_bench(jax.random.key(seed), pamid.Sarosi.from_vector(theta),
                                        protocol)
    data = pamid.pack_muscles([((frame["pressure_kPa"].to_numpy() / 100.0,
                                 frame["contraction_pct"].to_numpy()),
                                frame["force_N"].to_numpy())])
    return data, theta


def compare(name, data, key, truth=None, likelihood="normal"):
    r = fit_mcmc(data, key=key, ls_intervals=("wald", "profile"), likelihood=likelihood,
                 progress=False)
    ls = r.ls
    rows = []
    for j, c in enumerate(NAMES):
        iv = {"wald": ls.ci95[0, j], "profile": ls.ci95_profile[0, j], "eti": r.eti95[0, j],
              "hdi": r.hdi95[0, j]}
        wald_w = iv["wald"][1] - iv["wald"][0]
        row = {
            "constant": c, "unit": r.param_units[c],
            "ls_value": float(ls.theta[0, j]), "wald_se": float(ls.se[0, j]),
            "posterior_mean": float(r.mean[0, j]), "posterior_sd": float(r.sd[0, j]),
            **{f"{k}95": [float(v) for v in iv[k]] for k in KINDS},
            **{f"{k}_width_over_wald": float((iv[k][1] - iv[k][0]) / wald_w)
               for k in KINDS[1:]},
            "mean_shift_over_se": float((r.mean[0, j] - ls.theta[0, j]) / ls.se[0, j]),
            "r_hat": float(r.r_hat[0, j]), "ess_bulk": float(r.ess_bulk[0, j]),
        }
        if truth is not None:
            row["truth"] = float(truth[j])
            row["covers_truth"] = {k: bool(iv[k][0] <= truth[j] <= iv[k][1]) for k in KINDS}
        rows.append(row)
    s_ls = float(np.sqrt(ls.sse[0] / ls.dof[0]))
    sigma = {"ls_s": s_ls, "posterior_mean": float(r.mean[0, 6]),
             "eti95": [float(v) for v in r.eti95[0, 6]], "hdi95": [float(v) for v in r.hdi95[0, 6]],
             "r_hat": float(r.r_hat[0, 6]), "ess_bulk": float(r.ess_bulk[0, 6])}
    run = {"steps": r.n_steps, "burn_in": r.burn_steps, "walkers": r.n_walkers,
           "tau_max_steps": float(r.tau_steps.max()), "converged": bool(r.converged[0]),
           "acceptance": float(r.acceptance[0]), "seconds": round(r.seconds, 2),
           "n": int(r.n[0]), "dof": int(ls.dof[0]), "likelihood": likelihood}
    return {"name": name, "rows": rows, "sigma": sigma, "run": run}, r


def print_table(res):
    run = res["run"]
    print(f"\n{res['name']}  (n = {run['n']}, dof {run['dof']}; {run['likelihood']} likelihood; "
          f"{run['walkers']} walkers × {run['steps']} steps, burn-in {run['burn_in']}, "
          f"τ ≤ {run['tau_max_steps']:.0f}, converged {run['converged']}, "
          f"{run['seconds']:.1f} s)")
    head = ["", "LS value", "Wald 95%", "profile 95%", "post. mean", "ETI 95%", "HDI 95%",
            "prof/W", "ETI/W", "HDI/W", "shift/se", "R-hat", "ESS"]
    has_truth = "truth" in res["rows"][0]
    if has_truth:
        head += ["truth", "covered W/P/E/H"]
    table = [head]
    for r in res["rows"]:
        iv = lambda k: f"({r[k + '95'][0]:.5g}, {r[k + '95'][1]:.5g})"  # noqa: E731
        line = [r["constant"], f"{r['ls_value']:.6g}", iv("wald"), iv("profile"),
                f"{r['posterior_mean']:.6g}", iv("eti"), iv("hdi"),
                f"{r['profile_width_over_wald']:.3f}", f"{r['eti_width_over_wald']:.3f}",
                f"{r['hdi_width_over_wald']:.3f}", f"{r['mean_shift_over_se']:+.3f}",
                f"{r['r_hat']:.3f}", f"{r['ess_bulk']:.0f}"]
        if has_truth:
            cov = r["covers_truth"]
            line += [f"{r['truth']:.6g}", "/".join("y" if cov[k] else "n" for k in KINDS)]
        table.append(line)
    sg = res["sigma"]
    table.append(["σ [N]", f"{sg['ls_s']:.4g}", "", "", f"{sg['posterior_mean']:.4g}",
                  f"({sg['eti95'][0]:.4g}, {sg['eti95'][1]:.4g})",
                  f"({sg['hdi95'][0]:.4g}, {sg['hdi95'][1]:.4g})", "", "", "", "",
                  f"{sg['r_hat']:.3f}", f"{sg['ess_bulk']:.0f}"] + (["", ""] if has_truth else []))
    widths = [max(len(row[i]) for row in table) for i in range(len(head))]
    for row in table:
        print("  " + "  ".join(v.rjust(w) for v, w in zip(row, widths)))


def plot_intervals(results, path):
    fig, axes = plt.subplots(1, len(results), figsize=(4.2 * len(results), 6.0), sharey=True)
    axes = np.atleast_1d(axes)
    for ax, res in zip(axes, results):
        for j, r in enumerate(res["rows"]):
            hw = 0.5 * (r["wald95"][1] - r["wald95"][0])
            for k_i, k in enumerate(KINDS):
                lo, hi = ((np.asarray(r[k + "95"]) - r["ls_value"]) / hw)
                yy = j + (k_i - 1.5) * 0.17
                ax.plot([lo, hi], [yy, yy], "-", color=COLORS[k], lw=3,
                        label=k if j == 0 else None)
            ax.plot((r["posterior_mean"] - r["ls_value"]) / hw, j + 0.26, "v", color="k",
                    ms=4, label="posterior mean" if j == 0 else None)
            if "truth" in r:
                ax.plot((r["truth"] - r["ls_value"]) / hw, j - 0.35, "*", color="tab:green",
                        ms=8, label="truth" if j == 0 else None)
        ax.axvline(0.0, color="0.5", lw=0.8)
        ax.set_title(res["name"], fontsize=10)
        ax.set_xlabel("(interval − LS value) / Wald half-width")
        ax.grid(alpha=0.3, axis="x")
    axes[0].set_yticks(range(len(NAMES)), NAMES)
    axes[0].invert_yaxis()
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8)
    fig.suptitle("95% intervals of Sárosi's constants: least squares (Wald, profile) and "
                 "posterior (ETI, HDI)", fontsize=11)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent / "out" / NAME)
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--seed", type=int, default=SEED)
    args = ap.parse_args(argv)
    t0 = time.time()
    args.out.mkdir(parents=True, exist_ok=True)
    key = jax.random.key(args.seed)
    results = []

    for i, (label, noise) in enumerate((("synthetic-2N", 2.0), ("synthetic-21.5N", 21.5))):
        data, truth = synthetic(noise, seed=args.seed + i)
        res, _ = compare(label, data, jax.random.fold_in(key, i), truth)
        results.append(res)
        print_table(res)

    martens = None
    if args.data.is_file():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", pamid.CensoredRowsWarning)
            bench = pamid.load_bench(args.data)
        res, martens = compare("martens", bench, jax.random.fold_in(key, 10))
        results.append(res)
        print_table(res)
        res_t, _ = compare("martens-student-t", bench, jax.random.fold_in(key, 11),
                           likelihood="student-t")
        print_table(res_t)
        pamid.report.plot_pair(martens, 0, args.out / "martens_pair.png",
                               "Posterior of Sárosi's constants — Martens DMSP-10-250")
        pamid.report.plot_predictive(martens, 0, args.out / "martens_predictive.png",
                                     "Posterior predictive — Martens DMSP-10-250")
    else:
        res_t = None
        print(f"\n{args.data} not found: the measured data set is skipped.")

    plot_intervals(results, args.out / "intervals.png")
    payload = {"experiment": NAME, "seed": args.seed, "results": results,
               "martens_student_t": res_t, "seconds": round(time.time() - t0, 1)}
    write_text_atomic(args.out / f"{NAME}.json", json.dumps(payload, indent=2) + "\n")
    print(f"\nwritten to {args.out}/ ({payload['seconds']} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
