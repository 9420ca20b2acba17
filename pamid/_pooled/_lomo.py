"""Pooled models judged on muscles left out: leave-one-muscle-out (LOMO) cross-validation.

:func:`compare_pooled` fits every pooled model of a file's muscles and scores each by how
well it predicts a muscle it did not see: for each muscle i, the model fitted to the other
muscles predicts muscle i's rows from its descriptors alone. All fits of one model — all
muscles, and each muscle left out — are lanes of one batched least-squares solve
(``fit_lanes`` of :mod:`pamid._fit._least_squares`, the engine of
:func:`pamid.fit_least_squares`), as the length study does (:mod:`pamid._diagnose._length`).

The models (:data:`POOLED_KINDS`), for each base model (Sárosi eq. 2.1 by default):

* ``<base>_shared``: one set of constants for every muscle;
* ``<base>_smooth``: every constant α + Σ β_d·ln(d/d_ref) of the descriptors;
* ``<base>_custom``: the roles the user gave (``roles=``, :func:`._spec.parse_roles`);
* ``<base>_nearest``: the base fitted to each muscle alone; a muscle left out takes the
  constants of the tested muscle nearest in ln l0 (what a lab without a pooled model does);

and, where the file gives each muscle's length at 620 kPa (``l620_mm``), the normalized law
of Bolen et al. 2026 (:class:`pamid._models._bolen.Bolen2026`) fitted (``bolen2026``) and at
the Hunt lab code's 10 mm coefficients (``bolen2026_lab_code``, not fitted). The law needs
each muscle's ε_max; a muscle left out (or a new one) takes the ε_max of a straight line in
ln l0 through the other muscles' (:func:`emax_law`), never its own.

**Predictive interval of a new muscle (least squares).** The LOMO residuals r = y − F̂ of
the held-out muscles hold the spread of a muscle about the population law and the noise
within a muscle. Their variance is modelled as σ² + τ²·F̂² (a noise floor and a spread that
scales with the force: muscles differ by a few per cent of their force), fitted to r² by
non-negative least squares with every muscle weighted equally; the 95 % interval is
F̂ ± √((z·σ)² + (t·√(1 + 1/M)·τ·F̂)²), z the normal and t the Student-t (M − 1 dof) 97.5 %
quantile: the spread between muscles is estimated from M muscles only (the interval of a
new draw from a population whose mean and spread are estimated from M).
``lomo_coverage_95`` reports, per muscle, the share of its rows inside the interval
calibrated on the *other* muscles' residuals.

**Partial pooling** (``bayes=key``): ``bolen2026_hierarchical``, the Bolen law with a
factor of each muscle's own drawn from the population (:mod:`._hierarchical`), sampled on
every lane; a new muscle's interval is its posterior predictive.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
from scipy import optimize

from .._data._bench import BenchData
from .._errors import BenchDataError
from .._fit._api import bench_to_fit_data
from .._fit._compare import predict_lanes
from .._fit._least_squares import fit_lanes
from .._fit._spec import ModelSpec, get_model, spec_from_model
from .._inference import t_critical
from .._lanes._batch import FitData
from .._models._bolen import HUNT_LAB_CODE_10MM, Bolen2026
from ._descriptors import EMAX, Descriptors, muscle_descriptors
from ._hierarchical import fit_hierarchical, predictive_interval
from ._spec import mean_per_muscle, pooled_spec

#: The pooled models of each base (module text), in the order they are fitted.
POOLED_KINDS = ("shared", "smooth", "custom", "nearest")
#: The hierarchical fit takes every k-th row of a file so that at most this many remain.
BAYES_MAX_ROWS = 6000
#: A pooled comparison needs this many muscles (two to fit a slope, one to leave out).
MIN_MUSCLES = 3
LEVEL = 0.95
#: The pooled fits' step budget: Sárosi's 12 constants smooth in ln l0 took 135–442
#: Levenberg–Marquardt steps on a virtual population (100, the budget of a one-muscle fit,
#: left 8 of 9 lanes short of the tolerance).
MAX_STEPS = 1000


@dataclasses.dataclass(frozen=True)
class PredictiveSpread:
    """The spread of a new muscle's force about the pooled prediction F̂ (module text).

    Attributes:
        sigma_N: the noise floor σ (N); ``tau`` the relative spread τ between muscles.
        t_quantile: t's 97.5 % quantile on ``n_muscles`` − 1 dof; ``z`` the normal one.
    """

    sigma_N: float
    tau: float
    t_quantile: float
    z: float
    n_muscles: int

    def half_width(self, force_N):
        return half_width(self.to_dict(), force_N)

    def to_dict(self) -> dict:
        return {"sigma_N": self.sigma_N, "tau": self.tau, "t_quantile": self.t_quantile,
                "z": self.z, "n_muscles": self.n_muscles, "level": LEVEL,
                "form": "F̂ ± √((z·σ)² + (t·√(1 + 1/M)·τ·F̂)²)"}


def half_width(spread: dict, force_N):
    """The half-width of the predictive interval at the predicted forces ``force_N``, from a
    spread's JSON (:meth:`PredictiveSpread.to_dict`): √((z·σ)² + (t·√(1 + 1/M)·τ·F̂)²), the
    factor √(1 + 1/M) for the population mean estimated from M muscles."""
    force_N = np.asarray(force_N, dtype=np.float64)
    between = spread["t_quantile"] * math.sqrt(1.0 + 1.0 / spread["n_muscles"]) * spread["tau"]
    return np.sqrt((spread["z"] * spread["sigma_N"]) ** 2 + (between * force_N) ** 2)


def fit_spread(resid, pred, muscle, n_muscles: int, level: float = LEVEL) -> PredictiveSpread:
    """σ and τ of r² ≈ σ² + τ²·F̂² by non-negative least squares, each muscle weighted
    equally (rows of muscle i by 1/n_i); ``muscle`` holds each row's index."""
    resid, pred = np.asarray(resid, np.float64), np.asarray(pred, np.float64)
    muscle = np.asarray(muscle)
    counts = np.bincount(muscle, minlength=n_muscles).astype(np.float64)
    w = np.sqrt(1.0 / counts[muscle])
    scale = max(float(np.mean(resid**2)), 1e-300)
    f2 = pred**2 / max(float(np.mean(pred**2)), 1e-300)
    design = np.stack([np.ones_like(pred), f2], axis=1) * w[:, None]
    (s2, t2), _ = optimize.nnls(design, resid**2 / scale * w)
    tau2 = t2 * scale / max(float(np.mean(pred**2)), 1e-300)
    k = int(np.count_nonzero(counts))
    return PredictiveSpread(
        sigma_N=math.sqrt(s2 * scale), tau=math.sqrt(tau2),
        t_quantile=float(t_critical(max(k - 1, 1), level)),
        z=float(t_critical(math.inf, level)), n_muscles=k)  # t with ∞ dof: the normal


def emax_law(l0_mm, emax_pct, l0_ref_mm: float) -> tuple[float, float]:
    """(e0, e1) of ε_max ≈ e0 + e1·ln(l0/l0_ref) in %, least squares over the muscles given
    (e1 = 0 with fewer than two distinct lengths)."""
    g = np.log(np.asarray(l0_mm, np.float64) / l0_ref_mm)
    e = np.asarray(emax_pct, np.float64)
    if np.ptp(g) == 0:
        return float(np.mean(e)), 0.0
    e1, e0 = np.polyfit(g, e, 1)
    return float(e0), float(e1)


@dataclasses.dataclass(frozen=True)
class PooledModel:
    """One pooled model: its fit to every muscle and its LOMO score; ``to_dict`` is its
    entry in the ``"pooled"`` list of ``pamid compare --pooled --json`` (and what
    ``pamid predict`` reads back).

    Attributes:
        model, kind, base, roles, source: the model's name, kind ("shared", "smooth",
            "custom", "nearest", "bolen", "bolen_lab_code"), base model, the roles of the
            base's constants, and what it fits.
        param_names, param_units, theta: the constants of the fit to every muscle (for
            "nearest": the per-muscle constants, ``theta_per_muscle``).
        n_params, rmse_N, converged: constants fitted, RMSE of that fit, whether it (and
            every LOMO lane) converged.
        lomo_rmse_N, lomo_rmse_pct_fmax: RMSE of every row predicted with its muscle left
            out, in N and in % of the file's largest force.
        muscles: per muscle (name, l0_mm, rows, LOMO RMSE, LOMO coverage of the 95 %
            interval calibrated on the other muscles).
        spread: the predictive spread of a new muscle (:class:`PredictiveSpread`).
        descriptors: the file's descriptors (used, references, constant ones).
        emax: (e0, e1, l0_ref_mm) of ε_max in ln l0 over all muscles, for the Bolen law.
    """

    model: str
    kind: str
    base: str | None
    roles: tuple[str, ...] | None
    source: str
    param_names: tuple[str, ...]
    param_units: dict[str, str]
    theta: np.ndarray
    n_params: int
    rmse_N: float
    converged: bool
    lomo_rmse_N: float
    lomo_rmse_pct_fmax: float
    lomo_coverage_95: float
    muscles: tuple[dict, ...]
    spread: PredictiveSpread
    descriptors: Descriptors
    emax: tuple[float, float, float] | None = None
    theta_per_muscle: np.ndarray | None = None
    contraction_max_pct: float = float("nan")
    pressure_max_kPa: float = float("nan")
    lomo_lanes_converged: int | None = None
    posterior: dict | None = None

    def to_dict(self) -> dict:
        d = self.descriptors
        out = {
            "model": self.model,
            "lomo_rmse_N": _num(self.lomo_rmse_N),
            "lomo_rmse_pct_fmax": _num(self.lomo_rmse_pct_fmax),
            "muscles": [{k: _num(v) for k, v in m.items()} for m in self.muscles],
            "kind": self.kind, "base": self.base,
            "roles": (None if self.roles is None else
                      dict(zip(get_model(self.base).param_names, self.roles, strict=True))),
            "source": self.source, "n_params": self.n_params, "rmse_N": _num(self.rmse_N),
            "converged": self.converged, "lomo_lanes_converged": self.lomo_lanes_converged,
            "lomo_coverage_95": _num(self.lomo_coverage_95),
            "constants": {n: _num(v) for n, v in zip(self.param_names, self.theta,
                                                     strict=True)},
            "units": dict(self.param_units),
            "spread": self.spread.to_dict(),
            "descriptors": {"used": list(d.used), "ref": dict(d.ref),
                            "constant": dict(d.constant),
                            "muscle_values": {k: [float(x) for x in v]
                                              for k, v in d.values.items()}},
            "emax_law": (None if self.emax is None else
                         {"e0_pct": self.emax[0], "e1_pct": self.emax[1],
                          "l0_ref_mm": self.emax[2],
                          "form": "emax_pct = e0 + e1·ln(l0/l0_ref)"}),
            "contraction_max_pct": _num(self.contraction_max_pct),
            "pressure_max_kPa": _num(self.pressure_max_kPa),
        }
        if self.posterior is not None:
            out["posterior"] = self.posterior
        if self.theta_per_muscle is not None:
            out["constants_per_muscle"] = {
                mu: {n: _num(v) for n, v in zip(self.param_names, row, strict=True)}
                for mu, row in zip(d.muscles, self.theta_per_muscle, strict=True)}
        return out


@dataclasses.dataclass(frozen=True)
class PooledComparison:
    """Every pooled model of a file, best LOMO RMSE first; ``skipped``: (model, why)."""

    models: tuple[PooledModel, ...]
    muscles: tuple[str, ...]
    describe: tuple[str, ...]
    notes: tuple[str, ...]
    skipped: tuple[tuple[str, str], ...]
    fmax_N: float

    def model(self, name: str) -> PooledModel:
        return next(m for m in self.models if m.model == name)

    def to_dict(self) -> dict:
        return {"pooled": [m.to_dict() for m in self.models],
                "pooled_describe": list(self.describe), "pooled_notes": list(self.notes),
                "pooled_skipped": [{"model": n, "why": w} for n, w in self.skipped],
                "pooled_fmax_N": self.fmax_N,
                "pooled_level": LEVEL}


def _num(x):
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


@functools.cache
def bolen_spec() -> ModelSpec:
    return spec_from_model(Bolen2026)


@dataclasses.dataclass(frozen=True)
class _Rows:
    """The file's rows as the pooled fits take them."""

    bench: BenchData
    desc: Descriptors
    muscle: np.ndarray  # (N,) index
    y: np.ndarray
    m: int

    @property
    def n(self) -> int:
        return len(self.y)


def _lanes(rows: _Rows, x_lanes) -> FitData:
    """One lane with every row, then one per muscle left out."""
    m, n = rows.m, rows.n
    w = np.stack([np.ones(n)] + [(rows.muscle != i).astype(float) for i in range(m)])
    lanes = m + 1
    return FitData(
        x=tuple(jnp.asarray(np.broadcast_to(np.asarray(xi, np.float64), (lanes, n)))
                for xi in x_lanes),
        y=jnp.asarray(np.broadcast_to(rows.y, (lanes, n))),
        w=jnp.asarray(w),
        curve=jnp.zeros((lanes, n), dtype=jnp.int32),
    )


def _solve(spec: ModelSpec, data: FitData):
    """Every lane by pamid's batched least squares (the constants within the model's
    bounds), with the pooled fits' step budget; no intervals (the pooled model's
    uncertainty for a new muscle is its LOMO spread, not the constants' Wald interval)."""
    return fit_lanes(spec, data, solver="levenberg-marquardt", max_steps=MAX_STEPS)


def _held(pred_lanes: np.ndarray, rows: _Rows) -> np.ndarray:
    """Each row predicted by the lane that left its muscle out."""
    return pred_lanes[1 + rows.muscle, np.arange(rows.n)]


def _score(name, kind, base, roles, source, spec_names, units, theta, n_params, fit_pred,
           held, converged, rows: _Rows, fmax, **extra) -> PooledModel:
    y, muscle, m = rows.y, rows.muscle, rows.m
    resid = y - held
    spread = fit_spread(resid, held, muscle, m)
    per, inside_all = [], np.zeros(rows.n, dtype=bool)
    for i in range(m):
        sel = muscle == i
        others = ~sel
        sp = fit_spread(resid[others], held[others], muscle[others], m)
        inside = np.abs(resid[sel]) <= sp.half_width(held[sel])
        inside_all[sel] = inside
        per.append({"muscle": rows.desc.muscles[i],
                    "lomo_rmse_N": float(np.sqrt(np.mean(resid[sel] ** 2))),
                    "l0_mm": float(rows.desc.values["l0_mm"][i]), "n": int(sel.sum()),
                    "lomo_coverage_95": float(np.mean(inside))})
    lomo = float(np.sqrt(np.mean(resid**2)))
    frame = rows.bench.frame
    return PooledModel(
        model=name, kind=kind, base=base, roles=roles, source=source,
        param_names=tuple(spec_names), param_units=dict(units),
        theta=np.asarray(theta, np.float64), n_params=n_params,
        rmse_N=float(np.sqrt(np.mean((y - fit_pred) ** 2))), converged=bool(converged),
        lomo_rmse_N=lomo, lomo_rmse_pct_fmax=100.0 * lomo / fmax,
        lomo_coverage_95=float(np.mean([p["lomo_coverage_95"] for p in per])),
        muscles=tuple(per), spread=spread, descriptors=rows.desc,
        contraction_max_pct=float(frame["contraction_pct"].max()),
        pressure_max_kPa=float(frame["pressure_kPa"].max()), **extra)


def _pooled_base(rows: _Rows, base: ModelSpec, roles, kind: str, fmax) -> PooledModel:
    desc = rows.desc
    spec = pooled_spec(base, tuple(roles), desc.used, rows.m)
    feats = desc.features()[rows.muscle]  # (N, D)
    x = (*base.x_from_frame(rows.bench.frame, rows.bench.path), rows.muscle.astype(float),
         *feats.T)
    data = _lanes(rows, x)
    fit = _solve(spec, data)
    theta = np.array(fit.theta, np.float64)
    if "per_muscle" in roles:
        every = np.arange(rows.m)
        for i in range(rows.m):
            theta[1 + i] = mean_per_muscle(theta[1 + i], base, tuple(roles), desc.used,
                                           rows.m, i, every[every != i])
    pred = predict_lanes(spec, theta, data.x)
    # "converged": the fit to every muscle. A LOMO lane that stopped at the solver's step
    # limit still predicts from its last accepted point (counted in lomo_lanes_converged);
    # one with per-muscle constants has no rows for those of the muscle it leaves out.
    return _score(f"{base.name}_{kind}", kind, base.name, tuple(roles), spec.source,
                  spec.param_names, spec.param_units, theta[0], spec.n_params, pred[0],
                  _held(pred, rows), bool(fit.ok[0]), rows, fmax,
                  lomo_lanes_converged=int(np.sum(fit.ok[1:])))


def _per_muscle(rows: _Rows, column: str) -> np.ndarray | None:
    """A per-muscle column of the file as (M,) values (each muscle's first row), or None."""
    frame = rows.bench.frame
    if column not in frame:
        return None
    first = pd.Series(frame[column].to_numpy()).groupby(rows.muscle).first()
    return pd.to_numeric(first.reindex(range(rows.m)), errors="coerce").to_numpy(np.float64)


def _kinship(rows: _Rows) -> list[np.ndarray]:
    """The muscles' descriptors other than their length (the diameter where the file logs
    it, and any other described one): what a lab matches before it looks at the length."""
    out = [rows.desc.values[n] for n in rows.desc.described
           if n not in ("l0_mm", "l620_mm", EMAX)]
    diameter = _per_muscle(rows, "diameter_mm")
    if diameter is not None and "diameter_mm" not in rows.desc.values:
        out.append(diameter)
    return out


def _nearest(rows: _Rows, base: ModelSpec, fmax) -> PooledModel:
    per = fit_lanes(base, bench_to_fit_data(rows.bench, base, curves=False))
    theta = np.asarray(per.theta, np.float64)
    ln_l0 = np.log(rows.desc.values["l0_mm"])
    x = base.x_from_frame(rows.bench.frame, rows.bench.path)
    kin = _kinship(rows)
    nearest = np.empty(rows.m, dtype=int)
    for i in range(rows.m):
        # The nearest length among the muscles of the same diameter (and other
        # descriptors); among all where none shares them.
        same = np.ones(rows.m, bool)
        for v in kin:
            same &= np.isclose(v, v[i], rtol=1e-9, atol=0.0)
        same[i] = False
        d = np.abs(ln_l0 - ln_l0[i])
        d[i] = np.inf
        if same.any():
            d = np.where(same, d, np.inf)
        nearest[i] = int(np.argmin(d))
    pred_own = np.asarray(base.predict(jnp.asarray(theta[rows.muscle]),
                                       tuple(jnp.asarray(xi) for xi in x)))
    held = np.asarray(base.predict(jnp.asarray(theta[nearest[rows.muscle]]),
                                   tuple(jnp.asarray(xi) for xi in x)))
    return _score(f"{base.name}_nearest", "nearest", base.name, None,
                  f"{base.source}, fitted per muscle; an untested muscle takes the "
                  "constants of the tested one nearest in ln l0 of the same diameter",
                  base.param_names, base.param_units, np.full(base.n_params, np.nan),
                  rows.m * base.n_params, pred_own, held, bool(np.all(per.ok)),
                  rows, fmax, theta_per_muscle=theta)


def _bolen_x(rows: _Rows, emax_pct_rows):
    frame = rows.bench.frame
    return (frame["pressure_kPa"].to_numpy(np.float64),
            frame["contraction_pct"].to_numpy(np.float64) / 100.0,
            rows.desc.values["l0_mm"][rows.muscle],
            np.asarray(emax_pct_rows) / 100.0)


def _bolen(rows: _Rows, fmax, bayes=None, sampling=None) -> list[PooledModel]:
    desc = rows.desc
    l0, emax = desc.values["l0_mm"], desc.values[EMAX]
    l0_ref = float(np.exp(np.mean(np.log(l0))))
    law = emax_law(l0, emax, l0_ref)
    # Lane 0: every muscle's own ε_max; lane 1 + i: muscle i's from the others' line.
    emax_lanes = np.broadcast_to(emax[rows.muscle], (rows.m + 1, rows.n)).copy()
    every = np.arange(rows.m)
    for i in range(rows.m):
        e0, e1 = emax_law(l0[every != i], emax[every != i], l0_ref)
        emax_lanes[1 + i, rows.muscle == i] = e0 + e1 * math.log(l0[i] / l0_ref)
    x = _bolen_x(rows, emax_lanes[0])
    n_lanes = rows.m + 1
    x_lanes = (*(np.broadcast_to(v, (n_lanes, rows.n)) for v in x[:3]), emax_lanes / 100.0)
    data = _lanes(rows, x_lanes)
    spec = bolen_spec()
    fit = _solve(spec, data)
    theta = np.asarray(fit.theta, np.float64)
    pred = predict_lanes(spec, theta, data.x)
    emax_info = (law[0], law[1], l0_ref)
    fitted = _score("bolen2026", "bolen", None, None, spec.source, spec.param_names,
                    spec.param_units, theta[0], spec.n_params, pred[0], _held(pred, rows),
                    bool(fit.ok[0]), rows, fmax, emax=emax_info,
                    lomo_lanes_converged=int(np.sum(fit.ok[1:])))
    lab = np.array([HUNT_LAB_CODE_10MM[n] for n in spec.param_names])
    pred_lab = predict_lanes(spec, np.broadcast_to(lab, (n_lanes, lab.size)), data.x)
    fixed = _score("bolen2026_lab_code", "bolen_lab_code", None, None,
                   "Bolen et al. 2026 law at the Hunt lab code's 10 mm coefficients (not "
                   "fitted; not checked against the paper)", spec.param_names,
                   spec.param_units, lab, 0, pred_lab[0], _held(pred_lab, rows), True, rows,
                   fmax, emax=emax_info)
    out = [fitted, fixed]
    if bayes is not None:
        out.append(_bolen_hierarchical(rows, fmax, bayes, x_lanes, theta, emax_info,
                                       sampling or {}))
    return out


def _bolen_hierarchical(rows: _Rows, fmax, key, x_lanes, theta_lanes, emax_info,
                        sampling: dict):
    """The hierarchical Bolen law (:mod:`._hierarchical`) on every lane: all muscles, and
    each muscle left out (its rows weighted 0: its factor keeps its prior). The fit takes
    every k-th row of the file so that at most :data:`BAYES_MAX_ROWS` remain (the sampler
    evaluates every row for each walker and step); the held-out muscles are scored on all
    their rows, by the predictive median and the share of rows inside the 95 % predictive
    interval."""
    spec = bolen_spec()
    lower, upper = (np.asarray(b) for b in spec.bounds)
    every = max(1, -(-rows.n // BAYES_MAX_ROWS))
    sub = np.arange(0, rows.n, every)
    w = np.stack([np.ones(sub.size)] + [(rows.muscle[sub] != i).astype(float)
                                        for i in range(rows.m)])
    k_fit, k_pred = jax.random.split(key)
    post = fit_hierarchical(k_fit, tuple(np.asarray(v)[:, sub] for v in x_lanes),
                            np.broadcast_to(rows.y[sub], w.shape),
                            np.broadcast_to(rows.muscle[sub], w.shape), rows.m, theta_lanes,
                            lower=lower, upper=upper, w=w, **sampling)
    held = np.empty(rows.n)
    inside = np.zeros(rows.n, dtype=bool)
    for i in range(rows.m):
        sel = rows.muscle == i
        draws = {"theta": post.theta[1 + i], "tau": post.tau[1 + i],
                 "sigma_N": post.sigma_N[1 + i]}
        med, low, high = predictive_interval(jax.random.fold_in(k_pred, i), draws,
                                             *(np.asarray(v)[1 + i, sel] for v in x_lanes))
        held[sel] = med
        inside[sel] = (rows.y[sel] >= low) & (rows.y[sel] <= high)
    everyone = dataclasses.replace(post, theta=post.theta[0], tau=post.tau[0],
                                   sigma_N=post.sigma_N[0], scale=post.scale[0])
    fit_pred = np.asarray(predict_lanes(spec, np.median(post.theta[:1], axis=1),
                                        tuple(np.asarray(v)[:1] for v in x_lanes)))[0]
    model = _score("bolen2026_hierarchical", "bolen_hierarchical", None, None,
                   f"{spec.source}; each muscle's force × exp(τ·z), hierarchical Bayes "
                   f"(ensemble sampler, every {every} row(s))", spec.param_names,
                   spec.param_units, np.median(post.theta[0], axis=0), spec.n_params + 2,
                   fit_pred, held, True, rows, fmax, emax=emax_info,
                   posterior=everyone.to_dict())
    muscles = tuple(m | {"lomo_coverage_95": float(np.mean(inside[rows.muscle == i]))}
                    for i, m in enumerate(model.muscles))
    return dataclasses.replace(model, muscles=muscles, lomo_coverage_95=float(
        np.mean([m["lomo_coverage_95"] for m in muscles])))


def compare_pooled(bench: BenchData, models=("sarosi",), *, describe=("l0_mm",),
                   roles: tuple[str, ...] | None = None, kinds=POOLED_KINDS,
                   bolen: bool = True, bayes=None, sampling: dict | None = None,
                   progress=None) -> PooledComparison:
    """Fit every pooled model of ``bench``'s muscles and rank them by LOMO RMSE (module
    text).

    Args:
        bench: a file of at least :data:`MIN_MUSCLES` muscles of known ``l0_mm``.
        models: the base models of the ``shared``/``smooth``/``custom``/``nearest`` models
            (names, ForceModels or specs).
        describe: the descriptors a smooth constant depends on (``l0_mm``, ``diameter_mm``,
            ``emax_pct`` or any numeric per-muscle column).
        roles: the roles of the base's constants for ``<base>_custom``
            (:func:`._spec.parse_roles`); without it that model is not fitted.
        kinds: which of :data:`POOLED_KINDS` to fit.
        bolen: also the Bolen et al. 2026 law, where the file gives ``l620_mm``.
        bayes: a PRNG key: also the hierarchical Bayesian Bolen law
            (``bolen2026_hierarchical``, :mod:`._hierarchical`; minutes of sampling on a
            file of thousands of rows).
        sampling: the sampler's settings (``n_walkers``, ``n_burn``, ``n_draws``, ``thin``
            of :func:`._hierarchical.fit_hierarchical`).

    Raises:
        BenchDataError: fewer than :data:`MIN_MUSCLES` muscles, a muscle without l0, a bad
            descriptor.
    """
    say = progress or (lambda _msg: None)
    if len(bench.muscles) < MIN_MUSCLES:
        raise BenchDataError(bench.path, f"a pooled comparison needs at least {MIN_MUSCLES} "
                             f"muscles (a muscle column); the file has {len(bench.muscles)}",
                             column="muscle")
    desc = muscle_descriptors(bench, tuple(describe))
    frame = bench.frame
    muscle = pd.Categorical(frame["muscle"], categories=list(desc.muscles)).codes.astype(int)
    rows = _Rows(bench=bench, desc=desc, muscle=muscle,
                 y=frame["force_N"].to_numpy(np.float64), m=len(desc.muscles))
    fmax = float(np.max(np.abs(rows.y)))
    out, skipped = [], []
    for ref in models:
        base = get_model(ref, frame)
        for kind in kinds:
            if kind == "custom" and roles is None:
                continue
            say(f"pooled {base.name}_{kind}: {rows.m + 1} lanes (all muscles, each left out)")
            if kind == "nearest":
                out.append(_nearest(rows, base, fmax))
                continue
            r = {"shared": ("shared",) * base.n_params,
                 "smooth": ("smooth",) * base.n_params, "custom": roles}[kind]
            if len(r) != base.n_params:
                raise ValueError(f"roles give {len(r)} constants; {base.name} has "
                                 f"{base.n_params}")
            out.append(_pooled_base(rows, base, r, kind, fmax))
    diameters = _per_muscle(rows, "diameter_mm")
    sizes = (set() if diameters is None else
             {float(d) for d in diameters[np.isfinite(diameters)]})
    if bolen:
        if len(sizes) > 1:
            skipped.append(("bolen2026", "the law's F620(l0) is fitted for one diameter at a "
                                         "time (Bolen et al. 2026 fit their 10 mm and 20 mm "
                                         "muscles apart); this file has muscles of "
                                         f"{', '.join(f'{d:g}' for d in sorted(sizes))} mm: "
                                         "compare each diameter's muscles on their own"))
        elif EMAX in desc.values:
            say("pooled bolen2026: the normalized law, fitted and at the lab code's values")
            models = _bolen(rows, fmax, bayes, sampling)
            if sizes and sizes != {10.0}:
                models = [p for p in models if p.model != "bolen2026_lab_code"]
                skipped.append(("bolen2026_lab_code", "the Hunt lab code's coefficients are "
                                "for 10 mm muscles; these are "
                                f"{', '.join(f'{d:g}' for d in sorted(sizes))} mm"))
            out += models
        else:
            skipped.append(("bolen2026", "the law needs each muscle's maximal contraction "
                                         "(an l620_mm column: its length at 620 kPa)"))
    out.sort(key=lambda p: (not p.converged, p.lomo_rmse_N))
    return PooledComparison(models=tuple(out), muscles=desc.muscles,
                            describe=tuple(describe), notes=desc.notes,
                            skipped=tuple(skipped), fmax_N=fmax)
