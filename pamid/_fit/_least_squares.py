"""Batched least squares: every muscle of a batch fitted in one jit-compiled, vmapped solve.

Solver path (measured in ``benchmarks/fit_batch.py``): for the Sárosi model, "gauss-newton"
is the written-out batched Gauss–Newton of ``pamid/_solvers/_sarosi.py`` (its own coarse variable-
projection start, one loop over the samples per iteration); for other models it is
optimistix's, from the model's start. Under a batched loop every lane runs until the slowest
converges, so what matters for the batch is that no lane needs many steps; from a
variable-projection start none does. Levenberg–Marquardt and jaxopt's Levenberg–Marquardt
(from the 24-point variable-projection start) and pure variable projection are available
for comparison; fits with bounds on the constants run pamid's one Levenberg–Marquardt
loop with projected bounds (``pamid/_solvers/_levenberg_marquardt.py``).

:func:`fit_lanes` (what ``fit_least_squares`` runs) adds several starts and physical
bounds around :func:`solve`: the top start candidates of a model as extra lanes of one
batched solve, a second try from several starts for lanes one start did not serve, and a
refit within the bounds of only the lanes whose constants left them (a constant held on its
bound while its gradient points out of the box).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._inference import unscaled_covariance
from .._lanes._batch import FitData, LaneView, map_lanes, map_shared, padded_rows
from .._solvers import (  # noqa: F401 - residuals: where the weighted residual is found
    CONVERGED,
    MAX_STEPS,
    NONFINITE,
    SOLVER_CLASSES,
    STALLED,
    ProjectedLevenbergMarquardt,
    Solution,
    Solver,
    as_solver,
    residuals,
    residuals_and_jacobian,
)
from ._spec import ModelSpec

#: The solvers' names (``--solver``); the solvers themselves are values (``_solvers``).
SOLVERS = tuple(SOLVER_CLASSES)


@functools.partial(jax.jit, static_argnames=("spec", "solver", "max_steps", "rtol", "atol"))
def _solve_batch(spec, solver, theta0, x, y, w, max_steps, rtol, atol):
    """Solve every lane from its start by ``solver`` (a :class:`Solver` or its name);
    returns theta, success flag and step count per lane."""
    return as_solver(solver).run(spec, theta0, x, y, w, max_steps, rtol, atol)


@functools.partial(jax.jit, static_argnames=("spec", "solver", "make", "max_steps", "outputs"))
def _own_loop(spec, solver, make, max_steps, outputs, source, theta0, mask, bounds, lanes):
    """Every lane by pamid's own loop (``solver``, a
    :class:`~pamid._solvers.ProjectedLevenbergMarquardt`): from ``theta0`` (clipped into
    ``bounds``, per lane, where given), the constants where ``mask`` is 0 held, a constant
    on a bound whose gradient points out of the box held there (a converged lane is a
    constrained optimum: Karush–Kuhn–Tucker). A lane's data are ``lanes``' (x, y, w), or
    ``make(source, *lanes)`` (a :class:`~pamid._lanes._batch.LaneView`)."""

    def one(theta0, mask, bounds, lane):
        x, y, w = lane if make is None else make(source, *lane)
        if bounds is not None:
            theta0 = jnp.clip(theta0, *bounds)
        sol = solver.lane(spec, theta0, x, y, w, mask, bounds, max_steps=max_steps)
        out = {"params": sol.params, "result": sol.result, "steps": sol.steps,
               "free": sol.free, "sse": sol.sse, "decrement": sol.decrement}
        if "jacobian" in outputs:
            out["residual"], out["jac"] = sol.residual, sol.jac
        if "prediction" in outputs:
            out["prediction"] = spec.predict(sol.params, x)
        return out

    return jax.vmap(one)(theta0, mask, bounds, lanes)


@functools.partial(jax.jit, static_argnames=("spec",))
def _statistics(spec, theta, x, y, w):
    """SSE, Jacobian-based covariance factor, and the correlation of data and model."""

    def one(theta, x, y, w):
        r, jac = residuals_and_jacobian(spec, theta, x, y, w)
        # (JᵀJ)⁻¹ and the rank test, pamid's one of each (``pamid._inference``): through
        # the SVD of the column-scaled J (Q·R first), +inf where J is rank-deficient.
        jtj_inv, _, full_rank = unscaled_covariance(jac)
        model = spec.predict(theta, x)
        n = jnp.sum(w)
        mean_y = jnp.sum(w * y) / n
        mean_m = jnp.sum(w * model) / n
        cov_ym = jnp.sum(w * (y - mean_y) * (model - mean_m))
        var_y = jnp.sum(w * (y - mean_y) ** 2)
        corr = cov_ym / jnp.sqrt(var_y * jnp.sum(w * (model - mean_m) ** 2))
        return jnp.sum(r**2), jtj_inv, corr, n, full_rank

    return jax.vmap(one)(theta, x, y, w)


def least_squares(
    model: ModelSpec,
    data: FitData | LaneView,
    *,
    solver: Solver | str = "gauss-newton",
    theta0=None,
    bounds=None,
    weights=None,
    mask=None,
    max_steps: int = 100,
    rtol: float = 1e-10,
    atol: float = 1e-10,
    with_statistics: bool = False,
    outputs: tuple[str, ...] = (),
    chunk: int | None = None,
) -> Solution:
    """pamid's one batched least-squares entry: ``model`` fitted to every lane of ``data``
    (a muscle, a fold, a start …) in one compiled call, by ``solver`` (a value of
    :mod:`pamid._solvers`, or its name).

    Args:
        model: the model, a :class:`~pamid._fit._spec.ModelSpec` (a ``ForceModel`` class's
            view, or a model made of another: pooled, smooth in l0, with effects …).
        data: the packed batch, one lane per row of its arrays; or a
            :class:`~pamid._lanes._batch.LaneView`, whose lanes are made inside the
            compiled call from the arrays they share (the diagnosis's candidate sets ×
            folds of each muscle), run in calls of exactly ``chunk`` lanes.
        solver: the solver; where the model registers written-out kernels of its kind
            (Sárosi's Gauss–Newton), those run, from their own start. With ``bounds``,
            ``mask`` or a lane view, pamid's own loop runs:
            :class:`~pamid._solvers.ProjectedLevenbergMarquardt` as given (its tolerances
            are its fields), or, for another solver, with its defaults (a stopping test
            of 1e-12 of the SSE plus 1e-20 per sample) and at least 200 steps.
        theta0: starts (lanes, p); default the model's start.
        bounds: ``(lower, upper)`` of the constants, (p,) or per lane (lanes, p): every
            lane is fitted within them by pamid's own loop (a constant on a bound whose
            gradient points out of the box held there), from ``theta0`` clipped into them.
        weights: per-sample weights (lanes, rows) that multiply the data's own (padding
            stays 0): a fold of a cross-validation is this call with 0 on its held-out rows.
        mask: (lanes, p), 0 where a constant is held at its start (pamid's own loop).
        max_steps, rtol, atol: the step budget and stopping tolerances.
        outputs: more of each lane's solution from pamid's own loop: ``"jacobian"`` (the
            weighted residual and its Jacobian), ``"prediction"`` (the model on every
            sample, weight 0 too).
        chunk: lanes per compiled call (default: :func:`~pamid._lanes._batch.map_lanes`'
            own).
        with_statistics: (not with ``bounds``) also the statistics at the constants
            (:func:`statistics` with the lag-1 sums) where the model's written-out
            Gauss–Newton solves, from the same compiled call (one program and one pass of
            the samples fewer: benchmarks/README.md, "The solve and its statistics in one
            program"); None for the other solvers, whose caller computes them once with
            :func:`statistics` at the constants it keeps (one program for every solver,
            and no second pass where a retry changes some lanes).

    Returns:
        A :class:`~pamid._solvers.Solution` with a leading lane axis, as NumPy arrays:
        ``params``, ``result`` (``converged``; ``nonfinite`` where a constant is not
        finite; ``max_steps`` where the budget ran out; ``stalled`` where the solver
        stopped short of its tolerance before that), ``steps``, and with
        ``with_statistics`` the kernel's ``statistics`` and their ``sse``; from pamid's own
        loop also ``sse``, ``free`` (0 where a constant was held), ``decrement`` and the
        ``outputs`` asked for.
    """
    solver = as_solver(solver)
    constrained = bounds is not None or mask is not None
    if (constrained or isinstance(data, LaneView)
            or isinstance(solver, ProjectedLevenbergMarquardt)):
        # (with_statistics: None, as for every solver without a written-out kernel.)
        if with_statistics and constrained:
            raise ValueError("with_statistics is for fits without bounds or held constants")
        return _least_squares_own(model, data, solver, theta0, bounds, weights, mask,
                                  max_steps, tuple(outputs), chunk)
    if outputs:
        raise ValueError("outputs are given by pamid's own loop (bounds, a mask, or "
                         "solver=ProjectedLevenbergMarquardt())")
    data = _weighted(data, weights)
    # Through the class: an equinox module binds a method anew on every access (a
    # BoundMethod module, about 85 µs each here), which was a third of a warm one-muscle fit.
    kind = type(solver)
    kind.check(solver, model)
    kernel = kind.kernel(solver, model)
    fast = model.kernels
    budget = max_steps
    stats = None
    if kernel is not None:
        # The model's registered written-out solver, with its own start.
        start = () if theta0 is None else (_host(theta0),)
        if with_statistics:
            theta, ok, steps, stats = map_lanes(
                lambda x, y, w, c, *t0: _fit_statistics(
                    model, x, y, w, c, *t0, max_steps=max_steps, rtol=rtol, atol=atol
                ),
                data.x, data.y, data.w, data.curve, *start,
                cache_key=(f"{fast.key}_gauss_newton_statistics", max_steps, rtol, atol),
            )
        else:
            theta, ok, steps = map_lanes(
                lambda x, y, w, *t0: kernel(
                    x, y, w, *t0, max_steps=max_steps, rtol=rtol, atol=atol
                ),
                data.x, data.y, data.w, *start,
                cache_key=(f"{fast.key}_gauss_newton", max_steps, rtol, atol),
            )
        return _solution(theta, ok, steps, budget, stats)
    if theta0 is None:
        theta0 = _start_values(model, data)
    theta, ok, steps = map_lanes(
        lambda t0, x, y, w: _solve_batch(model, solver, t0, x, y, w, max_steps, rtol, atol),
        _host(theta0), data.x, data.y, data.w,
        cache_key=_key("solve", model, solver.name, max_steps, rtol, atol),
    )
    return _solution(theta, ok, steps, budget, stats)


def _weighted(data, weights):
    """``data`` with its weights multiplied by ``weights`` (lanes, rows)."""
    if weights is None:
        return data
    if isinstance(data, LaneView):
        raise ValueError("a lane view makes its own weights: give weights with FitData")
    weights = np.asarray(weights, dtype=np.float64)
    if weights.shape != tuple(np.shape(data.w)):
        raise ValueError(f"weights of shape {weights.shape}; the data's lanes and rows "
                         f"are {tuple(np.shape(data.w))}")
    if not np.all(np.isfinite(weights) & (weights >= 0)):
        raise ValueError("weights must be finite and ≥ 0")
    return data._replace(w=jax.device_put(np.asarray(data.w) * weights))


def _least_squares_own(model, data, solver, theta0, bounds, weights, mask, max_steps,
                       outputs, chunk) -> Solution:
    """:func:`least_squares` by pamid's own loop (its docstring): masks, bounds per lane,
    lane views, and more of each lane's solution."""
    unknown = set(outputs) - {"jacobian", "prediction"}
    if unknown:
        raise ValueError(f"unknown outputs {sorted(unknown)}: ask for 'jacobian', "
                         "'prediction'")
    data = _weighted(data, weights)
    if not isinstance(solver, ProjectedLevenbergMarquardt):
        # A fit within bounds, whatever the solver: the own loop, to its tight tolerance.
        solver = ProjectedLevenbergMarquardt()
        max_steps = max(max_steps, 200)
    view = isinstance(data, LaneView)
    n = data.n_lanes if view else int(np.shape(data.y)[0])
    if theta0 is None:
        if view:
            raise ValueError("a lane view needs its starts, theta0")
        theta0 = _start_values(model, data)
    theta0 = np.broadcast_to(_host(theta0), (n, model.n_params))
    per_lane = lambda a: None if a is None else np.broadcast_to(  # noqa: E731
        np.asarray(a, dtype=np.float64), (n, model.n_params))
    mask = per_lane(mask)
    if bounds is not None:
        bounds = tuple(per_lane(b) for b in bounds)
        if np.any(bounds[0] > bounds[1]):
            raise ValueError("every lower bound must be at most its upper bound")
    outputs = tuple(sorted(outputs))
    run = functools.partial(_own_loop, model, solver, data.make if view else None,
                            max_steps, outputs)
    key = _key("own_loop", model, solver, max_steps, outputs,
               None if not view else f"{data.make.__module__}.{data.make.__qualname__}")
    if not view:
        out = map_lanes(lambda t0, m, b, *lane: run(None, t0, m, b, lane), theta0, mask,
                        bounds, data.x, data.y, data.w, chunk=chunk, cache_key=key)
    else:
        out = map_shared(run, data.source, theta0, mask, bounds, tuple(data.index),
                         chunk=chunk or n, cache_key=key)
    result = np.asarray(out["result"])
    theta = np.asarray(out["params"])
    result = np.where(np.all(np.isfinite(theta), axis=-1), result, NONFINITE)
    return Solution(params=theta, residual=out.get("residual"), jac=out.get("jac"),
                    sse=np.asarray(out["sse"]), result=result,
                    steps=np.asarray(out["steps"]), free=np.asarray(out["free"]),
                    prediction=out.get("prediction"),
                    decrement=np.asarray(out["decrement"]))


def solve(spec: ModelSpec, data: FitData, *, solver: str = "gauss-newton", theta0=None,
          bounds=None, max_steps: int = 100, rtol: float = 1e-10, atol: float = 1e-10,
          with_statistics: bool = False):
    """:func:`least_squares` as a tuple, as ``pamid.engine.solve`` has returned it:
    ``(theta, converged, n_steps)`` as NumPy arrays with a leading muscle axis, and with
    ``with_statistics`` a fourth item, the kernel's statistics at those constants (None
    for the other solvers)."""
    sol = least_squares(spec, data, solver=solver, theta0=theta0, bounds=bounds,
                        max_steps=max_steps, rtol=rtol, atol=atol,
                        with_statistics=with_statistics)
    out = (sol.params, sol.converged, sol.steps)
    return (*out, sol.statistics) if with_statistics else out


def _solution(theta, ok, steps, budget: int, stats=None) -> Solution:
    """A batched solve's outputs as a :class:`~pamid._solvers.Solution` of NumPy arrays: a
    lane whose constants are not all finite has not converged (``nonfinite``), one that
    did not converge ran out of its ``budget`` of steps or stopped short (``stalled``)."""
    theta, steps = np.asarray(theta), np.asarray(steps)
    finite = np.all(np.isfinite(theta), axis=-1)
    result = np.where(~finite, NONFINITE, np.where(
        np.asarray(ok), CONVERGED, np.where(steps >= budget, MAX_STEPS, STALLED)))
    stats = None if stats is None else tuple(np.asarray(a) for a in stats)
    return Solution(params=theta, residual=None, jac=None,
                    sse=None if stats is None else stats[0], result=result, steps=steps,
                    free=None, statistics=stats)


@functools.partial(jax.jit, static_argnames=("spec", "max_steps", "rtol", "atol"))
def _fit_statistics(spec, x, y, w, curve, *theta0, max_steps, rtol, atol):
    """The model's registered Gauss–Newton (from its own start without ``theta0``) and
    :func:`statistics` (with the lag-1 sums within ``curve``) at its result, in one
    program."""
    theta, ok, steps = spec.kernels.gauss_newton(
        x, y, w, *theta0, max_steps=max_steps, rtol=rtol, atol=atol)
    return theta, ok, steps, _statistics_lag1(spec, theta, x, y, w, curve)


def _host(theta) -> np.ndarray:
    """Constants as a float64 NumPy array: a compiled call takes them to the device itself
    (``jnp.asarray`` first cost 13 µs of a one-muscle fit's 0.4 ms)."""
    return np.asarray(theta, dtype=np.float64)


def _start_values(spec: ModelSpec, data: FitData):
    """``spec.start`` of every lane. pamid's own specs' starts run compiled from their
    second call on (as they do through the exported programs of the command line): op by
    op, the generic start's ``candidates(...)[0][:, 0]`` was a tenth of a one-muscle
    Cullinan fit. The first call runs as written: the generic start does work outside JAX
    on first use (finding the linear constants), which cannot be traced, and a failed trace
    was measured to leave later compiled calls slower (benchmarks/README.md, "Figures that
    used to live in docstrings", (f)). A start that cannot be compiled (a registered
    user's, in NumPy) keeps running as written."""
    key = _key("start", spec)
    compiled = _COMPILED_STARTS.get(spec.start) if key is not None else None
    if compiled is not None:
        try:
            return map_lanes(compiled, data.x, data.y, data.w, cache_key=key)
        except _TRACING_ERRORS:
            _COMPILED_STARTS[spec.start] = None
    out = map_lanes(spec.start, data.x, data.y, data.w, cache_key=key)
    if key is not None:
        _COMPILED_STARTS.setdefault(spec.start, jax.jit(spec.start))
    return out


#: Compiled starts by start function (None: it cannot be compiled).
_COMPILED_STARTS: dict = {}
_TRACING_ERRORS = (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError,
                   jax.errors.TracerBoolConversionError, jax.errors.TracerIntegerConversionError)


def _key(what: str, spec: ModelSpec, *static) -> tuple | None:
    """The ``cache_key`` of a batched call (None, no caching, for specs not pamid's own)."""
    name = spec.program_key
    return None if name is None else (what, *name, *static)


def lag1_sums(r, groups, xp=np):
    """The sums behind :func:`lag1_autocorrelation`, along the last (row) axis: Σ rₜr_{t−1}
    over pairs of neighbouring rows of one group, Σ rₜ² over the rows of a group, and the
    number of pairs. ``xp``: NumPy, or ``jax.numpy`` inside a compiled program (the fit
    takes them from its statistics program, :func:`statistics`)."""
    g0, g1 = groups[..., 1:], groups[..., :-1]
    pair = (g0 == g1) & (g0 >= 0)
    num = xp.sum(pair * r[..., 1:] * r[..., :-1], axis=-1)
    den = xp.sum(xp.where(groups >= 0, r * r, 0.0), axis=-1)
    return num, den, xp.sum(pair, axis=-1)


@functools.partial(jax.jit, static_argnames=("spec",))
def _statistics_lag1(spec, theta, x, y, w, curve):
    """:func:`statistics`' program with the lag-1 sums of the residual within ``curve``
    (:func:`lag1_sums`) in the same compiled call: from the fast
    path's own pass over the samples where its statistics take ``curve=`` (Sárosi's
    ``sarosi_statistics``), else from the residual, computed once more."""
    fast = spec.kernels
    if fast is not None and fast.statistics_take_curve:
        return fast.statistics(theta, x, y, w, curve=curve)
    if fast is not None:
        stats = fast.statistics(theta, x, y, w)
    else:
        stats = _statistics(spec, theta, x, y, w)
    r = jax.vmap(lambda t, x, y, w: residuals(spec, t, x, y, w))(theta, x, y, w)
    return (*stats, *lag1_sums(r, curve, jnp))


def statistics(spec: ModelSpec, theta, data: FitData, *, lag1: bool = False):
    """Per muscle: SSE, (JᵀJ)⁻¹, correlation of model and data, sample count, and whether
    the Jacobian has full rank at the optimum (the constants are identifiable).

    For the Sárosi model, the written-out sums of ``sarosi_statistics`` (two passes over the
    samples; about 6× faster than a Jacobian, QR and SVD per lane, the same inverse to
    1e-10: ``benchmarks/profile_pieces.py --only-cores``, figures in benchmarks/README.md,
    "Figures that used to live in docstrings", (f)); for other models, the Jacobian (the
    model's ``value_and_jacobian``: :func:`pamid._solvers.residuals_and_jacobian`) and an
    SVD.

    ``lag1``: also the sums of the residual's lag-1 autocorrelation within ``data.curve``
    (:func:`pamid._fit._least_squares.lag1_sums`: three more arrays), from the same compiled
    call (a pass of its own and its round trip cost the fit of one muscle more than a
    quarter of its time: the same README section, (f))."""
    fast = spec.kernels
    if lag1:
        out = map_lanes(
            lambda t, x, y, w, c: _statistics_lag1(spec, t, x, y, w, c), _host(theta),
            data.x, data.y, data.w, data.curve,
            cache_key=_key("statistics_lag1", spec),
        )
        return tuple(np.asarray(a) for a in out)
    if fast is not None:
        out = map_lanes(
            fast.statistics, _host(theta), data.x, data.y, data.w,
            cache_key=(f"{fast.key}_statistics",),
        )
        return tuple(np.asarray(a) for a in out)
    out = map_lanes(
        lambda t, x, y, w: _statistics(spec, t, x, y, w), _host(theta), data.x, data.y,
        data.w, cache_key=_key("statistics", spec),
    )
    return tuple(np.asarray(a) for a in out)


# ----------------------------------------------------------------------------------------
# Several starts, physical bounds, and what each lane's fit says about its constants
# ----------------------------------------------------------------------------------------

#: Starts per muscle of a fit from a model's start candidates (``spec.candidates``, best
#: first), solved as extra lanes of the same batched solve, the best converged kept. One:
#: on the Martens DMSP-10-250 map, the AARL 10 mm file and the bundled virtual file, the
#: first start of every model reached the best optimum that 2, 4 or 8 starts found (SSE
#: within 1e-13; Sárosi's also that of SciPy from 50 a3 starts), and 8 starts took up to
#: 2.5× the time (``benchmarks/start_settings.py``, ``benchmarks/README.md``).
DEFAULT_STARTS = 1
#: Starts per muscle of the second try, for the muscles one start did not serve (not
#: converged, or constants outside their bounds).
RETRY_STARTS = 4


@dataclasses.dataclass(frozen=True)
class LaneFit:
    """The constants of every lane with what the fit learnt on the way (NumPy arrays with a
    leading muscle axis).

    Attributes:
        theta, ok, steps: the constants, the solver's verdict and its step count.
        free_theta: the constants of the fit without bounds (``theta`` where no bound
            applies).
        left_bounds: the fit without bounds ended outside the bounds (or not finite), and
            the lane was refitted within them.
        ran_away: of those, the lanes whose fit without bounds found no determined optimum
            (not converged, not finite, or a rank-deficient Jacobian where it stopped): a
            constant ran off, the data do not pin it.
        at_lower, at_upper: (M, p) constants on their lower / upper bound.
        starts: starts per muscle of the main solve.
        statistics: :func:`statistics` ``(..., lag1=True)`` at ``theta`` where ``fit_lanes``
            was asked for them and its main solve gave them (no lane changed after it);
            else None.
    """

    theta: np.ndarray
    ok: np.ndarray
    steps: np.ndarray
    free_theta: np.ndarray
    left_bounds: np.ndarray
    ran_away: np.ndarray
    at_lower: np.ndarray
    at_upper: np.ndarray
    starts: int
    statistics: tuple | None = None


@functools.partial(jax.jit, static_argnames=("spec",))
def _lane_sse(spec, theta, x, y, w):
    """Σ w·(model − data)² per lane; +inf where it is not finite."""
    sse = jax.vmap(lambda t, x, y, w: jnp.sum(residuals(spec, t, x, y, w) ** 2))(theta, x, y, w)
    return jnp.where(jnp.isfinite(sse), sse, jnp.inf)


def lane_sse(spec, theta, data: FitData) -> np.ndarray:
    """Σ w·(model − data)² of every lane at its constants (+inf where not finite), in calls
    of the lanes' size classes (:func:`._batch.map_lanes`)."""
    return np.asarray(map_lanes(
        lambda t, x, y, w: _lane_sse(spec, t, x, y, w),
        np.asarray(theta, dtype=np.float64), data.x, data.y, data.w,
        cache_key=_key("lane_sse", spec)))


def model_at(spec, theta, x):
    """The model of one muscle at ``theta`` on its inputs ``x`` (a tuple of 1-D arrays),
    compiled once per spec and padded sample count (:func:`._batch.padded_rows`): op by
    op, the diagnosis' per-muscle model values and Jacobians took 1.5 s of a 4.5 s
    diagnosis of 100 muscles."""
    return _on_padded_rows(_model_at, spec, theta, x)


def model_jacobian(spec, theta, x):
    """∂F/∂θ of one muscle at ``theta`` (n × p), compiled as :func:`model_at` is."""
    return _on_padded_rows(_model_jacobian, spec, theta, x)


def _on_padded_rows(fn, spec, theta, x):
    """``fn(spec, theta, x)`` on the rows of ``x`` padded (by repeating the last) to
    :func:`._batch.padded_rows`, the padding's rows dropped: a file of another row count in
    the same size class runs the same program."""
    x = tuple(np.asarray(a, dtype=np.float64) for a in x)
    n = len(x[0]) if x else 0
    size = padded_rows(n)
    if size > n > 0:
        x = tuple(np.concatenate([a, np.repeat(a[-1:], size - n)]) for a in x)
    return np.asarray(fn(spec, jnp.asarray(theta, dtype=jnp.float64), x))[:n]


@functools.partial(jax.jit, static_argnames="spec")
def _model_at(spec, theta, x):
    return spec.predict(theta, x)


@functools.partial(jax.jit, static_argnames="spec")
def _model_jacobian(spec, theta, x):
    return spec.jacobian(theta, x)


def _repeat_lanes(data: FitData, k: int) -> FitData:
    """Every lane of ``data`` ``k`` times in a row (lane i → lanes i·k … i·k + k − 1). In
    NumPy, then onto the device (as jnp operations, each a compiled program per shape)."""
    rep = lambda a: jax.device_put(np.repeat(np.asarray(a), k, axis=0))  # noqa: E731
    return data._replace(x=tuple(rep(a) for a in data.x), y=rep(data.y), w=rep(data.w),
                         curve=rep(data.curve))


def _take_lanes(data: FitData, idx) -> FitData:
    take = lambda a: jax.device_put(np.asarray(a)[np.asarray(idx)])  # noqa: E731
    return data._replace(x=tuple(take(a) for a in data.x), y=take(data.y), w=take(data.w),
                         curve=take(data.curve))


def _best_of(spec, theta, ok, steps, data_rep, k, lower=None, upper=None):
    """Per muscle, the best of its ``k`` lanes (rows i·k …): the lowest SSE among the
    converged ones within the bounds (``lower``, ``upper``; where none is, among the
    converged ones), else the lowest SSE of all."""
    sse = lane_sse(spec, theta, data_rep)
    sse = np.where(np.all(np.isfinite(theta), axis=-1), sse, np.inf).reshape(-1, k)
    ok = np.asarray(ok).reshape(-1, k)
    if lower is not None:
        with np.errstate(invalid="ignore"):
            inside = np.all((theta >= lower) & (theta <= upper), axis=-1).reshape(-1, k)
        ok_inside = ok & inside
        any_inside = np.any(ok_inside, axis=1, keepdims=True)
        ok = np.where(any_inside, ok_inside, ok)
        if not np.all(any_inside):
            # No lane of a muscle converged within the bounds: the one that will be refitted
            # within them is the one whose point, clipped into them, fits best (a far-away
            # optimum with a lower SSE can clip to a poor start).
            clipped = lane_sse(spec, np.clip(theta, lower, upper), data_rep).reshape(-1, k)
            sse = np.where(any_inside, sse, clipped)
    score = np.where(ok, sse, np.inf)
    pick = np.where(np.any(np.isfinite(score), axis=1), np.argmin(score, axis=1),
                    np.argmin(sse, axis=1))
    rows = np.arange(len(pick)) * k + pick
    return np.asarray(theta)[rows], ok.reshape(-1)[rows], np.asarray(steps)[rows]


_CANDIDATES: dict = {}


def start_candidates(spec: ModelSpec, data: FitData, bounds=None):
    """Start candidates of every muscle, best first: ``(theta (M, K, p), sse (M, K))``.

    The model's own (``spec.candidates``) where it has them; for a model with its own
    start and a registered fast path (Sárosi), the same variable projection
    (:mod:`._start`) over trial values of its nonlinear constants within ``bounds`` (or the
    spec's). None where neither is possible (a nonlinear constant without finite bounds)."""
    if spec.candidates is not None:
        return map_lanes(spec.candidates, data.x, data.y, data.w,
                         cache_key=_key("candidates", spec))
    lower, upper = bounds_arrays(spec, bounds)
    if spec.model_class is None or lower is None:
        return None
    key = (id(spec), tuple(lower.tolist()), tuple(upper.tolist()))
    if key not in _CANDIDATES:
        from ._start import linear_constants, projected_candidates, trial_values

        finite = np.isfinite(lower) & np.isfinite(upper)
        with np.errstate(invalid="ignore"):
            reference = np.where(finite, 0.5 * (lower + upper), 1.0)
        inputs = tuple(spec.model_class.inputs[: len(spec.columns)])
        linear = linear_constants(spec.predict, spec.n_params, inputs, reference)
        if not np.all(finite | linear):
            _CANDIDATES[key] = None
        else:
            trials = trial_values(reference, lower, upper, ~linear)
            _CANDIDATES[key] = jax.jit(projected_candidates(spec.predict, linear, trials,
                                                            lower, upper))
    fn = _CANDIDATES[key]
    if fn is None:
        return None
    return map_lanes(fn, data.x, data.y, data.w,
                     cache_key=_key("candidates_in_bounds", spec, key[1], key[2]))


def bounds_arrays(spec: ModelSpec, bounds):
    """The bounds of a fit as two float arrays of length p, or (None, None): ``bounds``
    where it gives a finite value, the model's physical bounds (``spec.bounds``) elsewhere."""
    if bounds is None and spec.bounds is None:
        return None, None
    if bounds is None and id(spec) in _OWN_BOUNDS and _OWN_BOUNDS[id(spec)][0] is spec:
        return _OWN_BOUNDS[id(spec)][1]
    p = spec.n_params
    own = spec.bounds if spec.bounds is not None else (-np.inf, np.inf)
    own_lower, own_upper = (np.broadcast_to(np.asarray(b, dtype=np.float64), (p,)) for b in own)
    if bounds is None:
        lower, upper = own_lower.copy(), own_upper.copy()
    else:
        lower, upper = (np.broadcast_to(np.asarray(b, dtype=np.float64), (p,)).copy()
                        for b in bounds)
        if np.any(lower > upper):
            raise ValueError("every lower bound must be at most its upper bound")
        user_lower, user_upper = np.isfinite(lower), np.isfinite(upper)
        lower = np.where(user_lower, lower, own_lower)
        upper = np.where(user_upper, upper, own_upper)
        # A model bound that contradicts the user's gives way to it.
        clash = lower > upper
        lower = np.where(clash & ~user_lower, -np.inf, lower)
        upper = np.where(clash & ~user_upper, np.inf, upper)
    out = (None, None) if np.all(np.isinf(lower)) and np.all(np.isinf(upper)) else (lower, upper)
    if bounds is None:
        _OWN_BOUNDS[id(spec)] = (spec, out)
    return out


#: The spec's own bounds as arrays, by spec (``bounds_arrays``: once per spec, not per fit).
_OWN_BOUNDS: dict = {}


def _multi_start(spec, data, solver, k, max_steps, rtol, atol, lower=None, upper=None):
    """The best of the top ``k`` start candidates of every muscle, solved as k lanes per
    muscle in one batched call; None where the model has no candidates."""
    cands = start_candidates(spec, data)
    if cands is None:
        return None
    theta0 = np.asarray(cands[0])
    if spec.candidates is None:  # the model's own start first, then the candidates
        own = _start_values(spec, data)
        theta0 = np.concatenate([np.asarray(own)[:, None], theta0], axis=1)
    k = min(k, theta0.shape[1])
    rep = _repeat_lanes(data, k)
    sol = least_squares(spec, rep, solver=solver,
                        theta0=theta0[:, :k].reshape(-1, spec.n_params),
                        max_steps=max_steps, rtol=rtol, atol=atol)
    return _best_of(spec, sol.params, sol.converged, sol.steps, rep, k, lower, upper)


def _rank_deficient(spec, theta, data, lanes, free=None) -> np.ndarray:
    """For the given lanes: whether the Jacobian (of the ``free`` constants, (M, p) mask,
    default all) fails the rank criterion at ``theta``; True where it is not finite."""
    out = np.zeros(len(lanes), dtype=bool)
    for j, i in enumerate(lanes):
        jac = _jacobian_rows(spec, theta[i], data, i)
        cols = np.ones(spec.n_params, bool) if free is None else free[i]
        if not np.any(cols):
            continue
        from .._inference import RANK_RTOL, null_direction

        ratio, _ = null_direction(jac[:, cols])
        out[j] = not ratio > RANK_RTOL
    return out


def _jacobian_rows(spec, theta, data: FitData, i: int) -> np.ndarray:
    """Lane ``i``'s Jacobian at ``theta`` on its rows of positive weight."""
    w = np.asarray(data.w[i])
    jac = np.asarray(model_jacobian(spec, jnp.asarray(theta, dtype=jnp.float64),
                                    tuple(jnp.asarray(a[i]) for a in data.x)))
    keep = w > 0
    return np.sqrt(w[keep])[:, None] * jac[keep]  # that of the residuals w^½·(model − data)


def _linear_in_all(spec: ModelSpec) -> bool:
    """Whether ``spec`` is linear in every constant (pamid's start knows it: ``spec.linear``;
    False for a model that brings its own start or kernels)."""
    return spec.kernels is None and spec.linear is not None and bool(np.all(spec.linear()))


def _linear_fit(spec: ModelSpec, data: FitData):
    """``(theta, converged, n_steps)`` of a model linear in every constant: its weighted
    least-squares fit without bounds, from the start's solve (:mod:`._start`: normal
    equations refined once, or an SVD), which is the Gauss–Newton step that reaches the
    optimum of a linear model from any point. One step; converged where finite (a design
    that cannot determine a constant is found by :func:`statistics`' rank test)."""
    theta = map_lanes(lambda x, y, w: spec.candidates(x, y, w, clip=False)[0][:, 0],
                      data.x, data.y, data.w, cache_key=_key("linear_fit", spec))
    theta = np.asarray(theta)
    ok = np.all(np.isfinite(theta), axis=-1)
    return theta, ok, np.ones(len(theta), dtype=np.int64)


def first_solve(spec: ModelSpec, data: FitData, *, solver: str, starts: int, theta0=None,
                max_steps: int = 100, rtol: float = 1e-10, atol: float = 1e-10,
                bounds=(None, None), with_statistics: bool = False):
    """Step 1 of :func:`fit_lanes`, the solve without bounds: a model linear in every
    constant solved directly; several starts as extra lanes where ``starts`` > 1 (not for
    a registered kernel, which has its own start); else one :func:`least_squares`, which
    also gives the statistics where ``with_statistics`` asks for them.

    Returns ``((theta, ok, steps), statistics or None, linear, several)``: ``several`` when
    the lanes already come from several starts (or were solved), so that no second try
    from other starts would help."""
    solver = as_solver(solver)
    linear = theta0 is None and solver.restarts and _linear_in_all(spec)
    out = None
    if linear:
        out = _linear_fit(spec, data)
    elif theta0 is None and starts > 1 and type(solver).kernel(solver, spec) is None:
        out = _multi_start(spec, data, solver, starts, max_steps, rtol, atol, *bounds)
    if out is not None:
        return out, None, linear, True
    sol = least_squares(spec, data, solver=solver, theta0=theta0, max_steps=max_steps,
                        rtol=rtol, atol=atol, with_statistics=with_statistics)
    return (sol.params, sol.converged, sol.steps), sol.statistics, linear, False


def fit_lanes(spec: ModelSpec, data: FitData, *, solver: str = "gauss-newton", bounds=None,
              starts: int | None = None, theta0=None, max_steps: int = 100,
              rtol: float = 1e-10, atol: float = 1e-10,
              with_statistics: bool = False) -> LaneFit:
    """Fit every muscle, from several starts where one is not enough, within bounds.

    1. Without bounds (fast): the model's registered kernels (Sárosi) from their own start;
       any other model from its top ``starts`` start candidates (default
       :data:`DEFAULT_STARTS`) as extra lanes of one batched solve, the best converged kept.
    2. Lanes that did not converge or left the bounds (``bounds``, else the model's physical
       ``spec.bounds``) start again from the top :data:`RETRY_STARTS` candidates (for
       Sárosi: trial values of a3 within its bounds).
    3. Lanes still outside the bounds are refitted within them from the clipped point by the
       one loop with projected bounds (:func:`_own_loop`); constants on a bound are
       marked.
       A lane whose fit without bounds found no determined optimum is marked as ran away.

    ``with_statistics``: the main solve of step 1 also returns the statistics at its
    constants (:func:`least_squares`); they are kept in ``LaneFit.statistics`` when no
    lane changed after it.
    """
    solver = as_solver(solver)
    k = DEFAULT_STARTS if starts is None else max(int(starts), 1)
    k_retry = max(k, RETRY_STARTS)
    lower, upper = bounds_arrays(spec, bounds)
    out, stats, linear, several = first_solve(
        spec, data, solver=solver, starts=k, theta0=theta0, max_steps=max_steps, rtol=rtol,
        atol=atol, bounds=(lower, upper), with_statistics=with_statistics)
    theta, ok, steps = (np.array(a) for a in out)
    m, p = theta.shape

    def outside(t):
        # (Comparisons with NaN are False without a warning: no errstate, 5 µs a call.)
        bad = ~np.isfinite(t).all(axis=-1)
        return bad if lower is None else bad | ((t < lower) | (t > upper)).any(axis=-1)

    # 2. Another try from several starts for the lanes one start did not serve.
    out_now = outside(theta)
    retry = np.flatnonzero(~ok | out_now)
    if (retry.size and theta0 is None and not linear and not (several and k >= k_retry)
            and solver.restarts):
        sub = _take_lanes(data, retry)
        cands = start_candidates(spec, sub, bounds)
        if cands is not None:
            kk = min(k_retry, cands[0].shape[1])
            rep = _repeat_lanes(sub, kk)
            sol = least_squares(spec, rep, solver=solver,
                                theta0=np.asarray(cands[0])[:, :kk].reshape(-1, p),
                                max_steps=max_steps, rtol=rtol, atol=atol)
            t2, ok2, st2 = _best_of(spec, sol.params, sol.converged, sol.steps, rep, kk,
                                    lower, upper)
            sse_old = lane_sse(spec, theta[retry], sub)
            sse_new = lane_sse(spec, t2, sub)
            # Better: in bounds where the old one was not, else converged where the old one
            # was not, else a lower SSE.
            key_old = np.stack([outside(theta[retry]), ~ok[retry], sse_old], -1)
            key_new = np.stack([outside(t2), ~ok2, sse_new], -1)
            better = [tuple(a) < tuple(b) for a, b in zip(key_new, key_old)]
            sel = retry[np.asarray(better, dtype=bool)]
            pos = np.asarray(better, dtype=bool)
            theta[sel], ok[sel], steps[sel] = t2[pos], ok2[pos], steps[sel] + st2[pos]
            out_now = outside(theta)
            if sel.size:
                stats = None  # not at these constants any more
    free_theta = theta.copy()
    free_ok = ok.copy()
    finite = np.all(np.isfinite(theta), axis=-1)
    left = out_now if lower is not None else np.zeros(m, bool)
    ran_away = np.zeros(m, bool)
    at_lower = np.zeros((m, p), bool)
    at_upper = np.zeros((m, p), bool)
    lanes = np.flatnonzero(left)
    if lanes.size:
        sub = _take_lanes(data, lanes)
        # 3. Within the bounds, from the clipped point (the candidates where it is not
        # finite): the one loop with projected bounds, which holds a constant on its bound
        # while the gradient points out of the box.
        start = np.clip(theta[lanes], lower, upper)
        cands = None
        if not np.all(np.isfinite(start)):
            cands = start_candidates(spec, sub, (lower, upper))
            best = (np.asarray(cands[0])[:, 0] if cands is not None else
                    np.broadcast_to(np.where(np.isfinite(lower) & np.isfinite(upper),
                                             0.5 * (lower + upper), np.clip(0.0, lower, upper)),
                                    start.shape))
            start = np.where(np.isfinite(start), start, best)
        sol = least_squares(spec, sub, theta0=start, bounds=(lower, upper),
                            max_steps=max_steps)
        tb = sol.params
        theta[lanes], ok[lanes], steps[lanes] = tb, sol.converged, steps[lanes] + sol.steps
        stats = None
        width = np.where(np.isfinite(upper - lower), upper - lower, 1.0)
        tol = 1e-9 * np.maximum(width, np.maximum(np.abs(np.where(np.isfinite(lower), lower, 0)),
                                                  np.abs(np.where(np.isfinite(upper), upper, 0))))
        at_lower[lanes] = np.abs(tb - lower) <= tol
        at_upper[lanes] = np.abs(tb - upper) <= tol
        # Ran away: the free fit found no determined optimum outside the bounds.
        sound = free_ok[lanes] & finite[lanes]
        check = lanes[sound]
        deficient = _rank_deficient(spec, free_theta, data, check) if check.size else []
        ran = ~sound
        ran[np.flatnonzero(sound)] = deficient
        ran_away[lanes] = ran
    return LaneFit(theta=theta, ok=ok, steps=steps, free_theta=free_theta, left_bounds=left,
                   ran_away=ran_away, at_lower=at_lower, at_upper=at_upper, starts=k,
                   statistics=stats)
