"""The on-disk cache of exported programs (``pamid/_lanes/_export_cache.py``) that lets the
command line skip tracing: same answers as tracing, entries per input shape, a clean
fallback for what cannot be exported."""

from __future__ import annotations

import contextlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamid
from pamid._lanes import _export_cache


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    before = _export_cache.directory()  # the run's own (conftest), put back after
    _export_cache.enable(tmp_path / "exported")
    yield tmp_path / "exported"
    _export_cache.enable(before)


def entries(directory, suffix=".jaxexport"):
    return sorted(p.name for p in directory.iterdir() if p.name.endswith(suffix))


def test_when_off_the_function_runs_as_it_is(monkeypatch):
    monkeypatch.setattr(_export_cache, "_DIR", None)
    assert _export_cache.directory() is None
    assert _export_cache.call(("f",), lambda a: a + 1, 1.0) == 2.0


def test_an_entry_per_shape_read_back_by_a_new_process(cache_dir, monkeypatch):
    traced = []

    def fn(a, b):
        traced.append(a.shape)
        return jnp.sin(a) * b.sum(), (jnp.cumsum(a), b.T)

    a, b = np.linspace(0, 1, 5), np.arange(6.0).reshape(2, 3)
    first = _export_cache.call(("fn", 1), fn, a, b)
    assert len(entries(cache_dir)) == 1 and traced == [(5,)]
    again = _export_cache.call(("fn", 1), fn, a, b)  # same process: the loaded program
    assert traced == [(5,)]
    monkeypatch.setattr(_export_cache, "_LOADED", {})  # as a new process: read from disk
    loaded = _export_cache.call(("fn", 1), fn, a, b)
    assert traced == [(5,)]
    want = (np.sin(a) * b.sum(), (np.cumsum(a), b.T))
    for got in (first, again, loaded):
        for g, w in zip(jax.tree.leaves(got), jax.tree.leaves(want)):
            np.testing.assert_allclose(g, w, rtol=1e-15)
    _export_cache.call(("fn", 1), fn, np.linspace(0, 1, 7), b)  # a new shape: a new entry
    _export_cache.call(("fn", 2), fn, a, b)  # another static argument: a new entry
    assert len(entries(cache_dir)) == 3


def test_small_programs_compile_unoptimised_and_large_ones_as_usual(cache_dir, monkeypatch):
    """A call of a one-muscle file's shapes (1 × 1024 samples: compiling is nearly all of
    its time) is compiled with LLVM's optimisation off, one of 512 muscles of 312 rows, or
    of 42 (its arithmetic counts), with XLA's defaults, read back from disk alike; both give
    the function's numbers."""
    from pamid._lanes._batch import SMALL_BATCH_SAMPLES

    assert _export_cache.compiler_options((np.zeros((1, 1024)), np.zeros(6))) == \
        _export_cache.SMALL_PROGRAM_OPTIONS
    assert _export_cache.compiler_options((np.zeros((1, SMALL_BATCH_SAMPLES + 1)),)) is None
    assert _export_cache.compiler_options(((np.zeros((512, 312)),), np.zeros(512))) is None
    # a 10,000-muscle fit's profile intervals: 42 muscles of 312 rows a call, heavy work
    assert _export_cache.compiler_options((np.zeros((42, 312)), np.zeros((42, 6)))) is None
    made = []
    jit = jax.jit

    def spy(fun, **options):
        if "compiler_options" in options:  # the program that runs (not the one exported)
            made.append(options["compiler_options"])
        return jit(fun, **options)

    monkeypatch.setattr(jax, "jit", spy)

    def fn(x, theta):
        return jnp.exp(theta[0] * x) @ jnp.cos(x).T + theta.sum()

    theta = np.array([-0.3, 2.0])
    for lanes, rows in ((1, 1024), (512, 312)):
        x = np.linspace(0.0, 1.0, lanes * rows).reshape(lanes, rows)
        want = np.exp(-0.3 * x) @ np.cos(x).T + 1.7
        for _ in range(2):  # exported, then (as a new process) read from disk
            monkeypatch.setattr(_export_cache, "_LOADED", {})
            got = _export_cache.call(("fn", lanes), fn, x, theta)
            np.testing.assert_allclose(got, want, rtol=1e-12)
    assert made == [_export_cache.SMALL_PROGRAM_OPTIONS] * 2 + [None] * 2


def test_what_cannot_be_exported_runs_as_it_is_and_is_remembered(cache_dir):
    def with_callback(a):
        return jax.pure_callback(lambda v: np.asarray(v) * 2, jax.ShapeDtypeStruct(a.shape,
                                                                                   a.dtype), a)

    a = np.arange(3.0)
    np.testing.assert_array_equal(_export_cache.call(("cb",), with_callback, a), a * 2)
    assert entries(cache_dir) == [] and len(entries(cache_dir, ".failed")) == 1
    np.testing.assert_array_equal(_export_cache.call(("cb",), with_callback, a), a * 2)


def test_a_damaged_entry_is_exported_again(cache_dir, monkeypatch):
    fn = lambda a: a * 3.0  # noqa: E731
    a = np.arange(4.0)
    _export_cache.call(("triple",), fn, a)
    (name,) = entries(cache_dir)
    (cache_dir / name).write_bytes(b"not a program")
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    np.testing.assert_array_equal(_export_cache.call(("triple",), fn, a), a * 3.0)
    assert (cache_dir / name).stat().st_size > 100


def test_fits_through_the_cache_equal_traced_fits(small_bench, cache_dir, monkeypatch):
    """Solve, statistics and profile intervals, exported then read back: the same answers
    as the traced functions, to the last bits that LLVM's optimisation moves (the same
    programs; these small ones, three muscles, are compiled without it on the command
    line's path: ``SMALL_PROGRAM_OPTIONS``)."""
    _export_cache.enable(None)
    traced = pamid.fit_least_squares(small_bench.data, intervals=("wald", "profile"))
    _export_cache.enable(cache_dir)
    exported = pamid.fit_least_squares(small_bench.data, intervals=("wald", "profile"))
    # the solve with its statistics (and the lag-1 sums of the residual) in one, profile
    assert len(entries(cache_dir)) == 2
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    loaded = pamid.fit_least_squares(small_bench.data, intervals=("wald", "profile"))
    for fit in (exported, loaded):
        np.testing.assert_allclose(fit.theta, traced.theta, rtol=1e-12)
        np.testing.assert_allclose(fit.ci95, traced.ci95, rtol=1e-12)
        np.testing.assert_allclose(fit.ci95_profile, traced.ci95_profile, rtol=1e-9)
        np.testing.assert_array_equal(fit.converged, traced.converged)
    np.testing.assert_array_equal(loaded.theta, exported.theta)  # one program, one answer
    np.testing.assert_array_equal(loaded.ci95_profile, exported.ci95_profile)


@pytest.mark.parametrize("chunk", [None, 2], ids=["one call", "calls of 2 muscles"])
def test_the_fit_s_programs_are_loaded_before_its_data_are_packed(small_bench, cache_dir,
                                                                   monkeypatch, chunk):
    """``prepare_fit`` with the rows that ``load_bench`` reports loads the very programs
    the fit then runs (the fit loads none after it), whether the fit's muscles go in one
    call or (a file of more muscles than a call takes) in several; and it compiles nothing:
    with nothing on disk it stops and writes no entry."""
    from pamid._fit._api import prepare_fit
    from pamid._fit._spec import SAROSI
    from pamid._lanes import _batch

    if chunk is not None:
        monkeypatch.setattr(_batch, "CPU_CHUNK_LANES", chunk)
    seen = []
    bench = pamid.load_bench(small_bench.bench.path, on_rows=seen.append)
    assert [r.tolist() for r in seen] == [
        small_bench.frame.groupby("muscle", sort=False).size().tolist()]
    intervals = ("wald", "profile")
    assert not prepare_fit(SAROSI, seen[0], intervals=intervals)
    assert entries(cache_dir) == [] and _export_cache._LOADED == {}
    pamid.fit_least_squares(bench, intervals=intervals)  # the programs, kept on disk
    assert len(entries(cache_dir)) == 2  # the solve with its statistics, the profile
    monkeypatch.setattr(_export_cache, "_LOADED", {})  # as in a new process
    assert prepare_fit(SAROSI, seen[0], intervals=intervals)
    loaded = dict(_export_cache._LOADED)
    assert len(loaded) == 2 and all(p is not None for p in loaded.values())
    fit = pamid.fit_least_squares(bench, intervals=intervals)
    assert _export_cache._LOADED == loaded and fit.converged.all()


def test_cached_only_runs_what_is_on_disk_and_compiles_nothing(cache_dir, monkeypatch):
    from pamid._lanes._batch import map_lanes

    fn = lambda a: a * 5.0  # noqa: E731
    a = np.arange(4.0)
    with _export_cache.cached_only():
        with pytest.raises(_export_cache.NotCached):
            _export_cache.call(("five",), fn, a)
        with pytest.raises(_export_cache.NotCached):  # no key: it would be compiled
            map_lanes(fn, a)
    assert entries(cache_dir) == []
    _export_cache.call(("five",), fn, a)  # kept on disk now
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    with _export_cache.cached_only():
        np.testing.assert_array_equal(_export_cache.call(("five",), fn, a), a * 5.0)
    assert not _export_cache.only_cached()
    np.testing.assert_array_equal(map_lanes(fn, a), a * 5.0)  # outside: as before


def test_python_scalars_among_the_inputs(cache_dir):
    scale = lambda a, c: a * c  # noqa: E731
    a = np.arange(3.0)
    np.testing.assert_array_equal(_export_cache.call(("scale",), scale, a, 2.0), a * 2.0)
    np.testing.assert_array_equal(_export_cache.call(("scale",), scale, a, 3.0), a * 3.0)
    assert len(entries(cache_dir)) == 1


def test_a_cache_that_cannot_be_written_costs_only_the_saving(tmp_path, monkeypatch):
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    before = _export_cache.directory()
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    _export_cache.enable(blocker / "exported")  # under a file: cannot be created
    assert _export_cache.directory() is None
    _export_cache.enable(tmp_path / "full")

    def disk_full(path, data):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(_export_cache, "write_bytes_atomic", disk_full)
    try:
        a = np.arange(3.0)
        np.testing.assert_array_equal(_export_cache.call(("full",), lambda v: v + 1, a), a + 1)
        assert list((tmp_path / "full").iterdir()) == []
    finally:
        _export_cache.enable(before)


def test_use_disk_caches_switches_both_on_and_gives_the_settings_back(tmp_path, monkeypatch):
    # pamid.engine.use_disk_caches: the command's caches for a script (PAMID_CACHE_DIR by
    # default); what it returns puts the caller's settings back, both caches.
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    before, exported = jax.config.jax_compilation_cache_dir, _export_cache.directory()
    monkeypatch.setenv("PAMID_CACHE_DIR", str(tmp_path / "env"))
    restore = pamid.engine.use_disk_caches()
    try:
        assert jax.config.jax_compilation_cache_dir == str(tmp_path / "env")
        assert _export_cache.directory() == tmp_path / "env" / "exported"
        a = np.arange(3.0)
        np.testing.assert_array_equal(_export_cache.call(("add",), lambda v: v + 1, a), a + 1)
        assert entries(tmp_path / "env" / "exported")
    finally:
        restore()
    assert jax.config.jax_compilation_cache_dir == before
    assert _export_cache.directory() == exported
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    with pytest.warns(UserWarning, match="cache .* cannot be written"):  # said once
        pamid.engine.use_disk_caches(blocker / "cache")()  # cannot be created: nothing changes
    assert jax.config.jax_compilation_cache_dir == before
    assert _export_cache.directory() == exported


def test_a_compiled_program_is_kept_and_read_back_without_lowering(cache_dir, monkeypatch):
    """Beside the exported program, the compiled one is kept (``.xla``, keyed also by the
    machine and XLA's options); a new process reads it back and runs it without lowering
    the exported program again, with the same numbers. A damaged entry is compiled again."""
    fn = lambda a, b: (jnp.sin(a) @ b, a.sum())  # noqa: E731
    a, b = np.linspace(0, 1, 12).reshape(3, 4), np.arange(8.0).reshape(4, 2)
    want = _export_cache.call(("sinmat",), fn, a, b)
    (exe,) = entries(cache_dir, ".xla")
    assert exe.startswith(entries(cache_dir)[0].removesuffix(".jaxexport"))
    monkeypatch.setattr(_export_cache, "_LOADED", {})  # as a new process
    lowered = []  # JAX's own record of each lowering to MLIR

    def on_duration(event, duration, **_):
        if "jaxpr_to_mlir_module" in event:
            lowered.append(event)

    jax.monitoring.register_event_duration_secs_listener(on_duration)
    try:
        got = _export_cache.call(("sinmat",), fn, a, b)
        assert lowered == []
        _export_cache.call(("sinmat",), fn, a[:2], b)  # a new shape: exported, lowered
        assert lowered
    finally:
        jax.monitoring.unregister_event_duration_listener(on_duration)
    program = _export_cache._LOADED[_export_cache._key(("sinmat",), (a, b))]
    assert isinstance(program, _export_cache._Program)
    for g, w in zip(jax.tree.leaves(got), jax.tree.leaves(want)):
        np.testing.assert_array_equal(g, w)
    # other argument types than it was compiled for: what the exported program says
    with pytest.raises(ValueError, match="Dtype mismatch"):
        program(a.astype(np.float32), b)
    (cache_dir / exe).write_bytes(b"not a program")
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    np.testing.assert_array_equal(_export_cache.call(("sinmat",), fn, a, b)[1], want[1])
    assert (cache_dir / exe).stat().st_size > 1000  # compiled and kept again


def test_a_program_read_from_jax_s_cache_is_compiled_again_to_be_kept(cache_dir, monkeypatch,
                                                                      tmp_path):
    """A program JAX read from its own compilation cache is not kept as it is (XLA's CPU
    client serializes it without its kernels): it is compiled once more under another key,
    and that is kept and read back; inside ``cached_only`` nothing is compiled for it."""
    fn = lambda a: jnp.cumsum(jnp.exp(a)) * 2.0  # noqa: E731
    a = np.linspace(0, 1, 9)
    program = jax.jit(fn)
    hits = []
    with _export_cache._cache_hits() as seen:
        _export_cache._on_event("/jax/compilation_cache/cache_hits")
        hits += seen
    assert hits == ["/jax/compilation_cache/cache_hits"]
    # pretend the first compile was a hit of JAX's cache
    calls = []
    real = _export_cache._cache_hits

    @contextlib.contextmanager
    def first_is_a_hit():
        with real() as events:
            if not calls:
                events.append("/jax/compilation_cache/cache_hits")
            calls.append(1)
            yield events

    monkeypatch.setattr(_export_cache, "_cache_hits", first_is_a_hit)
    with _export_cache.cached_only():
        exported = jax.export.export(program)(a)
        _export_cache._remember(cache_dir / "x.jaxexport", exported.serialize())
        kept = _export_cache._executable("k", None, exported, jax.jit(exported.call), (a,))
    assert isinstance(kept, _export_cache._Program) and entries(cache_dir, ".xla") == []
    calls.clear()
    kept = _export_cache._executable("k", None, exported, jax.jit(exported.call), (a,))
    assert len(calls) == 2 and len(entries(cache_dir, ".xla")) == 1  # compiled again, kept
    np.testing.assert_allclose(kept(a), np.cumsum(np.exp(a)) * 2.0, rtol=1e-15)


def test_a_program_that_calls_lapack_runs_when_read_back_in_a_new_process(tmp_path):
    """A linear solve is a call into LAPACK, whose kernels a process binds when it lowers a
    program that uses them; a new process reading the compiled program back lowers nothing
    and must bind them first (unbound, the call ended the process: a segmentation fault)."""
    import subprocess
    import sys

    script = (
        "import sys, numpy as np, jax, jax.numpy as jnp\n"
        "jax.config.update('jax_enable_x64', True)\n"
        "from pamid._lanes import _export_cache as ec\n"
        "ec.enable(sys.argv[1])\n"
        "a = np.array([[4.0, 1.0], [1.0, 3.0]]); b = np.array([1.0, 2.0])\n"
        "x = ec.call(('solve',), jnp.linalg.solve, a, b)\n"
        "print(type(ec._LOADED[ec._key(('solve',), (a, b))]).__name__, "
        "float(np.abs(a @ np.asarray(x) - b).max()))\n")
    runs = [subprocess.run([sys.executable, "-c", script, str(tmp_path / "exported")],
                           capture_output=True, text=True, timeout=120) for _ in range(2)]
    for run in runs:
        assert run.returncode == 0, run.stderr[-2000:]
        kind, error = run.stdout.split()
        assert kind == "_Program" and float(error) < 1e-12
    assert len(entries(tmp_path / "exported", ".xla")) == 1


def test_programs_jax_s_cache_holds_from_before_an_upgrade_are_still_kept(tmp_path):
    """After a change to pamid every entry is new while JAX's cache holds the same programs
    from the runs before it, once as compiled plainly and once more to be kept. The third
    such entry of one program (as after a second upgrade) is still compiled here and kept:
    with a fixed second key both forms came from JAX's cache, and no ``.xla`` entry was
    ever kept again (every later run lowered its programs)."""
    import subprocess
    import sys

    script = (
        "import sys, numpy as np, jax, jax.numpy as jnp\n"
        "jax.config.update('jax_enable_x64', True)\n"
        "jax.config.update('jax_compilation_cache_dir', sys.argv[1] + '/jax')\n"
        "jax.config.update('jax_persistent_cache_min_compile_time_secs', 0.0)\n"
        "jax.config.update('jax_persistent_cache_min_entry_size_bytes', 0)\n"
        "from pamid._lanes import _export_cache as ec\n"
        "ec.enable(sys.argv[1] + '/exported')\n"
        "a = np.linspace(0.0, 1.0, 7)\n"
        "exported = jax.export.export(jax.jit(lambda a: jnp.cumsum(jnp.sin(a)) * 3.0))(a)\n"
        "kinds = [type(ec._executable(k, None, exported, jax.jit(exported.call), (a,)))"
        ".__name__ for k in ('v1', 'v2', 'v3')]\n"
        "print(*kinds)\n")
    run = subprocess.run([sys.executable, "-c", script, str(tmp_path)], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == ["_Program"] * 3
    kept = sorted(p.name.split("-")[0] for p in (tmp_path / "exported").glob("*.xla"))
    assert kept == ["v1", "v2", "v3"]


def test_a_call_on_a_chosen_device_runs_where_it_is_called(cache_dir, monkeypatch):
    """A program read back compiled runs on the device it was compiled for; a call made
    where a device is chosen (``jax.default_device``: map_lanes runs so on the device that
    ``use_devices`` picked) goes to the jitted program instead, which runs there."""
    fn = lambda a: a * 7.0  # noqa: E731
    a = np.arange(3.0)
    _export_cache.call(("seven",), fn, a)
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    _export_cache.call(("seven",), fn, a)  # read back compiled
    program = _export_cache._LOADED[_export_cache._key(("seven",), (a,))]
    assert isinstance(program, _export_cache._Program)
    ran = []
    jitted = program.fallback
    monkeypatch.setattr(program, "fallback", lambda *args: ran.append(1) or jitted(*args))
    device = jax.devices()[-1]
    with jax.default_device(device):
        out = _export_cache.call(("seven",), fn, a)
    assert ran == [1] and out.devices() == {device}
    np.testing.assert_array_equal(out, a * 7.0)
    np.testing.assert_array_equal(_export_cache.call(("seven",), fn, a), a * 7.0)
    assert ran == [1]  # no device chosen: the compiled program
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    with jax.default_device(device):  # first loaded where a device is chosen: not compiled
        _export_cache.call(("seven",), fn, a)
    assert not isinstance(_export_cache._LOADED[_export_cache._key(("seven",), (a,))],
                          _export_cache._Program)


def test_a_compiled_program_is_keyed_by_what_its_machine_code_depends_on(monkeypatch):
    """XLA's options and flags and the processor name a compiled entry beside its exported
    program's key: a cache folder shared by another machine or flags is not read."""
    base = _export_cache._machine(None)
    assert base == _export_cache._machine({})
    assert base != _export_cache._machine(_export_cache.SMALL_PROGRAM_OPTIONS)
    monkeypatch.setenv("XLA_FLAGS", "--xla_force_host_platform_device_count=2")
    _export_cache._machine_base.cache_clear()
    try:
        assert _export_cache._machine(None) != base
    finally:
        monkeypatch.undo()
        _export_cache._machine_base.cache_clear()
    assert _export_cache._machine(None) == base


def test_the_programs_of_the_last_run_of_its_kind_are_read_back_ahead(cache_dir, monkeypatch):
    """A command says what it runs once its rows are known (``expect``); at its end the
    compiled programs it called are kept, in order, as the manifest of its kind. The next
    run of that kind reads them back on a thread of its own before it calls them; a call
    of a program being read waits for it; another kind of run reads nothing."""
    import threading

    monkeypatch.setattr(_export_cache, "_USED", {})
    monkeypatch.setattr(_export_cache, "_PENDING", {})
    monkeypatch.setattr(_export_cache, "_PREFETCH", {})
    fns = {"double": lambda a: a * 2.0, "cumsum": lambda a: jnp.cumsum(a) + 1.0}
    a = np.linspace(0.0, 1.0, 6)
    _export_cache.expect("diagnose", [300], "sarosi")
    for name in ("cumsum", "double"):
        _export_cache.call((name,), fns[name], a)
    _export_cache.keep_manifest()
    (manifest,) = (cache_dir / "manifests").iterdir()
    keys = [_export_cache._key((name,), (a,)) for name in ("cumsum", "double")]
    assert manifest.read_text().split() == keys

    # a new process of the same kind (290 rows: the same class of rows)
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    gate, read = threading.Event(), []
    real = _export_cache._prefetched

    def slow(key):  # the first program is read only once a call waits for it
        if not read:
            gate.wait(timeout=30)
        read.append(key)
        return real(key)

    monkeypatch.setattr(_export_cache, "_prefetched", slow)
    monkeypatch.setattr(_export_cache, "PREFETCH_THREADS", 1)  # one, to follow its order
    _export_cache.expect("diagnose", [290], "sarosi")
    thread = _export_cache._PREFETCH["thread"]
    for _ in range(1000):  # until the thread has taken the first key
        if _export_cache._PENDING:
            break
        threading.Event().wait(0.005)
    assert list(_export_cache._PENDING) == [keys[0]]
    threading.Timer(0.2, gate.set).start()
    traced = []
    out = _export_cache.call(("cumsum",), lambda x: traced.append(1) or fns["cumsum"](x), a)
    np.testing.assert_allclose(out, np.cumsum(a) + 1.0, rtol=1e-15)
    thread.join(timeout=30)
    assert read == keys and traced == []  # read ahead, neither traced nor read twice
    assert all(isinstance(_export_cache._LOADED[k], _export_cache._Program) for k in keys)
    _export_cache.keep_manifest()
    assert manifest.read_text().split() == keys[:1]  # what this run called

    # two threads, each reading every other program of the manifest
    manifest.write_text("\n".join(keys) + "\n")
    monkeypatch.setattr(_export_cache, "PREFETCH_THREADS", 2)
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    read.clear()
    read.append("the gate is open")
    _export_cache.expect("diagnose", [290], "sarosi")
    _export_cache._PREFETCH["thread"].join(timeout=30)
    assert sorted(read[1:]) == sorted(keys) and not _export_cache._PENDING
    assert all(isinstance(_export_cache._LOADED[k], _export_cache._Program) for k in keys)
    _export_cache.keep_manifest(keep=False)

    # another kind of run (four times the rows): nothing is read ahead
    monkeypatch.setattr(_export_cache, "_LOADED", {})
    _export_cache.expect("diagnose", [1200], "sarosi")
    _export_cache._PREFETCH["thread"].join(timeout=30)
    assert _export_cache._LOADED == {}
    _export_cache.keep_manifest(keep=False)
    assert len(list((cache_dir / "manifests").iterdir())) == 1 and _export_cache._LOADED == {}
