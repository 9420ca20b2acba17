"""The public fitting entry point and its result."""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from .._data._bench import BenchData
from .._inference import cut_at_bounds, scale_covariance
from .._lanes._batch import FitData, pack_rows
from .._solvers import as_solver
from . import _correlated, _intervals
from ._least_squares import DEFAULT_STARTS, bounds_arrays, first_solve, fit_lanes, statistics
from ._spec import ModelSpec, get_model

INTERVAL_KINDS = ("wald", "profile", "bootstrap", "cluster", "hac")


@dataclasses.dataclass(frozen=True, eq=False)
class FitResult:
    """Fitted constants of one model for every muscle of a batch, with 95% intervals.

    Arrays have a leading muscle axis; constants follow ``param_names``. ``ci95`` holds the
    Wald interval (the one the CLI table shows); ``ci95_profile`` and ``ci95_bootstrap`` are
    None unless asked for. ``status`` gives each muscle's result code (:data:`STATUSES`):
    "converged", "at_bound" (converged with constants on a physical bound), "max_steps",
    "not_identifiable" (the data cannot pin a constant: rank-deficient Jacobian, or a
    constant that ran off, then held on its bound), "nonfinite", "too_few_rows"; ``messages``
    says why in words, naming the constants at fault. ``converged`` is True for "converged"
    and "at_bound" only. Constants are reported for every muscle, never dropped.

    It holds results only: :meth:`to_dict` is their plain-data view; JSON text, figures and
    files are written by :mod:`pamid.report`.
    """

    model: str
    param_names: tuple[str, ...]
    param_units: dict[str, str]
    muscles: tuple[str | None, ...]
    theta: np.ndarray
    se: np.ndarray
    ci95: np.ndarray  # (M, p, 2), Wald with Student-t
    ci95_profile: np.ndarray | None
    ci95_bootstrap: np.ndarray | None
    covariance: np.ndarray  # (M, p, p) = s²·(JᵀJ)⁻¹
    n: np.ndarray
    dof: np.ndarray
    sse: np.ndarray
    rmse_N: np.ndarray
    r: np.ndarray
    converged: np.ndarray
    n_steps: np.ndarray
    solver: str
    profile_ok: np.ndarray | None = None
    bootstrap_converged: np.ndarray | None = None
    spec: ModelSpec | None = None
    messages: tuple[str | None, ...] = ()  # per muscle: why it is not "converged", else None
    status: tuple[str, ...] = ()  # per muscle: a result code of STATUSES
    # Intervals that hold under correlated residuals (pamid/_fit/_correlated.py), None
    # unless asked for: cluster-robust CR3 by curve, Newey–West HAC within trials.
    ci95_cluster: np.ndarray | None = None
    ci95_hac: np.ndarray | None = None
    cluster_groups: np.ndarray | None = None  # curves per muscle (G; t on G − 1 dof)
    hac_bandwidth: np.ndarray | None = None  # Andrews' bandwidth, in rows
    residual_lag1: np.ndarray | None = None  # lag-1 autocorrelation of the residual (M,)
    residual_lag1_p: np.ndarray | None = None  # its one-sided p-value (independence)
    interval_notes: tuple[str | None, ...] = ()  # per muscle: which interval holds, why
    interval_shown: str = "wald-t"
    interval_groups: dict | None = None  # {"cluster": "curve", "hac": "trial"}
    # Per muscle, the interval shown (the JSON's "ci95", the table's first columns):
    # "wald-t", or "cluster"/"hac" where the residual is correlated (_correlated.for_fit).
    # ``ci95`` and ``se`` above are always Wald's.
    interval_of: tuple[str, ...] = ()
    se_cluster: np.ndarray | None = None  # standard errors of the cluster interval (M, p)
    se_hac: np.ndarray | None = None
    # (M, p): True where an interval of the constant was cut at the fit's bounds (the
    # model's physical ones, or the user's); None where none was.
    interval_cut: np.ndarray | None = None

    def shown_of(self, i: int) -> str:
        """The kind of interval shown for muscle ``i``: "wald-t", "cluster" or "hac"."""
        return self.interval_of[i] if i < len(self.interval_of) else "wald-t"

    def shown_intervals(self) -> tuple[np.ndarray, np.ndarray]:
        """The shown interval of every muscle and its standard errors: ``(ci (M, p, 2),
        se (M, p))``, Wald's where :meth:`shown_of` says "wald-t"."""
        ci, se = self.ci95.copy(), self.se.copy()
        for kind, c, s in (("cluster", self.ci95_cluster, self.se_cluster),
                           ("hac", self.ci95_hac, self.se_hac)):
            rows = [i for i in range(self.n_muscles) if self.shown_of(i) == kind]
            if rows and c is not None:
                ci[rows], se[rows] = c[rows], s[rows]
        return ci, se

    def status_of(self, i: int) -> str:
        """Muscle ``i``'s result code (:data:`STATUSES`)."""
        if i < len(self.status):
            return self.status[i]
        return "converged" if self.converged[i] else "max_steps"

    def message(self, i: int) -> str | None:
        """Why muscle ``i``'s status is not "converged" (None when it is)."""
        return self.messages[i] if i < len(self.messages) else None

    @property
    def n_muscles(self) -> int:
        return self.theta.shape[0]

    def params(self, i: int = 0):
        """The constants of muscle ``i`` as the model's parameter object (Sarosi, Cullinan)."""
        return self.spec.make(self.theta[i])

    def to_dict(self) -> dict:
        """The fit as plain data (lists, floats, None for NaN): the JSON shape of ``pamid
        fit --json``. The result holds results only; :mod:`pamid.report` writes them
        (``fit_json`` this same document as text, ``plot_fit`` and ``plot_residuals`` the
        figures)."""
        columns, optional = fit_columns(self)
        plain = [_PLAIN[kind](values) for kind, values in columns]
        muscles = [muscle_entry(self, iter(values), optional) for values in zip(*plain)]
        return {**json_head(self), "muscles": muscles}


def json_head(result: FitResult) -> dict:
    """The fit's JSON document without its muscles: model, equation, units, solver,
    intervals."""
    return {
        "model": result.model,
        "equation": result.spec.source,
        "units": dict(result.spec.units),
        "solver": result.solver,
        # What each muscle's "ci95" is: one kind for all, else "per muscle" (its "interval").
        "interval": (kinds.pop() if len(kinds := {result.shown_of(i) for i in
                                                    range(result.n_muscles)} or {"wald-t"}) == 1
                     else "per muscle"),
        "interval_shown": result.interval_shown,
        "interval_groups": dict(result.interval_groups or {}),
    }


def fit_columns(result: FitResult) -> tuple[list[tuple[str, object]],
                                            tuple[tuple[str, bool], ...]]:
    """The muscles' values as columns, in the order :func:`muscle_entry` takes them: one
    ``(kind, values)`` per value of a muscle's entry, ``values`` over the muscles and
    ``kind`` one of "text" (a list of str or None), "int", "bool" (lists) and "float" (an
    array; NaN and ±inf are null in JSON); and the optional values of a constant present,
    as (key, whether it is a pair): the interval kinds computed, and where an interval was
    cut at a bound, that flag. :meth:`FitResult.to_dict` makes them plain values,
    ``pamid.report.fit_json`` JSON text."""
    # (key, kind, values (M, p, 2) for an interval or (M, p) for one value per constant)
    optional = [(key, "float", arr) for key, arr in (("ci95_profile", result.ci95_profile),
                                                     ("ci95_bootstrap", result.ci95_bootstrap),
                                                     ("ci95_cluster", result.ci95_cluster),
                                                     ("ci95_hac", result.ci95_hac))
                if arr is not None]
    if result.interval_cut is not None:
        optional.append(("ci95_cut_at_bound", "bool", result.interval_cut))
    m = len(result.muscles)
    lag1 = np.full(m, np.nan) if result.residual_lag1 is None else result.residual_lag1
    notes = [result.interval_notes[i] if i < len(result.interval_notes) else None
             for i in range(m)]
    columns = [("text", list(result.muscles)), ("int", result.n.tolist()),
               ("float", result.rmse_N), ("float", result.r),
               ("bool", np.asarray(result.converged, dtype=bool).tolist()),
               ("text", [result.status_of(i) for i in range(m)]),
               ("text", [result.message(i) for i in range(m)]),
               ("float", lag1), ("text", [result.shown_of(i) for i in range(m)]),
               ("text", notes)]
    ci, se = result.shown_intervals()
    for j in range(len(result.param_names)):
        columns += [("float", result.theta[:, j]), ("float", ci[:, j, 0]),
                    ("float", ci[:, j, 1]), ("float", se[:, j]),
                    ("float", result.ci95[:, j, 0]), ("float", result.ci95[:, j, 1]),
                    ("float", result.se[:, j])]
        for _, kind, arr in optional:
            columns += ([(kind, arr[:, j, 0]), (kind, arr[:, j, 1])] if arr.ndim == 3
                        else [(kind, arr[:, j].tolist() if kind == "bool" else arr[:, j])])
    return columns, tuple((key, arr.ndim == 3) for key, _, arr in optional)


def muscle_entry(result: FitResult, values, optional: tuple[tuple[str, bool], ...]) -> dict:
    """One muscle's entry of the JSON document, its values taken from the iterator
    ``values`` in order (the order of :func:`fit_columns`)."""
    head = {"muscle": next(values), "n": next(values), "rmse_N": next(values),
            "r": next(values), "converged": next(values), "status": next(values),
            "message": next(values), "residual_lag1": next(values),
            "interval": next(values), "interval_note": next(values)}
    params = {}
    for name in result.param_names:
        # "ci95" and "se": the interval shown (the muscle's "interval"); Wald's always too.
        entry = {"value": next(values), "ci95": [next(values), next(values)],
                 "se": next(values), "ci95_wald": [next(values), next(values)],
                 "se_wald": next(values), "unit": result.param_units[name]}
        for key, pair in optional:
            entry[key] = [next(values), next(values)] if pair else next(values)
        params[name] = entry
    return {**head, "params": params}


#: The result codes of a fit, per muscle (``FitResult.status``); ``converged`` is True for
#: the first two.
STATUSES = ("converged", "at_bound", "max_steps", "not_identifiable", "nonfinite",
            "too_few_rows")


def _statuses(spec, data: FitData, lanes, n, full_rank, se, sse):
    """Per muscle, the result code (:data:`STATUSES`) and, where it is not "converged", why
    in words, naming the constants at fault (the null direction of the Jacobian,
    :mod:`pamid._inference`)."""
    p = spec.n_params
    theta = lanes.theta
    at_bound = lanes.at_lower | lanes.at_upper
    status, messages = ["converged"] * len(n), [None] * len(n)
    # Only the muscles with something to say are looked at one by one (10,000 muscles
    # that converged cost one vectorised test).
    with np.errstate(invalid="ignore"):
        plain = ((n > p) & np.all(np.isfinite(theta), axis=-1) & np.isfinite(sse)
                 & ~lanes.ran_away & full_rank & lanes.ok & np.all(np.isfinite(se), axis=-1)
                 & ~at_bound.any(axis=-1))
    for i in np.flatnonzero(~plain):
        status, messages = _one_status(spec, data, lanes, i, n, full_rank, se, sse,
                                       status, messages)
    return tuple(status), tuple(messages)


def _one_status(spec, data, lanes, i, n, full_rank, se, sse, status, messages):
    """Muscle ``i``'s entry of :func:`_statuses`, set in the lists ``status`` and
    ``messages`` (returned)."""
    from .._inference import RANK_RTOL, null_direction, undetermined
    from ._least_squares import _jacobian_rows

    p, names = spec.n_params, spec.param_names
    theta = lanes.theta
    at_bound = lanes.at_lower | lanes.at_upper

    def put(code, text):
        status[i], messages[i] = code, text
        return status, messages

    bound_note = _bound_note(names, theta[i], lanes.at_lower[i], lanes.at_upper[i])
    if n[i] <= p:
        return put("too_few_rows", f"too few rows: {int(n[i])} for the {p} constants of "
                   f"{spec.source} (at least {p + 1} are needed to estimate them and their "
                   "error)")
    if not (np.all(np.isfinite(theta[i])) and np.isfinite(sse[i])):
        bad = _nonfinite_inputs(spec, data, i)
        why = (f"the data hold NaN or ±inf ({bad})" if bad else
               "the model gave NaN or ±inf at the constants the solver reached "
               "(an overflow, e.g. an exponential of a large argument)")
        return put("nonfinite", f"no finite fit: {why}; the constants shown are not a result")
    free = ~at_bound[i]
    deficient = not full_rank[i]
    faulty: tuple[str, ...] = ()
    if at_bound[i].any() or deficient:
        # The rank criterion on the constants not held on a bound; the null direction
        # names those the data cannot pin.
        jac = _jacobian_rows(spec, theta[i], data, i)
        if not np.all(np.isfinite(jac)):  # no rank to speak of (NumPy's SVD fails on it)
            bad = [nm for nm, ok in zip(names, np.isfinite(jac).all(axis=0)) if not ok]
            return put("nonfinite", f"no finite fit: {spec.source} has NaN or ±inf "
                       f"derivatives with respect to {', '.join(bad)} at the constants the "
                       "solver reached (e.g. sqrt or abs at 0); the constants shown are not "
                       "a result")
        ratio = null_direction(jac[:, free])[0] if free.any() else 1.0
        deficient = not ratio > RANK_RTOL
        if deficient:
            faulty = undetermined(jac[:, free], [nm for nm, f in zip(names, free) if f])
    if lanes.ran_away[i] or deficient:
        ran = [names[j] for j in range(p) if lanes.left_bounds[i] and not (
            np.isfinite(lanes.free_theta[i, j]) and _within(lanes.free_theta[i, j], lanes, i, j))]
        culprits = list(dict.fromkeys(ran + list(faulty))) or [
            names[j] for j in np.flatnonzero(at_bound[i])]
        verb = "is" if len(culprits) == 1 else "are"
        text = (f"{', '.join(culprits) or 'some constants'} {verb} not determined by these "
                f"data{_design(spec, data, i)}")
        if deficient and not ran:
            text = f"the data cannot determine all {p} constants of {spec.source}: {text}"
        if ran:
            text += "; the fit without bounds ran off to " + ", ".join(
                f"{names[j]} = {lanes.free_theta[i, j]:.3g}" for j in range(p) if names[j] in ran)
        if bound_note:
            text += f"; best fit within bounds: {bound_note}"
        return put("not_identifiable", text)
    if not lanes.ok[i]:
        return put("max_steps", f"the solver stopped after {int(lanes.steps[i])} steps without "
                   "meeting its tolerance; the constants shown are the best point it reached")
    if not np.all(np.isfinite(se[i])):
        bad = [names[j] for j in np.flatnonzero(~np.isfinite(se[i]))]
        return put("not_identifiable", f"no finite standard error for {', '.join(bad)}: those "
                   "constants are not determined by the data")
    if at_bound[i].any():
        return put("at_bound", f"converged on a physical bound: {bound_note} (the data would "
                   "take it beyond; its interval is not meaningful there)")
    return put("converged", None)


def _within(value, lanes, i, j) -> bool:
    """Whether the free fit's value of constant j lies within the bounds it was refitted
    to (the bound it ends on is on the same side)."""
    if lanes.at_lower[i, j]:
        return value >= lanes.theta[i, j]
    if lanes.at_upper[i, j]:
        return value <= lanes.theta[i, j]
    return True


def _bound_note(names, theta, at_lower, at_upper) -> str:
    """"a3 = -3 (at its lower bound)" for every constant on a bound, or ""."""
    parts = [f"{names[j]} = {theta[j]:.6g} (at its {'lower' if at_lower[j] else 'upper'} "
             "bound)" for j in np.flatnonzero(at_lower | at_upper)]
    return ", ".join(parts)


def _design(spec, data: FitData, i: int) -> str:
    """" (3 distinct contraction_pct values)": the inputs with few distinct values in
    muscle ``i``'s rows, which limit what the data can determine."""
    w = np.asarray(data.w[i]) > 0
    parts = []
    for column, x in zip(spec.columns, data.x):
        values = np.unique(np.round(np.asarray(x[i])[w], 9))
        if len(values) <= 10:
            parts.append(f"{len(values)} distinct {column} value{'s' if len(values) != 1 else ''}")
    return f" ({', '.join(parts)})" if parts else ""


def _nonfinite_inputs(spec, data: FitData, i: int) -> str:
    """The inputs (and force) of muscle ``i`` holding NaN or ±inf on rows of positive
    weight, named; "" where all are finite."""
    w = np.asarray(data.w[i]) > 0
    cols = [(c, x) for c, x in zip(spec.columns, data.x)] + [("force_N", data.y)]
    bad = [c for c, a in cols if not np.all(np.isfinite(np.asarray(a[i])[w]))]
    return ", ".join(f"in {c}" for c in bad)


def _json_values(a) -> list:
    """An array as (nested) lists of floats, NaN and ±inf as None: :func:`_num` for every
    element at once."""
    a = np.asarray(a, dtype=np.float64)
    return np.where(np.isfinite(a), a, None).tolist()


#: Plain values of each kind of :func:`fit_columns`.
_PLAIN = {"text": list, "int": list, "bool": list, "float": _json_values}


def _num(x):
    """A float for JSON: NaN and ±inf (not valid JSON) become null."""
    return float(x) if np.isfinite(x) else None


def _pair(v):
    return [_num(x) for x in v]


def bench_to_fit_data(bench: BenchData, model: str | ModelSpec = "sarosi", *,
                      curves: bool = True) -> FitData:
    """Pack a loaded bench file into a batch, one lane per muscle, with the model's inputs.

    Straight from the file's columns (``bench.columns``: no per-muscle frames, no pandas):
    the muscle codes as the reader found them, then :func:`~pamid._lanes._batch.pack_rows`.
    The curve of every sample (the bootstrap's resampling unit) is the file's one curve
    definition,
    ``bench.curves`` (:func:`pamid._data._curves.find_curves`); ``curves=False`` puts
    every sample of a muscle in curve 0, for fits that resample nothing.
    """
    columns = bench.columns
    spec = get_model(model, columns)
    codes = bench.muscle_codes
    x = spec.x_from_frame(columns, bench.path)
    y = np.asarray(columns["force_N"], dtype=np.float64)
    curve = bench.curves.curve if curves else None  # None: every row in curve 0
    return pack_rows(codes, x, y, curve, n_muscles=len(bench.muscles))


def prepare_fit(spec: ModelSpec, rows_per_muscle, *, solver: str = "gauss-newton",
                intervals: tuple[str, ...] = ("wald",)) -> bool:
    """Load, from the disk caches only, the programs that :func:`fit_least_squares` runs
    first on muscles of ``rows_per_muscle`` rows (one count per muscle): the first solve
    (from one start, the fit's default) with its statistics, and the profile intervals.
    Each runs once on one call's lanes, as many as a call of the fit takes and in the
    arrays' type it takes them (:func:`._batch.call_layout`), of weight zero, so that it
    returns at once. No program is compiled: at the first one not kept on disk it stops
    (:func:`._export_cache.cached_only`), and the fit compiles that one where it runs. (The
    constants a model is linear in are found here where not known yet, as the fit would.)
    ``pamid fit`` runs this on a thread of its own while it reads the rest of the file
    (``load_bench``'s ``on_rows``). Does nothing on several devices (those calls do not go
    through the programs kept on disk). Returns whether every program was loaded."""
    from .._lanes import _export_cache
    from .._lanes._batch import call_layout, items_per_call, padded_rows
    from .._lanes._sharding import lane_devices

    counts = np.asarray(rows_per_muscle)
    devices = lane_devices()
    if counts.size == 0 or len(devices) > 1:
        return False
    cpu, n = devices[0].platform == "cpu", padded_rows(int(counts.max()), counts.size)
    n_x = len(spec.to_x(*(np.zeros(1) for _ in spec.columns)))

    def lanes(chunk):
        m, host = call_layout(counts.size, chunk, cpu, n)
        put = (lambda a: a) if host else jax.device_put
        zeros = lambda dtype=np.float64: put(np.zeros((m, n), dtype=dtype))  # noqa: E731
        return m, FitData(x=tuple(zeros() for _ in range(n_x)), y=zeros(), w=zeros(),
                          curve=zeros(np.int64))

    try:
        with _export_cache.cached_only(), np.errstate(all="ignore"):  # no muscle: no warning
            m, data = lanes(items_per_call())
            _, stats, _, _ = first_solve(spec, data, solver=solver, starts=DEFAULT_STARTS,
                                         with_statistics=True)
            if stats is None:
                statistics(spec, np.zeros((m, spec.n_params)), data, lag1=True)
            if "profile" in intervals:
                m, data = lanes(items_per_call(2 * spec.n_params))
                nan = np.full((m, spec.n_params), np.nan)  # no end to look for: stops at once
                _intervals.profile(spec, data, nan, nan, np.ones(m), np.zeros(m), np.ones(m))
    except _export_cache.NotCached:
        return False
    return True


def fit_least_squares(
    data: BenchData | FitData,
    model: str | ModelSpec = "sarosi",
    *,
    solver: str = "gauss-newton",
    intervals: tuple[str, ...] = ("wald",),
    n_bootstrap: int = 1000,
    key: jax.Array | None = None,
    bounds=None,
    level: float = 0.95,
    muscles: tuple[str | None, ...] | None = None,
    starts: int | None = None,
    show: str = "holds",
) -> FitResult:
    """Fit a static force model to every muscle of ``data`` in one batched solve.

    Args:
        data: a loaded bench file (:func:`pamid.load_bench`) or a packed :class:`FitData`.
        model: "sarosi" (Sárosi eq. 2.1), "cullinan" (Cullinan eq. 3: A–E from static
            data, and G too when the data carry ``velocity_mm_s``), or a ModelSpec.
        solver: "gauss-newton" (default; for the Sárosi model the written-out batched
            Gauss–Newton of ``pamid/_solvers/_sarosi.py`` with its own start, otherwise
            optimistix's), "levenberg-marquardt", "variable-projection",
            "jaxopt-levenberg-marquardt", or a solver object of ``pamid._solvers``
            (solvers are values: :class:`~pamid._solvers.Solver`).
        intervals: any of "wald" (always computed), "profile", "bootstrap", "cluster"
            (cluster-robust CR3 by curve, t on G − 1: holds under residuals correlated
            within curves) and "hac" (Newey–West within trials); see ``_correlated.py``.
            The residual's lag-1 autocorrelation is always measured (within curves when
            an interval above needs them, else between consecutive samples);
            where it is significant, ``interval_notes`` say which interval holds, why.
        n_bootstrap: bootstrap replicates per muscle (whole curves resampled).
        key: PRNG key, required for the bootstrap.
        bounds: optional (lower, upper) arrays of the constants (±inf where none), in place
            of the model's physical bounds (``spec.bounds``). The fit runs without bounds
            first; only muscles whose constants leave the bounds are refitted within them
            (pamid's one loop with projected bounds), and a constant on a bound is marked
            (status "at_bound", or "not_identifiable" where the fit without bounds ran off).
        level: coverage of the intervals (0.95).
        starts: starts per muscle from the model's start candidates
            (``_least_squares.DEFAULT_STARTS``, one, by default); muscles that one start
            did not serve (not converged, or constants outside their bounds) get a second
            try from ``RETRY_STARTS`` starts.
        show: which interval a muscle shows (``interval_of``; the JSON's ``ci95``, the
            table's first columns): "holds" (default), where its residual is correlated
            within curves, the cluster interval (computed then even if ``intervals`` does
            not ask for it; HAC where only that is asked for), else Wald's; "wald":
            Wald's always. ``FitResult.ci95`` is Wald's either way.
    """
    spec = get_model(model, data.columns if isinstance(data, BenchData) else None)
    unknown = set(intervals) - set(INTERVAL_KINDS)
    if unknown:
        raise ValueError(f"unknown interval kinds {sorted(unknown)}; choose from {INTERVAL_KINDS}")
    if isinstance(data, BenchData):
        names = tuple(m if data.has_muscle_column else None for m in data.muscles)
        # Curves (seconds for millions of rows: benchmarks/README.md, "Figures that used to
        # live in docstrings", (i)) only for the intervals that resample or cluster
        # them; without them the residual's lag-1 autocorrelation is measured between
        # consecutive samples of each muscle, which crosses a curve boundary once a curve.
        grouped = bool({"bootstrap", "cluster", "hac"} & set(intervals))
        trials = _correlated.trial_groups(data) if grouped else None
        bench, data = data, bench_to_fit_data(data, spec, curves=grouped)
    else:
        names = muscles if muscles is not None else tuple([None] * data.n_muscles)
        trials = bench = None

    solver = as_solver(solver)
    lanes = fit_lanes(spec, data, solver=solver, bounds=bounds, starts=starts,
                      with_statistics=True)
    theta, steps = lanes.theta, lanes.steps
    # The statistics come from the solve's compiled call where no lane changed after it, the
    # residual's lag-1 sums (for_fit, below) from the statistics' call.
    stats = lanes.statistics
    if stats is None:
        stats = statistics(spec, theta, data, lag1=True)
    sse, jtj_inv, corr, n, full_rank, *lag1 = stats
    se, lo, hi, s2, dof = _intervals.wald(theta, jtj_inv, sse, n, level)
    # A fit whose constants are not all determined by the data (rank-deficient Jacobian, a
    # constant that ran off, no degrees of freedom left) is not reported as converged,
    # whatever the solver says: its result code says why.
    status, messages = _statuses(spec, data, lanes, np.asarray(n), np.asarray(full_rank),
                                 np.asarray(se), np.asarray(sse))
    converged = np.isin(np.asarray(status), ("converged", "at_bound"))

    ci_profile = profile_ok = None
    if "profile" in intervals:
        plo, phi, profile_ok = _intervals.profile(spec, data, theta, se, s2, sse, dof, level,
                                                  jtj_inv=jtj_inv,
                                                  bounds=bounds_arrays(spec, bounds))
        ci_profile = np.stack([plo, phi], axis=-1)
    ci_boot = boot_ok = None
    if "bootstrap" in intervals:
        if key is None:
            raise ValueError("the bootstrap needs a PRNG key: pass key=jax.random.key(...)")
        blo, bhi, _, boot_ok = _intervals.bootstrap(spec, data, theta, key, n_bootstrap, level)
        ci_boot = np.stack([blo, bhi], axis=-1)

    covariance = scale_covariance(jtj_inv, s2)  # ±inf where the data do not determine one
    # Data packed without their curves get them only where a cluster interval is computed.
    curves_of = (None if bench is None or {"bootstrap", "cluster", "hac"} & set(intervals) else
                 lambda muscles, width: _correlated.trial_groups(bench, of="curve",
                                                                 muscles=muscles, width=width))
    correlated = _correlated.for_fit(spec, data, theta, intervals, trials, level, lag1=lag1,
                                     show=show, curves_of=curves_of)
    # Every interval is cut at the fit's bounds (the user's, else the model's physical ones):
    # a wall thickness held at 0 is not reported as possibly -3 mm (the profile's ends are
    # within them already).
    ci95 = np.stack([lo, hi], axis=-1)
    ci95, ci_boot, cut = _cut_at_bounds(spec, bounds, ci95, ci_boot, correlated)
    return FitResult(
        model=spec.name,
        param_names=spec.param_names,
        param_units=spec.param_units,
        muscles=names,
        theta=theta,
        se=se,
        ci95=ci95,
        ci95_profile=ci_profile,
        ci95_bootstrap=ci_boot,
        covariance=covariance,
        n=n.astype(int),
        dof=dof,
        sse=sse,
        rmse_N=np.sqrt(sse / n),
        r=corr,
        converged=converged,
        n_steps=steps,
        solver=solver.name if not lanes.left_bounds.any() else f"{solver.name}+bounds",
        profile_ok=profile_ok,
        bootstrap_converged=boot_ok,
        spec=spec,
        messages=messages,
        status=status,
        interval_cut=cut,
        **correlated,
    )


def _cut_at_bounds(spec, bounds, ci95, ci_boot, correlated):
    """The fit's Wald, bootstrap and sandwich intervals cut at its bounds
    (:func:`pamid._inference.cut_at_bounds`; ``correlated``'s in place). Returns (ci95,
    ci_boot, cut): ``cut`` (M, p), True where an interval of the constant was cut, or None
    where the fit has no bounds or none was."""
    lower, upper = bounds_arrays(spec, bounds)
    if lower is None:
        return ci95, ci_boot, None
    cut = np.zeros(ci95.shape[:-1], dtype=bool)

    def one(ci):
        if ci is None:
            return None
        lo, hi, c = cut_at_bounds(ci[..., 0], ci[..., 1], (lower, upper))
        cut[...] |= c
        return np.stack([lo, hi], axis=-1)

    ci95, ci_boot = one(ci95), one(ci_boot)
    for key in ("ci95_cluster", "ci95_hac"):
        if correlated.get(key) is not None:
            correlated[key] = one(correlated[key])
    return ci95, ci_boot, (cut if cut.any() else None)
