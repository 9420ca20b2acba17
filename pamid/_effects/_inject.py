"""Effects the virtual bench can hide in its data: what real rigs add to the static model.

Each class here is one physical effect that Sárosi's static force model (eq. 2.1) does not
declare. :class:`~pamid._virtual._sweeps.SarosiProtocol` takes any number of them in its
``effects`` field, in any size and in more than one functional form, so that the diagnosis
of ``pamid diagnose`` can be tested on data whose file does not mention them.
An effect may add a column to the file (temperature, a humidity reading) as a real logger
would, but never says that the force depends on it.

Every effect sees a context of arrays that broadcast to the shape (C, M, P, D, K) — cycle
(1 when repeats are averaged), muscle, pressure, direction, point — in a sweep, or
(M, T, S) — muscle, trial, sample — in an isometric test
(:mod:`pamid._virtual._isometric`), and returns the force it adds, in N:

``p_bar`` gauge pressure (bar); ``kappa_pct`` contraction (%); ``direction`` +1 contracting,
−1 extending; ``time_s`` the time of the sample from the start of the muscle's test;
``velocity_mm_s`` the rate of contraction (positive while contracting; 0 in an isometric
test); ``moving_input`` the input that moves within a trial (the contraction in % in a
sweep, the pressure in kPa in an isometric test) and ``sequence_axes`` how many trailing axes
hold one trial's samples in time order (3 in a sweep: pressure, direction, point; 1 in an
isometric test); ``sweep`` the index of the sweep (cycle-major; the trial in an isometric
test) within a muscle; ``point_fraction`` the sample's place in its sweep or trial, 0 … 1;
``rng`` a NumPy Generator made from the bench's JAX key.

Compliance is different: it changes the muscle's length, not the force reading, so the
bench applies it inside the force law (see :class:`InjectedCompliance`).

``force_N`` in the context is the bench's force before its ``effects`` are added (the static
force law with the protocol's own hysteresis, transient and softening): an effect that
scales the force (:class:`InjectedRelativeTemperature`) reads it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = [
    "Injected",
    "InjectedCompliance",
    "InjectedCovariate",
    "InjectedDrift",
    "InjectedHysteresis",
    "InjectedMaxwellSlip",
    "InjectedRelativeTemperature",
    "InjectedTemperature",
    "InjectedViscousDamping",
]

_P_REF_BAR = 3.0  # the pressure at which every form of the hysteresis has the same size


class Injected:
    """What every effect of this module is: ``force_N(ctx)``, the force it adds (N), and
    ``columns(ctx)``, the columns it logs as a real logger would (none unless it says).
    An effect of one's own subclasses it (a frozen dataclass, as these are)."""

    def columns(self, ctx) -> dict[str, np.ndarray]:
        """The columns the effect adds to the file, by name (broadcast to the context)."""
        return {}

    def force_N(self, ctx):
        """The force the effect adds to the reading, in N."""
        raise NotImplementedError(f"{type(self).__name__} adds no force of its own")


def apply_effects(effects, ctx: dict, shape: tuple[int, ...]):
    """Run ``effects`` (all but :class:`InjectedCompliance`) on the context ``ctx``.

    Returns the force they add together (N, of ``shape``) and the columns they log, by name
    (each of ``shape``). ``ctx`` gains the logged columns, so that an effect can read them.
    """
    added = np.zeros(shape)
    columns: dict[str, np.ndarray] = {}
    for effect in effects:
        if not isinstance(effect, Injected):
            raise TypeError(f"{effect!r} is not an injected effect: subclass "
                            "pamid.Injected (force_N, and columns if it logs any)")
        for name, values in effect.columns(ctx).items():
            values = np.broadcast_to(values, shape)
            ctx[name] = values
            columns[name] = values
        added = added + effect.force_N(ctx)
    return added, columns


def _check_form(form: str, forms: tuple[str, ...], what: str) -> None:
    if form not in forms:
        raise ValueError(f"unknown {what} form {form!r}; choose one of {forms}")


@dataclasses.dataclass(frozen=True)
class InjectedHysteresis(Injected):
    """Direction-dependent force: the extending branch above the contracting one.

    Sárosi's upper (F_f) and lower (F_a) curves, eq. 2.3–2.4: the force read while the muscle
    contracts lies ``h(p)`` below the static curve, and ``h(p)`` above it while it extends.

    Forms of the half height h(p), all equal to ``N_at_3_bar`` at p = 3 bar:
    ``linear`` h ∝ p (what the library's ``hysteresis`` effect assumes, with an offset),
    ``sqrt`` h ∝ √p, ``constant`` h independent of p (pure dry friction), ``quadratic`` h ∝ p².
    """

    N_at_3_bar: float = 9.0
    form: str = "linear"

    def __post_init__(self):
        _check_form(self.form, ("linear", "sqrt", "constant", "quadratic"), "hysteresis")

    def force_N(self, ctx):
        u = np.maximum(ctx["p_bar"], 0.0) / _P_REF_BAR
        shape = {"linear": u, "sqrt": np.sqrt(u), "constant": np.ones_like(u),
                 "quadratic": u**2}[self.form]
        return -ctx["direction"] * self.N_at_3_bar * shape


@dataclasses.dataclass(frozen=True)
class InjectedMaxwellSlip(Injected):
    """Friction with memory: Maxwell-slip elements on the moving input, the force read while
    the input rises below the static curve and above it while it falls, curving after every
    reversal and closing minor loops (:mod:`pamid._effects._slip`).

    ``elements`` elements whose thresholds are spread geometrically over ``spread`` (shares
    of the input's range within the trial: the pressure's in an isometric test, the
    contraction's in a sweep) with equal weights, each element's slip force proportional
    to the pressure (``linear``: the braid's normal force, Tondu and Lopez 2000) or not
    (``constant``). Saturated — every element sliding — the force is ``N_at_3_bar`` below
    (or above) the static curve at 3 bar. Each trial starts as if its input had last fallen
    (a muscle deflated, or extended, before it). Unlike :class:`InjectedHysteresis`, it
    needs no direction: the loop's shape follows the input's path.
    """

    N_at_3_bar: float = 9.0
    spread: tuple[float, float] = (0.03, 0.3)
    elements: int = 8
    form: str = "linear"

    def __post_init__(self):
        _check_form(self.form, ("linear", "constant"), "Maxwell-slip")
        lo, hi = self.spread
        if not (0.0 < lo <= hi) or self.elements < 1:
            raise ValueError("spread must be two shares 0 < lo <= hi; elements >= 1")

    def force_N(self, ctx):
        from ._slip import stop_operator

        u = np.asarray(ctx["moving_input"], float)
        shape = u.shape
        n_seq = int(ctx["sequence_axes"])
        seqs = u.reshape(-1, int(np.prod(shape[len(shape) - n_seq:])))
        shares = np.geomspace(*self.spread, self.elements)
        out = np.zeros_like(seqs)
        for i, seq in enumerate(seqs):
            span = float(np.max(seq) - np.min(seq))
            if span <= 0:
                continue
            out[i] = stop_operator(seq, shares * span, initial=-1.0).mean(axis=1)
        scale = (np.maximum(ctx["p_bar"], 0.0) / _P_REF_BAR if self.form == "linear"
                 else np.ones(shape))
        return -self.N_at_3_bar * scale * out.reshape(shape)


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


@dataclasses.dataclass(frozen=True)
class InjectedDrift(Injected):
    """A slow change of the force reading with time: load-cell zero drift.

    ``linear``: ``N_per_hour`` per hour from the start of the test; ``exponential``: the zero
    settles towards ``N_per_hour`` with the time constant ``time_constant_s`` (a strain gauge
    warming up), i.e. N_per_hour·(1 − e^(−t/τ)).
    """

    N_per_hour: float = 20.0
    form: str = "linear"
    time_constant_s: float = 600.0

    def __post_init__(self):
        _check_form(self.form, ("linear", "exponential"), "drift")

    def force_N(self, ctx):
        t = ctx["time_s"]
        if self.form == "linear":
            return self.N_per_hour * t / 3600.0
        return self.N_per_hour * (1.0 - np.exp(-t / self.time_constant_s))


@dataclasses.dataclass(frozen=True)
class InjectedCompliance(Injected):
    """The rig stretches under load: the encoder reads the rod, not the muscle.

    The load cell, its mounts and a cable between them stretch by ``mm_per_N``·F, so the muscle
    is that much shorter than the rod position says: its true contraction is
    κ = κ_read + 100·c·F/l0, and the force solves F = F_model(p, κ_read + 100·c·F/l0).
    """

    mm_per_N: float = 0.01


@dataclasses.dataclass(frozen=True)
class InjectedViscousDamping(Injected):
    """A force opposing the rate of contraction: F − g·v (Cullinan's −G·ẏ term, eq. 3).

    Needs sweeps run at different speeds to be told apart from hysteresis; give the
    protocol ``sweep_seconds_per_point``.
    """

    N_s_per_mm: float = 2.0

    def force_N(self, ctx):
        return -self.N_s_per_mm * ctx["velocity_mm_s"]


@dataclasses.dataclass(frozen=True)
class InjectedCovariate(Injected):
    """Any other influence: a logged quantity (``column``) that the force depends on.

    Each sweep gets its own value drawn uniformly in ``range``, rounded to ``resolution``,
    written to the column; the force changes by ``N_per_unit·(v − mid)`` (``linear``),
    ``N_per_unit·(v − mid)²/half_range`` (``quadratic``) or
    ``N_per_unit·half_range·sin(π·(v − mid)/half_range)`` (``sine``), with ``mid`` and
    ``half_range`` the centre and half width of ``range``.
    """

    column: str = "humidity_pct"
    range: tuple[float, float] = (30.0, 70.0)
    N_per_unit: float = 0.3
    form: str = "linear"
    resolution: float = 0.1

    def __post_init__(self):
        _check_form(self.form, ("linear", "quadratic", "sine"), "covariate")

    def columns(self, ctx):
        lo, hi = self.range
        v = ctx["rng"].uniform(lo, hi, size=ctx["sweep"].shape[:-1] + (1,))
        v = np.broadcast_to(v, ctx["sweep"].shape[:-1] + (ctx["point_fraction"].shape[-1],))
        if self.resolution > 0:
            v = np.round(v / self.resolution) * self.resolution
        return {self.column: v}

    def force_N(self, ctx):
        lo, hi = self.range
        mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        u = ctx[self.column] - mid
        if self.form == "linear":
            return self.N_per_unit * u
        if self.form == "quadratic":
            return self.N_per_unit * u**2 / half
        return self.N_per_unit * half * np.sin(np.pi * u / half)
