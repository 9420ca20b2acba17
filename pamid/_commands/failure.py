"""What the ``pamid`` command says when something other than its input fails.

Exit codes of every command: 0 done; 1 a fit that did not converge (reported, not dropped);
2 bad input or a bad output place (one line naming the file, column and row); 3 an internal
failure: out of memory, or a defect in pamid (one line, never a traceback; ``PAMID_DEBUG=1``
re-raises it); 130 interrupted (Ctrl-C) and 143 terminated (SIGTERM), with ``--out`` left
as it was (:func:`pamid._io.output_folder`); 141 stdout closed early (``pamid fit --json | head``:
128 + SIGPIPE, what a shell reports for a program ended by a closed pipe), with nothing
printed.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from pathlib import Path

EXIT_INTERNAL = 3
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141
EXIT_TERMINATED = 143  # 128 + SIGTERM


class Terminated(BaseException):
    """SIGTERM arrived: raised in the main thread so that every ``finally`` and every
    clean-up runs (the staging folder of :func:`pamid._io.output_folder` is removed, no
    half-written file is left behind)."""


#: Signals received while :func:`catch_signals`' handlers were in place, first first.
_RECEIVED: list[int] = []
#: Whether a command's handlers are in place (:func:`catch_signals` to
#: :func:`restore_signals`): only then does a signal raise.
_ACTIVE = False
#: Seconds after a signal's exception was swallowed (:func:`_on_unraisable`) before the
#: signal is sent to the main thread again.
REDELIVER_S = 0.02
_LOCK = threading.Lock()
#: The number of the command whose handlers are in place: a redelivery timer that fires
#: late (a loaded machine; seen in a full test run, where it ended the next test's command
#: with "interrupted") acts only on the command it was started in.
_RUN = [0]
_PREVIOUS_HOOK: list = []
#: Whether a signal's exception is on its way (raised and not swallowed since): a second
#: signal (a redelivery, another kill) then does not interrupt the clean-up it runs.
_RAISED = False


def _on_signal(signum, frame):
    global _RAISED
    _RECEIVED.append(signum)
    # Not after restore_signals has begun (a late redelivery ends nothing), nor a second
    # time while the first exception is still on its way.
    if _ACTIVE and not _RAISED:
        _RAISED = True
        raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt


def _on_unraisable(unraisable) -> None:
    """``sys.unraisablehook`` while a command runs. Python runs a signal handler between
    two bytecodes of the main thread, which may be inside a garbage collector's callback
    (JAX registers one) or a ``__del__``: there the handler's exception is "ignored",
    printed with its traceback and dropped, and the command ran on to its end (a SIGTERM
    acted on 33 s late, before the commit, by :func:`raise_if_signalled`). Here it is
    dropped silently and the signal sent again to the main thread a moment later, when the
    finalizer is over, so that it ends the command where it runs."""
    global _RAISED
    exc = unraisable.exc_value
    if _ACTIVE and _RECEIVED and isinstance(exc, (Terminated, KeyboardInterrupt)):
        _RAISED = False
        signum = signal.SIGTERM if isinstance(exc, Terminated) else signal.SIGINT
        timer = threading.Timer(REDELIVER_S, _redeliver, (signum, _RUN[0]))
        timer.daemon = True
        timer.start()
        return
    (_PREVIOUS_HOOK[-1] if _PREVIOUS_HOOK else sys.__unraisablehook__)(unraisable)


def _redeliver(signum, run: int) -> None:
    with _LOCK:  # to the command whose finalizer swallowed it, never a later one
        if _ACTIVE and _RUN[0] == run:
            signal.pthread_kill(threading.main_thread().ident, signum)


def catch_signals():
    """Turn SIGTERM into :class:`Terminated` and SIGINT into :class:`KeyboardInterrupt` for
    the running command, and remember that they came (:func:`raise_if_signalled`); a signal
    whose exception a finalizer swallowed is sent again (:func:`_on_unraisable`). Returns
    the previous handlers (None outside the main thread, where no handler can be set)."""
    global _ACTIVE, _RAISED
    if threading.current_thread() is not threading.main_thread():
        return None
    _RECEIVED.clear()
    _RAISED = False
    _RUN[0] += 1
    _PREVIOUS_HOOK.append(sys.unraisablehook)
    sys.unraisablehook = _on_unraisable
    _ACTIVE = True
    return {s: signal.signal(s, _on_signal) for s in (signal.SIGTERM, signal.SIGINT)}


def raise_if_signalled() -> None:
    """Raise the exception of a signal that came but did not end the command: Python runs a
    signal handler between two bytecodes of the main thread, which may be inside a garbage
    collector's callback (JAX registers one) or a ``__del__``, where an exception is
    printed as "ignored" and dropped. A Ctrl-C there was lost: the command ran on and
    replaced ``--out``. Called before the results are committed."""
    global _RAISED
    if _RECEIVED:
        _RAISED = True
        raise Terminated if _RECEIVED[0] == signal.SIGTERM else KeyboardInterrupt


def restore_signals(previous) -> None:
    global _ACTIVE
    if previous is not None:
        _ACTIVE = False  # first: a signal from here on is remembered, never raised
        with _LOCK:  # and no redelivery is under way
            pass
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
        sys.unraisablehook = _PREVIOUS_HOOK.pop() if _PREVIOUS_HOOK else sys.__unraisablehook__
#: Longest message quoted from an exception (XLA's run to many lines).
MAX_QUOTE = 300


def is_out_of_memory(exc: BaseException) -> bool:
    """A ``MemoryError`` (NumPy, Python) or XLA's RESOURCE_EXHAUSTED (a JAX runtime error:
    ``jax.errors.JaxRuntimeError``, ``XlaRuntimeError`` in older jaxlib)."""
    if isinstance(exc, MemoryError):
        return True
    text = str(exc)
    return "RESOURCE_EXHAUSTED" in text or "Out of memory" in text


def _quote(exc: BaseException) -> str:
    lines = [s.strip() for s in str(exc).splitlines() if s.strip()]
    text = lines[0] if lines else ""
    return text if len(text) <= MAX_QUOTE else text[: MAX_QUOTE - 1] + "…"


def describe(exc: BaseException, command: str | None) -> str:
    """One line: what happened and what to do."""
    what = f"{type(exc).__name__}: {_quote(exc)}" if _quote(exc) else type(exc).__name__
    if is_out_of_memory(exc):
        advice = {"diagnose": "try --max-rows N or a machine with more memory",
                  "fit": "a Parquet file bigger than memory is fitted a chunk of muscles at "
                         "a time with --stream (a CSV file: convert it to Parquet first); "
                         "or a machine with more memory"}.get(
            command, "try a smaller file or a machine with more memory")
        return f"out of memory ({what}); {advice}"
    return (f"internal error ({what}); rerun with PAMID_DEBUG=1 for the traceback and "
            "report it")


def describe_exit(exc: SystemExit) -> str:
    """One line for a ``SystemExit`` raised inside a command: only code of the user's (a
    ``--model`` file's class, called while the model is fitted) ends the program there, so
    it names the user's file and line where the traceback shows it."""
    import sysconfig
    import traceback

    library = [str(Path(__file__).resolve().parents[1]), *{
        sysconfig.get_path(k) for k in ("stdlib", "platstdlib", "purelib", "platlib")}]
    frames = [f for f in traceback.extract_tb(exc.__traceback__)
              if not f.filename.startswith("<")
              and not any(str(Path(f.filename).resolve()).startswith(lib) for lib in library)]
    where = f"{frames[-1].filename}, line {frames[-1].lineno}: " if frames else ""
    return (f"{where}user code ended the program (SystemExit: {exc.code!r}) while pamid ran "
            "it; a model must return forces, not exit")


def debugging() -> bool:
    """``PAMID_DEBUG`` set to anything but empty or 0: failures keep their traceback."""
    return os.environ.get("PAMID_DEBUG", "") not in ("", "0")


def silence_stdout() -> None:
    """After a broken pipe: point stdout at the null device, so that the interpreter's last
    flush at exit does not fail again and print its own complaint."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, sys.stdout.fileno())
        os.close(null)
    except (OSError, ValueError, AttributeError):  # stdout is no file (a test's capture)
        pass
