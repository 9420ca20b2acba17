"""Does one set of constants hold for every resting length? The ``length`` study.

Sárosi (thesis, after eq. 2.1) states that eq. 2.1 holds "for any diameter and length" of a
muscle. Across the muscles of one file that differ in resting length l0 this is a testable
claim. :func:`length_study` fits three descriptions of the same rows and compares them:

(a) ``per_muscle``: one set of constants per muscle (M·p constants) — no claim at all;
(b) ``smooth_linear`` / ``smooth_log``: one pooled model whose every constant is a smooth
    function of l0, θ_j(l0) = α_j + β_j·g(l0), with g = (l0 − l0_ref)/(100 mm) or
    g = ln(l0/l0_ref) (2p constants; the form is chosen by cross-validation);
(c) ``pooled``: one set of constants for all lengths (p constants) — Sárosi's claim.

Each is scored by its cross-validated RMSE on held-out whole trials (the one hold-out rule of
:func:`pamid._data._holdout.holdout_units`, folds of :func:`pamid._fit._compare.fold_plan`,
the same rows held out in every option) and by BIC = n·ln(SSE/n) + k·ln n (one noise level
for all rows). The pooled options are also scored leave-one-length-out: each muscle
predicted by the fit to the other muscles (what a smooth law in l0 is for: a length that
was not tested).

The best option is the lowest BIC among those whose CV RMSE is within
:data:`TIE_FRACTION` of the lowest: a richer description must predict held-out trials
better, not only fit better. Every fit is pamid's batched least squares
(:func:`pamid.fit_least_squares`): the per-muscle fits and all fold fits of each option are
lanes of one solve.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._data._bench import BenchData
from .._errors import BenchDataError
from .._fit._api import fit_least_squares
from .._fit._compare import FoldPlan, fit_with_folds, fold_plan, predict_lanes
from .._fit._spec import ModelSpec, get_model
from .._inference import residual_variance, unscaled_covariance, wald_interval
from .._lanes._batch import FitData

#: Options whose CV RMSE is within this fraction of the lowest are tied; of tied options the
#: one of lowest BIC is chosen (the fewest constants, unless more fit much better).
TIE_FRACTION = 0.01
#: The forms of the smooth l0 dependence tried: g = (l0 − l0_ref)/L0_UNIT_MM or ln(l0/l0_ref).
FORMS = ("linear", "log")
L0_UNIT_MM = 100.0
#: A smooth model needs at least this many distinct lengths (two points fix any line).
MIN_LENGTHS = 3


@dataclasses.dataclass(frozen=True)
class LengthOption:
    """One description of the file's muscles and how well it does.

    Attributes:
        name: "per_muscle", "smooth_linear", "smooth_log" or "pooled".
        n_params: constants fitted (M·p, 2p or p).
        rmse_N: RMSE of the fit to all rows.
        cv_rmse_N: RMSE of every row predicted by the fit that did not see its trial.
        loo_length_rmse_N: RMSE of every row predicted by the fit to the *other* muscles
            (None for ``per_muscle``, which cannot predict a muscle it has not seen).
        bic: n·ln(SSE/n) + k·ln n of the fit to all rows.
        max_error_N: largest |data − model| of the fit to all rows.
        converged: whether the fit to all rows converged (every muscle's, for per_muscle).
        cv_rmse_by_muscle_N: the CV RMSE of each muscle's rows.
    """

    name: str
    n_params: int
    rmse_N: float
    cv_rmse_N: float
    loo_length_rmse_N: float | None
    bic: float
    max_error_N: float
    converged: bool
    cv_rmse_by_muscle_N: tuple[float, ...]


@dataclasses.dataclass(frozen=True)
class ConstantVsLength:
    """The l0 dependence of one constant, θ(l0) = value + slope·g(l0), in the chosen form.

    Attributes:
        name, unit: the constant and its unit; ``slope_unit`` that of the slope.
        value, value_ci95: θ at ``l0_ref_mm`` (Wald 95 %, Student-t) from the smooth fit.
        slope, slope_ci95: β from the smooth fit, Wald 95 %.
        slope_ci95_cluster: β's cluster-robust interval (CR3 by curve): holds when the
            residual is correlated within curves; None where it cannot be given.
        slope_between, slope_ci95_between: β from the per-muscle constants regressed on
            g(l0) (ordinary least squares over the M muscles, t on M − 2 dof): its interval
            includes the muscles' own scatter around a smooth law, which the pooled fit's
            intervals do not.
        per_muscle: the constant of each muscle's own fit, in the order of the study's muscles.
    """

    name: str
    unit: str
    slope_unit: str
    value: float
    value_ci95: tuple[float, float]
    slope: float
    slope_ci95: tuple[float, float]
    slope_ci95_cluster: tuple[float, float] | None
    slope_between: float
    slope_ci95_between: tuple[float, float]
    per_muscle: tuple[float, ...]


@dataclasses.dataclass(frozen=True)
class LengthStudy:
    """What :func:`length_study` found; :meth:`to_dict` is its JSON.

    Attributes:
        model: the force model's name; ``equation`` what it fits.
        muscles, l0_mm: the muscles and their resting lengths.
        n: rows; ``cv``: what was held out ("trials" or "curves"); ``n_folds``: folds.
        options: every option (:class:`LengthOption`), in the order a, b-linear, b-log, c.
        form: the smooth form chosen by CV ("linear" or "log"); ``l0_ref_mm`` its reference.
        dependence: per constant, its l0 dependence in that form (:class:`ConstantVsLength`).
        best: the chosen option (module text); ``verdict``: the finding in words.
    """

    model: str
    equation: str
    muscles: tuple[str, ...]
    l0_mm: tuple[float, ...]
    n: int
    cv: str
    n_folds: int
    options: tuple[LengthOption, ...]
    form: str
    l0_ref_mm: float
    dependence: tuple[ConstantVsLength, ...]
    best: str
    verdict: str

    def option(self, name: str) -> LengthOption:
        return next(o for o in self.options if o.name == name)

    def constants_at(self, l0_mm) -> dict[str, np.ndarray]:
        """The constants of the smooth model at the resting lengths ``l0_mm`` (mm), by
        name: value + slope·g(l0) in the chosen form (:func:`l0_feature`)."""
        g = l0_feature(l0_mm, self.form, self.l0_ref_mm)
        return {dep.name: dep.value + dep.slope * g for dep in self.dependence}

    def to_dict(self) -> dict:
        return _json(dataclasses.asdict(self) | {
            "tie_fraction": TIE_FRACTION,
            "bic_formula": "n·ln(SSE/n) + k·ln n (k constants, one noise level for all rows)",
            "g_of_l0": (f"(l0 − {self.l0_ref_mm:.4g} mm)/{L0_UNIT_MM:g} mm" if self.form == "linear"
                        else f"ln(l0/{self.l0_ref_mm:.4g} mm)"),
        })


def _json(value):
    if isinstance(value, dict):
        return {k: _json(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json(v) for v in value]
    if isinstance(value, (float, np.floating)):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.bool_):
        return bool(value)
    return value


def l0_feature(l0_mm, form: str, l0_ref_mm: float):
    """g(l0) of the smooth model: (l0 − l0_ref)/100 mm ("linear") or ln(l0/l0_ref) ("log")."""
    l0_mm = np.asarray(l0_mm, dtype=np.float64)
    if form == "linear":
        return (l0_mm - l0_ref_mm) / L0_UNIT_MM
    if form == "log":
        return np.log(l0_mm / l0_ref_mm)
    raise ValueError(f"unknown form {form!r}; choose one of {FORMS}")


def slope_unit(unit: str, form: str) -> str:
    """The unit of β_j for a constant of unit ``unit`` in the given form."""
    return f"{unit} per 100 mm" if form == "linear" else f"{unit} per e-fold of l0"


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class SmoothInL0(ModelSpec):
    """``base`` with every constant θ_j replaced by α_j + β_j·g (2p constants, α first, then
    β), its inputs those of ``base`` then g = :func:`l0_feature` of the row's l0 (the form is
    the caller's: the fit does not depend on it, so one spec, compiled once, serves both).
    A model that wraps a model: made by :func:`smooth_in_l0_spec`."""

    base: ModelSpec

    def predict(self, theta, x):
        *inputs, g = x
        p = self.base.n_params
        constants = theta[..., :p] + theta[..., p:] * g[..., None]
        return self.base.predict(constants, tuple(inputs))

    def start(self, x, y, w):  # the base model's start on the pooled rows, no slope
        alpha = self.base.start(tuple(x[:-1]), y, w)
        return jnp.concatenate([alpha, jnp.zeros_like(alpha)], axis=-1)

    def to_x(self, *cols):
        return (*self.base.to_x(*cols[:-1]), cols[-1])


@functools.cache
def smooth_in_l0_spec(base: ModelSpec) -> SmoothInL0:
    """:class:`SmoothInL0` of ``base``: one spec per base model, so that its compiled
    programs are reused."""
    slopes = tuple(f"{n}_slope" for n in base.param_names)
    return SmoothInL0(
        base=base,
        name=f"{base.name}_smooth_in_l0",
        param_names=base.param_names + slopes,
        param_units={**base.param_units,
                     **{s: f"{base.param_units[n]} per unit of g(l0)"
                        for s, n in zip(slopes, base.param_names, strict=True)}},
        units={**base.units, "l0": "mm"},
        columns=(*base.columns, "l0_feature"),
        source=f"{base.source}, every constant α + β·g(l0)",
    )


@dataclasses.dataclass(frozen=True)
class _Pooled:
    """One pooled option fitted on every lane: all rows, each fold's training rows, each
    muscle left out."""

    theta: np.ndarray  # (L, k)
    fit: object  # the FitResult of every lane
    sse: float
    n: int
    held_sq: np.ndarray  # (N,) squared error of each row predicted by its fold's fit
    loo_sq: np.ndarray  # (N,) ... by the fit without its muscle
    resid_all: np.ndarray  # (N,) residual of the fit to all rows


def _pooled_fit(spec: ModelSpec, x, y, curve, fold, muscle, k_folds: int, m: int,
                level: float) -> _Pooled:
    n = len(y)
    masks = [np.ones(n)] + [(fold != j).astype(float) for j in range(k_folds)] + [
        (muscle != i).astype(float) for i in range(m)]
    w = np.stack(masks)
    lanes = len(masks)
    data = FitData(
        x=tuple(jnp.asarray(np.broadcast_to(np.asarray(xi, np.float64), (lanes, n)))
                for xi in x),
        y=jnp.asarray(np.broadcast_to(y, (lanes, n))),
        w=jnp.asarray(w),
        curve=jnp.asarray(np.broadcast_to(curve, (lanes, n))),
    )
    solver = "gauss-newton" if spec.kernels is not None else "levenberg-marquardt"
    fit = fit_least_squares(data, spec, solver=solver, intervals=("wald", "cluster"),
                            level=level)
    pred = np.asarray(predict_lanes(spec, fit.theta, data.x))
    rows = np.arange(n)
    held = pred[1 + fold, rows]
    loo = pred[1 + k_folds + muscle, rows]
    return _Pooled(theta=np.asarray(fit.theta), fit=fit, sse=float(fit.sse[0]), n=n,
                   held_sq=(held - y) ** 2, loo_sq=(loo - y) ** 2, resid_all=y - pred[0])


def _predict_rows(spec: ModelSpec, theta_rows, x) -> np.ndarray:
    """The model at each row's own constants (``theta_rows`` (N, p)), elementwise."""
    return np.asarray(spec.predict(jnp.asarray(theta_rows), tuple(jnp.asarray(xi) for xi in x)))


def _bic(sse: float, n: int, k: int) -> float:
    return n * math.log(sse / n) + k * math.log(n)


def _by_muscle(sq: np.ndarray, muscle: np.ndarray, m: int) -> tuple[float, ...]:
    return tuple(float(np.sqrt(np.mean(sq[muscle == i]))) for i in range(m))


def length_study(bench: BenchData, model="sarosi", *, n_folds: int = 5,
                 forms: tuple[str, ...] = FORMS, level: float = 0.95) -> LengthStudy:
    """Compare one fit per muscle, constants smooth in l0 and one set for every length, by
    cross-validated RMSE on held-out whole trials and BIC (module text).

    Args:
        bench: a bench file with at least :data:`MIN_LENGTHS` muscles of distinct ``l0_mm``
            (a column or ``load_bench(..., l0_mm=)``), each with at least two trials or
            curves to hold out.
        model: the force model (a name, a :class:`~pamid.ForceModel` or a spec); Sárosi
            eq. 2.1 by default.
        n_folds: most cross-validation folds per muscle.
        forms: the smooth forms to try (:data:`FORMS`).
        level: the confidence level of every interval (the constants', their slopes', and
            the between-muscle slopes'; the JSON keeps the names ``*_ci95``).

    Raises:
        BenchDataError: fewer than three distinct lengths, a muscle without l0, or a muscle
            that cannot be cross-validated.
    """
    spec = get_model(model, bench.frame)
    muscles = tuple(bench.muscles)
    m = len(muscles)
    l0 = np.array([np.nan if bench.l0_mm.get(mu) is None else float(bench.l0_mm[mu])
                   for mu in muscles])
    if np.isnan(l0).any():
        raise BenchDataError(bench.path, "the length study needs each muscle's resting length "
                             "(an l0_mm column)", column="l0_mm")
    if len(np.unique(l0)) < MIN_LENGTHS:
        raise BenchDataError(bench.path, f"the length study needs at least {MIN_LENGTHS} "
                             f"muscles of distinct l0_mm; the file has {len(np.unique(l0))} "
                             "distinct length(s)", column="l0_mm")
    if not forms or any(f not in FORMS for f in forms):
        raise ValueError(f"forms must be some of {FORMS}, not {forms!r}")
    plan: FoldPlan = fold_plan(bench, n_folds)
    if np.any(plan.n_folds < 2):
        bad = muscles[int(np.flatnonzero(plan.n_folds < 2)[0])]
        raise BenchDataError(bench.path, f"muscle '{bad}' has fewer than two trials or curves: "
                             "it cannot be cross-validated, so the length study cannot compare "
                             "the options on held-out data", column="trial")
    frame = bench.frame
    muscle = pd.Categorical(frame["muscle"], categories=list(muscles)).codes.astype(np.int64)
    y = frame["force_N"].to_numpy(np.float64)
    n = len(y)
    fold = plan.fold_of_row
    k_folds = plan.max_folds
    # A cluster (curve) id unique over the pooled rows.
    curves = bench.curves.curve
    curve = pd.factorize(pd.Series(muscle) * (int(curves.max()) + 1) + curves)[0]
    x_base = spec.x_from_frame(frame, bench.path)
    l0_row = l0[muscle]
    l0_ref = float(np.exp(np.mean(np.log(l0))))  # geometric mean of the muscles' lengths

    # (a) one fit per muscle, all folds as lanes of one solve.
    per = fit_with_folds(bench, spec, plan)
    sse_a = float(np.sum(per.fit.sse))
    # Held-out squared errors row by row: each muscle's fold fits predict its fold's rows.
    fold_theta = np.nan_to_num(per.fold_theta[muscle, np.maximum(fold, 0)])
    cv_sq_a = (_predict_rows(spec, fold_theta, x_base) - y) ** 2
    pred_all_a = _predict_rows(spec, per.fit.theta[muscle], x_base)
    options = [LengthOption(
        name="per_muscle", n_params=m * spec.n_params, rmse_N=math.sqrt(sse_a / n),
        cv_rmse_N=float(np.sqrt(np.mean(cv_sq_a))), loo_length_rmse_N=None,
        bic=_bic(sse_a, n, m * spec.n_params),
        max_error_N=float(np.max(np.abs(pred_all_a - y))),
        converged=bool(np.all(per.fit.converged)),
        cv_rmse_by_muscle_N=_by_muscle(cv_sq_a, muscle, m))]

    # (b) constants smooth in l0, each form; (c) one set for every length.
    s_spec = smooth_in_l0_spec(spec)
    smooth = {form: _pooled_fit(s_spec, (*x_base, l0_feature(l0_row, form, l0_ref)), y, curve,
                                fold, muscle, k_folds, m, level) for form in forms}
    pooled = _pooled_fit(spec, x_base, y, curve, fold, muscle, k_folds, m, level)
    for name, k, fit in ([(f"smooth_{f}", 2 * spec.n_params, smooth[f]) for f in forms]
                         + [("pooled", spec.n_params, pooled)]):
        options.append(LengthOption(
            name=name, n_params=k, rmse_N=math.sqrt(fit.sse / n),
            cv_rmse_N=float(np.sqrt(np.mean(fit.held_sq))),
            loo_length_rmse_N=float(np.sqrt(np.mean(fit.loo_sq))),
            bic=_bic(fit.sse, n, k), max_error_N=float(np.max(np.abs(fit.resid_all))),
            converged=bool(fit.fit.converged[0]),
            cv_rmse_by_muscle_N=_by_muscle(fit.held_sq, muscle, m)))

    form = min(forms, key=lambda f: next(o.cv_rmse_N for o in options
                                         if o.name == f"smooth_{f}"))
    dependence = _dependence(spec, form, smooth[form].fit, per.fit.theta,
                             l0_feature(l0, form, l0_ref), level)
    contenders = [o for o in options if o.converged and o.name in
                  ("per_muscle", f"smooth_{form}", "pooled")]
    best_cv = min(o.cv_rmse_N for o in contenders)
    tied = [o for o in contenders if o.cv_rmse_N <= best_cv * (1 + TIE_FRACTION)]
    best = min(tied, key=lambda o: o.bic).name
    return LengthStudy(
        model=spec.name, equation=spec.source, muscles=muscles, l0_mm=tuple(map(float, l0)),
        n=n, cv=str(plan.kind[0]), n_folds=int(k_folds), options=tuple(options), form=form,
        l0_ref_mm=l0_ref, dependence=dependence, best=best,
        verdict=_verdict(options, best, form, dependence, l0))


def _dependence(spec, form, fit, theta_per, g_muscle, level) -> tuple[ConstantVsLength, ...]:
    """Each constant against the length: the smooth fit's slope, and the slope of the
    per-muscle constants regressed on g(l0) (ordinary least squares over the muscles, its
    Wald interval from pamid's one covariance, ``pamid._inference``)."""
    p = spec.n_params
    m = len(g_muscle)
    design = np.stack([np.ones(m), g_muscle], axis=1)
    coef, *_ = np.linalg.lstsq(design, theta_per, rcond=None)  # (2, p)
    resid = theta_per - design @ coef
    dof = m - 2
    slope_se = np.sqrt(residual_variance(np.sum(resid**2, axis=0), dof)
                       * unscaled_covariance(design)[0][1, 1])  # (p,)
    out = []
    cluster = fit.ci95_cluster
    for j, name in enumerate(spec.param_names):
        b = float(coef[1, j])
        out.append(ConstantVsLength(
            name=name, unit=spec.param_units[name],
            slope_unit=slope_unit(spec.param_units[name], form),
            value=float(fit.theta[0, j]), value_ci95=tuple(map(float, fit.ci95[0, j])),
            slope=float(fit.theta[0, p + j]), slope_ci95=tuple(map(float, fit.ci95[0, p + j])),
            slope_ci95_cluster=(None if cluster is None or not np.all(np.isfinite(
                cluster[0, p + j])) else tuple(map(float, cluster[0, p + j]))),
            slope_between=b,
            slope_ci95_between=tuple(map(float, wald_interval(b, slope_se[j], dof, level))),
            per_muscle=tuple(map(float, theta_per[:, j]))))
    return tuple(out)


def _verdict(options, best, form, dependence, l0) -> str:
    o = {x.name: x for x in options}
    a, b, c = o["per_muscle"], o[f"smooth_{form}"], o["pooled"]
    nums = (f"CV RMSE on held-out trials: one fit per muscle {a.cv_rmse_N:.3g} N, constants "
            f"{form} in l0 {b.cv_rmse_N:.3g} N, one set for all lengths {c.cv_rmse_N:.3g} N")
    loo = (f"; a muscle left out and predicted from the others: {b.loo_length_rmse_N:.3g} N "
           f"({form} in l0) against {c.loo_length_rmse_N:.3g} N (one set)")
    sloped = [d.name for d in dependence if not d.slope_ci95[0] <= 0.0 <= d.slope_ci95[1]]
    sloped_between = [d.name for d in dependence
                      if not d.slope_ci95_between[0] <= 0.0 <= d.slope_ci95_between[1]]
    span = f"{l0.min():.0f}–{l0.max():.0f} mm"
    if best == "pooled":
        return (f"No length effect: one set of constants for every length ({span}) predicts "
                f"held-out trials as well as the richer descriptions and has the lowest BIC "
                f"— Sárosi's 'any length' claim holds on these data. {nums}{loo}.")
    if best.startswith("smooth_"):
        return (f"A length effect: the constants vary with l0 ({span}) as a {form} function; "
                f"one set for every length predicts held-out trials worse "
                f"(+{100 * (c.cv_rmse_N / b.cv_rmse_N - 1):.1f} %), so Sárosi's 'any length' "
                f"claim does not hold here. Slopes whose 95 % interval excludes 0: "
                f"{', '.join(sloped) or 'none'} (pooled fit); "
                f"{', '.join(sloped_between) or 'none'} (across muscles). {nums}{loo}.")
    return (f"The muscles differ beyond a smooth function of l0: one fit per muscle predicts "
            f"held-out trials best; constants {form} in l0 are "
            f"{100 * (b.cv_rmse_N / a.cv_rmse_N - 1):+.1f} % and one set for every length "
            f"{100 * (c.cv_rmse_N / a.cv_rmse_N - 1):+.1f} % in CV RMSE. Sárosi's 'any length' "
            f"claim does not hold on these data, but with {len(l0)} lengths a difference between "
            f"muscles (tube, clamping) cannot be told from a length effect. Slopes whose 95 % "
            f"interval across muscles excludes 0: {', '.join(sloped_between) or 'none'}. "
            f"{nums}{loo}.")
