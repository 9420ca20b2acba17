"""The ``pamid`` command: ``pamid fit``, ``pamid demo``, ``pamid simulate lifting-mass``,
``pamid damping`` and ``pamid check-decays``.

Bad input ends with a one-line message that names the file, column and row, and exit code 2;
no traceback. Exit codes: 0 done; 1 a fit that did not converge; 2 bad input or a bad output
place, or a wrong option (argparse's errors in one line too); 3 an internal failure — out of
memory, or a defect — told in one line (``PAMID_DEBUG=1`` shows the traceback instead); 130
interrupted; 143 terminated (SIGTERM); 141 stdout closed early
(``pamid fit --json | head``), silently (:mod:`pamid._commands.failure`). Results go to
``--out`` as one set when the command has finished; on any failure or signal ``--out`` is
left as it was (:func:`pamid._io.output_folder`). ``--json``
prints exactly one JSON object on stdout; warnings and progress go to stderr. Compiled
code is cached on disk (``PAMID_CACHE_DIR``, default ``~/.cache/pamid/jax``), so the second
call of a command skips compilation.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import warnings

EXIT_BAD_INPUT = 2
#: Arguments of the commands that name input files (never written; see pamid._io).
_INPUT_ARGUMENTS = ("data", "decay", "model_json", "fit")


def _enable_compilation_cache():
    """Switch on the compilation cache and the exported programs for this command
    (:func:`pamid._lanes._export_cache.use_disk_caches`, ``PAMID_CACHE_DIR``); returns the
    function that puts the caller's settings back."""
    from ._lanes._export_cache import use_disk_caches

    return use_disk_caches()


class _Parser(argparse.ArgumentParser):
    """argparse with its errors in one line, exit 2, for every subcommand (subparsers take
    the class of their parent): ``pamid fit: error: argument --max-plots: invalid int
    value: '1.5' (see pamid fit --help)``. ``PAMID_DEBUG=1`` prints argparse's usage above
    it, for developers."""

    def error(self, message: str):
        from ._commands import failure

        if failure.debugging():
            self.print_usage(sys.stderr)
        message = " ".join(str(message).split())
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def format_help(self) -> str:
        # A description may be a function, called only when the help is shown: the text
        # of `pamid diagnose --help` lists the effects' registry, which imports JAX, and
        # every command builds every parser (`pamid fit` waited 1 s for it).
        if callable(self.description):
            self.description = self.description()
        return super().format_help()

    def parse_args(self, args=None, namespace=None):
        # argparse reports an unknown option from the top parser ("pamid: error: ...");
        # name the subcommand it was given to instead.
        namespace, extra = self.parse_known_args(args, namespace)
        if extra:
            prog = " ".join(filter(None, (self.prog, _command_name(namespace))))
            _Parser(prog=prog, add_help=False).error(
                f"unrecognized arguments: {' '.join(extra)}")
        return namespace


def _command_name(args) -> str:
    """The (sub)command given: ``fit``, ``simulate lifting-mass``, … ("" for none)."""
    words = (getattr(args, "command", None), getattr(args, "system", None))
    return " ".join(filter(None, words))


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="pamid", description="System identification for pneumatic artificial muscles."
    )
    sub = parser.add_subparsers(dest="command", required=True)

    from ._commands import demo, fit

    fit.register(sub)
    demo.register(sub)

    from ._commands import dynamics

    dynamics.register(sub)

    from ._commands import check

    check.register(sub)

    from ._commands import diagnose

    diagnose.register(sub)

    from ._commands import compare

    compare.register(sub)

    from ._commands import predict

    predict.register(sub)

    from ._commands import warmup

    warmup.register(sub)
    return parser


def _input_files(args) -> list[str]:
    """The input files named on the command line, a model file (``--model FILE.py:CLASS``)
    included: no output ever replaces one (pamid._io.protect_inputs)."""
    files = [getattr(args, name, None) for name in _INPUT_ARGUMENTS]
    model = getattr(args, "model", None)
    if isinstance(model, str) and ":" in model:
        files.append(model.rsplit(":", 1)[0])
    return files


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from . import _io
    from ._commands import failure
    from ._errors import BenchDataError, UntrustedResultError
    from ._lanes import _export_cache

    exporting = _export_cache.directory()
    signals = failure.catch_signals()
    restore_cache = lambda: None  # noqa: E731 (set where the cache is switched on)
    try:
        # Before any computing: the output place can be written, and no output of this run
        # can replace one of its input files (every writer of pamid._io checks). The
        # command writes into a hidden staging folder, moved into --out as one set when it
        # returns; on any failure or signal --out is left as it was (pamid._io.output_folder).
        _io.protect_inputs(_input_files(args))
        _io.refuse_inputs_among_outputs(_input_files(args), getattr(args, "out", None),
                                        getattr(args, "outputs", ()))
        with _io.output_folder(getattr(args, "out", None),
                               command=_command_name(args)) as staging, \
                warnings.catch_warnings():  # the start-up thread's warnings too
            warnings.simplefilter("always")
            warnings.showwarning = _show_warning
            if staging is not None:
                args.out = str(staging)
            if getattr(args, "before_jax", None) is not None:
                args.before_jax(args)  # what must come before JAX starts (jax.distributed)
            if getattr(args, "prepare", None) is not None:
                # JAX's start-up, the disk caches and what the command does before its data
                # are read, on a thread of their own while it reads them.
                args.startup = _export_cache.prepare_in_background(
                    disk_caches=True, then=lambda: args.prepare(args))
                restore_cache = args.startup.restore
            else:
                restore_cache = _enable_compilation_cache()
            code = args.func(args)
            failure.raise_if_signalled()  # a Ctrl-C that a callback swallowed: no commit
            _export_cache.keep_manifest()  # the programs it called, for the next such run
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's exit
        return code
    except BenchDataError as exc:
        print(f"pamid: error: {_option_words(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except ValueError as exc:  # bad options (a solver name, an output path onto an input)
        if failure.debugging():
            raise
        print(f"pamid: error: {_option_words(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except UntrustedResultError as exc:  # exit 1, as a fit that did not converge
        print(f"pamid: error: {_option_words(exc)}", file=sys.stderr)
        if getattr(args, "json", False):  # --json: still exactly one JSON object
            print(json.dumps({"status": "not_trustworthy", "message": _option_words(exc)}))
        return 1
    except BrokenPipeError:  # `pamid fit --json | head -c 1`: the reader has what it wanted
        failure.silence_stdout()
        return failure.EXIT_BROKEN_PIPE
    except failure.Terminated:  # output_folder has removed the staging folder on the way out
        print("pamid: terminated", file=sys.stderr)
        return failure.EXIT_TERMINATED
    except KeyboardInterrupt:
        if failure.debugging():
            raise
        print("pamid: interrupted", file=sys.stderr)
        return failure.EXIT_INTERRUPTED
    except SystemExit as exc:  # user code (argparse's exits come before): its file, exit 2
        if failure.debugging():
            raise
        print(f"pamid: error: {failure.describe_exit(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as exc:  # out of memory, or a defect: one line, never a traceback
        if failure.debugging():
            raise
        print(f"pamid: error: {failure.describe(exc, args.command)}", file=sys.stderr)
        return failure.EXIT_INTERNAL
    finally:  # a caller in the same process (a test, a notebook) gets its setting back
        _export_cache.keep_manifest(keep=False)  # a prefetch still running ends here
        restore_cache()
        _export_cache.enable(exporting)
        _io.protect_inputs([])
        failure.restore_signals(signals)


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"pamid: warning: {_option_words(message)}", file=sys.stderr)


#: How the library's messages name a parameter of its functions (``load_bench(...,
#: keep_censored=True)``) that the command line sets by an option: the one place where an
#: error or a warning on its way to the command line takes the option's name instead.
_OPTION_OF_PARAMETER = (
    (r"\bkeep_censored=True\b", "--keep-censored"),
    (r"\bn_boot(strap)?\b", "--bootstrap"),
    (r"\bn_walkers\b", "--walkers"),
    (r"\bmax_steps\b", "--max-steps"),
    (r"\bmax_rows\b", "--max-rows"),
    (r"\bn_folds\b", "--folds"),
)


def _option_words(message) -> str:
    """``message`` (an exception, a warning) with the command line's options in place of
    the library's parameters: "pass keep_censored=True to keep them" → "pass
    --keep-censored to keep them"; "n_boot must be at least 2" → "--bootstrap must be at
    least 2"; a message that named both ("max_rows (--max-rows)") names the option once."""
    import re

    text = str(message)
    for pattern, option in _OPTION_OF_PARAMETER:
        text = re.sub(pattern, option, text)
    return re.sub(r"(--[a-z-]+) \(\1\)", r"\1", text)


def console_main() -> None:
    """Entry point of the installed ``pamid`` command (and of ``python -m pamid``): runs
    the command and ends the process with its exit code. To run a command inside a process
    that goes on (a test, a notebook), call :func:`main`, which returns the code.

    The command owns its process, so it picks pyarrow's memory pool before pyarrow is
    loaded (a user's ``ARROW_DEFAULT_MEMORY_POOL`` wins): the system allocator. With
    pyarrow's default on Linux (mimalloc), reading the 10,000-muscle file of
    ``benchmarks/end_to_end.py`` took 0.49–1.29 s from one fresh process to the next; with
    the system's, 0.60–0.68 s (benchmarks/README.md)."""
    os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
    code = main()
    if "matplotlib" not in sys.modules:
        # Not after drawing: matplotlib's exit handler removes the temporary configuration
        # folder it makes where its own cannot be written.
        _end_process(code)
    sys.exit(code)


def _end_process(code) -> None:
    """End the process that has just run a command, without the interpreter's teardown.

    Everything the command makes is written and closed by then (``--out`` is committed,
    stdout flushed by :func:`main`); what is left is Python freeing every object and module
    and the libraries' static destructors, 0.35–0.45 s after ``pamid fit`` of 10,000
    muscles (benchmarks/README.md, end_to_end.py). The streams are flushed here, and the
    logging handlers; the exit code is the command's."""
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a reader gone (main silenced stdout), or closed
            pass
    os._exit(int(code or 0))


if __name__ == "__main__":
    console_main()
