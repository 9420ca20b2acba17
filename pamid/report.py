"""Writing results as a person reads them: JSON text, tables, NetCDF files and figures of a
fit, a posterior, a diagnosis, a model comparison and a decay posterior, as pamid's commands
write them.

The result objects (:class:`pamid.FitResult`, :class:`pamid.McmcResult`,
:class:`pamid.Diagnosis`, :class:`pamid.Comparison`, :class:`pamid.DecayPosterior`) hold
results only; their ``to_dict()`` (where they have one) is the plain-data view. Every
function here takes the result first::

    fit = pamid.fit_least_squares(bench)
    text = pamid.report.fit_json(fit, source="bench.csv")     # == json.dumps(fit.to_dict() | …)
    pamid.report.plot_fit(fit, bench, 0, "fit.png")           # muscle 0 of the bench fitted
    post = pamid.fit_mcmc(bench)
    pamid.report.plot_trace(post, 0, "trace.png")
    pamid.report.save_netcdf(post, "out/")                    # read back: pamid.load_inference_data
    d = pamid.diagnose(bench)
    print(pamid.report.diagnosis_report(d))
    c = pamid.compare_models(bench)
    print(pamid.report.comparison_table(c))
    dp = pamid.fit_decay_mcmc(pamid.load_decay("decays.csv"), key=jax.random.key(0))
    pamid.report.plot_decay_predictive(dp, dp.predictive(jax.random.key(1)), 0, "pred.png")

Figures: with a ``path`` the figure is written there (PNG unless the extension says else);
without one nothing is written and the figure is returned (a notebook shows it). The
posteriors' figures (ArviZ, pyplot; a decay posterior's too) are closed once saved and then
return None; the others return the figure either way. Forces are in N, the model's inputs
in the units of its columns (``pressure_kPa``, ``contraction_pct``, …), decays' residuals in
rad. Every file is written atomically, as :mod:`pamid.io` writes (beside its place, then
renamed: it appears whole or not at all). ``write_*_plots`` write the set of figures of
``pamid fit --out``, ``pamid fit --method mcmc --out`` and ``pamid compare --out`` into a
folder and return the file names.
"""

from ._report._compare import (
    comparison_table,
    plot_comparison,
    plot_cv_rmse,
    write_comparison_plots,
)
from ._report._decays import plot_decay_predictive
from ._report._diagnosis import (
    diagnosis_report,
    plot_diagnosis_residuals,
    plot_diagnosis_time_order,
)
from ._report._fit import (
    fit_json,
    plot_fit,
    plot_residuals,
    plot_rmse_histogram,
    write_fit_plots,
)
from ._report._mcmc import (
    plot_pair,
    plot_predictive,
    plot_trace,
    save_netcdf,
    write_mcmc_plots,
)
from ._report._pooled import (
    plot_pooled_lomo,
    plot_prediction,
    pooled_table,
    prediction_table,
)

__all__ = [
    # A least-squares fit (FitResult): its JSON text and its figures.
    "fit_json", "plot_fit", "plot_residuals", "plot_rmse_histogram", "write_fit_plots",
    # A posterior (McmcResult): NetCDF files and figures.
    "plot_pair", "plot_predictive", "plot_trace", "save_netcdf", "write_mcmc_plots",
    # A decay posterior (DecayPosterior): each trial against its posterior predictive.
    "plot_decay_predictive",
    # A diagnosis (Diagnosis): the report and the residual before and after.
    "diagnosis_report", "plot_diagnosis_residuals", "plot_diagnosis_time_order",
    # A model comparison (Comparison): the table and figures.
    "comparison_table", "plot_comparison", "plot_cv_rmse", "write_comparison_plots",
    # A pooled comparison (PooledComparison) and a predicted muscle (MusclePrediction).
    "plot_pooled_lomo", "plot_prediction", "pooled_table", "prediction_table",
]
