"""Effects the virtual bench can hide in its data: what real rigs add to the static model.

Each subclass of :class:`Injected` is one physical effect that Sárosi's static force model
(eq. 2.1) does not declare; it lives beside the effect's definition, in the effect's own
module of this package (``_hysteresis.py``: :class:`~pamid.InjectedHysteresis` and
:class:`~pamid.InjectedMaxwellSlip`; ``_temperature.py``, ``_drift.py``, ``_viscous_damping.py``,
``_covariate.py``, ``_compliance.py``). :class:`~pamid._virtual._sweeps.SarosiProtocol`
takes any number of them in its
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
bench applies it inside the force law (see :class:`~pamid.InjectedCompliance`).

``force_N`` in the context is the bench's force before its ``effects`` are added (the static
force law with the protocol's own hysteresis, transient and softening): an effect that
scales the force (:class:`~pamid.InjectedRelativeTemperature`) reads it.
"""

from __future__ import annotations

import numpy as np

__all__ = ["Injected", "apply_effects"]

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
    """Run ``effects`` (all but :class:`~pamid.InjectedCompliance`) on the context ``ctx``.

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
