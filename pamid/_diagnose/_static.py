"""Candidate effects for the static force models, and their batched refits.

The library's effects, each a small JAX extension of the fitted force law F_model(θ; p, x)
(Sárosi eq. 2.1 or Cullinan eq. 3) with few constants; p is the gauge pressure in bar, d the
direction of motion (+1 contracting, −1 extending), ΔT the temperature less the file's mean,
t the time from the start of the muscle's test in hours, v the rate of contraction:

=====================  =======================================  ==========================
effect                 added to the force (N)                   constants
=====================  =======================================  ==========================
``hysteresis``         −d·(h0 + h1·p)  (Sárosi eq. 2.3–2.4)      h0 (N), h1 (N/bar)
                       − Σ_i (h0_i + h1_i·p)·ŝ_i  (slip        h0_i (N), h1_i (N/bar), ≥ 0
                       elements, with a time order)
``temperature``        (τ0 + τ1·p)·ΔT                           τ0 (N/K), τ1 (N/(bar·K))
``drift``              δ1·t + δ2·t²  (load-cell zero drift)     δ1 (N/h), δ2 (N/h²)
``viscous_damping``    −g·v  (Cullinan's −G·ẏ, eq. 3)           g (N·s/mm or N·s/%)
``transient``          g·Σ Δp_k·exp(−(t − t_k)/τ), valve steps  g (N/kPa), τ (s, grid)
``softening``          −s·(1 − exp(−repeat/r))·F_model           s (1), r (repeats, grid)
``compliance``         F solves F = F_model(p, x + c·F)         c (mm/N or %/N)
``sensor_offset``      F = F_model(p + δ, x)                    δ (kPa)
``covariate:<col>``    b1·P1(z) + b2·P2(z) + b3·P3(z)           b1, b2, b3 (N)
=====================  =======================================  ==========================

Each effect is one definition, in a module of :mod:`pamid._effects` of its own beside its
injector (its constants, units, physical bounds, source and the virtual bench's injector),
listed in :mod:`pamid._effects._definitions`; this module reads that registry.
The temperature has a second form, ``temperature_relative``: F_model·(α0 + α1·p)·(T − T0)
added, a share of the force per kelvin (α0 in 1/K, α1 in 1/(bar·K), T0 in °C over a grid).

For ``covariate:<col>`` z is the column scaled to [−1, 1] over the file and P_k are Legendre
polynomials: a smooth function of any numeric column, so that an effect outside the library
is still traced to its covariate.

Every candidate set is fitted in one compiled call: lanes = (set × muscle × fold), all with
the same parameter layout — the base constants, one constant per transform effect (the
compliance c, the sensor offset δ), and ``n_slots`` linear effect constants whose feature
columns each lane gathers from the muscle's full feature matrix — and a 0/1 mask; masked
constants stay at zero. The solver is Levenberg–Marquardt on the normal equations with
Marquardt's diagonal scaling, started from the baseline fit.
"""

from __future__ import annotations

import contextlib
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._data._holdout import holdout_units
from .._effects._base import Effect, FileContext, MuscleContext, physical_bounds
from .._effects._covariate import COVARIATE_DEGREE
from .._effects._definitions import STATIC_EFFECT_DEFINITIONS, transforms
from .._effects._model import with_effects
from .._effects._steps import moving_steps, rod_steps, time_since_step
from .._effects._wrappers import transform_inputs
from .._fit._api import fit_least_squares
from .._fit._least_squares import bounds_arrays, least_squares, model_at, model_jacobian
from .._fit._spec import ModelSpec
from .._inference import cut_at_bounds, residual_variance, unscaled_covariance, wald_interval
from .._lanes._batch import SMALL_BATCH_SAMPLES, LaneView, items_per_call, map_shared, pack
from .._solvers import CONVERGED, MAX_STEPS, ProjectedLevenbergMarquardt
from .._units import KPA_PER_BAR, per_l0
from ._residual import autocorrelation_time, legendre_basis, scaled
from ._select import SetFit

N_FOLDS = 5
MAX_ITER = 60
#: Stopping test of the refits (:func:`pamid._solvers.levenberg_marquardt`): the
#: Gauss–Newton step would lower the SSE by at most RTOL of itself plus ATOL_N² per sample.
RTOL = 1e-11
ATOL_N = 1e-9
#: A lane out of steps whose remaining Gauss–Newton decrease would move its BIC by at most
#: this much has reached its least squares for the selection (:func:`reached`); a BIC
#: difference below 2 is "not worth more than a bare mention" (Kass and Raftery 1995), and
#: the selection asks for 10.
BIC_SLACK = 0.5
#: A covariate's Legendre term lies in the base model when least squares on the model's
#: Jacobian columns reproduces it to this fraction of its norm (:func:`degrees_in_model`).
IN_MODEL_RTOL = 1e-8
#: Fewest effect-constant slots of a lane: the first step of a forward selection (one
#: effect, at most 3 constants) and the second (two effects, at most 6) then share one
#: compiled shape; the unused slots are masked and cost little.
MIN_SLOTS = 8
#: Fewest columns of the feature matrix (padded to a power of two, see ``_fill_features``).
MIN_FEATURES = 16
#: A small diagnosis (muscles × rows ≤ ``SMALL_BATCH_SAMPLES``: a lab's file of one or a
#: few muscles, where compiling is nearly all of the time) runs its lanes in one shape per
#: size class of rows, whatever the file's columns and curves: room for ``SMALL_SLOTS``
#: slots (each lane runs with the 8 or 16 its set needs, ``evaluate``),
#: ``SMALL_FEATURES`` feature columns and ``N_FOLDS`` folds. The programs
#: `pamid warm-up` compiles on its virtual sweeps then serve a force map (16 features, 4
#: folds, sets of ≤ 8 constants) or another lab's isometric tests of that class; the slots
#: masked more cost the small lanes next to nothing.
SMALL_SLOTS = 16
SMALL_FEATURES = 32


def degrees_in_model(spec: ModelSpec, theta, x, frame: pd.DataFrame, covariates,
                     ranges) -> dict[str, tuple[int, ...]]:
    """Per covariate, the Legendre degrees (1 … COVARIATE_DEGREE) that the base model
    already contains: those in the span of its Jacobian columns on one muscle's rows. A
    model affine in the pressure (Sárosi eq. 2.1, Cullinan eq. 3) contains degree 1 of the
    pressure, Cullinan eq. 3 degrees 1 and 2 of the contraction y; such a term added as an
    effect would be unidentifiable. Found from the model, for any ForceModel."""
    jac = np.asarray(model_jacobian(spec, theta, x))
    out = {}
    for c in covariates:
        if c == "direction" or c not in frame:
            continue
        lo, hi = ranges[c]
        basis = legendre_basis(scaled(frame[c].to_numpy(float), lo, hi), COVARIATE_DEGREE)
        inside = []
        for k in range(1, COVARIATE_DEGREE + 1):
            f = basis[k - 1]
            coef, *_ = np.linalg.lstsq(jac, f, rcond=None)
            if np.linalg.norm(jac @ coef - f) <= IN_MODEL_RTOL * max(np.linalg.norm(f), 1e-300):
                inside.append(k)
        out[c] = tuple(inside)
    return out


def derive_covariates(frame: pd.DataFrame, spec: ModelSpec, curves) -> pd.DataFrame:
    """Covariates of one muscle's rows (in file order), from the file's curve structure.

    ``curves`` is the :class:`pamid._data._curves.Curves` of these rows. Adds ``direction``
    (the recorded one, derived where the file has none: +1 where the muscle is driven to
    contract), and when the file has time ``elapsed_s`` (continuous across trials whose
    clock restarts), the rate of contraction ``speed_mm_s`` (or ``speed_pct_s`` without
    l0; zero at a held length) and, where the pressure moves at a held length, the
    pressure rate ``pressure_rate_kPa_s`` and the time since the last step of the moving
    pressure in its trial ``time_since_step_s`` (:func:`pamid._effects._steps.
    time_since_step`); ``repeat``, the trial's (or cycle's) order among the repeats of its
    setting, when there are repeats.
    """
    out = frame.copy()
    out["direction"] = curves.direction
    if np.all(np.isfinite(curves.elapsed_s)):
        out["elapsed_s"] = curves.elapsed_s
        sweep = curves.moving == 0
        rate = np.where(sweep, curves.rate, 0.0)
        if "contraction_mm" in frame and curves.contraction_column == "contraction_pct":
            if "l0_mm" in frame:
                rate = rate * frame["l0_mm"].to_numpy(float) / 100.0
            else:
                rate = rate * frame["contraction_mm"].to_numpy(float) / np.where(
                    frame["contraction_pct"].to_numpy(float) != 0,
                    frame["contraction_pct"].to_numpy(float), np.nan)
        name = "speed_mm_s" if "contraction_mm" in frame else "speed_pct_s"
        out[name] = np.nan_to_num(rate)
        if not sweep.all():
            out["pressure_rate_kPa_s"] = np.nan_to_num(np.where(sweep, 0.0, curves.rate))
            steps = moving_steps(frame["pressure_kPa"].to_numpy(float), curves.moving,
                                 curves.trial)
            if np.any(steps):
                out["time_since_step_s"] = time_since_step(steps, curves.elapsed_s,
                                                           curves.trial)
    if "trial" in frame or "cycle" in frame:
        out["repeat"] = curves.repeat
    return out


#: Why a column that only counts rows is not a covariate (:func:`row_counters`).
ROW_COUNTER_WHY = ("whole numbers that rise from each row to the next within every trial of "
                   "every muscle: a row or sample counter (an index), not a measurement")


def row_counters(frames: list[pd.DataFrame], trials: list[np.ndarray],
                 columns) -> dict[str, str]:
    """The ``columns`` that only count rows, with why: whole numbers that rise strictly from
    each row to the next within every trial of every muscle (``frames``: one muscle's rows
    each, in file order; ``trials``: their trial index), in a file where some trial has at
    least three rows. Such a column (a sample index, the row number in a source file, a
    logger's tick count) is known before any measurement is made: a smooth function of it
    is a function of the sample order, which ``elapsed_s`` and the time order already
    cover, and it may not be offered as a physical covariate. Decided by measurement, not
    by the column's name."""
    out = {}
    longest = max((int(np.bincount(t).max()) for t in trials if len(t)), default=0)
    if longest < 3:
        return out
    for c in columns:
        counter = True
        for f, t in zip(frames, trials, strict=True):
            v = f[c].to_numpy(float) if c in f else np.array([np.nan])
            same = np.asarray(t[1:]) == np.asarray(t[:-1])
            if (not np.all(np.isfinite(v)) or np.any(v != np.round(v))
                    or np.any(np.diff(v)[same] <= 0)):
                counter = False
                break
        if counter:
            out[c] = ROW_COUNTER_WHY
    return out


def order_is_time(muscle_curves) -> bool:
    """Whether the order of the rows is one in which the residual's whiteness means
    something (the runs test and Ljung–Box read the residual in row order): True where the
    file has time, and where it has none but its rows follow a motion (the moving input
    reverses: sweeps out and back, inflations and deflations). False for a map: every
    muscle's rows without time, each curve running the same way as every other (the moving
    input never reverses) and the curves' held levels following each other in one sense —
    a table sorted by one input, then by the other, as force maps are published (Martens
    and Boblan 2017, table A2). There a residual that is not white in row order is a
    dependence on the inputs the table is sorted by, not on a time.

    ``muscle_curves``: each muscle's :class:`pamid._data._curves.Curves`."""
    for c in muscle_curves:
        if np.all(np.isfinite(c.elapsed_s)) or len(np.unique(c.direction)) > 1:
            return True
        first = np.r_[True, np.diff(c.curve) != 0]
        level = np.asarray(c.level, float)[first]
        step = np.diff(level[np.isfinite(level)])
        if np.any(step > 0) and np.any(step < 0):
            return True
    return False


def _muscle_rows(bench) -> list[np.ndarray]:
    """Row positions of each muscle of a bench file, in the order of ``bench.muscles``."""
    idx = bench.frame.groupby("muscle", sort=False).indices
    return [np.asarray(idx[m]) for m in bench.muscles]


def held_within_bounds(baseline, i: int, lower, upper) -> bool:
    """Whether muscle ``i``'s baseline (a :class:`~pamid._fit._api.FitResult` that did not
    converge) is the best fit within the model's bounds of a constant the data do not
    determine: status "not_identifiable", every constant finite, at least one held on a
    bound (``lower``, ``upper``: :func:`pamid._fit._least_squares.bounds_arrays`), and a
    finite standard error for every constant not on a bound (the fit's own rank test of
    the others). Its residual is that of a least-squares fit with those constants held: a
    diagnosis of it means what it means for any muscle, with the held constants held."""
    if lower is None or baseline.status_of(i) != "not_identifiable":
        return False
    theta = np.asarray(baseline.theta[i], float)
    held = _on_bound(theta, lower, upper)
    return bool(np.all(np.isfinite(theta)) and held.any()
                and np.all(np.isfinite(np.asarray(baseline.se[i], float)[~held])))


def check_baseline(bench, spec: ModelSpec, baseline, lower=None, upper=None) -> list[dict]:
    """Which muscles' baselines (``baseline``, the diagnosis's own fit of the model alone)
    can be diagnosed, and which are flagged.

    A muscle whose fit converged is diagnosed. One whose constant the data do not determine
    but whose best fit within bounds is otherwise determined (:func:`held_within_bounds`:
    three contraction levels whose intercepts no exponential fits, a3 held on its bound) is
    diagnosed with the others, that constant held, and flagged. Any other (no finite fit,
    too few rows, constants the data cannot tell apart even with the bounds, a solver out
    of steps) has a residual that says nothing about missing effects: it is left out of
    the diagnosis and flagged, never the whole file for one muscle. Only when no muscle
    can be diagnosed is the file refused, with the first one's reason, an
    :class:`~pamid.UntrustedResultError` (exit 1, as ``pamid fit``).

    Returns one entry per flagged muscle, in file order: ``{"muscle", "status", "why",
    "diagnosed"}`` (``status`` and ``why``: the fit's result code and message).
    """
    from .._errors import UntrustedResultError

    flags = []
    for i, muscle in enumerate(bench.muscles):
        if baseline.converged[i]:
            continue
        flags.append({"muscle": muscle, "status": baseline.status_of(i),
                      "why": baseline.message(i),
                      "diagnosed": held_within_bounds(baseline, i, lower, upper)})
    if flags and sum(not f["diagnosed"] for f in flags) == len(bench.muscles):
        first = flags[0]
        who = f"muscle '{first['muscle']}'" if bench.has_muscle_column else "the data"
        raise UntrustedResultError(
            f"{bench.path}: the baseline {spec.source} fit of {who} is not trustworthy "
            f"({first['why']}); a diagnosis of its residual would mean nothing")
    return flags


def _without_muscles(bench, muscles) -> object:
    """``bench`` without the rows of ``muscles``."""
    keep = ~bench.frame["muscle"].isin(list(muscles)).to_numpy()
    return bench.take(keep, muscles=tuple(m for m in bench.muscles if m not in muscles))


class StaticProblem:
    """One bench file prepared for diagnosis: packed data, covariates and effect features."""

    def __init__(self, bench, spec: ModelSpec, *, n_folds: int = N_FOLDS, bounds=None,
                 left_out: tuple[dict, ...] = ()):
        self.spec = spec
        #: Bounds of the model's constants (``bounds`` where given, the model's physical
        #: bounds elsewhere; :func:`pamid._fit._least_squares.bounds_arrays`), or None.
        self.lower, self.upper = bounds_arrays(spec, bounds)
        self.bench = bench
        frames, curve_ids, muscle_curves = [], [], []
        curves = bench.curves  # the file's one curve structure (pamid._data._curves)
        for rows_idx in _muscle_rows(bench):
            rows = bench.frame.iloc[rows_idx].reset_index(drop=True)
            c = curves.take(rows_idx)
            frames.append(derive_covariates(rows, spec, c))
            curve_ids.append(c.curve)
            muscle_curves.append(c)
        self.frames = frames
        # Each muscle's frame columns as arrays, read once (_features asks for them again
        # for every fold and every grid value).
        self._columns: list[dict[str, np.ndarray]] = [{} for _ in frames]
        allrows = pd.concat(frames, ignore_index=True)
        #: Numeric columns of the file not offered as covariates, with why.
        self.not_covariates = row_counters(frames, [c.trial for c in muscle_curves],
                                           [c for c in bench.covariates if c in allrows])
        self.covariates = self._covariate_names(allrows)
        #: Whether the rows' order is a time order (:func:`order_is_time`); False for a map.
        self.order_is_time = order_is_time(muscle_curves)
        groups = [(spec.x_from_frame(f, bench.path), f["force_N"].to_numpy(float))
                  for f in frames]
        self.data = pack(groups, curve_ids)
        # The baseline: the model alone, with its statistics, so that a fit the data cannot
        # determine is known (and said why) before any candidate is refitted on top of it.
        self.baseline = fit_least_squares(self.data, spec, intervals=("wald",),
                                          muscles=tuple(bench.muscles), bounds=bounds,
                                          show="wald")  # its residual is what is used
        # Before anything is built on it: muscles whose residual means nothing are left
        # out (the problem is built again without them), those held within bounds flagged.
        flags = check_baseline(bench, spec, self.baseline, self.lower, self.upper)
        out = tuple(f for f in flags if not f["diagnosed"])
        if out:
            self.__init__(_without_muscles(bench, {f["muscle"] for f in out}), spec,
                          n_folds=n_folds, bounds=bounds, left_out=(*left_out, *out))
            return
        #: Muscles whose baseline did not converge (:func:`check_baseline`): those left out
        #: of the diagnosis, then those diagnosed with a constant held on its bound.
        self.flagged = [*left_out, *flags]
        self.theta0 = self.baseline.theta
        # A constant the baseline holds on a bound stays there in every refit (its gradient
        # points out of the bounds; an effect added on top is judged with it held).
        self.base_free = np.ones_like(np.asarray(self.theta0, float))
        if self.lower is not None:
            self.base_free[_on_bound(self.theta0, self.lower, self.upper)] = 0.0
        # A muscle held within bounds is diagnosed like one whose fit converged.
        self.baseline_converged = self.baseline.converged | np.isin(
            np.asarray(bench.muscles, object), [f["muscle"] for f in flags if f["diagnosed"]])
        self.l0_mm = [bench.l0_mm.get(m_id) for m_id in bench.muscles]
        self.file = self._file_context(allrows, muscle_curves)
        self.muscles = [self._muscle_context(i, f, c, x)
                        for i, (f, c, (x, _)) in enumerate(zip(frames, muscle_curves, groups,
                                                               strict=True))]
        self.effects = self._effects()
        self._groups = groups
        self._choose_grids(groups)
        folds = []
        self._clips = []
        for f, c in zip(frames, muscle_curves, strict=True):
            fold = (_map_folds(f, spec, n_folds) if not self.order_is_time
                    and spec.contraction_column in f and "pressure_kPa" in f
                    else _diagnosis_folds(c.curve, c.trial, n_folds))
            folds.append(fold)
            # Features for all data, then for each fold with the covariates clamped to the
            # range of that fold's training samples: a held-out curve beyond that range is
            # predicted at the range's edge rather than by extrapolating a polynomial.
            clips = [None]
            for k in range(int(fold.max()) + 1):
                train = f[fold != k]
                clips.append({c: (float(train[c].min()), float(train[c].max()))
                              for c in self.covariates if c in train})
            self._clips.append(clips)
        m, n = self.data.y.shape
        self.n_folds = max(len(c) for c in self._clips) - 1
        self._fill_features()
        self.fold = np.full((m, n), -1)
        for i, fo in enumerate(folds):
            self.fold[i, : len(fo)] = fo
        curve = np.asarray(self.data.curve)
        self.n_curves = int(curve.max()) + 1
        self.curve_used = np.zeros((m, self.n_curves), bool)
        for i in range(m):
            self.curve_used[i, np.unique(curve[i][curve[i] >= 0])] = True

    # -- covariates and features ------------------------------------------------------------

    def _covariate_names(self, rows: pd.DataFrame) -> list[str]:
        names = ["direction", "pressure_kPa", self.spec.contraction_column]
        for c in ("elapsed_s", "speed_mm_s", "speed_pct_s", "pressure_rate_kPa_s",
                  "time_since_step_s", "temperature_C", "cycle", "repeat"):
            if c in rows:
                names.append(c)
        names += [c for c in self.bench.covariates if c in rows and c not in names
                  and c not in self.spec.columns and c not in self.not_covariates]
        return [c for c in names if rows[c].nunique() > 1]

    def _file_context(self, rows: pd.DataFrame, muscle_curves) -> FileContext:
        p = rows["pressure_kPa"].to_numpy(float)
        # The model's own terms are read from a muscle whose fit converged (a constant
        # held on its bound, a3 = −3, makes terms vanish that the model does hold).
        ref = int(np.argmax(self.baseline.converged)) if self.baseline.converged.any() else 0
        return FileContext(
            spec=self.spec, covariates=self.covariates,
            ranges={c: (float(rows[c].min()), float(rows[c].max())) for c in self.covariates},
            temperature_mean_C=(float(rows["temperature_C"].mean())
                                if "temperature_C" in rows else 0.0),
            pressure_median_bar=float(np.median(p)) / KPA_PER_BAR,
            pressure_max_kPa=float(np.max(np.abs(p))),
            unit_x="%" if self.spec.contraction_column == "contraction_pct" else "mm",
            has_pressure_steps="time_since_step_s" in self.covariates,
            step_input=_step_input(self.covariates, muscle_curves),
            max_repeat=int(rows["repeat"].max()) if "repeat" in rows else 0,
            distinct={c: int(rows[c].nunique()) for c in self.covariates},
            in_model=degrees_in_model(self.spec, self.theta0[ref], self.spec.x_from_frame(
                self.frames[ref]), self.frames[ref], self.covariates,
                {c: (float(rows[c].min()), float(rows[c].max())) for c in self.covariates}),
        )

    def _muscle_context(self, i, f, c, x) -> MuscleContext:
        time = c.elapsed_s if np.all(np.isfinite(c.elapsed_s)) else None
        stepped = self.file.step_input if time is not None else None
        kcol = self.spec.contraction_column
        step_noise = None
        if stepped == "pressure":
            steps = moving_steps(f["pressure_kPa"].to_numpy(float), c.moving, c.trial)
            step_noise = c.noise.get("pressure_kPa")
        elif stepped == "contraction" and kcol in f:
            step_noise = noise = c.noise.get(kcol, np.zeros(len(f)))
            steps = rod_steps(f[kcol].to_numpy(float), c.moving, c.trial, noise)
        else:
            steps = np.zeros(len(f))
        speed = next((s for s in ("speed_mm_s", "speed_pct_s") if s in self.covariates), None)
        base = np.asarray(model_at(self.spec, self.theta0[i], x))
        i_p, per_kpa = transform_inputs(self.spec)["pressure"]
        slope = np.inf
        if per_kpa:  # ∂F/∂p in N/kPa, by a difference of 1 kPa
            up = list(x)
            up[i_p] = np.asarray(x[i_p]) + per_kpa
            slope = float(np.max(np.asarray(model_at(self.spec, self.theta0[i], tuple(up)))
                                 - base))
        step_slope = None
        if stepped == "contraction" and kcol in f:
            # ∂F/∂κ per unit of the file's contraction, by a difference of 0.01 unit
            up = self.spec.x_from_frame(f.assign(**{kcol: f[kcol] + 0.01}))
            d = (np.asarray(model_at(self.spec, self.theta0[i], up)) - base) / 0.01
            step_slope = float(d[np.argmax(np.abs(d))]) if len(d) else None
        return MuscleContext(
            frame=f, baseline_N=base, steps=steps, trial=np.asarray(c.trial), time_s=time,
            file=self.file, speed=speed, l0_mm=self.l0_mm[i], max_dF_dp_N_per_kPa=slope,
            step_slope=step_slope, step_noise=step_noise)

    def _effects(self) -> list[Effect]:
        """The registry's effects
        (:data:`pamid._effects._definitions.STATIC_EFFECT_DEFINITIONS`) that this file has
        the covariates for, with their feature columns or transform slot."""
        effects: list[Effect] = []
        col = 0
        slot = {d.name: j for j, d in enumerate(transforms())}
        #: Per feature column, the bounds the fit holds its constant within (±inf but for a
        #: constant declared ``held``: a slip element's weight, ≥ 0).
        self.col_bounds: list[tuple[float, float]] = []
        for d in STATIC_EFFECT_DEFINITIONS:
            for name, covariate, consts in d.members(self.file):
                if d.transform:
                    cols, tr = (), slot[d.name]
                else:
                    cols, tr = tuple(range(col, col + len(consts))), None
                    col += len(consts)
                    self.col_bounds += [(c.lower, c.upper) if c.held else (-math.inf, math.inf)
                                        for c in consts]
                effects.append(Effect(name, covariate, tuple(c.name for c in consts),
                                      tuple(c.unit for c in consts), cols, d, tr, d.grid,
                                      tuple(physical_bounds(c, self.file) for c in consts)))
        self.grid_value = {e.name: [1.0] * len(self.frames) for e in effects if e.grid}
        return effects

    def _fill_features(self) -> None:
        """The feature matrix (muscle, fold + 1, sample, feature) of every linear effect."""
        m, n = self.data.y.shape
        feats = [[self._features(i, clip) for clip in clips]
                 for i, clips in enumerate(self._clips)]
        self.n_features = feats[0][0].shape[1]
        # Padded with unused zero columns to a power of two (at least MIN_FEATURES): files
        # whose covariates differ a little (a temperature column more) share the compiled
        # lanes, whose shape includes the feature matrix's.
        small = _small(m, n)
        width = max(SMALL_FEATURES if small else MIN_FEATURES,
                    1 << max(self.n_features - 1, 0).bit_length())
        folds = max(self.n_folds, N_FOLDS if small else 0) + 1  # unused folds stay zero
        self.features = np.zeros((m, folds, n, width))
        for i, ft in enumerate(feats):
            for k, fk in enumerate(ft):
                self.features[i, k, : len(fk), : fk.shape[1]] = fk
        self._shared = None  # the device's copy is made again from these

    def refresh_grids(self, fit: SetFit) -> None:
        """Choose again, on the residual of ``fit`` (the effects selected so far), the grid
        constants of the effects not in it, and rebuild their features. A grid value chosen
        on the baseline's residual may fit another effect's leftover instead of its own
        (the softening's r chosen while a drift is still in the residual); the effects in
        ``fit`` keep theirs. Called by the forward selection after each step."""
        todo = [e.name for e in self.effects if e.grid is not None and e.name not in fit.effects]
        if not todo:
            return
        old = {name: list(self.grid_value[name]) for name in todo}
        self._choose_grids(self._groups, fit, todo)
        if any(old[name] != self.grid_value[name] for name in todo):
            self._fill_features()

    def _choose_grids(self, groups, fit: SetFit | None = None,
                      names: list[str] | None = None) -> None:
        """Per muscle, the grid constant of each effect that has one (the transient's τ,
        the softening's r): the grid value whose column, of the allowed sign, best explains
        the baseline's residual (or that of ``fit``, for the effects ``names``) once the
        base model's own directions (and ``fit``'s linear effects') are projected out."""
        # muscle -> (an orthonormal basis of the directions projected out, the residual
        # left): the same for every effect with a grid
        projected = {}

        def residual_and_basis(i, m, x, y):
            if i not in projected:
                cols = [np.asarray(model_jacobian(self.spec, self.theta0[i], x)),
                        np.ones(len(y))[:, None]]
                if fit is None:
                    r = y - m.baseline_N
                else:
                    r = np.asarray(fit.extra["residual"][i][: len(y)], float)
                    slots = fit.extra["slots"]
                    if slots:
                        cols.append(self.features[i, 0, : len(y)][:, slots])
                q, _ = np.linalg.qr(np.column_stack(cols))
                projected[i] = (q, r - q @ (q.T @ r))
            return projected[i]

        for e in self.effects:
            if e.grid is None or (names is not None and e.name not in names):
                continue
            lower = e.definition.constants[0].lower
            for i, (m, (x, y)) in enumerate(zip(self.muscles, groups, strict=True)):
                values = np.atleast_1d(e.definition.grid_values(self.file, m))
                q, r = residual_and_basis(i, m, x, y)
                best, best_gain, best_any, any_gain = values[0], -1.0, values[0], -1.0
                for v in values:
                    z = np.asarray(e.definition.features(m, lambda c, f=m.frame: f[c].to_numpy(
                        float), float(v))[0])
                    z = z - q @ (q.T @ z)
                    zz = float(z @ z)
                    if zz <= 0:
                        continue
                    coef = float(z @ r) / zz
                    gain = coef**2 * zz
                    if gain > any_gain:
                        best_any, any_gain = v, gain
                    if coef >= lower and gain > best_gain:
                        best, best_gain = v, gain
                self.grid_value[e.name][i] = float(best if best_gain >= 0 else best_any)

    def _features(self, i: int, clip: dict | None = None) -> np.ndarray:
        m = self.muscles[i]
        f = m.frame
        raw = self._columns[i]

        def col(name):
            if name not in raw:
                raw[name] = f[name].to_numpy(float)
            v = raw[name]
            if clip and name in clip and name != "direction":
                v = np.clip(v, *clip[name])
            return v

        cols = []
        for e in self.effects:
            if e.transform is not None:
                continue
            g = self.grid_value[e.name][i] if e.grid is not None else None
            cols += e.definition.features(m, col, g, e)
        return np.column_stack(cols) if cols else np.zeros((len(f), 0))

    def effect(self, name: str) -> Effect:
        for e in self.effects:
            if e.name == name:
                return e
        raise KeyError(name)

    @property
    def candidate_names(self) -> list[str]:
        return [e.name for e in self.effects]

    @property
    def covariate_of(self) -> dict[str, str]:
        return {e.name: e.covariate for e in self.effects}

    def constants_of(self, fit: SetFit, name: str, i: int) -> dict[str, float]:
        """The fitted constants of effect ``name`` in ``fit`` for muscle ``i``, by name, and
        its grid constant where it has one (the transient's τ, the temperature's T0)."""
        e = self.effect(name)
        out = {p: float(fit.extra["params"][i][j])
               for p, j in zip(e.param_names, self._index(fit, name), strict=True)}
        if e.grid is not None:
            out[e.grid.name] = float(self.grid_value[name][i])
        return out

    def _index(self, fit: SetFit, name: str) -> list[int]:
        """Positions of effect ``name``'s constants in the lanes' parameter vector."""
        k = self.spec.n_params
        e = self.effect(name)
        if e.transform is not None:
            return [k + e.transform]
        start = k + len(transforms())
        for other in fit.effects:
            o = self.effect(other)
            if other == name:
                return [start + j for j in range(len(e.columns))]
            if o.transform is None:
                start += len(o.columns)
        raise KeyError(name)

    def unphysical(self, fit: SetFit, name: str) -> str | None:
        """Why effect ``name``'s constants in ``fit`` are not physical (the first muscle
        where they are not), or None. (The model's own constants cannot be past their
        bounds: the refits keep them within, :func:`_lane`.)"""
        e = self.effect(name)
        for i, m in enumerate(self.muscles):
            who = f"muscle {self.bench.muscles[i]}: " if len(self.muscles) > 1 else ""
            msg = e.definition.violation(self.constants_of(fit, name, i), e, self.file, m)
            if msg is not None:
                return who + msg
        return None

    # -- fitting -----------------------------------------------------------------------------

    def evaluate(self, sets: list[tuple[str, ...]]) -> list[SetFit]:
        """Fit every set on all data and on every fold, in one batched call.

        A lane is (set, muscle, fold); it carries only indices. The muscle's samples, its
        feature columns and its fold's weights are gathered inside the compiled function,
        lane by lane, so that the memory is the muscles' data plus O(lanes per call × rows)
        of temporaries: never lanes × rows × features on the host.
        """
        m, n = self.data.y.shape
        slots = [[c for name in s for c in self.effect(name).columns] for s in sets]
        n_tr = len(transforms())
        n_slots = _slot_bucket(max(SMALL_SLOTS if _small(m, n) else MIN_SLOTS,
                                   max(len(s) for s in slots)))
        folds = self.n_folds + 1
        lanes_set, lanes_muscle, lanes_fold = np.meshgrid(
            np.arange(len(sets)), np.arange(m), np.arange(folds), indexing="ij")
        lanes_set, lanes_muscle, lanes_fold = (a.ravel() for a in (lanes_set, lanes_muscle,
                                                                   lanes_fold))
        cols = np.zeros((len(sets), n_slots), int)
        colmask = np.zeros((len(sets), n_slots))
        # Bounds of the effects' constants held within them by the fit (transforms, slots).
        eff_bounds = np.tile(np.array([-np.inf, np.inf])[:, None, None],
                             (1, len(sets), n_tr + n_slots))
        trmask = np.zeros((len(sets), n_tr))
        implicit = np.zeros(len(sets), bool)
        hidden = np.zeros(len(sets), int)
        for i, s in enumerate(slots):
            cols[i, : len(s)] = s
            colmask[i, : len(s)] = 1.0
            for j, c in enumerate(s):
                eff_bounds[:, i, n_tr + j] = self.col_bounds[c]
            for name in sets[i]:
                e = self.effect(name)
                hidden[i] += e.hidden
                if e.transform is not None:
                    trmask[i, e.transform] = 1.0
                    implicit[i] |= e.definition.implicit
        slotmask = colmask
        colmask = np.concatenate([trmask, colmask], axis=1)
        source = self._shared_arrays()
        # Lanes with and without an implicit transform (the compliance) are two models, two
        # calls of the one entry: the implicit force law costs four Newton steps that the
        # other lanes do not need. The lanes of sets with few columns also run with fewer
        # slots than the widest set's (the hysteresis with its slip elements has 10): the
        # normal equations grow with the square of the constants. Every lane carrying 16
        # slots made the first selection step of 100 muscles 1.6 times as slow, and the
        # warm diagnosis of one AARL muscle (1,369 rows) 2.76 s where it takes 2.28–2.49 s
        # with 8 (the refits 1.2 s against 0.9 s): once `pamid warm-up` has compiled both
        # widths, a small diagnosis's time is its arithmetic too.
        width = np.array([_slot_bucket(max(MIN_SLOTS, len(c))) for c in slots])
        lane_kind = np.stack([implicit[lanes_set], width[lanes_set]], axis=1).astype(int)
        p_full = self.spec.n_params + n_tr + n_slots
        # The model's constants start at the baseline's; those it holds on a bound are held
        # there. The others are kept within their bounds inside the solve (pamid's own
        # Levenberg–Marquardt with projected bounds): a constant a refit pushes onto its
        # bound is held there. The effects' constants start at zero (no effect); those not
        # in the set are held there (masked); a slip element's weight is kept ≥ 0 (``held``
        # constants), the others are free: one past its physical bound is reported as what
        # it would have needed.
        free = self.base_free[lanes_muscle]
        mask = np.concatenate([free, colmask[lanes_set]], axis=1)
        theta0 = np.concatenate([np.asarray(self.theta0, float)[lanes_muscle],
                                 np.zeros((len(lanes_set), n_tr + n_slots))], axis=1)
        k = self.spec.n_params
        lower = np.full(k, -np.inf) if self.lower is None else np.asarray(self.lower, float)
        upper = np.full(k, np.inf) if self.upper is None else np.asarray(self.upper, float)
        lower = np.concatenate([np.tile(lower, (len(lanes_set), 1)),
                                eff_bounds[0][lanes_set]], axis=1)
        upper = np.concatenate([np.tile(upper, (len(lanes_set), 1)),
                                eff_bounds[1][lanes_set]], axis=1)
        size = _refit_call_lanes(m, n)

        def refit(kind, sel):
            flag, ns = kind
            p = p_full - n_slots + ns
            view = LaneView(source, (lanes_muscle[sel], lanes_fold[sel],
                                     cols[lanes_set[sel], :ns], slotmask[lanes_set[sel], :ns]),
                            lane_data)
            sol = least_squares(
                with_effects(self.spec, flag, ns), view, solver=REFIT_SOLVER,
                theta0=theta0[sel, :p], mask=mask[sel, :p],
                bounds=(lower[sel, :p], upper[sel, :p]),
                max_steps=MAX_ITER, outputs=("prediction",), chunk=size)
            return (_pad(sol.params, p_full), sol.sse, sol.prediction, sol.result,
                    sol.decrement, _pad(sol.free, p_full))

        params, sse, pred, result, decrement, free = _by_kind(lane_kind, refit)
        # Each lane's residual on every row (data − model, the held-out rows too), and its
        # held-out squared error.
        w = np.asarray(self.data.w)
        mu, fo = lanes_muscle, lanes_fold
        resid = np.asarray(self.data.y)[mu] - pred
        held = (self.fold[mu] == fo[:, None] - 1) & (fo[:, None] > 0)
        sse_test = np.sum(np.where(held, w[mu], 0.0) * resid**2, axis=1)
        n_train = np.sum((w[mu] > 0) & ~held, axis=1)
        ok = reached(result, decrement, sse, n_train)
        # (JᵀJ)⁻¹ and the numerical rank are asked of the fits to all data only (the
        # intervals, the BIC); the held-out fits need neither.
        full_lanes = np.flatnonzero(lanes_fold == 0)

        def statistics(kind, sel):
            flag, ns = kind
            lanes, p = full_lanes[sel], p_full - n_slots + ns
            jtj_inv, rank = _run_lanes(
                _lane_statistics_jit, "diagnose_lane_statistics", self.spec, flag, source,
                lanes_muscle[lanes], cols[lanes_set[lanes], :ns],
                slotmask[lanes_set[lanes], :ns], free[lanes, :p], params[lanes, :p])
            return _pad(_pad(jtj_inv, p_full), p_full, axis=-2), rank

        stats = _by_kind(lane_kind[full_lanes], statistics)
        jtj_inv = np.zeros((len(lanes_set), *stats[0].shape[1:]))
        rank = np.zeros(len(lanes_set), int)
        jtj_inv[full_lanes], rank[full_lanes] = stats
        n_free = np.sum(free > 0, axis=1)
        curve = np.maximum(np.asarray(self.data.curve), 0)
        n_used = np.sum(w > 0, axis=1)
        results = []
        for i, s in enumerate(sets):
            full = (lanes_set == i) & (lanes_fold == 0)
            cv = (lanes_set == i) & (lanes_fold > 0)
            # Held-out squared error per (muscle, curve), from the rows each cv lane held
            # out (muscles × folds × rows for one set: the size of the data, times folds).
            lane = np.flatnonzero(cv)
            mu = lanes_muscle[lane]
            w_test = np.where(self.fold[mu] == lanes_fold[lane][:, None] - 1, w[mu], 0.0)
            unit_sse = np.bincount(
                (mu[:, None] * self.n_curves + curve[mu]).ravel(),
                (w_test * resid[lane] ** 2).ravel(), minlength=m * self.n_curves,
            ).reshape(m, self.n_curves)
            results.append(SetFit(
                effects=tuple(s), sse=sse[full], n=n_used, k=rank[full] + hidden[i],
                cv_unit_sse=unit_sse[self.curve_used],
                cv_sse=float(np.sum(sse_test[cv])), cv_n=int(np.sum(w_test > 0)),
                converged=ok[full] & self.baseline_converged,
                extra={"params": params[full], "jtj_inv": jtj_inv[full],
                       "full_rank": rank[full] == n_free[full],
                       "residual": resid[full], "slots": slots[i],
                       "compliance": bool(implicit[i])},
            ))
            if self.order_is_time:
                # each muscle's residual on all data as a time series: its autocorrelation
                # time and lag-1 autocorrelation (the selection's effective sample size,
                # pamid._diagnose._select); a map's rows are not one, and carry none (n_eff = n)
                r = resid[full]
                results[-1].tau, results[-1].rho1 = np.array(
                    [autocorrelation_time(r[k][w[k] > 0]) for k in range(len(r))]).T
        return results

    def _shared_arrays(self):
        """What every lane gathers from (:func:`lane_data`), on the device once: (x, y, w,
        fold, features)."""
        if getattr(self, "_shared", None) is None:
            self._shared = (tuple(jnp.asarray(xi) for xi in self.data.x),
                            jnp.asarray(self.data.y), jnp.asarray(self.data.w),
                            jnp.asarray(self.fold), jnp.asarray(self.features))
        return self._shared


def _small(muscles: int, rows: int) -> bool:
    """Whether a diagnosis is small: its lanes run in one shape per size class of rows
    (``SMALL_SLOTS``)."""
    return muscles * rows <= SMALL_BATCH_SAMPLES


def _on_bound(theta, lower, upper):
    """Whether constants lie on (or, by rounding, just past) a bound: within 1e-9 of it,
    relative to the bound's size."""
    theta = np.asarray(theta, float)
    near = lambda b: np.isfinite(b) & (np.abs(theta - b) <= 1e-9 * (1.0 + np.abs(b)))  # noqa: E731
    return near(lower) | near(upper)


def _step_input(covariates, muscle_curves) -> str | None:
    """Which input the ``transient`` follows (:attr:`pamid._effects._base.FileContext.
    step_input`): the pressure where it moves in steps at a held length in some trial, else
    the contraction where every trial of every muscle is a sweep at held pressures (the rod
    steps at every point); None without time."""
    if "time_since_step_s" in covariates:
        return "pressure"
    if "elapsed_s" in covariates and all((c.moving == 0).all() for c in muscle_curves):
        return "contraction"
    return None


def _diagnosis_folds(curve: np.ndarray, trial: np.ndarray, n_folds: int) -> np.ndarray:
    """The file's one hold-out rule (:func:`pamid._data._holdout.holdout_units`: whole
    trials where a muscle has enough, else whole curves), dealt round robin into
    ``min(n_folds, units)`` folds of trials, or :func:`_folds` of curves."""
    unit, kind = holdout_units(curve, trial)
    if kind == "trials":
        return _folds(unit, min(n_folds, int(unit.max()) + 1))
    return _folds(unit, n_folds)


def _map_folds(frame: pd.DataFrame, spec: ModelSpec, n_folds: int) -> np.ndarray:
    """Folds of a map (:func:`order_is_time` False: no time, rows sorted by the inputs): the
    point at the i-th pressure and j-th contraction of the grid (ranks of the distinct
    values) is held out in fold (i + j) mod k, k = min(``n_folds``, the fewer levels of
    the two inputs, at least 2). Every fold then holds out points at every pressure and
    every contraction level, and a fit without them interpolates; holding out whole curves
    — a whole contraction level of a map sorted by contraction — asks a function of the
    contraction to extrapolate to a level it never saw, and eq. 2.1 alone (a3 from four
    levels) predicted such a level 30 times worse than it fits."""
    p = np.unique(frame["pressure_kPa"].to_numpy(float), return_inverse=True)
    x = np.unique(frame[spec.contraction_column].to_numpy(float), return_inverse=True)
    k = max(2, min(n_folds, len(p[0]), len(x[0])))
    return (p[1].ravel() + x[1].ravel()) % k


def _folds(curve: np.ndarray, n_folds: int) -> np.ndarray:
    """Whole curves are held out, round robin; a muscle with fewer curves than folds is cut
    into blocks of consecutive samples instead."""
    n_curves = int(curve.max()) + 1 if len(curve) else 0
    if n_curves >= n_folds:
        return curve % n_folds
    blocks = np.arange(len(curve)) * (4 * n_folds) // max(len(curve), 1)
    return blocks % n_folds


#: Bytes of temporaries per sample of one lane in the compiled refits: XLA's memory analysis
#: of the one entry's program over a lane view (``pamid._fit._least_squares._own_loop``) on
#: the CPU, 8 lanes of 2,000 and of 20,000 samples, gave 200–630 B for Sárosi with 1 or 8
#: effect slots, with and without the compliance (2026-11-29; 220–500 B for Cullinan in the
#: lane function before it, 2026-11-25); tests/test_cli_failures.py holds it. With at most
#: ``CALL_LANE_SAMPLES`` lane-samples a call, a call's temporaries stay below 8 MiB; two CPU
#: threads run calls side by side (:func:`pamid._lanes._batch.map_lanes`).
LANE_BYTES_PER_SAMPLE = 1024
#: Lanes of every compiled call when the samples are few (:func:`_run_lanes`)...
CALL_LANES = 64
#: ... fewer (a power of two) where a call would hold more than this many lane-samples.
#: A call's loop runs as long as its slowest lane: a refit in a flat valley (a covariate of
#: the contraction beside a2·exp(a3·κ) + a6 on a file of four lengths) takes all
#: ``MAX_ITER`` steps while the others of its call end in 5–15, and every lane of the call
#: computes each of those steps. Smaller calls confine such a lane to a few others: with
#: 65,536 lane-samples (32 lanes of the AARL muscle's 2,048-row class) its warm diagnosis
#: took 4.6–5.9 s in process, with 8,192 (4 lanes) 1.7–2.0 s, the same selection and
#: numbers; one-muscle virtual files of 300–2,000 rows 0.37–1.10 s against 0.17–0.71 s; 100
#: muscles of 300 rows 7.0–9.0 s against 6.6–7.5 s (``benchmarks/refit_calls.py``;
#: benchmarks/README.md, "The refits' calls"). Padding is smaller too: one muscle of 3,000
#: rows with 6 compliance lanes runs 3 calls of 2 lanes, not one of 64.
CALL_LANE_SAMPLES = 8 * 1024
#: ... and this many in a small diagnosis (``_small``: a file of one or a few muscles), whose
#: few lanes leave a flat-valley refit fewer others to hold up in a call of its own: the
#: refits of one AARL muscle took 0.98–1.12 s against 1.16–1.27 s at 8,192, virtual files of
#: 300–2,000 rows 0.09–0.43 s against 0.11–0.50 s, the same selections and RMSE; a file of
#: 100 muscles, not small, 2.38–2.50 s against 2.24–2.34 s, so it keeps 8,192
#: (benchmarks/README.md, "Smaller calls for a small diagnosis").
SMALL_CALL_LANE_SAMPLES = 4 * 1024


def _refit_call_lanes(muscles: int, rows: int) -> int:
    """Lanes of every call of the refits and of their statistics in a diagnosis of
    ``muscles`` × ``rows`` (padded rows), by pamid's one lane sizer: ``CALL_LANES``, fewer (a
    power of two) where that many would hold more than :data:`SMALL_CALL_LANE_SAMPLES`
    lane-samples in a small diagnosis, :data:`CALL_LANE_SAMPLES` in another."""
    samples = SMALL_CALL_LANE_SAMPLES if _small(muscles, rows) else CALL_LANE_SAMPLES
    return items_per_call(n_samples=rows, max_lane_samples=samples, max_lanes=CALL_LANES)


@contextlib.contextmanager
def call_lane_samples(n: int):
    """Within the block, the diagnosis's refits and their statistics run in calls of at most
    ``n`` lane-samples, small diagnoses and others alike (:data:`SMALL_CALL_LANE_SAMPLES`
    and :data:`CALL_LANE_SAMPLES`, the defaults, outside it): a setting of speed and memory,
    not of the results (``benchmarks/refit_calls.py`` times it). Each call size is a
    compiled shape of its own."""
    global CALL_LANE_SAMPLES, SMALL_CALL_LANE_SAMPLES
    if int(n) < 1:
        raise ValueError(f"call_lane_samples needs at least 1 lane-sample a call, not {n}")
    before = CALL_LANE_SAMPLES, SMALL_CALL_LANE_SAMPLES
    CALL_LANE_SAMPLES = SMALL_CALL_LANE_SAMPLES = int(n)
    try:
        yield
    finally:
        CALL_LANE_SAMPLES, SMALL_CALL_LANE_SAMPLES = before


def _by_kind(kinds, run):
    """``run((implicit, slots), sel)`` for the lanes ``sel`` of each kind (``kinds``: per
    lane, whether its model has an implicit transform, and its number of slots), the
    outputs put back in lane order: a compiled function per kind, since the implicit force
    law costs Newton steps and the slots normal equations that the other lanes do not
    need."""
    outs = None
    for kind in np.unique(kinds, axis=0):
        sel = np.flatnonzero(np.all(kinds == kind, axis=1))
        out = run((bool(kind[0]), int(kind[1])), sel)
        if outs is None:
            outs = [np.zeros((len(kinds), *np.shape(a)[1:]), dtype=np.asarray(a).dtype)
                    for a in out]
        for arr, a in zip(outs, out, strict=True):
            arr[sel] = np.asarray(a)
    return outs


def _slot_bucket(k: int) -> int:
    """The slots of a lane that needs ``k``: the next power of two (buckets, so that fewer
    shapes compile)."""
    return 1 << (k - 1).bit_length()


def _pad(a, size: int, axis: int = -1) -> np.ndarray:
    """``a`` with zeros appended along ``axis`` up to ``size``: a lane run with fewer slots
    than the batch's, its slots past its own held at zero."""
    a = np.asarray(a)
    width = [(0, 0)] * a.ndim
    width[axis] = (0, size - a.shape[axis])
    return np.pad(a, width)


def _run_lanes(fn, name, spec, with_compliance, shared, *lanes):
    """``fn(spec, with_compliance, shared, *lanes)`` (a jitted, vmapped lane function: the
    statistics of the refits) over the lanes as the refits run
    (:func:`pamid._fit._least_squares.least_squares` with a lane view): in calls of one size
    for a given sample count (:func:`pamid._lanes._batch.map_shared`), as many lanes as
    the refits' calls take (:func:`_refit_call_lanes`), through the exported program on disk when
    the command line keeps them (a new process then skips tracing the lanes)."""
    size = _refit_call_lanes(*shared[1].shape)  # the muscles' forces: (muscles, padded rows)
    key = spec.program_key
    if key is not None:
        key = (name, *key, with_compliance, *(d.name for d in transforms()))
    return map_shared(functools.partial(fn, spec, with_compliance), shared, *lanes,
                      chunk=size, cache_key=key)


#: The refits' solver: pamid's own Levenberg–Marquardt with masks and projected bounds,
#: stopping where a Gauss–Newton step would lower the SSE by at most RTOL of itself plus
#: ATOL_N² per sample.
REFIT_SOLVER = ProjectedLevenbergMarquardt(rtol=RTOL, floor_per_sample=ATOL_N**2)


def lane_data(source, muscle, fold, cols, slotmask):
    """One refit's data, made inside the compiled call (the ``make`` of the refits'
    :class:`~pamid._lanes._batch.LaneView`): ``muscle``'s samples, all of them (``fold``
    0) or all but fold ``fold − 1`` (weight 0), the inputs of
    :func:`pamid._effects._model.with_effects`: the base model's, then the set's effect
    columns ``cols`` of the muscle's feature matrix for that fold, zero where ``slotmask``
    is (the unused slots). Returns (x, y, w)."""
    x_all, y_all, w_all, fold_all, feat_all = source
    held = (fold_all[muscle] == fold - 1) & (fold > 0)
    w = jnp.where(held, 0.0, w_all[muscle])
    feats = jnp.take(feat_all[muscle, fold], cols, axis=1)
    return (*(xi[muscle] for xi in x_all), feats * slotmask[None, :]), y_all[muscle], w


def reached(result, decrement, sse, n):
    """Whether each refit reached its least squares as far as the selection can tell: it
    converged, or it ran out of steps (:data:`MAX_ITER`) where the Gauss–Newton step
    (``decrement``) would still lower its SSE by so little that the BIC, n·ln(SSE/n), would
    move by at most :data:`BIC_SLACK` (a decrement δ moves it by about n·δ/SSE). Such a
    lane is in a flat valley of constants that trade off — a ``covariate:<col>`` of the
    contraction beside eq. 2.1's a2·exp(a3·κ) + a6, whose a2 wanders to thousands of N over
    hundreds of steps while the SSE moves in its fourth digit — and its SSE is that of the
    optimum for every purpose of the comparison."""
    flat = (result == MAX_STEPS) & (decrement * np.maximum(n, 1) <= BIC_SLACK * sse)
    return (result == CONVERGED) | flat


def _lane_statistics(spec, with_compliance, shared, muscle, cols, slotmask, free, params):
    """(JᵀJ)⁻¹ and the numerical rank of a lane fitted to all its muscle's data, at its
    constants ``params``; the constants held there (``free`` 0: masked, or held on a bound
    at the end) have no variance and no rank."""
    x, _, w = lane_data(shared, muscle, 0, cols, slotmask)
    model = with_effects(spec, with_compliance, cols.shape[0])
    # pamid's one covariance and rank criterion (``pamid._inference``), held constants out;
    # the Jacobian of the residual data − model
    jac = -model.jacobian(params, x) * jnp.sqrt(w)[:, None]
    jtj_inv, rank, _ = unscaled_covariance(jac, free)
    return jtj_inv, rank


def _vmapped(lane):
    def run(spec, with_compliance, shared, *lanes):
        return jax.vmap(lambda *a: lane(spec, with_compliance, shared, *a))(*lanes)

    return jax.jit(run, static_argnums=(0, 1))


_lane_statistics_jit = _vmapped(_lane_statistics)


def intervals(problem: StaticProblem, fit: SetFit, level: float = 0.95) -> list[dict]:
    """Per muscle: every selected effect's constants with Wald-t intervals (a constant
    chosen over a grid — the transient's τ — is given with its grid value and no interval)."""
    out = []
    params, cov_un = fit.extra["params"], fit.extra["jtj_inv"]
    for i in range(len(params)):
        dof = int(fit.n[i] - fit.k[i])
        if fit.extra["full_rank"][i]:
            se = np.sqrt(np.diag(cov_un[i]) * residual_variance(fit.sse[i], dof))
        else:  # some constants are not identifiable: no interval
            se = np.full(cov_un[i].shape[0], np.nan)
        effects = {}
        for name in fit.effects:
            e = problem.effect(name)
            consts = {}
            idx = problem._index(fit, name)
            for k, (pname, unit, j) in enumerate(zip(e.param_names, e.units, idx,
                                                     strict=False)):
                v = float(params[i][j])
                c = e.columns[k] if e.columns else None
                if c is not None and _on_bound(v, *problem.col_bounds[c]):
                    # held on its bound by the fit (a slip element at 0: absent), no interval
                    consts[pname] = {"value": v, "ci95": [math.nan, math.nan], "unit": unit,
                                     "held_at_bound": True}
                    continue
                lo, hi = wald_interval(v, se[j], dof, level)
                # The constant cannot lie past its physical bound (a slip weight below 0):
                # the interval is cut there (pamid._inference.cut_at_bounds).
                lo, hi, cut = cut_at_bounds(lo, hi, e.bounds[k] if e.bounds else
                                            (-math.inf, math.inf))
                consts[pname] = {"value": v, "ci95": [float(lo), float(hi)], "unit": unit}
                if cut:
                    consts[pname]["ci95_cut_at_bound"] = True
                other = per_l0(unit, problem.l0_mm[i])  # a length per newton, also in mm
                if other is not None:
                    other_unit, scale = other
                    consts[f"{pname}_{other_unit.replace('/', '_per_')}"] = {
                        "value": v * scale, "ci95": [float(lo) * scale, float(hi) * scale],
                        "unit": other_unit}
            for dname, unit, weights in (e.definition.derived(problem.file)
                                         if e.definition.derived is not None else ()):
                # a linear combination of the constants, its variance wᵀ·Σ·w
                w = np.zeros(len(params[i]))
                for pname, weight in weights.items():
                    w[idx[e.param_names.index(pname)]] = weight
                v = float(w @ params[i])
                var = (float(w @ cov_un[i] @ w) * residual_variance(fit.sse[i], dof)
                       if fit.extra["full_rank"][i] else math.nan)
                lo, hi = wald_interval(v, math.sqrt(max(var, 0.0)) if np.isfinite(var)
                                       else math.nan, dof, level)
                consts[dname] = {"value": v, "ci95": [float(lo), float(hi)], "unit": unit,
                                 "derived": " + ".join(f"{wt:g}·{pn}"
                                                       for pn, wt in weights.items())}
            if e.grid is not None:
                consts[e.grid.name] = {"value": problem.grid_value[name][i],
                                       "ci95": [math.nan, math.nan], "unit": e.grid.unit,
                                       "chosen_over": "grid"}
            effects[name] = consts
        out.append(effects)
    return out
