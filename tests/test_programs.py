"""Compiled programs are dropped before the process runs out of memory regions
(``pamid/_lanes/_programs.py``): on Linux a process may map ``vm.max_map_count`` regions,
and every program XLA compiles for the CPU takes a few."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pamid._lanes import _export_cache, _programs
from pamid._lanes._batch import map_lanes

linux = pytest.mark.skipif(_programs.region_limit() is None,
                           reason="the system does not report its region limit")


@linux
def test_each_compiled_program_takes_regions_that_dropping_it_gives_back():
    before = _programs.regions()
    fns = [jax.jit(lambda x, k=k: jnp.sin(x) * k + jnp.cumsum(x)) for k in range(40)]
    for k, f in enumerate(fns):
        f(jnp.ones(7 + k)).block_until_ready()
    grown = _programs.regions() - before
    assert grown >= 40  # at least one region per program
    jax.clear_caches()
    assert _programs.regions() - before < grown / 2


@linux
def test_map_lanes_drops_the_programs_of_a_crowded_process(monkeypatch):
    f = jax.jit(lambda x: 2.0 * x)
    f(jnp.ones(3)).block_until_ready()
    assert f._cache_size() == 1
    released = _programs.times_released()
    # A share no process stays under: the next look finds it crowded.
    monkeypatch.setattr(_programs, "CROWDED_SHARE", 0.0)
    monkeypatch.setattr(_programs, "_last_look", -float("inf"))
    monkeypatch.setitem(_export_cache._LOADED, "a program read back", object())
    out = map_lanes(lambda x: x + 1.0, np.zeros((4, 3)))
    np.testing.assert_array_equal(out, np.ones((4, 3)))
    assert _programs.times_released() == released + 1
    assert f._cache_size() == 0  # every jitted function's programs were dropped
    assert _export_cache._LOADED == {}  # and those read back compiled from disk
    # Looked at most once a second: an immediate second call does not look again. (The
    # second is stretched here: under load the first call's compile took more than one, and
    # the second call looked again, in a clean-clone run of 2026-12-02.)
    monkeypatch.setattr(_programs, "LOOK_EVERY_S", 3600.0)
    map_lanes(lambda x: x + 1.0, np.zeros((4, 3)))
    assert _programs.times_released() == released + 1


def test_a_process_below_its_limit_keeps_its_programs(monkeypatch):
    f = jax.jit(lambda x: 3.0 * x)
    f(jnp.ones(3)).block_until_ready()
    monkeypatch.setattr(_programs, "CROWDED_SHARE", 1e9)
    assert not _programs.release_if_crowded(force_look=True)
    assert f._cache_size() == 1
