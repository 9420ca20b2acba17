"""A force law with candidate effects, as one model: what a diagnosis refits.

:class:`WithEffects` wraps a base model (any :class:`~pamid._fit._spec.ModelSpec`) in every
transform effect of :func:`~pamid._effects._definitions.transforms` (the compliance and the
sensor offset: constants that enter the force law itself) and in ``n_slots`` linear slots
(feature columns of the feature effects, each with its gain)::

    F = F_base(θ; T(x, F; t)) + Σ_j φ_j·f_j

``theta`` is (θ of the base model, t of the transforms in their registry order, φ of the
slots); ``x`` is the base model's inputs, then the (n, n_slots) feature columns. A
transform that depends on the force (the compliance: F = F_base(p, κ + c·F)) makes the law
implicit (``implicit``); the force is then the fixed point, found by Newton from the plain
model. A diagnosis refit is this model fitted with the constants of the effects not in
its set held at zero (:mod:`pamid._diagnose._static`); it is a model like any other, with
names, units and the base model's bounds.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._fit._spec import ModelSpec
from ._definitions import transforms

#: Newton steps of the implicit force law F = F_base(θ; T(x, F)) from the plain model.
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


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class WithEffects(ModelSpec):
    """``base`` with the transform effects and ``n_slots`` linear slots (module text). Made
    by :func:`with_effects`, one per (base, implicit, n_slots)."""

    base: ModelSpec
    implicit: bool
    n_slots: int

    @property
    def n_transforms(self) -> int:
        return len(transforms())

    def _split(self, theta):
        k, t = self.base.n_params, self.n_transforms
        return theta[..., :k], theta[..., k:k + t], theta[..., k + t:]

    def transformed(self, theta, tvals, x):
        """F_base with the transform effects at the constants ``tvals``: F =
        F_base(θ; T(x, F)), by Newton from the plain model where a transform depends on the
        force (:attr:`implicit`)."""
        base, io, defs = self.base, transform_inputs(self.base), transforms()

        def model(f, theta, tvals):
            xx = x
            for d, v in zip(defs, tvals, strict=True):
                xx = d.transform(xx, v, f, io)
            return base.predict(theta, xx)

        if not self.implicit:
            return model(base.predict(theta, x), theta, tvals)
        # Newton on F = g(F) with the constants held, so that the iterations carry no
        # tangents; the derivatives in the constants are those of the fixed point (implicit
        # function theorem), dF = ∂g/∂(θ, t) / (1 − ∂g/∂F), from one more evaluation of g
        # at F. Carrying the tangents of every constant through the Newton steps gives the
        # same numbers (the derivative of the converged steps) at about four times the cost.
        held = jax.lax.stop_gradient((theta, tvals))

        def g_held(f):
            return model(f, *held)

        f = base.predict(held[0], x)
        for _ in range(NEWTON_STEPS):
            g, dg = jax.jvp(g_held, (f,), (jnp.ones_like(f),))
            f = f - (f - g) / (1.0 - dg)
        f = jax.lax.stop_gradient(f)
        _, dg = jax.jvp(g_held, (f,), (jnp.ones_like(f),))
        g = model(f, theta, tvals)
        return f + (g - jax.lax.stop_gradient(g)) / (1.0 - jax.lax.stop_gradient(dg))

    def predict(self, theta, x):
        *inputs, features = x
        theta_b, tvals, phi = self._split(theta)
        return self.transformed(theta_b, tvals, tuple(inputs)) + features @ phi

    def value_and_jacobian(self, theta, x):
        return self.predict(theta, x), self.jacobian(theta, x)

    def jacobian(self, theta, x):
        """∂F/∂theta (n × p): forward-mode derivatives of the base model and the transforms
        only; the slots' gains enter linearly, their columns are the features."""
        *inputs, features = x
        k, t = self.base.n_params, self.n_transforms
        jac = jax.jacfwd(lambda q: self.transformed(q[:k], q[k:], tuple(inputs)))(theta[:k + t])
        return jnp.concatenate([jac, features], axis=1)

    def start(self, x, y, w):
        """The base model's start; every effect's constant at zero (no effect)."""
        theta0 = self.base.start(tuple(x[:-1]), y, w)
        return jnp.concatenate(
            [theta0, jnp.zeros(theta0.shape[:-1] + (self.n_transforms + self.n_slots,))],
            axis=-1)

    def to_x(self, *cols):
        return (*self.base.to_x(*cols[:-1]), cols[-1])


@functools.cache
def with_effects(base: ModelSpec, implicit: bool, n_slots: int) -> WithEffects:
    """:class:`WithEffects` of ``base``: the transform effects (implicit where ``implicit``)
    and ``n_slots`` linear slots. One per arguments, so that its compiled programs are
    reused."""
    unit_x = "%" if base.contraction_column == "contraction_pct" else "mm"
    names, units = list(base.param_names), dict(base.param_units)
    for d in transforms():
        c = d.constants[0]
        names.append(c.name)
        units[c.name] = c.unit.format(x=unit_x, step="kPa")
    for j in range(n_slots):
        names.append(f"phi{j}")
        units[f"phi{j}"] = "N per unit of its feature"
    p = len(names) - base.n_params
    bounds = None if base.bounds is None else (
        (*base.bounds[0], *(-np.inf,) * p), (*base.bounds[1], *(np.inf,) * p))
    label = "+".join(d.name for d in transforms())
    return WithEffects(
        base=base, implicit=implicit, n_slots=n_slots,
        name=f"{base.name}+effects",
        param_names=tuple(names),
        param_units=units,
        units=dict(base.units),
        columns=(*base.columns, "effect_features"),
        source=f"{base.source}, with {label} and {n_slots} linear effect slots",
        bounds=bounds,
    )
