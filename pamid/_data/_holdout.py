"""What cross-validation holds out whole: the one rule of ``pamid diagnose`` and
``pamid compare``, on the curves and trials of :func:`pamid._data._curves.find_curves`.

Only NumPy here: the command line's help states the rule, and building the parser must not
import the data layer.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MIN_TRIALS_FOR_TRIAL_CV", "holdout_units"]

#: A muscle with at least this many trials is cross-validated on held-out whole trials,
#: otherwise on held-out whole curves (:func:`holdout_units`).
MIN_TRIALS_FOR_TRIAL_CV = 3


def holdout_units(curve: np.ndarray, trial: np.ndarray) -> tuple[np.ndarray, str]:
    """What cross-validation holds out whole, for one muscle's rows: its trials where it has
    at least :data:`MIN_TRIALS_FOR_TRIAL_CV` (a leftover shared by a trial's curves — a
    transient, a softening, the trial's own zero — is then never learned from the trial
    itself), else its curves. Returns a dense unit id per row (0, 1, …) and "trials" or
    "curves". Used by ``pamid diagnose`` and ``pamid compare`` alike."""
    by_trial = np.unique(trial, return_inverse=True)[1]
    if len(by_trial) and int(by_trial.max()) + 1 >= MIN_TRIALS_FOR_TRIAL_CV:
        return by_trial, "trials"
    return np.unique(curve, return_inverse=True)[1], "curves"
