"""Atomic writing of output files (reports, tables, figures).

Every writer here puts the content into a temporary file in the destination's own directory
and then renames it over the destination with :func:`os.replace`, which is atomic on POSIX
and Windows when both paths are on one file system. A reader therefore sees either the old
file or the complete new one, never a half-written file; if writing fails, the temporary
file is removed and an existing destination is left untouched. Parent directories are
created as needed.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

__all__ = [
    "OutputPlaceError",
    "check_output_place",
    "protect_inputs",
    "refuse_overwrite_input",
    "save_figure_atomic",
    "write_atomic",
    "write_bytes_atomic",
    "write_frame_atomic",
    "write_text_atomic",
]

PARQUET_SUFFIXES = (".parquet", ".pq")

_umask_cache: int | None = None


def _umask() -> int:
    """The process umask (read once; os.umask can only be read by setting it)."""
    global _umask_cache
    if _umask_cache is None:
        old = os.umask(0o022)
        os.umask(old)
        _umask_cache = old
    return _umask_cache


class OutputPlaceError(ValueError):
    """An output cannot be written where it was asked for (a folder in its place, a file
    where a folder is needed, no permission, or an input file of the command)."""


#: Input files of the running command: no writer here ever replaces one of them.
_PROTECTED: list[Path] = []


def protect_inputs(paths: Iterable[str | os.PathLike | None]) -> None:
    """Declare the input files of the running command; every writer of this module then
    refuses to write onto any of them (``pamid fit DIR/fit_M1.png --out DIR``). Replaces
    the previous declaration; ``protect_inputs([])`` clears it."""
    _PROTECTED[:] = [Path(p) for p in paths if p]


def check_output_place(out: str | os.PathLike | None) -> None:
    """Check an output folder before any computing: it is a folder or can be made one, and
    it can be written. Raises :class:`OutputPlaceError` naming the problem."""
    if out is None:
        return
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise OutputPlaceError(f"--out {out} is a file, not a folder; name a folder for the "
                               "results")
    place = out
    while not place.exists():  # the nearest existing folder is where it will be made
        if place.parent == place:
            break
        place = place.parent
    if place.exists() and not place.is_dir():
        raise OutputPlaceError(f"--out {out}: {place} is a file, so no folder can be made "
                               "there")
    if place.exists() and not os.access(place, os.W_OK | os.X_OK):
        raise OutputPlaceError(f"--out {out}: no permission to write in {place}")


def write_atomic(path: str | os.PathLike, write_fn: Callable[[str], Any]) -> Path:
    """Write ``path`` atomically: ``write_fn(tmp_path)`` writes the content to a temporary file.

    ``write_fn`` receives the temporary file's path as a string and must write the whole
    content there (it may open, truncate and close it as it likes). On success the temporary
    file is flushed to disk and renamed to ``path``; if ``write_fn`` raises, the temporary
    file is deleted and the exception propagates, leaving no partial file behind. A new file
    gets the usual permissions (0666 less the umask); an existing file keeps its mode.
    Returns ``path`` as a :class:`pathlib.Path`.
    """
    dest = Path(path)
    if dest.is_dir():
        raise OutputPlaceError(f"cannot write {dest}: it is a folder; remove it or choose "
                               "another output folder")
    for inp in _PROTECTED:  # the inputs of the running command (protect_inputs)
        refuse_overwrite_input(dest, [inp])
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputPlaceError(f"cannot create the folder {dest.parent}: "
                               f"{exc.strerror or exc}") from exc
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".tmp", dir=dest.parent)
    except OSError as exc:
        raise OutputPlaceError(f"cannot write in {dest.parent}: {exc.strerror or exc}") from exc
    os.close(fd)
    try:
        write_fn(tmp)
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        try:
            mode = dest.stat().st_mode & 0o7777
        except FileNotFoundError:
            mode = 0o666 & ~_umask()
        os.chmod(tmp, mode)
        os.replace(tmp, dest)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return dest


def write_text_atomic(path: str | os.PathLike, text: str, *, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (``encoding`` defaults to UTF-8)."""
    data = text.encode(encoding)
    return write_bytes_atomic(path, data)


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""

    def write(tmp: str) -> None:
        with open(tmp, "wb") as fh:
            fh.write(data)

    return write_atomic(path, write)


def write_frame_atomic(
    path: str | os.PathLike, frame, *, index: bool = False, sep: str = ",", decimal: str = "."
) -> Path:
    """Write a pandas DataFrame to ``path`` atomically.

    The format follows the extension: ``.parquet`` or ``.pq`` gives Parquet (via pyarrow),
    anything else CSV (UTF-8, floats written so that they read back exactly; ``sep`` and
    ``decimal`` give the separator and the decimal mark, comma and point by default).
    The index is left out unless ``index=True``.
    """
    parquet = Path(path).suffix.lower() in PARQUET_SUFFIXES

    def write(tmp: str) -> None:
        if parquet:
            frame.to_parquet(tmp, index=index, engine="pyarrow")
        else:
            frame.to_csv(
                tmp, index=index, encoding="utf-8", lineterminator="\n", sep=sep,
                decimal=decimal,
            )

    return write_atomic(path, write)


def save_figure_atomic(fig, path: str | os.PathLike, **savefig_kwargs) -> Path:
    """Save a matplotlib figure to ``path`` atomically (PNG unless the extension says else).

    The image format is taken from the extension of ``path`` (``.png`` when there is none),
    because the temporary file's own name does not carry it. Further keyword arguments go to
    :meth:`matplotlib.figure.Figure.savefig` (e.g. ``dpi=150``).
    """
    fmt = Path(path).suffix.lstrip(".").lower() or "png"
    savefig_kwargs.setdefault("format", fmt)

    def write(tmp: str) -> None:
        fig.savefig(tmp, **savefig_kwargs)

    return write_atomic(path, write)


def refuse_overwrite_input(
    out_path: str | os.PathLike, input_paths: Iterable[str | os.PathLike]
) -> None:
    """Raise ValueError if ``out_path`` is one of ``input_paths``.

    Paths are compared after resolving symbolic links and ``..``; where both files exist,
    hard links to the same file are caught too. Inputs that do not exist are compared by
    their resolved path only.
    """
    out = Path(out_path)
    out_resolved = out.resolve()
    for inp in input_paths:
        inp_path = Path(inp)
        same = inp_path.resolve() == out_resolved
        if not same and out.exists() and inp_path.exists():
            try:
                same = os.path.samefile(out, inp_path)
            except OSError:
                same = False
        if same:
            raise ValueError(
                f"refusing to write {out}: it is the input file {inp_path}; "
                "choose another output path"
            )


def json_ready(value):
    """``value`` with NumPy scalars and arrays made plain Python, recursively, every
    non-finite float made None (JSON has no NaN), and dictionary keys made strings (as JSON
    writes them; a NumPy key would not be written at all)."""
    import numpy as np

    if isinstance(value, dict):
        return {str(k): json_ready(x) for k, x in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [json_ready(x) for x in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    return value
