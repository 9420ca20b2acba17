"""Muscle damping G fitted through the joint simulator to free decays (valves shut).

Source: M. F. Cullinan, C. McGinn, K. Kelly, "Sleeve Pneumatic Artificial Muscles for
Antagonistically Actuated Joints", eq. 3–5 (the damper term −G·ẏ of each muscle) and
section VI (free decays of the arm). The linear-oscillator fit of :mod:`pamid._decays._analysis`
reports a joint damping c (N·m·s/rad); this module fits the constant of eq. 3
itself, G (N·s/mm, the same for both muscles), by least squares on the recorded angle
THROUGH :func:`pamid.simulate_joint_arm`'s model: the sealed muscles' pressures follow
their volumes, the arm swings under gravity, RK4 at the record's sample interval.

Model of trial i, sampled at the record's times t_k (uniform, starting at t_0):

    angle_k = β(t_k − t_0; G, β0_i, β̇0_i [, s]) [+ δ_i]

with β the simulated joint angle released from (β0_i, β̇0_i) at t_0, and optionally

* ``"pressure_scale"`` s: both sealed gauge pressures multiplied by s (the joint's
  stiffness scales with them; a stiffness-scale correction when the recorded frequency
  differs from the model's), and
* ``"angle_offset"`` δ_i: a constant added to the simulated angle (encoder zero or
  equilibrium offset).

Every trial is fitted on its own (its own G as well), all trials in one vmapped, jit-
compiled optimistix Gauss–Newton (or Levenberg–Marquardt) solve in float64, the
parameters scaled to order one. Intervals are Wald, θ̂ ± t_{0.975, n−p}·se with
se² = s²·diag((JᵀJ)⁻¹) and s² = SSE/(n − p) (:func:`pamid._inference.wald_interval`).
The pooled G is the inverse-variance weighted mean of the converged trials' G (fixed
effect), its interval Student-t with the summed residual dof.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._fit._least_squares import least_squares
from .._fit._spec import ModelSpec, scaled
from .._inference import standard_errors, wald_interval
from .._lanes._batch import FitData
from .._sim._joint_sim import JointArm, arm_rhs, sealed_pressure_laws
from .._sim._oscillator import rk4_scan
from .._solvers import ProjectedLevenbergMarquardt

__all__ = ["JOINT_FIT_NAMES", "JointDecayFit", "fit_joint_decays"]

#: Parameters :func:`fit_joint_decays` can fit, with their units.
JOINT_FIT_NAMES = {
    "G": "N·s/mm",
    "beta0": "rad",
    "beta_dot0": "rad/s",
    "pressure_scale": "1",
    "angle_offset": "rad",
}
_REQUIRED = ("G", "beta0", "beta_dot0")
#: Starting damping of pamid's one least-squares loop for each ``method``: Gauss–Newton
#: steps (the damping rises only after a step that does not lower the SSE), or
#: Levenberg–Marquardt's usual start.
_DAMPING0 = {"gauss_newton": 1e-12, "levenberg_marquardt": 1e-3}


def _with_damping(arm: JointArm, g, pressure_scale):
    return eqx.tree_at(
        lambda a: (a.muscle1.G, a.muscle2.G, a.p1_kPa, a.p2_kPa),
        arm,
        (g, g, arm.p1_kPa * pressure_scale, arm.p2_kPa * pressure_scale),
    )


def _simulate_angle(arm: JointArm, g, beta0, beta_dot0, pressure_scale, dt, n, substeps):
    a = _with_damping(arm, g, pressure_scale)
    ys = rk4_scan(arm_rhs(a, sealed_pressure_laws(a)), jnp.stack([beta0, beta_dot0]), dt, n,
                  substeps)
    return ys[:, 0]


def _unpack(names, p):
    d = dict(zip(names, p, strict=True))
    return (d["G"], d["beta0"], d["beta_dot0"], d.get("pressure_scale", 1.0),
            d.get("angle_offset", 0.0))


@dataclass(frozen=True, eq=False, kw_only=True)
class ArmDecay(ModelSpec):
    """One trial's decay of the arm (module text) as a model: ``theta`` = the constants
    ``names`` (of :data:`JOINT_FIT_NAMES`), ``x`` = (the joint, a :class:`JointArm`,) (the
    trial's n samples, dt apart). The arm is an input, not a field, so that one model (and
    its compiled programs) serves every arm of the same shape."""

    dt: float
    n: int
    substeps: int

    def predict(self, theta, x):
        g, b0, v0, s, off = _unpack(self.param_names, theta)
        return _simulate_angle(x[0], g, b0, v0, s, self.dt, self.n, self.substeps) + off


@functools.cache
def _arm_model(names: tuple[str, ...], dt: float, n: int, substeps: int) -> ModelSpec:
    """:class:`ArmDecay` of these constants and samples, in constants divided by each
    lane's scale (:func:`~pamid._fit._spec.scaled`): one object per arguments."""
    return scaled(ArmDecay(
        dt=dt, n=n, substeps=substeps, name="joint_decay", param_names=names,
        param_units={k: JOINT_FIT_NAMES[k] for k in names}, units={"angle": "rad"},
        columns=("joint",), source="the arm's decay, Cullinan eq. 3–5",
        output=("angle", "rad")))


def _fit_batch(arm, names, method, p0, scale, y, w, dt, n, substeps, rtol, atol, max_steps):
    """Every trial (a lane) through pamid's one least-squares entry, by its own
    Levenberg–Marquardt (damped from the start, or nearly undamped: :data:`_DAMPING0`):
    the constants (unscaled), the weighted residual and its Jacobian (in the scaled
    constants), convergence (with a finite residual) and steps."""
    lanes = np.shape(y)[0]
    joint = jax.tree.map(lambda v: np.broadcast_to(np.asarray(v, float), (lanes, *np.shape(v))),
                         arm)
    data = FitData(x=(joint, scale), y=y, w=w, curve=np.zeros(np.shape(y), np.int32))
    sol = least_squares(_arm_model(tuple(names), float(dt), int(n), int(substeps)), data,
                        solver=ProjectedLevenbergMarquardt(rtol=rtol, floor_per_sample=atol**2,
                                                           damping0=_DAMPING0[method]),
                        theta0=p0, max_steps=max_steps, outputs=("jacobian",))
    ok = sol.converged & np.all(np.isfinite(sol.residual), axis=1)
    return sol.params * scale, sol.residual, sol.jac, ok, sol.steps


@dataclass(frozen=True)
class JointDecayFit:
    """Result of :func:`fit_joint_decays`; arrays have one row per trial.

    * ``names``: the fitted parameters, in the column order of ``values``.
    * ``values``, ``se`` (n_trials, p); ``ci95`` (n_trials, p, 2): Wald, Student-t, n − p dof.
    * ``converged`` (n_trials,): the solver reported success and the residuals are finite.
    * ``n_steps``, ``n_samples``, ``dof`` (n_trials,); ``rmse_rad`` (n_trials,).
    * ``G_pooled``, ``G_pooled_se``, ``G_pooled_ci95``: inverse-variance weighted mean of the
      converged trials' G (N·s/mm) and its 95 % interval (t, summed dof).
    """

    names: tuple[str, ...]
    values: np.ndarray
    se: np.ndarray
    ci95: np.ndarray
    converged: np.ndarray
    n_steps: np.ndarray
    n_samples: np.ndarray
    dof: np.ndarray
    rmse_rad: np.ndarray
    G_pooled: float
    G_pooled_se: float
    G_pooled_ci95: tuple[float, float]

    def column(self, name: str) -> np.ndarray:
        """Values of one parameter over trials."""
        return self.values[:, self.names.index(name)]

    def to_dict(self) -> dict:
        trials = []
        for i in range(self.values.shape[0]):
            trials.append({
                "params": {k: float(self.values[i, j]) for j, k in enumerate(self.names)},
                "params_se": {k: float(self.se[i, j]) for j, k in enumerate(self.names)},
                "params_ci95": {k: [float(self.ci95[i, j, 0]), float(self.ci95[i, j, 1])]
                                for j, k in enumerate(self.names)},
                "converged": bool(self.converged[i]), "n_steps": int(self.n_steps[i]),
                "n_samples": int(self.n_samples[i]), "dof": int(self.dof[i]),
                "rmse_rad": float(self.rmse_rad[i]),
            })
        return {"units": {k: JOINT_FIT_NAMES[k] for k in self.names}, "trials": trials,
                "G_pooled": self.G_pooled, "G_pooled_se": self.G_pooled_se,
                "G_pooled_ci95": list(self.G_pooled_ci95)}


def _per_trial(value, n_trials, name):
    v = np.broadcast_to(np.asarray(value, float), (n_trials,))
    if not np.all(np.isfinite(v)):
        raise ValueError(f"start value of {name!r} must be finite")
    return v


def fit_joint_decays(
    arm: JointArm,
    time_s,
    angle_rad,
    *,
    fit: tuple[str, ...] = ("G", "beta0", "beta_dot0"),
    start: dict | None = None,
    method: str = "gauss_newton",
    substeps: int = 1,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_steps: int = 200,
    level: float = 0.95,
) -> JointDecayFit:
    """Fit Cullinan's G (both muscles) and each trial's release state to free decays.

    Args:
        arm: the joint, arm and seal state (:class:`pamid.JointArm`), unbatched; its
            muscles' G is replaced by the fitted one (and the sealed pressures scaled when
            ``"pressure_scale"`` is fitted).
        time_s: (T,) uniform sample times; the release state is that at ``time_s[0]``.
        angle_rad: (n_trials, T) or (T,) recorded joint angles; non-finite samples get zero
            weight.
        fit: parameters to fit; must contain ``"G"``, ``"beta0"``, ``"beta_dot0"`` and may
            add ``"pressure_scale"`` and ``"angle_offset"`` (:data:`JOINT_FIT_NAMES`).
        start: start values by name, scalar or one per trial. Defaults: G from
            ``arm.muscle1.G`` (0.3 N·s/mm if that is not positive), β0 the first sample, β̇0
            a finite difference over the first 5 samples, scale 1, offset 0.
        method: ``"gauss_newton"`` (default: undamped steps while they lower the SSE) or
            ``"levenberg_marquardt"`` (damped from the start); both are pamid's one loop,
            :func:`pamid._solvers.levenberg_marquardt`.
        substeps: RK4 steps per sample interval.
        rtol, atol, max_steps: stop when a Gauss–Newton step would lower the SSE by at
            most ``rtol`` of itself plus ``atol``² per sample, or after ``max_steps``.
        level: confidence level of the intervals (default 95 %).

    Returns:
        :class:`JointDecayFit`.
    """
    fit = tuple(fit)
    unknown = [k for k in fit if k not in JOINT_FIT_NAMES]
    if unknown or len(set(fit)) != len(fit):
        raise ValueError(f"fit must name distinct parameters of {tuple(JOINT_FIT_NAMES)}, "
                         f"got {fit!r}")
    missing = [k for k in _REQUIRED if k not in fit]
    if missing:
        raise ValueError(f"fit must include {missing!r}")
    if method not in _DAMPING0:
        raise ValueError(f"method must be one of {tuple(_DAMPING0)}, got {method!r}")
    if int(substeps) < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
    start = dict(start or {})
    bad = [k for k in start if k not in fit]
    if bad:
        raise ValueError(f"start names parameters that are not fitted: {bad!r}")
    if any(jnp.ndim(x) for x in jax.tree_util.tree_leaves(arm)):
        raise ValueError("arm must be unbatched (one joint for all trials)")

    t = np.asarray(time_s, float)
    y = np.asarray(angle_rad, float)
    if y.ndim == 1:
        y = y[None]
    if t.ndim != 1 or t.size < 3 or y.ndim != 2 or y.shape[1] != t.size:
        raise ValueError(f"time_s must be (T,) with T >= 3 and angle_rad (n_trials, T); got "
                         f"{t.shape} and {np.shape(angle_rad)}")
    steps = np.diff(t)
    dt = float((t[-1] - t[0]) / (t.size - 1))
    if not (dt > 0 and np.all(np.abs(steps - dt) <= 1e-6 * dt)):
        raise ValueError("time_s must be increasing and uniformly spaced")
    n_trials, n = y.shape
    w = np.isfinite(y).astype(float)
    y0 = np.where(w > 0, y, 0.0)
    n_used = w.sum(axis=1).astype(int)

    g_default = float(arm.muscle1.G)
    g_default = g_default if g_default > 0 else 0.3
    k = min(5, n)
    first = np.array([row[np.isfinite(row)][0] if np.isfinite(row).any() else 0.0
                      for row in y])
    with np.errstate(invalid="ignore"):
        head = np.where(np.isfinite(y[:, :k]), y[:, :k], first[:, None])
        rate = np.polyfit(t[:k] - t[0], head.T, 1)[0]
    defaults = {"G": g_default, "beta0": first, "beta_dot0": np.nan_to_num(rate),
                "pressure_scale": 1.0, "angle_offset": 0.0}
    p0 = np.stack([_per_trial(start.get(k_, defaults[k_]), n_trials, k_) for k_ in fit], -1)

    amp = np.array([np.nanmax(np.abs(row - np.nanmean(row))) if np.isfinite(row).any()
                    else 1.0 for row in y])
    amp = np.maximum(amp, 1e-3)
    typical = {"G": np.maximum(np.abs(p0[:, fit.index("G")]), 1e-2),
               "beta0": np.maximum(np.abs(p0[:, fit.index("beta0")]), amp),
               "beta_dot0": amp * 2.0 * math.pi, "pressure_scale": np.ones(n_trials),
               "angle_offset": amp}
    scale = np.stack([np.broadcast_to(typical[k_], (n_trials,)) for k_ in fit], -1)

    theta, res, jac, ok, n_steps = _fit_batch(
        arm, fit, method, p0 / scale, scale, y0, w, dt, n, int(substeps), float(rtol),
        float(atol), int(max_steps))
    theta, res, jac = np.asarray(theta), np.asarray(res), np.asarray(jac)
    n_par = len(fit)
    dof = n_used - n_par
    sse = np.sum(res**2, axis=1)
    se = standard_errors(jac, sse, dof)[0] * scale  # NaN where a trial's J is rank-deficient
    ci = np.stack(wald_interval(theta, se, np.asarray(dof)[:, None], level), -1)
    converged = np.asarray(ok, bool)

    j = fit.index("G")
    g, g_se = theta[:, j], se[:, j]
    use = converged & np.isfinite(g) & np.isfinite(g_se) & (g_se > 0)
    if use.any():
        wt = 1.0 / g_se[use] ** 2
        pooled = float(np.sum(wt * g[use]) / np.sum(wt))
        pooled_se = float(1.0 / math.sqrt(np.sum(wt)))
        pooled_ci = tuple(float(b) for b in
                          wald_interval(pooled, pooled_se, int(np.sum(dof[use])), level))
    else:
        pooled, pooled_se, pooled_ci = math.nan, math.nan, (math.nan, math.nan)

    return JointDecayFit(
        names=fit, values=theta, se=se, ci95=ci, converged=converged,
        n_steps=np.asarray(n_steps, int), n_samples=n_used, dof=dof,
        rmse_rad=np.sqrt(sse / np.maximum(n_used, 1)), G_pooled=pooled,
        G_pooled_se=pooled_se, G_pooled_ci95=pooled_ci,
    )
