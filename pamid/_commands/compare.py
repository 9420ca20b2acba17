"""``pamid compare DATA``: several force models fitted to one bench file, ranked per muscle.

Every model (default: all of pamid's own, ``--models a,b,file.py:Class`` for a choice) is
fitted to every muscle in one batched solve that also holds its cross-validation refits
(:mod:`pamid._fit._compare`); the models are ranked per muscle by the RMSE on held-out
whole trials (or whole curves) and by BIC = n·ln(SSE/n) + p·ln n. ``--json`` prints exactly
one JSON object; ``--out DIR`` writes compare.json, one plot per muscle of every model
against the data, and a summary plot of the CV RMSE per model and muscle (the table and
the figures: :mod:`pamid._report._compare`). Progress goes to stderr. Exit 0 when every
muscle has a best model (a converged fit), 1 when some muscle has none, 2 for bad input (an
unknown model, a file that lacks a model's input).

``--pooled`` adds the pooled models over all muscles (:mod:`pamid._pooled._lomo`), ranked by
leave-one-muscle-out RMSE: the JSON's ``"pooled"`` list, a second table, and
pooled_lomo.png; ``pamid predict`` reads them back.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path


def register(subparsers) -> None:
    from .._fit._compare_options import BIC_FORMULA, MIN_TRIALS_FOR_TRIAL_CV, N_FOLDS
    from ._model import CODE_WARNING

    cmp = subparsers.add_parser(
        "compare",
        help="fit several force models to a bench file and rank them per muscle by "
             "cross-validated RMSE and BIC",
        description="Fit every model to every muscle (one batched solve per model, its "
                    "cross-validation refits included as weighted lanes) and rank the models "
                    "per muscle by the RMSE on held-out whole trials (muscles with at least "
                    f"{MIN_TRIALS_FOR_TRIAL_CV} trials) or whole curves, and by BIC = "
                    f"{BIC_FORMULA}. The best model of a muscle is the converged one of "
                    "lowest CV RMSE.",
    )
    cmp.add_argument("data", help="bench file (CSV, Parquet or .xlsx): pressure, force_N, "
                                  "contraction_pct or length_mm (+ l0_mm), optional muscle, "
                                  "trial, …")
    cmp.add_argument("--models", metavar="A,B,…",
                     help="comma-separated models: names of pamid's own and/or "
                          "path/to/file.py:ClassName (default: every registered model; "
                          "those whose inputs the file lacks are skipped and listed). "
                          + CODE_WARNING)
    cmp.add_argument("--folds", type=int, default=N_FOLDS,
                     help=f"most cross-validation folds per muscle (default {N_FOLDS})")
    cmp.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    cmp.add_argument("--out", help="folder for compare.json and PNG plots")
    from ._common import NonNegative

    cmp.add_argument("--max-plots", type=int, action=NonNegative, default=6,
                     help="muscles to plot against every model (default 6)")
    cmp.add_argument("--bounds", default=None, metavar="[MODEL.]NAME=LOW:HIGH,...",
                     help="physical bounds of constants in place of the models' own, e.g. "
                          "'sarosi.a3=-3:0' for one model, or 'a3=-3:0' for every compared "
                          "model with a constant a3 (an empty side: no bound there)")
    cmp.add_argument("--pooled", action="store_true",
                     help="also fit pooled models over all muscles (constants shared, smooth "
                          "in the descriptors, per muscle, the Bolen et al. 2026 law) and rank "
                          "them by leave-one-muscle-out RMSE; the per-muscle ranking then "
                          "covers --models only (default: sarosi)")
    cmp.add_argument("--describe", default="l0_mm", metavar="A,B,…",
                     help="with --pooled: the per-muscle descriptors smooth constants depend "
                          "on (default l0_mm; also diameter_mm, emax_pct or any numeric "
                          "column with one value per muscle)")
    cmp.add_argument("--roles", default=None, metavar="NAME=ROLE,…",
                     help="with --pooled: also a pooled model of your roles, e.g. "
                          "'a1=shared,a3=per_muscle' (ROLE: shared, smooth, per_muscle; "
                          "constants not named are smooth); for the first of --models")
    cmp.add_argument("--bayes", action="store_true",
                     help="with --pooled: also the hierarchical Bayesian Bolen law (each "
                          "muscle's factor drawn from the population; ensemble sampler, "
                          "PRNG key 0; minutes on a file of thousands of rows)")
    from ._reading import add_reading_arguments

    add_reading_arguments(cmp)
    cmp.set_defaults(func=cmd_compare, outputs=("compare.json", "models_*.png", "cv_rmse.png",
                                                "pooled_lomo.png"))


def _model_list(text: str | None) -> list[str] | None:
    if text is None:
        return None
    items = [s.strip() for s in text.split(",") if s.strip()]
    if not items:
        raise ValueError("--models: name at least one model, e.g. --models sarosi,cullinan")
    return items


def cmd_compare(args) -> int:
    from .._data._bench import load_bench
    from .._fit._compare import compare_models
    from .._fit._spec import MODELS
    from .._io import final_place, write_text_atomic
    from .._report._compare import comparison_table, write_comparison_plots
    from ._model import check_model, parse_bounds_per_model
    from ._reading import expecting, reading_options

    t0 = time.perf_counter()

    def progress(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)

    if args.folds < 2:
        raise ValueError("--folds must be at least 2")
    models = _model_list(args.models)
    if getattr(args, "pooled", False) and models is None:
        models = ["sarosi"]
    specs = [check_model(ref)  # a typo or a broken model file: one line, before reading data
             for ref in (models if models is not None else list(MODELS))]
    bounds = parse_bounds_per_model(args.bounds, specs)
    bench = load_bench(args.data, on_rows=expecting(args), **reading_options(args))
    progress(f"loaded {len(bench.frame)} rows, {len(bench.muscles)} muscle(s) from {args.data}")
    result = compare_models(bench, models, n_folds=args.folds, bounds=bounds,
                            progress=progress)
    for name, why in result.skipped:
        progress(f"skipped {name}: {why}")
    payload = result.to_dict()
    payload["source"] = str(args.data)
    payload["n_censored_dropped"] = bench.n_censored
    pooled = _pooled(args, bench, specs, progress) if getattr(args, "pooled", False) else None
    if pooled is not None:
        payload.update(pooled.to_dict())
    if args.out:
        out = Path(args.out)
        progress(f"writing plots to {final_place(out)}")
        owners: dict = {}
        payload["plots"] = write_comparison_plots(result, bench, out, args.max_plots,
                                                  owners=owners)
        payload["muscle_of_file"] = owners
        if pooled is not None:
            from .._report._pooled import plot_pooled_lomo

            plot_pooled_lomo(pooled, out / "pooled_lomo.png")
            payload["plots"].append("pooled_lomo.png")
        payload["seconds"] = round(time.perf_counter() - t0, 3)
        write_text_atomic(out / "compare.json", json.dumps(payload, indent=2) + "\n")
    payload["seconds"] = round(time.perf_counter() - t0, 3)
    if args.json:
        print(json.dumps(payload))
    else:
        print(comparison_table(result))
        if pooled is not None:
            from .._report._pooled import pooled_table

            print()
            print(pooled_table(pooled))
    progress("done")
    return 0 if all(m["best"] is not None for m in payload["muscles"]) else 1


def _pooled(args, bench, specs, progress):
    """``--pooled``: every pooled model of the file's muscles, ranked by LOMO RMSE."""
    from .._pooled._lomo import compare_pooled
    from .._pooled._spec import parse_roles

    describe = tuple(s.strip() for s in args.describe.split(",") if s.strip())
    if not describe:
        raise ValueError("--describe: name at least one descriptor, e.g. --describe l0_mm")
    roles = (None if args.roles is None
             else parse_roles(args.roles, specs[0].param_names))
    bayes = None
    if args.bayes:
        import jax

        bayes = jax.random.key(0)
    result = compare_pooled(bench, specs, describe=describe, roles=roles, bayes=bayes,
                            progress=progress)
    for name, why in result.skipped:
        progress(f"skipped pooled {name}: {why}")
    return result
