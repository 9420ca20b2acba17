"""A decay posterior (:class:`pamid.DecayPosterior`) drawn: each trial's recorded decay
against its posterior predictive (:class:`pamid.DecayPredictive`), as ``pamid check-decays
--mcmc --out`` draws it."""

from __future__ import annotations

import numpy as np

from ._mcmc import _finish


def plot_decay_predictive(result, pred, i: int = 0, path=None, title: str | None = None,
                          record=None):
    """Trial ``i`` of a decay posterior ``result`` (:func:`pamid.fit_decay_mcmc`) against
    its posterior predictive ``pred`` (``result.predictive(key)``). Top: the recorded
    samples of the fitted window with the 95% predictive band, in degrees; bottom: the
    residuals about the posterior-mean prediction, with the band. ``record``: optionally
    the whole (time_s, angle_rad) of the trial, drawn faintly. The title says what share of
    the samples lies inside the band. Saved to ``path`` (PNG) if given, else returned."""
    import matplotlib.pyplot as plt

    on = pred.mask[i]
    t, y = pred.time_s[i, on], pred.observed_rad[i, on]
    lo, hi = pred.band[i, 0, on], pred.band[i, 1, on]
    centre = pred.mean_rad[i].mean(axis=0)[on]
    fig, (ax, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True,
                                  gridspec_kw={"height_ratios": [2, 1]})
    if record is not None:
        ax.plot(record[0], np.degrees(record[1]), color="0.75", lw=0.6, label="record")
    ax.fill_between(t, np.degrees(lo), np.degrees(hi), color="C1", alpha=0.35,
                    label="95% posterior predictive")
    ax.plot(t, np.degrees(y), ".", ms=1.2, color="C0", label="fitted samples")
    ax.set_ylabel("angle [deg]")
    ax.legend(loc="upper right", fontsize=8)
    cov = pred.coverage()[i]
    ax.set_title(title or f"trial {result.trials[i]}: {cov:.1%} of samples inside the band")
    ax2.fill_between(t, np.degrees(lo - centre), np.degrees(hi - centre), color="C1",
                     alpha=0.35)
    ax2.plot(t, np.degrees(y - centre), ".", ms=1.2, color="C0")
    ax2.axhline(0.0, color="k", lw=0.5)
    ax2.set_ylabel("residual [deg]")
    ax2.set_xlabel("time [s]")
    fig.tight_layout()
    return _finish(fig, path, dpi=110)
