"""``pamid.diagnose``: find what a fitted model misses, name it, model it, report the gain.

The procedure:

1. Fit the baseline model (Sárosi eq. 2.1 or Cullinan eq. 3 for bench files; the linear
   damped oscillator for decay files). Analyse its residual: whiteness of the time-ordered
   residual (runs test, Ljung–Box) and its dependence on every covariate — the file's own
   columns and derived ones (direction of motion, speed, elapsed time, temperature, cycle,
   pressure, contraction, force level).
2. Refit with each candidate effect (:mod:`pamid._diagnose._static`), batched.
3. Select by BIC and cross-validated error on held-out curves, forward, until nothing
   significant remains (:mod:`pamid._diagnose._select`). Where a selected effect leaves its
   own covariate in the residual, try its other physical form (the temperature as a share
   of the force rather than newtons; :mod:`pamid._diagnose._forms`) and say which was kept.
4. Report the ranked candidates, the selected effects' constants with 95 % intervals, the
   error before and after (RMSE, max error, per covariate bin) and what stays unexplained.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from ._result import Diagnosis, analyse_residual, build_diagnosis, unexplained
from ._select import forward_select


def diagnose(data, *, model: str = "sarosi", inertia_kg_m2: float | None = None,
             n_folds: int = 5, progress=None, read_options: dict | None = None,
             max_rows: int | None = None, bounds=None) -> Diagnosis:
    """Diagnose a bench or decay file (a path, a :class:`~pamid.BenchData` or a
    :class:`~pamid.DecayData`).

    Decay files are recognised by their columns (``angle_rad`` or ``angle_deg``, with
    ``time_s`` and optionally ``trial``) and diagnosed with the oscillator model; they need
    ``inertia_kg_m2`` for the friction torque in N·m. ``read_options`` are keyword
    arguments of :func:`~pamid.load_bench` for a bench file given as a path.

    ``bounds``: (lower, upper) arrays over the model's constants (±inf where none), in place
    of the model's physical bounds, as :func:`~pamid.fit_least_squares` takes them. The
    baseline is fitted within them; a constant it holds on a bound stays there when effects
    are refitted on top, and an effect whose refit moves a constant past its bound is not
    selected (the candidate's row says which constant would have needed what). Bench files
    only.

    ``max_rows``: a bench file with more rows is diagnosed on a representative subsample of
    whole curves (:func:`subsample_curves`); the diagnosis says so (``rows_used``,
    ``rows_total``, ``subsample``). Decay files are always diagnosed whole.
    """
    from .._data._bench import BenchData, load_bench
    from .._data._decay_file import DecayData, load_decay

    if isinstance(data, (str, os.PathLike)):
        if _is_decay_file(Path(data)):
            data = load_decay(data)
        else:
            data = load_bench(data, **(read_options or {}))
    if isinstance(data, DecayData):
        from ._decay import diagnose_decays

        if bounds is not None:
            raise ValueError(f"{data.path}: bounds (--bounds) are for a bench file's force "
                             "model; a decay file is diagnosed with the oscillator model")

        return diagnose_decays(data, inertia_kg_m2, n_folds=n_folds, progress=progress)
    if not isinstance(data, BenchData):
        raise TypeError(f"diagnose takes a path, BenchData or DecayData, not {type(data)}")
    if max_rows is not None and max_rows < 1:
        raise ValueError(f"max_rows (--max-rows) must be at least 1, not {max_rows}")
    return _diagnose_bench(data, model, n_folds, progress, max_rows, bounds)


def _level_groups(group, level):
    """Held levels of curves as set points: within each ``group`` (a muscle's sweeps or its
    isometric curves), levels closer than 2 % of the group's range of levels are one (a
    curve's level is estimated from its noisy samples, so repeats of a set point differ in
    their last digits)."""
    out = np.zeros(len(level), int)
    for g in np.unique(group):
        idx = np.flatnonzero(group == g)
        order = idx[np.argsort(level[idx], kind="stable")]
        values = level[order]
        gap = 0.02 * (values[-1] - values[0])
        out[order] = np.concatenate([[0], np.cumsum(np.diff(values) > gap)])
    return out


def _spread(pos):
    """An order of the places 0, 1, 2, … of curves in time that spreads them over the test:
    the places' bits reversed (0, then the middle, then the quarters, …)."""
    pos = np.asarray(pos, np.int64)
    bits = max(1, int(pos.max()).bit_length()) if len(pos) else 1
    out = np.zeros_like(pos)
    for b in range(bits):
        out |= ((pos >> b) & 1) << (bits - 1 - b)
    return out


def _is_decay_file(path: Path) -> bool:
    """A decay file names its angle (``angle_rad`` or ``angle_deg``); a bench file never does.
    Only the header is read; a file that cannot be read is left to ``load_bench`` to report."""
    from .._data._readers import column_names  # a pipe is read once, kept for the loader

    try:
        names = column_names(path)
    except Exception:
        return False
    return "angle_rad" in names or "angle_deg" in names


def subsample_curves(bench, max_rows: int):
    """A representative subsample of ``bench`` of at most ``max_rows`` rows, whole curves kept.

    Curves are those of :func:`pamid._data._curves.find_curves` (``bench.curves``). Every
    muscle keeps the same share of its curves, and at least two of every setting it was
    tested at (moving input, direction, held level; one where it has one): a model fitted
    to one contraction level of an isometric file cannot be diagnosed, and a
    cross-validation fold that holds out the only curve of a setting tests extrapolation.
    The curves of a setting are taken in an order spread over the test (the first, then
    the middle, then the quarters, …), and the settings in turn, so that each share keeps
    every setting and early and late curves of it. Where whole curves cannot get under
    ``max_rows``, every k-th row of each kept curve is kept instead.

    Returns ``(bench, note)``: ``bench`` itself and None when it has ``max_rows`` rows or
    fewer, else a :class:`~pamid.BenchData` of the kept rows (in file order) and a phrase
    that says how they were drawn.
    """
    frame = bench.frame
    n = len(frame)
    if n <= max_rows:
        return bench, None
    c = bench.curves
    muscle = pd.factorize(frame["muscle"], sort=False)[0]
    uid = muscle * (int(c.curve.max()) + 1) + c.curve  # one id per (muscle, curve)
    ids, first, sizes = np.unique(uid, return_index=True, return_counts=True)
    owner = muscle[first]
    level = _level_groups(owner * 2 + c.moving[first], np.nan_to_num(c.level[first], nan=0.0))
    setting = np.unique(np.stack([owner, c.moving[first], c.direction[first], level], axis=1),
                        axis=0, return_inverse=True)[1].ravel()
    by_setting = np.lexsort((first, setting))
    pos = np.empty(len(ids), int)  # the curve's place in its setting, in time order
    pos[by_setting] = np.arange(len(ids)) - np.searchsorted(setting[by_setting],
                                                             setting[by_setting])
    order = np.lexsort((setting, _spread(pos), owner))
    ids, sizes, owner = ids[order], sizes[order], owner[order]
    rank = np.arange(len(ids)) - np.searchsorted(owner, owner)  # position within its muscle
    count = np.bincount(owner)[owner]  # curves of its muscle
    # Every setting of its muscle twice where it has two curves of it: a held-out fold of
    # the cross-validation then never takes away the only curve of a setting.
    setting_owner = np.zeros(int(setting.max()) + 1, int)
    setting_owner[setting] = muscle[first]
    fewest = np.bincount(setting_owner, np.minimum(np.bincount(setting), 2),
                         minlength=int(muscle.max()) + 1)[owner]
    share = max_rows / n
    for _ in range(30):
        want = np.maximum(fewest, np.round(share * count))
        kept = rank < want
        rows = int(np.sum(sizes[kept]))
        if rows <= max_rows or np.all(want == fewest):
            break
        share *= 0.98 * max_rows / rows
    keep = np.isin(uid, ids[kept])
    note = f"{int(np.sum(kept))} of {len(ids)} whole curves, evenly spread over settings and time"
    step = -(-rows // max_rows)  # ceil
    while step > 1 and int(np.sum(-(-sizes[kept] // step))) > max_rows:
        step += 1  # each curve keeps its rows 0, step, 2·step, …: ceil(size / step) of them
    if step > 1:  # the curves each setting needs are still too many: thin them alike
        within = pd.Series(uid[keep]).groupby(uid[keep]).cumcount().to_numpy()
        keep[np.flatnonzero(keep)[within % step != 0]] = False
        note = (f"one row in {step} of {int(np.sum(kept))} of {len(ids)} curves, evenly "
                "spread over settings and time")
    sub = bench.take(keep)
    return sub, note


def _check_enough_rows(bench, spec) -> None:
    """A diagnosis compares fits with more constants than the model's: a muscle needs at
    least the model's constants plus two rows, or nothing it reports could be trusted."""
    from .._errors import BenchDataError

    need = spec.n_params + 2
    counts = bench.frame.groupby("muscle", sort=False).size()
    few = counts[counts < need]
    if len(few):
        who = f"muscle '{few.index[0]}' has" if bench.has_muscle_column else "the file has"
        raise BenchDataError(
            bench.path,
            f"{who} {int(few.iloc[0])} row(s); diagnosing the {spec.name} model "
            f"({spec.n_params} constants) needs at least {need} rows per muscle "
            "(the constants, an added effect and one degree of freedom)",
        )


def _diagnose_bench(bench, model: str, n_folds: int, progress,
                    max_rows: int | None = None, bounds=None, shape_check: bool = True
                    ) -> Diagnosis:
    from .._fit._spec import get_model
    from ._forms import form_groups, other_forms
    from ._shape import force_law_shape, shape_suspected
    from ._static import StaticProblem, intervals

    rows_total = len(bench.frame)
    note = None
    if max_rows is not None:
        bench, note = subsample_curves(bench, max_rows)
        if note is not None and progress is not None:
            progress(f"diagnosing {len(bench.frame)} of {rows_total} rows: {note} "
                     "(--max-rows)")
    spec = get_model(model, bench.frame)
    _check_enough_rows(bench, spec)
    problem = StaticProblem(bench, spec, n_folds=n_folds, bounds=bounds)  # checks its baseline
    for f in problem.flagged:
        if progress is not None:
            progress(f"muscle {f['muscle']}: {f['why']}; "
                     + ("diagnosed with the others, that constant held"
                        if f["diagnosed"] else "left out of the diagnosis"))
    bench = problem.bench  # without the muscles left out
    forms = form_groups(problem)

    def select(candidates):
        return forward_select(candidates, problem.evaluate, problem.covariate_of,
                              progress=progress, unphysical=problem.unphysical,
                              refresh=problem.refresh_grids, forms=forms)

    # A selected effect that leaves its own covariate behind is tried in its other form
    # (pamid._diagnose._forms): the temperature as a share of the force, not newtons.
    result, tried_forms = other_forms(problem, select(problem.candidate_names), select)
    for r in tried_forms:
        if progress is not None:
            progress(r["why"])
    suspects = shape_suspected(problem, result) if shape_check else []
    shape = (force_law_shape(problem.bench, spec, result, suspects, n_folds=n_folds,
                             order_is_time=problem.order_is_time, progress=progress)
             if suspects else None)
    if shape is not None:
        # The force law's shape (pamid._diagnose._shape): the effects are diagnosed again
        # on top of the law that fits, so that none stands in for it.
        if progress is not None:
            progress(f"the force law's shape: {shape['law']} fits this file better than "
                     f"{spec.name} with any effect; diagnosing the effects on top of it")
        d = _diagnose_bench(problem.bench, shape["law"], n_folds, progress,
                            shape_check=False)
        d.force_law_shape, d.model_requested = shape, spec.name
        d.rows_total, d.subsample = rows_total, note
        return d
    base, final = result["baseline"], result["final"]
    table = _long_table(problem, base, final)
    covs = [*problem.covariates, "force_N"]
    before = analyse_residual(table, "residual_before_N", covs)
    after = analyse_residual(table, "residual_after_N", covs)
    status = {f["muscle"]: f["status"] for f in problem.flagged}
    constants = [
        {"muscle": m, **({"effects": e} if e else {"effects": {}}),
         "base": dict(zip(spec.param_names, map(float, final.extra["params"][i][:spec.n_params]),
                          strict=True)),
         # "not_identifiable": the base constants are the best fit within bounds, one held
         # on its bound (muscles_flagged says which and why), not a finding
         "baseline_status": status.get(m, problem.baseline.status_of(i))}
        for i, (m, e) in enumerate(zip(bench.muscles, intervals(problem, final), strict=True))
    ]
    d = build_diagnosis(bench.path, "bench", spec.name, list(bench.muscles), result,
                        before, after, constants, table,
                        unexplained(after, order_is_time=problem.order_is_time))
    d.order_is_time = problem.order_is_time
    d.rows_used, d.rows_total, d.subsample = len(bench.frame), rows_total, note
    d.muscles_flagged = [dict(f) for f in problem.flagged]
    d.forms = tried_forms
    d.covariates_not_used = [{"column": c, "why": why}
                             for c, why in problem.not_covariates.items()]
    return d


def _long_table(problem, base, final) -> pd.DataFrame:
    parts = []
    for i, f in enumerate(problem.frames):
        n = len(f)
        part = f.copy()
        part["group"] = str(f["muscle"].iloc[0])
        part["residual_before_N"] = base.extra["residual"][i][:n]
        part["residual_after_N"] = final.extra["residual"][i][:n]
        parts.append(part)
    return pd.concat(parts, ignore_index=True)
