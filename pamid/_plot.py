"""Figures a person would rather look at than read: data against model, and residuals."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ._io import save_figure_atomic  # noqa: E402
from ._models._sarosi import Sarosi, sarosi_force  # noqa: E402
from ._units import KPA_PER_BAR  # noqa: E402


def _pressure_levels(p_kpa):
    """Distinct pressure levels (rounded to 1 kPa) in ascending order."""
    return np.unique(np.round(p_kpa))


def plot_fit(frame, theta, path, title: str) -> None:
    """Force against contraction per pressure, data and fitted model, with residuals below.

    ``frame`` is one muscle's rows of a bench table (pressure_kPa, contraction_pct,
    force_N, optionally direction); ``theta`` the fitted Sárosi constants.
    """
    params = Sarosi.from_vector(np.asarray(theta))
    p = frame["pressure_kPa"].to_numpy()
    k = frame["contraction_pct"].to_numpy()
    f = frame["force_N"].to_numpy()
    direction = frame["direction"].to_numpy() if "direction" in frame else np.zeros_like(p)
    resid = f - np.asarray(sarosi_force(params, p / KPA_PER_BAR, k))
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
        ax.plot(kk, sarosi_force(params, level / KPA_PER_BAR, kk), "-", color=color, lw=1.5,
                label=f"{level:g} kPa")
    ax.set_ylabel("force F [N]")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    leg = ax.legend(title="pressure (lines: model eq. 2.1)", fontsize=8, title_fontsize=8)
    leg.get_frame().set_alpha(0.8)
    if (direction != 0).any():
        ax.text(0.99, 0.55, "○ contracting   □ extending", transform=ax.transAxes,
                ha="right", fontsize=8, color="0.3")
    axr.axhline(0.0, color="k", lw=0.8)
    axr.set_xlabel("contraction κ [%]")
    axr.set_ylabel("residual [N]\n(data − model)")
    axr.grid(alpha=0.3)
    fig.tight_layout()
    save_figure_atomic(fig, path, dpi=110)
    plt.close(fig)


def plot_residuals(frame, theta, path, title: str) -> None:
    """Residuals against contraction, pressure, fitted force and sample order."""
    params = Sarosi.from_vector(np.asarray(theta))
    p = frame["pressure_kPa"].to_numpy()
    k = frame["contraction_pct"].to_numpy()
    f = frame["force_N"].to_numpy()
    model = np.asarray(sarosi_force(params, p / KPA_PER_BAR, k))
    resid = f - model
    direction = frame["direction"].to_numpy() if "direction" in frame else None

    fig, axes = plt.subplots(2, 2, figsize=(9, 6.5))
    panels = [
        (k, "contraction κ [%]"),
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
