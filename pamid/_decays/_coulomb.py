"""Free decays with candidate effects: exact Coulomb friction in JAX, a drifting equilibrium,
and one batched, cross-validated fit of every (effect set × trial × fold).

Baseline (Cullinan, section VI, the model behind eq. 8–11): the arm is a linear damped
oscillator, J·β̈ + c·β̇ + k·(β − β_eq) = 0, with ω_n² = k/J and ζ = c/(2·√(k·J)) (eq. 11).

Candidate effects (neither is in the sources; both are standard mechanics), each a model
that wraps the oscillator (:class:`~pamid._decays._analysis.Trajectory`), in the order of
:data:`~pamid._effects._definitions.DECAY_EFFECT_DEFINITIONS` (:func:`decay_model`):

* ``"coulomb_friction"`` (:class:`pamid._effects._coulomb_friction.CoulombFriction`): a
  constant friction torque T_c against the motion (sliding seals, the cable over the
  pulley): J·β̈ + c·β̇ + k·(β − β_eq) + T_c·sign(β̇) = 0, sticking for good where the arm
  comes to rest with k·|β − β_eq| ≤ T_c. Each half cycle is the oscillator's closed form
  about the shifted centre β_eq − sign(β̇)·u_c, u_c = T_c/k. This is the model of
  :func:`pamid._virtual._decay.coulomb_decay` (NumPy, a Python loop);
  :func:`coulomb_response` is the same in JAX, pure and exact (no smoothed sign): a
  ``lax.scan`` over a fixed number of half cycles computes each one's start time, centre
  and start state analytically, and every sample evaluates the closed form of its half
  cycle. The fit lets u_c take either sign (the analytic continuation), so that near
  u_c = 0 the fit and its Wald interval are smooth and an interval can contain 0.

* ``"drift"`` (:class:`pamid._effects._drift.DecayDrift`): the equilibrium moves linearly
  in time, β_eq(t) = β_eq + r·t (a slow leak, a creeping set point, an encoder drifting
  with temperature): β(t) = r·t + the wrapped decay started from β(0) and β̇(0) − r; with
  the friction as well, the friction's sign follows the rate about the moving centre.

Fit (:func:`fit_decay_models`): for every effect set (a tuple of effect names; ``()`` is
the baseline) and every trial, the model is fitted to the samples of the window that
:func:`pamid._decays._analysis.fit_decay_trajectories` uses (first to last usable extremum).
The parameter vector has one fixed layout, ``FIT_NAMES`` = (ζ, ω_n, β(0), β̇(0), β_eq, u_c,
r); a 0/1 mask switches the effects' constants on. All lanes, (effect set × trial × (the
full window and each cross-validation fold)), are solved in one vmapped, jit-compiled
Levenberg–Marquardt loop on the normal equations, in which the masked rows and columns of
JᵀJ are replaced by the identity and the masked gradient entries by zero, so that the
masked constants stay exactly 0. Every lane starts from the baseline trajectory fit.

Cross-validation: the window is cut into ``BLOCKS_PER_FOLD·n_folds`` contiguous blocks of
(nearly) equal numbers of samples, assigned to the folds round-robin (or, with a ``key``, by a
random permutation of that assignment), so that every fold is spread over the whole decay;
fold f is fitted with weight 0 on its own blocks, and its prediction error is taken on
them. Every sample is held out once: cv_rmse = √(mean over the window of the held-out
squared errors).

Intervals: Wald, θ̂ ± t_{0.975, n−p}·se, se² = s²·diag((JᵀJ)⁻¹) over the unmasked
parameters, s² = SSE/(n − p), as :func:`fit_decay_trajectories` reports them; T_c = u_c·k
with k = J·ω_n² and its interval by the delta method (J taken as exact). Measured on
virtual decays (Cullinan's arm: ζ = 0.05, f_n = 2.2 Hz, releases from 9°, 6° and −8°, a
12-bit encoder, noise of half a step, 500 Hz for 3 s; 15 seeds, one batched call): the
T_c interval covered the hidden 0.1 N·m in 41 of 45 trials and 0 in 43 of 45 trials
without friction; the drift interval covered a hidden 2 mrad/s in 14 of 15 trials and 0
in 42 of 45 trials without drift or friction, but 0 in only 35 of 45 trials with the
(unmodelled) friction: an interval is only as good as the model it comes from.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import jax
import jax.numpy as jnp
import numpy as np

from .._effects._definitions import DECAY_EFFECT_DEFINITIONS
from .._fit._least_squares import least_squares
from .._fit._spec import ModelSpec, scaled
from .._inference import covariance, wald_interval
from .._lanes._batch import FitData
from .._solvers import ProjectedLevenbergMarquardt
from ._analysis import FIT_NAMES as TRAJECTORY_NAMES
from ._analysis import (
    TRAJECTORY,
    DecrementEstimate,
    Extrema,
    TrajectoryFit,
    _plain,
    fit_decay_trajectories,
)

__all__ = [
    "DECAY_EFFECTS",
    "FIT_NAMES",
    "DecayModelFit",
    "DecayTrialModelFit",
    "coulomb_response",
    "fit_decay_models",
    "fold_labels",
]

#: Candidate effects of :func:`fit_decay_models` and the constant each one adds, from the
#: registry of effects (:data:`pamid._effects._definitions.DECAY_EFFECT_DEFINITIONS`).
DECAY_EFFECTS = {e.name: e.fit_name for e in DECAY_EFFECT_DEFINITIONS}
#: The fixed parameter layout of every lane (the last two are the effects' constants).
FIT_NAMES = (*TRAJECTORY_NAMES, *(e.fit_name for e in DECAY_EFFECT_DEFINITIONS))
N_BASE = len(TRAJECTORY_NAMES)
#: Contiguous blocks per fold in the cross-validation (20 blocks for 5 folds).
BLOCKS_PER_FOLD = 4
LEVEL = 0.95
#: Absolute convergence floor of the fit, rad per sample (far below any encoder step).
ATOL_RAD = 1e-12


# --------------------------------------------------------------------------------------
# The decay model: the oscillator wrapped in every candidate effect
# --------------------------------------------------------------------------------------


@functools.cache
def decay_model(n_half: int) -> ModelSpec:
    """The linear oscillator (:class:`~pamid._decays._analysis.Trajectory`) wrapped in every
    effect of :data:`~pamid._effects._definitions.DECAY_EFFECT_DEFINITIONS`, in its order
    (the Coulomb friction over ``n_half`` half cycles, then the drift): ``theta`` =
    :data:`FIT_NAMES`, ``x`` = (time since the window's start, s,). One object per
    ``n_half``, so that its compiled programs are reused."""
    model = TRAJECTORY.base
    for e in DECAY_EFFECT_DEFINITIONS:
        fields = {"n_half": n_half} if "n_half" in e.model.__dataclass_fields__ else {}
        model = e.model.wrap(model, **fields)
    return replace(model, name="decay_with_effects",
                   source="the linear decay with Coulomb friction and a drifting equilibrium")


@functools.partial(jax.jit, static_argnames=("max_half_cycles",))
def coulomb_response(
    zeta,
    omega_n_rad_s,
    angle0_rad,
    rate0_rad_s,
    equilibrium_rad,
    coulomb_shift_rad,
    t_s,
    *,
    drift_rad_s=0.0,
    max_half_cycles=64,
):
    """Exact angle of J·β̈ + c·β̇ + k·(β − β_eq(t)) + T_c·sign(β̇) = 0 at times ``t_s`` ≥ 0:
    :func:`decay_model` at these constants.

    Args:
        zeta, omega_n_rad_s: ζ and ω_n of the viscous oscillator (Cullinan eq. 11).
        angle0_rad, rate0_rad_s: the angle and rate at t = 0.
        equilibrium_rad: β_eq at t = 0.
        coulomb_shift_rad: u_c = T_c/k, the friction torque as an angle (≥ 0 is physical;
            negative values are the analytic continuation, module docstring).
        t_s: sample times (any shape), ≥ 0.
        drift_rad_s: r of the drifting equilibrium β_eq(t) = β_eq + r·t.
        max_half_cycles: half cycles computed (static). Times after the end of the last one
            are NaN (unless the arm stuck before), so ask for more than 2·f_d·t_max + 2.

    Pure and exact (module docstring): jit-, vmap- and grad-able in every parameter; at
    u_c = 0 it is the linear oscillator's closed form. Scalars per call: use ``jax.vmap``
    for batches of parameters.
    """
    values = (zeta, omega_n_rad_s, angle0_rad, rate0_rad_s, equilibrium_rad, coulomb_shift_rad)
    theta = jnp.stack([jnp.asarray(x, float) for x in (*values, drift_rad_s)])
    t = jnp.asarray(t_s, float)
    return decay_model(max_half_cycles).predict(theta, (t.ravel(),)).reshape(t.shape)


# --------------------------------------------------------------------------------------
# The masked, batched Levenberg–Marquardt solve
# --------------------------------------------------------------------------------------


@functools.cache
def _friction_model(n_half: int) -> ModelSpec:
    """:func:`decay_model` in constants divided by each lane's scale
    (:func:`~pamid._fit._spec.scaled`)."""
    return scaled(decay_model(n_half))


def _fit_lanes(p0, scale, mask, t, y, w, n_half, max_steps, rtol):
    """Every lane through pamid's one least-squares entry, by its own Levenberg–Marquardt
    with the effects not in a lane's set held (``mask``).

    Stops when the Gauss–Newton step would lower the SSE by less than ``rtol`` of itself
    plus (:data:`ATOL_RAD`)² per sample (the second term for data the model fits exactly):
    then ``converged``. Returns the scaled optimum, the residuals model − y at every sample
    (also where w = 0: the held-out predictions), the weighted Jacobian there, the
    convergence flag and the number of steps.
    """
    data = FitData(x=(t, scale), y=y, w=w, curve=np.zeros(np.shape(t), np.int32))
    sol = least_squares(_friction_model(n_half), data,
                        solver=ProjectedLevenbergMarquardt(rtol=rtol,
                                                           floor_per_sample=ATOL_RAD**2),
                        theta0=p0, mask=mask, max_steps=max_steps,
                        outputs=("jacobian", "prediction"))
    return sol.params, sol.prediction - np.asarray(y), sol.jac, sol.converged, sol.steps


# --------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DecayTrialModelFit:
    """One trial fitted with one effect set.

    Attributes:
        params: ζ, ω_n (rad/s), the angle and rate at the window start ``t0_s``, β_eq (the
            centre at ``t0_s``), ``coulomb_shift_rad`` u_c, ``coulomb_Nm`` T_c = u_c·J·ω_n²
            and ``drift_rad_s`` r; the constants of effects not in the set are 0.
        params_ci95: 95 % Wald intervals of the fitted parameters (and of ``coulomb_Nm``
            when friction is fitted); effects not in the set have none.
        sse, n, n_params: Σ residual², the window's samples and the parameters fitted.
        rmse_rad: √(sse/n).
        cv_rmse_rad: √(mean held-out squared prediction error), every sample held out once.
        converged: the full-window fit converged; ``cv_converged``: every fold's did.
        n_steps: Levenberg–Marquardt steps of the full-window fit.
        time_s, residual_rad: the window's sample times (the file's clock) and the residual
            angle − model at each.
    """

    params: dict
    params_ci95: dict
    sse: float
    n: int
    n_params: int
    rmse_rad: float
    cv_rmse_rad: float
    converged: bool
    cv_converged: bool
    n_steps: int
    t0_s: float
    time_s: np.ndarray
    residual_rad: np.ndarray

    def to_dict(self) -> dict:
        """Plain JSON-ready numbers (the residual array left out)."""
        return _plain(
            {
                "params": self.params,
                "params_ci95": self.params_ci95,
                "sse": self.sse,
                "n": self.n,
                "n_params": self.n_params,
                "rmse_rad": self.rmse_rad,
                "cv_rmse_rad": self.cv_rmse_rad,
                "converged": self.converged,
                "cv_converged": self.cv_converged,
                "n_steps": self.n_steps,
                "window_s": [float(self.time_s[0]), float(self.time_s[-1])],
            }
        )


@dataclass(frozen=True)
class DecayModelFit:
    """Every trial fitted with one effect set (``effects``, ``()`` for the baseline)."""

    effects: tuple[str, ...]
    trials: list[DecayTrialModelFit]

    @property
    def sse(self) -> np.ndarray:
        return np.array([f.sse for f in self.trials])

    @property
    def n(self) -> np.ndarray:
        return np.array([f.n for f in self.trials])

    @property
    def n_params(self) -> np.ndarray:
        return np.array([f.n_params for f in self.trials])

    @property
    def cv_rmse_rad(self) -> np.ndarray:
        return np.array([f.cv_rmse_rad for f in self.trials])

    def to_dict(self) -> dict:
        return {"effects": list(self.effects), "trials": [f.to_dict() for f in self.trials]}


# --------------------------------------------------------------------------------------
# fit_decay_models
# --------------------------------------------------------------------------------------


def _check_effects(effect_sets) -> list[tuple[str, ...]]:
    effect_sets = list(effect_sets)
    for s in effect_sets:
        if isinstance(s, str):
            raise ValueError(
                f"each effect set is a tuple of effect names, e.g. ({s!r},); "
                f"got the bare name {s!r}"
            )
    sets = [tuple(s) for s in effect_sets]
    if not sets:
        raise ValueError("effect_sets must name at least one effect set (() is the baseline)")
    for s in sets:
        for name in s:
            if isinstance(name, str) and name.startswith("covariate:"):
                raise ValueError(
                    f"effect {name!r}: covariates are not available for decays; "
                    f"accepted effects: {', '.join(DECAY_EFFECTS)}"
                )
            if name not in DECAY_EFFECTS:
                raise ValueError(
                    f"unknown decay effect {name!r}; accepted effects: {', '.join(DECAY_EFFECTS)}"
                )
        if len(set(s)) != len(s):
            raise ValueError(f"effect set {s!r} names an effect twice")
    return sets


def fold_labels(n: int, n_folds: int, key: jax.Array | None = None) -> np.ndarray:
    """Fold of each of ``n`` samples: ``BLOCKS_PER_FOLD·n_folds`` contiguous blocks of nearly
    equal size, assigned to the folds round-robin (or by a permutation of that drawn with
    the JAX PRNG ``key``)."""
    n_blocks = BLOCKS_PER_FOLD * n_folds
    if n < n_blocks:
        raise ValueError(
            f"a window of {n} samples is too short for {n_folds} folds ({n_blocks} blocks)"
        )
    labels = np.arange(n_blocks) % n_folds
    if key is not None:
        labels = np.asarray(jax.random.permutation(key, labels))
    block = np.arange(n) * n_blocks // n
    return labels[block]


def _half_cycle_budget(window_s: float, omega: float, zeta: float) -> int:
    """Half cycles to compute: twice the window's, plus a margin, rounded up to 16."""
    f_d = omega * math.sqrt(max(1.0 - zeta**2, 1e-6)) / (2.0 * math.pi)
    need = 2.0 * (2.0 * f_d * window_s) + 4.0
    return 16 * math.ceil(need / 16)


def fit_decay_models(
    times: list[np.ndarray],
    angles: list[np.ndarray],
    extrema: list[Extrema],
    starts: list[DecrementEstimate],
    inertia_kg_m2: float,
    effect_sets,
    *,
    n_folds: int = 5,
    key: jax.Array | None = None,
    baseline: list[TrajectoryFit] | None = None,
    max_steps: int = 100,
    rtol: float = 1e-10,
) -> list[DecayModelFit]:
    """Fit every trial with every effect set, cross-validated, in one batched solve.

    Args:
        times, angles, extrema, starts: per trial, as for
            :func:`pamid._decays._analysis.fit_decay_trajectories` (which gives the start).
        inertia_kg_m2: J, for T_c = u_c·J·ω_n².
        effect_sets: tuples of names from :data:`DECAY_EFFECTS`; ``()`` is the baseline.
        n_folds: cross-validation folds (≥ 2).
        key: a JAX PRNG key to shuffle the blocks' fold labels (per trial); None: round-robin.
        baseline: the trials' baseline fits, if already made (``fit_decay_trajectories``, or
            ``analyze_decays(...).fits``); None: made here.
        max_steps, rtol: the Levenberg–Marquardt budget and convergence test (``_fit_lanes``).

    Returns:
        One :class:`DecayModelFit` per effect set, in order.
    """
    sets = _check_effects(effect_sets)
    if int(n_folds) < 2:
        raise ValueError(f"n_folds must be at least 2, got {n_folds!r}")
    n_folds = int(n_folds)
    if baseline is None:
        base = fit_decay_trajectories(times, angles, extrema, starts, inertia_kg_m2)
    elif len(baseline) != len(times):
        raise ValueError(f"baseline holds {len(baseline)} fits for {len(times)} trials")
    else:
        base = list(baseline)
    windows, labels, scales, p0s, budgets = [], [], [], [], []
    for i, (t, y, fit) in enumerate(zip(times, angles, base, strict=True)):
        sel = (t >= fit.t0_s) & (t <= fit.t1_s)
        tw, yw = t[sel] - fit.t0_s, y[sel]
        windows.append((tw, yw))
        labels.append(
            fold_labels(len(tw), n_folds, None if key is None else jax.random.fold_in(key, i))
        )
        p = fit.params
        amp = abs(p["angle0_rad"] - p["equilibrium_rad"]) or 1.0
        omega, duration = p["omega_n_rad_s"], max(float(tw[-1]), 1e-9)
        p0s.append([p[name] for name in FIT_NAMES[:N_BASE]] + [0.0, 0.0])
        scales.append(
            [max(abs(p["zeta"]), 1e-3), omega, amp, amp * omega, amp, amp, amp / duration]
        )
        budgets.append(_half_cycle_budget(duration, omega, p["zeta"]))
    n_half = max(budgets)
    n_max = 512 * -(-max(len(w[0]) for w in windows) // 512)

    # Lanes: effect set (outer) × trial × (full window, fold 0, …, fold n_folds − 1).
    n_trials, n_sub = len(windows), n_folds + 1
    lane_p0, lane_scale, lane_mask, lane_t, lane_y, lane_w = [], [], [], [], [], []
    for s in sets:
        mask = np.ones(len(FIT_NAMES))
        for i, name in enumerate(FIT_NAMES[N_BASE:], start=N_BASE):
            mask[i] = float(any(DECAY_EFFECTS[e] == name for e in s))
        for (tw, yw), lab, p0, sc in zip(windows, labels, p0s, scales, strict=True):
            tt, yy = np.full(n_max, tw[-1]), np.zeros(n_max)
            tt[: len(tw)], yy[: len(yw)] = tw, yw
            for fold in range(-1, n_folds):
                ww = np.zeros(n_max)
                ww[: len(tw)] = 1.0 if fold < 0 else (lab != fold)
                lane_p0.append(np.asarray(p0) / np.asarray(sc))
                lane_scale.append(sc)
                lane_mask.append(mask)
                lane_t.append(tt)
                lane_y.append(yy)
                lane_w.append(ww)
    p, r, jw, ok, steps = _fit_lanes(
        *(np.asarray(a, float) for a in (lane_p0, lane_scale, lane_mask, lane_t, lane_y,
                                         lane_w)),
        n_half,
        int(max_steps),
        float(rtol),
    )
    p, r, jw = np.asarray(p), np.asarray(r), np.asarray(jw)
    ok, steps = np.asarray(ok), np.asarray(steps)
    scale_arr, mask_arr = np.asarray(lane_scale), np.asarray(lane_mask)

    out = []
    for si, s in enumerate(sets):
        trials = []
        for ti, ((tw, yw), lab) in enumerate(zip(windows, labels, strict=True)):
            lane = (si * n_trials + ti) * n_sub
            n = len(tw)
            theta = p[lane] * scale_arr[lane]
            mask = mask_arr[lane] > 0
            res = r[lane, :n]
            sse = float(np.sum(res**2))
            held = np.zeros(n)
            for fold in range(n_folds):
                on = lab == fold
                held[on] = r[lane + 1 + fold, :n][on]
            n_par = int(mask.sum())
            params, cis = _params_and_intervals(
                theta, jw[lane], scale_arr[lane], mask, sse, n, inertia_kg_m2
            )
            trials.append(
                DecayTrialModelFit(
                    params=params,
                    params_ci95=cis,
                    sse=sse,
                    n=n,
                    n_params=n_par,
                    rmse_rad=math.sqrt(sse / n),
                    cv_rmse_rad=math.sqrt(float(np.mean(held**2))),
                    converged=bool(ok[lane]),
                    cv_converged=bool(ok[lane + 1 : lane + n_sub].all()),
                    n_steps=int(steps[lane]),
                    t0_s=float(base[ti].t0_s),
                    time_s=tw + base[ti].t0_s,
                    residual_rad=-res,
                )
            )
        out.append(DecayModelFit(effects=s, trials=trials))
    return out


def _params_and_intervals(theta, jw, scale, mask, sse, n, inertia):
    """Parameters with T_c, and Wald intervals of the unmasked ones (module docstring)."""
    n_par = int(mask.sum())
    dof = n - n_par
    cov_scaled, _ = covariance(np.asarray(jw)[:, mask], sse, dof)  # NaN where undetermined
    cov = np.zeros((len(theta), len(theta)))
    cov[np.ix_(mask, mask)] = cov_scaled * np.outer(scale[mask], scale[mask])
    params = dict(zip(FIT_NAMES, (float(v) for v in theta), strict=True))
    omega, shift = params["omega_n_rad_s"], params["coulomb_shift_rad"]
    params["coulomb_Nm"] = shift * inertia * omega**2
    cis = {}
    for i, name in enumerate(FIT_NAMES):
        if mask[i]:
            se = math.sqrt(max(cov[i, i], 0.0))
            cis[name] = [float(b) for b in wald_interval(params[name], se, dof, LEVEL)]
    if mask[FIT_NAMES.index("coulomb_shift_rad")]:
        i, j = FIT_NAMES.index("omega_n_rad_s"), FIT_NAMES.index("coulomb_shift_rad")
        g = np.array([2.0 * inertia * omega * shift, inertia * omega**2])
        se = math.sqrt(max(float(g @ cov[np.ix_([i, j], [i, j])] @ g), 0.0))
        cis["coulomb_Nm"] = [float(b) for b in
                             wald_interval(params["coulomb_Nm"], se, dof, LEVEL)]
    return params, cis
