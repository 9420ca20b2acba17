"""The log-posterior of a model's constants and the noise level, written in JAX.

The sampled vector is ``z = (theta, log σ)``: the model's constants in the order of
``ModelSpec.param_names`` and the logarithm of the noise scale σ in N. It is model-agnostic:
the force comes from ``spec.predict(theta, x)``, the constants' priors from a :class:`Prior`
built for the spec's names, so a new model (the dynamic one, say) is sampled by writing its
spec and its prior.

Likelihood, one muscle, samples weighted by ``w`` (0 on padding, a count otherwise):

* ``"normal"``: ``F_i ~ Normal(predict(theta, x_i), σ)``;
* ``"student-t"``: ``F_i ~ StudentT(ν, predict(theta, x_i), σ)`` with ν fixed (default 4):
  a few outliers then cost a logarithm instead of a square, so they cannot drag the fit.

Priors (documented per constant in :data:`PRIOR_NOTES`): weakly informative, each constant
a wide Normal in its own unit, with hard support where physics fixes a sign. The noise scale
has a half-Cauchy prior (scale 10 N), and σ is kept within [1e-6, 1e6] N so that the
density stays finite. All priors are stated up to a constant (normalising constants of
truncated densities are left out; they do not change the posterior).

The log-posterior returns −inf outside the support and for any input that makes it
non-finite (NaN or ±inf constants, overflow), never NaN: the samplers rely on that.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammaln

from .._fit._spec import ModelSpec
from ._options import DEFAULT_NU, LIKELIHOODS

LOG_SIGMA_BOUNDS = (math.log(1e-6), math.log(1e6))  # σ in N
NOISE_SCALE_N = 10.0


@dataclasses.dataclass(frozen=True)
class Prior:
    """Independent priors on the constants, plus an optional joint physical condition.

    Each constant has a Normal(loc, scale) density (``scale = inf``: flat) restricted to
    the open interval (lower, upper). Tuples, not arrays, so that a Prior is hashable and
    can be a static argument of jitted code.

    Attributes:
        names: the constants, in the order of ``theta``.
        loc, scale: centre and standard deviation of each Normal, in the constant's unit.
        lower, upper: the support of each constant (±inf for none).
        noise_scale_N: scale of the half-Cauchy prior on the noise σ, in ``noise_unit``
            (N for the force models; the name is kept for them).
        noise_unit, noise_quantity: what σ measures, for outputs ("N", "force").
        condition: optional ``condition(theta) -> bool``: a joint physical requirement
            (for Sárosi: the force at zero contraction grows with pressure); the density
            is 0 where it is False.
        notes: the physical reason for each prior, for outputs.
    """

    names: tuple[str, ...]
    loc: tuple[float, ...]
    scale: tuple[float, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    noise_scale_N: float = NOISE_SCALE_N
    noise_unit: str = "N"
    noise_quantity: str = "force"
    condition: Callable | None = None
    condition_note: str = ""
    notes: tuple[str, ...] = ()

    def __post_init__(self):
        n = len(self.names)
        for field in ("loc", "scale", "lower", "upper"):
            if len(getattr(self, field)) != n:
                raise ValueError(f"Prior.{field} has {len(getattr(self, field))} entries "
                                 f"for {n} constants {self.names}")
        if any(not lo < hi for lo, hi in zip(self.lower, self.upper)):
            raise ValueError("Prior: every lower bound must be below its upper bound")
        if any(not s > 0 for s in self.scale):
            raise ValueError("Prior: every scale must be positive (inf for a flat prior)")

    def inside(self, theta) -> jax.Array:
        """True where ``theta`` (last axis: constants) lies in the prior's support."""
        theta = jnp.asarray(theta)
        ok = jnp.all((theta > jnp.asarray(self.lower)) & (theta < jnp.asarray(self.upper)),
                     axis=-1)
        if self.condition is not None:
            ok = ok & self.condition(theta)
        return ok

    def describe(self) -> dict:
        """The prior as JSON: one line per constant, and the noise prior."""
        out = {}
        for j, name in enumerate(self.names):
            lo, hi = self.lower[j], self.upper[j]
            dist = (f"Normal({self.loc[j]:g}, {self.scale[j]:g})" if math.isfinite(self.scale[j])
                    else "flat")
            if math.isfinite(lo) or math.isfinite(hi):
                dist += f" on ({lo:g}, {hi:g})"
            out[name] = dist + (f": {self.notes[j]}" if self.notes else "")
        u = self.noise_unit
        out["sigma"] = (f"HalfCauchy({self.noise_scale_N:g} {u}), σ in [1e-06, 1e+06] {u}: "
                        f"noise of one {self.noise_quantity} sample")
        if self.condition is not None:
            out["condition"] = self.condition_note
        return out


def _sarosi_condition(theta):
    # ∂F/∂p at κ = 0 is a1 + a5 (eq. 2.1): a muscle pulls harder at higher pressure.
    return theta[..., 0] + theta[..., 4] > 0.0


_INF = math.inf

# Sárosi eq. 2.1, p in bar, κ in %, F in N. Festo's fluidic muscles (DMSP 5–40 mm) pull at
# most about 6000 N at 6 bar, so force constants of ±1000 N or N/bar (sd) are wide for all.
SAROSI_PRIOR = Prior(
    names=("a1", "a2", "a3", "a4", "a5", "a6"),
    loc=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    scale=(1000.0, 1000.0, 1.0, 100.0, 1000.0, 1000.0),
    lower=(-_INF, -_INF, -5.0, -_INF, -_INF, -_INF),
    upper=(_INF, _INF, 0.0, _INF, _INF, _INF),
    condition=_sarosi_condition,
    condition_note="a1 + a5 > 0: at zero contraction the force grows with pressure",
    notes=(
        "pressure-dependent amplitude of the exponential term, either sign",
        "amplitude of the exponential term at zero pressure, either sign",
        "negative: the exponential term decays with contraction (a3 = 0 would make it a "
        "constant, confounded with a5 and a6; below -5 it would vanish within 0.2 %)",
        "force change per % contraction and bar, either sign (Table 3-1: -9.3)",
        "force per bar, either sign on its own (see the condition)",
        "offset force, either sign",
    ),
)

# Cullinan eq. 3 in N, kPa, mm, s.
CULLINAN_PRIOR = Prior(
    names=("A", "B", "C", "D", "E", "G"),
    loc=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    scale=(1000.0, 10.0, 100.0, 1.0, 10.0, 10.0),
    lower=(-_INF, 0.0, -_INF, -_INF, -_INF, 0.0),
    upper=(_INF, _INF, _INF, _INF, _INF, _INF),
    notes=(
        "force at zero pressure and contraction, either sign",
        "positive: at zero contraction the muscle pulls harder at higher pressure "
        "(10 N/kPa sd would be 6000 N at 600 kPa)",
        "spring rate at zero pressure, either sign in a fit",
        "pressure dependence of the spring rate, either sign",
        "quadratic spring term, either sign",
        "non-negative: the damper dissipates energy",
    ),
)

def _documented_priors() -> dict:
    """The documented priors, registered by model class (a spec of the same class keeps its
    prior whatever its name; any other model gets :func:`model_prior`)."""
    from .._models._cullinan import Cullinan
    from .._models._sarosi import Sarosi

    return {Sarosi: SAROSI_PRIOR, Cullinan: CULLINAN_PRIOR}


def default_prior(spec: ModelSpec) -> Prior:
    """The documented prior for a model, restricted to the constants its spec fits."""
    full = _documented_priors().get(spec.model_class)
    if full is None and spec.model_class is not None:
        return model_prior(spec)
    if full is None:
        raise ValueError(
            f"no default prior for model {spec.name!r}: pass prior=Prior(...) with the "
            f"constants {spec.param_names}"
        ) from None
    missing = [n for n in spec.param_names if n not in full.names]
    if missing:
        raise ValueError(f"the default prior of {spec.name!r} has no entry for {missing}")
    if full.names == spec.param_names:
        return full
    idx = [full.names.index(n) for n in spec.param_names]
    pick = lambda t: tuple(t[i] for i in idx)  # noqa: E731
    # A joint condition is written for the full vector; keep it only if nothing was dropped.
    return dataclasses.replace(
        full, names=spec.param_names, loc=pick(full.loc), scale=pick(full.scale),
        lower=pick(full.lower), upper=pick(full.upper),
        notes=pick(full.notes) if full.notes else (),
        condition=None, condition_note="",
    )


def model_prior(spec: ModelSpec) -> Prior:
    """The prior of a :class:`~pamid.ForceModel` without a documented one: flat on the
    interval its ``prior`` declares for a constant, else flat within its physical ``bounds``,
    else flat on the real line (improper: the data must determine that constant; the
    posterior is proper when the least-squares fit identifies every constant)."""
    declared = dict(spec.prior or {})
    lower, upper = spec.bounds if spec.bounds is not None else (
        (-_INF,) * spec.n_params, (_INF,) * spec.n_params)
    lo, hi, notes = [], [], []
    for j, name in enumerate(spec.param_names):
        if name in declared:
            a, b = (float(v) for v in declared[name])
            notes.append("declared by the model")
        elif math.isfinite(lower[j]) or math.isfinite(upper[j]):
            a, b = lower[j], upper[j]
            notes.append("the model's physical bounds")
        else:
            a, b = -_INF, _INF
            notes.append("improper: the data alone determine it")
        lo.append(a)
        hi.append(b)
    n = spec.n_params
    return Prior(names=spec.param_names, loc=(0.0,) * n, scale=(_INF,) * n,
                 lower=tuple(lo), upper=tuple(hi), notes=tuple(notes))


def restricted_prior(prior: Prior, bounds) -> Prior:
    """``prior`` with each constant's support intersected with ``bounds`` = (lower, upper)
    (the ``--bounds`` of a fit); the note of a constant whose support narrowed says so. A
    ValueError names a constant whose support and bounds do not overlap."""
    lower, upper = (tuple(float(v) for v in side) for side in bounds)
    lo, hi, notes = [], [], []
    for j, name in enumerate(prior.names):
        a, b = max(prior.lower[j], lower[j]), min(prior.upper[j], upper[j])
        if not a < b:
            raise ValueError(f"--bounds: {name}: ({lower[j]:g}, {upper[j]:g}) lies outside the "
                             f"support of its prior ({prior.lower[j]:g}, {prior.upper[j]:g})")
        note = prior.notes[j] if prior.notes else ""
        if (a, b) != (prior.lower[j], prior.upper[j]):
            note = (note + "; " if note else "") + f"restricted to ({a:g}, {b:g}) by the bounds"
        lo.append(a)
        hi.append(b)
        notes.append(note)
    return dataclasses.replace(prior, lower=tuple(lo), upper=tuple(hi), notes=tuple(notes))


def log_prior(prior: Prior, theta, log_sigma):
    """Log prior density (up to a constant) of the constants and of log σ; −inf outside."""
    theta = jnp.asarray(theta)
    loc, scale = jnp.asarray(prior.loc), jnp.asarray(prior.scale)
    finite_scale = jnp.isfinite(scale)
    terms = jnp.where(finite_scale, -0.5 * jnp.square((theta - loc) / scale), 0.0)
    sigma = jnp.exp(log_sigma)
    s0 = prior.noise_scale_N
    # Half-Cauchy on σ, carried to log σ by the Jacobian dσ/dlog σ = σ.
    lp_sigma = -jnp.log1p(jnp.square(sigma / s0)) + log_sigma
    inside = prior.inside(theta) & (log_sigma > LOG_SIGMA_BOUNDS[0]) & (
        log_sigma < LOG_SIGMA_BOUNDS[1])
    return jnp.where(inside, jnp.sum(terms, axis=-1) + lp_sigma, -jnp.inf)


def pointwise_log_likelihood(spec: ModelSpec, theta, log_sigma, x, y, *,
                             likelihood: str = "normal", nu: float = DEFAULT_NU):
    """Log density of every force sample given the constants and log σ (one muscle)."""
    r = (y - spec.predict(theta, x)) / jnp.exp(log_sigma)
    if likelihood == "normal":
        return -0.5 * math.log(2.0 * math.pi) - log_sigma - 0.5 * jnp.square(r)
    if likelihood == "student-t":
        const = gammaln(0.5 * (nu + 1.0)) - gammaln(0.5 * nu) - 0.5 * math.log(nu * math.pi)
        return const - log_sigma - 0.5 * (nu + 1.0) * jnp.log1p(jnp.square(r) / nu)
    raise ValueError(f"unknown likelihood {likelihood!r}; choose one of {LIKELIHOODS}")


def log_posterior(spec: ModelSpec, prior: Prior, z, x, y, w, *, likelihood: str = "normal",
                  nu: float = DEFAULT_NU):
    """Log posterior (up to a constant) of ``z = (theta, log σ)`` for one muscle.

    ``x``, ``y``, ``w``: the muscle's inputs, forces and weights (0 on padding). Returns
    a scalar; −inf outside the prior's support and wherever the value is not finite.
    """
    z = jnp.asarray(z)
    theta, log_sigma = z[:-1], z[-1]
    lp = log_prior(prior, theta, log_sigma)
    ll = pointwise_log_likelihood(spec, theta, log_sigma, x, y, likelihood=likelihood, nu=nu)
    # where, not w·ll: a weight of 0 on padding must give 0 even where ll is −inf.
    total = lp + jnp.sum(jnp.where(w > 0, w * ll, 0.0))
    return jnp.where(jnp.isfinite(total), total, -jnp.inf)


def make_log_prob(spec: ModelSpec, prior: Prior, likelihood: str = "normal",
                  nu: float = DEFAULT_NU) -> Callable:
    """``log_prob(z, x, y, w)`` for one walker of one muscle, the function both samplers use.

    Vectorize it with ``jax.vmap`` (over walkers: ``in_axes=(0, None, None, None)``; over
    muscles as well: wrap once more with ``in_axes=0``).
    """
    if likelihood not in LIKELIHOODS:
        raise ValueError(f"unknown likelihood {likelihood!r}; choose one of {LIKELIHOODS}")
    if likelihood == "student-t" and not nu > 0:
        raise ValueError(f"the Student-t likelihood needs nu > 0, got {nu}")
    if prior.names != spec.param_names:
        raise ValueError(f"the prior is for {prior.names}, the model fits {spec.param_names}")

    def log_prob(z, x, y, w):
        return log_posterior(spec, prior, z, x, y, w, likelihood=likelihood, nu=nu)

    return log_prob


def numpy_log_prob(spec_name: str, prior: Prior, likelihood: str = "normal",
                   nu: float = DEFAULT_NU) -> Callable:
    """The same log-posterior in NumPy, vectorized over walkers, for Sárosi only:
    ``log_prob(z (W, d), x, y, w) -> (W,)``, e.g. for an ``emcee.EnsembleSampler`` with
    ``vectorize=True``.

    For comparison: the benchmarks (``benchmarks/mcmc_batch.py``, ``run.py``) measure with it
    the remark that a NumPy log-probability is faster per call than a jitted JAX one for a
    model this small; the tests check that both agree.
    """
    if spec_name != "sarosi":
        raise ValueError("the NumPy log-probability is written for the Sárosi model only")
    loc, scale = np.asarray(prior.loc), np.asarray(prior.scale)
    lower, upper = np.asarray(prior.lower), np.asarray(prior.upper)
    const = (math.lgamma(0.5 * (nu + 1.0)) - math.lgamma(0.5 * nu)
             - 0.5 * math.log(nu * math.pi))

    def log_prob(z, x, y, w):
        z = np.atleast_2d(z)
        th, ls = z[:, :-1], z[:, -1]
        p, k = x
        a = [th[:, i : i + 1] for i in range(6)]
        with np.errstate(all="ignore"):
            f = (a[0] * p + a[1]) * np.exp(a[2] * k) + a[3] * k * p + a[4] * p + a[5]
            r = (y - f) / np.exp(ls)[:, None]
            if likelihood == "normal":
                ll = -0.5 * math.log(2 * math.pi) - ls[:, None] - 0.5 * r * r
            else:
                ll = const - ls[:, None] - 0.5 * (nu + 1.0) * np.log1p(r * r / nu)
            ll = np.where(w > 0, w * ll, 0.0).sum(axis=1)
            sig = np.exp(ls)
            lp = (-0.5 * np.square((th - loc) / scale)).sum(axis=1)
            lp += -np.log1p(np.square(sig / prior.noise_scale_N)) + ls
            inside = np.all((th > lower) & (th < upper), axis=1)
            inside &= (ls > LOG_SIGMA_BOUNDS[0]) & (ls < LOG_SIGMA_BOUNDS[1])
            if prior.condition is not None:
                inside &= np.asarray(prior.condition(th))
            total = lp + ll
        return np.where(inside & np.isfinite(total), total, -np.inf)

    return log_prob
