"""The ``transient`` effect: the force relaxing after every step of the moving input; its
definition (its injectors are fields of the virtual protocols)."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ._base import Constant, EffectDefinition
from ._wrappers import FeatureEffect

#: Time constants of the ``transient`` grid, as multiples of the median sample interval.
TRANSIENT_GRID = 2.0 ** (np.arange(-4.0, 13.0) / 2.0)


def _relaxation(steps, time_s, trial, tau):
    """Σ_k Δp_k·exp(−(t − t_k)/τ) over the earlier steps of the sample's trial: the
    first-order relaxation of every step. A step seen first at sample n happened somewhere
    between samples n − 1 and n; it is placed halfway (the recursion
    y_n = e^(−Δt_n/τ)·y_(n−1) + Δp_n·e^(−Δt_n/(2τ)))."""
    out = np.zeros(len(steps))
    dt = np.maximum(np.diff(time_s, prepend=time_s[:1]), 0.0)
    decay = np.exp(-dt / tau)
    kick = steps * np.exp(-0.5 * dt / tau)
    new_trial = np.r_[True, trial[1:] != trial[:-1]]
    y = 0.0
    for i, (step, a, new) in enumerate(zip(kick.tolist(), decay.tolist(),
                                           new_trial.tolist(), strict=True)):
        y = (0.0 if new else a * y) + step
        out[i] = y
    return out


def _transient_grid(file, muscle):
    if muscle.time_s is None or not np.any(muscle.steps):
        return np.array([1.0])
    dt = np.diff(muscle.time_s)
    dt = dt[dt > 0]
    return float(np.median(dt)) * TRANSIENT_GRID if len(dt) else np.array([1.0])


def _transient_check(values, file, muscle):
    g = values["g"]
    if muscle is None:
        return None
    slope = muscle.step_slope
    if slope is None:
        slope = muscle.max_dF_dp_N_per_kPa
    if not np.isfinite(slope) or slope == 0:
        return None
    unit = "N/kPa" if file is None else f"N/{file.step_unit}"
    what = "pressure" if file is None or file.step_input == "pressure" else "rod's step"
    if g * np.sign(slope) <= -abs(slope):
        return (f"transient would need g = {g:.3g} {unit} {'≤' if slope > 0 else '≥'} "
                f"{-slope:.3g} {unit} (a lag of more than the whole step: the force would "
                f"move against the {what}): not physical")
    return None


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class Transient(FeatureEffect):
    """A force law with the force relaxing after every step of the moving input: F_base +
    g·Σ_k Δu_k·e^(−(t − t_k)/τ), τ chosen over a grid (:func:`transient`)."""

    constants: ClassVar[tuple[Constant, ...]] = (
        Constant("g", "N/{step}",
                 meaning="relaxation per unit of step, either sign (see the text)"),)

    @staticmethod
    def features(muscle, col, grid_value, effect=None):
        return [_relaxation(muscle.steps, muscle.time_s, muscle.trial, grid_value)]


def transient() -> EffectDefinition:
    """Force relaxation after each step of the moving input: g·Σ_k Δu_k·e^(−(t − t_k)/τ).

    u is the input that moves in steps: the pressure at a held length (isometric tests:
    valve pulses; g in N/kPa), or, in a file whose every trial is a sweep at held
    pressures (Sárosi's protocol), the contraction that the rod steps point by point (g
    in N/% or N/mm; :func:`rod_steps`). The same first-order relaxation follows either.

    Physical reason: the bladder's rubber is viscoelastic; a step of the pressure first
    loads it with its instantaneous (glassy) modulus, and the force relaxes towards the
    static one with the material's relaxation time — the standard linear solid (Zener,
    Elasticity and Anelasticity of Metals, 1948; for McKibben muscles, the viscoelastic
    sheath model of arXiv:2301.04684, "Viscoelastic McKibben actuators with tunable
    force-velocity curves", 2023); the air's heating by compression relaxes alike: the force
    overshoots in the direction of the step, g > 0. The opposite sign is physical too: where
    the sensor sits upstream of the muscle (at the valve), the muscle's own pressure follows
    the logged one through the tubing with a first-order lag (a pneumatic RC), and the force
    lags, g < 0 — but never by more than the whole step: g ≥ −max ∂F_model/∂p (for the
    rod's steps, where ∂F/∂κ < 0: g ≤ max |∂F_model/∂κ|). τ > 0.
    The AARL 10 mm file
    (``../shared/data/README.md``) shows such a transient at every valve pulse. The
    covariate is the time since the last step of the moving input, within its trial
    (:func:`time_since_step`); τ is chosen over a grid of multiples of the sample interval.
    Injectors: ``IsometricProtocol.transient_N_per_kPa`` / ``transient_tau_s``
    (:mod:`pamid._virtual._isometric`), ``SarosiProtocol.transient_N_per_pct`` /
    ``transient_tau_s`` (:mod:`pamid._virtual._sweeps`).
    """
    return EffectDefinition(
        name="transient", covariates=("time_since_step_s", "elapsed_s"),
        constants=Transient.constants, model=Transient,
        injector=("pamid._virtual._isometric.IsometricProtocol.transient_N_per_kPa",
                  "pamid._virtual._sweeps.SarosiProtocol.transient_N_per_pct"),
        check=_transient_check,
        grid=Constant("tau_s", "s", lower=0.0), grid_values=_transient_grid,
        applies=lambda f: f.step_input is not None,
    )
