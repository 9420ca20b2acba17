"""A pooled comparison and a predicted muscle, written out: tables and figures.

:func:`pooled_table` and :func:`plot_pooled_lomo` show :class:`pamid.PooledComparison`
(``pamid compare --pooled``); :func:`prediction_table` and :func:`plot_prediction` show
:class:`pamid.MusclePrediction` (``pamid predict``).
"""

from __future__ import annotations

import numpy as np


def _g(x, digits: int = 3) -> str:
    return "—" if x is None or not np.isfinite(x) else f"{x:.{digits}g}"


def pooled_table(result) -> str:
    """Every pooled model, best LOMO RMSE first, with its LOMO RMSE per muscle."""
    muscles = result.muscles
    l0 = result.models[0].descriptors.values["l0_mm"] if result.models else []
    labels = [f"{v:.0f}mm" for v in l0]
    if len(set(labels)) < len(labels):  # muscles of one length (several diameters): names
        labels = [mu[:7] for mu in muscles]
    head = (f"{'model':<22} {'k':>3} {'fit RMSE':>9} {'LOMO RMSE':>10} {'% Fmax':>7} "
            f"{'cover':>6}  " + " ".join(f"{label:>7}" for label in labels))
    lines = ["Pooled models, judged on each muscle left out (LOMO): RMSE [N] of its rows "
             "predicted from the other muscles",
             f"descriptors: {', '.join(result.describe)}; muscles: {', '.join(muscles)}",
             head, "-" * len(head)]
    for m in result.models:
        flag = "" if m.converged else "  (fit to all muscles did not converge)"
        lines.append(
            f"{m.model:<22} {m.n_params:>3} {_g(m.rmse_N, 4):>9} {_g(m.lomo_rmse_N, 4):>10} "
            f"{_g(m.lomo_rmse_pct_fmax, 3):>7} {_g(100 * m.lomo_coverage_95, 3):>6}  "
            + " ".join(f"{_g(x['lomo_rmse_N'], 3):>7}" for x in m.muscles) + flag)
    lines.append("cover: % of a held-out muscle's rows inside its 95 % predictive interval "
                 "(calibrated on the other muscles), mean over muscles")
    lines += [f"note: {n}" for n in result.notes]
    lines += [f"skipped {n}: {w}" for n, w in result.skipped]
    return "\n".join(lines)


def plot_pooled_lomo(result, path=None, *, title: str | None = None):
    """LOMO RMSE [N] of each pooled model against the held-out muscle's resting length.
    Written to ``path`` (PNG) atomically unless it is None; the figure is returned."""
    import matplotlib
    from matplotlib.figure import Figure

    from . import _plot

    fig = Figure(figsize=(7.5, 4.6), layout="constrained")
    ax = fig.subplots()
    tab = matplotlib.colormaps["tab10"]
    markers = "osD^v<>ph*"
    for k, m in enumerate(result.models):
        l0 = [x["l0_mm"] for x in m.muscles]
        rm = [x["lomo_rmse_N"] for x in m.muscles]
        # Muscles of one length (several diameters) would be joined across diameters:
        # markers only then.
        joined = len(set(l0)) == len(l0)
        ax.plot(l0, rm, marker=markers[k % len(markers)], color=tab(k % 10),
                lw=1.2 if joined else 0, label=f"{m.model} ({m.lomo_rmse_N:.3g} N)")
    ax.set_xlabel("resting length l0 of the muscle left out [mm]")
    ax.set_ylabel("LOMO RMSE [N]")
    ax.set_ylim(bottom=0)
    ax.set_title(title or "Each muscle predicted from the others (leave one muscle out)")
    _plot._grid(ax)
    ax.legend(fontsize=8, title="model (overall LOMO RMSE)", title_fontsize=8)
    _plot._save(fig, path)
    return fig


def prediction_table(result) -> str:
    """The predicted map, one line per point: pressure, contraction, force and its interval."""
    desc = ", ".join(f"{k} = {v:.4g}" for k, v in result.descriptors.items())
    lines = [f"Predicted force of an untested muscle ({desc}) — model {result.model}",
             f"{100 * result.level:.0f} % predictive interval (spread of muscles about the "
             "pooled law + noise)"]
    if result.emax_source:
        lines.append(f"emax_pct from {result.emax_source}")
    lines += [f"note: {n}" for n in result.notes]
    head = f"{'p [kPa]':>8} {'κ [%]':>7} {'F [N]':>9} {'low [N]':>9} {'high [N]':>9}"
    lines += [head, "-" * len(head)]
    for p, k, f, lo, hi in zip(result.pressure_kPa, result.contraction_pct, result.force_N,
                               result.low_N, result.high_N, strict=True):
        lines.append(f"{p:>8.4g} {k:>7.3g} {f:>9.4g} {lo:>9.4g} {hi:>9.4g}")
    return "\n".join(lines)


def plot_prediction(result, path=None, *, measured=None, title: str | None = None):
    """The predicted force against contraction at each pressure, with its 95 % predictive
    band; ``measured`` (a frame with pressure_kPa, contraction_pct, force_N) is drawn on
    top where given. Written to ``path`` atomically unless it is None; the figure is
    returned."""
    from matplotlib.figure import Figure

    from . import _plot

    fig = Figure(figsize=(7.5, 5.0), layout="constrained")
    ax = fig.subplots()
    pressures = np.unique(result.pressure_kPa)
    colors = _plot._CMAP(np.linspace(0.0, 1.0, max(len(pressures), 2)))
    for c, p in zip(colors, pressures, strict=False):
        sel = result.pressure_kPa == p
        k = result.contraction_pct[sel]
        order = np.argsort(k)
        ax.fill_between(k[order], np.maximum(result.low_N[sel][order], 0.0),
                        np.maximum(result.high_N[sel][order], 0.0), color=c, alpha=0.18, lw=0)
        ax.plot(k[order], result.force_N[sel][order], color=c, lw=1.6, label=f"{p:.0f} kPa")
    if measured is not None:
        ax.scatter(measured["contraction_pct"], measured["force_N"], s=4, color="0.2",
                   alpha=0.35, label="measured", zorder=3)
    desc = ", ".join(f"{k} = {v:.4g}" for k, v in result.descriptors.items())
    ax.set_title(title or f"Predicted muscle ({desc})\nmodel {result.model}, band: "
                 f"{100 * result.level:.0f} % predictive interval", fontsize=10)
    ax.set_xlabel("contraction κ [%]")
    ax.set_ylabel("force [N]")
    ax.set_ylim(bottom=0)
    ax.set_xlim(left=0)
    _plot._grid(ax)
    ax.legend(fontsize=8, ncols=2)
    _plot._save(fig, path)
    return fig
