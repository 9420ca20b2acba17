"""The temperature effects: ``temperature`` (additive, N/K) and its other form
``temperature_relative`` (the force scaled per kelvin); their definitions and injectors."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from .._units import KPA_PER_BAR
from ._base import Constant, EffectDefinition
from ._inject import Injected, _check_form
from ._wrappers import FeatureEffect


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class Temperature(FeatureEffect):
    """A force law with a force that changes with the temperature: F_base + (τ0 + τ1·p)·
    (T − T̄), T̄ the file's mean temperature (:func:`temperature`)."""

    constants: ClassVar[tuple[Constant, ...]] = (Constant("tau0", "N/K"),
                                                 Constant("tau1", "N/(bar·K)"))

    @staticmethod
    def features(muscle, col, grid_value, effect=None):
        dt = col("temperature_C") - muscle.file.temperature_mean_C
        return [dt, dt * muscle.p_bar]


def temperature() -> EffectDefinition:
    """Force changing with the muscle's temperature: (τ0 + τ1·p)·(T − T̄).

    Physical reason: the bladder's rubber stiffens or softens with temperature (entropy
    elasticity, Treloar, The Physics of Rubber Elasticity, 1975, ch. 2), changing the force
    at a given pressure and length. No sign is imposed: both occur. This additive form
    also holds a load cell's thermal zero shift (N per kelvin, any strain-gauge datasheet);
    a modulus that changes with temperature scales the force instead:
    ``temperature_relative``, its other form. Injector:
    :class:`pamid._effects._temperature.InjectedTemperature`.
    """
    return EffectDefinition(
        name="temperature", covariates=("temperature_C",), constants=Temperature.constants,
        injector="pamid._effects._temperature.InjectedTemperature", model=Temperature)


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class RelativeTemperature(FeatureEffect):
    """A force law whose force is scaled with the temperature: F_base + F_model·(α0 + α1·p)·
    (T − T0), F_model the baseline fit and T0 chosen over a grid
    (:func:`temperature_relative`)."""

    constants: ClassVar[tuple[Constant, ...]] = (
        Constant("alpha1", "1/(bar·K)",
                 meaning="change per bar of the force's relative change per kelvin"),
        Constant("alpha0", "1/K", meaning="relative change of the force per kelvin"))

    @staticmethod
    def features(muscle, col, grid_value, effect=None):
        dt = col("temperature_C") - grid_value
        return [muscle.baseline_N * dt * muscle.p_bar, muscle.baseline_N * dt]


#: Reference temperatures T0 of ``temperature_relative``, as shares of the file's range of
#: temperature w from its mean: T̄ + w·(−2 … 2) in 64 steps (a step of w/16).
RELATIVE_T0_SHARES = np.linspace(-2.0, 2.0, 65)
ABSOLUTE_ZERO_C = -273.15


def _relative_temperature_t0(file, muscle):
    lo, hi = file.ranges["temperature_C"]
    t0 = file.temperature_mean_C + max(hi - lo, 1.0) * RELATIVE_T0_SHARES
    return t0[t0 > ABSOLUTE_ZERO_C]


def _relative_temperature_check(values, file, muscle):
    """The force's factor 1 + (α0 + α1·p)·(T − T0) must stay positive over the file's
    pressures and temperatures: a muscle whose force vanished or reversed with temperature
    alone would not be a muscle (the factor is linear in p and in T: its corners decide)."""
    (p_lo, p_hi), (t_lo, t_hi) = file.ranges["pressure_kPa"], file.ranges["temperature_C"]
    t0 = values.get("T0_C", file.temperature_mean_C)
    for p in (p_lo / KPA_PER_BAR, p_hi / KPA_PER_BAR):
        for t in (t_lo, t_hi):
            factor = 1.0 + (values["alpha0"] + values["alpha1"] * p) * (t - t0)
            if factor <= 0:
                return (f"temperature_relative would need the force scaled by "
                        f"1 + (α0 + α1·p)·(T − T0) = {factor:.3g} ≤ 0 at p = {p:.3g} bar, "
                        f"T = {t:.4g} °C (T0 = {t0:.4g} °C: a force that vanishes or "
                        "reverses with temperature): not physical")
    return None


def temperature_relative() -> EffectDefinition:
    """The force scaled by the muscle's temperature: F = F_model·(1 + (α0 + α1·p)·(T − T0)),
    α0 + α1·p the relative change of the force per kelvin (1/K; p in bar), T0 the
    temperature at which the force law F_model holds.

    Physical reason: the bladder's rubber changes its modulus with temperature — for an
    ideal network the shear modulus is G = N·k·T (entropy elasticity; Treloar, The Physics
    of Rubber Elasticity, 3rd ed. 1975, ch. 2 and 4), a relative change of 1/T ≈ +0.34 %
    per kelvin at 20 °C; filled rubbers soften as they warm instead. A modulus that changes
    scales the force the rubber carries by a share of itself per kelvin, not by a fixed
    number of newtons, and the muscle's stiffness ∂F/∂κ by the same share. The share may
    depend on the pressure (the rubber's part of the force is a different share of it at
    each pressure): α1. No sign is imposed; the factor must stay positive over the file
    (:func:`_relative_temperature_check`). F_model is the baseline fit.

    T0 matters where α1 ≠ 0: at the file's mean temperature T̄ the force is then
    F_model·(1 + α1·p·(T̄ − T0)), a pressure-dependent share that no law fitted at T̄ holds
    (left to itself, the compliance and the sensor offset stand in for it). T0 is chosen
    per muscle over a grid (:data:`RELATIVE_T0_SHARES` of the file's range of temperature
    around T̄, above absolute zero) as the module text describes, by the pressure's term
    (listed first for that reason); α0·(T̄ − T0) only rescales F_model. This is the other
    form of ``temperature`` (additive, N/K): the two are never selected together.
    Injector: :class:`pamid._effects._temperature.InjectedRelativeTemperature`.
    """
    return EffectDefinition(
        name="temperature_relative", covariates=("temperature_C",),
        constants=RelativeTemperature.constants,
        injector="pamid._effects._temperature.InjectedRelativeTemperature",
        model=RelativeTemperature,
        grid=Constant("T0_C", "°C", lower=ABSOLUTE_ZERO_C,
                      meaning="the temperature at which the force law holds"),
        grid_values=_relative_temperature_t0,
        check=_relative_temperature_check, form_of="temperature")


@dataclasses.dataclass(frozen=True)
class InjectedTemperature(Injected):
    """Force changing with the muscle's temperature, and the thermometer column that shows it.

    The bladder softens as it warms, so the force at a given pressure and contraction changes
    by ``(N_per_K + N_per_bar_K·p)·(T − T_ref)`` (``linear``) or by that slope times
    ``(T − T_ref)·|T − T_ref| / 10 K`` (``quadratic``). Each sweep is run at its own
    temperature, drawn uniformly in ``range_C`` (a climate chamber, or a muscle warmed by
    earlier cycling), and the temperature creeps by ``ramp_K`` over the sweep; the file gets
    a ``temperature_C`` column rounded to ``resolution_C``.
    """

    N_per_K: float = -0.5
    N_per_bar_K: float = -0.3
    range_C: tuple[float, float] = (20.0, 45.0)
    ramp_K: float = 1.0
    reference_C: float = 25.0
    resolution_C: float = 0.1
    form: str = "linear"

    def __post_init__(self):
        _check_form(self.form, ("linear", "quadratic"), "temperature")

    def columns(self, ctx):
        return {"temperature_C": _thermometer(ctx, self.range_C, self.ramp_K,
                                              self.resolution_C)}

    def force_N(self, ctx):
        dt = ctx["temperature_C"] - self.reference_C
        if self.form == "quadratic":
            dt = dt * np.abs(dt) / 10.0
        return (self.N_per_K + self.N_per_bar_K * ctx["p_bar"]) * dt


def _thermometer(ctx, range_C, ramp_K, resolution_C):
    """The muscle's temperature at each sample (°C): each sweep (or trial) at its own level,
    drawn uniformly in ``range_C``, creeping by ``ramp_K`` over it, rounded to
    ``resolution_C``."""
    lo, hi = range_C
    level = ctx["rng"].uniform(lo, hi, size=ctx["sweep"].shape[:-1] + (1,))
    t = level + ramp_K * ctx["point_fraction"]
    if resolution_C > 0:
        t = np.round(t / resolution_C) * resolution_C
    return t


@dataclasses.dataclass(frozen=True)
class InjectedRelativeTemperature(Injected):
    """The force scaled by the muscle's temperature, and the thermometer column that shows it.

    The bladder's rubber changes its modulus with temperature (entropy elasticity: the shear
    modulus of an ideal network is G = N·k·T, Treloar, The Physics of Rubber Elasticity,
    3rd ed. 1975, ch. 2 and 4; filled rubbers soften as they warm instead), so the force at
    a given pressure and contraction changes by a share of itself per kelvin, not by a
    fixed number of newtons:

        F = F_static·(1 + (per_K + per_bar_K·p)·(T − T_ref)),

    the relative change of the force per kelvin ``per_K + per_bar_K·p`` (1/K; p in bar),
    negative where the muscle softens as it warms. The muscle's stiffness ∂F/∂κ changes by
    the same share. ``F_static`` is the bench's force before its ``effects`` (``force_N`` of
    the context). Temperatures as :class:`InjectedTemperature`'s: each sweep (or trial) at
    its own level in ``range_C``, creeping by ``ramp_K``, logged as ``temperature_C`` rounded
    to ``resolution_C``.
    """

    per_K: float = -0.004
    per_bar_K: float = 0.0
    range_C: tuple[float, float] = (20.0, 45.0)
    ramp_K: float = 1.0
    reference_C: float = 25.0
    resolution_C: float = 0.1

    def columns(self, ctx):
        return {"temperature_C": _thermometer(ctx, self.range_C, self.ramp_K,
                                              self.resolution_C)}

    def force_N(self, ctx):
        dt = ctx["temperature_C"] - self.reference_C
        return ctx["force_N"] * (self.per_K + self.per_bar_K * ctx["p_bar"]) * dt
