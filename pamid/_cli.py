"""The ``pamid`` command: ``pamid fit``, ``pamid demo``, ``pamid simulate lifting-mass``,
``pamid damping`` and ``pamid check-decays``.

Bad input ends with a one-line message that names the file, column and row, and exit code 2;
no traceback. Exit codes: 0 done; 1 a fit that did not converge; 2 bad input or a bad output
place, or a wrong option (argparse's errors in one line too); 3 an internal failure — out of
memory, or a defect — told in one line (``PAMID_DEBUG=1`` shows the traceback instead); 130
interrupted; 143 terminated (SIGTERM); 141 stdout closed early
(``pamid fit --json | head``), silently (:mod:`pamid._commands.failure`). Results go to
``--out`` as one set when the command has finished; on any failure or signal ``--out`` is
left as it was (:func:`pamid._io.output_folder`). ``--json``
prints exactly one JSON object on stdout; warnings and progress go to stderr. Compiled
code is cached on disk (``PAMID_CACHE_DIR``, default ``~/.cache/pamid/jax``), so the second
call of a command skips compilation.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time
import warnings
from pathlib import Path

from ._commands._common import stage

EXIT_BAD_INPUT = 2
#: Arguments of the commands that name input files (never written; see pamid._io).
_INPUT_ARGUMENTS = ("data", "decay", "model_json", "fit")


def _enable_compilation_cache():
    """Switch on the compilation cache and the exported programs for this command
    (:func:`pamid._fit._export_cache.use_disk_caches`, ``PAMID_CACHE_DIR``); returns the
    function that puts the caller's settings back."""
    from ._fit._export_cache import use_disk_caches

    return use_disk_caches()


def _format_table(result, published=None) -> str:
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


def _fit_prepare(args):
    """What ``pamid fit`` does before its data are read: check its options (the model's
    spec, a typo or a broken model file: one line; ``--bounds``, bad text: one line, exit 2)
    and import the fit. Returns (spec, bounds)."""
    from ._commands._model import check_model, parse_bounds
    from ._fit import _api  # noqa: F401 - the fit's modules, imported while the file is read

    spec = check_model(args.model)
    return spec, parse_bounds(getattr(args, "bounds", None), spec)


def _warm_fit(startup, rows_per_muscle, intervals) -> None:
    """``prepare_fit`` for the model the start-up thread checked; best effort: whatever
    fails here is done, or reported, where the fit runs."""
    try:
        prepared = startup.value()
        if prepared is not None:
            from ._fit._api import prepare_fit

            prepare_fit(prepared[0], rows_per_muscle, intervals=intervals)
    except (Exception, SystemExit):  # noqa: BLE001 - a warm-up only (a model file may exit)
        pass


def _cmd_fit(args) -> int:
    from ._commands._reading import reading_options
    from ._data._bench import load_bench

    quiet = args.json
    t0 = time.perf_counter()
    startup = getattr(args, "startup", None)  # main's: JAX starts and the checks run there
    if startup is None:
        from ._fit import _export_cache

        startup = _export_cache.prepare_in_background(then=lambda: _fit_prepare(args))
    intervals = tuple(s.strip() for s in args.intervals.split(",") if s.strip())
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
        bench = load_bench(args.data, on_rows=on_rows, **reading_options(args))
    except BaseException:
        startup.result()  # a bad model or bounds is told first, as if checked before reading
        raise
    finally:
        for thread in warming:
            thread.join()
    spec, bounds = startup.result()

    import jax

    from ._fit._api import fit_least_squares
    from ._io import final_place, write_text_atomic

    stage(f"loaded {len(bench.frame)} rows, {len(bench.muscles)} muscle(s) from {args.data}",
           quiet)
    if args.method == "mcmc":
        from ._commands.mcmc import run_mcmc_fit

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
        from ._report._fit import write_fit_plots

        owners: dict = {}
        payload["plots"] = write_fit_plots(result, bench, out, args.max_plots, owners=owners)
        payload["muscle_of_file"] = owners
        write_text_atomic(out / "fit.json",
                          json.dumps({**result.to_dict(), **payload}, indent=2) + "\n")
    if args.json:
        from ._report._fit import fit_json

        print(fit_json(result, **payload))  # json.dumps({**result.to_dict(), **payload})
    else:
        print(_format_table(result))
        if not result.converged.all():
            bad = [m for m, ok in zip(result.muscles, result.converged) if not ok]
            print(f"WARNING: {len(bad)} muscle(s) did not converge: {bad[:10]}")
    return 0 if result.converged.all() else 1


def _cmd_demo(args) -> int:
    import jax

    from ._data._bench import load_bench
    from ._fit._api import fit_least_squares
    from ._fit._batch import pack
    from ._io import final_place, write_text_atomic
    from ._models._hysteresis import hysteresis_damping
    from ._models._sarosi import TABLE_3_1, TABLE_3_1_L0_MM, Sarosi, table_3_1_fit_json
    from ._units import KPA_PER_BAR
    from ._virtual._default import default_bench_path, default_protocol

    out = Path(args.out)
    path = default_bench_path()
    protocol = default_protocol()
    print(f"pamid demo — bundled virtual-bench data set: {path.name}")
    print(f"  simulated by pamid's virtual bench from Sárosi Table 3-1 (DMSP-20-400N, "
          f"l0 = {TABLE_3_1_L0_MM:g} mm), protocol: pressures {list(protocol.pressures_kPa)} kPa, "
          f"{protocol.points_per_curve} points per sweep, both directions, {protocol.repeats} "
          f"repeats averaged, noise {protocol.noise_sd_N} N, hysteresis "
          f"±{protocol.hysteresis_N_per_bar} N/bar.")
    bench = load_bench(path)
    t0 = time.perf_counter()
    result = fit_least_squares(bench, intervals=("wald", "profile", "bootstrap"),
                               n_bootstrap=1000, key=jax.random.key(args.seed))
    print(f"\nFit of both branches together ({time.perf_counter() - t0:.2f} s, compilation "
          "included), beside Table 3-1:\n")
    print(_format_table(result, published=TABLE_3_1))

    # Hysteresis branches and damping, Sárosi eq. 2.3–2.10, at 400 kPa with 50 kg.
    frame = bench.frame
    branches = {}
    for d, name in ((-1, "upper (extending)"), (1, "lower (contracting)")):
        sub = frame[frame["direction"] == d]
        data = pack([((sub["pressure_kPa"].to_numpy() / KPA_PER_BAR,
                       sub["contraction_pct"].to_numpy()), sub["force_N"].to_numpy())])
        branches[name] = fit_least_squares(data).theta[0]
    p_bar, mass = 4.0, 50.0
    k_hi = float(frame.loc[(frame.pressure_kPa == 400.0), "contraction_pct"].max())
    damping = hysteresis_damping(
        Sarosi.from_vector(branches["upper (extending)"]),
        Sarosi.from_vector(branches["lower (contracting)"]),
        p_bar, 0.0, k_hi, 12.5, TABLE_3_1_L0_MM / 1000.0, mass,
    )
    damping = {k: float(v) for k, v in damping.items()}
    print(f"Hysteresis damping at {p_bar * 100:g} kPa, loop over κ = 0 … {k_hi:.2f} %, "
          f"m = {mass:g} kg, stiffness at κ = 12.5 % (Sárosi eq. 2.3–2.10):")
    for key, value in damping.items():
        print(f"  {key:>22s} = {value:.6g}")

    # Closing the loop: what does eq. 2.1 miss in these data, and what does adding it gain?
    from ._diagnose._api import diagnose
    from ._report._diagnosis import plot_diagnosis_residuals
    from ._report._fit import write_fit_plots

    diag = diagnose(bench)
    print("\nClosing the loop (pamid diagnose): the residual of eq. 2.1 against every covariate, "
          "each candidate effect refitted:")
    for row in diag.candidates[:4]:
        print(f"  {row['effect']:<26} ΔBIC {row['delta_bic']:>9.1f}   CV RMSE "
              f"{row['cv_rmse']:.3f} N   {'significant' if row['significant'] else ''}")
    print(f"  selected: {', '.join(diag.selected) or 'nothing'}; RMSE {diag.rmse_before:.3f} → "
          f"{diag.rmse_after:.3f} N, max error {diag.max_error_before:.2f} → "
          f"{diag.max_error_after:.2f} N; unexplained: {', '.join(diag.unexplained) or 'nothing'}")
    for name, consts in diag.constants[0]["effects"].items():
        for pname, c in consts.items():
            lo, hi = c["ci95"]
            print(f"  {name} {pname} = {c['value']:.4g} {c['unit']} [{lo:.4g}, {hi:.4g}]")

    out.mkdir(parents=True, exist_ok=True)
    plots = write_fit_plots(result, bench, out, 1)
    plot_diagnosis_residuals(diag, out / "diagnosis_residuals.png")
    plots.append("diagnosis_residuals.png")
    summary = result.to_dict()
    summary["source"] = str(path)
    summary["hysteresis_damping_400kPa_50kg"] = damping
    summary["diagnosis"] = {k: v for k, v in diag.to_dict().items()
                            if k in ("rmse_before", "rmse_after", "max_error_before",
                                     "max_error_after", "selected", "candidates",
                                     "constants", "unexplained")}
    summary["published_table_3_1"] = table_3_1_fit_json()["muscles"][0]["params"]
    summary["plots"] = plots
    write_text_atomic(out / "demo.json", json.dumps(summary, indent=2) + "\n")
    print(f"\nPlots and demo.json written to {final_place(out)}/: {', '.join(plots)}")
    return 0


class _Parser(argparse.ArgumentParser):
    """argparse with its errors in one line, exit 2, for every subcommand (subparsers take
    the class of their parent): ``pamid fit: error: argument --max-plots: invalid int
    value: '1.5' (see pamid fit --help)``. ``PAMID_DEBUG=1`` prints argparse's usage above
    it, for developers."""

    def error(self, message: str):
        from ._commands import failure

        if failure.debugging():
            self.print_usage(sys.stderr)
        message = " ".join(str(message).split())
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def format_help(self) -> str:
        # A description may be a function, called only when the help is shown: the text
        # of `pamid diagnose --help` lists the effects' registry, which imports JAX, and
        # every command builds every parser (`pamid fit` waited 1 s for it).
        if callable(self.description):
            self.description = self.description()
        return super().format_help()

    def parse_args(self, args=None, namespace=None):
        # argparse reports an unknown option from the top parser ("pamid: error: ...");
        # name the subcommand it was given to instead.
        namespace, extra = self.parse_known_args(args, namespace)
        if extra:
            prog = " ".join(filter(None, (self.prog, _command_name(namespace))))
            _Parser(prog=prog, add_help=False).error(
                f"unrecognized arguments: {' '.join(extra)}")
        return namespace


def _command_name(args) -> str:
    """The (sub)command given: ``fit``, ``simulate lifting-mass``, … ("" for none)."""
    words = (getattr(args, "command", None), getattr(args, "system", None))
    return " ".join(filter(None, words))


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="pamid", description="System identification for pneumatic artificial muscles."
    )
    sub = parser.add_subparsers(dest="command", required=True)

    fit = sub.add_parser("fit",
                         help="fit a static force model to bench data (CSV, Parquet or .xlsx)")
    fit.add_argument("data", help="bench file: pressure_kPa|bar|Pa|psi, force_N, contraction_pct "
                                  "or length_mm (+ l0_mm), optional muscle, trial, direction, …")
    from ._commands._model import add_model_argument

    add_model_argument(fit)
    from ._commands._model import add_bounds_argument

    add_bounds_argument(fit)
    fit.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    fit.add_argument("--out", help="folder for plots (PNG) and fit.json")
    fit.add_argument("--solver", default="gauss-newton",
                     choices=["gauss-newton", "levenberg-marquardt", "variable-projection",
                              "jaxopt-levenberg-marquardt"])
    fit.add_argument("--intervals", default="wald,profile",
                     help="comma-separated: wald, profile, bootstrap, cluster (holds under "
                          "residuals correlated within curves), hac (default wald,profile)")
    fit.add_argument("--bootstrap", type=int, default=0, metavar="B",
                     help="also bootstrap whole curves with B replicates per muscle")
    fit.add_argument("--seed", type=int, default=0, help="PRNG seed for the bootstrap and MCMC")
    from ._commands._common import NonNegative

    fit.add_argument("--max-plots", type=int, action=NonNegative, default=6,
                     help="muscles to plot (default 6)")
    from ._commands._reading import add_reading_arguments
    from ._commands.mcmc_options import add_mcmc_arguments

    add_reading_arguments(fit)
    add_mcmc_arguments(fit)
    fit.set_defaults(func=_cmd_fit, prepare=_fit_prepare, outputs=(
        "fit.json", "fit_*.png", "residuals_*.png", "rmse_histogram.png", "mcmc_*.nc",
        "mcmc_*.nc3", "mcmc_*.png"))  # the names it writes in --out (checked before any work)

    demo = sub.add_parser("demo", help="fit the bundled virtual-bench data set, beside Table 3-1")
    demo.add_argument("--out", default="demo-out", help="folder for plots and demo.json")
    demo.add_argument("--seed", type=int, default=0, help="PRNG seed for the bootstrap")
    demo.set_defaults(func=_cmd_demo)

    from ._commands import dynamics

    dynamics.register(sub)

    from ._commands import check

    check.register(sub)

    from ._commands import diagnose

    diagnose.register(sub)

    from ._commands import compare

    compare.register(sub)

    from ._commands import predict

    predict.register(sub)

    from ._commands import warmup

    warmup.register(sub)
    return parser


def _input_files(args) -> list[str]:
    """The input files named on the command line, a model file (``--model FILE.py:CLASS``)
    included: no output ever replaces one (pamid._io.protect_inputs)."""
    files = [getattr(args, name, None) for name in _INPUT_ARGUMENTS]
    model = getattr(args, "model", None)
    if isinstance(model, str) and ":" in model:
        files.append(model.rsplit(":", 1)[0])
    return files


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from . import _io
    from ._commands import failure
    from ._errors import BenchDataError, UntrustedResultError
    from ._fit import _export_cache

    exporting = _export_cache.directory()
    signals = failure.catch_signals()
    restore_cache = lambda: None  # noqa: E731 (set where the cache is switched on)
    try:
        # Before any computing: the output place can be written, and no output of this run
        # can replace one of its input files (every writer of pamid._io checks). The
        # command writes into a hidden staging folder, moved into --out as one set when it
        # returns; on any failure or signal --out is left as it was (pamid._io.output_folder).
        _io.protect_inputs(_input_files(args))
        _io.refuse_inputs_among_outputs(_input_files(args), getattr(args, "out", None),
                                        getattr(args, "outputs", ()))
        with _io.output_folder(getattr(args, "out", None),
                               command=_command_name(args)) as staging, \
                warnings.catch_warnings():  # the start-up thread's warnings too
            warnings.simplefilter("always")
            warnings.showwarning = _show_warning
            if staging is not None:
                args.out = str(staging)
            if getattr(args, "prepare", None) is not None:
                # JAX's start-up, the disk caches and what the command does before its data
                # are read, on a thread of their own while it reads them.
                args.startup = _export_cache.prepare_in_background(
                    disk_caches=True, then=lambda: args.prepare(args))
                restore_cache = args.startup.restore
            else:
                restore_cache = _enable_compilation_cache()
            code = args.func(args)
            failure.raise_if_signalled()  # a Ctrl-C that a callback swallowed: no commit
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's exit
        return code
    except BenchDataError as exc:
        print(f"pamid: error: {_option_words(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except ValueError as exc:  # bad options (a solver name, an output path onto an input)
        if failure.debugging():
            raise
        print(f"pamid: error: {_option_words(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except UntrustedResultError as exc:  # exit 1, as a fit that did not converge
        print(f"pamid: error: {_option_words(exc)}", file=sys.stderr)
        if getattr(args, "json", False):  # --json: still exactly one JSON object
            print(json.dumps({"status": "not_trustworthy", "message": _option_words(exc)}))
        return 1
    except BrokenPipeError:  # `pamid fit --json | head -c 1`: the reader has what it wanted
        failure.silence_stdout()
        return failure.EXIT_BROKEN_PIPE
    except failure.Terminated:  # output_folder has removed the staging folder on the way out
        print("pamid: terminated", file=sys.stderr)
        return failure.EXIT_TERMINATED
    except KeyboardInterrupt:
        if failure.debugging():
            raise
        print("pamid: interrupted", file=sys.stderr)
        return failure.EXIT_INTERRUPTED
    except SystemExit as exc:  # user code (argparse's exits come before): its file, exit 2
        if failure.debugging():
            raise
        print(f"pamid: error: {failure.describe_exit(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as exc:  # out of memory, or a defect: one line, never a traceback
        if failure.debugging():
            raise
        print(f"pamid: error: {failure.describe(exc, args.command)}", file=sys.stderr)
        return failure.EXIT_INTERNAL
    finally:  # a caller in the same process (a test, a notebook) gets its setting back
        restore_cache()
        _export_cache.enable(exporting)
        _io.protect_inputs([])
        failure.restore_signals(signals)


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"pamid: warning: {_option_words(message)}", file=sys.stderr)


#: How the library's messages name a parameter of its functions (``load_bench(...,
#: keep_censored=True)``) that the command line sets by an option: the one place where an
#: error or a warning on its way to the command line takes the option's name instead.
_OPTION_OF_PARAMETER = (
    (r"\bkeep_censored=True\b", "--keep-censored"),
    (r"\bn_boot(strap)?\b", "--bootstrap"),
    (r"\bn_walkers\b", "--walkers"),
    (r"\bmax_steps\b", "--max-steps"),
    (r"\bmax_rows\b", "--max-rows"),
    (r"\bn_folds\b", "--folds"),
)


def _option_words(message) -> str:
    """``message`` (an exception, a warning) with the command line's options in place of
    the library's parameters: "pass keep_censored=True to keep them" → "pass
    --keep-censored to keep them"; "n_boot must be at least 2" → "--bootstrap must be at
    least 2"; a message that named both ("max_rows (--max-rows)") names the option once."""
    import re

    text = str(message)
    for pattern, option in _OPTION_OF_PARAMETER:
        text = re.sub(pattern, option, text)
    return re.sub(r"(--[a-z-]+) \(\1\)", r"\1", text)


def console_main() -> None:
    """Entry point of the installed ``pamid`` command (and of ``python -m pamid``): runs
    the command and ends the process with its exit code. To run a command inside a process
    that goes on (a test, a notebook), call :func:`main`, which returns the code.

    The command owns its process, so it picks pyarrow's memory pool before pyarrow is
    loaded (a user's ``ARROW_DEFAULT_MEMORY_POOL`` wins): the system allocator. With
    pyarrow's default on Linux (mimalloc), reading the 10,000-muscle file of
    ``benchmarks/end_to_end.py`` took 0.49–1.29 s from one fresh process to the next; with
    the system's, 0.60–0.68 s (benchmarks/README.md)."""
    os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
    code = main()
    if "matplotlib" not in sys.modules:
        # Not after drawing: matplotlib's exit handler removes the temporary configuration
        # folder it makes where its own cannot be written.
        _end_process(code)
    sys.exit(code)


def _end_process(code) -> None:
    """End the process that has just run a command, without the interpreter's teardown.

    Everything the command makes is written and closed by then (``--out`` is committed,
    stdout flushed by :func:`main`); what is left is Python freeing every object and module
    and the libraries' static destructors, 0.35–0.45 s after ``pamid fit`` of 10,000
    muscles (benchmarks/README.md, end_to_end.py). The streams are flushed here, and the
    logging handlers; the exit code is the command's."""
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a reader gone (main silenced stdout), or closed
            pass
    os._exit(int(code or 0))


if __name__ == "__main__":
    console_main()
