"""Candidate effects for the static force models, and their batched refits.

The library's effects, each a small JAX extension of the fitted force law F_model(θ; p, x)
(Sárosi eq. 2.1 or Cullinan eq. 3) with few constants; p is the gauge pressure in bar, d the
direction of motion (+1 contracting, −1 extending), ΔT the temperature less the file's mean,
t the time from the start of the muscle's test in hours, v the rate of contraction:

=====================  =======================================  ==========================
effect                 added to the force (N)                   constants
=====================  =======================================  ==========================
``hysteresis``         −d·(h0 + h1·p)  (Sárosi eq. 2.3–2.4)      h0 (N), h1 (N/bar)
``temperature``        (τ0 + τ1·p)·ΔT                           τ0 (N/K), τ1 (N/(bar·K))
``drift``              δ1·t + δ2·t²  (load-cell zero drift)     δ1 (N/h), δ2 (N/h²)
``viscous_damping``    −g·v  (Cullinan's −G·ẏ, eq. 3)           g (N·s/mm or N·s/%)
``compliance``         F solves F = F_model(p, x + c·F)         c (mm/N or %/N)
``covariate:<col>``    b1·P1(z) + b2·P2(z) + b3·P3(z)           b1, b2, b3 (N)
=====================  =======================================  ==========================

For ``covariate:<col>`` z is the column scaled to [−1, 1] over the file and P_k are Legendre
polynomials: a smooth function of any numeric column, so that an effect outside the library
is still traced to its covariate.

Every candidate set is fitted in one compiled call: lanes = (set × muscle × fold), all with
the same parameter layout — the base constants, the compliance c, and ``n_slots`` linear
effect constants whose feature columns each lane gathers from the muscle's full feature
matrix — and a 0/1 mask; masked constants stay at zero. The solver is Levenberg–Marquardt on
the normal equations with Marquardt's diagonal scaling, started from the baseline fit.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._fit import _export_cache
from .._fit._api import fit_least_squares
from .._fit._batch import map_lanes, pack
from .._fit._engine import CONVERGED, levenberg_marquardt
from .._fit._sharding import lane_devices
from .._fit._spec import ModelSpec, builtin_key
from .._units import KPA_PER_BAR
from ._residual import legendre_basis, scaled
from ._select import SetFit

N_FOLDS = 5
COVARIATE_DEGREE = 3
MAX_ITER = 60
#: Stopping test of the refits (:func:`pamid._fit._engine.levenberg_marquardt`): the
#: Gauss–Newton step would lower the SSE by at most RTOL of itself plus ATOL_N² per sample.
RTOL = 1e-11
ATOL_N = 1e-9
#: Legendre degrees of a covariate that the base model already contains (at fixed values of
#: the other inputs): Sárosi eq. 2.1 and Cullinan eq. 3 are affine in the pressure, and
#: Cullinan eq. 3 is quadratic in the contraction y. Those terms would be unidentifiable.
_IN_BASE_MODEL = {
    ("sarosi", "pressure_kPa"): (1,),
    ("cullinan", "pressure_kPa"): (1,),
    ("cullinan", "contraction_mm"): (1, 2),
}


@dataclasses.dataclass(frozen=True)
class Effect:
    name: str
    covariate: str
    param_names: tuple[str, ...]
    units: tuple[str, ...]
    columns: tuple[int, ...]  # feature columns; empty for compliance


def derive_covariates(frame: pd.DataFrame, spec: ModelSpec, curves) -> pd.DataFrame:
    """Covariates of one muscle's rows (in file order), from the file's curve structure.

    ``curves`` is the :class:`pamid._data._curves.Curves` of these rows. Adds ``direction``
    (the recorded one, derived where the file has none: +1 where the muscle is driven to
    contract), and when the file has time ``elapsed_s`` (continuous across trials whose
    clock restarts), the rate of contraction ``speed_mm_s`` (or ``speed_pct_s`` without
    l0; zero at a held length) and, where the pressure moves at a held length, the
    pressure rate ``pressure_rate_kPa_s``; ``repeat``, the trial's (or cycle's) order among
    the repeats of its setting, when there are repeats.
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
    if "trial" in frame or "cycle" in frame:
        out["repeat"] = curves.repeat
    return out


def _muscle_rows(bench) -> list[np.ndarray]:
    """Row positions of each muscle of a bench file, in the order of ``bench.muscles``."""
    idx = bench.frame.groupby("muscle", sort=False).indices
    return [np.asarray(idx[m]) for m in bench.muscles]


class StaticProblem:
    """One bench file prepared for diagnosis: packed data, covariates and effect features."""

    def __init__(self, bench, spec: ModelSpec, *, n_folds: int = N_FOLDS):
        self.spec = spec
        self.bench = bench
        frames, curve_ids = [], []
        curves = bench.curves  # the file's one curve structure (pamid._data._curves)
        for rows_idx in _muscle_rows(bench):
            rows = bench.frame.iloc[rows_idx].reset_index(drop=True)
            c = curves.take(rows_idx)
            frames.append(derive_covariates(rows, spec, c))
            curve_ids.append(c.curve)
        self.frames = frames
        allrows = pd.concat(frames, ignore_index=True)
        self.covariates = self._covariate_names(allrows)
        self.effects = self._effects(allrows)
        groups, feats, folds = [], [], []
        for f, curve in zip(frames, curve_ids, strict=True):
            x = spec.x_from_frame(f, bench.path)
            groups.append((x, f["force_N"].to_numpy(float)))
            fold = _folds(curve, n_folds)
            folds.append(fold)
            # Features for all data, then for each fold with the covariates clamped to the
            # range of that fold's training samples: a held-out curve beyond that range is
            # predicted at the range's edge rather than by extrapolating a polynomial.
            per_fold = [self._features(f)]
            for k in range(int(fold.max()) + 1):
                train = f[fold != k]
                clip = {c: (float(train[c].min()), float(train[c].max()))
                        for c in self.covariates if c in train}
                per_fold.append(self._features(f, clip))
            feats.append(per_fold)
        self.data = pack(groups, curve_ids)
        m, n = self.data.y.shape
        self.n_folds = max(len(ft) for ft in feats) - 1
        self.n_features = feats[0][0].shape[1]
        self.features = np.zeros((m, self.n_folds + 1, n, self.n_features))
        self.fold = np.full((m, n), -1)
        for i, (ft, fo) in enumerate(zip(feats, folds, strict=True)):
            for k, fk in enumerate(ft):
                self.features[i, k, : len(fk)] = fk
            self.fold[i, : len(fo)] = fo
        curve = np.asarray(self.data.curve)
        self.n_curves = int(curve.max()) + 1
        self.curve_used = np.zeros((m, self.n_curves), bool)
        for i in range(m):
            self.curve_used[i, np.unique(curve[i][curve[i] >= 0])] = True
        # The baseline: the model alone, with its statistics, so that a fit the data cannot
        # determine is known (and said why) before any candidate is refitted on top of it.
        self.baseline = fit_least_squares(self.data, spec, intervals=("wald",),
                                          muscles=tuple(bench.muscles))
        self.theta0 = self.baseline.theta
        self.baseline_converged = self.baseline.converged
        self.l0_mm = [bench.l0_mm.get(m_id) for m_id in bench.muscles]

    # -- covariates and features ------------------------------------------------------------

    def _covariate_names(self, rows: pd.DataFrame) -> list[str]:
        names = ["direction", "pressure_kPa", self.spec.contraction_column]
        for c in ("elapsed_s", "speed_mm_s", "speed_pct_s", "pressure_rate_kPa_s",
                  "temperature_C", "cycle", "repeat"):
            if c in rows:
                names.append(c)
        names += [c for c in self.bench.covariates if c in rows and c not in names
                  and c not in self.spec.columns]
        return [c for c in names if rows[c].nunique() > 1]

    def _effects(self, rows: pd.DataFrame) -> list[Effect]:
        effects: list[Effect] = []
        col = 0
        unit_x = "%" if self.spec.contraction_column == "contraction_pct" else "mm"

        def add(name, covariate, params, units):
            nonlocal col
            cols = tuple(range(col, col + len(params)))
            col += len(params)
            effects.append(Effect(name, covariate, params, units, cols))

        if "direction" in self.covariates:
            add("hysteresis", "direction", ("h0", "h1"), ("N", "N/bar"))
        if "temperature_C" in self.covariates:
            add("temperature", "temperature_C", ("tau0", "tau1"), ("N/K", "N/(bar·K)"))
        if "elapsed_s" in self.covariates:
            add("drift", "elapsed_s", ("delta1", "delta2"), ("N/h", "N/h²"))
        speed = next((c for c in ("speed_mm_s", "speed_pct_s") if c in self.covariates), None)
        if speed is not None and len(self.spec.columns) < 3:  # Cullinan with G has it already
            unit = "N·s/mm" if speed == "speed_mm_s" else "N·s/%"
            add("viscous_damping", speed, ("g",), (unit,))
        for c in self.covariates:
            if c == "direction":
                continue
            top = min(COVARIATE_DEGREE, rows[c].nunique() - 1)
            degrees = [k for k in range(1, top + 1)
                       if k not in _IN_BASE_MODEL.get((self.spec.name, c), ())]
            if degrees:
                add(f"covariate:{c}", c, tuple(f"b{k}" for k in degrees), ("N",) * len(degrees))
        effects.append(Effect("compliance", "force_N", ("c",), (f"{unit_x}/N",), ()))
        self._ranges = {c: (float(rows[c].min()), float(rows[c].max()))
                        for c in self.covariates}
        self._t_mean = float(rows["temperature_C"].mean()) if "temperature_C" in rows else 0.0
        return effects

    def _features(self, f: pd.DataFrame, clip: dict | None = None) -> np.ndarray:
        p = f["pressure_kPa"].to_numpy(float) / KPA_PER_BAR

        def col(name):
            v = f[name].to_numpy(float)
            if clip and name in clip and name != "direction":
                v = np.clip(v, *clip[name])
            return v

        cols = []
        for e in self.effects:
            if e.name == "hysteresis":
                d = col("direction")
                cols += [-d, -d * p]
            elif e.name == "temperature":
                dt = col("temperature_C") - self._t_mean
                cols += [dt, dt * p]
            elif e.name == "drift":
                h = col("elapsed_s") / 3600.0
                cols += [h, h**2]
            elif e.name == "viscous_damping":
                cols += [-col(e.covariate)]
            elif e.name.startswith("covariate:"):
                lo, hi = self._ranges[e.covariate]
                z = scaled(col(e.covariate), lo, hi)
                basis = legendre_basis(z, COVARIATE_DEGREE)
                cols += [basis[int(name[1:]) - 1] for name in e.param_names]
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

    # -- fitting -----------------------------------------------------------------------------

    def evaluate(self, sets: list[tuple[str, ...]]) -> list[SetFit]:
        """Fit every set on all data and on every fold, in one batched call.

        A lane is (set, muscle, fold); it carries only indices. The muscle's samples, its
        feature columns and its fold's weights are gathered inside the compiled function,
        lane by lane, so that the memory is the muscles' data plus O(lanes per call × rows)
        of temporaries: never lanes × rows × features on the host.
        """
        m, n = self.data.y.shape
        k = self.spec.n_params
        slots = [[c for name in s if name != "compliance" for c in self.effect(name).columns]
                 for s in sets]
        n_slots = max(1, max(len(s) for s in slots))
        n_slots = 1 << (n_slots - 1).bit_length()  # buckets: fewer shapes to compile
        folds = self.n_folds + 1
        lanes_set, lanes_muscle, lanes_fold = np.meshgrid(
            np.arange(len(sets)), np.arange(m), np.arange(folds), indexing="ij")
        lanes_set, lanes_muscle, lanes_fold = (a.ravel() for a in (lanes_set, lanes_muscle,
                                                                   lanes_fold))
        cols = np.zeros((len(sets), n_slots), int)
        colmask = np.zeros((len(sets), n_slots))
        comp = np.zeros(len(sets))
        for i, s in enumerate(slots):
            cols[i, : len(s)] = s
            colmask[i, : len(s)] = 1.0
            comp[i] = float("compliance" in sets[i])
        shared = self._shared_arrays()
        # Lanes with and without the compliance are solved by two compiled functions: the
        # implicit force law costs four Newton steps that the other lanes do not need.
        lane_comp = comp[lanes_set] > 0
        parts = {}
        for flag in (False, True):
            sel = np.flatnonzero(lane_comp == flag)
            if len(sel) == 0:
                continue
            parts[flag] = (sel, _fit_lanes(
                self.spec, flag, shared, lanes_muscle[sel], lanes_fold[sel],
                cols[lanes_set[sel]], colmask[lanes_set[sel]],
            ))
        outs = []
        for j in range(7):
            first = next(iter(parts.values()))[1][j]
            arr = np.zeros((len(lanes_set), *np.shape(first)[1:]), dtype=np.asarray(first).dtype)
            for sel, out in parts.values():
                arr[sel] = np.asarray(out[j])
            outs.append(arr)
        params, sse, sse_test, resid, jtj_inv, ok, rank = outs
        w = np.asarray(self.data.w)
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
                effects=tuple(s), sse=sse[full], n=n_used, k=rank[full],
                cv_unit_sse=unit_sse[self.curve_used],
                cv_sse=float(np.sum(sse_test[cv])), cv_n=int(np.sum(w_test > 0)),
                converged=ok[full] & self.baseline_converged,
                extra={"params": params[full], "jtj_inv": jtj_inv[full],
                       "full_rank": rank[full] == k + len(slots[i]) + int(comp[i]),
                       "residual": resid[full], "slots": slots[i], "compliance": comp[i] > 0},
            ))
        return results

    def _shared_arrays(self):
        """What every lane gathers from, on the device once: (θ0, x, y, w, fold, features)."""
        if getattr(self, "_shared", None) is None:
            self._shared = (jnp.asarray(self.theta0), tuple(jnp.asarray(xi) for xi in self.data.x),
                            jnp.asarray(self.data.y), jnp.asarray(self.data.w),
                            jnp.asarray(self.fold), jnp.asarray(self.features))
        return self._shared


def _folds(curve: np.ndarray, n_folds: int) -> np.ndarray:
    """Whole curves are held out, round robin; a muscle with fewer curves than folds is cut
    into blocks of consecutive samples instead."""
    n_curves = int(curve.max()) + 1 if len(curve) else 0
    if n_curves >= n_folds:
        return curve % n_folds
    blocks = np.arange(len(curve)) * (4 * n_folds) // max(len(curve), 1)
    return blocks % n_folds


def _predict(spec, theta, c, x, with_compliance: bool):
    """F_model with the rig's compliance: F = F_model(p, x + c·F), by Newton from c = 0."""
    if not with_compliance:
        return spec.predict(theta, x)
    x0, x1, *rest = x

    def model(f):
        return spec.predict(theta, (x0, x1 + c * f, *rest))

    f = spec.predict(theta, x)
    for _ in range(4):
        g, dg = jax.jvp(model, (f,), (jnp.ones_like(f),))
        f = f - (f - g) / (1.0 - dg)
    return f


#: Bytes of temporaries per sample of one lane in the compiled lane function: XLA's memory
#: analysis of ``_fit_lanes_jit`` on the CPU (8 lanes of 10,000 samples) gave 400–590 B for
#: Sárosi and 220–500 B for Cullinan with 1–8 effect slots, with and without the compliance.
LANE_BYTES_PER_SAMPLE = 1024
#: Temporaries one compiled call may hold: lanes per call = this / (bytes per lane). Two CPU
#: threads run calls side by side (:func:`pamid._fit._batch.map_lanes`).
CALL_BUDGET_BYTES = 256 * 2**20
#: Fewest lanes a call is padded to when the samples are few: the steps of a forward
#: selection then reuse one compiled shape...
MIN_LANES = 64
#: ... as long as the padded call holds at most this many lane-samples: with more samples
#: the padding costs more than compiling another shape (one muscle of 3,000 rows: 6 lanes
#: with the compliance padded to 64 took most of a step's time).
MIN_LANE_SAMPLES = 64 * 1024


def lanes_per_call(n_samples: int) -> int:
    """Lanes per compiled call for muscles of ``n_samples`` (padded) samples: a power of two
    whose temporaries fit :data:`CALL_BUDGET_BYTES`, at most ``CHUNK_LANES``."""
    from .._fit._batch import CHUNK_LANES

    fit = max(1, CALL_BUDGET_BYTES // (LANE_BYTES_PER_SAMPLE * max(n_samples, 1)))
    return min(CHUNK_LANES, 1 << (fit.bit_length() - 1))


def _fit_lanes(spec, with_compliance, shared, muscle, fold, cols, colmask):
    """Solve the lanes, in calls of :func:`lanes_per_call` lanes. Fewer lanes than that are
    padded to a power of two (repeating the last lane), at least ``MIN_LANES`` while that
    stays within ``MIN_LANE_SAMPLES``, so that the steps of a forward selection reuse a few
    compiled shapes; more are cut into calls of that many (:func:`pamid._fit._batch.
    map_lanes` pads only the last)."""
    n = len(muscle)
    n_samples = shared[2].shape[1]
    chunk = lanes_per_call(n_samples)
    fewest = min(MIN_LANES, 1 << (max(1, MIN_LANE_SAMPLES // n_samples).bit_length() - 1))
    size = min(chunk, max(fewest, 1 << (n - 1).bit_length())) if n <= chunk else n
    idx = np.minimum(np.arange(size), n - 1)
    lanes = (muscle[idx], fold[idx], cols[idx], colmask[idx])
    run = functools.partial(_fit_lanes_jit, spec, with_compliance)
    name = builtin_key(spec)
    if name is not None and len(lane_devices()) == 1:
        # Through the exported program on disk when the command line keeps them: a new
        # process then skips tracing the lanes (most of a warm diagnosis of 1,000 rows).
        key = ("diagnose_lanes", *name, with_compliance, MAX_ITER)
        out = map_lanes(lambda *a: _export_cache.call(key, run, shared, *a), *lanes,
                        chunk=chunk)
    else:
        out = map_lanes(lambda *a: run(shared, *a), *lanes, chunk=chunk)
    return jax.tree.map(lambda a: a[:n], out)


def numerical_rank(jac, rtol: float = 1e-9):
    """Numerical rank of ``jac`` (n × p) with its columns scaled to unit length: the
    singular values above ``rtol`` times the largest. Constants the data cannot tell apart
    count once in the BIC.

    J = Q·R first (Householder, backward stable: R has J's singular values to rounding),
    then the SVD of the p × p R. The SVD of the tall J itself allocated n × n on the CPU
    (47 GB for one muscle of 9,596 samples in a batch of 64 lanes); Q·R needs n × p. The
    eigenvalues of the scaled JᵀJ would square the condition number: a rank-deficient J
    gives eigenvalues of rounding size, ~1e-16 of the largest, above a 1e-18 threshold.
    """
    norms = jnp.sqrt(jnp.sum(jac**2, axis=0))
    scaled_jac = jac / jnp.where(norms > 0, norms, 1.0)
    sv = jnp.linalg.svd(jnp.linalg.qr(scaled_jac, mode="r"), compute_uv=False)
    return jnp.sum(sv > sv[0] * rtol)


def _lane(spec, with_compliance, shared, muscle, fold, cols, colmask):
    """One lane: the set's effect columns ``cols`` (masked by ``colmask``) fitted to
    ``muscle``'s samples, all of them (``fold`` 0) or all but fold ``fold − 1``."""
    theta0_all, x_all, y_all, w_all, fold_all, feat_all = shared
    theta0 = theta0_all[muscle]
    x = tuple(xi[muscle] for xi in x_all)
    y = y_all[muscle]
    held = (fold_all[muscle] == fold - 1) & (fold > 0)
    w = jnp.where(held, 0.0, w_all[muscle])
    w_test = jnp.where(held, w_all[muscle], 0.0)
    feats = jnp.take(feat_all[muscle, fold], cols, axis=1)
    k = theta0.shape[0]
    s = feats.shape[1]
    comp = 1.0 if with_compliance else 0.0
    mask = jnp.concatenate([jnp.ones(k), jnp.full(1, comp), colmask])
    sw = jnp.sqrt(w)
    lin = feats * colmask[None, :]

    def pred(params):
        theta, c, phi = params[:k], params[k], params[k + 1:]
        return _predict(spec, theta, c, x, with_compliance) + lin @ phi

    def resid(params):
        return sw * (y - pred(params))

    def normal(params):
        r = resid(params)
        # The effects' constants enter linearly: their Jacobian columns are the features;
        # only the base constants (and c) need forward-mode derivatives of the model.
        jac_nl = jax.jacfwd(
            lambda tc: _predict(spec, tc[:k], tc[k], x, with_compliance))(params[: k + 1])
        jac = -jnp.concatenate([jac_nl, lin], axis=1) * sw[:, None]
        jac = jac * mask[None, :]
        return r, jac

    params0 = jnp.concatenate([theta0, jnp.zeros(1 + s)])
    eye_off = jnp.diag(1.0 - mask)
    floor = jnp.sum(w > 0) * ATOL_N**2
    sol = levenberg_marquardt(normal, params0, mask, max_steps=MAX_ITER, rtol=RTOL,
                              floor=floor)
    params, sse, jac = sol.params, sol.sse, sol.jac
    a = jac.T @ jac + eye_off
    jtj_inv = jnp.linalg.inv(a) * mask[:, None] * mask[None, :]
    rank = numerical_rank(jac)
    resid_all = y - pred(params)
    sse_test = jnp.sum(w_test * resid_all**2)
    ok = sol.result == CONVERGED
    return params, sse, sse_test, resid_all, jtj_inv, ok, rank


def _fit_lanes_impl(spec, with_compliance, shared, muscle, fold, cols, colmask):
    return jax.vmap(lambda *a: _lane(spec, with_compliance, shared, *a))(
        muscle, fold, cols, colmask)


_fit_lanes_jit = jax.jit(_fit_lanes_impl, static_argnums=(0, 1))


def intervals(problem: StaticProblem, fit: SetFit, level: float = 0.95) -> list[dict]:
    """Per muscle: every selected effect's constants with Wald-t intervals."""
    from .._fit._intervals import wald_interval

    k = problem.spec.n_params
    out = []
    params, cov_un = fit.extra["params"], fit.extra["jtj_inv"]
    for i in range(len(params)):
        dof = int(fit.n[i] - fit.k[i])
        s2 = float(fit.sse[i]) / dof if dof > 0 else math.nan
        se = np.sqrt(np.maximum(np.diag(cov_un[i]) * s2, 0.0))
        if not fit.extra["full_rank"][i]:
            se = np.full_like(se, np.nan)  # some constants are not identifiable: no interval
        effects = {}
        slot = 0
        for name in fit.effects:
            e = problem.effect(name)
            consts = {}
            if name == "compliance":
                idx = [k]
            else:
                idx = [k + 1 + slot + j for j in range(len(e.columns))]
                slot += len(e.columns)
            for pname, unit, j in zip(e.param_names, e.units, idx, strict=True):
                v = float(params[i][j])
                lo, hi = wald_interval(v, se[j], dof, level)
                consts[pname] = {"value": v, "ci95": [float(lo), float(hi)], "unit": unit}
            if name == "compliance" and e.units[0] == "%/N" and problem.l0_mm[i]:
                scale = problem.l0_mm[i] / 100.0
                c = consts["c"]
                consts["c_mm_per_N"] = {"value": c["value"] * scale,
                                        "ci95": [b * scale for b in c["ci95"]], "unit": "mm/N"}
            effects[name] = consts
        out.append(effects)
    return out
