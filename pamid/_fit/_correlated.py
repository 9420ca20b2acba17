"""Intervals that hold when the residuals are correlated: sandwich covariances.

The Wald interval (:func:`pamid._fit._intervals.wald`) takes Cov(θ̂) = s²·(JᵀJ)⁻¹, which is
right only when the residuals are independent with one variance. Bench residuals are not:
a force transient, a drift or a model that misses the curve's shape leaves runs of
residuals of one sign along every curve (the real AARL 10 mm file: lag-1 autocorrelation
≈ 0.5 after the best selection). With A = JᵀJ (J the weighted Jacobian at the optimum) and
the scores sₜ = Jₜ·rₜ of every row, the sandwich

    Cov(θ̂) = A⁻¹ · B · A⁻¹,   B = an estimate of Var(Σₜ sₜ)

needs no model of the noise, only an assumption about which rows may be correlated:

* ``cluster`` — rows of different groups (curves or trials) are independent, rows within a
  group may be correlated in any way: B = Σ_g u_g u_gᵀ with u_g = Σ_{t∈g} sₜ (Liang & Zeger
  1986; Cameron & Miller 2015, "A Practitioner's Guide to Cluster-Robust Inference",
  J. Human Resources 50(2) 317–372). With few clusters B is too small; the corrections
  (Cameron & Miller 2015, on few clusters): CR1 = G/(G − 1)·(N − 1)/(N − p)·CR0; CR2
  (Bell & McCaffrey 2002) replaces u_g by J_gᵀ(I − H_gg)^(−1/2) r_g; CR3 by
  J_gᵀ(I − H_gg)⁻¹ r_g, which makes A⁻¹·B·A⁻¹ the (uncentred) jackknife of deleting one
  cluster, H_gg = J_g A⁻¹ J_gᵀ being the cluster's block of the hat matrix. Intervals use
  Student's t with G − 1 degrees of freedom, as Cameron & Miller 2015 recommend.
* ``hac`` — rows are correlated with their neighbours in time within a trial, weakly at
  large lags: B = Γ₀ + Σ_{l≥1} k(l/S)·(Γ_l + Γ_lᵀ), Γ_l = Σ sₜ s_{t−l}ᵀ over pairs of rows l
  apart *inside the same group*, with Bartlett's kernel k(x) = 1 − |x| (Newey & West 1987,
  Econometrica 55(3) 703–708) and the bandwidth S of Andrews' AR(1) plug-in (Andrews 1991,
  Econometrica 59(3) 817–858, section 6): S = 1.1447·(α̂(1)·n)^(1/3),
  α̂(1) = Σ_a 4ρ_a²σ_a⁴/((1 − ρ_a)⁶(1 + ρ_a)²) / Σ_a σ_a⁴/(1 − ρ_a)⁴, where ρ_a, σ_a² are an
  AR(1) fitted to score component a (each component scaled to unit mean square first, so
  that constants of different units weigh alike). Scaled by n/(n − p) so that it equals the
  Wald covariance for independent noise; t with n − p degrees of freedom.

The groups pamid passes are **trials** for ``hac`` (time runs on inside a trial from one
curve to the next, and so does a transient or drift: the kernel's weights fall off with
the lag anyway) and **curves** for ``cluster`` (:func:`pamid._data._curves.find_curves`:
a curve lies inside one trial, so clusters never mix trials; curves are twice as many as
trials in an isometric file, and a cluster sandwich needs many clusters). The kind pamid
shows, CR3 by curve, was chosen by the coverage study ``experiments/interval_coverage.py``
(table in experiments/README.md): on virtual files with AR(1) noise inside curves (φ = 0,
0.5, 0.8) and with a smooth misfit-like residual, Sárosi and Cullinan models, Sárosi's
sweeps (10 curves) and AARL-like isometric stairs (24 curves), 1000 muscles each, CR3 by
curve covered 94.6–96.6 % (mean over the constants; 92.4 % for the worst constant of the
worst setting); CR2 92–95 %, CR1 90–93 %, the HAC interval 85–95 % (its bandwidth,
estimated from short curves, is too small when the correlation is strong, and 2× or 4×
that bandwidth did not help) and the whole-curve bootstrap 88–94 %.

Everything is computed for all muscles of a batch at once, NumPy arrays with a leading
muscle axis; memory is proportional to the rows (the scores) plus p² per cluster.
Rows must be in time order within each group (file order: :func:`pack_rows` keeps it).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._inference import gram_inverse, normal_upper_tail, t_critical, wald_interval
from .._lanes._batch import FitData, map_lanes
from .._solvers import residuals_and_jacobian
from ._least_squares import _key, _take_lanes, lag1_sums, residuals
from ._spec import ModelSpec

CLUSTER_KINDS = ("CR1", "CR2", "CR3")

#: The eigenvalues of a cluster's leverage A^(−1/2)·A_g·A^(−1/2) are capped below 1: a
#: cluster that alone determines a direction of θ (leverage 1) gets a huge, honest variance.
_MAX_LEVERAGE = 1.0 - 1e-9


@functools.partial(jax.jit, static_argnames=("spec",))
def _jacobian_residuals(spec, theta, x, y, w):
    def one(theta, x, y, w):
        r, jac = residuals_and_jacobian(spec, theta, x, y, w)
        return jac, r

    return jax.vmap(one)(theta, x, y, w)


def jacobian_residuals(spec: ModelSpec, theta, data: FitData, of_lanes: int | None = None):
    """The weighted Jacobian J (M, n, p) and residuals r (M, n) = w^½·(model − y) at θ,
    every muscle in one batched call (zero on padding); ``of_lanes``: the muscles of the
    batch these were taken from (:func:`pamid._lanes._batch.map_lanes`)."""
    jac, r = map_lanes(
        lambda t, x, y, w: _jacobian_residuals(spec, t, x, y, w),
        jnp.asarray(theta, dtype=jnp.float64), data.x, data.y, data.w,
        cache_key=_key("jacobian_residuals", spec), of_lanes=of_lanes,
    )
    return np.asarray(jac), np.asarray(r)


@functools.partial(jax.jit, static_argnames=("spec",))
def _residuals_only(spec, theta, x, y, w):
    return jax.vmap(lambda t, x, y, w: residuals(spec, t, x, y, w))(theta, x, y, w)


def batch_residuals(spec: ModelSpec, theta, data: FitData) -> np.ndarray:
    """The weighted residuals r (M, n) = w^½·(model − y) at θ (zero on padding)."""
    return np.asarray(map_lanes(
        lambda t, x, y, w: _residuals_only(spec, t, x, y, w),
        jnp.asarray(theta, dtype=jnp.float64), data.x, data.y, data.w,
        cache_key=_key("batch_residuals", spec),
    ))


def _bread(jac):
    """A⁻¹ = (JᵀJ)⁻¹ per muscle (pamid's one rank criterion, on A:
    :func:`pamid._inference.gram_inverse`; NaN where J is rank-deficient) and A."""
    a = np.matmul(np.swapaxes(jac, 1, 2), jac)
    return a, gram_inverse(a)[0]


def _dense_groups(groups):
    """Group ids (M, n), −1 on padding, and the number of group slots G_max."""
    groups = np.asarray(groups, dtype=np.int64)
    return groups, int(groups.max()) + 1 if groups.size else 0


def _group_sums(values, groups, g_max):
    """Σ over the rows of every group: values (M, n, k) → (M, G_max, k); padding dropped."""
    m, n, k = values.shape
    valid = groups >= 0
    idx = (np.arange(m)[:, None] * g_max + np.where(valid, groups, 0)).ravel()
    out = np.empty((m * g_max, k))
    for j in range(k):  # a loop over the (few) columns, each one bincount over all rows
        column = np.where(valid, values[..., j], 0.0).ravel()
        out[:, j] = np.bincount(idx, weights=column, minlength=m * g_max)
    return out.reshape(m, g_max, k)


def n_groups(groups) -> np.ndarray:
    """Number of non-empty groups of every muscle (M,)."""
    groups, g_max = _dense_groups(groups)
    if g_max == 0:
        return np.zeros(groups.shape[0], dtype=np.int64)
    counts = _group_sums(np.ones(groups.shape + (1,)), groups, g_max)[..., 0]
    return np.sum(counts > 0, axis=-1)


def cluster_covariance(jac, r, groups, kind: str = "CR3"):
    """Cluster-robust sandwich covariance A⁻¹·B·A⁻¹ (M, p, p), groups independent.

    ``kind``: "CR1" (Cameron & Miller 2015's G/(G−1)·(N−1)/(N−p) factor), "CR2"
    (Bell & McCaffrey 2002's bias-reduced linearisation) or "CR3" (the jackknife). CR2 and
    CR3 need (I − H_gg)^(−a) only in the p-dimensional space of the cluster's columns: with
    C_g = A^(−½)·A_g·A^(−½) (A_g = J_gᵀJ_g), J_gᵀ·f(H_gg)·r_g = A^(½)·f(C_g)·A^(−½)·u_g for
    f(h) = (1 − h)^(−a) (the push-through identity), so no n_g × n_g matrix is formed.
    Returns (covariance, G) with G the number of non-empty groups per muscle.
    """
    if kind not in CLUSTER_KINDS:
        raise ValueError(f"unknown cluster kind {kind!r}; choose one of {CLUSTER_KINDS}")
    jac, r = np.asarray(jac, float), np.asarray(r, float)
    groups, g_max = _dense_groups(groups)
    m, n, p = jac.shape
    a, a_inv = _bread(jac)
    u = _group_sums(jac * r[..., None], groups, g_max)  # (M, G, p)
    g_count = n_groups(groups)
    if kind == "CR1":
        n_obs = np.sum(groups >= 0, axis=-1)
        with np.errstate(divide="ignore", invalid="ignore"):
            factor = (g_count / (g_count - 1.0)) * (n_obs - 1.0) / (n_obs - p)
        v = u * np.sqrt(np.where(g_count > 1, factor, np.nan))[:, None, None]
    else:
        a_g = np.empty((m, g_max, p, p))
        for i in range(p):  # A_g = J_gᵀJ_g by rows: memory of one column of products
            prod = _group_sums(jac[..., i:i + 1] * jac[..., i:], groups, g_max)
            a_g[..., i, i:] = prod
            a_g[..., i:, i] = prod
        lam, vec = np.linalg.eigh(a)  # A^(±½) by its eigendecomposition
        with np.errstate(invalid="ignore", divide="ignore"):
            root = np.sqrt(np.where(lam > 0, lam, np.nan))
        vt = np.swapaxes(vec, 1, 2)
        a_half = (vec * root[:, None, :]) @ vt
        a_mhalf = (vec / root[:, None, :]) @ vt
        c_g = a_mhalf[:, None] @ a_g @ a_mhalf[:, None]
        c_g = 0.5 * (c_g + np.swapaxes(c_g, -1, -2))
        ok = np.all(np.isfinite(c_g), axis=(-1, -2))
        lam_g, vec_g = np.linalg.eigh(np.where(ok[..., None, None], c_g, 0.0))
        power = 0.5 if kind == "CR2" else 1.0
        f = (1.0 - np.clip(lam_g, 0.0, _MAX_LEVERAGE)) ** -power
        f_c = (vec_g * f[..., None, :]) @ np.swapaxes(vec_g, -1, -2)
        v = (a_half[:, None] @ f_c @ (a_mhalf[:, None] @ u[..., None]))[..., 0]
        v = np.where(ok[..., None], v, np.nan)
    meat = np.swapaxes(v, 1, 2) @ v
    return a_inv @ meat @ np.swapaxes(a_inv, 1, 2), g_count


def _pairs(groups, lag):
    """Mask (M, n − lag) of the row pairs (t, t − lag) inside one group."""
    g0, g1 = groups[:, lag:], groups[:, :-lag]
    return (g0 == g1) & (g0 >= 0)


def andrews_bandwidth(scores, groups) -> np.ndarray:
    """Andrews' (1991, section 6) AR(1) plug-in bandwidth S (M,) of the Bartlett kernel,
    S = 1.1447·(α̂(1)·n)^(1/3), with unit weights; an AR(1) per score component, fitted to
    the pairs of neighbouring rows inside a group, after scaling the component to unit mean
    square."""
    groups = np.asarray(groups)
    valid = groups >= 0
    n = np.sum(valid, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.sqrt(np.sum(scores**2, axis=1) / n[:, None])  # (M, p)
        z = scores / np.where(scale > 0, scale, 1.0)[:, None, :]
        pair = _pairs(groups, 1)[..., None]
        zt, zl = z[:, 1:], z[:, :-1]
        rho = np.sum(pair * zt * zl, axis=1) / np.sum(pair * zl * zl, axis=1)
        rho = np.clip(np.nan_to_num(rho), -0.97, 0.97)
        innov = pair * (zt - rho[:, None, :] * zl)
        sigma2 = np.sum(innov**2, axis=1) / np.maximum(np.sum(pair, axis=1), 1)
        num = np.sum(4 * rho**2 * sigma2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2), axis=-1)
        den = np.sum(sigma2**2 / (1 - rho) ** 4, axis=-1)
        alpha1 = np.where(den > 0, num / den, 0.0)
    return 1.1447 * (alpha1 * n) ** (1.0 / 3.0)


def hac_covariance(jac, r, groups, bandwidth=None):
    """Newey–West (Bartlett-kernel) HAC sandwich A⁻¹·B·A⁻¹·n/(n − p) (M, p, p) with pairs
    of rows summed only inside a group. ``bandwidth`` S (M,) or scalar; default Andrews'
    AR(1) plug-in (:func:`andrews_bandwidth`), at most the longest group. Lags l < S get
    weight 1 − l/S. Returns (covariance, S)."""
    jac, r = np.asarray(jac, float), np.asarray(r, float)
    groups = np.asarray(groups, dtype=np.int64)
    m, n, p = jac.shape
    _, a_inv = _bread(jac)
    s = jac * r[..., None]
    if bandwidth is None:
        bandwidth = andrews_bandwidth(s, groups)
    longest = _longest_run(groups)
    bandwidth = np.minimum(np.broadcast_to(np.asarray(bandwidth, float), (m,)), longest)
    meat = np.swapaxes(s, 1, 2) @ s
    max_lag = int(np.ceil(np.nanmax(bandwidth))) if m else 0
    for lag in range(1, min(max_lag, n - 1) + 1):  # a loop over lags, all muscles at once
        weight = np.clip(1.0 - lag / bandwidth, 0.0, None)  # (M,)
        if not np.any(weight > 0):
            break
        pair = _pairs(groups, lag) * weight[:, None]
        gamma = np.swapaxes(s[:, lag:] * pair[..., None], 1, 2) @ s[:, :-lag]
        meat += gamma + np.swapaxes(gamma, -1, -2)
    n_obs = np.sum(groups >= 0, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(n_obs > p, n_obs / (n_obs - p), np.nan)
    cov = a_inv @ meat @ np.swapaxes(a_inv, 1, 2) * factor[:, None, None]
    return cov, bandwidth


def _longest_run(groups) -> np.ndarray:
    """Rows of the largest group of every muscle (M,)."""
    groups, g_max = _dense_groups(groups)
    if g_max == 0:
        return np.zeros(groups.shape[0])
    counts = _group_sums(np.ones(groups.shape + (1,)), groups, g_max)[..., 0]
    return counts.max(axis=-1)


def lag1_from_sums(num, den, n_pairs):
    """ρ̂ = num / den and its one-sided p-value against independence (z = ρ̂·√pairs);
    NumPy arrays. Returns (rho, p_value, pairs)."""
    num, den, n_pairs = np.asarray(num), np.asarray(den), np.asarray(n_pairs)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = num / den
    p_value = np.where(n_pairs > 0, normal_upper_tail(rho * np.sqrt(n_pairs)), np.nan)
    return rho, p_value, n_pairs


def lag1_autocorrelation(r, groups):
    """Lag-1 autocorrelation of the residuals inside groups, per muscle, and its one-sided
    p-value against independence: ρ̂ = Σ rₜr_{t−1} / Σ rₜ² over pairs of neighbouring rows
    of one group, z = ρ̂·√(pairs) ~ N(0, 1) under independence (Box & Jenkins' large-sample
    standard error 1/√n). Returns (rho, p_value, pairs)."""
    return lag1_from_sums(*lag1_sums(np.asarray(r, float), np.asarray(groups)))


def ar1_noise(key, groups, n_draws: int, sigma: float, phi: float) -> np.ndarray:
    """Noise for coverage studies: ``n_draws`` rows (n_draws, n) of a stationary AR(1),
    eₜ = φ·e_{t−1} + √(1 − φ²)·σ·εₜ, restarted (e ~ N(0, σ²)) at the first row of every
    group of ``groups`` (n,), rows of a group contiguous: independent between groups."""
    groups = np.asarray(groups)
    n = len(groups)
    eps = sigma * np.asarray(jax.random.normal(key, (n_draws, n), dtype=jnp.float64))
    start = np.r_[True, groups[1:] != groups[:-1]] if n else np.zeros(0, bool)
    out = np.empty_like(eps)
    innov = np.sqrt(1.0 - phi**2)
    for t in range(n):  # a loop over rows, every draw at once
        out[:, t] = eps[:, t] if start[t] else phi * out[:, t - 1] + innov * eps[:, t]
    return out


def sandwich_intervals(theta, cov, dof, level: float = 0.95):
    """se (M, p), lower, upper of the Student-t interval θ̂ ± t_dof·se from a covariance."""
    with np.errstate(invalid="ignore"):
        se = np.sqrt(np.diagonal(cov, axis1=-2, axis2=-1))
    lower, upper = wald_interval(theta, se, np.asarray(dof, float)[..., None], level)
    return se, lower, upper


def correlated_intervals(spec: ModelSpec, data: FitData, theta, method: str = "cluster",
                         groups=None, *, kind: str = "CR3", level: float = 0.95,
                         jac_r=None):
    """Intervals of every muscle's constants that hold under correlated residuals.

    ``method``: "cluster" (:func:`cluster_covariance`, t on G − 1 dof) or "hac"
    (:func:`hac_covariance`, t on n − p dof). ``groups`` (M, n): cluster / HAC group of
    every row (−1 on padding); default ``data.curve``. ``jac_r``: (J, r) when already
    computed. Returns a dict with se, lower, upper, covariance, dof and, for "hac", the
    bandwidth; for "cluster", the number of groups.
    """
    groups = np.asarray(data.curve if groups is None else groups)
    jac, r = jacobian_residuals(spec, theta, data) if jac_r is None else jac_r
    p = jac.shape[-1]
    out = {}
    if method == "cluster":
        cov, g = cluster_covariance(jac, r, groups, kind)
        dof = np.where(g > 1, g - 1.0, np.nan)
        out["n_groups"] = g
    elif method == "hac":
        cov, bw = hac_covariance(jac, r, groups)
        dof = np.sum(groups >= 0, axis=-1) - float(p)
        dof = np.where(dof > 0, dof, np.nan)
        out["bandwidth"] = bw
    else:
        raise ValueError(f"unknown method {method!r}; choose 'cluster' or 'hac'")
    se, lower, upper = sandwich_intervals(theta, cov, dof, level)
    out.update(se=se, lower=lower, upper=upper, covariance=cov, dof=dof)
    return out


#: The fit says that its Wald interval is too narrow where the residual's lag-1
#: autocorrelation within curves is at least this and significant (one-sided p below
#: ``LAG1_P``). 0.1 keeps tiny, practically harmless correlations of long files quiet; at
#: ρ = 0.1 the Wald variance is already too small by the factor (1 + ρ)/(1 − ρ) ≈ 1.2.
LAG1_NOTE = 0.1
LAG1_P = 0.01


def trial_groups(bench, of: str = "trial", muscles=None, width: int | None = None
                 ) -> np.ndarray:
    """The trial of every row of a loaded bench file, packed like its batch (M, n_max),
    −1 on padding: ``bench.curves.trial`` by :func:`~pamid._lanes._batch.pack_rows`.
    ``of="curve"``: the curve of every row (``bench.curves.curve``) instead.

    ``muscles``: only these muscles (indices, in this order), their curves found on their
    own rows (the file's curves are not found for the others, unless found already), in
    ``width`` columns (the batch's)."""
    from .._lanes._batch import pack_rows

    codes = bench.muscle_codes
    if muscles is None:
        packed = pack_rows(codes, (), np.zeros(len(codes)), getattr(bench.curves, of),
                           n_muscles=len(bench.muscles))
        return np.asarray(packed.curve)
    from .._data._curves import find_curves

    muscles = np.asarray(muscles, dtype=np.int64)
    rows = np.flatnonzero(np.isin(codes, muscles))
    if "curves" in bench.__dict__:  # found already (a cached property): reuse them
        ids = np.asarray(getattr(bench.curves, of))[rows]
    else:
        ids = np.asarray(getattr(find_curves(bench.columns.take(rows)), of))
    lane = np.full(len(bench.muscles), -1, dtype=np.int64)
    lane[muscles] = np.arange(len(muscles))  # each muscle's lane, in the order given
    packed = np.asarray(pack_rows(lane[codes[rows]], (), np.zeros(len(rows)), ids,
                                  n_muscles=len(muscles)).curve)
    width = packed.shape[1] if width is None else int(width)
    out = np.full((len(muscles), width), -1, dtype=np.int64)
    k = min(width, packed.shape[1])
    out[:, :k] = packed[:, :k]
    return out


def for_fit(spec: ModelSpec, data: FitData, theta, intervals, trials=None,
            level: float = 0.95, lag1=None, show: str = "holds", curves_of=None) -> dict:
    """What :func:`pamid.fit_least_squares` adds to its result: the residual's lag-1
    autocorrelation (always; within curves where ``data`` carries them), the "cluster"
    interval (CR3 by curve, t on G − 1) and the "hac" interval (Newey–West within
    ``trials``, default within curves) where asked for, and per muscle a note on which
    interval holds and why. ``lag1``: the sums of :func:`lag1_sums` within ``data.curve``
    where the caller has them already (the fit's statistics program computes them: no
    second pass over the samples).

    ``show``: "holds" (default): where a muscle's residual is correlated (:data:`LAG1_NOTE`,
    :data:`LAG1_P`) its shown interval (``interval_of``) is one that holds under correlated
    noise: the cluster interval, computed here where neither it nor HAC was asked for
    (``curves_of(muscles, width)``: the packed curve of every sample of those muscles, for
    data packed without them; computed on those muscles' lanes alone), or HAC where only
    that was asked for; a muscle of fewer than two curves keeps Wald's, and its note says
    so. "wald": Wald's for every muscle."""
    if show not in ("holds", "wald"):
        raise ValueError(f"show must be 'holds' or 'wald', not {show!r}")
    wanted = [k for k in ("cluster", "hac") if k in intervals]
    need = None  # the muscles whose shown interval is the cluster one though none was asked
    if show == "holds" and not wanted:
        # The residual's correlation first: the cluster interval is computed only for the
        # muscles that need it, on their lanes alone (10,000 white-noise muscles flag ~40 by
        # chance: their curves and Jacobians, not the file's, 3.3 s and 1.5 s of 12 s).
        if lag1 is not None:
            rho, p_value, _ = lag1_from_sums(*lag1)
        else:
            rho, p_value, _ = lag1_autocorrelation(batch_residuals(spec, theta, data),
                                                   np.asarray(data.curve))
        need = np.flatnonzero((rho >= LAG1_NOTE) & (p_value < LAG1_P))
        if len(need):
            wanted = ["cluster"]
    out = {}
    m = theta.shape[0]
    g = bw = None
    if need is not None:
        out.update(residual_lag1=rho, residual_lag1_p=p_value)
        if len(need):
            curves = (curves_of(need, data.y.shape[1]) if curves_of is not None
                      else np.asarray(data.curve)[need])
            lanes = _take_lanes(data, need)._replace(curve=jax.device_put(curves))
            # In the calls of the whole batch (``of_lanes``): one compiled shape however many
            # muscles need it (about 40 of 10,000 white-noise muscles, by chance), the one
            # `pamid warm-up` compiles.
            jac_r = jacobian_residuals(spec, theta[need], lanes, of_lanes=m)
            c = correlated_intervals(spec, lanes, theta[need], "cluster", curves, kind="CR3",
                                     level=level, jac_r=jac_r)
            p = theta.shape[1]
            ci, se_c = np.full((m, p, 2), np.nan), np.full((m, p), np.nan)
            g = np.zeros(m, dtype=np.asarray(c["n_groups"]).dtype)
            ci[need] = np.stack([c["lower"], c["upper"]], axis=-1)
            se_c[need], g[need] = np.asarray(c["se"]), np.asarray(c["n_groups"])
            out.update(ci95_cluster=ci, se_cluster=se_c, cluster_groups=g)
    else:
        # The curves to the host only where used (10,000 muscles of 300 rows: 24 MB).
        curves = np.asarray(data.curve) if wanted or lag1 is None else None
        if wanted:
            jac_r = jacobian_residuals(spec, theta, data)
        if lag1 is not None:
            rho, p_value, _ = lag1_from_sums(*lag1)
        else:
            r = jac_r[1] if wanted else batch_residuals(spec, theta, data)
            rho, p_value, _ = lag1_autocorrelation(r, curves)
        out.update(residual_lag1=rho, residual_lag1_p=p_value)
    if "cluster" in wanted and need is None:
        c = correlated_intervals(spec, data, theta, "cluster", curves, kind="CR3",
                                 level=level, jac_r=jac_r)
        out["ci95_cluster"] = np.stack([c["lower"], c["upper"]], axis=-1)
        out["se_cluster"] = np.asarray(c["se"])
        g = out["cluster_groups"] = c["n_groups"]
    if "hac" in wanted:
        h = correlated_intervals(spec, data, theta, "hac",
                                 curves if trials is None else trials, level=level,
                                 jac_r=jac_r)
        out["ci95_hac"] = np.stack([h["lower"], h["upper"]], axis=-1)
        out["se_hac"] = np.asarray(h["se"])
        bw = out["hac_bandwidth"] = h["bandwidth"]
    flagged = (rho >= LAG1_NOTE) & (p_value < LAG1_P)
    notes = [None] * m
    interval_of = ["wald-t"] * m
    for i in np.flatnonzero(flagged).tolist():  # only the muscles with something to say
        head = (f"residual lag-1 autocorrelation {rho[i]:.2f} between consecutive samples: "
                "the Wald interval assumes independent noise and is too narrow; ")
        if g is not None and g[i] >= 2:
            few = (f" (only {int(g[i])} curves; pamid's coverage study had 10–24)"
                   if g[i] < 10 else "")
            shown = ", shown as ci95" if show == "holds" else ""
            notes[i] = (head + f"ci95_cluster (CR3 by curve, t on {int(g[i]) - 1} dof) "
                         f"holds under correlated noise{few}{shown}")
            interval_of[i] = "cluster" if show == "holds" else "wald-t"
        elif bw is not None:
            shown = " (shown as ci95)" if show == "holds" else ""
            notes[i] = (head + f"ci95_hac (Newey–West, bandwidth {bw[i]:.0f} rows){shown} "
                         "allows for it but ran 85–95 % in pamid's coverage study; ask for "
                         "the cluster interval (--intervals wald,profile,cluster) where the "
                         "data have curves")
            interval_of[i] = "hac" if show == "holds" else "wald-t"
        elif g is not None:
            notes[i] = (head + f"the cluster interval needs at least two curves (this "
                         f"muscle has {int(g[i])}), so none that holds can be given; "
                         "Wald's is shown")
        else:
            notes[i] = (head + "ask for the cluster interval (--intervals wald,profile,cluster), "
                         "which holds under correlated noise")
    out["interval_notes"] = tuple(notes)
    groups_of = {"cluster": "curve", "hac": "curve" if trials is None else "trial"}
    out["interval_groups"] = {k: groups_of[k] for k in wanted}
    shown = "wald-t"
    if np.any(flagged) and show == "holds":
        shown = "cluster" if "cluster" in wanted else ("hac" if "hac" in wanted else shown)
    out["interval_shown"] = shown
    out["interval_of"] = tuple(interval_of)
    return out


__all__ = [
    "CLUSTER_KINDS",
    "andrews_bandwidth",
    "ar1_noise",
    "batch_residuals",
    "for_fit",
    "trial_groups",
    "cluster_covariance",
    "correlated_intervals",
    "hac_covariance",
    "jacobian_residuals",
    "lag1_autocorrelation",
    "lag1_from_sums",
    "lag1_sums",
    "n_groups",
    "sandwich_intervals",
    "t_critical",
]
