"""``pamid fit DATA --method mcmc``: posterior sampling from the command line.

:func:`~pamid._commands.mcmc_options.add_mcmc_arguments` adds the options to the
``fit`` parser (a light module: building the parser imports no sampler); :func:`run_mcmc_fit`
runs the sampler on a loaded bench file and returns the JSON payload (the shape of the
least-squares fit, each constant also with ``hdi95``, ``r_hat``, ``ess_bulk``) and the exit
code (0, or 1 when a muscle did not converge). Progress and warnings go to stderr, the
table to stdout unless ``--json``; with ``--out`` it writes ``fit.json``, per muscle (up to
``--max-plots``) a NetCDF file with the ArviZ groups and PNGs of the traces, the pair plot
of the constants and the posterior predictive against the data.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from ._common import stage
from .mcmc_options import add_mcmc_arguments  # noqa: F401 (its home before)


def format_mcmc_table(result) -> str:
    """Posterior mean, sd, 95% equal-tailed and HDI intervals, R-hat and bulk ESS of every
    constant and σ, beside the least-squares value and its Wald (and profile) interval."""
    lines = []
    profile = result.ls.ci95_profile
    for i, muscle in enumerate(result.muscles):
        head = f"muscle {muscle}" if muscle is not None else "muscle"
        status = "converged" if result.converged[i] else "NOT CONVERGED"
        tau = result.tau_steps[i].max()
        lines.append(
            f"{head}: n = {result.n[i]}, RMSE = {result.rmse_N[i]:.4g} N at the posterior "
            f"mean, {status} ({result.sampler}, {result.n_walkers} walkers × "
            f"{result.n_steps} steps, burn-in {result.burn_steps}, τ ≤ {tau:.0f} steps, "
            f"kept {result.kept_steps / tau:.0f} τ, acceptance {result.acceptance[i]:.2f})")
        cols = ["constant", "unit", "mean", "sd", "2.5%", "97.5%", "HDI low", "HDI high",
                "R-hat", "ESS bulk", "LS value", "Wald low", "Wald high"]
        if profile is not None:
            cols += ["profile low", "profile high"]
        rows = [cols]
        for j, name in enumerate(result.var_names):
            row = [name, result.var_units[name], f"{result.mean[i, j]:.6g}",
                   f"{result.sd[i, j]:.3g}", f"{result.eti95[i, j, 0]:.6g}",
                   f"{result.eti95[i, j, 1]:.6g}", f"{result.hdi95[i, j, 0]:.6g}",
                   f"{result.hdi95[i, j, 1]:.6g}", f"{result.r_hat[i, j]:.3f}",
                   f"{result.ess_bulk[i, j]:.0f}"]
            if j < len(result.param_names):
                row += [f"{result.ls.theta[i, j]:.6g}", f"{result.ls.ci95[i, j, 0]:.6g}",
                        f"{result.ls.ci95[i, j, 1]:.6g}"]
                if profile is not None:
                    row += [f"{profile[i, j, 0]:.6g}", f"{profile[i, j, 1]:.6g}"]
            else:
                s = (result.ls.sse[i] / max(result.ls.dof[i], 1)) ** 0.5
                row += [f"{s:.6g}", "", ""] + (["", ""] if profile is not None else [])
            rows.append(row)
        widths = [max(len(r[c]) for r in rows) for c in range(len(cols))]
        for r in rows:
            lines.append("  " + "  ".join(v.rjust(w) for v, w in zip(r, widths)))
        lines.append("")
    lines.append(f"mean, sd, 2.5%/97.5% (equal-tailed) and HDI: posterior, {result.likelihood} "
                 "likelihood, priors in the JSON output; R-hat with walkers as chains.")
    lines.append("LS value, Wald low/high: least squares with Wald-t intervals (σ: the "
                 "residual standard deviation s)" + ("; profile: profile-t intervals."
                                                    if profile is not None else "."))
    return "\n".join(lines)


def run_mcmc_fit(args, bench, bounds=None) -> tuple[dict, int]:
    """Sample the posterior for every muscle of ``bench``; returns (payload, exit code).

    ``args`` carries the ``fit`` options (model, json, out, seed, max_plots, solver,
    intervals, data) and those of :func:`add_mcmc_arguments`; ``bounds``: ``--bounds`` as
    :func:`pamid._commands._model.parse_bounds` reads it. Prints the table on stdout
    unless ``args.json``; the caller prints the JSON payload.
    """
    import jax

    from .._io import final_place, write_text_atomic
    from .._report._mcmc import save_netcdf, write_mcmc_plots
    from .._sampling._mcmc import fit_mcmc

    quiet = bool(getattr(args, "json", False))
    t0 = time.perf_counter()
    requested = tuple(s.strip() for s in getattr(args, "intervals", "wald").split(",")
                      if s.strip())
    ls_intervals = tuple(k for k in requested if k in ("wald", "profile")) or ("wald",)
    if "bootstrap" in requested or getattr(args, "bootstrap", 0):
        stage("the bootstrap is not run with --method mcmc (the posterior replaces it)", quiet)
    stage(f"sampling the posterior ({args.likelihood} likelihood, {args.walkers} walkers, "
           f"up to {args.max_steps} steps, sampler {args.sampler}; least-squares start and "
           f"intervals: {', '.join(ls_intervals)})", quiet)
    result = fit_mcmc(
        bench,
        args.model,
        key=jax.random.key(getattr(args, "seed", 0)),
        n_walkers=args.walkers,
        max_steps=args.max_steps,
        thin=args.thin,
        likelihood=args.likelihood,
        nu=args.nu,
        sampler=args.sampler,
        progress=(not quiet) and sys.stderr.isatty(),
        solver=getattr(args, "solver", "gauss-newton"),
        ls_intervals=ls_intervals,
        bounds=bounds,
    )
    payload = result.to_dict()
    payload["source"] = str(getattr(args, "data", bench.path))
    payload["n_censored_dropped"] = bench.n_censored
    if getattr(args, "out", None):
        out = Path(args.out)
        n_files = min(getattr(args, "max_plots", 6), result.n_muscles)
        stage(f"writing NetCDF and plots for {n_files} of {result.n_muscles} muscle(s) "
               f"to {final_place(out)}", quiet)
        owners: dict = {}
        payload["netcdf"] = save_netcdf(result, out, muscles=range(n_files), owners=owners)
        payload["plots"] = write_mcmc_plots(result, bench, out, n_files, owners=owners)
        payload["muscle_of_file"] = owners
    payload["seconds"] = round(time.perf_counter() - t0, 3)
    if getattr(args, "out", None):
        write_text_atomic(Path(args.out) / "fit.json", json.dumps(payload, indent=2) + "\n")
    if not quiet:
        print(format_mcmc_table(result))
        if not result.converged.all():
            bad = [m for m, ok in zip(result.muscles, result.converged) if not ok]
            print(f"WARNING: {len(bad)} muscle(s) did not converge: {bad[:10]}")
    return payload, 0 if result.converged.all() else 1
