"""Figures a person would rather look at than read: data against model, and residuals."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ._io import save_figure_atomic  # noqa: E402

_LABELS = {
    "contraction_pct": "contraction κ [%]",
    "contraction_mm": "contraction y [mm]",
}


def _model_on_rows(spec, theta, frame):
    return np.asarray(spec.predict(np.asarray(theta), spec.x_from_frame(frame)))


def _model_curve(spec, theta, p_kpa, contraction):
    """The model along a contraction grid at one pressure, at rest (velocities zero)."""
    cols = {c: np.zeros_like(contraction) for c in spec.columns}
    cols["pressure_kPa"] = np.full_like(contraction, p_kpa)
    cols[spec.contraction_column] = contraction
    x = spec.to_x(*(cols[c] for c in spec.columns))
    return np.asarray(spec.predict(np.asarray(theta), x))


def _pressure_levels(p_kpa):
    """Distinct pressure levels (rounded to 1 kPa) in ascending order."""
    return np.unique(np.round(p_kpa))


def plot_fit(frame, spec, theta, path, title: str) -> None:
    """Force against contraction per pressure, data and fitted model, with residuals below.

    ``frame`` is one muscle's rows of a bench table; ``spec`` the fitted model
    (``pamid._fit._spec.ModelSpec``) and ``theta`` its constants. Model lines are drawn at
    rest (zero velocity); residuals use every column the model takes.
    """
    p = frame["pressure_kPa"].to_numpy()
    k = frame[spec.contraction_column].to_numpy()
    f = frame["force_N"].to_numpy()
    direction = frame["direction"].to_numpy() if "direction" in frame else np.zeros_like(p)
    resid = f - _model_on_rows(spec, theta, frame)
    levels = _pressure_levels(p)
    colors = plt.cm.viridis(np.linspace(0.0, 0.9, max(len(levels), 1)))

    fig, (ax, axr) = plt.subplots(
        2, 1, figsize=(7.5, 7.5), sharex=True, gridspec_kw={"height_ratios": [3, 1.3]}
    )
    for level, color in zip(levels, colors):
        sel = np.round(p) == level
        for d, marker, label in ((1, "o", "contracting"), (-1, "s", "extending"), (0, "o", "")):
            s = sel & (direction == d)
            if not s.any():
                continue
            ax.plot(k[s], f[s], marker, ms=3.5, mfc="none", color=color, alpha=0.8)
            axr.plot(k[s], resid[s], marker, ms=3, mfc="none", color=color, alpha=0.8)
        kk = np.linspace(k[sel].min(), k[sel].max(), 200)
        ax.plot(kk, _model_curve(spec, theta, level, kk), "-", color=color, lw=1.5,
                label=f"{level:g} kPa")
    ax.set_ylabel("force F [N]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    leg = ax.legend(title=f"pressure (lines: {spec.source})", fontsize=8, title_fontsize=8)
    leg.get_frame().set_alpha(0.8)
    if (direction != 0).any():
        ax.text(0.99, 0.55, "○ contracting   □ extending", transform=ax.transAxes,
                ha="right", fontsize=8, color="0.3")
    axr.axhline(0.0, color="k", lw=0.8)
    axr.set_xlabel(_LABELS[spec.contraction_column])
    axr.set_ylabel("residual [N]\n(data − model)")
    axr.grid(alpha=0.3)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)


def plot_residuals(frame, spec, theta, path, title: str) -> None:
    """Residuals against contraction, pressure, fitted force and sample order."""
    p = frame["pressure_kPa"].to_numpy()
    k = frame[spec.contraction_column].to_numpy()
    f = frame["force_N"].to_numpy()
    model = _model_on_rows(spec, theta, frame)
    resid = f - model
    direction = frame["direction"].to_numpy() if "direction" in frame else None

    fig, axes = plt.subplots(2, 2, figsize=(9, 6.5))
    panels = [
        (k, _LABELS[spec.contraction_column]),
        (p, "pressure p [kPa]"),
        (model, "fitted force [N]"),
        (np.arange(len(resid)), "sample order in file"),
    ]
    for ax, (xv, label) in zip(axes.ravel(), panels):
        if direction is not None:
            for d, color, name in ((1, "tab:blue", "contracting"), (-1, "tab:red", "extending")):
                s = direction == d
                ax.plot(xv[s], resid[s], ".", ms=3, color=color, label=name, alpha=0.7)
            ax.legend(fontsize=7)
        else:
            ax.plot(xv, resid, ".", ms=3, color="tab:blue", alpha=0.7)
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xlabel(label)
        ax.set_ylabel("residual [N]")
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)


def plot_rmse_histogram(rmse, path, title: str) -> None:
    """Distribution of the fit RMSE across many muscles."""
    fig, ax = plt.subplots(figsize=(6.5, 4))
    ax.hist(np.asarray(rmse), bins=min(60, max(10, len(rmse) // 20)), color="tab:blue")
    ax.set_xlabel("RMSE of the fit [N]")
    ax.set_ylabel("muscles")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)
