"""Effects as models: a force law wrapped in what it may lack (what :func:`pamid._effects.
_model.with_effects` builds a diagnosis's refit model from).

An effect is a model that wraps a model, its constants after the base's, with their names,
units and physical bounds. There are two kinds:

- A **transform** changes the inputs the base model sees, and its constants enter the
  force law itself (:class:`InputTransform`, one subclass per effect in the effect's own
  module): the compliance, F = F_base(p, κ + c·F)
  (:class:`pamid._effects._compliance.Compliance`), and the pressure sensor's offset,
  F = F_base(p + δ, κ) (:class:`pamid._effects._sensor_offset.SensorOffset`). A transform
  that depends on the force makes the law implicit; the force is then the fixed point,
  found by Newton from the base model.
- A **feature** effect (the hysteresis, the temperature, a drift, …) adds columns to the
  force, its constants their gains: one effect is a :class:`FeatureEffect` subclass in
  its module, whose ``features`` make its columns from a muscle's rows
  (``Hysteresis.wrap(base)``); :class:`LinearTerms` wraps a model in ``n_slots``
  anonymous slots, each a feature column (the last input) with its gain, to hold the
  columns of several effects::

      F = F_inner(θ; x) + Σ_j φ_j·f_j

What a diagnosis refits is :func:`~pamid._effects._model.with_effects`: the base model
wrapped in every transform of the registry (:func:`~pamid._effects._definitions.transforms`),
in its order, then in the linear slots. Every set of candidate effects of a batch is this
one model, the constants of the effects not in the set held at zero
(:mod:`pamid._diagnose._static`), so that all of them run as one compiled program; one
effect alone is the same wrapping of its base (``Compliance.wrap(base, implicit=True)``).
Each is a model like any other (:class:`~pamid._fit._spec.ModelSpec`): names, units,
bounds, ``predict`` and a structured ``jacobian``; ``pamid.engine.least_squares`` fits it.
"""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from .._fit._spec import ModelSpec

#: Newton steps of an implicit force law F = F_base(θ; T(x, F)) from the base model.
NEWTON_STEPS = 4


def transform_inputs(base: ModelSpec) -> dict:
    """Where a transform finds the base model's inputs: the contraction's place in ``x``
    and the pressure's place with the model's pressure unit per kPa (``base.to_x`` is
    linear)."""
    cols = list(base.columns)
    io = {"contraction": cols.index(base.contraction_column)
          if base.contraction_column in cols else min(1, len(cols) - 1)}
    if "pressure_kPa" in cols:
        i = cols.index("pressure_kPa")
        one = base.to_x(*[np.ones(1)] * len(cols))[i]
        zero = base.to_x(*[np.zeros(1)] * len(cols))[i]
        io["pressure"] = (i, float(np.asarray(one - zero)[0]))
    else:
        io["pressure"] = (0, 0.0)
    return io


def _unit_x(base: ModelSpec) -> str:
    return "%" if base.contraction_column == "contraction_pct" else "mm"


def _layout(base: ModelSpec, constants: tuple) -> tuple:
    """(names, units, bounds) of ``base`` wrapped in an effect of ``constants``: the base's,
    then the effect's, each unit's ``{x}`` the contraction's unit and ``{step}`` kPa."""
    names = (*base.param_names, *(c.name for c in constants))
    units = dict(base.param_units)
    units.update({c.name: c.unit.format(x=_unit_x(base), step="kPa") for c in constants})
    lower, upper = ((-np.inf,) * base.n_params, (np.inf,) * base.n_params) \
        if base.bounds is None else base.bounds
    return names, units, ((*lower, *(c.lower for c in constants)),
                          (*upper, *(c.upper for c in constants)))


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class EffectWrapper(ModelSpec):
    """A model wrapped in one effect: ``theta`` = (θ of ``base``, the effect's constants).
    A subclass gives :attr:`constants` and ``predict``; :meth:`wrap` makes it with the names,
    units and bounds of the base and of the effect. The transform effects of a force law
    (:class:`InputTransform`) and the effects of a free decay (the Coulomb friction,
    :class:`pamid._effects._coulomb_friction.CoulombFriction`; the drifting equilibrium,
    :class:`pamid._effects._drift.DecayDrift`) are its subclasses; a feature effect, whose
    constants may depend on the file, is a :class:`FeatureEffect`."""

    base: ModelSpec

    #: The effect's constants (:class:`pamid._effects._base.Constant`), in order.
    constants: ClassVar[tuple] = ()

    @classmethod
    def wrap(cls, base: ModelSpec, **fields) -> EffectWrapper:
        """``base`` wrapped in the effect (``fields``: the subclass's own), with the names,
        units and physical bounds of its constants (bounds that depend on the file, a sensor
        offset's, are left open: the diagnosis reports a constant past them as not
        physical). A model without bounds stays without them where the effect's constants
        have none."""
        names, units, bounds = _layout(base, cls.constants)
        open_ = all(c.lower == -np.inf and c.upper == np.inf for c in cls.constants)
        label = cls.__name__.lower()
        return cls(base=base, name=f"{base.name}+{label}", param_names=names,
                   param_units=units, units=dict(base.units), columns=base.columns,
                   source=f"{base.source}, with {label}", output=base.output,
                   bounds=None if base.bounds is None and open_ else bounds, **fields)

    def split(self, theta):
        """(θ of the base, the effect's constants)."""
        k = self.base.n_params
        return theta[..., :k], theta[..., k:]

    @property
    def program_key(self) -> tuple | None:
        key = self.base.program_key
        return None if key is None else (*key, type(self).__qualname__,
                                         *self._key_fields())

    def _key_fields(self) -> tuple:
        return ()

    def start(self, x, y, w):
        """The base model's start; the effect's constants at zero (no effect)."""
        theta0 = self.base.start(x, y, w)
        return jnp.concatenate(
            [theta0, jnp.zeros(theta0.shape[:-1] + (len(self.constants),))], axis=-1)

    def to_x(self, *cols):
        return self.base.to_x(*cols)


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class InputTransform(EffectWrapper):
    """``base`` with the inputs it sees transformed by an effect: F = F_base(θ; T(x, t, F)),
    ``theta`` = (θ of the base, t of the effect). A subclass (one per effect, beside its
    definition) gives :attr:`constants` and :meth:`transform`, and
    :attr:`depends_on_force` where T reads the force. Made by :meth:`wrap`.

    ``implicit``: solve the fixed point F = F_base(θ; T(x, t, F)) by Newton from the base
    model; False puts the base model's force in T instead, which is exact where the
    effect's constants are zero (the lanes of a diagnosis whose set lacks the effect, which
    then skip the Newton steps).
    """

    implicit: bool = False

    #: Whether :meth:`transform` reads the force (the law is then implicit).
    depends_on_force: ClassVar[bool] = False

    @classmethod
    def transform(cls, x, t, force, io):
        """The inputs ``x`` as the base model feels them at the effect's constants ``t``
        and the force ``force`` (``io``: where the inputs are, :func:`transform_inputs`)."""
        raise NotImplementedError(f"{cls.__name__} defines no transform")

    @classmethod
    def wrap(cls, base: ModelSpec, *, implicit: bool = False) -> InputTransform:
        """``base`` wrapped in the effect (:meth:`EffectWrapper.wrap`); ``implicit`` only
        where the transform reads the force."""
        return super().wrap(base, implicit=implicit and cls.depends_on_force)

    def predict(self, theta, x):
        base, io, k = self.base, transform_inputs(self.base), self.base.n_params
        theta_b, t = theta[..., :k], theta[..., k:]

        def g(f, theta_b, t, x):
            return base.predict(theta_b, self.transform(x, t, f, io))

        if not self.depends_on_force:
            return g(None, theta_b, t, x)
        if not self.implicit:
            return g(base.predict(theta_b, x), theta_b, t, x)
        # Newton on F = g(F) with the constants and inputs held, so that the iterations
        # carry no tangents; the derivatives are those of the fixed point (implicit
        # function theorem), dF = ∂g/∂(θ, t, x) / (1 − ∂g/∂F), from one more evaluation
        # of g at F. Carrying the tangents of every constant through the Newton steps
        # gives the same numbers (the derivative of the converged steps) at about four
        # times the cost.
        held = jax.lax.stop_gradient((theta_b, t, x))

        def g_held(f):
            return g(f, *held)

        f = base.predict(held[0], held[2])
        for _ in range(NEWTON_STEPS):
            gf, dg = jax.jvp(g_held, (f,), (jnp.ones_like(f),))
            f = f - (f - gf) / (1.0 - dg)
        f = jax.lax.stop_gradient(f)
        _, dg = jax.jvp(g_held, (f,), (jnp.ones_like(f),))
        gf = g(f, theta_b, t, x)
        return f + (gf - jax.lax.stop_gradient(gf)) / (1.0 - jax.lax.stop_gradient(dg))

    def _key_fields(self) -> tuple:
        return (self.implicit,)


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class LinearTerms(ModelSpec):
    """``base`` plus ``n_slots`` feature columns, each with its gain: F = F_base(θ; x) +
    Σ_j φ_j·f_j, ``theta`` = (θ of the base, φ), ``x`` = (the base's inputs, the (n,
    n_slots) feature columns). How a feature effect (the hysteresis, the temperature, …)
    wraps a model: its definition makes the columns from the file. Made by :meth:`wrap`."""

    base: ModelSpec
    n_slots: int

    @classmethod
    def wrap(cls, base: ModelSpec, n_slots: int) -> LinearTerms:
        names = (*base.param_names, *(f"phi{j}" for j in range(n_slots)))
        units = dict(base.param_units)
        units.update({f"phi{j}": "N per unit of its feature" for j in range(n_slots)})
        bounds = None if base.bounds is None else (
            (*base.bounds[0], *(-np.inf,) * n_slots), (*base.bounds[1], *(np.inf,) * n_slots))
        return cls(base=base, n_slots=n_slots, name=base.name, param_names=names,
                   param_units=units, units=dict(base.units),
                   columns=(*base.columns, "effect_features"),
                   source=f"{base.source}, and {n_slots} linear effect slots",
                   output=base.output, bounds=bounds)

    def predict(self, theta, x):
        *inputs, features = x
        k = self.base.n_params
        return self.base.predict(theta[..., :k], tuple(inputs)) + features @ theta[..., k:]

    def value_and_jacobian(self, theta, x):
        return self.predict(theta, x), self.jacobian(theta, x)

    def jacobian(self, theta, x):
        """∂F/∂theta (n × p): the base's, then the features (the gains enter linearly)."""
        *inputs, features = x
        k = self.base.n_params
        return jnp.concatenate([self.base.jacobian(theta[:k], tuple(inputs)), features],
                               axis=1)

    @property
    def program_key(self) -> tuple | None:
        key = self.base.program_key
        return None if key is None else (*key, type(self).__qualname__, self.n_slots)

    def start(self, x, y, w):
        """The base model's start; every gain at zero (no effect)."""
        theta0 = self.base.start(tuple(x[:-1]), y, w)
        return jnp.concatenate([theta0, jnp.zeros(theta0.shape[:-1] + (self.n_slots,))],
                               axis=-1)

    def to_x(self, *cols):
        return (*self.base.to_x(*cols[:-1]), cols[-1])


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class FeatureEffect(LinearTerms):
    """One feature effect as a model: F = F_base(θ; x) + Σ_j φ_j·f_j, the f_j the effect's
    columns (the last input, made from a muscle's rows by :meth:`features`), the φ_j its
    constants, with their names, units and physical bounds. A subclass, one per feature
    effect beside its definition (``Hysteresis`` in ``_hysteresis.py``, ``Transient`` in
    ``_transient.py``, …), gives :meth:`features` and :attr:`constants`. Made by
    :meth:`wrap`; :class:`LinearTerms` is the same with anonymous slots, which hold the
    columns of every effect of a diagnosis's candidate sets in one compiled program."""

    #: The effect's constants (:class:`pamid._effects._base.Constant`) that every file has,
    #: in the order of its columns; a file may add more (the hysteresis' slip elements).
    constants: ClassVar[tuple] = ()

    @staticmethod
    def features(muscle, col, grid_value, effect=None) -> list:
        """The effect's columns for one muscle's rows (N per unit of each constant):
        ``muscle`` a :class:`pamid._effects._base.MuscleContext`, ``col(name)`` reads a
        covariate (clamped to a fold's range), ``grid_value`` the constant chosen over a
        grid (or None), ``effect`` the :class:`~pamid._effects._base.Effect` where the
        columns depend on the member of a family."""
        raise NotImplementedError("a feature effect defines its features")

    @classmethod
    def wrap(cls, base: ModelSpec, constants: tuple | None = None) -> FeatureEffect:
        """``base`` wrapped in the effect, its constants :attr:`constants` or those of a
        file (``EffectDefinition.members``), each with its unit (``{x}`` the contraction's
        unit, ``{step}`` kPa) and bounds."""
        consts = cls.constants if constants is None else tuple(constants)
        names, units, bounds = _layout(base, consts)
        label = cls.__name__.lower()
        return cls(base=base, n_slots=len(consts), name=f"{base.name}+{label}",
                   param_names=names, param_units=units, units=dict(base.units),
                   columns=(*base.columns, f"{label}_features"),
                   source=f"{base.source}, with {label}", output=base.output, bounds=bounds)
