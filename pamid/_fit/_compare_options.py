"""The settings of ``pamid compare`` that its command-line help states: kept apart from
:mod:`pamid._fit._compare` so that building the parser imports nothing heavy."""

from .._data._holdout import MIN_TRIALS_FOR_TRIAL_CV  # noqa: F401 (the rule's threshold)

#: Cross-validation folds per muscle (at most; fewer where a muscle has fewer units).
N_FOLDS = 5
#: The Bayesian information criterion as ranked (Gaussian errors, σ² profiled out).
BIC_FORMULA = "n·ln(SSE/n) + p·ln(n)"
