"""The model a diagnosis refits: a force law wrapped in every candidate effect.

:func:`with_effects` wraps a base model (any :class:`~pamid._fit._spec.ModelSpec`) in each
transform effect of :func:`~pamid._effects._definitions.transforms` (the compliance, then
the sensor offset: :class:`~pamid._effects._wrappers.InputTransform` subclasses, each in its
effect's module), then in ``n_slots`` linear slots
(:class:`~pamid._effects._wrappers.LinearTerms`: the feature effects' columns with their
gains)::

    F = F_base(θ; T(x, F; t)) + Σ_j φ_j·f_j

``theta`` is (θ of the base model, t of the transforms in their registry order, φ of the
slots); ``x`` is the base model's inputs, then the (n, n_slots) feature columns. A
diagnosis refit is this model fitted with the constants of the effects not in its set held
at zero (:mod:`pamid._diagnose._static`): every set of a batch is then one model and one
compiled program.
"""

from __future__ import annotations

import dataclasses
import functools

from .._fit._spec import ModelSpec
from ._definitions import transforms
from ._wrappers import LinearTerms


@functools.cache
def with_effects(base: ModelSpec, implicit: bool, n_slots: int) -> LinearTerms:
    """``base`` wrapped in every transform effect of the registry, in its order (an
    implicit force law where ``implicit``: the compliance's fixed point solved), then in
    ``n_slots`` linear slots (module text). One per arguments, so that its compiled
    programs are reused."""
    model = base
    for d in transforms():
        model = d.model.wrap(model, implicit=implicit)
    label = "+".join(d.name for d in transforms())
    return dataclasses.replace(
        LinearTerms.wrap(model, n_slots), name=f"{base.name}+effects",
        source=f"{base.source}, with {label} and {n_slots} linear effect slots")
