"""What a candidate effect of a diagnosis is: its definition and what it reads of a file.

An :class:`EffectDefinition` says everything the diagnosis needs to know of one effect that
a fitted force law F_model(θ; p, x) (Sárosi eq. 2.1, Cullinan eq. 3, any
:class:`~pamid.ForceModel`) may lack: its name, the covariates it needs, its constants with
units and physical bounds, how it changes the model — its ``model``, a class that wraps
the force law: feature columns added to the force (a
:class:`~pamid._effects._wrappers.FeatureEffect`, the constants entering linearly) or a
transform of the model's inputs (an :class:`~pamid._effects._wrappers.InputTransform`,
the constants entering the force law itself) — its physical reason and source (the
docstring of its builder), and the injector of the virtual bench that hides it in data.
Each effect is one module of this package, its definition beside its injector
(``_hysteresis.py``, ``_temperature.py``, …);
:data:`pamid._effects._definitions.STATIC_EFFECT_DEFINITIONS` is the registry that
:class:`pamid._diagnose._static.StaticProblem` reads, one line per effect, and
:data:`~pamid._effects._definitions.DECAY_EFFECT_DEFINITIONS` the same for free decays
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
from ._wrappers import InputTransform


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
    ``transform`` is its place among the transform constants, or None; ``bounds`` the
    physical (lower, upper) of each constant in this file (:func:`physical_bounds`).
    """

    name: str
    covariate: str
    param_names: tuple[str, ...]
    units: tuple[str, ...]
    columns: tuple[int, ...]
    definition: EffectDefinition = dataclasses.field(repr=False, default=None)
    transform: int | None = None
    grid: Constant | None = None
    bounds: tuple[tuple[float, float], ...] = ()

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
        """The pressure in bar (computed once: every fold's features read it)."""
        if "p_bar" not in self.memo:
            self.memo["p_bar"] = self.frame["pressure_kPa"].to_numpy(float) / KPA_PER_BAR
        return self.memo["p_bar"]


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
        model: the effect as a model that wraps its base, a class in the effect's module:
            for a transform effect an :class:`~pamid._effects._wrappers.InputTransform`
            subclass (the inputs as the muscle feels them), for a feature effect a
            :class:`~pamid._effects._wrappers.FeatureEffect` subclass, whose
            :meth:`features` make its columns.
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
    model: type
    grid: Constant | None = None
    grid_values: Callable | None = None
    applies: Callable | None = None
    check: Callable | None = None
    family: Callable | None = None
    form_of: str | None = None
    more: Callable | None = None
    derived: Callable | None = None

    @property
    def transform(self) -> bool:
        """Whether the effect transforms the model's inputs (else it adds columns)."""
        return issubclass(self.model, InputTransform)

    @property
    def implicit(self) -> bool:
        """Whether the transform reads the force: the force law becomes implicit."""
        return self.transform and self.model.depends_on_force

    def features(self, muscle: MuscleContext, col: Callable, grid_value=None,
                 effect: Effect | None = None) -> list:
        """A feature effect's columns for one muscle
        (:meth:`pamid._effects._wrappers.FeatureEffect.features`)."""
        return self.model.features(muscle, col, grid_value, effect)

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
            lo, hi = physical_bounds(c, file)
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


def physical_bounds(c: Constant, file: FileContext) -> tuple[float, float]:
    """The physical (lower, upper) of constant ``c`` in ``file``: what the fit may not
    report past (``violation``), and what its interval is cut at (the diagnosis's
    intervals)."""
    return c.bounds(file) if c.bounds is not None else (c.lower, c.upper)


def _fmt(v: float, unit: str, muscle: MuscleContext | None) -> str:
    out = f"{v:.3g}" if unit == "1" else f"{v:.3g} {unit}"
    other = per_l0(unit, muscle.l0_mm) if muscle is not None else None
    if other is not None:
        out += f" ({v * other[1]:.3g} {other[0]})"
    return out


@dataclasses.dataclass(frozen=True)
class DecayEffect:
    """A candidate effect of a free-decay diagnosis (:mod:`pamid._decays._coulomb`):
    ``fit_name`` is its constant in the lanes' layout, ``key`` and ``constant`` how it is
    reported; ``model`` the effect as a model that wraps the oscillator (an
    :class:`~pamid._effects._wrappers.EffectWrapper` subclass in the effect's module, whose
    one constant is ``fit_name``)."""

    name: str
    covariate: str
    key: str
    constant: Constant
    injector: str | None
    doc: str
    model: type

    @property
    def fit_name(self) -> str:
        """The effect's constant in the decay model: its wrapper's one constant."""
        return self.model.constants[0].name

    def violation(self, value: float) -> str | None:
        c = self.constant
        if np.isfinite(value) and c.lower > -math.inf and value <= c.lower:
            return (f"{self.name} would need {c.name} = {value:.3g} {c.unit} ≤ {c.lower:g} "
                    f"{c.unit}: not physical")
        return None
