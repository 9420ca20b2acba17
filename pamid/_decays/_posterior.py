"""Bayesian fit of recorded free decays, and their posterior predictive, per trial.

The model is the linear damped oscillator of a PAM-driven joint (Cullinan, section VI),
J·β̈ + c·β̇ + k·(β − β_eq) = 0, in its closed form
(:func:`pamid._sim._oscillator.oscillator_response`), fitted to the encoder samples of each
trial: ``x = (time_s,)`` the time since the start of the trial's window, ``y`` the angle in
rad. Sampled per trial (ensemble MCMC, all trials stacked in one JAX call through
:func:`pamid.fit_mcmc`): the constants

    ζ (damping ratio), f_n = ω_n/2π [Hz], β(t0) [rad], β̇(t0) [rad/s], β_eq [rad]

and the noise σ [rad] of one sample. J cancels out of the free decay, so only ζ and f_n are
identified; given J, k = J·(2π·f_n)² and c = 2·ζ·J·2π·f_n (Cullinan eq. 11) follow draw by
draw (:meth:`DecayPosterior.derived_draws`).

Window. As in :func:`pamid.fit_decay_trajectories`, each trial is fitted from its first to
its last usable extremum (``find_extrema``: above the noise floor); here the window starts at
the first *sample* at or after the first usable extremum, so that its times are the uniform
grid the simulator produces (``t0`` is that sample's time).

Priors (:func:`decay_prior`; weakly informative, each a flat density on its support):

* ζ uniform on (0, 1): a free decay that oscillates is under-damped; ζ ≤ 0 would not decay;
* f_n uniform on (0, f_Nyquist), f_Nyquist = half the sample rate: a faster oscillation
  could not be told from its alias;
* β(t0) and β_eq uniform on (−π, π) rad (one turn of the absolute encoder); β̇(t0) flat;
* σ half-Cauchy with scale a few (default 3) encoder steps, 2π/2^bits rad each (12-bit
  AMT203: 1.5 mrad per step): noise of about one step is typical, a hundred steps is not
  excluded. σ is kept in [1e-6, 1e6] rad by :mod:`._posterior`.

The log-posterior is −inf outside this support and wherever it is not finite (NaN data,
overflow), never NaN (:func:`pamid._sampling._posterior.log_posterior`).

Start: the walkers start around the least-squares optimum of the same model, which
Gauss–Newton (``fit_least_squares`` inside ``fit_mcmc``) reaches from the trajectory fit
:func:`pamid.fit_decay_trajectories` (itself started from the logarithmic decrement),
carried from the first extremum to ``t0`` by the closed form.

Posterior predictive (:meth:`DecayPosterior.predictive`): ``n_draws`` posterior draws per
trial are pushed through :func:`pamid.simulate_oscillator` in ONE batched call (an
oscillator of shape (trials, draws)), Gaussian noise σ of each draw is added, and the 95 %
band is the 2.5–97.5 % quantiles at every sample. When the model is right, about 95 % of
the recorded samples fall inside it; Coulomb friction, which the viscous model lacks,
shows as lower coverage and as residuals that grow late in the decay
(:func:`pamid.report.plot_decay_predictive` draws it).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math

import jax
import jax.numpy as jnp
import numpy as np

from .._data._decay_file import DecayData
from .._fit._spec import ModelSpec
from .._lanes._batch import FitData, pack
from .._sampling._mcmc import McmcResult, fit_mcmc
from .._sampling._posterior import Prior
from .._sim._oscillator import DampedOscillator, oscillator_response, simulate_oscillator
from ._analysis import (
    NoOscillationError,
    find_extrema,
    fit_decay_trajectories,
    pooled_decrement_estimate,
)

__all__ = [
    "DECAY_NAMES",
    "DECAY_SPEC",
    "DecayPosterior",
    "DecayPredictive",
    "decay_prior",
    "fit_decay_mcmc",
]

DECAY_NAMES = ("zeta", "natural_frequency_Hz", "angle0_rad", "rate0_rad_s", "equilibrium_rad")
DECAY_UNITS = {"zeta": "1", "natural_frequency_Hz": "Hz", "angle0_rad": "rad",
               "rate0_rad_s": "rad/s", "equilibrium_rad": "rad"}
#: Default scale of the half-Cauchy prior on σ, in encoder steps.
NOISE_STEPS = 3.0
#: Encoder step assumed when the data show none (12 bit, Cullinan's AMT203).
DEFAULT_STEP_RAD = 2.0 * math.pi / 4096


def decay_predict(theta, x):
    """Angle [rad] at times ``x[0]`` (s since t0) of the decay with constants ``theta``."""
    zeta, f_n, angle0, rate0, eq = (theta[..., j] for j in range(5))
    osc = DampedOscillator.from_modal(zeta, f_n, 1.0, eq)  # J cancels out of a free decay
    return oscillator_response(osc, angle0, rate0, x[0])[0]


def _trajectory_start(t, y, e, t_start=None, fit=None):
    """(ζ, f_n, β, β̇ at ``t_start`` (default t[0]), β_eq) from the trajectory fit of a
    record whose usable extrema ``e`` were found on it (NumPy); ``fit``: that fit, if made."""
    t_start = t[0] if t_start is None else t_start
    fit = _trajectory_fit(t, y, e) if fit is None else fit
    p = fit.params
    osc = DampedOscillator(1.0, p["omega_n_rad_s"] ** 2,
                           2.0 * p["zeta"] * p["omega_n_rad_s"], p["equilibrium_rad"])
    # The fit's state is at its first usable extremum; carry it to the first sample.
    a0, r0 = oscillator_response(osc, p["angle0_rad"], p["rate0_rad_s"], t_start - fit.t0_s)
    return [p["zeta"], p["omega_n_rad_s"] / (2.0 * math.pi), float(a0), float(r0),
            p["equilibrium_rad"]]


def _trajectory_fit(t, y, e):
    """The trajectory fit of one record, started from its decrement (J = 1: unused)."""
    est = pooled_decrement_estimate([e], 1.0)
    return fit_decay_trajectories([t], [y], [e], [est], 1.0)[0]


def _lane_key(t, y) -> bytes:
    return hashlib.sha1(np.ascontiguousarray(t, float).tobytes()
                        + np.ascontiguousarray(y, float).tobytes()).digest()


#: Starts found on the whole records by :func:`decay_windows`, by window content: inside a
#: window the extremum it starts on is not refinable (the parabola would leave the record),
#: so a short window can have one usable extremum too few for a fit of its own.
_KNOWN_STARTS: dict[bytes, list] = {}


def decay_start(x, y, w):
    """Start of the least-squares solve for a batch of windows: the trajectory fit (found
    on the whole record by :func:`decay_windows`, else on the window itself)."""
    t, y, w = (np.asarray(a) for a in (x[0], y, w))
    out = []
    for i in range(y.shape[0]):
        on = w[i] > 0
        known = _KNOWN_STARTS.get(_lane_key(t[i, on], y[i, on]))
        if known is not None:
            out.append(known)
            continue
        try:
            out.append(_trajectory_start(t[i, on], y[i, on], find_extrema(t[i, on], y[i, on])))
        except (NoOscillationError, ValueError, IndexError):
            out.append([math.nan] * 5)
    return jnp.asarray(out, dtype=jnp.float64)


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class DecaySpec(ModelSpec):
    """The free decay's closed-form trajectory as the fitting code sees it: ``theta`` the
    five constants :data:`DECAY_NAMES`, ``x`` the time since the window's start."""

    def predict(self, theta, x):
        return decay_predict(theta, x)

    def start(self, x, y, w):
        return decay_start(x, y, w)

    def make(self, theta):
        return dict(zip(DECAY_NAMES, np.asarray(theta).tolist(), strict=True))


DECAY_SPEC = DecaySpec(
    name="decay",
    param_names=DECAY_NAMES,
    param_units=DECAY_UNITS,
    units={"angle": "rad", "time": "s"},
    columns=("time_s",),
    source="J·β̈ + c·β̇ + k·(β − β_eq) = 0, closed form (Cullinan section VI)",
    output=("angle", "rad"),
)


def decay_prior(sample_rate_Hz: float, encoder_step_rad: float = DEFAULT_STEP_RAD,
                noise_steps: float = NOISE_STEPS) -> Prior:
    """The documented weakly informative prior of the decay model (module docstring)."""
    if not (sample_rate_Hz > 0 and math.isfinite(sample_rate_Hz)):
        raise ValueError(f"sample_rate_Hz must be positive, got {sample_rate_Hz!r}")
    if not encoder_step_rad > 0:
        encoder_step_rad = DEFAULT_STEP_RAD
    inf, nyquist = math.inf, 0.5 * sample_rate_Hz
    return Prior(
        names=DECAY_NAMES,
        loc=(0.0,) * 5,
        scale=(inf,) * 5,
        lower=(0.0, 0.0, -math.pi, -inf, -math.pi),
        upper=(1.0, nyquist, math.pi, inf, math.pi),
        noise_scale_N=noise_steps * encoder_step_rad,
        noise_unit="rad",
        noise_quantity="angle",
        notes=(
            "uniform: under-damped (0 < ζ < 1), the decay oscillates",
            f"uniform below the Nyquist frequency {nyquist:g} Hz",
            "uniform over one turn of the absolute encoder (rad)",
            "flat (rad/s)",
            "uniform over one turn of the absolute encoder (rad)",
        ),
    )


# --------------------------------------------------------------------------------------
# Windows


@dataclasses.dataclass(frozen=True)
class DecayWindows:
    """The fitted part of every trial, packed: ``data.x[0]`` is time since ``t0_s``."""

    data: FitData
    trials: tuple[str, ...]
    t0_s: np.ndarray  # (M,) time of the window's first sample in the record
    n: np.ndarray  # (M,) samples per window
    dt_s: float
    encoder_step_rad: float
    #: (M,) RMS residual of the least-squares trajectory fit (NaN where it failed), rad
    fit_rmse_rad: np.ndarray | None = None


def _as_trials(data):
    """(trial ids, list of (time_s, angle_rad)) from DecayData or a list of pairs."""
    if isinstance(data, DecayData):
        return tuple(data.trials), [data.arrays(tr) for tr in data.trials]
    pairs = [(np.asarray(t, float), np.asarray(y, float)) for t, y in data]
    return tuple(str(i + 1) for i in range(len(pairs))), pairs


def decay_windows(data) -> DecayWindows:
    """Cut every trial to its usable decay (first to last usable extremum) and pack them."""
    trials, pairs = _as_trials(data)
    groups, t0s, ns, dts, steps, rmses = [], [], [], [], [], []
    for t, y in pairs:
        e = find_extrema(t, y)
        te = e.used[0]
        sel = (t >= te[0]) & (t <= te[-1])
        tw, yw = t[sel], y[sel]
        x = tw - tw[0]
        groups.append(((x,), yw))
        if len(_KNOWN_STARTS) > 10_000:
            _KNOWN_STARTS.clear()
        try:
            fit = _trajectory_fit(t, y, e)
            _KNOWN_STARTS[_lane_key(x, yw)] = _trajectory_start(t, y, e, tw[0], fit)
            rmses.append(fit.rmse_rad)
        except (ValueError, IndexError):
            rmses.append(math.nan)
        t0s.append(tw[0])
        ns.append(len(tw))
        dts.append(float(np.median(np.diff(t))))
        steps.append(e.quantum_rad)
    dt = float(np.median(dts))
    if max(abs(d - dt) for d in dts) > 1e-6 * dt:
        raise ValueError("the trials are sampled at different rates; fit them separately")
    step = max(steps) if max(steps) > 0 else DEFAULT_STEP_RAD
    return DecayWindows(pack(groups), trials, np.asarray(t0s), np.asarray(ns), dt, step,
                        np.asarray(rmses))


def _check_prior_support(windows: DecayWindows, prior: Prior) -> None:
    """ValueError naming the trial when a recording lies outside what the prior allows: an
    angle beyond the prior's range of β, or a fit closer than the smallest noise σ (a
    recording without noise has no posterior that a sampler could explore)."""
    from .._sampling._posterior import LOG_SIGMA_BOUNDS

    lo, hi = prior.lower[2], prior.upper[2]
    sigma_min = math.exp(LOG_SIGMA_BOUNDS[0])
    y, on = np.asarray(windows.data.y), np.asarray(windows.data.w) > 0
    for i, trial in enumerate(windows.trials):
        angles = y[i, on[i]]
        if angles.min() <= lo or angles.max() >= hi:
            reach = angles.max() if angles.max() >= hi else angles.min()
            raise ValueError(f"trial '{trial}': the angle reaches {reach:.6g} rad, outside the "
                             f"({lo:.4g}, {hi:.4g}) rad (one encoder turn) that the posterior's "
                             "prior allows for β")
        rmse = windows.fit_rmse_rad[i] if windows.fit_rmse_rad is not None else math.nan
        if rmse < sigma_min:
            raise ValueError(f"trial '{trial}': the decay model fits the recording to "
                             f"{rmse:.3g} rad RMS, below the smallest noise σ = {sigma_min:g} "
                             "rad the posterior allows: a recording without noise has no "
                             "posterior to sample")


# --------------------------------------------------------------------------------------
# Posterior and predictive


@dataclasses.dataclass(frozen=True)
class DecayPredictive:
    """Posterior-predictive decays: ``angle_rad`` (M, draws, T) with noise, ``mean_rad``
    (M, draws, T) without; ``time_s`` (M, T) in record time; ``observed_rad`` and
    ``mask`` (M, T) (False on padding); ``band`` (M, 2, T), the 2.5 and 97.5 % quantiles."""

    time_s: np.ndarray
    angle_rad: np.ndarray
    mean_rad: np.ndarray
    observed_rad: np.ndarray
    mask: np.ndarray
    band: np.ndarray

    def coverage(self) -> np.ndarray:
        """Per trial, the fraction of recorded samples inside the 95 % predictive band."""
        inside = (self.observed_rad >= self.band[:, 0]) & (self.observed_rad <= self.band[:, 1])
        return (inside & self.mask).sum(axis=1) / self.mask.sum(axis=1)


@dataclasses.dataclass(frozen=True, eq=False)
class DecayPosterior:
    """The posterior of every trial's decay (:func:`fit_decay_mcmc`).

    ``mcmc`` is the :class:`pamid.McmcResult` (samples (M, W, D, 6): ζ, f_n, β(t0), β̇(t0),
    β_eq, σ [rad]; its ``ls`` is the least-squares fit the walkers started from, with Wald
    intervals); ``windows`` the fitted part of each trial.
    """

    mcmc: McmcResult
    windows: DecayWindows
    prior: Prior

    @property
    def trials(self) -> tuple[str, ...]:
        return self.windows.trials

    def flat_draws(self) -> np.ndarray:
        """(M, W·D, 6): every kept draw of every trial."""
        s = self.mcmc.samples
        return s.reshape(s.shape[0], -1, s.shape[-1])

    def derived_draws(self, inertia_kg_m2: float) -> dict:
        """k = J·ω_n² and c = 2·ζ·J·ω_n per draw (Cullinan eq. 11), each (M, W·D)."""
        d = self.flat_draws()
        omega = 2.0 * math.pi * d[..., 1]
        return {"stiffness_Nm_per_rad": inertia_kg_m2 * omega**2,
                "damping_Nms_per_rad": 2.0 * d[..., 0] * inertia_kg_m2 * omega}

    def intervals(self, inertia_kg_m2: float | None = None) -> list[dict]:
        """Per trial: posterior mean, sd, 95 % ETI, R-hat, bulk ESS, MCSE of ζ and f_n (and
        k, c given J), beside the least-squares value and Wald interval."""
        m, ls = self.mcmc, self.mcmc.ls
        out = []
        extra = self.derived_draws(inertia_kg_m2) if inertia_kg_m2 else {}
        for i, trial in enumerate(self.trials):
            row = {"trial": trial}
            for j, name in enumerate((*DECAY_NAMES, "sigma_rad")):
                row[name] = {
                    "mean": float(m.mean[i, j]), "sd": float(m.sd[i, j]),
                    "eti95": [float(v) for v in m.eti95[i, j]],
                    "r_hat": float(m.r_hat[i, j]), "ess_bulk": float(m.ess_bulk[i, j]),
                    "mcse_mean": float(m.mcse_mean[i, j]),
                }
                if j < len(DECAY_NAMES):
                    row[name]["ls"] = float(ls.theta[i, j])
                    row[name]["ls_wald95"] = [float(v) for v in ls.ci95[i, j]]
            for name, v in extra.items():
                row[name] = {"mean": float(v[i].mean()), "sd": float(v[i].std(ddof=1)),
                             "eti95": [float(q) for q in np.quantile(v[i], [0.025, 0.975])]}
            row["converged"] = bool(m.converged[i])
            out.append(row)
        return out

    def predictive(self, key: jax.Array, n_draws: int = 200) -> DecayPredictive:
        """``n_draws`` posterior draws per trial through the simulator in one batched call,
        plus the noise σ of each draw; the 95 % band per sample (module docstring)."""
        k_pick, k_noise = jax.random.split(key)
        d = self.flat_draws()
        m_trials, n_all, _ = d.shape
        pick = np.asarray(jax.random.choice(k_pick, n_all, (n_draws,), replace=n_draws > n_all))
        z = jnp.asarray(d[:, pick])  # (M, n_draws, 6)
        osc = DampedOscillator.from_modal(z[..., 0], z[..., 1], 1.0, z[..., 4])
        n_max = self.windows.data.y.shape[1]
        dt = self.windows.dt_s
        run = simulate_oscillator(osc, z[..., 2], z[..., 3], duration_s=(n_max - 1) * dt,
                                  sample_rate_Hz=1.0 / dt, with_rate=False)
        mean = np.asarray(run.angle_rad)  # (M, n_draws, T)
        noise = np.asarray(jax.random.normal(k_noise, mean.shape)) * np.asarray(z[..., 5:6])
        angle = mean + noise
        band = np.quantile(angle, [0.025, 0.975], axis=1)  # (2, M, T)
        mask = np.asarray(self.windows.data.w) > 0
        time = self.windows.t0_s[:, None] + np.asarray(self.windows.data.x[0])
        return DecayPredictive(time, angle, mean, np.asarray(self.windows.data.y), mask,
                               np.moveaxis(band, 0, 1))


def fit_decay_mcmc(
    data,
    *,
    key: jax.Array,
    noise_steps: float = NOISE_STEPS,
    encoder_step_rad: float | None = None,
    n_walkers: int = 24,
    max_steps: int = 20_000,
    min_steps: int = 0,
    check_every: int = 1000,
    thin: int = 10,
    **kwargs,
) -> DecayPosterior:
    """Sample the posterior of every trial's decay in one stacked run (module docstring).

    Args:
        data: a :class:`pamid.DecayData` (``load_decay``) or a list of (time_s, angle_rad)
            pairs, one per trial, all at one sample rate.
        key: JAX PRNG key, the only source of randomness.
        noise_steps, encoder_step_rad: the σ prior's half-Cauchy scale is ``noise_steps``
            encoder steps; the step is found in the data (12-bit default if none).
        n_walkers, max_steps, min_steps, check_every, thin, **kwargs: passed to
            :func:`pamid.fit_mcmc` (which runs until 50 autocorrelation times are kept).
    """
    windows = decay_windows(data)
    step = windows.encoder_step_rad if encoder_step_rad is None else encoder_step_rad
    # Rounded, so that records at one nominal rate share one prior (and one compilation).
    prior = decay_prior(float(f"{1.0 / windows.dt_s:.9g}"), step, noise_steps)
    _check_prior_support(windows, prior)
    mcmc = fit_mcmc(windows.data, DECAY_SPEC, key=key, prior=prior, n_walkers=n_walkers,
                    max_steps=max_steps, min_steps=min_steps, check_every=check_every,
                    thin=thin, muscles=windows.trials, **kwargs)
    return DecayPosterior(mcmc, windows, prior)
