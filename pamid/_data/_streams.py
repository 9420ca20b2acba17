"""Reading a data file's bytes: regular files, and pipes, FIFOs and ``/dev/stdin``.

A file that is not a regular one (``pamid fit <(cat f.csv)``, ``/dev/stdin``, a FIFO) is
read once, whole, and its bytes go to every reader; one that has no extension is read as
the format its first bytes name (:func:`pamid._data._readers.reader_for`), else as CSV. The
first byte must arrive within :data:`STREAM_TIMEOUT_S` (10 s): a FIFO nobody writes to is an
error, not a wait for ever. A look at a stream's header before it is loaded
(:func:`read_ahead`, :func:`head_bytes`) keeps its bytes for the loader.
"""

from __future__ import annotations

import os
import select
import stat
import time
from pathlib import Path

from .._errors import BenchDataError


def _looks_binary(data: bytes) -> bool:
    """True for bytes that are clearly not a text table (NULs or many control bytes)."""
    head = data[:8192]
    if b"\x00" in head:
        return True
    control = sum(1 for b in head if b < 32 and b not in (9, 10, 12, 13))
    return control > 0.05 * len(head)


def _stream_key(path: Path, shown: str) -> tuple[int, int] | None:
    """None for a regular file, else the stream's identity (device, inode): a pipe, a FIFO,
    ``/dev/stdin``, a character device. Errors for a missing path or a directory."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        raise BenchDataError(shown, "file not found") from None
    except OSError as exc:
        raise BenchDataError(shown, f"cannot read the file: {exc.strerror or exc}") from exc
    if stat.S_ISDIR(info.st_mode):
        raise BenchDataError(shown, "is a directory, not a data file")
    if stat.S_ISREG(info.st_mode):
        return None
    return info.st_dev, info.st_ino


def _no_data(shown: str, timeout_s: float) -> BenchDataError:
    return BenchDataError(shown, f"no data arrived within {timeout_s:g} s (a pipe or FIFO "
                                 "with no writer?)")


def _read_stream(path: Path, shown: str, timeout_s: float) -> bytes:
    """Every byte of a pipe, FIFO or device, read once.

    The first byte must arrive within ``timeout_s`` seconds (a FIFO nobody writes to would
    otherwise block for ever); after it, the stream is read to its end however slowly it
    comes. A character device stops early once its bytes are plainly not text
    (``/dev/zero`` never ends)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # a FIFO with no writer opens too
    except OSError as exc:
        raise BenchDataError(shown, f"cannot read the file: {exc.strerror or exc}") from exc
    device = stat.S_ISCHR(os.fstat(fd).st_mode)
    chunks: list[bytes] = []
    size = 0
    try:
        poller = select.poll()
        poller.register(fd, select.POLLIN | select.POLLPRI)
        deadline = time.monotonic() + timeout_s
        while True:
            if chunks:
                wait = None  # data is coming: read it all
            else:
                wait = max(0.0, deadline - time.monotonic()) * 1000.0
            if not poller.poll(wait) and not chunks:
                raise _no_data(shown, timeout_s)
            try:
                chunk = os.read(fd, 1 << 20)
            except BlockingIOError:  # woken without data (a FIFO whose writer is not there)
                if not chunks and time.monotonic() >= deadline:
                    raise _no_data(shown, timeout_s) from None
                continue
            except OSError as exc:
                raise BenchDataError(shown, f"cannot read the file: {exc.strerror or exc}"
                                     ) from exc
            if not chunk:
                break  # the writer closed its end
            chunks.append(chunk)
            size += len(chunk)
            if device and size >= 8192 and _looks_binary(b"".join(chunks[:8])):
                break
    finally:
        os.close(fd)
    return b"".join(chunks)


#: Seconds :func:`load_bench` and :func:`load_decay` wait for the first byte from a pipe, a
#: FIFO or ``/dev/stdin`` before they give up (a FIFO with no writer never sends one).
STREAM_TIMEOUT_S = 10.0

# Streams read ahead by :func:`read_ahead`: their bytes (or the error reading them gave), for
# the next read of the same stream, which takes them.
_READ_AHEAD: dict[tuple[int, int], bytes | BenchDataError] = {}


def _stream_bytes(path: Path, shown: str, timeout_s: float | None = None) -> bytes | None:
    """The bytes of ``path`` if it is a stream (pipe, FIFO, ``/dev/stdin``, device), read once
    (a stream cannot be read twice: every reader of the file is handed these bytes); None for a
    regular file, which each reader reads itself. Errors for a missing path, a directory, an
    empty stream or one that sends nothing within ``timeout_s`` (:data:`STREAM_TIMEOUT_S`)."""
    key = _stream_key(path, shown)
    if key is None:
        return None
    data = _READ_AHEAD.pop(key, None)
    if data is None:
        data = _read_stream(path, shown, STREAM_TIMEOUT_S if timeout_s is None else timeout_s)
    if isinstance(data, BenchDataError):
        raise data
    if not data:
        raise BenchDataError(shown, "no data: the stream ended before its first byte (0 "
                                    "bytes); expected a table with a header")
    return data


def read_ahead(path: Path, shown: str) -> bytes | None:
    """None for a regular file; else every byte of the stream (pipe, FIFO, ``/dev/stdin``),
    read once and kept for the next :func:`_stream_bytes` of it, so that a look at the header
    does not spoil the stream for the loader. The error reading it gave is kept too, and
    raised again there (the stream is waited for once). Raises BenchDataError where the
    file cannot be read."""
    key = _stream_key(path, shown)
    if key is None:
        return None
    if key not in _READ_AHEAD:
        try:
            _READ_AHEAD[key] = _read_stream(path, shown, STREAM_TIMEOUT_S)
        except BenchDataError as exc:
            _READ_AHEAD[key] = exc
            raise
    data = _READ_AHEAD[key]
    if isinstance(data, BenchDataError):
        raise data
    return data


def head_bytes(path: str | os.PathLike, size: int = 65536) -> bytes:
    """The first ``size`` bytes of a data file, to tell what it holds (its header) without
    spoiling it for the reader: a stream (pipe, FIFO, ``/dev/stdin``) is read whole, once,
    and its bytes are handed to the next :func:`load_bench` or :func:`load_decay` of it.
    Raises BenchDataError where the file cannot be read."""
    p, shown = Path(path), str(path)
    data = read_ahead(p, shown)
    if data is None:
        try:
            with open(p, "rb") as f:
                return f.read(size)
        except OSError as exc:
            raise BenchDataError(shown, f"cannot read the file: {exc.strerror or exc}"
                                 ) from exc
    return data[:size]


def _read_bytes(path: Path, shown: str, data: bytes | None = None) -> bytes:
    """The file's bytes: ``data`` where the caller read the stream already, else read now."""
    if data is None:
        data = _stream_bytes(path, shown)
    if data is None:
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise BenchDataError(shown, f"cannot read the file: {exc.strerror or exc}"
                                 ) from exc
    if not data:
        raise BenchDataError(shown, "the file is empty (0 bytes); expected a table with a header")
    return data
