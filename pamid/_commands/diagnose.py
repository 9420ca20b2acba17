"""``pamid diagnose DATA``: what the model misses, named, modelled, before and after.

Bench files are diagnosed with the static model (``--model sarosi|cullinan``); decay files,
recognised by their columns (``angle_rad`` or ``angle_deg``, optional ``trial``), with the
oscillator model, which needs ``--inertia`` (kg·m²). ``--json`` prints exactly one JSON
object; ``--out DIR`` writes diagnosis.json, report.txt and residual plots (PNG). Progress
goes to stderr.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path


def candidate_effects_text() -> str:
    """The candidate effects, as the registry (:mod:`pamid._effects._definitions`) lists
    them: bench files' effects, then free decays'."""
    from .._effects._definitions import DECAY_EFFECT_DEFINITIONS, STATIC_EFFECT_DEFINITIONS

    bench = [f"{d.name}:<column>" if d.family is not None else d.name
             for d in STATIC_EFFECT_DEFINITIONS]
    decay = [e.name for e in DECAY_EFFECT_DEFINITIONS]
    return f"bench files: {', '.join(bench)}; decay files: {', '.join(decay)}"


def _description() -> str:
    return ("Fit the baseline model, test its residual for whiteness and for dependence on "
            "every covariate, refit with each candidate effect "
            f"({candidate_effects_text()}), select by BIC and cross-validated error, and "
            "report the error before and after. A numeric column that only counts rows "
            "(whole numbers that rise from each row to the next within every trial of every "
            "muscle: a sample index, a row number of a source file, a logger's tick count) "
            "is not offered as a covariate, whatever its name; the report says which columns "
            "were left out and why.")


def register(subparsers) -> None:
    diag = subparsers.add_parser(
        "diagnose",
        help="trace the residual of a fit to effects the model lacks, add them, report the gain",
        description=_description,  # a function: the parser calls it for --help only
    )
    diag.add_argument("data", help="bench file (CSV, Parquet or .xlsx) or decay file (time_s, "
                                   "angle_rad|angle_deg, optional trial)")
    from ._model import add_bounds_argument, add_model_argument

    add_model_argument(diag)
    add_bounds_argument(diag)
    diag.add_argument("--inertia", type=float, dest="inertia_kg_m2", metavar="J",
                      help="moment of inertia of the arm in kg·m² (decay files)")
    diag.add_argument("--folds", type=int, default=5,
                      help="cross-validation folds of held-out curves (default 5)")
    diag.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    diag.add_argument("--out", help="folder for diagnosis.json, report.txt and PNG plots")
    diag.add_argument("--max-rows", type=int, dest="max_rows", metavar="N",
                      help="diagnose a bench file of more rows on a representative subsample "
                           "of whole curves of at most N rows (the report and JSON say so: "
                           "rows_used, rows_total); default: all rows")
    from ._reading import add_reading_arguments

    add_reading_arguments(diag)
    diag.set_defaults(func=cmd_diagnose, outputs=(
        "diagnosis.json", "report.txt", "residuals_before_after.png", "residual_time_order.png"))


def cmd_diagnose(args) -> int:
    from .._diagnose._api import diagnose
    from .._io import final_place, write_text_atomic
    from .._report._diagnosis import (
        diagnosis_report,
        plot_diagnosis_residuals,
        plot_diagnosis_time_order,
    )

    if args.folds < 2:
        raise ValueError("--folds must be at least 2")
    t0 = time.perf_counter()

    def progress(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)

    from ._model import check_model, parse_bounds

    spec = check_model(args.model)  # a typo or a broken model file: one line, before reading
    bounds = parse_bounds(args.bounds, spec)  # bad text: one line, exit 2
    progress(f"diagnosing {args.data}")
    from ._reading import expecting, reading_options

    d = diagnose(args.data, model=args.model, inertia_kg_m2=args.inertia_kg_m2,
                 n_folds=args.folds, progress=progress, read_options={
                     **reading_options(args), "on_rows": expecting(args)},
                 max_rows=args.max_rows, bounds=bounds)
    out_json = d.to_dict()
    if args.out:
        out = Path(args.out)
        write_text_atomic(out / "diagnosis.json", json.dumps(out_json, indent=2) + "\n")
        write_text_atomic(out / "report.txt", diagnosis_report(d) + "\n")
        plot_diagnosis_residuals(d, out / "residuals_before_after.png")
        written = ["diagnosis.json", "report.txt", "residuals_before_after.png"]
        if d.order_is_time:  # a map sorted by its inputs has no time order to plot
            plot_diagnosis_time_order(d, out / "residual_time_order.png")
            written.append("residual_time_order.png")
        progress(f"wrote {', '.join(written)} to {final_place(out)}/"
                 + ("" if d.order_is_time else
                    " (no residual_time_order.png: the rows are a map sorted by its "
                    "inputs, not a time order)"))
    if args.json:
        print(json.dumps(out_json))
    else:
        print(diagnosis_report(d))
    progress("done")
    return 0
