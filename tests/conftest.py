"""Shared fixtures: float64, the constants of Sárosi Table 3-1, and a small virtual bench.

pamid switches float64 on at import (fitting needs it); the assertion below fails the whole
run early if that ever stops being true, instead of letting tolerances fail one by one.
"""

from __future__ import annotations

import os
import subprocess
import sys
from typing import NamedTuple

# `make test` runs as many worker processes as the machine has cores (pytest-xdist). Each
# worker, and the commands and notebook kernels it starts, keeps to a core of its own:
# unpinned, each worker's lane threads and XLA's kernels also ran on the other's core, and a
# length study that takes 0.8 s alone took 25-31 s beside notebook 04. Before JAX starts.
_WORKER = os.environ.get("PYTEST_XDIST_WORKER", "")
if _WORKER.startswith("gw") and hasattr(os, "sched_setaffinity"):
    _cores = sorted(os.sched_getaffinity(0))
    if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "0")) == len(_cores) > 1:
        os.sched_setaffinity(0, {_cores[int(_WORKER[2:]) % len(_cores)]})

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402

import pamid  # noqa: E402

assert jax.config.jax_enable_x64, "pamid must switch on float64 at import"
assert jnp.asarray(1.0).dtype == jnp.float64

PARAM_NAMES = ("a1", "a2", "a3", "a4", "a5", "a6")

# Sárosi, Table 3-1 (DMSP-20-400N, l0 = 400 mm), typed in from the summary, not from pamid:
# value, lower and upper 95% limits.
TABLE_3_1_PRINTED = {
    "a1": (-4.35572689, -5.775448554, -2.936005225),
    "a2": (281.2237983, 278.065759, 284.3818376),
    "a3": (-0.32866293, -0.335236188, -0.322089671),
    "a4": (-9.27034945, -9.348917301, -9.191781595),
    "a5": (302.2010663, 300.3018044, 304.1003281),
    "a6": (-263.691854, -268.3566557, -259.0270514),
}


@pytest.fixture(scope="session")
def theta31() -> np.ndarray:
    """Table 3-1 constants as a NumPy vector (a1, …, a6)."""
    return np.array([TABLE_3_1_PRINTED[name][0] for name in PARAM_NAMES])


@pytest.fixture(scope="session")
def ci31() -> np.ndarray:
    """Table 3-1 95% intervals, shape (6, 2)."""
    return np.array([TABLE_3_1_PRINTED[name][1:] for name in PARAM_NAMES])


@pytest.fixture(scope="session")
def sarosi31(theta31) -> pamid.Sarosi:
    """Table 3-1 constants as a :class:`pamid.Sarosi`."""
    return pamid.Sarosi(*theta31)


class SmallBench(NamedTuple):
    """Three muscles on the virtual bench, Sárosi's protocol (default noise 2 N)."""

    theta: np.ndarray  # (3, 6) true constants
    frame: pd.DataFrame  # as simulate_sarosi_bench wrote it
    bench: pamid.BenchData  # the same table written to CSV and loaded back
    data: pamid.FitData  # packed for fitting, one lane per muscle
    groups: list  # per muscle: ((pressure_bar, contraction_pct), force_N), unpadded


def frame_groups(frame: pd.DataFrame) -> list:
    """Split a virtual-bench table into per-muscle ((p_bar, κ_pct), F_N) arrays."""
    return [
        (
            (g["pressure_kPa"].to_numpy() / 100.0, g["contraction_pct"].to_numpy()),
            g["force_N"].to_numpy(),
        )
        for _, g in frame.groupby("muscle", sort=True)
    ]


def _fresh_python(code: str):
    """Run ``code`` in a new interpreter (from the repository root) and return the JSON
    value of the last line it prints."""
    import json
    from pathlib import Path

    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[1])
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="session")
def fresh_python():
    """The function :func:`_fresh_python`: what a fresh process imports, for tests of the
    import cost."""
    return _fresh_python


@pytest.fixture(scope="session")
def split_frame():
    """The function :func:`frame_groups`, for tests that simulate their own bench."""
    return frame_groups


@pytest.fixture(scope="session")
def small_bench(theta31, tmp_path_factory) -> SmallBench:
    # Three muscles whose constants differ inside the Table 3-1 intervals.
    shift = np.array(
        [[0.0] * 6, [0.5, 1.0, 0.002, 0.03, -0.5, 1.0], [-0.5, -1.0, -0.002, -0.03, 0.5, -1.0]]
    )
    theta = theta31 + shift
    frame = pamid.simulate_sarosi_bench(
        jax.random.key(0), pamid.Sarosi.from_vector(theta), pamid.SarosiProtocol(min_force_N=10.0)
    )
    path = tmp_path_factory.mktemp("bench") / "small_bench.csv"
    frame.to_csv(path, index=False)
    bench = pamid.load_bench(path)
    return SmallBench(theta, frame, bench, pamid.bench_to_fit_data(bench), frame_groups(frame))


#: What the run's compilation cache keeps: programs that took at least this long to compile.
#: The many small programs of eager array operations are left out: in a census of one run
#: they were 5,237 compiles of 18 ms on average, and their repeats in other processes came
#: to 22 s of the run's test time (a threshold of 0 was not tried).
CACHE_MIN_COMPILE_S = 0.1


@pytest.fixture(scope="session", autouse=True)
def _compilation_cache_of_the_run(tmp_path_factory):
    """One compilation cache for the whole test run, empty when it starts: both workers,
    every command, script and notebook kernel they start, and the commands run in-process
    (``pamid._cli.main``) read and write it, so a program is compiled once per run, not
    once per process (two thirds of the suite's time was XLA compiling, much of it the
    same programs in several processes). Never the user's ``~/.cache/pamid``.

    JAX's cache is keyed by the compiled program itself (its HLO, the compiler options and
    versions), so a test gets what it would have compiled. pamid's own cache of traced and
    compiled programs (``exported``, in the same folder) is on wherever a command runs, in
    a subprocess or in-process (``main`` switches it on, as the command does, and back
    off when it returns); the library's calls outside a command trace and compile as a
    library user's do. A test that runs one computation both ways compiles it twice (two
    forms of each program). Two workers may write one entry at the same moment: JAX then
    reads a torn entry as a miss (a warning) and compiles."""
    from jax.experimental.compilation_cache import compilation_cache

    base = tmp_path_factory.getbasetemp()
    # Under pytest-xdist each worker has its own base folder inside the run's.
    cache = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "jax-cache"
    cache.mkdir(exist_ok=True)
    settings = {"jax_compilation_cache_dir": str(cache),
                "jax_persistent_cache_min_compile_time_secs": CACHE_MIN_COMPILE_S,
                "jax_persistent_cache_min_entry_size_bytes": 0}
    env = {"PAMID_CACHE_DIR": str(cache), **{k.upper(): str(v) for k, v in settings.items()}}
    before_env = {k: os.environ.get(k) for k in env}
    before = {k: getattr(jax.config, k) for k in settings}
    os.environ.update(env)  # the processes the tests start
    for k, v in settings.items():
        jax.config.update(k, v)
    compilation_cache.reset_cache()  # pamid's import compiled before the cache was set
    yield
    for k, v in before.items():
        jax.config.update(k, v)
    compilation_cache.reset_cache()
    for k, v in before_env.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


@pytest.fixture(scope="module", autouse=True)
def _programs_below_the_region_limit():
    """After each test file: a worker that nears the system's limit on memory regions
    (``vm.max_map_count``) drops its compiled programs, as pamid's own lanes do
    (``pamid/_lanes/_programs.py``). Each test worker compiles thousands of programs, about
    3.4 regions each; at 96 % of the suite one crossed 65,530 regions and died of a
    segmentation fault inside XLA, and the run then hung (CI, 2026-11-27)."""
    yield
    from pamid._lanes._programs import release_if_crowded

    release_if_crowded(force_look=True)


#: The installed command, as a user runs it (in a subprocess).
PAMID = [sys.executable, "-m", "pamid._cli"]


@pytest.fixture(scope="session")
def cli_env():
    """The environment of a command run in a subprocess: the run's compilation cache
    (:func:`_compilation_cache_of_the_run`), so that a program one test compiled is loaded,
    not compiled again, by the next, and the CPU."""
    return {**os.environ, "JAX_PLATFORMS": "cpu"}


@pytest.fixture(scope="module")
def pamid_cli(cli_env):
    """``pamid_cli(args)`` runs the command in a subprocess (:func:`cli_env`) and returns
    the CompletedProcess (text stdout and stderr)."""
    env = cli_env

    def run(args, timeout=900):
        return subprocess.run(PAMID + [str(a) for a in args], capture_output=True, text=True,
                              env=env, timeout=timeout)

    return run


@pytest.fixture(scope="session")
def run_notebook():
    """``run_notebook(path, folder)`` executes a notebook top to bottom in a new kernel whose
    working folder and temporary folder (``TMPDIR``: what the notebook's
    ``tempfile.mkdtemp()`` writes into) are ``folder``; a failing cell raises
    ``CellExecutionError`` naming it."""
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")

    def run(path, folder):
        nb = nbformat.read(path, as_version=4)
        client = nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                         resources={"metadata": {"path": str(folder)}})
        with pytest.MonkeyPatch.context() as env:
            env.setenv("TMPDIR", str(folder))  # the kernel inherits this process' environment
            client.execute()
        return nb

    return run


#: Test files that take longest, longest first (per-file time of a whole run, from
#: ``pytest --junitxml``). `make test` hands whole files to two workers in collection order,
#: the next file to whichever is free: a long file handed out last kept one worker busy
#: while the other had finished. Run first, they leave the short files for the end.
SLOWEST_FIRST = (
    "test_close_the_loop_aarl.py", "test_notebooks.py", "test_mcmc.py",
    "test_diagnose_protocols.py", "test_compile_budget.py", "test_fit.py", "test_diagnose.py",
    "test_diagnose_effects.py", "test_sharding.py", "test_cli_failures.py",
    "test_real_files.py", "test_cli.py", "test_fit_status.py", "test_force_model.py",
    "test_published_models.py", "test_joint_fit.py", "test_compare.py",
    "test_virtual_isometric.py", "test_joint_sim.py", "test_check_decays.py",
)


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session):
    """A worker collects its garbage before it tells the controller it has finished, then
    freezes what is left (``gc.freeze``), so that pytest's own cleanup, five more
    collections, has nothing of the run's heap to walk. execnet sends a worker that is
    still running 5 s after the controller asked it to stop a SIGINT; a
    ``KeyboardInterrupt`` "ignored in _xla_gc_callback" (JAX's callback on each collection)
    was printed at the end of most runs, and in none since this hook. Runs after the
    session's fixtures are torn down (``trylast``) and before pytest-xdist reports the worker
    finished (its hook wraps this one)."""
    import gc

    if os.environ.get("PYTEST_XDIST_WORKER"):
        gc.collect()
        gc.freeze()


def pytest_collection_modifyitems(config, items):
    """The files of :data:`SLOWEST_FIRST` first, in that order, then the others in their
    usual order; the tests of a file keep their order. A name there that is not a file here
    (renamed, removed) stops the run."""
    from pathlib import Path

    here = Path(__file__).resolve().parent
    stale = [name for name in SLOWEST_FIRST if not (here / name).is_file()]
    if stale:
        raise pytest.UsageError(f"tests/conftest.py SLOWEST_FIRST names no file: {stale}")
    rank = {name: i for i, name in enumerate(SLOWEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))
