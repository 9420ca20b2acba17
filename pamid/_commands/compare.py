"""``pamid compare DATA``: several force models fitted to one bench file, ranked per muscle.

Every model (default: all of pamid's own, ``--models a,b,file.py:Class`` for a choice) is
fitted to every muscle in one batched solve that also holds its cross-validation refits
(:mod:`pamid._fit._compare`); the models are ranked per muscle by the RMSE on held-out
whole trials (or whole curves) and by BIC = n·ln(SSE/n) + p·ln n. ``--json`` prints exactly
one JSON object; ``--out DIR`` writes compare.json, one plot per muscle of every model
against the data, and a summary plot of the CV RMSE per model and muscle. Progress goes to
stderr. Exit 0 when every muscle has a best model (a converged fit), 1 when some muscle has
none, 2 for bad input (an unknown model, a file that lacks a model's input).
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np


def register(subparsers) -> None:
    from .._fit._compare_options import BIC_FORMULA, MIN_TRIALS_FOR_TRIAL_CV, N_FOLDS

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
                          "those whose inputs the file lacks are skipped and listed)")
    cmp.add_argument("--folds", type=int, default=N_FOLDS,
                     help=f"most cross-validation folds per muscle (default {N_FOLDS})")
    cmp.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    cmp.add_argument("--out", help="folder for compare.json and PNG plots")
    cmp.add_argument("--max-plots", type=int, default=6,
                     help="muscles to plot against every model (default 6)")
    cmp.add_argument("--bounds", default=None, metavar="[MODEL.]NAME=LOW:HIGH,...",
                     help="physical bounds of constants in place of the models' own, e.g. "
                          "'sarosi.a3=-3:0' for one model, or 'a3=-3:0' for every compared "
                          "model with a constant a3 (an empty side: no bound there)")
    from ._reading import add_reading_arguments

    add_reading_arguments(cmp)
    cmp.set_defaults(func=cmd_compare)


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
    from ._model import check_model, parse_bounds_per_model
    from ._reading import reading_options

    t0 = time.perf_counter()

    def progress(msg: str) -> None:
        print(f"[{time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True)

    if args.folds < 2:
        raise ValueError("--folds must be at least 2")
    if args.max_plots < 0:
        raise ValueError("--max-plots must be 0 or more")
    models = _model_list(args.models)
    specs = [check_model(ref)  # a typo or a broken model file: one line, before reading data
             for ref in (models if models is not None else list(MODELS))]
    bounds = parse_bounds_per_model(args.bounds, specs)
    bench = load_bench(args.data, **reading_options(args))
    progress(f"loaded {len(bench.frame)} rows, {len(bench.muscles)} muscle(s) from {args.data}")
    result = compare_models(bench, models, n_folds=args.folds, bounds=bounds,
                            progress=progress)
    for name, why in result.skipped:
        progress(f"skipped {name}: {why}")
    payload = result.to_dict()
    payload["source"] = str(args.data)
    payload["n_censored_dropped"] = bench.n_censored
    if args.out:
        out = Path(args.out)
        progress(f"writing plots to {final_place(out)}")
        payload["plots"] = write_plots(bench, result, out, args.max_plots)
        payload["seconds"] = round(time.perf_counter() - t0, 3)
        write_text_atomic(out / "compare.json", json.dumps(payload, indent=2) + "\n")
    payload["seconds"] = round(time.perf_counter() - t0, 3)
    if args.json:
        print(json.dumps(payload))
    else:
        print(format_table(payload))
    progress("done")
    return 0 if all(m["best"] is not None for m in payload["muscles"]) else 1


def _g(x, digits: int = 4) -> str:
    return "—" if x is None else f"{x:.{digits}g}"


def format_table(payload: dict) -> str:
    """The comparison as a table per muscle, best first."""
    lines = []
    for mu in payload["muscles"]:
        head = f"muscle {mu['muscle']}" if mu["muscle"] is not None else "muscle"
        n = mu["models"][0]["n"] if mu["models"] else 0
        cv = (f"CV on held-out whole {mu['cv']} ({mu['cv_folds']} folds of "
              f"{mu['cv_units']} {mu['cv']})" if mu["cv"] else
              "no cross-validation (one curve, fewer than 3 trials): ranked by BIC")
        lines.append(f"{head}: n = {n}, {cv}; best: {mu['best'] or 'none converged'}")
        rows = [["rank", "model", "p", "RMSE [N]", "CV RMSE [N]", "folds ok", "BIC",
                 "status"]]
        for k, r in enumerate(mu["models"], start=1):
            rows.append([str(k), r["model"], str(r["n_params"]), _g(r["rmse_N"]),
                         _g(r["cv_rmse_N"]), f"{r['cv_folds_converged']}/{mu['cv_folds']}",
                         _g(r["bic"], 6), r["status"]])
        widths = [max(len(row[c]) for row in rows) for c in range(len(rows[0]))]
        for row in rows:
            lines.append("  " + "  ".join(v.ljust(w) if c in (1, 7) else v.rjust(w)
                                          for c, (v, w) in enumerate(zip(row, widths))))
        for r in mu["models"]:
            if r["message"]:
                lines.append(f"  why {r['model']}: {r['message']}")
        lines.append("")
    if payload["skipped"]:
        for s in payload["skipped"]:
            lines.append(f"skipped {s['model']}: {s['why']}")
        lines.append("")
    lines.append(f"BIC = {payload['bic']}; best = {payload['best']}.")
    return "\n".join(lines)


def write_plots(bench, result, out: Path, max_plots: int) -> list[str]:
    """One PNG per muscle (at most ``max_plots``) of every model against the data, and one
    of the CV RMSE per model and muscle."""
    from .._io import safe_file_name

    written = []
    for i, muscle in enumerate(bench.muscles[:max_plots]):
        name = safe_file_name(muscle) if bench.has_muscle_column else "muscle"
        label = muscle if bench.has_muscle_column else Path(bench.path).name
        plot_models(bench.for_muscle(muscle), result, i, out / f"models_{name}.png",
                    f"Every model against the data — {label}")
        written.append(f"models_{name}.png")
    plot_cv_rmse(result, out / "cv_rmse.png", f"Cross-validated RMSE — {Path(bench.path).name}")
    written.append("cv_rmse.png")
    return written


def plot_models(frame, result, i: int, path, title: str):
    """Small multiples: one panel (data and model at each held level, residual below) per
    model, drawn by :func:`pamid._plot._fit_panel` — the same panel ``pamid fit`` draws —
    best model first; one legend for the figure."""
    from matplotlib.figure import Figure

    from .. import _plot
    from .._data._curves import find_curves
    from .._io import save_figure_atomic

    order = result.ranking(i)
    curves_by_column = {}
    columns = min(len(order), 3)
    blocks = math.ceil(len(order) / columns)
    kinds = None
    panels = []
    for k in order:
        mc = result.models[k]
        col = mc.spec.contraction_column
        if col not in curves_by_column:
            curves_by_column[col] = find_curves(frame, contraction_column=col)
        panels.append((mc, curves_by_column[col]))
    first_curves = panels[0][1]
    kinds = [m for m in (0, 1) if np.any(first_curves.moving == m)]
    fig = Figure(figsize=(5.2 * columns, 5.0 * blocks * len(kinds) + 0.9),
                 layout="constrained")
    gs = fig.add_gridspec(2 * blocks * len(kinds), columns,
                          height_ratios=[3, 1.3] * (blocks * len(kinds)))
    handles = None
    fit_axes, res_axes = [], []
    for slot, (mc, curves) in enumerate(panels):
        theta = mc.fit.theta[i]
        rows_obj = _plot._Rows(frame, mc.spec, theta, curves)
        for kk, moving in enumerate(kinds):
            row = 2 * (kk * blocks + slot // columns)
            ax = fig.add_subplot(gs[row, slot % columns])
            axr = fig.add_subplot(gs[row + 1, slot % columns], sharex=ax)
            ax.tick_params(labelbottom=False)
            rows = np.flatnonzero(curves.moving == moving)
            _plot._fit_panel(fig, ax, axr, rows_obj, rows, moving, theta)
            legend = ax.get_legend()
            if handles is None and legend is not None:
                handles = [h for h in legend.legend_handles
                           if not str(h.get_label()).startswith("model:")]
            if legend is not None:
                legend.remove()
            cv = mc.cv_rmse_N[i]
            status = "" if mc.fit.converged[i] else ", NOT CONVERGED"
            ax.set_title(_plot.wrap(
                f"{slot + 1}. {mc.spec.name}: RMSE {mc.fit.rmse_N[i]:.3g} N, CV RMSE "
                f"{cv:.3g} N{status}" + ("" if len(kinds) == 1 else
                                         f" ({_plot._KINDS[moving]['title'].split(':')[0]})"),
                48), fontsize=9)
            fit_axes.append(ax)
            res_axes.append(axr)
    # One force scale for every panel (the data's, with a margin), so that a runaway model
    # does not squash the data; each residual panel on its own model's scale, capped there.
    f = frame["force_N"].to_numpy(np.float64)
    span = float(np.ptp(f)) or 1.0
    for ax in fit_axes:
        ax.set_ylim(float(f.min()) - 0.1 * span, float(f.max()) + 0.1 * span)
    for axr in res_axes:
        lo, hi = axr.get_ylim()
        lim = min(max(abs(lo), abs(hi)), 0.6 * span)
        axr.set_ylim(-lim, lim)
    if handles:
        fig.legend(handles=handles, loc="outside lower center",
                   ncols=min(len(handles), 7), fontsize=8)
    fig.suptitle(_plot.wrap(title, 60 * columns), fontsize=11)
    save_figure_atomic(fig, path, dpi=_plot._DPI)
    return fig


def plot_cv_rmse(result, path, title: str, max_muscles: int = 24):
    """CV RMSE per model and muscle: grouped bars for a few muscles (the best of each
    marked), a box per model over the muscles for many."""
    import matplotlib
    from matplotlib.figure import Figure

    from .. import _plot
    from .._io import save_figure_atomic

    names = [mc.spec.name for mc in result.models]
    cv = np.array([mc.cv_rmse_N for mc in result.models])  # (models, muscles)
    conv = np.array([mc.fit.converged for mc in result.models], dtype=bool)
    m = cv.shape[1]
    labels = [str(mu) if mu is not None else "muscle" for mu in result.muscles]
    fig = Figure(figsize=(max(6.5, 0.9 * min(m, max_muscles) * max(1, len(names) / 4) + 3),
                          4.8), layout="constrained")
    ax = fig.subplots()
    tab = matplotlib.colormaps["tab10"]
    # The scale of the sensible fits: values beyond ten times the median of the converged
    # ones (a fit that ran off on a fold) are clipped there and labelled with their value.
    finite = cv[np.isfinite(cv) & conv]
    sane = finite[finite <= 10.0 * np.median(finite)] if finite.size else finite
    top = float(np.max(sane)) * 1.15 if sane.size else 1.0
    if m <= max_muscles:
        width = 0.8 / len(names)
        x = np.arange(m)
        for k, name in enumerate(names):
            values = np.where(np.isfinite(cv[k]), cv[k], np.nan)
            shown = np.minimum(values, top)
            bars = ax.bar(x + (k - (len(names) - 1) / 2) * width, shown, width,
                          color=tab(k % 10), label=name, edgecolor="none")
            for j, bar in enumerate(bars):
                if not conv[k, j]:
                    bar.set_hatch("///")
                    bar.set_edgecolor("white")
                if np.isfinite(values[j]) and values[j] > top:
                    ax.annotate(f"{values[j]:.2g}", (bar.get_x() + bar.get_width() / 2, top),
                                ha="center", va="bottom", fontsize=6, rotation=90)
        for j in range(m):
            best = result.best(j)
            if best is not None:
                k = names.index(best)
                ax.plot(x[j] + (k - (len(names) - 1) / 2) * width, cv[k, j], marker="*",
                        ms=11, color="gold", mec="0.1", zorder=5, ls="none",
                        label="best (lowest CV RMSE)" if j == 0 else None)
        ax.set_xticks(x, [_plot.wrap(s, 18) for s in labels], fontsize=8,
                      rotation=0 if m <= 6 else 30)
        ax.set_ylim(0, top * 1.08)
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0),
                  title="model (hatched: not converged)", title_fontsize=8)
    else:
        data = [cv[k][np.isfinite(cv[k]) & conv[k]] for k in range(len(names))]
        ax.boxplot(data, tick_labels=names)
        ax.set_xlabel(f"model ({m} muscles; converged fits only)")
        ax.tick_params(axis="x", labelrotation=30)
    ax.set_ylabel("CV RMSE [N] (held-out trials / curves)")
    ax.grid(alpha=0.3, axis="y")
    ax.set_title(_plot.wrap(title, 80), fontsize=10)
    save_figure_atomic(fig, path, dpi=_plot._DPI)
    return fig
