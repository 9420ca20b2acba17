"""The low-level tier: pamid's model registry, batched least-squares engine, starts, interval
estimators and sampler pieces, for code that builds on them (benchmarks, new workflows).

:func:`pamid.fit_least_squares`, :func:`pamid.fit_mcmc` and :func:`pamid.diagnose` put these
pieces together; here they are one by one, for a workflow pamid does not have or to time one
stage alone. The names are stable, as those of ``pamid`` are, but lower-level: they take
packed batches (:class:`pamid.FitData`, arrays (M, n) of M muscles by n samples, weight 0 on
padding; :func:`pamid.bench_to_fit_data`, :func:`pamid.pack_muscles`) and a model's
:class:`ModelSpec`, return NumPy arrays with a leading muscle axis (the ``sarosi_*`` kernels:
JAX arrays), and check less than the workflows do. ::

    spec = pamid.engine.get_model("sarosi")
    data = pamid.bench_to_fit_data(pamid.load_bench("bench.csv"), spec)
    sol = pamid.engine.least_squares(spec, data)  # a Solution: params, result, steps …
    theta = sol.params
    sse, jtj_inv, corr, n, full_rank = pamid.engine.statistics(spec, theta, data)
    se, lower, upper, s2, dof = pamid.engine.wald_intervals(theta, jtj_inv, sse, n)
    cr3 = pamid.engine.correlated_intervals(spec, data, theta, "cluster")

* Models: :func:`get_model` (a name of :func:`model_names`, a ``file.py:Class``, a
  :class:`pamid.ForceModel`) gives the :class:`ModelSpec` the engine fits; a spec with
  ``written_out=False`` (``dataclasses.replace``) is fitted by the generic solvers, without
  the written-out kernels registered for its model class.
* Least squares: :func:`least_squares`, the one entry (one compiled call for the batch,
  from the model's start or ``theta0``, within ``bounds``, with ``weights``, constants held
  by a ``mask``; the solvers ``"gauss-newton"``, ``"levenberg-marquardt"``,
  ``"variable-projection"``, ``"jaxopt-levenberg-marquardt"``,
  ``"projected-levenberg-marquardt"`` (pamid's own loop, which bounds and masks run) or a
  solver value), which returns a :class:`Solution`
  (constants, a result code per lane of :data:`RESULT_NAMES`, steps; the statistics where
  asked); :func:`solve`, the same as the tuple (theta, converged, steps); :func:`statistics`;
  :func:`find_curves` (the curve structure the bootstrap and the cluster intervals group
  by); :func:`use_disk_caches` (the compiled programs kept on disk, as the command keeps
  them); :func:`padded_rows` (the size class of rows a batch is packed to: files of one
  class run the same compiled programs).
* Sárosi eq. 2.1's written-out kernels: the default start :func:`sarosi_fast_start`, the
  solver :func:`sarosi_gauss_newton`, variable projection (:func:`sarosi_variable_projection`,
  its start :func:`sarosi_variable_projection_start`, the fit at a fixed a3
  :func:`sarosi_fit_at_a3`); inputs (pressure_bar, contraction_pct), force in N.
* Intervals: Wald, profile likelihood, the whole-curve bootstrap
  (:func:`wald_intervals`, :func:`profile_intervals`, :func:`bootstrap_intervals`), and the
  sandwich intervals that hold under correlated residuals (:func:`correlated_intervals`,
  from :func:`jacobian_residuals`, :func:`cluster_covariance` of the kinds
  :data:`CLUSTER_KINDS`, :func:`hac_covariance` and :func:`sandwich_intervals`), with
  :func:`lag1_autocorrelation` and the AR(1) noise of coverage studies, :func:`ar1_noise`.
* Sampling: the log-posterior :func:`pamid.fit_mcmc` samples (:func:`walker_log_prob`,
  over the walkers of one muscle :func:`ensemble_log_prob`; in NumPy for Sárosi
  :func:`numpy_log_prob`), its start :func:`initial_walkers`, its stacked sampler
  :class:`StackedSampler` (moves: :data:`DE_FRACTION` differential evolution, the rest
  stretch; ``sampler="auto"`` is :data:`AUTO_SAMPLER`) and emcee's autocorrelation time
  :func:`integrated_time`. The ensemble kernel itself is in ``pamid`` (``ensemble_step``).
* Diagnosis: :class:`StaticDiagnosisProblem`, a bench file prepared as
  :func:`pamid.diagnose` prepares it (packed data, covariates, the candidate effects'
  feature columns and folds), whose ``evaluate(sets)`` refits candidate sets (set × muscle
  × fold, one batched Levenberg–Marquardt call of at most :data:`DIAGNOSIS_MAX_STEPS`
  steps per lane); :func:`diagnosis_call_lane_samples`, a block within which the refits
  run in calls of another number of lane-samples (speed and memory, not results).
* Effects as models that wrap a model (each one class in its effect's module): a force law
  with a transform of its inputs, :class:`Compliance` (F = F_base(p, κ + c·F), solved as a
  fixed point) and :class:`SensorOffset` (F = F_base(p + δ, κ)), subclasses of
  :class:`InputTransform`; with the columns of a feature effect, :class:`Hysteresis`,
  :class:`Temperature`, :class:`RelativeTemperature`, :class:`Drift`,
  :class:`ViscousDamping`, :class:`Transient`, :class:`Softening`, :class:`Covariate`,
  subclasses of :class:`FeatureEffect` (their ``features`` make the columns, the last
  input); :class:`LinearTerms`, anonymous slots for several effects' columns;
  :func:`with_effects`, the model a diagnosis refits (every transform, then the slots); a
  free decay's :class:`CoulombFriction` and :class:`DecayDrift`, subclasses of
  :class:`EffectWrapper` around the linear oscillator, and :func:`decay_model`, the
  oscillator in both. Each is a :class:`ModelSpec`: ``Compliance.wrap(get_model("sarosi"),
  implicit=True)`` is fitted by :func:`least_squares`.
* Pooled models: the hierarchical Bayesian Bolen law of ``pamid.compare_pooled(...,
  bayes=key)`` on stacked data sets (:func:`fit_hierarchical`, one ensemble each) and a new
  muscle's posterior predictive interval (:func:`hierarchical_predictive`).
"""

from ._data._curves import Curves, find_curves
from ._decays._coulomb import decay_model
from ._diagnose._static import MAX_ITER as DIAGNOSIS_MAX_STEPS
from ._diagnose._static import StaticProblem as StaticDiagnosisProblem
from ._diagnose._static import call_lane_samples as diagnosis_call_lane_samples
from ._effects._compliance import Compliance
from ._effects._coulomb_friction import CoulombFriction
from ._effects._covariate import Covariate
from ._effects._drift import DecayDrift, Drift
from ._effects._hysteresis import Hysteresis
from ._effects._model import with_effects
from ._effects._sensor_offset import SensorOffset
from ._effects._softening import Softening
from ._effects._temperature import RelativeTemperature, Temperature
from ._effects._transient import Transient
from ._effects._viscous_damping import ViscousDamping
from ._effects._wrappers import EffectWrapper, FeatureEffect, InputTransform, LinearTerms
from ._fit._correlated import (
    CLUSTER_KINDS,
    ar1_noise,
    cluster_covariance,
    correlated_intervals,
    hac_covariance,
    jacobian_residuals,
    lag1_autocorrelation,
    sandwich_intervals,
)
from ._fit._intervals import bootstrap as bootstrap_intervals
from ._fit._intervals import profile as profile_intervals
from ._fit._intervals import wald as wald_intervals
from ._fit._least_squares import least_squares, solve, statistics
from ._fit._spec import ModelSpec, get_model, model_names
from ._lanes._batch import padded_rows
from ._lanes._export_cache import use_disk_caches
from ._pooled._hierarchical import fit_hierarchical
from ._pooled._hierarchical import predictive_interval as hierarchical_predictive
from ._sampling._mcmc import (
    AUTO_SAMPLER,
    DE_FRACTION,
    StackedSampler,
    ensemble_log_prob,
    initial_walkers,
    integrated_time,
    walker_log_prob,
)
from ._sampling._posterior import numpy_log_prob
from ._solvers import (
    RESULT_NAMES,
    Solution,
    sarosi_fast_start,
    sarosi_fit_at_a3,
    sarosi_gauss_newton,
    sarosi_variable_projection,
    sarosi_variable_projection_start,
)

__all__ = [
    # The model registry.
    "ModelSpec", "get_model", "model_names",
    # Batched least squares (the one entry and what it returns; ``solve``, its tuple), the
    # curve structure, the disk caches.
    "least_squares", "Solution", "RESULT_NAMES", "solve", "statistics", "Curves",
    "find_curves", "use_disk_caches", "padded_rows",
    # Sárosi eq. 2.1's written-out kernels: starts and solvers.
    "sarosi_fast_start", "sarosi_gauss_newton", "sarosi_fit_at_a3",
    "sarosi_variable_projection", "sarosi_variable_projection_start",
    # Intervals.
    "wald_intervals", "profile_intervals", "bootstrap_intervals", "CLUSTER_KINDS",
    "ar1_noise", "cluster_covariance", "correlated_intervals", "hac_covariance",
    "jacobian_residuals", "lag1_autocorrelation", "sandwich_intervals",
    # Sampling.
    "AUTO_SAMPLER", "DE_FRACTION", "StackedSampler", "ensemble_log_prob", "initial_walkers",
    "integrated_time", "numpy_log_prob", "walker_log_prob",
    # Diagnosis, and the effects as models that wrap a model.
    "DIAGNOSIS_MAX_STEPS", "diagnosis_call_lane_samples", "StaticDiagnosisProblem",
    "EffectWrapper", "InputTransform", "FeatureEffect", "LinearTerms", "Compliance",
    "SensorOffset", "Hysteresis", "Temperature",
    "RelativeTemperature", "Drift", "ViscousDamping", "Transient", "Softening", "Covariate",
    "with_effects", "CoulombFriction", "DecayDrift", "decay_model",
    # Pooled models.
    "fit_hierarchical", "hierarchical_predictive",
]
