"""A bench table's columns as NumPy arrays: what a fit reads, without pandas.

:class:`~pamid._data._bench.BenchData` keeps its rows as :class:`Columns`: float and integer
columns as arrays, label and text columns as :class:`Coded` (every row's code into the
distinct values, in order of first appearance, as the reader found them). Its pandas frame
(``BenchData.frame``) is made from them the first time something asks for it. A fit reads
the columns and the muscle codes and never imports pandas: importing pandas is about 0.2 s,
a fifth of a warm ``pamid fit`` of a one-muscle file (benchmarks/README.md, "A fit without
pandas").

:func:`factorize` numbers values in order of first appearance, as ``pd.factorize(values,
sort=False)`` does: the one definition of that numbering for the readers and the curve
finder.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["Coded", "Columns", "as_column", "factorize"]


class Coded(NamedTuple):
    """A text column as ``uniques[codes]``: ``codes`` (int64, one per row) index ``uniques``
    (an object array of str, distinct, in order of first appearance)."""

    codes: np.ndarray
    uniques: np.ndarray

    def values(self) -> np.ndarray:
        """Every row's text, an object array."""
        return self.uniques[self.codes]


def factorize(values) -> tuple[np.ndarray, np.ndarray]:
    """``(codes, uniques)`` with ``values == uniques[codes]``, ``uniques`` distinct and in
    order of first appearance (code k first appears after code k − 1 does), as
    ``pd.factorize(values, sort=False)`` numbers them; NaN values are one value.

    Integers cost one pass when their range is at most a few times their number (codes,
    row groups), else a sort; other values (text) are numbered by a dict, meant for the
    distinct cells of a column rather than its rows.
    """
    a = np.asarray(values)
    if a.ndim != 1:
        a = a.reshape(-1)
    n = len(a)
    if n == 0:
        return np.zeros(0, dtype=np.int64), a[:0]
    if a.dtype.kind in "iub":
        a_int = a.astype(np.int64, copy=False)
        lo, hi = int(a_int.min()), int(a_int.max())
        if hi - lo <= 4 * n + 1024:
            k = a_int - lo
            first = np.full(hi - lo + 1, n, dtype=np.int64)
            first[k[::-1]] = np.arange(n - 1, -1, -1)  # the last write is the first row
            present = np.flatnonzero(first < n)
            order = present[np.argsort(first[present], kind="stable")]
            rank = np.empty(hi - lo + 1, dtype=np.int64)
            rank[order] = np.arange(len(order))
            return rank[k], (order + lo).astype(a.dtype)
        return _by_sorting(a)
    if a.dtype.kind == "f":
        return _by_sorting(a)
    index: dict = {}
    codes = np.empty(n, dtype=np.int64)
    for i, value in enumerate(a.tolist()):
        # NaN (not equal to itself) is one value, as pandas counts it
        codes[i] = index.setdefault(_NAN if value != value else value, len(index))
    uniques = np.empty(len(index), dtype=object)
    for value, code in index.items():
        uniques[code] = np.nan if value is _NAN else value
    return codes, uniques


_NAN = object()  # factorize's key for NaN


def _by_sorting(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`factorize` through ``np.unique`` (NaN one value), reordered by first row."""
    uniq, first, inverse = np.unique(a, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty(len(uniq), dtype=np.int64)
    rank[order] = np.arange(len(uniq))
    return rank[inverse.reshape(-1)], uniq[order]


def as_column(value):
    """A column for :class:`Columns`: an array as it is, text (a list of str, an object
    array, a pandas Series of text) as :class:`Coded`, another Series as its array."""
    if isinstance(value, Coded):
        return value
    if isinstance(value, list):
        codes, uniques = factorize(np.asarray(value, dtype=object))
        return Coded(codes, uniques)
    if isinstance(value, np.ndarray):
        if value.dtype == object:
            codes, uniques = factorize(value)
            return Coded(codes, uniques)
        return value
    import pandas as pd  # a Series: pandas is there

    if value.dtype == object or pd.api.types.is_string_dtype(value.dtype):
        codes, uniques = pd.factorize(value, sort=False, use_na_sentinel=False)
        return Coded(np.asarray(codes, dtype=np.int64), np.asarray(uniques, dtype=object))
    return value.to_numpy()


class Columns:
    """The rows of a bench table as named NumPy columns, in the frame's column order.

    ``columns[name]`` is the column as an array (text as an object array of str);
    ``name in columns`` asks whether it is there; ``len(columns)`` and :attr:`n_rows` are
    the number of rows (as ``len`` of a DataFrame); iterating gives the names.
    :meth:`codes` gives a label column as codes, :meth:`take` a subset of the rows,
    :meth:`to_frame` the pandas DataFrame."""

    __slots__ = ("_data", "n_rows", "_values")

    def __init__(self, data: dict, n_rows: int) -> None:
        self._data = {name: as_column(value) for name, value in data.items()}
        self.n_rows = int(n_rows)
        self._values: dict[str, np.ndarray] = {}

    @classmethod
    def of_frame(cls, frame) -> Columns:
        """A DataFrame's columns: text columns coded, the others as their NumPy arrays."""
        return cls({name: as_column(frame[name]) for name in frame.columns}, len(frame))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self._data)

    def __contains__(self, name) -> bool:
        return name in self._data

    def __iter__(self):
        return iter(self._data)

    def __len__(self) -> int:
        return self.n_rows

    def __getitem__(self, name: str) -> np.ndarray:
        value = self._data[name]
        if isinstance(value, Coded):
            out = self._values.get(name)
            if out is None:
                out = self._values[name] = value.values()
            return out
        return value

    def codes(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """A label column as ``(codes, uniques)`` (:func:`factorize`'s numbering)."""
        value = self._data[name]
        if isinstance(value, Coded):
            return value.codes, value.uniques
        return factorize(value)

    def take(self, rows) -> Columns:
        """The columns of a subset of the rows (a boolean mask or integer indices, in the
        order given); a coded column keeps only the values its rows hold, numbered again in
        order of first appearance."""
        rows = np.asarray(rows)
        data: dict = {}
        for name, value in self._data.items():
            if isinstance(value, Coded):
                kept, which = factorize(value.codes[rows])
                data[name] = Coded(kept, value.uniques[which])
            else:
                data[name] = value[rows]
        n = int(np.count_nonzero(rows)) if rows.dtype == bool else len(rows)
        return Columns(data, n)

    def to_frame(self):
        """The pandas DataFrame of these columns (text of the dtype pandas gives a list of
        str)."""
        import pandas as pd

        from ._table import _text_values

        data = {name: (_text_values(value.uniques, value.codes) if isinstance(value, Coded)
                       else value) for name, value in self._data.items()}
        return pd.DataFrame(data, copy=False)
