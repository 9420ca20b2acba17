"""What the fitting code needs to know about a model: its constants and its prediction.

A model is fitted as ``y ≈ predict(theta, x)`` with ``theta`` a flat vector of constants
and ``x`` a tuple of per-sample arrays. The batched solvers, the intervals, the bootstrap,
the plots and the CLI only see this interface (:class:`ModelSpec`).

A :class:`~pamid.ForceModel` is fitted through :class:`ModelView`, a thin flat view of its
class generated once (:func:`spec_from_model`): its fields are the constants, and the view's
methods build the model from ``theta`` and call it. Models made of other models (the
length study's constants smooth in l0, the pooled models, the decay trajectory) are
subclasses of :class:`ModelSpec` that wrap their base. pamid's own models are registered by
name as classes (:data:`MODELS` makes their views on first use); written-out kernels are
registered by model class (:data:`KERNELS`) and found by the view's type, not by a name.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from collections.abc import Callable, MutableMapping

import jax.numpy as jnp
import numpy as np

from .._errors import BenchDataError
from .._models._cullinan import CULLINAN_NAMES, Cullinan
from .._models._sarosi import Sarosi


@dataclasses.dataclass(frozen=True)
class FastPath:
    """A model class's written-out kernels, registered for it in :data:`KERNELS` and used in
    place of the generic ones (``_least_squares.solve``, ``statistics``,
    ``_intervals.profile``) for a view that fits all of its constants from all of its inputs.

    Attributes:
        gauss_newton: ``(x, y, w, [theta0], *, max_steps, rtol, atol) -> (theta, ok,
            steps)`` for a batch, with its own start when no ``theta0`` is given.
        statistics: ``(theta, x, y, w) -> (sse, (JᵀJ)⁻¹, corr, n, full_rank)`` for a batch.
        statistics_take_curve: ``statistics`` also takes ``curve=`` (the lanes' curve ids)
            and then returns the residual's lag-1 sums after those five
            (:func:`pamid._fit._least_squares.lag1_sums`), from its own pass.
        variable_projection: ``(x, y, w, n_refine) -> (theta, _, bracket_width)`` or None.
        profile_derivatives: ``(x, y, w) -> (derivatives, sse_only)`` for the profile
            intervals' Newton iteration, or None.
        start: ``(x, y, w) -> theta0`` for a batch, the model's start for every solver in
            place of the generic one (kept where ``written_out=False``), or None.
    """

    gauss_newton: Callable
    statistics: Callable
    statistics_take_curve: bool = False
    variable_projection: Callable | None = None
    profile_derivatives: Callable | None = None
    start: Callable | None = None

    @property
    def key(self) -> str:
        """A name for the kernels, the same in every process (the key of their exported
        programs): where the Gauss–Newton kernel is defined."""
        return f"{self.gauss_newton.__module__}.{self.gauss_newton.__qualname__}"


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class ModelSpec:
    """A model as the fitting code sees it: ``predict(theta, x)`` of a flat vector of
    constants. A subclass defines :meth:`predict` and :meth:`start` (and :meth:`to_x`,
    :meth:`make` where they are not the identity); its fields are data.

    Attributes:
        name: the model's name in outputs ("sarosi", "cullinan").
        param_names: names of the constants, in the order of ``theta``.
        param_units: unit of each constant.
        units: the units the constants are stated in (the JSON ``"units"`` field).
        columns: bench-frame columns that make ``x``, in order.
        source: the equation fitted, for outputs.
        output: the fitted quantity and its unit (force in N for the static models).
        bounds: physical (lower, upper) of each constant (±inf where none), or None.
        model_class: the :class:`~pamid.ForceModel` the spec was made from, or None.
        prior: uniform priors ``{name: (low, high)}`` declared by the model, for MCMC.
        written_out: use the model class's registered written-out kernels
            (:data:`KERNELS`, :attr:`kernels`) where it has them; False fits it with the
            generic solvers and statistics (``dataclasses.replace(spec,
            written_out=False)``).
    """

    name: str
    param_names: tuple[str, ...]
    param_units: dict[str, str]
    units: dict[str, str]
    columns: tuple[str, ...]
    source: str
    output: tuple[str, str] = ("force", "N")
    bounds: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    model_class: type | None = None
    prior: dict | None = None
    written_out: bool = True

    def predict(self, theta, x):
        """The model's output for one set of constants ``theta`` (p,) at inputs ``x``."""
        raise NotImplementedError(f"{type(self).__name__} defines no predict")

    def start(self, x, y, w):
        """Start values ``theta0`` (M, p) for a batch (leading muscle axis; ``w`` = 0 on
        padding)."""
        raise NotImplementedError(f"{type(self).__name__} defines no start")

    def value_and_jacobian(self, theta, x):
        """(predict, ∂predict/∂theta (n × p)) at one set of constants, from one forward-mode
        pass (the prediction is its primal), unless a subclass knows the structure."""
        import jax

        jac, value = jax.jacfwd(lambda th: (self.predict(th, x),) * 2, has_aux=True)(theta)
        return value, jac

    def jacobian(self, theta, x):
        """∂predict/∂theta (n × p) at one set of constants (:meth:`value_and_jacobian`)."""
        return self.value_and_jacobian(theta, x)[1]

    def to_x(self, *cols):
        """The model's ``x`` from its :attr:`columns` (NumPy arrays)."""
        return tuple(cols)

    def make(self, theta):
        """The model's parameter object from ``theta`` (the vector itself by default)."""
        return theta

    #: ``candidates(x, y, w, clip=True) -> (theta (M, K, p), sse (M, K))``, start candidates
    #: best first (:mod:`._start`; ``clip``: into the bounds), or None where the model
    #: brings its own start.
    candidates = None
    #: ``linear() -> mask (p,)``, the constants the model is linear in (found on first use,
    #: :func:`._start.linear_constants`), or None where the model brings its own start.
    linear = None

    @property
    def kernels(self) -> FastPath | None:
        """The registered written-out kernels the fit uses for this spec, or None."""
        return None

    @property
    def program_key(self) -> tuple | None:
        """A name for the spec that is the same in every process, for the compiled
        programs kept on disk (``_export_cache``); None where there is none (a user's
        model, whose code pamid's hash does not cover)."""
        return None

    @property
    def n_params(self) -> int:
        return len(self.param_names)

    @property
    def contraction_column(self) -> str:
        """The frame column of the model's contraction input (``contraction_pct`` where it
        takes none)."""
        return next((c for c in self.columns if c.startswith("contraction")),
                    "contraction_pct")

    def x_from_frame(self, frame, path: str | None = None) -> tuple[np.ndarray, ...]:
        """The model inputs from a bench frame; a clear error if a column is missing."""
        for col in self.columns:
            if col not in frame:
                hint = {
                    "contraction_pct": "give contraction_pct, or length_mm with l0_mm",
                    "contraction_mm": "give contraction_mm, or length_mm or contraction_pct "
                    "together with l0_mm",
                }.get(col, f"add a {col} column")
                raise BenchDataError(
                    path, f"the {self.name} model needs {col}: {hint}", column=col
                )
        return self.to_x(*(np.asarray(frame[c], dtype=float) for c in self.columns))


def _deprecated_fast_path(self) -> FastPath | None:
    warnings.warn("ModelSpec.fast_path is deprecated: kernels are registered by model class "
                  "(pamid._fit._spec.KERNELS); read ModelSpec.kernels, and give "
                  "written_out=False to fit without them", DeprecationWarning, stacklevel=2)
    return self.kernels


ModelSpec.fast_path = property(_deprecated_fast_path)


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class Scaled(ModelSpec):
    """``base`` in its constants divided by a scale of each, given as the last input (the
    lane's typical sizes): ``theta`` = constants / scale, ``x`` = (*base's x, scale), so
    that a solver's steps, damping and tolerances see constants of order one. A model that
    wraps a model: made by :func:`scaled`."""

    base: ModelSpec

    def predict(self, theta, x):
        *inputs, scale = x
        return self.base.predict(theta * scale, tuple(inputs))


def scaled(base: ModelSpec) -> Scaled:
    """:class:`Scaled` of ``base``, its names, units and source."""
    return Scaled(base=base, name=f"{base.name}_scaled", param_names=base.param_names,
                  param_units={n: f"{u} per unit of scale" for n, u in base.param_units.items()},
                  units=dict(base.units), columns=(*base.columns, "scale"),
                  source=f"{base.source}, constants divided by a scale", output=base.output)


class ModelDefinitionError(ValueError):
    """A :class:`~pamid.ForceModel` that cannot be fitted as written; the message says what
    to change."""


#: Written-out kernels by model class (dispatch on the model's type): a function that
#: returns the class's :class:`FastPath` (built on first use).
KERNELS: dict[type, Callable[[], FastPath]] = {}


@functools.cache
def _sarosi_kernels() -> FastPath:
    """Sárosi eq. 2.1's written-out Gauss–Newton, statistics, variable projection, profile
    derivatives and start (:mod:`pamid._solvers._sarosi`)."""
    from .._solvers import (
        sarosi_derivatives,
        sarosi_gauss_newton,
        sarosi_statistics,
        sarosi_variable_projection,
        sarosi_variable_projection_start,
    )

    return FastPath(gauss_newton=sarosi_gauss_newton,
                    statistics=sarosi_statistics, statistics_take_curve=True,
                    variable_projection=sarosi_variable_projection,
                    profile_derivatives=sarosi_derivatives,
                    start=sarosi_variable_projection_start)


KERNELS[Sarosi] = _sarosi_kernels


def _input_unit(name: str) -> tuple[str, str]:
    """(quantity, unit) of an input name: ``pressure_kPa`` -> ("pressure", "kPa")."""
    quantity, _, unit = name.partition("_")
    unit = {"pct": "%", "ratio": "1", "mm_s": "mm/s", "m_s": "m/s"}.get(unit, unit)
    return quantity, unit or "1"


def _field_defaults(cls) -> dict[str, float]:
    out = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
    return out


def _fitted_fields(cls) -> tuple[str, ...]:
    """A model class's constants: its fields not marked ``eqx.field(static=True)``."""
    return tuple(f.name for f in dataclasses.fields(cls) if not f.metadata.get("static", False))


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class ModelView(ModelSpec):
    """The flat view of a :class:`~pamid.ForceModel` class that the fitting code fits:
    ``theta`` holds the constants :attr:`param_names` (fields of ``model_class``, in field
    order), the other fields keep the values :attr:`fixed`; ``x`` holds the inputs
    :attr:`inputs` converted from :attr:`columns` by :attr:`factors`. Made by
    :func:`spec_from_model`.

    Attributes:
        inputs: the model inputs taken, a prefix of ``model_class.inputs``.
        factors: (multiplier, divisor) of each input from its column.
        fixed: the values of the fields not fitted.
        defaults: start values by constant (the fields' defaults, or an instance's values).
        start_with: a batched ``start(x, y, w)`` given in place of the model's own, or None.
        from_instance: made from an instance, whose values are the start: the class's
            registered kernels (which bring their own start) are not used.
    """

    inputs: tuple[str, ...]
    factors: tuple[tuple[float, float], ...]
    fixed: dict[str, float] = dataclasses.field(default_factory=dict)
    defaults: dict[str, float] = dataclasses.field(default_factory=dict)
    start_with: Callable | None = None
    from_instance: bool = False

    def _build(self, theta):
        return self.model_class(**{n: theta[..., i] for i, n in enumerate(self.param_names)},
                                **self.fixed)

    def predict(self, theta, x):
        return self._build(theta)(*x)

    def make(self, theta):
        return self._build(jnp.asarray(theta))

    def to_x(self, *cols):
        return tuple(c if m == d == 1.0 else c * m / d
                     for c, (m, d) in zip(cols, self.factors, strict=True))

    @functools.cached_property
    def _complete(self) -> bool:
        """Whether the view fits every constant of its class, in field order, from every
        input: what a class's registered kernels are written for."""
        cls = self.model_class
        return (not self.fixed and self.inputs == tuple(cls.inputs)
                and self.param_names == _fitted_fields(cls))

    @property
    def _registered(self) -> FastPath | None:
        make = KERNELS.get(self.model_class)
        usable = make is not None and self._complete and not self.from_instance
        return make() if usable else None

    @property
    def kernels(self) -> FastPath | None:
        return self._registered if self.written_out else None

    @property
    def _own_start(self) -> Callable | None:
        """The start the model brings: one given to :func:`spec_from_model`, the class's
        ``start`` classmethod, or its registered kernels' start."""
        if self.start_with is not None:
            return self.start_with
        own = getattr(self.model_class, "start", None)
        if own is not None:
            return own
        registered = self._registered
        return None if registered is None else registered.start

    def start(self, x, y, w):
        own = self._own_start
        if own is not None:
            return own(x, y, w)
        return self._candidates(x, y, w)[0][:, 0]

    @property
    def candidates(self):
        return None if self._own_start is not None else self._candidates

    @property
    def linear(self):
        return None if self._own_start is not None else self._linear_mask

    def _reference(self) -> list[float]:
        return [float(self.defaults.get(n, 1.0)) for n in self.param_names]

    def _linear_mask(self) -> np.ndarray:
        # Found on first use (it traces the model), not when the view is made.
        return self._linear_found

    @functools.cached_property
    def _linear_found(self) -> np.ndarray:
        from ._start import linear_constants

        cls = self.model_class
        key = (cls.__module__, cls.__qualname__, self.param_names, self.inputs,
               repr(sorted(self.fixed.items())))
        return linear_constants(self.predict, self.n_params, self.inputs, self._reference(),
                                cache_key=key if self._own_code else None)

    @functools.cached_property
    def _design(self):
        from ._start import projected_candidates, trial_values

        linear = self._linear_mask()
        lacking = [n for n, lin in zip(self.param_names, linear, strict=True)
                   if not lin and n not in self.defaults]
        if lacking:
            raise ModelDefinitionError(
                f"{self.model_class.__name__}: give {', '.join(lacking)} a default (its start "
                "value) or define a classmethod start(cls, inputs, force_N, weight)")
        lower, upper = self._bound_arrays()
        trials = trial_values(self._reference(), lower, upper, ~linear)
        return projected_candidates(self.predict, linear, trials, lower, upper)

    def _candidates(self, x, y, w, clip=True):
        return self._design(x, y, w, clip=clip)

    def _bound_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        p = self.n_params
        if self.bounds is None:
            return np.full(p, -np.inf), np.full(p, np.inf)
        return np.asarray(self.bounds[0], float), np.asarray(self.bounds[1], float)

    @functools.cached_property
    def _own_code(self) -> bool:
        """pamid's own classes are named alike in every process (and their code is in the
        hash that keys the programs kept on disk); a user's are not."""
        cls = self.model_class
        return cls is not None and cls.__module__.split(".")[0] == "pamid"

    @functools.cached_property
    def program_key(self) -> tuple | None:
        # A view made from an instance starts from its values, which the key would not
        # name: its programs are not kept on disk.
        if not self._own_code or self.from_instance:
            return None
        cls = self.model_class
        start = self.start_with
        return (f"{cls.__module__}.{cls.__qualname__}", self.param_names, self.inputs,
                repr(sorted(self.fixed.items())), repr(self.bounds),
                None if start is None else f"{start.__module__}.{start.__qualname__}",
                self.kernels is not None)


def spec_from_model(model, *, params: tuple[str, ...] | None = None,
                    inputs: tuple[str, ...] | None = None,
                    start: Callable | None = None,
                    fast_path: FastPath | None = None,
                    name: str | None = None, source: str | None = None,
                    units: dict[str, str] | None = None) -> ModelView:
    """The fitting code's view of a :class:`~pamid.ForceModel` subclass (or instance).

    Args:
        model: the model class, or an instance whose field values become the start values
            (fitted from them by the generic solvers: a class's registered kernels bring
            their own start).
        params: the constants to fit (default: every field not marked
            ``eqx.field(static=True)``); the others keep their defaults.
        inputs: the inputs to give, a prefix of ``model.inputs`` (default: all of them).
        start: a batched ``start(x, y, w) -> theta0`` in place of the model's own
            ``start`` or the generic one.
        fast_path: written-out kernels for the class, registered for it in
            :data:`KERNELS` (every complete view of the class then uses them).
        name, source: the model's name and equation in outputs, in place of the class's.
        units: the JSON ``"units"`` field, in place of the one made from the inputs.

    The constants' order is the fields' order. Raises :class:`ModelDefinitionError` where
    the class lacks something the fit needs (a unit, an input, a start value).
    """
    from .._models._protocol import INPUT_CONVERSIONS, ForceModel

    cls = model if isinstance(model, type) else type(model)
    if not (isinstance(cls, type) and issubclass(cls, ForceModel)):
        raise ModelDefinitionError(f"{cls!r} is not a pamid.ForceModel subclass")
    label = cls.__name__
    fields = [f for f in dataclasses.fields(cls)]
    names = _fitted_fields(cls) if params is None else tuple(params)
    unknown = [n for n in names if n not in {f.name for f in fields}]
    if unknown:
        raise ModelDefinitionError(f"{label} has no constant(s) {', '.join(unknown)}")
    if not names:
        raise ModelDefinitionError(f"{label} has no constants to fit (no fields)")
    defaults = _field_defaults(cls)
    if not isinstance(model, type):
        defaults.update({f.name: getattr(model, f.name) for f in fields})
    model_inputs = tuple(cls.inputs)
    taken = model_inputs if inputs is None else tuple(inputs)
    if not taken or not all(isinstance(i, str) for i in taken):
        raise ModelDefinitionError(
            f"{label}.inputs must name the bench columns __call__ takes, in call order, "
            "e.g. inputs = ('pressure_kPa', 'contraction_pct')")
    if taken != model_inputs[:len(taken)]:
        raise ModelDefinitionError(f"inputs {taken} are not a prefix of {label}.inputs")
    param_units = dict(cls.units)
    missing_units = [n for n in names if n not in param_units]
    if missing_units:
        raise ModelDefinitionError(
            f"{label}.units has no unit for {', '.join(missing_units)}: give every constant "
            "its unit, e.g. units = {'c0': 'N'}")
    fixed = {k: v for k, v in defaults.items() if k not in names}
    lower = np.full(len(names), -np.inf)
    upper = np.full(len(names), np.inf)
    for key, (lo, hi) in dict(cls.bounds).items():
        if key not in names:
            if key in fixed:
                continue
            raise ModelDefinitionError(f"{label}.bounds names {key!r}, which is not a constant")
        if not lo < hi:
            raise ModelDefinitionError(f"{label}.bounds[{key!r}]: lower {lo} must be below "
                                       f"upper {hi}")
        lower[names.index(key)], upper[names.index(key)] = lo, hi
    bounds = None if np.all(np.isinf(lower)) and np.all(np.isinf(upper)) else (
        tuple(lower.tolist()), tuple(upper.tolist()))
    columns, factors = [], []
    for taken_name in taken:
        column, *factor = INPUT_CONVERSIONS.get(taken_name, (taken_name, 1.0, 1.0))
        columns.append(column)
        factors.append(tuple(factor))
    if fast_path is not None:
        KERNELS[cls] = lambda: fast_path
    doc = (cls.__doc__ or "").strip().splitlines()
    if doc and doc[0].startswith(f"{label}("):  # written by dataclasses, not by the author
        doc = []
    return ModelView(
        name=name or cls.name or label.lower(),
        param_names=names,
        param_units={n: param_units[n] for n in names},
        units=dict(units) if units is not None else {
            "force": "N", **dict(_input_unit(i) for i in taken)},
        columns=tuple(columns),
        source=source or cls.source or (doc[0] if doc else f"{label} (user model)"),
        bounds=bounds,
        model_class=cls,
        prior=dict(cls.prior) or None,
        inputs=taken,
        factors=tuple(factors),
        fixed=fixed,
        defaults=defaults,
        start_with=start,
        from_instance=not isinstance(model, type),
    )


_CULLINAN_UNITS = {"force": "N", "pressure": "kPa", "contraction": "mm", "time": "s"}


class _Registry(MutableMapping):
    """pamid's own models by name: a class with the options of its view, the view made on
    first use (one per name, so that its compiled programs are reused); a view set
    directly is kept as it is."""

    def __init__(self):
        self._entries: dict[str, object] = {}

    def add(self, key: str, model, **options) -> None:
        """Register ``model`` (a ForceModel class) under ``key`` with the options of its
        view (:func:`spec_from_model`: ``params``, ``inputs``, ``name``, ``source`` …)."""
        self._entries[key] = (model, options)

    def __getitem__(self, name: str) -> ModelSpec:
        entry = self._entries[name]
        if not isinstance(entry, ModelSpec):
            model, options = entry
            entry = self._entries[name] = spec_from_model(model, **options)
        return entry

    def __setitem__(self, name: str, spec: ModelSpec) -> None:
        self._entries[name] = spec

    def __delitem__(self, name: str) -> None:
        del self._entries[name]

    def __iter__(self):
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def model_class(self, name: str) -> type | None:
        entry = self._entries[name]
        return entry.model_class if isinstance(entry, ModelSpec) else entry[0]


#: pamid's own models by name (``--model NAME``): classes, their views made on first use.
MODELS = _Registry()
MODELS.add("sarosi", Sarosi)
MODELS.add("cullinan", Cullinan, params=CULLINAN_NAMES[:5], inputs=Cullinan.inputs[:2],
           units=_CULLINAN_UNITS, source="Cullinan eq. 3 (static: A–E)")


def _published() -> None:
    """The published static force laws (:mod:`pamid._models._published`), by their names."""
    from .._models._published import published_models

    for model, options in published_models():
        MODELS.add(options.get("name") or model.name or model.__name__.lower(), model,
                   **options)


_published()


#: The views of pamid's two models, as :func:`get_model` gives them.
SAROSI = MODELS["sarosi"]
CULLINAN = MODELS["cullinan"]
CULLINAN_DYNAMIC = spec_from_model(Cullinan, units=_CULLINAN_UNITS,
                                   source="Cullinan eq. 3 (with velocity: A–E and G)")

#: A model's variants fitted where the data carry a further input: (column, spec) pairs
#: tried in order (Cullinan eq. 3 with its damping constant G where the file has a
#: velocity).
VARIANTS: dict[str, tuple[tuple[str, ModelSpec], ...]] = {
    "cullinan": (("velocity_mm_s", CULLINAN_DYNAMIC),)}


def register_model(model, *, name: str | None = None, **kwargs) -> ModelSpec:
    """Add a :class:`~pamid.ForceModel` to pamid's own models (``--model NAME``)."""
    spec = spec_from_model(model, name=name, **kwargs)
    MODELS[spec.name] = spec
    return spec


def model_names() -> tuple[str, ...]:
    """The names of pamid's own models, those :func:`register_model` added included (what
    ``--model NAME`` and :func:`get_model` accept), in the order they were registered."""
    return tuple(MODELS)


def get_model(name, frame=None) -> ModelSpec:
    """The spec for a model: a name of pamid's own (for "cullinan", with G when the data
    carry a velocity), ``"path/to/file.py:ClassName"`` for a user's, a
    :class:`~pamid.ForceModel` class or instance, or a ModelSpec (returned as it is)."""
    if isinstance(name, ModelSpec):
        return name
    if isinstance(name, type):
        return _class_spec(name)
    if not isinstance(name, str):
        return spec_from_model(name)  # an instance: its values are the start
    if ":" in name and name.split(":", 1)[0].endswith(".py"):
        return _class_spec(load_model_class(name))
    try:
        spec = MODELS[name]
    except KeyError:
        raise ValueError(
            f"unknown model {name!r}; choose one of {sorted(MODELS)}, or give "
            "path/to/file.py:ClassName for your own pamid.ForceModel") from None
    for column, variant in VARIANTS.get(name, ()) if frame is not None else ():
        if column in frame:
            return variant
    return spec


@functools.cache
def _class_spec(cls: type) -> ModelSpec:
    """One spec per model class, so that its compiled programs are reused across fits."""
    for name in MODELS:
        if MODELS.model_class(name) is cls:
            return MODELS[name]
    return spec_from_model(cls)


_LOADED: dict[tuple[str, str, float], type] = {}


def load_model_class(reference: str) -> type:
    """The class named by ``"path/to/file.py:ClassName"``, imported from that file.

    Raises :class:`ModelDefinitionError` with one line naming the file (and the line, for
    an error in it) when the file cannot be read or run, or holds no such ForceModel."""
    import importlib.util
    import os
    import sys
    import traceback

    from .._models._protocol import ForceModel

    path, _, class_name = reference.rpartition(":")
    if not class_name:
        raise ModelDefinitionError(f"{reference}: name the class after a colon, "
                                   "e.g. models.py:Quadratic")
    try:
        mtime = os.stat(path).st_mtime
    except OSError as exc:
        raise ModelDefinitionError(f"{path}: cannot read the model file "
                                   f"({exc.strerror or exc})") from None
    key = (os.path.abspath(path), class_name, mtime)
    if key in _LOADED:
        return _LOADED[key]
    module_name = f"pamid_user_model_{abs(hash(key))}"
    try:
        module_spec = importlib.util.spec_from_file_location(module_name, path)
        if module_spec is None or module_spec.loader is None:
            raise ModelDefinitionError(f"{path}: not a Python file")
        module = importlib.util.module_from_spec(module_spec)
        sys.modules[module_name] = module
        module_spec.loader.exec_module(module)
    except ModelDefinitionError:
        raise
    except SyntaxError as exc:
        raise ModelDefinitionError(
            f"{path}, line {exc.lineno}: syntax error in the model file: {exc.msg}") from None
    except (Exception, SystemExit) as exc:  # the user's code: where it failed, in one line
        frames = [f for f in traceback.extract_tb(exc.__traceback__)
                  if os.path.abspath(f.filename) == key[0]]
        where = f", line {frames[-1].lineno}" if frames else ""
        what = (f"it ended the program (SystemExit: {exc.code!r}); a model file defines "
                "classes" if isinstance(exc, SystemExit) else f"{type(exc).__name__}: {exc}")
        raise ModelDefinitionError(
            f"{path}{where}: the model file failed to run: {what}") from None
    cls = getattr(module, class_name, None)
    if cls is None:
        found = sorted(k for k, v in vars(module).items()
                       if isinstance(v, type) and issubclass(v, ForceModel) and v is not ForceModel)
        raise ModelDefinitionError(
            f"{path}: no class {class_name!r}; pamid.ForceModel classes in it: "
            f"{', '.join(found) or 'none'}")
    if not (isinstance(cls, type) and issubclass(cls, ForceModel)):
        raise ModelDefinitionError(f"{path}: {class_name} is not a pamid.ForceModel subclass")
    _LOADED[key] = cls
    return cls


def check_callable(spec: ModelSpec, where: str) -> None:
    """Call the model once at its start values on a few probe inputs: a
    :class:`ModelDefinitionError` naming the file and line of a model that fails there or
    returns no force of the inputs' shape."""
    import os
    import traceback

    from ._start import probe_inputs

    cls = spec.model_class
    path = os.path.abspath(where.rpartition(":")[0]) if ":" in where else None
    probe = probe_inputs(tuple(cls.inputs[: len(spec.columns)]))
    defaults = _field_defaults(cls)
    theta = jnp.asarray([float(defaults.get(n, 1.0)) for n in spec.param_names])
    try:
        out = spec.predict(theta, probe)
        shape = np.shape(out)
    except (Exception, SystemExit) as exc:  # the user's code: one line, the place it failed
        frames = [f for f in traceback.extract_tb(exc.__traceback__)
                  if path is not None and os.path.abspath(f.filename) == path]
        at = f"{where.rpartition(':')[0]}, line {frames[-1].lineno}" if frames else where
        raise ModelDefinitionError(
            f"{at}: {cls.__name__}.__call__ failed on test inputs "
            f"({type(exc).__name__}: {exc})") from None
    if shape != np.shape(probe[0]):
        raise ModelDefinitionError(
            f"{where}: {cls.__name__}.__call__ returned shape {shape} for inputs of shape "
            f"{np.shape(probe[0])}: it must return one force per sample")
