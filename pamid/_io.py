"""Atomic writing of output files (reports, tables, figures).

Every writer here puts the content into a temporary file in the destination's own directory
and then renames it over the destination with :func:`os.replace`, which is atomic on POSIX
and Windows when both paths are on one file system. A reader therefore sees either the old
file or the complete new one, never a half-written file; if writing fails, the temporary
file is removed and an existing destination is left untouched. Parent directories are
created as needed.

A command's results go through :func:`output_folder`: every file of one run is written into
a fresh hidden folder and moved into the output folder as one set when the run ends, so that
a run either leaves its complete result set or changes nothing there.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

__all__ = [
    "OutputPlaceError",
    "check_output_place",
    "final_place",
    "output_folder",
    "protect_inputs",
    "refuse_inputs_among_outputs",
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


def refuse_inputs_among_outputs(inputs: Iterable[str | os.PathLike | None],
                                out: str | os.PathLike | None,
                                outputs: Iterable[str]) -> None:
    """Before any computing: an input file that lies in the output folder ``out`` under a
    name the command writes there (``outputs``: names and patterns, ``fit.json``,
    ``fit_*.png``) is refused as :func:`refuse_overwrite_input` refuses it (ValueError,
    one line), not when the results are written, after the work."""
    import fnmatch

    if not out:
        return
    outputs = tuple(outputs)
    for inp in inputs:
        if inp and any(fnmatch.fnmatchcase(Path(inp).name, p) for p in outputs):
            refuse_overwrite_input(Path(out) / Path(inp).name, [inp])


def check_output_place(out: str | os.PathLike | None) -> None:
    """Check an output folder before any computing: it is a folder or can be made one, and
    it can be written. Raises :class:`OutputPlaceError` naming the problem."""
    if out is None:
        return
    out = Path(out)
    if out.is_symlink() and not out.exists():
        raise OutputPlaceError(f"--out {out} is a symbolic link to {os.readlink(out)}, which "
                               "does not exist; make that folder or name another")
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
    place = final_place(dest)  # where it ends up: inside an output_folder, not the staging
    for target in {dest, place}:
        if target.is_dir():
            raise OutputPlaceError(f"cannot write {target}: it is a folder; remove it or "
                                   "choose another output folder")
    for inp in _PROTECTED:  # the inputs of the running command (protect_inputs)
        refuse_overwrite_input(place, [inp])
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
        try:  # the file it replaces (in the output folder, past the staging)
            mode = place.stat().st_mode & 0o7777
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


#: Longest piece of a file name, in UTF-8 bytes, that :func:`safe_file_name` makes of a
#: muscle's or a trial's name: with the longest prefix ("mcmc_predictive_"), a suffix
#: (".png") and the temporary name :func:`write_atomic` writes first
#: (".NAME.XXXXXXXX.tmp"), a file name stays well under the 255 bytes file systems allow.
MAX_NAME_BYTES = 160


def _name_hash(text: str) -> str:
    """8 hex digits of the SHA-256 of ``text``: the same in every run and on every machine."""
    import hashlib

    return hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:8]


def safe_file_name(name, *, hashed: bool = False) -> str:
    """``name`` (a muscle's, a trial's) as a piece of a file name that still says whose file
    it is: letters, digits, '-', '_' and '.' kept, anything else '_', at most
    :data:`MAX_NAME_BYTES` bytes. Where that changes the name (a character replaced, a name
    cut short), or with ``hashed``, '-' and a hash of the name are appended, so that names
    that read alike never share a file: 'A/B' → 'A_B-998d3ed8', 'A B' → 'A_B-fea4c5ce',
    while 'A_B' and 'Festo10mm_lc40cm' stay as they are. The names of one command's files
    come from :func:`safe_file_names`."""
    text = str(name)
    safe = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in text)
    encoded = safe.encode("utf-8")
    if not hashed and safe == text and len(encoded) <= MAX_NAME_BYTES:
        return safe
    head = encoded[: MAX_NAME_BYTES - 9].decode("utf-8", "ignore")  # a whole character
    return f"{head}-{_name_hash(text)}"


def safe_file_names(names) -> list[str]:
    """:func:`safe_file_name` of each of ``names`` (the muscles of one file, its trials),
    unique among them, also where a file system does not tell capitals from small letters:
    names whose pieces still meet ('M1' and 'm1'; a name written like another's hashed
    piece) get the hash too, and a coincidence left after that their place in ``names``."""
    names = list(names)
    pieces = [safe_file_name(n) for n in names]
    for hashed in (True, False):
        counts: dict[str, int] = {}
        for piece in pieces:
            counts[piece.casefold()] = counts.get(piece.casefold(), 0) + 1
        for i, piece in enumerate(pieces):
            if counts[piece.casefold()] > 1:
                pieces[i] = safe_file_name(names[i], hashed=True) if hashed else f"{piece}-{i}"
    return pieces


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


# --------------------------------------------------------------------------------------
# One run's results as one set: output_folder

#: The hidden file of an output folder that lists, per command, the files its last run left
#: there: a re-run replaces exactly that set, and every other file in the folder is left be.
MANIFEST = ".pamid-outputs.json"
#: Name of the hidden folder a run writes into (``.pamid-staging-<out>-XXXXXXXX``).
STAGING_PREFIX = ".pamid-staging-"

#: The output folders of running commands: (staging folder, the output folder it becomes).
_STAGED: list[tuple[Path, Path]] = []


def final_place(path: str | os.PathLike) -> Path:
    """Where ``path`` will be when its run ends: a path inside the staging folder of an
    active :func:`output_folder` is mapped to the output folder (for messages, and for the
    checks of the writers); any other path is returned as it is."""
    path = Path(path)
    absolute = Path(os.path.abspath(path))
    for staging, final in _STAGED:
        if absolute == staging or staging in absolute.parents:
            return final / absolute.relative_to(staging)
    return path


@contextlib.contextmanager
def output_folder(out: str | os.PathLike | None, *, command: str) -> Iterator[Path | None]:
    """The results of one run of ``command`` as one set: yields a fresh hidden folder to
    write them into, and moves its content into ``out`` when the block ends without an
    exception. Yields None (and does nothing) when ``out`` is None or empty.

    Before anything is computed, the output place is checked (:func:`check_output_place`),
    missing parent folders are made and the staging folder is created: in ``out`` when it
    is a folder already, beside it otherwise (same file system either way, so that the
    results are moved by renaming, not copied).

    The guarantee. When the block raises anything (an error, :class:`KeyboardInterrupt`
    from SIGINT, SIGTERM turned into an exception by
    :func:`pamid._commands.failure.catch_signals`), the staging folder and the parent
    folders made for it are removed, and ``out`` is left byte for byte as it was (or absent,
    as it was). When the block ends normally: a new ``out`` is the staging folder renamed,
    one atomic step; into an existing ``out``, the set of files the previous run of the same
    ``command`` left there (listed in its :data:`MANIFEST`) and every file of the same name
    as a new one are moved aside, the new files are renamed in, and the old ones are
    deleted. Those renames take milliseconds, SIGINT and SIGTERM are held while they run
    (and acted on after), and if one fails the renames done are undone and ``out`` is as it
    was (exit 2, one line). Only a hard kill (SIGKILL, power loss) inside that window can
    leave a mix, and then the old files are in the leftover ``.pamid-staging-*`` folder.
    Files in ``out`` that ``command`` neither wrote last time nor writes now (a user's
    notes, another command's results) are never touched; no output ever replaces an input
    file of the run (:func:`protect_inputs`), and an earlier output that is now an input
    stays.
    """
    if out is None or str(out) == "":
        yield None
        return
    final = Path(out)
    check_output_place(final)
    made: list[Path] = []
    staging = None
    try:
        with _signals_held():  # a signal now still finds what to remove below
            made = _make_parents(final.parent)
            holder = Path(os.path.abspath(final if final.is_dir() else final.parent))
            try:
                staging = Path(tempfile.mkdtemp(prefix=f"{STAGING_PREFIX}{final.name}-",
                                                dir=holder))
            except OSError as exc:
                raise OutputPlaceError(f"--out {final}: cannot write in {holder}: "
                                       f"{exc.strerror or exc}") from exc
        os.chmod(staging, 0o777 & ~_umask())  # a new --out: a folder as mkdir makes it
        _STAGED.append((staging, final))
        try:
            yield staging
        finally:
            _STAGED.remove((staging, final))
        with _signals_held():
            _commit(staging, final, command)
    except BaseException:
        with _signals_held():
            if staging is not None:
                shutil.rmtree(staging, ignore_errors=True)
            _remove_made(made)
        raise


def _make_parents(folder: Path) -> list[Path]:
    """Make ``folder`` and its missing parents; returns the folders made, deepest first."""
    missing = []
    place = Path(os.path.abspath(folder))
    while not place.exists() and place.parent != place:
        missing.append(place)
        place = place.parent
    try:
        for made in reversed(missing):
            made.mkdir()
    except OSError as exc:
        _remove_made(missing)
        raise OutputPlaceError(f"cannot create the folder {folder}: "
                               f"{exc.strerror or exc}") from exc
    return missing


def _remove_made(made: list[Path]) -> None:
    for folder in made:  # deepest first; a folder someone else has filled stays
        try:
            folder.rmdir()
        except OSError:
            return


@contextlib.contextmanager
def _signals_held() -> Iterator[None]:
    """SIGINT and SIGTERM wait until the block ends, then act as they would have (Python
    signal handlers: any thread of the process may receive the signal, so a thread's signal
    mask would not hold it). Outside the main thread nothing can be held."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    held = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.signal(s, lambda signum, frame: caught.append(signum)) for s in held}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
        if caught:
            signal.raise_signal(caught[0])


def _plain_name(name) -> bool:
    """A file name directly in the folder (a manifest someone edited cannot name others)."""
    return (isinstance(name, str) and name not in ("", ".", "..", MANIFEST)
            and "/" not in name and "\\" not in name and "\0" not in name)


def _read_manifest(folder: Path) -> dict[str, list[str]]:
    """The folder's manifest: command → names of its last run's files ({} without one)."""
    try:
        commands = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))["commands"]
        return {str(c): [n for n in names if _plain_name(n)] for c, names in commands.items()
                if isinstance(names, list)}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}


def _input_at(path: Path) -> str | None:
    """The message refusing to replace ``path`` when it is, or is a folder holding, an
    input file of the running command; None otherwise."""
    for inp in _PROTECTED:
        try:
            refuse_overwrite_input(path, [inp])
        except ValueError as exc:
            return str(exc)
        if path.resolve() in inp.resolve().parents:
            return f"refusing to replace {path}: it holds the input file {inp}"
    return None


def _commit(staging: Path, final: Path, command: str) -> None:
    """Move the staged results into ``final`` (see :func:`output_folder`)."""
    previous = _read_manifest(final) if final.is_dir() else {}
    new = sorted(p.name for p in staging.iterdir())
    manifest = {c: [n for n in names if n not in new] for c, names in previous.items()
                if c != command}
    manifest[command] = new
    (staging / MANIFEST).write_text(json.dumps({
        "about": "written by pamid: the files of the last run of each command in this "
                 "folder, replaced as one set when the command writes here again",
        "commands": {c: names for c, names in sorted(manifest.items()) if names}},
        indent=2) + "\n", encoding="utf-8")
    units = [*new, MANIFEST]
    for name in units:  # every refusal before anything moves
        target = final / name
        refusal = _input_at(target)
        if refusal:
            raise OutputPlaceError(refusal)
        if (staging / name).is_file() and target.is_dir() and not target.is_symlink():
            raise OutputPlaceError(f"cannot write {target}: it is a folder; remove it or "
                                   "choose another output folder")
    if not os.path.lexists(final):
        try:
            os.rename(staging, final)  # a new folder: one atomic step
            return
        except OSError:  # made meanwhile by someone else: merge into it as below
            pass
    stale = [n for n in previous.get(command, []) if n not in units
             and os.path.lexists(final / n) and _input_at(final / n) is None]
    done: list[tuple[Path, Path]] = []
    try:
        aside = Path(tempfile.mkdtemp(prefix=".replaced-", dir=staging))
        for name in [*units, *stale]:
            if os.path.lexists(final / name):
                os.replace(final / name, aside / name)
                done.append((final / name, aside / name))
        for name in units:
            os.replace(staging / name, final / name)
            done.append((staging / name, final / name))
    except OSError as exc:
        for src, dst in reversed(done):  # undo: the folder as it was
            with contextlib.suppress(OSError):
                os.replace(dst, src)
        raise OutputPlaceError(f"cannot move the results into {final}: "
                               f"{exc.strerror or exc}; it is left as it was") from exc
    shutil.rmtree(staging, ignore_errors=True)
