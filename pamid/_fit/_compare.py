"""Several force models fitted to the same bench file and ranked per muscle.

:func:`compare_models` fits every model to every muscle of a file — for each model one
batched least-squares solve (:func:`pamid._fit._api.fit_least_squares`) whose lanes are
every muscle on all of its data *and* every muscle on every cross-validation fold — and
ranks the models per muscle:

* by the **cross-validated RMSE** on held-out data: whole trials are held out where a muscle
  has at least :data:`MIN_TRIALS_FOR_TRIAL_CV` trials, else whole curves
  (:func:`pamid._data._curves.find_curves`: a sweep at a held pressure, or an inflation or
  deflation at a held length), dealt round robin into ``k = min(n_folds, units)`` folds. A
  fold's fit is the muscle's lane with weight 0 on the fold's rows, so no held-out row
  touches the fit that predicts it; every row is held out exactly once, and the CV RMSE is
  √(Σ held-out squared error / n). The folds are the same for every model. A fold whose
  fit did not converge still predicts its rows (the error of the model's fitting procedure
  on that design); ``cv_folds_converged`` says how many did.
* by the **Bayesian information criterion** of the fit to all data,
  BIC = n·ln(SSE/n) + p·ln n (n rows, p constants, SSE the sum of squared residuals; the
  Gaussian log-likelihood at its maximum, up to a constant shared by all models of the
  same data: Schwarz 1978).

The best model of a muscle is the one of lowest CV RMSE among those whose fit to all data
converged; a model that did not converge there is never "best". Where a muscle cannot be
cross-validated (one curve and fewer than three trials) the best is the lowest BIC among
the converged models, and ``cv`` is None.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Sequence

import jax
import numpy as np
import pandas as pd

from .._data._bench import BenchData
from .._data._holdout import holdout_units
from .._errors import BenchDataError
from .._lanes._batch import FitData, map_lanes, pack_rows
from ._api import FitResult, bench_to_fit_data, fit_least_squares
from ._compare_options import BIC_FORMULA, MIN_TRIALS_FOR_TRIAL_CV, N_FOLDS
from ._spec import MODELS, ModelSpec, get_model


@dataclasses.dataclass(frozen=True, eq=False)
class FoldPlan:
    """The cross-validation folds of a bench file, shared by every model.

    Attributes:
        fold: (M, n_max) the fold in which each packed row is held out (−1 on padding),
            laid out as :func:`~pamid._fit._api.bench_to_fit_data` packs the rows.
        fold_of_row: the same, aligned with ``bench.frame``'s rows.
        n_folds: (M,) folds per muscle (0 where it cannot be cross-validated).
        kind: per muscle, "trials", "curves" or None (no cross-validation).
        n_units: (M,) held-out units (trials or curves) per muscle.
    """

    fold: np.ndarray
    fold_of_row: np.ndarray
    n_folds: np.ndarray
    kind: tuple[str | None, ...]
    n_units: np.ndarray

    @property
    def max_folds(self) -> int:
        return int(self.n_folds.max(initial=0))


def fold_plan(bench: BenchData, n_folds: int = N_FOLDS) -> FoldPlan:
    """Folds of whole trials (a muscle with ≥ 3 trials) or else whole curves, per muscle,
    from the file's one curve structure (``bench.curves``); ``k = min(n_folds, units)``
    folds, units dealt round robin in file order."""
    if n_folds < 2:
        raise ValueError("the cross-validation needs at least 2 folds")
    curves = bench.curves
    codes = pd.factorize(bench.frame["muscle"], sort=False)[0]
    m = len(bench.muscles)
    fold_of_row = np.full(len(codes), -1, dtype=np.int64)
    k_per, kinds, units_per = np.zeros(m, np.int64), [], np.zeros(m, np.int64)
    for i, rows in enumerate(_rows_per_muscle(codes, m)):
        unit, kind = holdout_units(curves.curve[rows], curves.trial[rows])
        n_units = int(unit.max(initial=-1)) + 1
        units_per[i] = n_units
        if n_units < 2:
            kinds.append(None)
            continue
        k = min(n_folds, n_units)
        fold_of_row[rows] = unit % k  # units round robin
        k_per[i] = k
        kinds.append(kind)
    packed = pack_rows(codes, (fold_of_row.astype(np.float64),), np.zeros(len(codes)),
                       n_muscles=m)
    fold = np.where(np.asarray(packed.w) > 0, np.asarray(packed.x[0]), -1).astype(np.int64)
    return FoldPlan(fold=fold, fold_of_row=fold_of_row, n_folds=k_per, kind=tuple(kinds),
                    n_units=units_per)


def _rows_per_muscle(codes: np.ndarray, m: int) -> list[np.ndarray]:
    order = np.argsort(codes, kind="stable")
    return np.split(order, np.cumsum(np.bincount(codes, minlength=m))[:-1])


def fold_lanes(data: FitData, plan: FoldPlan) -> FitData:
    """Every muscle's lane repeated 1 + K times (K = the most folds of any muscle): lane
    ``(m, 0)`` all its rows, lane ``(m, j)`` weight 0 on the rows of fold j − 1 (all rows
    again where muscle m has fewer than j folds: such lanes are not used)."""
    reps = 1 + plan.max_folds
    m, n = data.y.shape
    j = np.arange(reps)[None, :, None] - 1  # (1, reps, 1): −1 is the fit to all data
    keep = (plan.fold[:, None, :] != j) | (j < 0)
    w = np.asarray(data.w)[:, None, :] * keep
    # In NumPy, then onto the device: each jnp operation here was a compiled program of its
    # own, per shape, in every new process.
    rep = lambda a: jax.device_put(np.repeat(np.asarray(a), reps, axis=0))  # noqa: E731
    return FitData(x=tuple(rep(xi) for xi in data.x), y=rep(data.y),
                   w=jax.device_put(w.reshape(m * reps, n)), curve=rep(data.curve))


@dataclasses.dataclass(frozen=True, eq=False)
class ModelComparison:
    """One model fitted to every muscle, on all data and on every cross-validation fold.

    Attributes:
        spec: the model.
        fit: the fit to all data (one lane per muscle), as ``pamid fit`` reports it.
        fold_theta: (M, K, p) constants fitted on each fold's training rows (NaN for folds a
            muscle does not have).
        fold_converged: (M, K) whether each fold's fit converged (False where no fold).
        cv_sse: (M,) held-out squared error summed over the folds (NaN: no CV).
        cv_n: (M,) held-out rows (every row of a cross-validated muscle).
        bic: (M,) n·ln(SSE/n) + p·ln n of the fit to all data.
        max_error_N: (M,) largest |data − model| of the fit to all data.
    """

    spec: ModelSpec
    fit: FitResult
    fold_theta: np.ndarray
    fold_converged: np.ndarray
    cv_sse: np.ndarray
    cv_n: np.ndarray
    bic: np.ndarray
    max_error_N: np.ndarray

    @property
    def cv_rmse_N(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.sqrt(self.cv_sse / self.cv_n)

    def status(self, i: int) -> str:
        """The fit's per-muscle status code (``FitResult.status`` where pamid gives one)."""
        status_of = getattr(self.fit, "status_of", None)
        if status_of is not None:
            return str(status_of(i))
        return "converged" if bool(self.fit.converged[i]) else "not_converged"


@dataclasses.dataclass(frozen=True, eq=False)
class Comparison:
    """Models ranked per muscle; see the module text. It holds results only: ``to_dict()``
    is their plain-data view (the JSON of ``pamid compare --json``); the table and the
    figures are written by :mod:`pamid.report` (``comparison_table``, ``plot_comparison``,
    ``plot_cv_rmse``)."""

    muscles: tuple[str | None, ...]
    models: tuple[ModelComparison, ...]
    plan: FoldPlan
    skipped: tuple[tuple[str, str], ...] = ()  # (model, why) not fitted to this file
    source: str | None = None

    def ranking(self, i: int) -> list[int]:
        """Indices of the models for muscle ``i``, best first: the converged fits by CV
        RMSE (by BIC where the muscle has no CV), then the others by the same key."""
        def key(k):
            mc = self.models[k]
            score = mc.cv_rmse_N[i] if self.plan.kind[i] is not None else mc.bic[i]
            score = float(score) if np.isfinite(score) else np.inf
            return (not bool(mc.fit.converged[i]), score, k)

        return sorted(range(len(self.models)), key=key)

    def best(self, i: int) -> str | None:
        """The model of lowest CV RMSE among those converged on muscle ``i`` (lowest BIC
        where the muscle has no CV); None when no model converged there."""
        top = self.ranking(i)
        if not top:
            return None
        mc = self.models[top[0]]
        score = mc.cv_rmse_N[i] if self.plan.kind[i] is not None else mc.bic[i]
        return mc.spec.name if bool(mc.fit.converged[i]) and np.isfinite(score) else None

    def to_dict(self) -> dict:
        """The comparison as plain data (lists, floats, None for NaN): per muscle the models
        best first, with RMSE, CV RMSE and max error [N], BIC, ranks, status and constants;
        the ``pamid compare --json`` object."""
        out = []
        for i, muscle in enumerate(self.muscles):
            order = self.ranking(i)
            rank_cv = _ranks([self.models[k].cv_rmse_N[i] for k in range(len(self.models))])
            rank_bic = _ranks([self.models[k].bic[i] for k in range(len(self.models))])
            rows = []
            for k in order:
                mc = self.models[k]
                fit = mc.fit
                rows.append({
                    "model": mc.spec.name,
                    "n_params": mc.spec.n_params,
                    "n": int(fit.n[i]),
                    "rmse_N": _num(fit.rmse_N[i]),
                    "cv_rmse_N": _num(mc.cv_rmse_N[i]),
                    "max_abs_error_N": _num(mc.max_error_N[i]),
                    "bic": _num(mc.bic[i]),
                    "rank_cv": rank_cv[k],
                    "rank_bic": rank_bic[k],
                    "converged": bool(fit.converged[i]),
                    "status": mc.status(i),
                    "message": fit.message(i),
                    "cv_folds_converged": int(mc.fold_converged[i].sum()),
                    "params": {name: _num(fit.theta[i, j])
                               for j, name in enumerate(fit.param_names)},
                    "equation": mc.spec.source,
                })
            out.append({
                "muscle": muscle,
                "best": self.best(i),
                "cv": self.plan.kind[i],
                "cv_folds": int(self.plan.n_folds[i]),
                "cv_units": int(self.plan.n_units[i]),
                "models": rows,
            })
        return {
            "muscles": out,
            "models": [mc.spec.name for mc in self.models],
            "skipped": [{"model": name, "why": why} for name, why in self.skipped],
            "bic": BIC_FORMULA,
            "cv_rmse": "√(Σ squared error of every row, predicted by the fit on the other "
                       "folds / n); whole trials held out where a muscle has ≥ "
                       f"{MIN_TRIALS_FOR_TRIAL_CV} trials, else whole curves",
            "best": "lowest cv_rmse_N among the models converged on the muscle",
            "source": self.source,
        }


def _num(x):
    x = float(x)
    return x if np.isfinite(x) else None


def _ranks(values) -> list[int | None]:
    """1 for the lowest finite value, 2 for the next, …; None where not finite."""
    v = np.asarray([float(x) for x in values])
    order = [k for k in np.argsort(np.where(np.isfinite(v), v, np.inf), kind="stable")
             if np.isfinite(v[k])]
    ranks: list[int | None] = [None] * len(v)
    for r, k in enumerate(order, start=1):
        ranks[k] = r
    return ranks


@functools.cache
def _vmapped(predict: Callable) -> Callable:
    return jax.jit(jax.vmap(predict))


def predict_lanes(spec: ModelSpec, theta, x) -> np.ndarray:
    """The model of every lane at its own constants, in chunks of lanes."""
    name = spec.program_key
    return map_lanes(_vmapped(spec.predict), np.asarray(theta, dtype=np.float64), x,
                     cache_key=None if name is None else ("predict", *name))


def fit_with_folds(bench: BenchData, spec: ModelSpec, plan: FoldPlan, *,
                   solver: str = "gauss-newton", bounds=None) -> ModelComparison:
    """One model: all muscles on all data and on every fold, in one batched fit (within
    ``bounds``, as :func:`pamid.fit_least_squares` takes them, on every lane)."""
    data = bench_to_fit_data(bench, spec, curves=False)
    m, n = data.y.shape
    reps = 1 + plan.max_folds
    lanes = fold_lanes(data, plan)
    names = tuple(mu if bench.has_muscle_column else None for mu in bench.muscles)
    lane_fit = fit_least_squares(lanes, spec, solver=solver, intervals=("wald",), bounds=bounds,
                                 muscles=tuple(np.repeat(np.array(names, dtype=object), reps)),
                                 show="wald")  # ranked by errors: no interval is shown
    first = np.arange(m) * reps
    fit = _lanes_of(lane_fit, first, names)
    p = spec.n_params
    theta = np.asarray(lane_fit.theta).reshape(m, reps, p)
    ok = np.asarray(lane_fit.converged, bool).reshape(m, reps)
    has_fold = np.arange(reps - 1)[None, :] < plan.n_folds[:, None]
    fold_theta = np.where(has_fold[..., None], theta[:, 1:], np.nan)
    fold_ok = ok[:, 1:] & has_fold
    # Held-out error: each lane's prediction on the rows of its own fold only.
    pred = np.asarray(predict_lanes(spec, lane_fit.theta, lanes.x)).reshape(m, reps, n)
    w = np.asarray(data.w)
    held = (plan.fold[:, None, :] == np.arange(reps - 1)[None, :, None]) & has_fold[..., None]
    with np.errstate(invalid="ignore", over="ignore"):
        err = w[:, None, :] * (pred[:, 1:] - np.asarray(data.y)[:, None, :]) ** 2
        cv_sse = np.where(held, err, 0.0).sum(axis=(1, 2))
    cv_n = np.where(held, w[:, None, :], 0.0).sum(axis=(1, 2))
    cv_sse = np.where(plan.n_folds > 0, cv_sse, np.nan)
    with np.errstate(invalid="ignore"):
        max_error = np.where(w > 0, np.abs(pred[:, 0] - np.asarray(data.y)), 0.0).max(axis=1)
    n_rows = np.asarray(fit.n, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        bic = n_rows * np.log(np.asarray(fit.sse) / n_rows) + p * np.log(n_rows)
    return ModelComparison(spec=spec, fit=fit, fold_theta=fold_theta, fold_converged=fold_ok,
                           cv_sse=cv_sse, cv_n=cv_n, bic=bic, max_error_N=max_error)


def _lanes_of(result: FitResult, lanes: np.ndarray, names) -> FitResult:
    """The fit result of some lanes (the fits to all data) as a FitResult of its own."""
    changes = {}
    for f in dataclasses.fields(result):
        value = getattr(result, f.name)
        if isinstance(value, np.ndarray) and value.ndim >= 1 and len(value) == result.n_muscles:
            changes[f.name] = value[lanes]
        elif f.name == "messages":
            changes[f.name] = tuple(value[k] if k < len(value) else None for k in lanes)
        elif isinstance(value, (list, tuple)) and len(value) == result.n_muscles \
                and f.name not in ("param_names", "muscles"):
            changes[f.name] = type(value)(value[k] for k in lanes)
    changes["muscles"] = tuple(names)
    return dataclasses.replace(result, **changes)


def _missing_input(spec: ModelSpec, bench: BenchData) -> str | None:
    """Why a model cannot be fitted to the file (the input columns it lacks), else None."""
    missing = [c for c in spec.columns if c not in bench.frame]
    if not missing:
        return None
    return (f"the file gives no {', '.join(missing)} (the {spec.name} model takes "
            f"{', '.join(spec.columns)})")


def compare_models(bench: BenchData, models: Sequence | None = None, *,
                   n_folds: int = N_FOLDS, solver: str = "gauss-newton",
                   bounds: dict[str, tuple] | None = None,
                   progress: Callable[[str], None] | None = None) -> Comparison:
    """Fit every model to every muscle of ``bench`` and rank them per muscle (module text).

    Args:
        bench: a loaded bench file (:func:`pamid.load_bench`).
        models: model names (pamid's own, :data:`pamid._fit._spec.MODELS`),
            ``"path/file.py:Class"`` references, :class:`~pamid.ForceModel` classes or
            specs; default: every registered model. A model given here whose inputs the
            file lacks is an error (:class:`~pamid.BenchDataError`); of the default set it
            is skipped and listed in ``Comparison.skipped``.
        n_folds: most cross-validation folds per muscle (at least 2).
        solver: the least-squares solver (:func:`~pamid.fit_least_squares`).
        bounds: {model name: (lower, upper)} in place of those models' own physical bounds
            (as :func:`~pamid.fit_least_squares` takes them), for the fits to all data and
            to every fold alike.
        progress: called with a line of text before each model's fit.
    """
    explicit = models is not None
    refs = list(MODELS) if models is None else list(models)
    if not refs:
        raise ValueError("no models to compare")
    specs, skipped, seen = [], [], set()
    for ref in refs:
        spec = get_model(ref, bench.frame)
        if spec.name in seen:
            continue
        why = _missing_input(spec, bench)
        if why is not None:
            if explicit:
                spec.x_from_frame(bench.frame, bench.path)  # its error names the column
            skipped.append((spec.name, why))
            continue
        seen.add(spec.name)
        specs.append(spec)
    if not specs:
        raise BenchDataError(bench.path, "none of the models can be fitted to this file: "
                             + "; ".join(f"{n}: {w}" for n, w in skipped))
    plan = fold_plan(bench, n_folds)
    done = []
    for k, spec in enumerate(specs, start=1):
        if progress is not None:
            progress(f"model {k}/{len(specs)}: {spec.name} ({spec.n_params} constants), "
                     f"{len(bench.muscles)} muscle(s) × (all data + {plan.max_folds} folds)")
        done.append(fit_with_folds(bench, spec, plan, solver=solver,
                                   bounds=(bounds or {}).get(spec.name)))
    names = tuple(mu if bench.has_muscle_column else None for mu in bench.muscles)
    return Comparison(muscles=names, models=tuple(done), plan=plan, skipped=tuple(skipped),
                      source=str(bench.path))
