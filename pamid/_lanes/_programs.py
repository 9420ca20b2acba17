"""The compiled programs this process holds, kept below the operating system's limit.

Every program XLA compiles for the CPU is loaded into memory regions of its own (code,
constants, data): about 3.4 regions per program on this project's machine, and JAX keeps
every program it has compiled for the life of the process. Linux caps the regions of one
process (``vm.max_map_count``, 65,530 by default); a process that compiles more than about
19,000 programs — a long study that diagnoses hundreds of files, a test run's worker — then
fails to map the next one and dies of a segmentation fault inside XLA (seen 2026-11-27: a
test worker at 96 % of the suite, in the compilation cache's ``executable.serialize()``;
the worker's regions grew by about 2,700 a minute).

:func:`release_if_crowded` drops JAX's caches of compiled programs when the process holds
more than :data:`CROWDED_SHARE` of its limit. Programs still in use are not affected; those
needed again are compiled again, or read back from the disk caches when they are on
(:mod:`._export_cache`). It looks at most once a second (:data:`LOOK_EVERY_S`): the
kernel writes the region list for each look, about 5 ms at 6,000 regions on this project's
machine (2026-11-28), so at most 0.5 % of a busy second then; a call between looks costs
about 0.5 µs.
"""

from __future__ import annotations

import functools
import gc
import threading
import time

#: The share of the process's region limit above which compiled programs are dropped.
CROWDED_SHARE = 0.4
#: Seconds between two looks at the region count (a look reads /proc/self/maps).
LOOK_EVERY_S = 1.0

_LOCK = threading.Lock()
_last_look = -float("inf")
_released = 0  # how many times this process has dropped its programs


@functools.cache
def region_limit() -> int | None:
    """The most memory regions one process may map (``vm.max_map_count``); None where the
    system does not say (not Linux). Read once: a setting of the system, not of the
    process."""
    try:
        with open("/proc/sys/vm/max_map_count", "rb") as f:
            return int(f.read().strip())
    except (OSError, ValueError):
        return None


def regions() -> int | None:
    """The memory regions this process maps now; None where the system does not say."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return f.read().count(b"\n")
    except OSError:
        return None


def release_if_crowded(force_look: bool = False) -> bool:
    """Drop JAX's compiled programs (``jax.clear_caches``) when this process maps more than
    :data:`CROWDED_SHARE` of its region limit; True when it did. Looks at most once every
    :data:`LOOK_EVERY_S` unless ``force_look``. Where the system gives no limit, nothing."""
    global _last_look, _released
    now = time.monotonic()
    with _LOCK:
        if not force_look and now - _last_look < LOOK_EVERY_S:
            return False
        _last_look = now
        limit, held = region_limit(), regions()
        if limit is None or held is None or held <= CROWDED_SHARE * limit:
            return False
        import jax

        from . import _export_cache

        jax.clear_caches()
        _export_cache.forget()  # the programs read back compiled hold their own
        gc.collect()
        _released += 1
        return True


def times_released() -> int:
    """How many times this process has dropped its compiled programs."""
    return _released
