"""Inference for least-squares constants: the one rank criterion (``_rank``), the one
covariance s²·(JᵀJ)⁻¹ (``_covariance``), the Wald interval (``_wald``), and the Student-t
quantile and normal tail that it and the fit's tests use (``_distributions``, without
SciPy). Pure NumPy / JAX math on Jacobians and residuals; it knows nothing of models, files
or solvers, and every package that fits something takes its covariance from here
(docs/architecture.md)."""

from ._covariance import (
    covariance,
    gram_inverse,
    residual_variance,
    scale_covariance,
    standard_errors,
    unscaled_covariance,
)
from ._distributions import normal_upper_tail
from ._rank import (
    NULL_SHARE,
    RANK_PIVOT,
    RANK_RTOL,
    determined,
    null_direction,
    numerical_rank,
    scaled_svd,
    undetermined,
)
from ._wald import cut_at_bounds, t_critical, wald, wald_interval

__all__ = [
    "NULL_SHARE", "RANK_PIVOT", "RANK_RTOL", "covariance", "cut_at_bounds", "determined",
    "gram_inverse", "normal_upper_tail",
    "null_direction", "numerical_rank", "residual_variance", "scale_covariance", "scaled_svd",
    "standard_errors", "t_critical", "undetermined", "unscaled_covariance", "wald",
    "wald_interval",
]
