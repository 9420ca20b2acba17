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
import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

from .._fit._batch import map_lanes, pack
from .._fit._least_squares import solve
from .._fit._spec import ModelSpec
from .._units import KPA_PER_BAR
from ._residual import legendre_basis, scaled
from ._select import SetFit

N_FOLDS = 5
COVARIATE_DEGREE = 3
MAX_ITER = 60
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


def derive_covariates(frame: pd.DataFrame, spec: ModelSpec) -> pd.DataFrame:
    """Covariates of one muscle's rows, which must be in time order.

    Adds ``direction`` (from the time order of the contraction when the file has no
    direction column), ``elapsed_s``, and the rate of contraction ``speed_mm_s`` (or
    ``speed_pct_s`` without l0) when the file has time.
    """
    out = frame.copy()
    x = frame[spec.contraction_column].to_numpy(float)
    p = frame["pressure_kPa"].to_numpy(float)
    cycle = frame["cycle"].to_numpy() if "cycle" in frame else np.zeros(len(frame))
    segment = np.concatenate([[0], np.cumsum((np.diff(p) != 0) | (np.diff(cycle) != 0))])
    if "direction" not in frame:
        out["direction"] = _direction_from_order(x, segment)
    if "time_s" in frame:
        t = frame["time_s"].to_numpy(float)
        out["elapsed_s"] = t - t[0]
        length_x = (frame["contraction_mm"].to_numpy(float) if "contraction_mm" in frame
                    else x)
        name = "speed_mm_s" if "contraction_mm" in frame else "speed_pct_s"
        out[name] = _rate(length_x, t, segment)
    return out


def _direction_from_order(x: np.ndarray, segment: np.ndarray) -> np.ndarray:
    """+1 where the contraction grows, −1 where it falls, within runs of constant pressure:
    the step that led to a sample, else the step that leaves it, else the nearest known."""
    n = len(x)
    d = np.zeros(n)
    same_prev = np.zeros(n, bool)
    same_prev[1:] = segment[1:] == segment[:-1]
    back = np.zeros(n)
    back[1:] = np.sign(x[1:] - x[:-1])
    d[same_prev] = back[same_prev]
    fwd = np.zeros(n)
    fwd[:-1] = np.sign(x[1:] - x[:-1])
    same_next = np.zeros(n, bool)
    same_next[:-1] = segment[:-1] == segment[1:]
    fill = (d == 0) & same_next
    d[fill] = fwd[fill]
    known = np.flatnonzero(d != 0)
    if len(known) == 0:
        return np.ones(n)
    idx = np.flatnonzero(d == 0)
    nearest = known[np.clip(np.searchsorted(known, idx), 0, len(known) - 1)]
    d[idx] = d[nearest]
    return d


def _rate(x: np.ndarray, t: np.ndarray, segment: np.ndarray) -> np.ndarray:
    v = np.zeros(len(x))
    for s in np.unique(segment):
        m = segment == s
        if np.sum(m) >= 2 and np.all(np.diff(t[m]) > 0):
            v[m] = np.gradient(x[m], t[m])
    return v


class StaticProblem:
    """One bench file prepared for diagnosis: packed data, covariates and effect features."""

    def __init__(self, bench, spec: ModelSpec, *, n_folds: int = N_FOLDS):
        self.spec = spec
        self.bench = bench
        frames = []
        for _, rows in bench.groups():
            if "time_s" in rows:
                rows = rows.sort_values("time_s", kind="stable").reset_index(drop=True)
            frames.append(derive_covariates(rows, spec))
        self.frames = frames
        allrows = pd.concat(frames, ignore_index=True)
        self.covariates = self._covariate_names(allrows)
        self.effects = self._effects(allrows)
        groups, curves, feats, folds = [], [], [], []
        for f in frames:
            x = spec.x_from_frame(f, bench.path)
            groups.append((x, f["force_N"].to_numpy(float)))
            curve = _curves(f)
            curves.append(curve)
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
        self.data = pack(groups, curves)
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
        theta, ok, _ = solve(spec, self.data)
        self.theta0 = theta
        self.baseline_converged = ok
        self.l0_mm = [bench.l0_mm.get(m_id) for m_id in bench.muscles]

    # -- covariates and features ------------------------------------------------------------

    def _covariate_names(self, rows: pd.DataFrame) -> list[str]:
        names = ["direction", "pressure_kPa", self.spec.contraction_column]
        for c in ("elapsed_s", "speed_mm_s", "speed_pct_s", "temperature_C", "cycle"):
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
        """Fit every set on all data and on every fold, in one batched call."""
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
        w = self.data.w[lanes_muscle]
        held = (self.fold[lanes_muscle] == (lanes_fold[:, None] - 1)) & (lanes_fold[:, None] > 0)
        w_train = np.where(held, 0.0, w)
        w_test = np.where(held, w, 0.0)
        feats = np.take_along_axis(
            self.features[lanes_muscle, lanes_fold], cols[lanes_set][:, None, :], axis=2
        ) * colmask[lanes_set][:, None, :]
        # Lanes with and without the compliance are solved by two compiled functions: the
        # implicit force law costs four Newton steps that the other lanes do not need.
        lane_comp = comp[lanes_set] > 0
        parts = {}
        for flag in (False, True):
            sel = np.flatnonzero(lane_comp == flag)
            if len(sel) == 0:
                continue
            parts[flag] = (sel, _fit_lanes(
                self.spec, flag, jnp.asarray(self.theta0[lanes_muscle[sel]]),
                tuple(jnp.asarray(xi[lanes_muscle[sel]]) for xi in self.data.x),
                jnp.asarray(self.data.y[lanes_muscle[sel]]), jnp.asarray(w_train[sel]),
                jnp.asarray(w_test[sel]), jnp.asarray(feats[sel]),
                jnp.asarray(colmask[lanes_set[sel]]),
            ))
        outs = []
        for j in range(7):
            first = next(iter(parts.values()))[1][j]
            arr = np.zeros((len(lanes_set), *np.shape(first)[1:]), dtype=np.asarray(first).dtype)
            for sel, out in parts.values():
                arr[sel] = np.asarray(out[j])
            outs.append(arr)
        params, sse, sse_test, resid, jtj_inv, ok, rank = outs
        results = []
        for i, s in enumerate(sets):
            full = (lanes_set == i) & (lanes_fold == 0)
            cv = (lanes_set == i) & (lanes_fold > 0)
            n_used = np.sum(self.data.w > 0, axis=1)
            unit_sse = np.zeros((m, self.n_curves))
            lane_idx = np.flatnonzero(cv)
            np.add.at(unit_sse, (lanes_muscle[lane_idx][:, None], np.maximum(
                self.data.curve[lanes_muscle[lane_idx]], 0)),
                w_test[lane_idx] * resid[lane_idx] ** 2)
            results.append(SetFit(
                effects=tuple(s), sse=sse[full], n=n_used, k=rank[full],
                cv_unit_sse=unit_sse[self.curve_used],
                cv_sse=float(np.sum(sse_test[cv])), cv_n=int(np.sum(w_test[cv] > 0)),
                converged=ok[full] & self.baseline_converged,
                extra={"params": params[full], "jtj_inv": jtj_inv[full],
                       "full_rank": rank[full] == k + len(slots[i]) + int(comp[i]),
                       "residual": resid[full], "slots": slots[i], "compliance": comp[i] > 0},
            ))
        return results


def _curves(frame: pd.DataFrame) -> np.ndarray:
    """Sweep index of each sample: a new sweep where pressure, direction or cycle changes."""
    keys = [frame["pressure_kPa"].to_numpy(float), frame["direction"].to_numpy(float)]
    if "cycle" in frame:
        keys.append(frame["cycle"].to_numpy(float))
    change = np.zeros(len(frame), bool)
    for k in keys:
        change[1:] |= k[1:] != k[:-1]
    return np.cumsum(change)


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


def _fit_lanes(spec, with_compliance, *arrays):
    """Solve the lanes; their count is padded to a power of two (repeating the last lane),
    so that the steps of a forward selection reuse a few compiled shapes."""
    n = jax.tree.leaves(arrays)[0].shape[0]
    size = max(64, 1 << (n - 1).bit_length())
    idx = np.minimum(np.arange(size), n - 1)
    padded = jax.tree.map(lambda a: a[idx], arrays)
    out = map_lanes(lambda *a: _fit_lanes_jit(spec, with_compliance, *a), *padded)
    return jax.tree.map(lambda a: a[:n], out)


def _lane(spec, with_compliance, theta0, x, y, w, w_test, feats, colmask):
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

    def step(state):
        params, lam, sse, it, done = state
        r, jac = normal(params)
        a = jac.T @ jac
        g = jac.T @ r
        d = jnp.diag(a) * mask + (1.0 - mask)
        trial = params - jnp.linalg.solve(a + lam * jnp.diag(d) + eye_off, g)
        r_new = resid(trial)
        sse_new = r_new @ r_new
        better = jnp.isfinite(sse_new) & (sse_new <= sse)
        params = jnp.where(better, trial, params)
        # At the optimum a step changes the SSE by rounding only, better or not.
        rel = jnp.abs(sse - sse_new) / jnp.maximum(sse, 1e-300)
        done = (rel < 1e-11) & (lam < 1.0)
        lam = jnp.where(better, jnp.maximum(lam / 5.0, 1e-12), lam * 8.0)
        done = done | (lam > 1e12)
        return params, lam, jnp.where(better, sse_new, sse), it + 1, done

    r0 = resid(params0)
    state = (params0, jnp.asarray(1e-4), r0 @ r0, 0, False)
    params, lam, sse, it, done = jax.lax.while_loop(
        lambda st: (~st[4]) & (st[3] < MAX_ITER), step, state)
    r, jac = normal(params)
    a = jac.T @ jac + eye_off
    jtj_inv = jnp.linalg.inv(a) * mask[:, None] * mask[None, :]
    # Numerical rank of the column-scaled Jacobian: constants the data cannot tell apart
    # count once in the BIC.
    norms = jnp.sqrt(jnp.sum(jac**2, axis=0))
    sv = jnp.linalg.svd(jac / jnp.where(norms > 0, norms, 1.0), compute_uv=False)
    rank = jnp.sum(sv > sv[0] * 1e-9)
    resid_all = y - pred(params)
    sse_test = jnp.sum(w_test * resid_all**2)
    ok = jnp.all(jnp.isfinite(params)) & (lam < 1e12)
    return params, sse, sse_test, resid_all, jtj_inv, ok, rank


def _fit_lanes_impl(spec, with_compliance, theta0, x, y, w, w_test, feats, colmask):
    return jax.vmap(lambda *a: _lane(spec, with_compliance, *a))(
        theta0, x, y, w, w_test, feats, colmask)


_fit_lanes_jit = jax.jit(_fit_lanes_impl, static_argnums=(0, 1))


def intervals(problem: StaticProblem, fit: SetFit, level: float = 0.95) -> list[dict]:
    """Per muscle: every selected effect's constants with Wald-t intervals."""
    from .._fit._intervals import t_critical

    k = problem.spec.n_params
    out = []
    params, cov_un = fit.extra["params"], fit.extra["jtj_inv"]
    for i in range(len(params)):
        dof = int(fit.n[i] - fit.k[i])
        s2 = float(fit.sse[i]) / dof if dof > 0 else math.nan
        t = float(t_critical(dof, level))
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
                consts[pname] = {"value": v, "ci95": [v - t * se[j], v + t * se[j]],
                                 "unit": unit}
            if name == "compliance" and e.units[0] == "%/N" and problem.l0_mm[i]:
                scale = problem.l0_mm[i] / 100.0
                c = consts["c"]
                consts["c_mm_per_N"] = {"value": c["value"] * scale,
                                        "ci95": [b * scale for b in c["ci95"]], "unit": "mm/N"}
            effects[name] = consts
        out.append(effects)
    return out
