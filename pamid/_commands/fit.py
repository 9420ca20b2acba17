"""``pamid fit DATA``: a static force model fitted to every muscle of a bench file, with its
intervals, as a table, JSON (``--json``) or fit.json and plots (``--out``); ``--method mcmc``
samples the posterior instead (:mod:`pamid._commands.mcmc`). Exit 0 when every muscle's fit
converged, 1 when one did not, 2 for bad input."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

from ._common import stage

#: ``--solver``'s choices: the names of :data:`pamid._solvers.SOLVER_CLASSES`.
SOLVER_NAMES = ("gauss-newton", "levenberg-marquardt", "variable-projection",
                "jaxopt-levenberg-marquardt", "projected-levenberg-marquardt")

def register(subparsers) -> None:
    fit = subparsers.add_parser(
        "fit", help="fit a static force model to bench data (CSV, Parquet or .xlsx)")
    fit.add_argument("data", help="bench file: pressure_kPa|bar|Pa|psi, force_N, contraction_pct "
                                  "or length_mm (+ l0_mm), optional muscle, trial, direction, …")
    from ._model import add_bounds_argument, add_model_argument

    add_model_argument(fit)
    add_bounds_argument(fit)
    fit.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    fit.add_argument("--out", help="folder for plots (PNG) and fit.json")
    # The names of SOLVER_CLASSES (pamid._solvers), written out: the parser is built for
    # every command, and importing the solvers imports JAX (tests/test_solvers.py checks
    # that the two lists agree).
    fit.add_argument("--solver", default="gauss-newton", choices=SOLVER_NAMES)
    fit.add_argument("--intervals", default="wald,profile",
                     help="comma-separated: wald, profile, bootstrap, cluster (holds under "
                          "residuals correlated within curves), hac (default wald,profile)")
    fit.add_argument("--bootstrap", type=int, default=0, metavar="B",
                     help="also bootstrap whole curves with B replicates per muscle")
    fit.add_argument("--seed", type=int, default=0, help="PRNG seed for the bootstrap and MCMC")
    from ._common import Positive

    fit.add_argument("--stream", action="store_true",
                     help="a Parquet file bigger than memory: read and fit it a chunk of "
                          "whole muscles at a time (each muscle's rows together), keeping "
                          "only the constants: --out gets constants.parquet (one row per "
                          "muscle), fit_stream.json and rmse_histogram.png")
    fit.add_argument("--chunk-rows", type=int, action=Positive, default=1_000_000,
                     metavar="N", help="--stream: rows per chunk (default 1,000,000; whole "
                                       "muscles, so a chunk may hold more)")
    from ._common import NonNegative

    fit.add_argument("--max-plots", type=int, action=NonNegative, default=6,
                     help="muscles to plot (default 6)")
    from . import fit_processes
    from ._reading import add_reading_arguments
    from .mcmc_options import add_mcmc_arguments

    fit_processes.add_arguments(fit)
    add_reading_arguments(fit)
    add_mcmc_arguments(fit)
    fit.set_defaults(func=run, prepare=prepare, before_jax=fit_processes.start, outputs=(
        "fit.json", "fit_*.png", "residuals_*.png", "rmse_histogram.png", "mcmc_*.nc",
        "mcmc_*.nc3", "mcmc_*.png", "constants.parquet", "fit_stream.json"))


def fit_table(result, published=None) -> str:
    """Constants with the 95% interval each muscle shows (Wald's, or the cluster interval
    where its residual is correlated: ``FitResult.shown_of``), then Wald's where another is
    shown, and profile/bootstrap/cluster/HAC/published where present."""
    import numpy as np

    lines = []
    shown_ci, _ = result.shown_intervals()
    labels = {"wald-t": "95%", "cluster": "cluster", "hac": "HAC"}
    for i, muscle in enumerate(result.muscles):
        status = result.status_of(i) if result.converged[i] else \
            f"NOT CONVERGED: {result.status_of(i)}"
        head = f"muscle {muscle}" if muscle is not None else "muscle"
        lines.append(
            f"{head}: n = {result.n[i]}, RMSE = {result.rmse_N[i]:.4g} N, "
            f"R = {result.r[i]:.6f}, {status} ({result.n_steps[i]} steps, {result.solver})"
        )
        if result.message(i):
            lines.append(f"  why: {result.message(i)}")
        if i < len(result.interval_notes) and result.interval_notes[i]:
            lines.append(f"  intervals: {result.interval_notes[i]}")
        shown = result.shown_of(i)
        cols = ["constant", "unit", "value", f"{labels[shown]} low", f"{labels[shown]} high"]
        if shown != "wald-t":
            cols += ["Wald low", "Wald high"]
        if result.ci95_profile is not None:
            cols += ["profile low", "profile high"]
        if result.ci95_bootstrap is not None:
            cols += ["bootstrap low", "bootstrap high"]
        # (an interval computed for other muscles only, not this one: not a column of NaN)
        extra = [(label, ci) for label, ci in (("cluster", result.ci95_cluster),
                                               ("HAC", result.ci95_hac))
                 if ci is not None and label != labels[shown] and not np.all(np.isnan(ci[i]))]
        cols += [f"{label} {end}" for label, _ in extra for end in ("low", "high")]
        if published is not None:
            cols += ["published", "pub. low", "pub. high"]
        rows = [cols]
        for j, name in enumerate(result.param_names):
            row = [name, result.param_units[name], f"{result.theta[i, j]:.6g}",
                   f"{shown_ci[i, j, 0]:.6g}", f"{shown_ci[i, j, 1]:.6g}"]
            if shown != "wald-t":
                row += [f"{result.ci95[i, j, 0]:.6g}", f"{result.ci95[i, j, 1]:.6g}"]
            for ci in (result.ci95_profile, result.ci95_bootstrap, *(c for _, c in extra)):
                if ci is not None:
                    row += [f"{ci[i, j, 0]:.6g}", f"{ci[i, j, 1]:.6g}"]
            if published is not None:
                pub = published[name]
                row += [f"{pub['value']:.6g}", f"{pub['ci95'][0]:.6g}", f"{pub['ci95'][1]:.6g}"]
            rows.append(row)
        widths = [max(len(r[c]) for r in rows) for c in range(len(cols))]
        for r in rows:
            lines.append("  " + "  ".join(v.rjust(w) for v, w in zip(r, widths)))
        cut = result.interval_cut
        if cut is not None and cut[i].any():
            names = ", ".join(n for n, c in zip(result.param_names, cut[i], strict=True) if c)
            lines.append(f"  intervals cut at the constants' bounds: {names} (an end past "
                         "what the model allows is shown at the bound)")
        lines.append("")
    kinds = {result.shown_of(i) for i in range(len(result.muscles))}
    wald = f"Wald intervals with Student-t (n − {result.theta.shape[1]} dof), as Excel reports them"
    if "wald-t" in kinds or not kinds:
        lines.append(f"95% low/high: {wald}.")
    if kinds - {"wald-t"}:
        lines.append(f"Wald low/high: {wald}; too narrow where the residual is correlated, "
                     "so a muscle whose residual is shows the interval that holds first.")
    if result.ci95_profile is not None:
        lines.append("profile: profile-likelihood (profile-t) intervals.")
    if result.ci95_bootstrap is not None:
        lines.append("bootstrap: percentile intervals from resampling whole curves.")
    if result.ci95_cluster is not None:
        lines.append("cluster: cluster-robust (CR3 by curve, t on curves − 1 dof) intervals; "
                     "they hold when the residuals are correlated within curves.")
    if result.ci95_hac is not None:
        lines.append("HAC: Newey–West intervals (Bartlett kernel, pairs within a trial, "
                     "Andrews' bandwidth).")
    return "\n".join(lines)


def prepare(args):
    """What ``pamid fit`` does before its data are read: check its options (the model's
    spec, a typo or a broken model file: one line; ``--bounds``, bad text: one line, exit 2)
    and import the fit. Returns (spec, bounds)."""
    from .._fit import _api  # noqa: F401 - the fit's modules, imported while the file is read
    from ._model import check_model, parse_bounds

    spec = check_model(args.model)
    return spec, parse_bounds(getattr(args, "bounds", None), spec)


def _warm_fit(startup, rows_per_muscle, intervals) -> None:
    """``prepare_fit`` for the model the start-up thread checked; best effort: whatever
    fails here is done, or reported, where the fit runs."""
    try:
        prepared = startup.value()
        if prepared is not None:
            from .._fit._api import prepare_fit

            prepare_fit(prepared[0], rows_per_muscle, intervals=intervals)
    except (Exception, SystemExit):  # noqa: BLE001 - a warm-up only (a model file may exit)
        pass


def run(args) -> int:
    from .._data._bench import load_bench
    from ._reading import expecting, reading_options

    quiet = args.json
    t0 = time.perf_counter()
    startup = getattr(args, "startup", None)  # main's: JAX starts and the checks run there
    if startup is None:
        from .._lanes import _export_cache

        startup = _export_cache.prepare_in_background(then=lambda: prepare(args))
    intervals = tuple(s.strip() for s in args.intervals.split(",") if s.strip())
    if args.stream:
        from . import fit_processes
        from .fit_stream import run_stream

        try:
            return run_stream(args, startup, intervals)
        finally:
            fit_processes.finish(args)
    if args.bootstrap and "bootstrap" not in intervals:
        intervals += ("bootstrap",)
    warming: list[threading.Thread] = []

    def on_rows(rows_per_muscle):
        # The fit's compiled programs for data of this shape, loaded on a thread of their
        # own while the rest of the file is checked (the default solver: the others may warn).
        if not warming and args.method == "ls" and args.solver == "gauss-newton":
            warming.append(threading.Thread(
                target=_warm_fit, args=(startup, rows_per_muscle, intervals),
                name="pamid-warm"))
            warming[0].start()

    try:
        bench = load_bench(args.data, on_rows=expecting(args, then=on_rows),
                           **reading_options(args))
    except BaseException:
        startup.result()  # a bad model or bounds is told first, as if checked before reading
        raise
    finally:
        for thread in warming:
            thread.join()
    spec, bounds = startup.result()

    import jax

    from .._fit._api import fit_least_squares
    from .._io import final_place, write_text_atomic

    stage(f"loaded {len(bench)} rows, {len(bench.muscles)} muscle(s) from {args.data}",
           quiet)
    if args.method == "mcmc":
        from .mcmc import run_mcmc_fit

        payload, code = run_mcmc_fit(args, bench, bounds)
        if args.json:
            print(json.dumps(payload))
        return code
    stage(f"fitting ({args.solver}; intervals: {', '.join(intervals)})", quiet)
    result = fit_least_squares(
        bench,
        args.model,
        solver=args.solver,
        intervals=intervals,
        n_bootstrap=args.bootstrap or 1000,
        key=jax.random.key(args.seed) if "bootstrap" in intervals else None,  # a compiled call
        bounds=bounds,
    )
    payload = {"source": str(args.data), "n_censored_dropped": bench.n_censored,
               "seconds": round(time.perf_counter() - t0, 3)}  # after result.to_dict()'s keys
    if args.out:
        out = Path(args.out)
        stage(f"writing plots to {final_place(out)}", quiet)
        from .._report._fit import write_fit_plots

        owners: dict = {}
        payload["plots"] = write_fit_plots(result, bench, out, args.max_plots, owners=owners)
        payload["muscle_of_file"] = owners
        write_text_atomic(out / "fit.json",
                          json.dumps({**result.to_dict(), **payload}, indent=2) + "\n")
    if args.json:
        from .._report._fit import fit_json

        print(fit_json(result, **payload))  # json.dumps({**result.to_dict(), **payload})
    else:
        print(fit_table(result))
        if not result.converged.all():
            bad = [m for m, ok in zip(result.muscles, result.converged) if not ok]
            print(f"WARNING: {len(bad)} muscle(s) did not converge: {bad[:10]}")
    return 0 if result.converged.all() else 1
