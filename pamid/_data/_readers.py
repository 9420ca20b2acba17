"""The file formats pamid reads, one registry keyed by extension.

Every loader takes its reader from here: :func:`pamid._data._bench.load_bench` (bench
files), :func:`pamid._data._decay_file.load_decay` (decay files), and :func:`column_names`,
which reads a file's header alone (``pamid diagnose`` tells a decay file from a bench file
by it). A reader turns a file into a raw table (:mod:`._table`), which the loaders check and
convert; every reader reads a regular file or a stream's bytes (:mod:`._streams`).

Adding a format is adding one :class:`Reader` to :data:`FORMATS`.

Which reader reads a file (:func:`reader_for`): the one its extension names; a stream
(``/dev/stdin``, a pipe), which has no extension, by its first bytes (Parquet, a spreadsheet);
anything else as CSV. A regular file is never sniffed: a Parquet file named ``x.csv`` is an
error that says so.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from ._csv import CSV_SUFFIXES, _read_csv, csv_names, read_csv_fast
from ._parquet import PARQUET_SUFFIXES, _read_parquet, parquet_chunks, parquet_names
from ._spreadsheet import (
    ALL_SHEETS,
    SPREADSHEET_SIGNATURES,
    SPREADSHEET_SUFFIXES,
    read_spreadsheet,
    sheet_names,
    spreadsheet_names,
)
from ._streams import read_ahead
from ._table import _Table

__all__ = ["ALL_SHEETS", "FORMATS", "READERS", "Reader", "column_names", "reader_for"]


@dataclass(frozen=True)
class Reader:
    """One file format: how to recognise it and how to read it.

    Attributes:
        name: the format in messages, plural ("CSV files", "spreadsheets").
        suffixes: the extensions read with it (lower case, with the dot).
        signatures: first bytes that mark a stream as this format; () for a text format.
        read: ``read(path, shown, *, data=None, columns=None, **options) -> _Table``, the
            reference reader: it reads every file of the format and words every problem.
            ``shown`` is the path as the user gave it (for messages), ``data`` a stream's
            bytes (read once, by the caller), ``columns`` the user's mapping of headers to
            pamid's names (which the loader applies; a reader that looks for its header
            among notes counts those headers as known), ``options`` those of
            :attr:`options` that the user gave.
        names: ``names(path, shown, data=None) -> list[str]``, the header alone.
        options: the reading options of :func:`~pamid.load_bench` that apply (``"sep"``,
            ``"decimal"``, ``"sheet"``, ``"header_row"``); any other is an error naming the
            formats it applies to.
        fast: ``fast(path, shown, *, data=None, columns=None, **options) -> _Table | None``,
            a quicker reader that gives the table with pamid's names or declines (None) any
            file in doubt; the reference reader then reads the file and words its problem.
        parts: ``parts(path, shown, data=None) -> list[str]``, for a format whose file
            holds several tables (a workbook's sheets): their names, which ``read`` takes as
            ``sheet=`` (``load_bench(sheet="all")`` reads each as a muscle).
        chunks: ``chunks(path, shown, rows, columns=None) -> Iterator[_Table]``, for a
            format that can be read a part at a time: tables of whole muscles of about
            ``rows`` rows, in file order (:func:`~pamid._data._bench.load_bench_chunks`,
            ``pamid fit --stream``).
    """

    name: str
    suffixes: tuple[str, ...]
    signatures: tuple[bytes, ...]
    read: Callable[..., _Table]
    names: Callable[..., list[str]]
    options: tuple[str, ...] = ()
    fast: Callable[..., _Table | None] | None = None
    parts: Callable[..., list[str]] | None = None
    chunks: Callable[..., Iterator[_Table]] | None = None


#: CSV: also every file whose extension no other reader claims.
CSV = Reader("CSV files", CSV_SUFFIXES, (), _read_csv, csv_names, ("sep", "decimal"),
             fast=read_csv_fast)
#: The formats, in the order messages list them.
FORMATS: tuple[Reader, ...] = (
    CSV,
    Reader("Parquet files", PARQUET_SUFFIXES, (b"PAR1",), _read_parquet, parquet_names,
           chunks=parquet_chunks),
    Reader("spreadsheets", SPREADSHEET_SUFFIXES, SPREADSHEET_SIGNATURES, read_spreadsheet,
           spreadsheet_names, ("sheet", "header_row", "decimal"), parts=sheet_names),
)
#: The reader of each extension.
READERS: dict[str, Reader] = {suffix: reader for reader in FORMATS for suffix in reader.suffixes}


def reader_for(path: Path, stream: bytes | None) -> Reader:
    """The reader of a file: by its extension; a stream (``stream``, its bytes) without the
    extension of a binary format by its first bytes; else CSV."""
    reader = READERS.get(path.suffix.lower())
    if reader is not None and reader.signatures:
        return reader
    if stream is not None:
        for candidate in FORMATS:
            if any(stream.startswith(mark) for mark in candidate.signatures):
                return candidate
    return reader or CSV


def readers_taking(option: str) -> tuple[Reader, ...]:
    """The formats a reading option (``"sep"``, ``"decimal"``, ``"sheet"``,
    ``"header_row"``) applies to."""
    return tuple(reader for reader in FORMATS if option in reader.options)


def column_names(path: str | os.PathLike) -> list[str]:
    """The column names in a data file's header, the rest of the file unread; a stream
    (pipe, FIFO, ``/dev/stdin``) is read once and its bytes kept for the loader. Raises
    BenchDataError, or the format library's own error, where the file cannot be read."""
    p, shown = Path(path), str(path)
    stream = read_ahead(p, shown)
    return reader_for(p, stream).names(p, shown, stream)
