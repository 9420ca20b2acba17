"""ArviZ 1.x view of a posterior: DataTree, summary, diagnostics, and reading NetCDF back.

The DataTree of one muscle is built with :func:`arviz.from_dict`, not ``from_emcee``, for
both samplers: the stacked sampler is not an emcee sampler, and the groups beyond the
posterior (pointwise log-likelihood, posterior predictive, the model's inputs) are
computed from the kept draws after burn-in anyway. Walkers are ArviZ's chains, as in
``from_emcee``; the tests check that the posterior equals ``from_emcee``'s after burn-in.

NetCDF: a DataTree with groups needs a NetCDF-4 engine (h5netcdf or netCDF4). Where
neither is installed, ``pamid.report.save_netcdf`` (:mod:`pamid._report._mcmc`) writes one
NetCDF-3 file per group into a folder (SciPy's writer; list-valued attributes stored as JSON
text, :func:`encode_attrs`) and warns; :func:`load_inference_data` reads either form. The
figures of a posterior are :mod:`pamid._report._mcmc`'s.
"""

from __future__ import annotations

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from scipy import fft as _fft
from scipy import special as _special

from . import _posterior

GROUPS = ("posterior", "sample_stats", "log_likelihood", "posterior_predictive",
          "observed_data", "constant_data")
_JSON_PREFIX = "json:"


def input_names(spec) -> list[str]:
    """Names of the model's inputs in its own units: ("pressure_bar", "contraction_pct")."""
    names = []
    for col in spec.columns:
        quantity = col.split("_")[0]
        unit = spec.units.get(quantity)
        unit = {"%": "pct"}.get(unit, unit)
        names.append(f"{quantity}_{unit}" if unit else col)
    return names


def observed(result, i):
    """Muscle ``i``'s rows with a positive weight: inputs, force, weight and curve."""
    w = np.asarray(result.data.w[i])
    keep = w > 0
    x = tuple(np.asarray(xj[i])[keep] for xj in result.data.x)
    return x, np.asarray(result.data.y[i])[keep], w[keep], np.asarray(result.data.curve[i])[keep]


def to_inference_data(result, i: int = 0, *, predictive: bool = True):
    """One muscle's posterior as an ArviZ DataTree (see the module docstring)."""
    import arviz as az

    spec = result.spec
    p = len(result.param_names)
    draws = result.samples[i]  # (W, D, p + 1)
    theta, sigma = draws[..., :p], draws[..., p]
    x, y, w, curve = observed(result, i)
    n_obs = len(y)

    posterior = {name: theta[..., j] for j, name in enumerate(result.param_names)}
    posterior["sigma"] = sigma
    data = {
        "posterior": posterior,
        "sample_stats": {"lp": result.log_prob[i]},
        "observed_data": {"force_N": y},
        "constant_data": {**dict(zip(input_names(spec), x)), "weight": w, "curve": curve},
    }
    if predictive:
        ll, ppc = _predictive(result, i, theta, sigma, x, y)
        data["log_likelihood"] = {"force_N": ll * w}  # a weight is a count of repeated rows
        data["posterior_predictive"] = {"force_N": ppc}
    obs_vars = ["force_N", "weight", "curve", *input_names(spec)]
    muscle = result.muscles[i]
    attrs = {
        "model": result.model,
        "equation": spec.source,
        "muscle": "" if muscle is None else str(muscle),
        "likelihood": result.likelihood,
        "nu": result.nu if result.likelihood == "student-t" else 0.0,
        "sampler": result.sampler,
        "n_walkers": result.n_walkers,
        "n_steps": result.n_steps,
        "burn_in_steps": result.burn_steps,
        "thin": result.thin,
        "units": json.dumps(result.var_units),
        "prior": json.dumps(result.prior.describe()),
    }
    dt = az.from_dict(data, dims={v: ["obs"] for v in obs_vars},
                      coords={"obs": np.arange(n_obs)})
    # On the root and on the posterior: the NetCDF-3 fallback keeps groups only.
    dt.attrs.update(attrs)
    dt["posterior"].attrs.update(attrs)
    for name, unit in result.var_units.items():
        dt["posterior"][name].attrs["units"] = unit
    return dt


def _predictive(result, i, theta, sigma, x, y):
    """Pointwise log-likelihood and one posterior-predictive replicate per draw."""
    spec = result.spec
    t = jnp.asarray(theta.reshape(-1, theta.shape[-1]))
    log_s = jnp.log(jnp.asarray(sigma.reshape(-1)))
    xj = tuple(jnp.asarray(a) for a in x)

    def one(th, ls):
        return _posterior.pointwise_log_likelihood(spec, th, ls, xj, jnp.asarray(y),
                                                   likelihood=result.likelihood, nu=result.nu)

    ll = jax.vmap(one)(t, log_s)
    mu = jax.vmap(lambda th: spec.predict(th, xj))(t)
    key = jax.random.fold_in(result.key, i)
    if result.likelihood == "student-t":
        eps = jax.random.t(key, result.nu, mu.shape, dtype=mu.dtype)
    else:
        eps = jax.random.normal(key, mu.shape, dtype=mu.dtype)
    ppc = mu + jnp.exp(log_s)[:, None] * eps
    shape = theta.shape[:2] + (len(y),)
    return np.asarray(ll).reshape(shape), np.asarray(ppc).reshape(shape)


def summary(dt):
    """mean, sd, 95% HDI and equal-tailed interval, bulk and tail ESS, R-hat, MCSE."""
    import arviz as az

    # ci_prob also sets the quantiles of ArviZ's tail ESS: (0.05, 0.95) at 0.95.
    with az.rc_context({"stats.ci_prob": 0.95}):
        by_hdi = az.summary(dt, ci_prob=0.95, ci_kind="hdi", round_to="none")
        by_eti = az.summary(dt, kind="stats", ci_prob=0.95, ci_kind="eti", round_to="none")
    out = by_hdi.copy()
    at = list(out.columns).index("hdi95_ub") + 1
    for c in ("eti95_lb", "eti95_ub"):
        out.insert(at, c, by_eti[c])
        at += 1
    return out


# --------------------------------------------------------------------------------------
# Diagnostics, vectorized over muscles and variables.
#
# ArviZ computes R-hat and ESS one (muscle, variable) cell at a time in Python, seconds for
# hundreds of muscles (benchmarks/README.md, "Figures that used to live in docstrings",
# (j)). The functions below compute the same
# quantities (Vehtari et al. 2021, as arviz-stats 1.x implements them: rank-normalized split
# R-hat, bulk and tail ESS with Geyer's initial monotone sequence) on whole arrays;
# tests/test_mcmc.py checks them against ArviZ cell by cell. Input: (..., chain, draw).


def _split(x):
    half = x.shape[-1] // 2
    return np.concatenate([x[..., :half], x[..., -half:]], axis=-2)


def _average_ranks(flat):
    """Ranks 1 … n along the last axis, ties given their average rank (as
    ``scipy.stats.rankdata(method="average")``, which sorts stably and is slower)."""
    n = flat.shape[-1]
    idx = np.argsort(flat, axis=-1)
    srt = np.take_along_axis(flat, idx, axis=-1)
    pos = np.broadcast_to(np.arange(n), flat.shape)
    first = np.ones(flat.shape, bool)
    first[..., 1:] = srt[..., 1:] != srt[..., :-1]
    last = np.ones(flat.shape, bool)
    last[..., :-1] = first[..., 1:]
    start = np.maximum.accumulate(np.where(first, pos, 0), axis=-1)
    end = np.flip(np.minimum.accumulate(np.flip(np.where(last, pos, n - 1), -1), axis=-1), -1)
    ranks = np.empty(flat.shape)
    np.put_along_axis(ranks, idx, 0.5 * (start + end) + 1.0, axis=-1)
    return ranks


def _z_scale(x):
    flat = x.reshape(*x.shape[:-2], -1)
    rank = _average_ranks(flat)
    size = flat.shape[-1]
    return _special.ndtri((rank - 0.375) / (size + 0.25)).reshape(x.shape)


def _rhat_basic(x):
    n = x.shape[-1]
    between = n * np.var(x.mean(axis=-1), axis=-1, ddof=1)
    within = np.mean(np.var(x, axis=-1, ddof=1), axis=-1)
    return np.sqrt((between / within + n - 1) / n)


def rhat_rank(x, z_split=None) -> np.ndarray:
    """Rank-normalized split R-hat: the larger of the bulk and the folded (tail) R-hat.
    ``z_split``: ``_z_scale(_split(x))`` if already computed."""
    x = _split(np.asarray(x, dtype=float))
    z = _z_scale(x) if z_split is None else z_split
    med = np.median(x.reshape(*x.shape[:-2], -1), axis=-1)[..., None, None]
    return np.maximum(_rhat_basic(z), _rhat_basic(_z_scale(np.abs(x - med))))


def _ess(x):
    """ESS of (..., chain, draw) with Geyer's initial positive and monotone sequences."""
    x = np.asarray(x, dtype=float)
    n_chain, n = x.shape[-2:]
    m = _fft.next_fast_len(2 * n)
    xc = x - x.mean(axis=-1, keepdims=True)
    f = _fft.rfft(xc, n=m, axis=-1)
    acov = _fft.irfft(f * np.conjugate(f), n=m, axis=-1)[..., :n] / n
    mean_var = acov[..., 0].mean(axis=-1) * n / (n - 1.0)
    var_plus = mean_var * (n - 1.0) / n
    if n_chain > 1:
        var_plus = var_plus + np.var(x.mean(axis=-1), axis=-1, ddof=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = 1.0 - (mean_var[..., None] - acov.mean(axis=-2)) / var_plus[..., None]
    rho[..., 0] = 1.0
    n_pairs = n // 2
    pairs = rho[..., : 2 * n_pairs].reshape(*rho.shape[:-1], n_pairs, 2).sum(axis=-1)
    # Pairs k = 1, 2, … are read while the previous pair's sum is positive and 2k − 1 < n − 3.
    k_lim = max((n - 3) // 2, 0)
    nonpos = pairs[..., : k_lim + 1] <= 0
    k_neg = np.where(nonpos.any(axis=-1), nonpos.argmax(axis=-1), k_lim + 1)
    k_last = np.where(k_neg == 0, 0, np.minimum(k_neg, k_lim))
    monotone = np.minimum.accumulate(pairs, axis=-1)
    k = np.arange(n_pairs)
    head = np.where(k < k_last[..., None], monotone, 0.0).sum(axis=-1)
    rho_last = np.take_along_axis(rho, (2 * k_last)[..., None], axis=-1)[..., 0]
    p_last = np.take_along_axis(pairs, k_last[..., None], axis=-1)[..., 0]
    stopped_on_sign = (k_neg == k_last) & (k_last > 0)
    last = np.where(stopped_on_sign & (p_last < 0), np.maximum(rho_last, 0.0), rho_last)
    tau = -1.0 + 2.0 * head + last
    total = n_chain * n
    tau = np.maximum(tau, 1.0 / np.log10(total))
    ess = total / tau
    ess = np.where(np.isnan(rho).any(axis=-1), np.nan, ess)
    const = (x.max(axis=(-2, -1)) - x.min(axis=(-2, -1))) < np.finfo(float).resolution
    return np.where(const, float(total), ess)


def ess_bulk(x, z_split=None) -> np.ndarray:
    """Bulk ESS: ESS of the rank-normalized split chains."""
    return _ess(_z_scale(_split(np.asarray(x, dtype=float))) if z_split is None else z_split)


def ess_tail(x, prob: float = 0.95) -> np.ndarray:
    """Tail ESS: the smaller ESS of the indicators of the 1 − prob and prob quantiles
    (5% and 95% by default, Vehtari et al. 2021; ArviZ's ``prob`` convention)."""
    x = np.asarray(x, dtype=float)
    flat = x.reshape(*x.shape[:-2], -1)
    out = []
    for q in (1.0 - prob, prob):
        cut = np.quantile(flat, q, axis=-1)[..., None, None]
        out.append(_ess(_split((x <= cut).astype(float))))
    return np.minimum(*out)


def mcse_mean(x) -> np.ndarray:
    """Monte Carlo standard error of the mean: sd / √ESS(mean)."""
    x = np.asarray(x, dtype=float)
    sd = np.std(x.reshape(*x.shape[:-2], -1), axis=-1, ddof=1)
    return sd / np.sqrt(_ess(_split(x)))


def diagnostics(x) -> dict:
    """All of the above for (..., chain, draw), sharing the rank normalization."""
    x = np.asarray(x, dtype=float)
    z = _z_scale(_split(x))
    return {
        "r_hat": rhat_rank(x, z),
        "ess_bulk": ess_bulk(x, z),
        "ess_tail": ess_tail(x, 0.95),
        "mcse_mean": mcse_mean(x),
    }


def hdi(x, prob: float = 0.95) -> np.ndarray:
    """Highest-density interval over (chain, draw): (..., 2), ArviZ's "nearest" method."""
    from arviz_stats.base import array_stats

    return np.asarray(array_stats.hdi(np.asarray(x, dtype=float), prob, axis=(-2, -1)))


def eti(x, prob: float = 0.95) -> np.ndarray:
    """Equal-tailed interval over (chain, draw): (..., 2)."""
    x = np.asarray(x, dtype=float)
    q = np.quantile(x.reshape(*x.shape[:-2], -1), [(1 - prob) / 2, (1 + prob) / 2], axis=-1)
    return np.moveaxis(q, 0, -1)


# --------------------------------------------------------------------------------------
# NetCDF: the attributes of the NetCDF-3 fallback, and reading what was written
# (the writing is pamid._report._mcmc's).


def encode_attrs(attrs) -> dict:
    """Attributes as a NetCDF-3 file can hold them: str, int and float kept, anything else
    (lists, booleans, arrays) as JSON text behind a prefix that :func:`load_inference_data`
    reads back."""
    out = {}
    for k, v in attrs.items():
        if isinstance(v, (str, int, float)) and not isinstance(v, bool):
            out[k] = v
        else:
            out[k] = _JSON_PREFIX + json.dumps(v if not isinstance(v, np.ndarray) else v.tolist())
    return out


def _decode_attrs(attrs):
    return {k: json.loads(v[len(_JSON_PREFIX):]) if isinstance(v, str)
            and v.startswith(_JSON_PREFIX) else v for k, v in attrs.items()}


def load_inference_data(path):
    """Read what ``pamid.report.save_netcdf`` wrote: a NetCDF-4 file, or a folder of
    NetCDF-3 files (one per group)."""
    import arviz as az
    import xarray as xr

    path = Path(path)
    if path.is_file():
        return az.from_netcdf(path)
    groups = {}
    for f in sorted(path.glob("*.nc")):
        with xr.open_dataset(f, engine="scipy") as ds:
            ds = ds.load()
        ds.attrs = _decode_attrs(ds.attrs)
        for v in ds.variables.values():
            v.attrs = _decode_attrs(v.attrs)
        groups[f.stem] = ds
    if not groups:
        raise FileNotFoundError(f"{path}: no NetCDF file or group folder there")
    return xr.DataTree.from_dict(groups)


# --------------------------------------------------------------------------------------
# The posterior predictive along a grid (drawn by pamid._report._mcmc.plot_predictive).


def predictive_bands(result, i, p_level, contraction, n_draws: int = 2000, prob=0.95,
                     n_noise: int = 4):
    """Along a contraction grid at one level of the first input (pressure), at rest:
    posterior mean force, the 95% band of the mean force, and the 95% predictive band
    (noise included; ``n_noise`` noise replicates per draw). Returns
    (mean, (lo, hi), (lo, hi)) as NumPy arrays."""
    spec = result.spec
    p = len(result.param_names)
    draws = result.samples[i].reshape(-1, p + 1)
    pick = np.linspace(0, len(draws) - 1, min(n_draws, len(draws))).astype(int)
    theta, sigma = draws[pick, :p], draws[pick, p]
    x = [np.zeros_like(contraction) for _ in spec.columns]
    x[0] = np.full_like(contraction, p_level)
    x[1] = contraction
    x = tuple(jnp.asarray(a) for a in x)
    mu = np.asarray(jax.vmap(lambda th: spec.predict(th, x))(jnp.asarray(theta)))
    rng = np.random.default_rng(int(jax.random.randint(jax.random.fold_in(result.key, i),
                                                       (), 0, 2**31 - 1)))
    shape = (n_noise, *mu.shape)
    if result.likelihood == "student-t":
        eps = rng.standard_t(result.nu, shape)
    else:
        eps = rng.standard_normal(shape)
    pred = (mu + sigma[:, None] * eps).reshape(-1, mu.shape[-1])
    q = [(1 - prob) / 2, (1 + prob) / 2]
    return (mu.mean(axis=0), tuple(np.quantile(mu, q, axis=0)),
            tuple(np.quantile(pred, q, axis=0)))
