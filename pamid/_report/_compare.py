"""A model comparison (:class:`pamid.Comparison`) written out: the table ``pamid compare``
prints, every model against the data per muscle, and the cross-validated RMSE per model and
muscle, as ``pamid compare --out`` writes them. Figures are written atomically
(:func:`pamid._io.save_figure_atomic`); the panels are the fit's own (:mod:`._plot`)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def _g(x, digits: int = 4) -> str:
    return "—" if x is None else f"{x:.{digits}g}"


def comparison_table(result) -> str:
    """The comparison as ``pamid compare`` prints it: per muscle, the models best first,
    with their number of constants, RMSE and CV RMSE [N], folds converged, BIC and status,
    why a fit is not trusted, and the models skipped."""
    payload = result.to_dict()
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


def write_comparison_plots(result, bench, folder, max_plots: int = 6, *,
                           owners: dict | None = None) -> list[str]:
    """What ``pamid compare --out`` draws: ``models_<muscle>.png`` (every model against the
    data) for the first ``max_plots`` muscles of ``bench`` (the file compared), and
    ``cv_rmse.png``; each written atomically into ``folder``. Returns the names written;
    ``owners``, a dict, gets {file name: muscle} for the files of one muscle."""
    from ._fit import bench_muscle

    folder = Path(folder)
    written = []
    for i in range(len(bench.muscles[:max_plots])):
        _, name, _ = bench_muscle(bench, i)
        plot_comparison(result, bench, i, folder / f"models_{name}.png")
        written.append(f"models_{name}.png")
        if owners is not None:
            owners[written[-1]] = bench.muscles[i]
    plot_cv_rmse(result, folder / "cv_rmse.png",
                 title=f"Cross-validated RMSE — {Path(bench.path).name}")
    written.append("cv_rmse.png")
    return written


def plot_comparison(result, bench, i: int = 0, path=None, *, title: str | None = None):
    """Muscle ``i`` of ``bench`` (the file compared) against every model: small multiples,
    one panel per model (force [N] against the moving input at each held level, the
    residual below; the panel ``pamid fit`` draws), best model first, one force scale for
    all and one legend. Written to ``path`` (PNG) atomically unless it is None; the figure
    is returned."""
    from matplotlib.figure import Figure

    from .._data._curves import find_curves
    from .._io import save_figure_atomic
    from . import _plot
    from ._fit import bench_muscle

    frame, _, label = bench_muscle(bench, i)
    title = title or f"Every model against the data — {label}"
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
    if path is not None:
        save_figure_atomic(fig, path, dpi=_plot._DPI)
    return fig


def plot_cv_rmse(result, path=None, *, title: str | None = None, max_muscles: int = 24):
    """The cross-validated RMSE [N] per model and muscle: grouped bars for up to
    ``max_muscles`` muscles (the best of each starred, fits that did not converge hatched),
    a box per model over the muscles for more. Written to ``path`` (PNG) atomically unless
    it is None; the figure is returned."""
    import matplotlib
    from matplotlib.figure import Figure

    from .._io import save_figure_atomic
    from . import _plot

    if title is None:
        title = "Cross-validated RMSE" + (f" — {Path(result.source).name}"
                                          if result.source else "")

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
    if path is not None:
        save_figure_atomic(fig, path, dpi=_plot._DPI)
    return fig
