"""Partial pooling: a hierarchical Bayesian fit of the Bolen et al. 2026 law, and the
posterior predictive of a new muscle.

Each muscle i pulls s_i times the population law (:class:`pamid._models._bolen.Bolen2026`,
constants θ shared), and each row carries white noise:

    F_ij = s_i · F_pop(P_ij, ε_ij; l0_i, ε_max,i; θ) + e_ij,   e_ij ~ N(0, σ²)
    ln s_i ~ N(0, τ²)

with θ flat within the law's physical bounds, τ half-normal (scale :data:`TAU_SCALE`: a
muscle rarely differs from its population by more than a few tens of per cent) and σ flat in
ln σ. The scale of the force is where cut muscles of one tube differ most (F620 beyond the
arctangent in l0: tube batch, clamping); the shape of the law is shared. A new muscle draws
its own s = exp(τ·z), z ~ N(0, 1), from the posterior of τ: its predictive interval holds
the population spread, the uncertainty of θ, τ and σ, and the noise.

The sampler sees ln s_i itself for a muscle with rows (centred: hundreds of rows pin s_i,
and ln s_i = τ·z_i would make τ and z_i a curved ridge that an affine-invariant ensemble
crosses slowly: with it, 1,500 burn-in steps left τ's 97.5 % quantile at 0.086 where 6,000
reached 0.11 on a virtual population; centred, 0.138 and 0.139) and z_i for one without (a
muscle left out: its factor has only its prior, and the non-centred form has no funnel).

Sampler: pamid's affine-invariant ensemble (:func:`pamid._sampling._ensemble.run_ensembles`,
stretch and differential-evolution moves: no gradients, no tuning), started in a small ball
about the least-squares fit. The ensembles are stacked: one per data set, so that many
virtual populations are sampled in one call (``tests/test_pooled_bayes.py``). The noise
model is white: on the AARL file, whose residuals are correlated within curves, θ's posterior
is too narrow; the predictive of a new muscle is dominated by τ and σ.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .._models._bolen import P_TOP_KPA, f620_N, normalized_force
from .._sampling._ensemble import ensemble_init, run_ensembles

#: Scale of τ's half-normal prior.
TAU_SCALE = 0.25
#: The law's constants in the sampler's order and their bounds (Bolen2026.bounds).
THETA_NAMES = ("a_N", "b_per_m", "a0", "a1", "a3")


def _law(theta, p, ratio, l0, emax, c_mm):
    return f620_N(l0, theta[0], theta[1], c_mm) * normalized_force(
        ratio / emax, p / P_TOP_KPA, theta[2], theta[3], theta[4])


def log_posterior(params, x, y, muscle, w, lower, upper, c_mm: float = 7.5):
    """ln p(θ, ln τ, ln σ, v | data) up to a constant, for one parameter vector
    (5 + 2 + M,) and one data set: x = (P [kPa], ε [ratio], l0 [mm], ε_max [ratio]) per row,
    ``muscle`` the rows' index, ``w`` 1 on the rows that count and 0 on the others (a
    muscle left out keeps only its prior); −inf outside θ's bounds. v_i is ln s_i for a
    muscle with rows, z_i = ln s_i/τ for one without (module text)."""
    k = len(THETA_NAMES)
    theta, log_tau, log_sigma, v = params[:k], params[k], params[k + 1], params[k + 2:]
    tau, sigma = jnp.exp(log_tau), jnp.exp(log_sigma)
    has = jnp.zeros(v.shape).at[muscle].add(w) > 0
    log_s = jnp.where(has, v, tau * v)
    f = _law(theta, *x, c_mm)
    r = y - jnp.exp(log_s)[muscle] * f
    n = jnp.sum(w)
    prior_s = jnp.where(has, -0.5 * (v / tau) ** 2 - log_tau, -0.5 * v**2)
    lp = (-0.5 * jnp.sum(w * r**2) / sigma**2 - n * log_sigma
          + jnp.sum(prior_s)
          - 0.5 * (tau / TAU_SCALE) ** 2 + log_tau)  # half-normal on τ, sampled in ln τ
    inside = jnp.all((theta >= lower) & (theta <= upper))
    return jnp.where(inside & jnp.isfinite(lp), lp, -jnp.inf)


@functools.partial(jax.jit, static_argnames=("n_draws", "thin", "n_burn"))
def _sample(key, start, x, y, muscle, w, lower, upper, n_draws, thin, n_burn):
    """Stacked ensembles: ``start`` (E, W, d), data (E, N) each."""

    def lp_fn(pos):  # (E, h, d) -> (E, h)
        one = jax.vmap(log_posterior, in_axes=(0, None, None, None, None, None, None))
        return jax.vmap(one, in_axes=(0, 0, 0, 0, 0, None, None))(pos, x, y, muscle, w,
                                                                  lower, upper)

    state = ensemble_init(start, lp_fn)
    k_burn, k_draw = jax.random.split(key)
    state, _, _, _ = run_ensembles(k_burn, state, lp_fn, n_burn, 1)
    _, pos, lp, acc = run_ensembles(k_draw, state, lp_fn, n_draws, thin)
    return pos, lp, acc


@dataclasses.dataclass(frozen=True)
class HierarchicalFit:
    """Posterior draws of the hierarchical Bolen law, one data set (or stacked: a leading
    axis on every array).

    Attributes:
        theta: (n, 5) draws of the law's constants (:data:`THETA_NAMES`).
        tau, sigma_N: (n,) draws of the spread between muscles and of the noise.
        scale: (n, M) draws of each fitted muscle's factor s_i.
        acceptance: the ensemble's acceptance fraction.
    """

    theta: np.ndarray
    tau: np.ndarray
    sigma_N: np.ndarray
    scale: np.ndarray
    acceptance: float

    def to_dict(self, max_draws: int = 400) -> dict:
        step = max(1, -(-self.tau.shape[-1] // max_draws))
        return {"theta_names": list(THETA_NAMES),
                "theta": np.asarray(self.theta[::step]).tolist(),
                "tau": np.asarray(self.tau[::step]).tolist(),
                "sigma_N": np.asarray(self.sigma_N[::step]).tolist(),
                "acceptance": self.acceptance, "tau_prior": f"half-normal({TAU_SCALE})"}


def fit_hierarchical(key, x, y, muscle, n_muscles: int, theta0, *, lower, upper, w=None,
                     n_walkers: int = 48, n_burn: int = 1500, n_draws: int = 400,
                     thin: int = 5) -> HierarchicalFit:
    """Sample the hierarchical model (module text) for one or several data sets.

    Args:
        key: PRNG key. x: the law's inputs (4 arrays of (N,) or (E, N)); y, muscle: the
            forces and the rows' muscle index, (N,) or (E, N); theta0: the least-squares
            constants, (5,) or (E, 5), the centre of the start; lower, upper: θ's bounds;
            w: 1 on the rows that count, 0 on the others (default: all count).
    """
    stacked = np.ndim(y) == 2
    x = tuple(np.atleast_2d(np.asarray(v, np.float64)) for v in x)
    y = np.atleast_2d(np.asarray(y, np.float64))
    muscle = np.atleast_2d(np.asarray(muscle))
    w = np.ones_like(y) if w is None else np.atleast_2d(np.asarray(w, np.float64))
    theta0 = np.atleast_2d(np.asarray(theta0, np.float64))
    e = y.shape[0]
    k_start, k_run = jax.random.split(key)
    # Start: θ near least squares; each muscle's factor and the noise from its residual.
    starts = []
    for j in range(e):
        f = np.asarray(_law(jnp.asarray(theta0[j]), *(v[j] for v in x), 7.5))
        num = np.bincount(muscle[j], w[j] * y[j] * f, minlength=n_muscles)
        den = np.bincount(muscle[j], w[j] * f**2, minlength=n_muscles)
        s = np.where(den > 0, num / np.where(den > 0, den, 1.0), 1.0)
        tau0 = max(float(np.std(np.log(s[den > 0]))), 0.02)
        sigma0 = float(np.sqrt(np.sum(w[j] * (y[j] - s[muscle[j]] * f) ** 2) / np.sum(w[j])))
        starts.append(np.concatenate([theta0[j], [math.log(tau0), math.log(sigma0)],
                                      np.where(den > 0, np.log(s), 0.0)]))
    start = np.asarray(starts)[:, None, :]
    d = start.shape[-1]
    jitter = 1e-3 * np.asarray(jax.random.normal(k_start, (e, n_walkers, d)))
    start = start * (1.0 + jitter) + jitter  # relative for the constants, absolute near 0
    pos, _, acc = _sample(k_run, jnp.asarray(start), tuple(jnp.asarray(v) for v in x),
                          jnp.asarray(y), jnp.asarray(muscle), jnp.asarray(w),
                          jnp.asarray(lower),
                          jnp.asarray(upper), n_draws, thin, n_burn)
    pos = np.asarray(pos).transpose(1, 0, 2, 3).reshape(e, n_draws * n_walkers, d)
    k = len(THETA_NAMES)
    tau = np.exp(pos[..., k])
    has = np.stack([np.bincount(muscle[j], w[j], minlength=n_muscles) > 0 for j in range(e)])
    v = pos[..., k + 2:]
    out = HierarchicalFit(
        theta=pos[..., :k], tau=tau, sigma_N=np.exp(pos[..., k + 1]),
        scale=np.exp(np.where(has[:, None, :], v, tau[..., None] * v)),
        acceptance=float(np.mean(np.asarray(acc)) / (n_draws * thin * n_walkers)))
    if stacked:
        return out
    return dataclasses.replace(out, theta=out.theta[0], tau=out.tau[0],
                               sigma_N=out.sigma_N[0], scale=out.scale[0])


def predictive_interval(key, draws: dict, p, ratio, l0, emax, level: float = 0.95,
                        c_mm: float = 7.5):
    """(median, low, high) of a new muscle's force at the points (p [kPa], ε [ratio],
    l0 [mm], ε_max [ratio]) from posterior draws (:meth:`HierarchicalFit.to_dict`): each
    draw's law times a new factor exp(τ·z), plus noise."""
    theta = jnp.asarray(draws["theta"])
    tau, sigma = jnp.asarray(draws["tau"]), jnp.asarray(draws["sigma_N"])
    k_z, k_e = jax.random.split(key)
    z = jax.random.normal(k_z, tau.shape)
    f = jax.vmap(lambda t: _law(t, p, ratio, l0, emax, c_mm))(theta)  # (n, points)
    noise = jax.random.normal(k_e, f.shape)
    y = jnp.exp(tau * z)[:, None] * f + sigma[:, None] * noise
    q = jnp.quantile(y, jnp.asarray([0.5, (1 - level) / 2, (1 + level) / 2]), axis=0)
    return tuple(np.asarray(v) for v in q)
