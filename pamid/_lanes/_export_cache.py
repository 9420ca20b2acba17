"""Traced and lowered programs kept on disk, so that a new process does not trace them again.

JAX's persistent compilation cache skips XLA's compile, but every process still traces the
Python code and lowers it to StableHLO before it can look the compiled program up; for the
one-muscle ``pamid fit`` that was most of the run (benchmarks/README.md, "Figures that used
to live in docstrings", (e); ``benchmarks/fit_batch.py`` section 6 times the command as a
whole). Here a function
is exported once per input shape with :mod:`jax.export` and serialized; a later process
deserializes it (milliseconds). Beside it, the program compiled from it is kept (``.xla``,
:func:`_executable`): a later process reads that back and runs it, without converting the
exported program to MLIR and hashing it for JAX's cache (about 20 ms a program, half of
what loading one cost: the Martens map's diagnosis loads 34 of them). A command that says
what it runs (:func:`expect`, once its rows are known) has the compiled programs that the
last run of its kind called read back on a thread of its own while it computes; at its end
it keeps the list of those it called (:func:`keep_manifest`, a ``manifests/`` file).

Off unless :func:`enable` has been called (the command line does, beside the compilation
cache). An entry is keyed by the caller's name for the function and its static arguments,
the shapes and dtypes of the inputs, the backend, a hash of pamid's own source files and the
versions of JAX and of the libraries traced with it (equinox, lineax, optimistix, jaxopt):
any change to that code makes new entries. A function that cannot be exported (a host
callback, say) runs as it is, and is remembered as such.

The exported program runs on one device; sharded calls do not come here.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import re
import threading
import zlib
from pathlib import Path

import numpy as np

from .._io import write_bytes_atomic

_DIR: Path | None = None
_LOCK = threading.Lock()
_LOADED: dict[str, object] = {}  # key → jitted exported.call, or None: run the function
_USED: dict[str, None] = {}  # the keys called in this process, in the order first called
_PENDING: dict[str, threading.Event] = {}  # keys being read by the prefetch thread
_PREFETCH: dict = {}  # "tag", "thread", "stop" of this process's manifest (expect())
_THREAD = threading.local()  # .cached_only: see cached_only()


class NotCached(LookupError):
    """Raised by :func:`call` inside :func:`cached_only` for a program not kept on disk."""


def only_cached() -> bool:
    """Whether this thread is inside :func:`cached_only`."""
    return getattr(_THREAD, "cached_only", False)


@contextlib.contextmanager
def cached_only():
    """Within this block, on this thread, :func:`call` runs only programs that are kept on
    disk (or loaded already) and raises :class:`NotCached` for any other, which it would
    have to trace and compile: for a warm-up that should load what is there and compile
    nothing (``pamid fit``'s, while it reads its file: a file refused by its later checks is
    told at once, not after a compile)."""
    before = getattr(_THREAD, "cached_only", False)
    _THREAD.cached_only = True
    try:
        yield
    finally:
        _THREAD.cached_only = before


def enable(directory) -> None:
    """Keep exported programs in ``directory`` (created if needed); None turns it off, and so
    does a directory that cannot be created (the programs are then traced as usual)."""
    global _DIR
    if directory is None:
        _DIR = None
        return
    path = Path(directory)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        _DIR = None
        return
    _DIR = path


def directory() -> Path | None:
    """Where exported programs are kept; None when the cache is off."""
    return _DIR


def use_disk_caches(directory=None):
    """Switch on the disk caches the ``pamid`` command uses: JAX's persistent compilation
    cache in ``directory`` and pamid's exported programs (:func:`enable`) in its
    ``exported`` folder, so that a later process neither traces nor compiles what an earlier
    one ran. ``directory``: default ``PAMID_CACHE_DIR``, else ``~/.cache/pamid/jax``; one
    that cannot be created or written leaves both caches as they were (everything is
    compiled as usual), with one warning that says so (JAX's cache, switched on there,
    warned once for every program it could not write). Returns the function that puts the
    caller's settings back (a test or a notebook calling the command in-process keeps
    compiling as it did before)."""
    import os
    import tempfile
    import warnings

    import jax
    from jax.experimental.compilation_cache import compilation_cache

    cache = directory or os.environ.get("PAMID_CACHE_DIR") or str(
        Path.home() / ".cache" / "pamid" / "jax")
    try:  # written to, not asked (os.access says yes to root on a read-only file system)
        Path(cache).mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".pamid-probe-", dir=cache)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:  # no reason to fail: every program is compiled as usual
        named = "PAMID_CACHE_DIR " if cache == os.environ.get("PAMID_CACHE_DIR") else ""
        warnings.warn(f"the compilation cache {named}{cache} cannot be written "
                      f"({exc.strerror or exc}): every program is compiled anew and none is "
                      "kept for the next run", stacklevel=2)
        return lambda: None
    names = ("jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs",
             "jax_persistent_cache_min_entry_size_bytes")
    before = {name: getattr(jax.config, name) for name in names}
    exporting = _DIR

    def restore() -> None:
        for name, value in before.items():
            jax.config.update(name, value)
        compilation_cache.reset_cache()
        enable(exporting)

    compilation_cache.reset_cache()
    jax.config.update("jax_compilation_cache_dir", str(cache))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    enable(Path(cache) / "exported")  # the traced programs: a new process skips tracing
    return restore


#: Packages whose code is traced into pamid's programs: a new version of any makes new entries.
TRACED_PACKAGES = ("jax", "jaxlib", "equinox", "lineax", "optimistix", "jaxopt")


@functools.cache
def _code_version() -> str:
    """A hash of every Python file of the pamid package and the versions of the packages it
    traces (an entry is stale once any of them changes)."""
    from importlib.metadata import PackageNotFoundError, version

    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    for name in TRACED_PACKAGES:
        try:
            h.update(f"{name}={version(name)}".encode())
        except PackageNotFoundError:
            h.update(f"{name}=none".encode())
    return h.hexdigest()


def prepare_in_background(disk_caches: bool = False, then=None) -> Startup:
    """Start a thread that does what the first compiled calls of a fit wait for, whatever
    the data, so that it runs while the caller reads its data file (pyarrow's parse and
    NumPy's copies release the GIL): importing JAX (``import pamid`` does not), the disk
    caches when ``disk_caches`` (:func:`use_disk_caches`), then ``then()`` (the command's
    checks of its options, which import the model), then JAX's CPU backend and its first
    array and the hash of pamid's source (:func:`_code_version`, when the cache is on).
    Neither SciPy nor pandas: a fit's programs call no LAPACK, its quantiles are pamid's
    own and its file is read without pandas (:mod:`pamid._data._columns`,
    :mod:`pamid._arrow`), so a fit imports neither (a program that calls LAPACK binds its
    kernels, from SciPy, where it is read back: :func:`_lapack_ready`).

    :meth:`Startup.result` waits for the thread and returns what ``then`` returned, or
    raises what it raised; :meth:`Startup.restore` waits for it and puts the caches'
    settings back. The warm-up is best effort: whatever fails or is not done yet there is
    done where it is needed (an import started on the thread is waited for by Python's
    import lock). ``pamid fit`` on 10,000 muscles: see benchmarks/README.md, end_to_end.py."""
    global _STARTING
    startup = _STARTING = Startup(disk_caches, then)
    startup.start()
    return startup


_STARTING = None  # the last Startup: its .caches tells when the disk caches are set


class Startup(threading.Thread):
    """The thread of :func:`prepare_in_background`.

    Not a daemon: the interpreter waits for it before it shuts down (a daemon thread still
    inside an extension's import when a command ends early, on a bad input say, crashed the
    process in its finalization: exit -11)."""

    def __init__(self, disk_caches: bool, then) -> None:
        super().__init__(name="pamid-prepare")
        self._disk_caches = disk_caches
        self._then = then
        self._restore = lambda: None
        self._value = None
        self._error: BaseException | None = None
        self.caches = threading.Event()  # set once the disk caches are on (or not to be)

    def run(self) -> None:
        try:
            try:
                if self._disk_caches:
                    self._restore = use_disk_caches()
            finally:
                self.caches.set()
            if self._then is not None:
                self._value = self._then()
        except BaseException as exc:  # noqa: BLE001 - handed to the caller by result()
            self._error = exc
            return
        try:
            import jax.numpy as jnp

            jnp.zeros(1).block_until_ready()

            if _DIR is not None:
                _code_version()
        except Exception:  # noqa: BLE001 - a warm-up only; the real call reports errors
            pass

    def result(self):
        """Wait for the thread; what ``then`` returned, or the exception it raised."""
        self.join()
        if self._error is not None:
            error, self._error = self._error, None
            raise error
        return self._value

    def value(self):
        """Wait for the thread; what ``then`` returned, or None where it raised (which
        :meth:`result` still raises)."""
        self.join()
        return None if self._error is not None else self._value

    def restore(self) -> None:
        """Wait for the thread, then put back the settings its :func:`use_disk_caches`
        changed."""
        self.join()
        self._restore()


def forget() -> None:
    """Drop the programs loaded in this process (read again from disk when next called):
    those read back compiled hold their executables, which ``jax.clear_caches`` leaves
    (:func:`pamid._lanes._programs.release_if_crowded`)."""
    with _LOCK:
        _LOADED.clear()


def _key(name: tuple, args) -> str:
    import jax

    leaves, treedef = jax.tree.flatten(args)
    avals = [(np.shape(a), str(a.dtype if hasattr(a, "dtype") else np.result_type(a)))
             for a in leaves]
    parts = (
        repr(name),
        str(treedef),
        repr(avals),
        jax.default_backend(),
        str(jax.config.jax_enable_x64),
        _code_version(),
    )
    return hashlib.sha256("\x1f".join(parts).encode()).hexdigest()


def call(name: tuple, fn, *args):
    """``fn(*args)``, through the exported program of ``fn`` for these input shapes when the
    cache is on. ``name`` must identify ``fn`` and everything it closes over (static
    arguments); ``args`` are pytrees of arrays (NumPy or JAX)."""
    only = only_cached()
    if _DIR is None:
        if only:
            raise NotCached(name)
        return fn(*args)
    key = _key(name, args)
    while True:
        with _LOCK:
            reading = _PENDING.get(key)
            if reading is None:
                _USED[key] = None
                if key not in _LOADED:
                    if only and not (_DIR / f"{key}.jaxexport").exists():
                        raise NotCached(name)
                    _LOADED[key] = _load_or_export(key, fn, args)
                program = _LOADED[key]
                break
        reading.wait()  # the prefetch thread is reading it (expect()): then loaded, or not
    if program is None and only:
        raise NotCached(name)
    return fn(*args) if program is None else program(*args)


def _read_exported(key: str):
    """``(exported, data)``: entry ``key``'s exported program and its serialized bytes, or
    ``(None, None)`` where there is none or it is damaged (exported again by the caller)."""
    from jax import export

    try:
        data = (_DIR / f"{key}.jaxexport").read_bytes()
        return export.deserialize(bytearray(data)), data
    except Exception:  # noqa: BLE001 - missing or damaged
        return None, None


def _load_or_export(key: str, fn, args):
    import jax
    from jax import export

    path = _DIR / f"{key}.jaxexport"
    failed = _DIR / f"{key}.failed"
    if failed.exists():
        return None
    options = compiler_options(args)
    exported, data = _read_exported(key)
    if exported is None:
        try:
            data = _export(jax.jit(fn), args).serialize()
        except Exception:  # noqa: BLE001 - not exportable: run the function itself from now on
            _remember(failed, b"")
            return None
        _remember(path, data)
        # The program as later processes will read it: compiled from the exported object
        # itself, its lowering differed from the deserialized one's, so the compilation
        # cache missed once more in the second process (benchmarks/README.md, "Figures
        # that used to live in docstrings", (e)).
        exported = export.deserialize(bytearray(data))
    jitted = jax.jit(exported.call, compiler_options=options)
    return _executable(key, options, exported, jitted, args, lapack=b"lapack_" in data)


class _Program:
    """A compiled program read back from disk (:func:`_executable`), called as the jitted
    exported program it was compiled from; that one (``fallback``) runs any call whose
    argument types differ from those it was compiled for (JAX's ``TypeError``, raised
    before anything runs), as jit would retrace it, and any call made where a device is
    chosen (``jax.default_device``, as :func:`pamid._lanes._batch.map_lanes` runs a call
    on the device ``use_devices`` picked): the compiled program runs on the device it was
    compiled for, the jitted one where it is called."""

    __slots__ = ("compiled", "fallback")

    def __init__(self, compiled, fallback) -> None:
        self.compiled, self.fallback = compiled, fallback

    def __call__(self, *args):
        import jax

        if jax.config.jax_default_device is not None:
            return self.fallback(*args)
        try:
            return self.compiled(*args)
        except TypeError:
            return self.fallback(*args)


def _executable(key: str, options, exported, jitted, args, lapack: bool = True):
    """The compiled program of ``jitted`` (the exported program of entry ``key``, with
    XLA's ``options``) for ``args``: read from its ``.xla`` entry, else compiled (JAX's
    compilation cache serves it where an earlier process compiled it) and kept there.

    Reading the compiled program back skips what a new process otherwise does before JAX's
    cache can even look it up: converting the exported program to MLIR and hashing it
    (measured with ``JAX_LOG_COMPILES``: 0.21 s of tracing and 0.70 s of MLIR for the 46
    programs of the Martens map's diagnosis, beside 1.18 s of loading them;
    benchmarks/README.md, "Compiled programs read back"). The entry is keyed also by what
    the machine code depends on (:func:`_machine`): XLA's flags, the backend and its
    devices, the processor's features. ``lapack``: the program calls LAPACK (its kernels
    are bound first, :func:`_lapack_ready`). Whatever fails here falls back to ``jitted``, and
    ``PAMID_COMPILED_CACHE=off`` turns this layer off (each program is then lowered and
    looked up in JAX's cache, as before; ``benchmarks/compiled_programs.py`` compares)."""
    from jax.experimental import serialize_executable

    if _compiled_off():  # also where a device is chosen: _Program
        return jitted
    program = _read_compiled(key, options, exported, jitted, lapack)
    if program is not None:
        return program
    try:
        compiled, fresh = _compile_here(exported, jitted, options, args)
        if not fresh:  # read from JAX's cache, as it will be again
            return _Program(compiled, jitted)
        payload, _, _ = serialize_executable.serialize(compiled)
    except Exception:  # noqa: BLE001 - cannot be compiled ahead or kept: jit as usual
        return jitted
    # compressed (zlib's fastest level): a fifth of the size, 1 ms a program to read back
    _remember(_DIR / f"{key}-{_machine(options)}.xla", zlib.compress(payload, 1))
    return _Program(compiled, jitted)


def _read_compiled(key: str, options, exported, jitted, lapack: bool):
    """The :class:`_Program` of entry ``key`` read back from its ``.xla`` entry for XLA's
    ``options``, or None where there is none that can be read here."""
    from jax.experimental import serialize_executable

    exe = _DIR / f"{key}-{_machine(options)}.xla"
    if exe.exists() and (not lapack or _lapack_ready()):
        try:
            compiled = serialize_executable.deserialize_and_load(
                zlib.decompress(exe.read_bytes()), exported.in_tree, exported.out_tree)
            return _Program(compiled, jitted)
        except Exception:  # noqa: BLE001 - a damaged or foreign entry is compiled again
            pass
    return None


def _switched_off(variable: str) -> bool:
    """Whether the environment variable ``variable`` turns a layer off ("off", "0", "no")."""
    import os

    return os.environ.get(variable, "on").strip().lower() in ("off", "0", "no")


def _compiled_off() -> bool:
    """``PAMID_COMPILED_CACHE=off``, or a device chosen (:class:`_Program`)."""
    import jax

    return _switched_off("PAMID_COMPILED_CACHE") or jax.config.jax_default_device is not None


def expect(command: str, rows_per_muscle, *options) -> None:
    """Say what this process runs, once its data are read: ``command`` (with the
    ``options`` that change its programs: the model, the folds) on muscles of
    ``rows_per_muscle`` rows. The programs the last run of the same kind called (its
    manifest, :func:`keep_manifest`) are then read back from their ``.xla`` entries on
    threads of their own, in the order that run called them, while this one computes: reading
    a compiled program back is XLA's work, outside Python's lock, and was the largest part
    of a warm diagnosis of a small file (34 programs, 0.76 s of the Martens map's 2.4 s).
    A program the command calls first is read by the command itself; one it never calls
    costs the other core only. Nothing is traced, exported or compiled there.
    ``PAMID_PREFETCH=off`` turns this off (``benchmarks/compiled_programs.py --layer
    prefetch`` compares)."""
    counts = np.asarray(rows_per_muscle, dtype=np.int64)
    if _PREFETCH or counts.size == 0:
        return
    with _LOCK:
        _USED.clear()  # the manifest: what this run calls from here on
    stop = threading.Event()
    # The thread also names the kind of run: that needs pamid's version (a hash of its
    # source) and, for `pamid fit`, the disk caches, which its start-up thread turns on
    # while the file is read.
    thread = threading.Thread(target=_prefetch_kind, args=(command, counts, options, stop),
                              name="pamid-prefetch")
    _PREFETCH.update(thread=thread, stop=stop)
    thread.start()


def _prefetch_kind(command, counts, options, stop) -> None:
    """:func:`expect`'s thread: the kind of run (its manifest's name), then its programs
    read back (:func:`_prefetch`), by :data:`PREFETCH_THREADS` threads. (At a lower
    priority, ``nice`` 10 or 19, the AARL muscle's diagnosis was no faster: its refits keep
    both cores busy either way.)"""
    from ._sizes import padded_rows

    if _STARTING is not None:  # `pamid fit` turns the disk caches on while it reads
        _STARTING.caches.wait(timeout=300)
    if _DIR is None:
        return
    text = repr((command, int(counts.size), padded_rows(int(counts.max()), int(counts.size)),
                 options, _code_version()))  # (another version of pamid: other programs)
    _PREFETCH["tag"] = tag = hashlib.sha256(text.encode()).hexdigest()[:20]
    if _compiled_off() or _switched_off("PAMID_PREFETCH"):
        return
    try:
        keys = (_DIR / "manifests" / f"{tag}.txt").read_text().split()
    except OSError:
        return
    others = [threading.Thread(target=_prefetch, args=(keys[i::PREFETCH_THREADS], stop),
                               name="pamid-prefetch") for i in range(1, PREFETCH_THREADS)]
    for thread in others:
        thread.start()
    _prefetch(keys[::PREFETCH_THREADS], stop)
    for thread in others:
        thread.join()


#: Threads that read a manifest's programs back, each every other one in order: reading a
#: program is XLA's work outside Python's lock, and the command waits for the program it
#: calls next where the reading has not got there yet. With one thread the Martens map's
#: diagnosis waited 0.32–0.56 s for them, with two 0.21–0.32 s (2-core VM, 2026-12-02;
#: benchmarks/README.md, "Programs read ahead").
PREFETCH_THREADS = 2


def _prefetch(keys, stop) -> None:
    """Read the programs of ``keys`` back, each unless called or read already, until
    ``stop``."""
    for key in keys:
        if stop.is_set():
            return
        with _LOCK:
            if key in _LOADED or key in _PENDING:
                continue
            reading = _PENDING[key] = threading.Event()
        program = None
        try:
            program = _prefetched(key)
        except Exception:  # noqa: BLE001 - a prefetch only: the caller reads it itself
            pass
        finally:
            with _LOCK:
                if program is not None:
                    _LOADED.setdefault(key, program)
                del _PENDING[key]
            reading.set()


def _prefetched(key: str):
    """Entry ``key``'s compiled program, where its ``.xla`` entry is there to be read (for
    either of :func:`compiler_options`' values), else None."""
    import jax

    exported, data = _read_exported(key)
    if exported is None:
        return None
    for options in (SMALL_PROGRAM_OPTIONS, None):
        if (_DIR / f"{key}-{_machine(options)}.xla").exists():
            jitted = jax.jit(exported.call, compiler_options=options)
            return _read_compiled(key, options, exported, jitted, b"lapack_" in data)
    return None


def keep_manifest(keep: bool = True) -> None:
    """End what :func:`expect` started: stop the prefetch thread (after the program it is
    reading), and where ``keep`` (the command ran to its end), keep the keys of the compiled
    programs this process called, in order, as the manifest of its kind of run (rewritten
    only where they changed)."""
    thread, stop = _PREFETCH.get("thread"), _PREFETCH.get("stop")
    if stop is not None:
        stop.set()
        thread.join()
    tag = _PREFETCH.get("tag")
    _PREFETCH.clear()
    if not keep or tag is None or _DIR is None:
        return
    with _LOCK:
        keys = [k for k in _USED if isinstance(_LOADED.get(k), _Program)]
    text = "\n".join(keys) + "\n"
    path = _DIR / "manifests" / f"{tag}.txt"
    try:
        if not keys or (path.exists() and path.read_text() == text):
            return
        path.parent.mkdir(exist_ok=True)
    except OSError:
        return
    _remember(path, text.encode())


def _compile_here(exported, jitted, options, args):
    """``(compiled, fresh)``: ``jitted`` (``exported``'s program with XLA's ``options``)
    compiled for ``args``, and whether it was compiled here (keepable) rather than read
    from JAX's cache (:func:`_cache_hits`: kept, it would lack its kernels). One read there
    is compiled once more, past that cache (:func:`_another_key`), except inside
    :func:`cached_only`, which compiles nothing."""
    import jax

    again = lambda: jax.jit(exported.call,  # noqa: E731
                            compiler_options={**(options or {}), **_another_key()})
    for program in (jitted, None):
        with _cache_hits() as hits:
            compiled = (program or again()).lower(*args).compile()
        if not hits:
            return compiled, True
        if only_cached():
            break
    return compiled, False


@functools.cache
def _lapack_ready() -> bool:
    """Whether jaxlib's LAPACK kernels are bound (to SciPy's LAPACK), as a program that
    calls them needs before it runs. Lowering a program binds them; a program read back
    compiled is not lowered, and one that called an unbound kernel ended the process
    (a segmentation fault in a diagnosis's refit: its linear solves are LAPACK calls). Where
    they cannot be bound, no ``.xla`` entry is read."""
    try:
        import numpy as np
        from jaxlib import lapack

        lapack.prepare_lapack_call("getrf_ffi", np.float64)  # binds them all, once
    except Exception:  # noqa: BLE001 - another jaxlib: the programs are lowered as before
        return False
    return True


def _another_key() -> dict:
    """An XLA option that changes nothing in the program (how many buffers a debugging
    text of its buffer assignment lists; JAX's cache key leaves out the options of dumps),
    at a value of its own: the same program under a key of JAX's cache that no compile has
    had, so that it is compiled here whatever that cache holds. A fixed value did not do:
    after a second change to pamid (new entries here, the same programs in JAX's cache) a
    process read both forms of each program from JAX's cache, kept no ``.xla`` entry, and
    every later run lowered its programs again (none of the Martens map's diagnosis's 34
    programs had one)."""
    import os

    return {"xla_debug_buffer_assignment_show_max": int.from_bytes(os.urandom(4), "big") >> 1}

_HITS = threading.local()  # .events: a list while inside _cache_hits(), on this thread


def _on_event(event: str, **_) -> None:
    events = getattr(_HITS, "events", None)
    if events is not None and event == "/jax/compilation_cache/cache_hits":
        events.append(event)


@contextlib.contextmanager
def _cache_hits():
    """A list of the hits of JAX's persistent compilation cache on this thread within the
    block. A program that JAX read from its cache cannot be kept as an ``.xla`` entry: XLA's
    CPU client serializes such an executable without its kernels, and the program read back
    from it failed ("NOT_FOUND: Function bitcast_concatenate_fusion.8 not found"). Only a
    program compiled here is kept; one read from JAX's cache is read from there again."""
    _listen()
    _HITS.events = []
    try:
        yield _HITS.events
    finally:
        _HITS.events = None


@functools.cache
def _listen() -> None:
    import jax.monitoring

    jax.monitoring.register_event_listener(_on_event)


@functools.cache
def _machine_base() -> str:
    import os

    import jax

    backend = jax.devices()[0].client
    # The devices this process runs on, by their ids in the job: a compiled program is
    # bound to its device, and in a job of several processes (`pamid fit --stream
    # --processes 2`) each has its own. Keyed by the device kinds alone, process 1 read the
    # program process 0 had kept, for process 0's device, and hung running it (the second
    # run of such a job on one cache, every time; the test suite's shared cache, 2026-12-02).
    parts = [os.environ.get("XLA_FLAGS", ""), backend.platform, backend.platform_version,
             repr([d.device_kind for d in backend.devices()]),
             f"process {jax.process_index()} of {jax.process_count()}",
             repr([d.id for d in jax.local_devices()])]
    try:  # the features the CPU code was compiled for (Linux; elsewhere the model name)
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            parts += sorted({line for line in fh if line.startswith(("flags", "model name"))})
    except OSError:
        import platform

        parts.append(platform.processor())
    return "\x1f".join(parts)


def _machine(options) -> str:
    """A short hash of what a compiled program's machine code depends on beyond its
    entry's key: XLA's flags and ``options``, the backend and devices, the processor."""
    text = _machine_base() + "\x1f" + repr(sorted((options or {}).items()))
    return hashlib.sha256(text.encode()).hexdigest()[:16]


#: XLA's options for a small program: one of at most :data:`SMALL_CALL_LANES` lanes whose
#: largest argument holds at most :data:`pamid._lanes._sizes.SMALL_BATCH_SAMPLES` numbers
#: (a lab's file of one or a few muscles): LLVM's optimisation off. Compiling is nearly all
#: of such a program's time, and optimising its machine code was a quarter of it: the
#: one-muscle fit's two programs compiled in 1.14 and 0.95 s against 1.48 and 1.39 s
#: (benchmarks/README.md, "LLVM's optimisation off for small programs"). A larger call's
#: arithmetic counts, and its programs are optimised as usual: unoptimised, a diagnosis's
#: refits ran twice as long, and the profile intervals of a 10,000-muscle fit (calls of 42
#: muscles of 312 rows, 13,104 numbers) made the fit 3.8–4.0 s instead of 3.0 s.
SMALL_PROGRAM_OPTIONS = {"xla_backend_optimization_level": 0}
SMALL_CALL_LANES = 8


def compiler_options(args) -> dict | None:
    """:data:`SMALL_PROGRAM_OPTIONS` for a call whose arrays ``args`` (pytrees, lanes on
    the leading axis) are all small, else None (XLA's defaults)."""
    import jax

    from ._sizes import SMALL_BATCH_SAMPLES

    shapes = [np.shape(a) for a in jax.tree.leaves(args)]
    small = all(int(np.prod(s)) <= SMALL_BATCH_SAMPLES and (not s or s[0] <= SMALL_CALL_LANES)
                for s in shapes)
    return SMALL_PROGRAM_OPTIONS if small else None


def _remember(path: Path, data: bytes) -> None:
    """Write an entry; a cache that cannot be written (full, read-only) only costs the next
    process its tracing."""
    try:
        write_bytes_atomic(path, data)
    except OSError:
        pass


def _export(jitted, args):
    """Export; calls into LAPACK that JAX does not promise to keep stable across versions
    are allowed (the entry is only ever read by this JAX and jaxlib version)."""
    from jax import export

    checks = []
    for _ in range(8):
        try:
            return export.export(jitted, disabled_checks=checks)(*args)
        except ValueError as err:
            targets = set(re.findall(r"custom_call @(\w+)", str(err)))
            if "custom calls whose targets" not in str(err) or not targets:
                raise
            checks += [export.DisabledSafetyCheck.custom_call(t) for t in sorted(targets)]
    raise RuntimeError("could not export: too many custom-call targets")
