"""The ``hysteresis`` effect: friction in the braid, a jump at every reversal and Maxwell-slip
elements with memory; its definition and its injectors."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import numpy as np

from ._base import Constant, EffectDefinition, FileContext, MuscleContext
from ._inject import _P_REF_BAR, Injected, _check_form
from ._wrappers import FeatureEffect

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


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class Hysteresis(FeatureEffect):
    """A force law with friction hysteresis: F_base − d·(h0 + h1·p) − Σ_i (h0_i + h1_i·p)·ŝ_i,
    d the direction and ŝ_i the slip elements' deflections, where the rows have a time
    order (:func:`hysteresis`; the slip elements' constants join :attr:`constants` in such
    a file: ``Hysteresis.wrap(base, constants)``)."""

    constants: ClassVar[tuple[Constant, ...]] = (Constant("h0", "N", lower=0.0, held=True),
                                                 Constant("h1", "N/bar", lower=0.0, held=True))

    @staticmethod
    def features(muscle, col, grid_value, effect=None):
        d = col("direction")
        out = [-d, -d * muscle.p_bar]
        if _slip_labels(muscle.file):
            for s in slip_features(muscle).T:
                out += [-s, -s * muscle.p_bar]
        return out


def hysteresis() -> EffectDefinition:
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
    :class:`pamid._effects._hysteresis.InjectedHysteresis` (and
    ``IsometricProtocol.hysteresis_N_at_3_bar``),
    :class:`~pamid._effects._hysteresis.InjectedMaxwellSlip`.
    """
    return EffectDefinition(
        name="hysteresis", covariates=("direction",),
        constants=Hysteresis.constants, model=Hysteresis,
        injector=("pamid._effects._hysteresis.InjectedHysteresis",
                  "pamid._effects._hysteresis.InjectedMaxwellSlip",
                  "pamid._virtual._isometric.IsometricProtocol.hysteresis_N_at_3_bar",
                  "pamid._virtual._sweeps.SarosiProtocol.hysteresis_N_per_bar"),
        more=_slip_constants,
        derived=_hysteresis_half_height,
    )


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
