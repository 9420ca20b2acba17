"""The candidate effects of a diagnosis, one self-contained definition each.

An :class:`EffectDefinition` says everything the diagnosis needs to know of one effect that
a fitted force law F_model(θ; p, x) (Sárosi eq. 2.1, Cullinan eq. 3, any
:class:`~pamid.ForceModel`) may lack: its name, the covariates it needs, its constants with
units and physical bounds, how it changes the model — feature columns added to the force
(the constants enter linearly) or a transform of the model's inputs (the constants enter
the force law itself) — its physical reason and source (the docstring of its builder), and
the injector of the virtual bench that hides it in data. :data:`STATIC_EFFECT_DEFINITIONS` is the
registry that :class:`pamid._diagnose._static.StaticProblem` reads; adding an effect means
adding one definition there. :data:`DECAY_EFFECT_DEFINITIONS` is the same for free decays
(:mod:`pamid._decays._coulomb`).

A constant chosen over a small grid (a time constant, a softening scale, a reference
temperature) is a
``grid`` constant: it is chosen per muscle, once, where the baseline's residual (with the
base model's Jacobian projected out) is best explained by the effect's column of a
physically allowed sign, and it counts as one more constant in the BIC. The gain that
multiplies the column is then fitted with everything else. A grid is used rather than a
nonlinear fit because the lanes of the batched solve share one parameter layout in which
every effect constant enters linearly. The transient's grid holds 17 time constants a
factor √2 apart, from a quarter of the sample interval to 64 of them; where τ is about
one sample interval, g and τ trade off against each other and their product (the
relaxation's integral per kPa of step) is what the data fix.

An effect whose fitted constants land at or past a physical bound is not reported as
found: :meth:`EffectDefinition.violation` says what it would have needed.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
import pandas as pd

from .._units import KPA_PER_BAR, per_l0
from ._basis import legendre_basis, scaled

__all__ = [
    "DECAY_EFFECT_DEFINITIONS",
    "STATIC_EFFECT_DEFINITIONS",
    "Constant",
    "DecayEffect",
    "Effect",
    "EffectDefinition",
    "moving_steps",
]

COVARIATE_DEGREE = 3
#: A sample-to-sample change of the moving input larger than this many robust standard
#: deviations of such changes is a step (the valve's pulse), not sensor noise.
STEP_SIGMAS = 5.0
#: Time constants of the ``transient`` grid, as multiples of the median sample interval.
TRANSIENT_GRID = 2.0 ** (np.arange(-4.0, 13.0) / 2.0)
#: Scales r (in repeats) of the ``softening`` grid.
SOFTENING_GRID = (0.3, 1.0, 3.0, 10.0)
#: Largest pressure-sensor offset that is still an offset, as a share of the largest
#: logged pressure; beyond it the logged pressure is not the muscle's pressure at all.
MAX_OFFSET_SHARE = 0.1


@dataclasses.dataclass(frozen=True)
class Constant:
    """One constant of an effect: its name, unit (``{x}`` stands for the contraction's unit,
    % or mm) and physical bounds (lower, upper; ±inf where physics sets none)."""

    name: str
    unit: str
    lower: float = -math.inf
    upper: float = math.inf
    meaning: str = ""
    #: ``bounds(file) -> (lower, upper)`` where the bounds depend on the file.
    bounds: Callable | None = None
    #: Held within its bounds by the fit itself, rather than fitted freely and reported as
    #: unphysical past them: a weight of an element that may be absent (a slip element of
    #: the hysteresis), for which 0 is a result, not a violation.
    held: bool = False


@dataclasses.dataclass(frozen=True)
class Effect:
    """An effect as one diagnosis uses it: its definition bound to one file.

    ``columns`` are its columns in the problem's feature matrix (empty for a transform);
    ``transform`` is its place among the transform constants, or None.
    """

    name: str
    covariate: str
    param_names: tuple[str, ...]
    units: tuple[str, ...]
    columns: tuple[int, ...]
    definition: EffectDefinition = dataclasses.field(repr=False, default=None)
    transform: int | None = None
    grid: Constant | None = None

    @property
    def hidden(self) -> int:
        """Constants chosen over a grid rather than fitted: each counts in the BIC."""
        return 0 if self.grid is None else 1


@dataclasses.dataclass
class FileContext:
    """What an effect may read of the file: the model, covariates and their ranges."""

    spec: object
    covariates: list[str]
    ranges: dict[str, tuple[float, float]]
    temperature_mean_C: float
    pressure_median_bar: float
    pressure_max_kPa: float
    unit_x: str
    has_pressure_steps: bool
    max_repeat: int
    distinct: dict[str, int]
    #: Per covariate, the Legendre degrees the base model already contains.
    in_model: dict[str, tuple[int, ...]] = dataclasses.field(default_factory=dict)
    #: The input whose steps the ``transient`` follows: "pressure" where the pressure moves
    #: in steps at a held length (isometric tests), "contraction" where the rod steps the
    #: length at a held pressure in every trial (Sárosi's sweeps), None without time.
    step_input: str | None = None

    @property
    def step_unit(self) -> str:
        """The unit of a step of :attr:`step_input`: kPa, or the contraction's % or mm."""
        return "kPa" if self.step_input == "pressure" else self.unit_x


@dataclasses.dataclass
class MuscleContext:
    """One muscle's rows and what the features of an effect are made from."""

    frame: pd.DataFrame
    baseline_N: np.ndarray  # F_model at the baseline constants
    steps: np.ndarray  # the moving pressure's steps (kPa), 0 between steps
    trial: np.ndarray
    time_s: np.ndarray | None
    file: FileContext
    speed: str | None = None  # the rate-of-contraction column, if any
    l0_mm: float | None = None
    #: The largest ∂F_model/∂p over the muscle's rows (N/kPa), at the baseline constants.
    max_dF_dp_N_per_kPa: float = math.inf
    #: ∂F_model/∂(the stepped input) of the largest magnitude over the muscle's rows, with
    #: its sign (N per kPa, or per % or mm of contraction); None: that of the pressure.
    step_slope: float | None = None
    #: The noise standard deviation of the stepped input at each row (its unit), as the
    #: curve finder estimates it (:attr:`pamid._data._curves.Curves.noise`); None: none.
    step_noise: np.ndarray | None = None
    #: Features that are the same in every fold (the slip elements), computed once.
    memo: dict = dataclasses.field(default_factory=dict, repr=False)

    @property
    def p_bar(self) -> np.ndarray:
        return self.frame["pressure_kPa"].to_numpy(float) / KPA_PER_BAR


@dataclasses.dataclass(frozen=True)
class EffectDefinition:
    """One candidate effect (see the module docstring).

    Attributes:
        name: its name in reports ("hysteresis").
        covariates: columns it needs, all varying in the file (alternatives: the first
            present is used for the covariate it is traced to).
        constants: the fitted constants, in order (for a feature effect, one per column);
            a unit's ``{x}`` is the contraction's unit, ``{step}`` that of the stepped input.
        injector: the virtual bench's injectors that hide it in data (dotted names, one or
            a tuple): an ``Injected*`` class of :mod:`pamid._effects._inject` works in both
            protocols' ``effects``; a protocol field names where that protocol has its own.
            :attr:`injectors` gives them as a tuple.
        features: ``features(muscle, col, grid_value) -> list of columns`` (N per unit of
            each constant); ``col(name)`` reads a covariate (clamped to a fold's range).
        transform: ``transform(x, value, force, io) -> x``: the model's inputs as the
            muscle feels them, for a transform effect (``io`` names the inputs' places).
        implicit: the transform depends on the force (the force law becomes implicit).
        grid: a constant chosen over ``grid_values(file, muscle)`` (see the module).
        applies: ``applies(file) -> bool``, beyond having its covariates.
        check: ``check(values, file, muscle) -> message or None``: a physical condition
            that bounds cannot state (a transient must not lag by more than its whole step).
        family: ``family(file) -> [(name, covariate, constants)]``: for a family of
            effects (``covariate:<col>``), the members in this file.
        form_of: the effect this one is another physical form of (``temperature_relative``,
            a share of the force per kelvin, is one of ``temperature``, newtons per
            kelvin): forms of one effect are never selected together, and where the
            selected form leaves its covariate in the residual the diagnosis tries the
            others (:mod:`pamid._diagnose._forms`). None: a form of itself.
        more: ``more(file) -> constants`` that join :attr:`constants` where the file
            allows them (the hysteresis' slip elements, where the rows have a time order).
        derived: ``derived(file) -> [(name, unit, {constant: weight})]``: linear
            combinations of the constants reported beside them with their intervals (the
            hysteresis loop's half height, which its jump and slip elements share).
    """

    name: str
    covariates: tuple[str, ...]
    constants: tuple[Constant, ...]
    injector: str | tuple[str, ...]
    features: Callable | None = None
    transform: Callable | None = None
    implicit: bool = False
    grid: Constant | None = None
    grid_values: Callable | None = None
    applies: Callable | None = None
    check: Callable | None = None
    family: Callable | None = None
    form_of: str | None = None
    more: Callable | None = None
    derived: Callable | None = None

    @property
    def injectors(self) -> tuple[str, ...]:
        """The dotted names of :attr:`injector`, as a tuple."""
        return (self.injector,) if isinstance(self.injector, str) else tuple(self.injector)

    def members(self, file: FileContext) -> list[tuple[str, str, tuple[Constant, ...]]]:
        """(name, covariate, constants) of every effect of this definition in ``file``."""
        if self.family is not None:
            return self.family(file)
        present = [c for c in self.covariates if c in file.covariates]
        if self.covariates and not present:
            return []
        if self.applies is not None and not self.applies(file):
            return []
        extra = self.more(file) if self.more is not None else ()
        consts = tuple(dataclasses.replace(c, unit=c.unit.format(x=file.unit_x,
                                                                 step=file.step_unit))
                       for c in (*self.constants, *extra))
        return [(self.name, present[0] if present else "force_N", consts)]

    def violation(self, values: dict[str, float], effect: Effect, file: FileContext,
                  muscle: MuscleContext | None = None) -> str | None:
        """None when the fitted ``values`` are physical; else what the effect would need,
        e.g. "compliance would need c = −0.12 mm/N < 0: not physical"."""
        extra = self.more(file) if self.more is not None else ()
        for c, unit in zip((*self.constants, *extra), effect.units, strict=False):
            v = values.get(c.name)
            if v is None or not np.isfinite(v) or c.held:
                continue
            lo, hi = _bounds(c, file)
            u = "" if unit == "1" else f" {unit}"
            if v <= lo and lo > -math.inf:
                return (f"{effect.name} would need {c.name} = {_fmt(v, unit, muscle)} "
                        f"{'<' if v < lo else 'at'} {lo:g}{u}: not physical")
            if v >= hi and hi < math.inf:
                return (f"{effect.name} would need {c.name} = {_fmt(v, unit, muscle)} "
                        f"{'>' if v > hi else 'at'} {hi:g}{u}: not physical")
        if self.check is not None:
            return self.check(values, file, muscle)
        return None


def _bounds(c: Constant, file: FileContext) -> tuple[float, float]:
    return c.bounds(file) if c.bounds is not None else (c.lower, c.upper)


def _offset_bounds(file: FileContext) -> tuple[float, float]:
    b = MAX_OFFSET_SHARE * file.pressure_max_kPa
    return -b, b


def _fmt(v: float, unit: str, muscle: MuscleContext | None) -> str:
    out = f"{v:.3g}" if unit == "1" else f"{v:.3g} {unit}"
    other = per_l0(unit, muscle.l0_mm) if muscle is not None else None
    if other is not None:
        out += f" ({v * other[1]:.3g} {other[0]})"
    return out


# -- the moving input's steps ------------------------------------------------------------------


def moving_steps(pressure_kPa: np.ndarray, moving: np.ndarray, trial: np.ndarray
                 ) -> np.ndarray:
    """The steps of the moving pressure (kPa) at each sample of one muscle, 0 elsewhere.

    A step is a change from the previous sample of the same trial, where the pressure moves
    (``moving == 1``, an isometric test), larger than :data:`STEP_SIGMAS` robust standard
    deviations (1.4826·median absolute deviation) of all such changes: a valve's pulse, not
    the sensor's noise. Without noise every change is a step (a ramp is a train of steps).
    """
    dp = np.diff(pressure_kPa, prepend=pressure_kPa[:1])
    same = np.r_[False, trial[1:] == trial[:-1]] & (moving == 1)
    dp = np.where(same, dp, 0.0)
    if not same.any():
        return dp
    inside = dp[same]
    sigma = 1.4826 * np.median(np.abs(inside - np.median(inside)))
    floor = 1e-9 * (np.max(np.abs(pressure_kPa)) + 1.0)
    return np.where(np.abs(dp) > max(STEP_SIGMAS * sigma, floor), dp, 0.0)


def rod_steps(contraction: np.ndarray, moving: np.ndarray, trial: np.ndarray,
              noise: np.ndarray | float) -> np.ndarray:
    """The steps of the moving contraction (in its unit) at each sample of one muscle, 0
    elsewhere: a change from the previous sample of the same trial, where the contraction
    moves (``moving == 0``, Sárosi's sweeps: the rod steps at every point), larger than
    :data:`STEP_SIGMAS` times the contraction's noise (``noise``: the curve finder's
    estimate, :attr:`pamid._data._curves.Curves.noise`). Every point of a sweep is a step,
    so the robust spread of the changes (:func:`moving_steps`) cannot measure the noise
    here."""
    dk = np.diff(contraction, prepend=contraction[:1])
    same = np.r_[False, trial[1:] == trial[:-1]] & (moving == 0)
    floor = 1e-9 * (np.max(np.abs(contraction)) + 1.0) if len(contraction) else 0.0
    return np.where(same & (np.abs(dk) > np.maximum(STEP_SIGMAS * np.asarray(noise), floor)),
                    dk, 0.0)


def time_since_step(steps: np.ndarray, time_s: np.ndarray, trial: np.ndarray) -> np.ndarray:
    """Time since the last step of the moving input in the same trial (since the trial's
    first sample where none came yet), in s."""
    n = len(steps)
    idx = np.arange(n)
    first = np.r_[True, trial[1:] != trial[:-1]]
    marker = np.where((steps != 0) | first, idx, 0)
    last = np.maximum.accumulate(marker)
    return time_s - time_s[last]


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


# -- the static effects --------------------------------------------------------------------


#: Thresholds of the hysteresis' slip elements, as shares of the range of the moving input
#: over the muscle's rows: an element of share q slides once the input has moved by 2q of
#: its range since the last reversal. 0.4 is the largest that still slides within the range
#: (an element of 0.5 would never slide in a loop over the whole range: a spring, no loop).
SLIP_SHARES = (0.05, 0.1, 0.2, 0.4)
#: The slip elements see the moving input through a play of this many of its noise standard
#: deviations (:data:`pamid._data._curves.NOISE_SIGMAS`: beyond it a change is motion).
SLIP_DEADBAND_SIGMAS = 5.0


def _slip_labels(file: FileContext) -> tuple[str, ...]:
    """The slip elements' labels ("05" for a share of 0.05) where the file has them: rows
    in a time order with a moving input (:attr:`FileContext.step_input`)."""
    if file is None or file.step_input is None:
        return ()
    return tuple(f"{round(100 * q):02d}" for q in SLIP_SHARES)


def _slip_constants(file: FileContext) -> tuple[Constant, ...]:
    out = []
    for k in _slip_labels(file):
        what = f"slip element of threshold {int(k)} % of the moving input's range"
        out += [Constant(f"h0_r{k}", "N", lower=0.0, held=True, meaning=what),
                Constant(f"h1_r{k}", "N/bar", lower=0.0, held=True,
                         meaning=what + ", per bar")]
    return tuple(out)


def slip_features(m: MuscleContext) -> np.ndarray:
    """The normalized deflections ŝ (rows, elements) of the slip elements of
    :data:`SLIP_SHARES` on the muscle's moving input (:mod:`pamid._effects._slip`), each
    trial starting again, the input's jitter within :data:`SLIP_DEADBAND_SIGMAS` of its noise
    taken out first (:func:`~pamid._effects._slip.play_operator`); computed once per muscle
    (the same in every fold)."""
    if "slip" not in m.memo:
        from ._slip import play_operator, stop_operator

        spec = m.file.spec
        name = "pressure_kPa" if m.file.step_input == "pressure" else spec.contraction_column
        u = m.frame[name].to_numpy(float)
        lo, hi = np.quantile(u, [0.005, 0.995]) if len(u) else (0.0, 0.0)
        start = np.r_[True, m.trial[1:] != m.trial[:-1]] if len(u) else np.zeros(0, bool)
        if m.step_noise is not None:
            u = play_operator(u, SLIP_DEADBAND_SIGMAS * m.step_noise, start)
        if hi > lo:
            m.memo["slip"] = stop_operator(u, np.asarray(SLIP_SHARES) * (hi - lo), start)
        else:
            m.memo["slip"] = np.zeros((len(u), len(SLIP_SHARES)))
    return m.memo["slip"]


def _hysteresis_half_height(file: FileContext):
    """The loop's half height at 3 bar once every slip element slides (a loop over the
    input's whole range: the largest threshold is 0.4 of it): h0 + 3·h1 + Σ_i (h0_i +
    3·h1_i) N. The jump and the slip elements may share one loop between them (an element
    whose threshold is half a valve step slides within the step, as the jump does); this
    sum is what the data fix where loops at 3 bar span the range (isometric tests), and an
    extrapolation where they do not (a sweep at 3 bar contracts less than at the top
    pressure), which its interval does not include."""
    weights = {"h0": 1.0, "h1": 3.0}
    for k in _slip_labels(file):
        weights |= {f"h0_r{k}": 1.0, f"h1_r{k}": 3.0}
    return [("half_height_at_3bar", "N", weights)]


def _hysteresis_features(m, col, g):
    d = col("direction")
    out = [-d, -d * m.p_bar]
    if _slip_labels(m.file):
        for s in slip_features(m).T:
            out += [-s, -s * m.p_bar]
    return out


def _hysteresis() -> EffectDefinition:
    """Inflate/deflate or contract/extend hysteresis, with memory where the rows have a time
    order: −d·(h0 + h1·p) − Σ_i (h0_i + h1_i·p)·ŝ_i N.

    Physical reason: dry friction between the braid's fibres and between braid and bladder
    dissipates energy, so the force while contracting lies below the force while extending
    (Sárosi's lower and upper curves F_a and F_f, eq. 2.3–2.4; Chou and Hannaford 1996,
    IEEE Trans. Robot. Autom. 12(1):90–102). The first term is the jump at a reversal (d the
    direction, recorded or derived). The friction of many fibres does not jump all at
    once: each slides only once the input has moved far enough since the last reversal, so
    the loop curves after every reversal and closes minor loops. That is the generalized
    Maxwell-slip model (Al-Bender, Lampaert and Swevers, IEEE Trans. Autom. Control
    50(11):1883–1887, 2005): ŝ_i ∈ [−1, 1] is the normalized stop operator of slip element
    i on the moving input (the pressure in an isometric test, the contraction in a sweep;
    :mod:`pamid._effects._slip`), of threshold :data:`SLIP_SHARES` of the input's range;
    its slip force h0_i + h1_i·p has a part from the braid's pretension and one from the
    pressure's normal force (Tondu and Lopez 2000). Every element dissipates — the jump
    too: a jump the wrong way at a reversal would be a loop run backwards there, which
    gains energy — so h0, h1, h0_i and h1_i are ≥ 0, held so by the fit (an element at 0
    is absent), and no loop the physics forbids is ever fitted, let alone reported.
    Unlike the transient it does not relax at a held input. Injectors:
    :class:`pamid._effects._inject.InjectedHysteresis` (and
    ``IsometricProtocol.hysteresis_N_at_3_bar``),
    :class:`~pamid._effects._inject.InjectedMaxwellSlip`.
    """
    return EffectDefinition(
        name="hysteresis", covariates=("direction",),
        constants=(Constant("h0", "N", lower=0.0, held=True),
                   Constant("h1", "N/bar", lower=0.0, held=True)),
        injector=("pamid._effects._inject.InjectedHysteresis",
                  "pamid._effects._inject.InjectedMaxwellSlip",
                  "pamid._virtual._isometric.IsometricProtocol.hysteresis_N_at_3_bar",
                  "pamid._virtual._sweeps.SarosiProtocol.hysteresis_N_per_bar"),
        features=_hysteresis_features,
        more=_slip_constants,
        derived=_hysteresis_half_height,
    )


def _temperature() -> EffectDefinition:
    """Force changing with the muscle's temperature: (τ0 + τ1·p)·(T − T̄).

    Physical reason: the bladder's rubber stiffens or softens with temperature (entropy
    elasticity, Treloar, The Physics of Rubber Elasticity, 1975, ch. 2), changing the force
    at a given pressure and length. No sign is imposed: both occur. This additive form
    also holds a load cell's thermal zero shift (N per kelvin, any strain-gauge datasheet);
    a modulus that changes with temperature scales the force instead:
    ``temperature_relative``, its other form. Injector:
    :class:`pamid._effects._inject.InjectedTemperature`.
    """
    def features(m, col, g):
        dt = col("temperature_C") - m.file.temperature_mean_C
        return [dt, dt * m.p_bar]

    return EffectDefinition(
        name="temperature", covariates=("temperature_C",),
        constants=(Constant("tau0", "N/K"), Constant("tau1", "N/(bar·K)")),
        injector="pamid._effects._inject.InjectedTemperature", features=features)


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


def _temperature_relative() -> EffectDefinition:
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
    Injector: :class:`pamid._effects._inject.InjectedRelativeTemperature`.
    """
    def features(m, col, t0):
        dt = col("temperature_C") - t0
        return [m.baseline_N * dt * m.p_bar, m.baseline_N * dt]

    return EffectDefinition(
        name="temperature_relative", covariates=("temperature_C",),
        constants=(Constant("alpha1", "1/(bar·K)",
                            meaning="change per bar of the force's relative change per kelvin"),
                   Constant("alpha0", "1/K", meaning="relative change of the force per kelvin")),
        injector="pamid._effects._inject.InjectedRelativeTemperature", features=features,
        grid=Constant("T0_C", "°C", lower=ABSOLUTE_ZERO_C,
                      meaning="the temperature at which the force law holds"),
        grid_values=_relative_temperature_t0,
        check=_relative_temperature_check, form_of="temperature")


def _drift() -> EffectDefinition:
    """Load-cell zero drift: δ1·t + δ2·t², t in hours from the start of the muscle's test.

    Physical reason: a strain-gauge bridge's zero moves as it warms and creeps (any load
    cell's datasheet states a zero drift per hour and per kelvin); it is additive and does
    not depend on the load. Injector: :class:`pamid._effects._inject.InjectedDrift`.
    """
    def features(m, col, g):
        h = col("elapsed_s") / 3600.0
        return [h, h**2]

    return EffectDefinition(
        name="drift", covariates=("elapsed_s",),
        constants=(Constant("delta1", "N/h"), Constant("delta2", "N/h²")),
        injector="pamid._effects._inject.InjectedDrift", features=features)


def _viscous_damping() -> EffectDefinition:
    """A force opposing the rate of contraction: −g·v (Cullinan's −G·ẏ, eq. 3).

    Physical reason: viscous losses in the bladder and the air flow resist motion in
    proportion to speed; dissipation requires g ≥ 0. Injector:
    :class:`pamid._effects._inject.InjectedViscousDamping`.
    """
    return EffectDefinition(
        name="viscous_damping", covariates=("speed_mm_s", "speed_pct_s"),
        constants=(Constant("g", "N·s/{x}", lower=0.0),),
        injector="pamid._effects._inject.InjectedViscousDamping",
        features=lambda m, col, g: [-col(m.speed)],
        applies=lambda f: len(f.spec.columns) < 3,  # Cullinan with G has it already
    )


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


def _transient() -> EffectDefinition:
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
        constants=(Constant("g", "N/{step}",
                            meaning="relaxation per unit of step, either sign (see the text)"),),
        injector=("pamid._virtual._isometric.IsometricProtocol.transient_N_per_kPa",
                  "pamid._virtual._sweeps.SarosiProtocol.transient_N_per_pct"),
        check=_transient_check,
        features=lambda m, col, tau: [_relaxation(m.steps, m.time_s, m.trial, tau)],
        grid=Constant("tau_s", "s", lower=0.0), grid_values=_transient_grid,
        applies=lambda f: f.step_input is not None,
    )


def _softening() -> EffectDefinition:
    """Loss of force from repeat to repeat, saturating: −s·(1 − e^(−repeat/r))·F_model.

    Physical reason: the Mullins effect — a filled rubber loaded again to a strain it has
    seen needs less stress than on its first loading, and the loss saturates over the
    first few cycles (Mullins, Rubber Chem. Technol. 42:339–362, 1969; Diani, Fayolle and
    Gilormini, "A review on the Mullins effect", Eur. Polym. J. 45:601–612, 2009). A loss
    of force: 0 ≤ s < 1; r > 0 (in repeats) is chosen over a grid. F_model is the baseline
    fit. The covariate is the repeat index (:attr:`pamid._data._curves.Curves.repeat`: a
    trial's order among the muscle's trials of the same setting, or the cycle). Injectors:
    ``IsometricProtocol.softening`` / ``softening_repeats`` (:mod:`pamid._virtual._isometric`),
    ``SarosiProtocol.softening`` / ``softening_repeats`` (:mod:`pamid._virtual._sweeps`).
    """
    return EffectDefinition(
        name="softening", covariates=("repeat",),
        constants=(Constant("s", "1", lower=0.0, upper=1.0, meaning="share of force lost"),),
        injector=("pamid._virtual._isometric.IsometricProtocol.softening",
                  "pamid._virtual._sweeps.SarosiProtocol.softening"),
        features=lambda m, col, r: [-(1.0 - np.exp(-m.frame["repeat"].to_numpy(float) / r))
                                    * m.baseline_N],
        grid=Constant("r", "repeats", lower=0.0),
        grid_values=lambda f, m: np.asarray(SOFTENING_GRID),
        applies=lambda f: f.max_repeat >= 1,
    )


def _covariate_family(file: FileContext):
    out = []
    for c in file.covariates:
        if c == "direction":
            continue
        lo, hi = file.ranges[c]
        top = min(COVARIATE_DEGREE, file.distinct[c] - 1)
        degrees = [k for k in range(1, top + 1)
                   if k not in file.in_model.get(c, ())]
        if degrees:
            out.append((f"covariate:{c}", c, tuple(Constant(f"b{k}", "N") for k in degrees)))
    return out


def _covariate_features(m, col, g, effect):
    lo, hi = m.file.ranges[effect.covariate]
    basis = legendre_basis(scaled(col(effect.covariate), lo, hi), COVARIATE_DEGREE)
    return [basis[int(name[1:]) - 1] for name in effect.param_names]


def _covariate() -> EffectDefinition:
    """Any smooth function of a covariate z: b1·P1(z) + b2·P2(z) + b3·P3(z), z scaled to
    [−1, 1] over the file, P_k Legendre polynomials (Abramowitz and Stegun, 22.2.10).

    Not a physical effect: it traces what the library cannot model to its covariate, so
    that an effect outside the library is still named by what it depends on. No bounds.
    Injector: :class:`pamid._effects._inject.InjectedCovariate`.
    """
    return EffectDefinition(
        name="covariate", covariates=(), constants=(),
        injector="pamid._effects._inject.InjectedCovariate",
        features=_covariate_features, family=_covariate_family)


def _compliance_transform(x, c, force, io):
    x = list(x)
    x[io["contraction"]] = x[io["contraction"]] + c * force
    return tuple(x)


def _compliance() -> EffectDefinition:
    """Something in series with the force stretches under load: F solves
    F = F_model(p, x + c·F).

    Physical reason: the load cell, its mounts and any cable stretch under the force, so the
    muscle is shorter than the encoder says by c·F (a spring in series; Sárosi's rig reads
    the rod, not the muscle); so do the muscle's own end fittings and braid, which a static
    law of p and κ alone does not describe. On the AARL 10 mm muscles the fitted c grew with
    the muscle's length (0.0012, 0.0066 and 0.025 mm/N at 83, 132 and 281 mm;
    experiments/README.md §10): there it is the muscle's stretch, not the rig's. A spring
    has c ≥ 0: a negative c would mean a line that shortens under load. Injector:
    :class:`pamid._effects._inject.InjectedCompliance`.
    """
    return EffectDefinition(
        name="compliance", covariates=(), constants=(Constant("c", "{x}/N", lower=0.0),),
        injector="pamid._effects._inject.InjectedCompliance",
        transform=_compliance_transform, implicit=True,
        applies=lambda f: f.spec.contraction_column in f.spec.columns)


def _offset_transform(x, delta_kpa, force, io):
    x = list(x)
    i, per_kpa = io["pressure"]
    x[i] = x[i] + delta_kpa * per_kpa
    return tuple(x)


def _sensor_offset() -> EffectDefinition:
    """An offset of the logged pressure: F = F_model(p_logged + δ, x).

    Physical reason: a pressure transducer's zero is off by manufacturing tolerance,
    mounting stress and temperature (zero-offset error; e.g. Ashcroft, "What causes offset
    in the output of a transducer at zero and span?", blog.ashcroft.com, and any sensor's
    datasheet, which states it in % of full scale); AARL's logger reads 7–9 kPa at ambient
    (``../shared/data/README.md``), i.e. δ ≈ −8 kPa. |δ| must stay below
    :data:`MAX_OFFSET_SHARE` of the largest logged pressure. Identifiable only where the
    force law is not affine in p at every length (Sárosi eq. 2.1: through the a4·κ·p term).
    Injectors: ``IsometricProtocol.pressure_offset_kPa`` (:mod:`pamid._virtual._isometric`),
    ``SarosiProtocol.pressure_offset_kPa`` (:mod:`pamid._virtual._sweeps`).
    """
    return EffectDefinition(
        name="sensor_offset", covariates=(),
        constants=(Constant("delta_kPa", "kPa", bounds=_offset_bounds),),
        injector=("pamid._virtual._isometric.IsometricProtocol.pressure_offset_kPa",
                  "pamid._virtual._sweeps.SarosiProtocol.pressure_offset_kPa"),
        transform=_offset_transform,
        applies=lambda f: "pressure_kPa" in f.spec.columns)


#: Every candidate effect of a static diagnosis, in the order they are listed.
STATIC_EFFECT_DEFINITIONS: tuple[EffectDefinition, ...] = (
    _hysteresis(), _temperature(), _temperature_relative(), _drift(), _viscous_damping(),
    _transient(), _softening(), _covariate(), _compliance(), _sensor_offset(),
)


def transforms() -> tuple[EffectDefinition, ...]:
    """The effects that transform the model's inputs, in the order of their constants in
    the lanes' parameter layout."""
    return tuple(d for d in STATIC_EFFECT_DEFINITIONS if d.transform is not None)


# -- the decay effects -----------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class DecayEffect:
    """A candidate effect of a free-decay diagnosis (:mod:`pamid._decays._coulomb`):
    ``fit_name`` is its constant in the lanes' layout, ``key`` and ``constant`` how it is
    reported."""

    name: str
    covariate: str
    fit_name: str
    key: str
    constant: Constant
    injector: str | None
    doc: str

    def violation(self, value: float) -> str | None:
        c = self.constant
        if np.isfinite(value) and c.lower > -math.inf and value <= c.lower:
            return (f"{self.name} would need {c.name} = {value:.3g} {c.unit} ≤ {c.lower:g} "
                    f"{c.unit}: not physical")
        return None


DECAY_EFFECT_DEFINITIONS: tuple[DecayEffect, ...] = (
    DecayEffect(
        "coulomb_friction", "velocity_rad_s", "coulomb_shift_rad", "coulomb_Nm",
        Constant("coulomb_Nm", "N·m", lower=0.0),
        "pamid._virtual._decay.simulate_decays (coulomb_Nm=)",
        "A constant friction torque T_c·sign(β̇) (the sliding seal, the cable over the "
        "pulley): the amplitude falls linearly instead of geometrically; T_c ≥ 0 "
        "(dissipation)."),
    DecayEffect(
        "drift", "elapsed_s", "drift_rad_s", "drift_rad_s", Constant("drift_rad_s", "rad/s"),
        "pamid._virtual._decay.simulate_decays (drift_rad_s=)",
        "An equilibrium that moves with time, β_eq + r·t (a slow leak); either sign."),
)
