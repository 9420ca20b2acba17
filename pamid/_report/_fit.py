"""A least-squares fit (:class:`pamid.FitResult`) written out: its JSON document as text,
and its figures (data against model, residuals, the RMSE across muscles) as ``pamid fit
--out`` writes them.

The JSON writer is here because it writes text; the document's layout (what an entry
holds, in which order) is the result's own, shared with :meth:`pamid.FitResult.to_dict`
(:func:`pamid._fit._api.fit_columns`, :func:`~pamid._fit._api.muscle_entry`). The figures
are drawn by :mod:`._plot`, which this module imports only when a figure is asked for: the
JSON path stays free of matplotlib.
"""

from __future__ import annotations

import json
from pathlib import Path

from .._arrow import constant_strings, from_numpy, strings
from .._fit._api import fit_columns, json_head, muscle_entry


def fit_json(result, **extra) -> str:
    """``json.dumps({**result.to_dict(), **extra})``, the same text, written without the
    dictionaries: every muscle's entry is one row of a template that
    :func:`pamid._fit._api.muscle_entry` lays out, its values' texts joined column-wise by
    pyarrow (benchmarks/README.md, "Figures that used to live in docstrings", (i)).
    ``extra``: keys added at the top level after the fit's own (``pamid fit --json`` adds
    source, seconds, plots)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    columns, optional = fit_columns(result)
    columns = _column_texts(columns)
    marks = [f'"<<pamid-json-{k}>>"' for k in range(len(columns))]
    template = json.dumps(muscle_entry(result, iter(m[1:-1] for m in marks), optional))
    pieces = []
    for mark in marks:
        before, found, template = template.partition(mark)
        if not found or mark in template:  # a value that is no mark's text
            return json.dumps({**result.to_dict(), **extra})
        pieces.append(before)
    n = len(columns[0]) if columns else 0  # muscles
    rows = [part for piece, column in zip(pieces, columns, strict=True)
            for part in (constant_strings(piece, n),
                         column if isinstance(column, pa.Array) else strings(column))]
    entries = (pc.binary_join_element_wise(*rows, constant_strings(template, n),
                                           constant_strings("", n)).to_pylist()
               if columns else [])
    muscles = "[" + ", ".join(entries) + "]"
    head = json.dumps({**json_head(result), "muscles": "<<pamid-json-muscles>>", **extra})
    return head.replace('"<<pamid-json-muscles>>"', muscles, 1)


def _column_texts(columns) -> list:
    """The JSON texts of :func:`pamid._fit._api.fit_columns`' columns: :data:`_TEXT`'s, and
    the float columns written by one :func:`_json_floats` over all of them, then cut apart
    (a file of 10,000 muscles has some seventy such columns of 10,000 values each)."""
    import numpy as np

    floats = [k for k, (kind, _) in enumerate(columns) if kind == "float"]
    texts = [None if kind == "float" else _TEXT[kind](values) for kind, values in columns]
    if floats:
        parts = [np.ravel(np.asarray(columns[k][1], dtype=np.float64)) for k in floats]
        joined = _json_floats(np.concatenate(parts))
        at = 0
        for k, part in zip(floats, parts, strict=True):
            texts[k] = joined.slice(at, len(part))
            at += len(part)
    return texts


#: Where pyarrow's text of a float64 (the shortest digits that read back as the same
#: number) is Python's ``repr`` once ".0" is added to a whole number: 1e-4 <= |x| < 1e10,
#: and zero. Outside it the two place the exponent differently ("1e-05" against "0.00001",
#: "10000000000.0" against "1e+10"), and ``repr`` writes those values.
_ARROW_REPR_RANGE = (1e-4, 1e10)


def _json_floats(a):
    """A 1-D array as the JSON text of each element (a pyarrow string array), as
    ``json.dumps`` writes the plain values of :meth:`pamid.FitResult.to_dict`:
    ``float.__repr__``, null for NaN and ±inf. pyarrow writes the values in
    :data:`_ARROW_REPR_RANGE` (4× faster than ``repr``) and the nulls, Python the other
    finite values."""
    import numpy as np
    import pyarrow as pa
    import pyarrow.compute as pc

    a = np.asarray(a, dtype=np.float64)
    low, high = _ARROW_REPR_RANGE
    size = np.abs(a)
    with np.errstate(invalid="ignore"):
        fast = ((size >= low) & (size < high)) | (a == 0)
    n = len(a)
    text = pc.cast(from_numpy(np.where(fast, a, 0.0)), pa.string())
    whole = pc.invert(pc.match_substring(text, "."))  # "100" is 100.0 in Python
    text = pc.if_else(whole, pc.binary_join_element_wise(
        text, constant_strings(".0", n), constant_strings("", n)), text)
    if fast.all():
        return text
    missing = ~np.isfinite(a)  # null, whole columns of them where an interval is not shown
    if missing.any():
        text = pc.if_else(from_numpy(missing), constant_strings("null", n), text)
    slow = ~fast & ~missing
    if not slow.any():
        return text
    reprs = [float.__repr__(x) for x in a[slow].tolist()]
    return pc.replace_with_mask(text, from_numpy(slow), strings(reprs))


def _json_texts(values: list) -> list[str]:
    """The JSON text of each of ``values``, as ``json.dumps`` writes it."""
    ascii_text = json.encoder.encode_basestring_ascii  # what json.dumps uses for a str
    return ["null" if v is None else ascii_text(v) if type(v) is str else json.dumps(v)
            for v in values]


#: JSON text of each kind of column of :func:`pamid._fit._api.fit_columns` but "float",
#: whose columns :func:`_column_texts` writes together (:func:`_json_floats`).
_TEXT = {
    "text": _json_texts,
    "int": lambda values: [str(int(v)) for v in values],
    "bool": lambda values: ["true" if v else "false" for v in values],
}


# --------------------------------------------------------------------------------------
# Figures.


def bench_muscle(bench, i: int) -> tuple:
    """Muscle ``i`` of a bench file as the figures take it: its rows (a DataFrame), its
    name in file names, unique among the file's muscles (:func:`pamid._io.safe_file_names`;
    "muscle" in a file without a muscle column) and its label in titles (the file's name
    there)."""
    from .._io import safe_file_names

    muscle = bench.muscles[i]
    frame = bench.for_muscle(muscle)
    name = safe_file_names(bench.muscles)[i] if bench.has_muscle_column else "muscle"
    label = muscle if bench.has_muscle_column else Path(bench.path).name
    return frame, name, label


def _muscle(result, bench, i: int):
    """:func:`bench_muscle`, with the rows' curves for the fitted model's inputs."""
    from .._data._curves import find_curves

    frame, name, label = bench_muscle(bench, i)
    curves = find_curves(frame, contraction_column=result.spec.contraction_column)
    return frame, curves, name, label


def plot_fit(result, bench, i: int = 0, path=None, *, title: str | None = None):
    """Muscle ``i`` of ``bench`` (the bench ``result`` was fitted to) against its fitted
    model: force [N] against the moving input at each held level, the residual below;
    one column of panels per kind of curve (sweeps, isometric tests). Written to ``path``
    (PNG unless the extension says else) atomically, unless it is None; the matplotlib
    figure is returned either way."""
    from . import _plot

    frame, curves, _, label = _muscle(result, bench, i)
    return _plot.plot_fit(frame, result.spec, result.theta[i], path,
                          title or f"{result.spec.source} fit — {label}", curves=curves)


def plot_residuals(result, bench, i: int = 0, path=None, *, title: str | None = None):
    """The residual [N] of muscle ``i`` against the moving input, the held level, the
    elapsed time and the fitted force. Written to ``path`` atomically unless it is None;
    the figure is returned."""
    from . import _plot

    frame, curves, _, label = _muscle(result, bench, i)
    title = title or f"Residuals — {result.spec.source} fit — {label}"
    return _plot.plot_residuals(frame, result.spec, result.theta[i], path, title,
                                curves=curves)


def plot_rmse_histogram(result, path=None, *, title: str | None = None):
    """The distribution of the fit's RMSE [N] across its muscles. Written to ``path``
    atomically unless it is None; the figure is returned."""
    from . import _plot

    return _plot.plot_rmse_histogram(
        result.rmse_N, path, title or f"Fit RMSE across {result.n_muscles} muscles")


def write_fit_plots(result, bench, folder, max_plots: int = 6, *,
                    owners: dict | None = None) -> list[str]:
    """What ``pamid fit --out`` draws: ``fit_<muscle>.png`` and ``residuals_<muscle>.png``
    for the first ``max_plots`` muscles (names: :func:`bench_muscle`), and
    ``rmse_histogram.png`` when there are several; each written atomically into
    ``folder``. Returns the file names written; ``owners``, a dict, gets {file name: muscle}
    for the files of one muscle (``muscle_of_file`` in fit.json)."""
    from . import _plot

    folder = Path(folder)
    written = []
    for i in range(len(bench.muscles[:max_plots])):
        frame, curves, name, label = _muscle(result, bench, i)  # a few muscles only
        title = f"{result.spec.source} fit — {label}"
        _plot.plot_fit(frame, result.spec, result.theta[i], folder / f"fit_{name}.png", title,
                       curves=curves)
        _plot.plot_residuals(frame, result.spec, result.theta[i],
                             folder / f"residuals_{name}.png", f"Residuals — {title}",
                             curves=curves)
        written += [f"fit_{name}.png", f"residuals_{name}.png"]
        if owners is not None:
            owners.update(dict.fromkeys(written[-2:], bench.muscles[i]))
    if result.n_muscles > 1:
        plot_rmse_histogram(result, folder / "rmse_histogram.png")
        written.append("rmse_histogram.png")
    return written
