"""Posterior sampling of a static model's constants and noise, one ensemble per muscle.

Two samplers advance the same ensembles with the same moves on the same JAX log-posterior
(:mod:`._posterior`):

* ``"emcee"``: one :class:`emcee.EnsembleSampler` per muscle with ``vectorize=True``; its
  log-probability is the jitted log-posterior ``vmap``-ped over walkers.
* ``"stacked"``: pamid's own ensemble moves in JAX. The walkers of all M muscles are
  stacked, (M, W, d), and one jitted, ``vmap``-ped call evaluates every proposal of every
  muscle; ``lax.scan`` runs many steps per call, so there is no Python between steps. The
  M ensembles stay independent: a walker only ever moves relative to walkers of its own
  muscle. Keys are explicit (``jax.random``).

Moves: a share ``de_fraction`` = 0.8 of the moves are differential-evolution moves (ter
Braak 2006; emcee's ``DEMove``, γ = 2.38/√(2d)), the rest Goodman & Weare's stretch move
(a = 2). Both are affine invariant and both leave the posterior invariant, so a mixture
of them does too (the stacked sampler draws the move per walker, emcee per step).
Measured on Sárosi's and Cullinan's posteriors (synthetic data, the Martens DMSP-10 map;
8000 steps, 32 walkers), the integrated autocorrelation time τ was 27–34 steps with this
mixture against 76–92 with the stretch move alone, for the same means and standard
deviations: a run of 50 τ costs a third. The stretch move stays in the mix because it
explores heavy tails better: with the Student-t likelihood on data with outliers the
noise σ has a faint far tail (≈ 0.5% of the mass near σ ≈ 3 N) that pure DE visited less
often. ``de_fraction=0`` gives the pure stretch move, ``1`` pure DE.

Which is faster (``benchmarks/mcmc_batch.py``; figures: benchmarks/README.md, "Figures
that used to live in docstrings", (a)): per step and muscle the stacked sampler is about an
order of magnitude faster than a loop of emcee samplers, with a JAX or a NumPy
log-probability. Its gain is the absence of Python between
steps, not the batching: its cost per muscle hardly changes with M. Its compilation is
cached on disk by the CLI; for one muscle in a fresh process without that cache, a whole
emcee run is about as fast. So ``sampler="auto"`` means ``"stacked"`` (``AUTO_SAMPLER``).
The stacked sampler's kernel and moves are public (:mod:`._ensemble`, ``pamid.ensemble_step``),
and so are the sampler and its pieces (``pamid.engine.StackedSampler``, ``walker_log_prob``,
``initial_walkers``).

Run length. Walkers start in a small ball around the least-squares optimum (0.1 Wald
standard errors). The chains grow in chunks; every ``check_every`` steps the integrated
autocorrelation time τ is estimated (emcee's estimator, averaged over walkers), the first
``burn_tau``·τ steps are discarded as burn-in, and sampling stops once what is kept spans
at least ``n_tau`` = 50 τ for every muscle, constant and σ. If ``max_steps`` runs out first,
a :class:`McmcBudgetWarning` says how many steps would have been needed, and the muscles
concerned are reported as not converged.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import sys
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._data._bench import BenchData
from .._fit._api import FitResult, bench_to_fit_data, fit_least_squares
from .._fit._spec import ModelSpec, get_model
from .._lanes._batch import FitData
from . import _posterior
from ._ensemble import EnsembleState, de_move, run_ensembles, stretch_move
from ._options import SAMPLERS
from ._posterior import DEFAULT_NU, LIKELIHOODS, Prior, default_prior, restricted_prior

AUTO_SAMPLER = "stacked"  # measured faster at M = 1 … 1000 (benchmarks/mcmc_batch.py)
DE_FRACTION = 0.8  # see the module docstring
R_HAT_MAX = 1.05  # a muscle whose worst R-hat (walkers as chains) exceeds this: not converged


class McmcBudgetWarning(UserWarning):
    """The step budget ended before the chains spanned ``n_tau`` autocorrelation times."""


# --------------------------------------------------------------------------------------
# The stacked sampler: pamid's ensemble kernel (``_ensemble``) over the muscles' posteriors.


@functools.partial(jax.jit, static_argnames=("log_prob", "n_draws", "thin", "de_fraction"))
def _advance_stacked(log_prob, key, state, x, y, w, n_draws, thin, de_fraction=DE_FRACTION):
    """``n_draws · thin`` steps of all ensembles; every ``thin``-th state is kept. The moves:
    differential evolution with probability ``de_fraction``, else the stretch move."""
    per_walker = jax.vmap(log_prob, in_axes=(0, None, None, None))
    per_muscle = jax.vmap(per_walker, in_axes=(0, 0, 0, 0))

    def lp_fn(z):
        return per_muscle(z, x, y, w)

    moves = ((de_move, de_fraction), (stretch_move, 1.0 - de_fraction))
    return run_ensembles(key, state, lp_fn, n_draws, thin, moves)


@functools.cache
def _log_prob(spec: ModelSpec, prior: Prior, likelihood: str, nu: float):
    # One function object per (model, prior, likelihood): jit caches by its identity.
    return _posterior.make_log_prob(spec, prior, likelihood, nu)


@functools.cache
def _walker_log_prob(spec, prior, likelihood, nu):
    """jit(vmap over walkers): emcee's vectorized log-probability for one muscle."""
    return jax.jit(jax.vmap(_log_prob(spec, prior, likelihood, nu),
                            in_axes=(0, None, None, None)))


def walker_log_prob(spec: ModelSpec, prior: Prior, likelihood: str = "normal",
                    nu: float = DEFAULT_NU):
    """The log-posterior :func:`fit_mcmc` samples, for one walker of one muscle:
    ``log_prob(z, x, y, w)`` with z = (θ, log σ) (:func:`._posterior.make_log_prob`). The
    same function object for the same arguments, so that what is compiled with it (a
    :class:`StackedSampler`, :func:`initial_walkers`) is compiled once."""
    return _log_prob(spec, prior, likelihood, float(nu))


def ensemble_log_prob(spec: ModelSpec, prior: Prior, likelihood: str = "normal",
                      nu: float = DEFAULT_NU):
    """:func:`walker_log_prob` ``vmap``-ped over the walkers of one muscle and jitted:
    ``f(z (W, d), x, y, w) -> (W,)``, the vectorized log-probability that
    ``fit_mcmc(sampler="emcee")`` hands each ``emcee.EnsembleSampler``."""
    return _walker_log_prob(spec, prior, likelihood, float(nu))


@functools.cache
def _stacked_log_prob(log_prob):
    """jit(vmap over muscles of vmap over walkers): (M, W, d) → (M, W)."""
    return jax.jit(jax.vmap(jax.vmap(log_prob, (0, None, None, None)), (0, 0, 0, 0)))


class StackedSampler:
    """The ``"stacked"`` sampler of :func:`fit_mcmc`: the ensembles of all muscles of
    ``data``, advanced together by one compiled call per chunk of steps (module docstring).

    ``log_prob``: one walker's log-posterior (:func:`walker_log_prob`); ``key``: a JAX PRNG
    key; ``position``: the walkers' start (M, W, d), e.g. :func:`initial_walkers`;
    ``de_fraction``: the share of differential-evolution moves, the rest stretch moves.
    :meth:`advance` runs ``n_steps`` steps (a multiple of ``thin``) and returns the kept
    positions (M, n_steps/thin, W, d), their log-posteriors (M, n_steps/thin, W) and the
    accepted moves per muscle (M,); ``state`` is the last :class:`EnsembleState`. A call
    with the same ``n_steps`` and ``thin`` reuses the compiled program.
    """

    name = "stacked"

    def __init__(self, log_prob, key, position, data: FitData,
                 de_fraction: float = DE_FRACTION):
        self.log_prob, self.key, self.de_fraction = log_prob, key, de_fraction
        self.x, self.y, self.w = data.x, data.y, data.w
        lp = _stacked_log_prob(log_prob)(jnp.asarray(position), self.x, self.y, self.w)
        self.state = EnsembleState(jnp.asarray(position), lp)

    def advance(self, n_steps, thin):
        self.key, k = jax.random.split(self.key)
        self.state, pos, lp, acc = _advance_stacked(
            self.log_prob, k, self.state, self.x, self.y, self.w, n_steps // thin, thin,
            self.de_fraction)
        # (draws, M, W, …) → (M, draws, W, …)
        return (np.moveaxis(np.asarray(pos), 0, 1), np.moveaxis(np.asarray(lp), 0, 1),
                np.asarray(acc))


class _EmceeBackend:
    """A loop of emcee samplers, one per muscle, advanced chunk by chunk together."""

    name = "emcee"

    def __init__(self, spec, prior, likelihood, nu, key, position, data: FitData,
                 de_fraction):
        import emcee

        f = _walker_log_prob(spec, prior, likelihood, nu)
        m, n_walkers, ndim = position.shape
        seeds = np.asarray(jax.random.randint(key, (m,), 0, 2**31 - 1))
        self.samplers, self.states = [], []
        for i in range(m):
            x_i = tuple(xj[i] for xj in data.x)
            y_i, w_i = data.y[i], data.w[i]

            def log_prob(z, x_i=x_i, y_i=y_i, w_i=w_i):
                return np.asarray(f(jnp.asarray(z), x_i, y_i, w_i))

            moves = [(emcee.moves.DEMove(), de_fraction),
                     (emcee.moves.StretchMove(), 1.0 - de_fraction)]
            moves = [mv for mv in moves if mv[1] > 0]
            sampler = emcee.EnsembleSampler(n_walkers, ndim, log_prob, vectorize=True,
                                            moves=moves)
            sampler.random_state = np.random.RandomState(int(seeds[i])).get_state()
            self.samplers.append(sampler)
            self.states.append(emcee.State(np.asarray(position[i])))

    def advance(self, n_steps, thin):
        pos, lp, acc = [], [], []
        for i, sampler in enumerate(self.samplers):
            before = sampler.backend.accepted.sum()
            self.states[i] = sampler.run_mcmc(self.states[i], n_steps // thin, thin_by=thin,
                                              skip_initial_state_check=True)
            chain = sampler.get_chain()[-(n_steps // thin):]  # (draws, W, d)
            pos.append(chain)
            lp.append(sampler.get_log_prob()[-(n_steps // thin):])
            # emcee counts the acceptances of the last step of every thinned block only.
            acc.append((sampler.backend.accepted.sum() - before) * thin)
        return np.stack(pos), np.stack(lp), np.asarray(acc)


# --------------------------------------------------------------------------------------
# Autocorrelation time.


def integrated_time(chain, c: float = 5.0) -> np.ndarray:
    """Integrated autocorrelation time of every coordinate, in draws: emcee's estimator
    (autocorrelation averaged over walkers, Sokal's automatic window with ``c``), vectorized
    over leading axes. ``chain``: (..., n_draws, n_walkers, d) → (..., d)."""
    x = np.asarray(chain, dtype=float)
    n = x.shape[-3]
    x = x - x.mean(axis=-3, keepdims=True)
    n_fft = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(x, n=n_fft, axis=-3)
    acf = np.fft.irfft(f * np.conj(f), n=n_fft, axis=-3)[..., :n, :, :]
    with np.errstate(invalid="ignore", divide="ignore"):
        acf = acf / acf[..., :1, :, :]
    acf = np.nan_to_num(acf, nan=0.0)  # a walker that never moved: no autocorrelation info
    rho = acf.mean(axis=-2)  # (..., n, d)
    taus = 2.0 * np.cumsum(rho, axis=-2) - 1.0
    beyond = np.arange(n)[:, None] >= c * taus
    window = np.where(beyond.any(axis=-2), beyond.argmax(axis=-2), n - 1)
    return np.take_along_axis(taus, window[..., None, :], axis=-2)[..., 0, :]


class _RunLength(NamedTuple):
    burn_draws: int
    tau_steps: np.ndarray  # (M, d)
    kept_steps: int
    enough: np.ndarray  # (M,)


def _run_length(chain, thin, n_tau, burn_tau) -> _RunLength:
    """Burn-in and τ from a chain (M, draws, W, d): τ is first estimated on the last
    three quarters, the burn-in set to ``burn_tau``·τ (the same for all muscles), and τ
    estimated again on what is kept."""
    n = chain.shape[1]
    tau0 = integrated_time(chain[:, n // 4 :]) * thin
    burn = min(int(math.ceil(burn_tau * tau0.max() / thin)), n - 2)
    tau = np.maximum(integrated_time(chain[:, burn:]), 1.0) * thin
    kept = (n - burn) * thin
    return _RunLength(burn, tau, kept, kept >= n_tau * tau.max(axis=-1))


# --------------------------------------------------------------------------------------
# The result.


@dataclasses.dataclass(frozen=True, eq=False)
class McmcResult:
    """Posterior draws of one model's constants and noise σ for every muscle of a batch.

    ``samples`` is (M, W, D, p + 1): muscles, walkers (ArviZ's chains), kept draws, and the
    constants in the order of ``param_names`` followed by σ [N]. The summary arrays are
    (M, p + 1) over the same variables (``var_names``); intervals (M, p + 1, 2). ``value``
    in :meth:`to_dict` is the posterior mean, ``se`` the posterior sd, ``ci95`` the 95%
    equal-tailed interval and ``hdi95`` the 95% highest-density interval. ``converged`` is
    False for a muscle whose kept chain spans fewer than ``n_tau`` autocorrelation times
    or whose worst R-hat exceeds ``R_HAT_MAX``. ``ls`` is the least-squares fit the walkers
    started from.

    It holds results only: :meth:`to_dict` is their plain-data view, :meth:`summary` and
    :meth:`to_inference_data` their ArviZ views; NetCDF files and figures are written by
    :mod:`pamid.report` (``save_netcdf``, ``plot_trace``, ``plot_pair``,
    ``plot_predictive``).
    """

    model: str
    param_names: tuple[str, ...]
    param_units: dict[str, str]
    muscles: tuple[str | None, ...]
    samples: np.ndarray
    log_prob: np.ndarray  # (M, W, D)
    mean: np.ndarray
    sd: np.ndarray
    eti95: np.ndarray
    hdi95: np.ndarray
    r_hat: np.ndarray
    ess_bulk: np.ndarray
    ess_tail: np.ndarray
    mcse_mean: np.ndarray
    tau_steps: np.ndarray
    acceptance: np.ndarray  # (M,)
    n_steps: int
    burn_steps: int
    thin: int
    n_tau: float
    enough_steps: np.ndarray
    converged: np.ndarray
    rmse_N: np.ndarray
    r: np.ndarray
    n: np.ndarray
    likelihood: str
    nu: float
    prior: Prior
    sampler: str
    seconds: float
    ls: FitResult
    data: FitData
    spec: ModelSpec
    key: jax.Array
    de_fraction: float = DE_FRACTION
    samplers: tuple | None = None  # the emcee samplers (sampler="emcee" only)

    @property
    def n_muscles(self) -> int:
        return self.samples.shape[0]

    @property
    def n_walkers(self) -> int:
        return self.samples.shape[1]

    @property
    def var_names(self) -> tuple[str, ...]:
        return (*self.param_names, "sigma")

    @property
    def var_units(self) -> dict[str, str]:
        return {**self.param_units, "sigma": self.spec.output[1]}

    @property
    def theta_mean(self) -> np.ndarray:
        """Posterior means of the constants, (M, p)."""
        return self.mean[:, :-1]

    def params(self, i: int = 0):
        """The posterior means of muscle ``i`` as the model's parameter object."""
        return self.spec.make(self.theta_mean[i])

    def to_dict(self) -> dict:
        """The posterior as plain data (lists, floats, None for NaN): the JSON shape of
        ``pamid fit --method mcmc --json``, that of the least-squares fit, each constant
        with ``hdi95``, ``r_hat``, ``ess_bulk`` and ``ess_tail`` too, and its
        least-squares value and Wald interval under ``"ls"``."""
        from .._io import json_ready

        unit = self.spec.output[1]  # N for force models (keys rmse_N, sigma_N), rad for decays
        muscles = []
        for i, muscle in enumerate(self.muscles):
            entries = {}
            for j, name in enumerate(self.var_names):
                entry = {
                    "value": json_ready(self.mean[i, j]),
                    "ci95": json_ready(self.eti95[i, j]),
                    "se": json_ready(self.sd[i, j]),
                    "unit": self.var_units[name],
                    "hdi95": json_ready(self.hdi95[i, j]),
                    "r_hat": json_ready(self.r_hat[i, j]),
                    "ess_bulk": json_ready(self.ess_bulk[i, j]),
                    "ess_tail": json_ready(self.ess_tail[i, j]),
                    "mcse_mean": json_ready(self.mcse_mean[i, j]),
                    "tau_steps": json_ready(self.tau_steps[i, j]),
                }
                if j < len(self.param_names):
                    ls = {"value": json_ready(self.ls.theta[i, j]),
                          "ci95": json_ready(self.ls.ci95[i, j])}
                    if self.ls.ci95_profile is not None:
                        ls["ci95_profile"] = json_ready(self.ls.ci95_profile[i, j])
                    entry["ls"] = ls
                entries[name] = entry
            sigma = entries.pop("sigma")
            muscles.append({
                "muscle": muscle,
                "n": int(self.n[i]),
                f"rmse_{unit}": json_ready(self.rmse_N[i]),
                "r": json_ready(self.r[i]),
                "converged": bool(self.converged[i]),
                # the run-length control's verdict, in the fit's result codes: not
                # converged means the step budget ran out before R-hat and ESS were met
                "status": "converged" if self.converged[i] else "max_steps",
                # why the least-squares start is not trusted, as `pamid fit` says it
                "message": self.ls.message(i) if self.ls is not None else None,
                "params": entries,
                f"sigma_{unit}": sigma,
                "sampling": {
                    "acceptance": json_ready(self.acceptance[i]),
                    "tau_max_steps": json_ready(self.tau_steps[i].max()),
                    "kept_over_tau": json_ready(self.kept_steps / self.tau_steps[i].max()),
                    "enough_steps": bool(self.enough_steps[i]),
                    "r_hat_max": json_ready(self.r_hat[i].max()),
                    "ess_bulk_min": json_ready(self.ess_bulk[i].min()),
                },
            })
        return {
            "model": self.model,
            "equation": self.spec.source,
            "units": dict(self.spec.units),
            "solver": f"mcmc ({self._sampler_text()})",
            "interval": "posterior: value = mean, se = sd, ci95 = 95% equal-tailed, "
                        "hdi95 = 95% highest density; ls.ci95 = least-squares Wald-t",
            "likelihood": {"kind": self.likelihood,
                           **({"nu": self.nu} if self.likelihood == "student-t" else {})},
            "prior": self.prior.describe(),
            "sampling": {
                "sampler": self.sampler,
                "moves": {"differential_evolution": self.de_fraction,
                          "stretch": 1.0 - self.de_fraction},
                "walkers": self.n_walkers,
                "steps": self.n_steps,
                "burn_in_steps": self.burn_steps,
                "thin": self.thin,
                "draws_per_walker": self.samples.shape[2],
                "required_tau_multiple": self.n_tau,
                "seconds": round(self.seconds, 3),
            },
            "muscles": muscles,
        }

    @property
    def kept_steps(self) -> int:
        return self.n_steps - self.burn_steps

    def _sampler_text(self) -> str:
        kind = ("emcee EnsembleSampler, one per muscle" if self.sampler == "emcee"
                else "pamid stacked ensembles, all muscles in one JAX call")
        return (f"{kind}; {self.n_walkers} walkers; moves: differential evolution "
                f"{self.de_fraction:.0%}, stretch (a = 2) {1 - self.de_fraction:.0%}")

    def summary(self, i: int = 0):
        """ArviZ summary of muscle ``i``: mean, sd, 95% HDI and equal-tailed interval, R-hat,
        bulk and tail ESS, MCSE (a pandas DataFrame, one row per constant and σ)."""
        from ._arviz import summary

        return summary(self.to_inference_data(i, predictive=False))

    def to_inference_data(self, i: int = 0, *, predictive: bool = True):
        """Muscle ``i`` as an ArviZ DataTree: posterior, sample_stats, log_likelihood,
        posterior_predictive, observed_data and constant_data (the model's inputs)."""
        from ._arviz import to_inference_data

        return to_inference_data(self, i, predictive=predictive)


# --------------------------------------------------------------------------------------
# The entry point.


def _inside_support(theta: np.ndarray, prior: Prior) -> np.ndarray:
    """``theta`` (M, p) with the constants that lie on a bound of the prior's open support
    (a least-squares fit within bounds stops there) moved inside by 1e-6 of the support's
    width (of the constant's magnitude, at least 1, for a half-open support)."""
    lo, hi = np.asarray(prior.lower, np.float64), np.asarray(prior.upper, np.float64)
    with np.errstate(invalid="ignore"):
        span = np.where(np.isfinite(hi - lo), hi - lo, np.maximum(np.abs(theta), 1.0))
    step = 1e-6 * span
    theta = np.where(np.isfinite(lo) & (np.abs(theta - lo) <= step), lo + step, theta)
    return np.where(np.isfinite(hi) & (np.abs(hi - theta) <= step), hi - step, theta)


def initial_walkers(key, ls: FitResult, prior: Prior, log_prob_1, data, n_walkers: int,
                    scale: float):
    """Walkers around the least-squares optimum, as :func:`fit_mcmc` starts them, (M, W,
    p + 1): (θ, log s) + scale·(se, 1/√(2·dof))·N(0, 1), redrawn where the log-posterior
    ``log_prob_1`` (:func:`walker_log_prob`) is not finite. ``ls``: the least-squares fit
    of ``data`` (a FitResult with Wald standard errors)."""
    m, p = ls.theta.shape
    theta = _inside_support(np.asarray(ls.theta, np.float64), prior)
    s = np.sqrt(ls.sse / np.maximum(ls.dof, 1))
    centre = np.concatenate([theta, np.log(np.maximum(s, 1e-5))[:, None]], axis=1)
    se = np.where(np.isfinite(ls.se) & (ls.se > 0), ls.se,
                  1e-3 * np.maximum(np.abs(ls.theta), 1e-3))
    width = scale * np.concatenate([se, 1.0 / np.sqrt(2.0 * np.maximum(ls.dof, 1))[:, None]],
                                   axis=1)
    failed = ~np.all(np.isfinite(ls.theta), axis=1)
    if failed.any():
        i = int(np.flatnonzero(failed)[0])
        raise ValueError(
            f"muscle {ls.muscles[i] if ls.muscles[i] is not None else i}: the least-squares "
            "fit that starts the walkers gave non-finite constants; check the data (too few "
            "points or pressures for the model?)")
    inside = np.asarray(prior.inside(theta))
    if not inside.all():
        i = int(np.flatnonzero(~inside)[0])
        values = ", ".join(f"{n} = {v:.6g}" for n, v in zip(prior.names, ls.theta[i]))
        raise ValueError(
            f"muscle {ls.muscles[i] if ls.muscles[i] is not None else i}: the least-squares "
            f"optimum ({values}) lies outside the prior's support; check the data, or pass a "
            f"prior that allows it. Support: {prior.describe()}")
    batched = _stacked_log_prob(log_prob_1)
    pos = np.empty((m, n_walkers, p + 1))
    todo = np.ones((m, n_walkers), bool)
    for attempt in range(100):
        key, k = jax.random.split(key)
        draw = centre[:, None] + width[:, None] * np.asarray(
            jax.random.normal(k, (m, n_walkers, p + 1)))
        pos = np.where(todo[..., None], draw, pos)
        lp = np.asarray(batched(jnp.asarray(pos), data.x, data.y, data.w))
        todo = ~np.isfinite(lp)
        if not todo.any():
            return pos
        width = np.where(todo.any(axis=1)[:, None], 0.5 * width, width)
    i = int(np.flatnonzero(todo.any(axis=1))[0])
    raise ValueError(f"muscle {i}: no finite log-posterior near the least-squares optimum")


def _validate(n_walkers, ndim, thin, max_steps, min_steps, likelihood, sampler, nu):
    if likelihood not in LIKELIHOODS:
        raise ValueError(f"unknown likelihood {likelihood!r}; choose one of {LIKELIHOODS}")
    if sampler not in SAMPLERS:
        raise ValueError(f"unknown sampler {sampler!r}; choose one of {SAMPLERS}")
    if n_walkers % 2 or n_walkers < 2 * ndim:
        raise ValueError(f"n_walkers must be even and at least 2 × {ndim} sampled dimensions "
                         f"= {2 * ndim} for the ensemble moves, got {n_walkers}")
    if thin < 1:
        raise ValueError(f"thin must be at least 1, got {thin}")
    if max_steps < 10 * thin or min_steps > max_steps:
        raise ValueError(f"need 10·thin ≤ max_steps and min_steps ≤ max_steps; got "
                         f"thin = {thin}, min_steps = {min_steps}, max_steps = {max_steps}")
    if likelihood == "student-t" and not nu > 0:
        raise ValueError(f"the Student-t likelihood needs nu > 0, got {nu}")


def fit_mcmc(
    data: BenchData | FitData,
    model: str | ModelSpec = "sarosi",
    *,
    key: jax.Array,
    n_walkers: int = 32,
    max_steps: int = 20_000,
    min_steps: int = 0,
    check_every: int = 1000,
    thin: int = 10,
    likelihood: str = "normal",
    nu: float = DEFAULT_NU,
    prior: Prior | None = None,
    sampler: str = "auto",
    de_fraction: float = DE_FRACTION,
    progress: bool | None = None,
    n_tau: float = 50.0,
    burn_tau: float = 3.0,
    ball_scale: float = 0.1,
    solver: str = "gauss-newton",
    ls_intervals: tuple[str, ...] = ("wald",),
    muscles: tuple[str | None, ...] | None = None,
    bounds=None,
) -> McmcResult:
    """Sample the posterior of a model's constants and noise σ, for every muscle of ``data``.

    Args:
        data: a loaded bench file or a packed :class:`FitData` (one lane per muscle).
        model: "sarosi", "cullinan" or a ModelSpec (with ``prior=`` for a model that has no
            default prior).
        key: JAX PRNG key, the only source of randomness.
        n_walkers: walkers per muscle (even, at least twice the sampled dimension).
        max_steps: step budget per walker; ``min_steps``: run at least this long (set both
            equal for a fixed-length run).
        check_every: steps between autocorrelation checks.
        thin: keep every ``thin``-th step.
        likelihood: "normal" or "student-t" (ν = ``nu``, fixed).
        prior: a :class:`Prior`; default: the documented prior of the model.
        sampler: "stacked" (all muscles in one JAX call), "emcee" (a loop of emcee
            samplers), or "auto" (``AUTO_SAMPLER``, the one measured faster).
        de_fraction: share of differential-evolution steps; the rest are stretch steps.
        progress: a progress bar on stderr; default: when stderr is a terminal.
        n_tau: the kept chain must span this many autocorrelation times (50).
        burn_tau: burn-in in autocorrelation times (3).
        ball_scale: radius of the starting ball in Wald standard errors.
        solver, ls_intervals: passed to :func:`pamid.fit_least_squares` for the start (and
            for the side-by-side intervals: add "profile" to get profile intervals too).
        bounds: optional (lower, upper) of the constants, as :func:`pamid.fit_least_squares`
            takes them: the least-squares start is fitted within them, and the posterior is
            restricted to them (the prior's support intersected with the bounds; the JSON's
            prior says so).
    """
    import time

    t0 = time.perf_counter()
    frame = data.frame if isinstance(data, BenchData) else None
    spec = get_model(model, frame)
    prior = default_prior(spec) if prior is None else prior
    if bounds is not None:
        prior = restricted_prior(prior, bounds)
    ndim = spec.n_params + 1
    _validate(n_walkers, ndim, thin, max_steps, min_steps, likelihood, sampler, nu)
    if not 0.0 <= de_fraction <= 1.0:
        raise ValueError(f"de_fraction must lie in [0, 1], got {de_fraction}")
    if isinstance(data, BenchData):
        names = tuple(m if data.has_muscle_column else None for m in data.muscles)
        data = bench_to_fit_data(data, spec)
    else:
        names = muscles if muscles is not None else tuple([None] * data.n_muscles)
    sampler = AUTO_SAMPLER if sampler == "auto" else sampler
    if progress is None:
        progress = sys.stderr.isatty()

    ls = fit_least_squares(data, spec, solver=solver, intervals=ls_intervals, muscles=names,
                           bounds=bounds)
    log_prob_1 = _log_prob(spec, prior, likelihood, float(nu))
    k_ball, k_run, k_pred = jax.random.split(key, 3)
    start = initial_walkers(k_ball, ls, prior, log_prob_1, data, n_walkers, ball_scale)
    if sampler == "stacked":
        backend = StackedSampler(log_prob_1, k_run, start, data, float(de_fraction))
    else:
        backend = _EmceeBackend(spec, prior, likelihood, float(nu), k_run, start, data,
                                float(de_fraction))

    chunk = thin * max(1, min(check_every, 200) // thin)
    max_steps = int(math.ceil(max_steps / chunk)) * chunk
    check_every = max(chunk, int(math.ceil(check_every / chunk)) * chunk)
    chunks_pos, chunks_lp, accepted, steps = [], [], 0, 0
    bar = _progress_bar(progress, max_steps, spec, data.n_muscles, backend.name)
    try:
        while steps < max_steps:
            pos, lp, acc = backend.advance(chunk, thin)
            chunks_pos.append(pos)
            chunks_lp.append(lp)
            accepted = accepted + acc
            steps += chunk
            bar.update(chunk)
            if steps % check_every == 0 and steps >= min_steps:
                run = _run_length(np.concatenate(chunks_pos, axis=1), thin, n_tau, burn_tau)
                if run.enough.all():
                    break
    finally:
        bar.close()
    chain = np.concatenate(chunks_pos, axis=1)  # (M, draws, W, d)
    lp = np.concatenate(chunks_lp, axis=1)
    run = _run_length(chain, thin, n_tau, burn_tau)
    samples = np.swapaxes(chain[:, run.burn_draws :], 1, 2).copy()  # (M, W, D, d)
    samples[..., -1] = np.exp(samples[..., -1])  # log σ → σ
    log_post = np.swapaxes(lp[:, run.burn_draws :], 1, 2)

    stats = _summaries(samples)
    mean_theta = stats["mean"][:, :-1]
    rmse, r, n = _fit_quality(spec, mean_theta, data)
    converged = run.enough & (stats["r_hat"].max(axis=1) < R_HAT_MAX)
    if not run.enough.all():
        _warn_budget(names, run, steps, n_tau, burn_tau, thin)

    return McmcResult(
        model=spec.name,
        param_names=spec.param_names,
        param_units=dict(spec.param_units),
        muscles=names,
        samples=samples,
        log_prob=log_post,
        **stats,
        tau_steps=run.tau_steps,
        acceptance=np.asarray(accepted) / (steps * n_walkers),
        n_steps=steps,
        burn_steps=run.burn_draws * thin,
        thin=thin,
        n_tau=n_tau,
        enough_steps=run.enough,
        converged=converged,
        rmse_N=rmse,
        r=r,
        n=n,
        likelihood=likelihood,
        nu=float(nu),
        prior=prior,
        sampler=backend.name,
        seconds=time.perf_counter() - t0,
        ls=ls,
        data=data,
        spec=spec,
        key=k_pred,
        de_fraction=float(de_fraction),
        samplers=tuple(backend.samplers) if backend.name == "emcee" else None,
    )


def _progress_bar(progress, total, spec, m, name):
    from tqdm import tqdm  # plain: a terminal bar (stderr), no notebook widgets

    return tqdm(total=total, disable=not progress, file=sys.stderr, unit="step",
                desc=f"pamid mcmc ({spec.name}, {m} muscle{'s' if m > 1 else ''}, {name})",
                leave=False, dynamic_ncols=True)


def _warn_budget(names, run: _RunLength, steps, n_tau, burn_tau, thin):
    short = np.flatnonzero(~run.enough)
    tau_max = run.tau_steps.max(axis=1)
    need = int(math.ceil((n_tau + burn_tau) * tau_max[short].max()))
    label = [names[i] if names[i] is not None else int(i) for i in short[:5]]
    more = f" and {len(short) - 5} more" if len(short) > 5 else ""
    warnings.warn(McmcBudgetWarning(
        f"MCMC budget too short for {len(short)} of {len(names)} muscle(s) ({label}{more}): "
        f"after {steps} steps and a burn-in of {run.burn_draws * thin} the kept chain spans "
        f"{run.kept_steps / tau_max[short].max():.1f} autocorrelation times (τ up to "
        f"{tau_max[short].max():.0f} steps), fewer than the {n_tau:g} τ needed for reliable "
        f"intervals; raise max_steps to at least {need} (these muscles are reported as not "
        "converged)"), stacklevel=3)


def _summaries(samples) -> dict:
    """Mean, sd, 95% ETI and HDI, rank R-hat, bulk and tail ESS, MCSE of the mean, for
    every muscle and variable at once. ``samples``: (M, W, D, k) → arrays (M, k, …)."""
    from . import _arviz as diag

    x = np.moveaxis(samples, -1, 1)  # (M, k, chain, draw)
    return {
        "mean": x.mean(axis=(-2, -1)),
        "sd": x.std(axis=(-2, -1), ddof=1),
        "eti95": diag.eti(x, 0.95),
        "hdi95": diag.hdi(x, 0.95),
        **diag.diagnostics(x),
    }


def _fit_quality(spec, theta, data: FitData):
    """RMSE and correlation of data and model at the posterior mean, per muscle."""
    pred = np.asarray(jax.vmap(spec.predict)(jnp.asarray(theta), data.x))
    y, w = np.asarray(data.y), np.asarray(data.w)
    n = w.sum(axis=1)
    rmse = np.sqrt((w * (y - pred) ** 2).sum(axis=1) / n)
    ym, pm = (w * y).sum(axis=1) / n, (w * pred).sum(axis=1) / n
    cov = (w * (y - ym[:, None]) * (pred - pm[:, None])).sum(axis=1)
    r = cov / np.sqrt((w * (y - ym[:, None]) ** 2).sum(axis=1)
                      * (w * (pred - pm[:, None]) ** 2).sum(axis=1))
    return rmse, r, n.astype(int)
