"""Ragged groups of samples (one per muscle) packed into padded arrays with weights.

Every batched computation in pamid sees arrays of shape (M, n_max): M muscles (or
bootstrap replicates, or synthetic data sets) by the largest sample count, with weight 0
on the padding. A weight may also be a count (a bootstrap replicate that draws a curve
twice gives its samples weight 2), which weighted least squares treats exactly as
repeated rows.
"""

from __future__ import annotations

import concurrent.futures
import functools
import os
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from . import _export_cache
from ._programs import release_if_crowded
from ._sharding import chosen_devices, lane_devices, lane_sharding, lanes_per_call
from ._sizes import SMALL_BATCH_SAMPLES, padded_rows


class FitData(NamedTuple):
    """A batch of muscles for fitting.

    Attributes:
        x: model inputs, each (M, n), e.g. (pressure_bar, contraction_pct) for Sárosi.
        y: measured output (force in N), (M, n).
        w: sample weights, (M, n); 0 marks padding.
        curve: index of the curve (sweep) each sample belongs to within its muscle,
            (M, n); −1 on padding. The bootstrap resamples whole curves.
    """

    x: tuple[Float[Array, "M n"], ...]
    y: Float[Array, "M n"]
    w: Float[Array, "M n"]
    curve: Int[Array, "M n"]

    @property
    def n_muscles(self) -> int:
        return self.y.shape[0]


class LaneView(NamedTuple):
    """A batch whose lanes are made inside the compiled call from arrays they share: lane
    i's ``(x, y, w)`` is ``make(source, *(a[i] for a in index))``. What a batch of many
    lanes over the same samples (the diagnosis's candidate sets × folds of each muscle)
    passes to the one least-squares entry instead of a :class:`FitData` with a copy of the
    samples per lane: the memory is the source plus a call's temporaries.

    Attributes:
        source: the shared arrays (a pytree), on the device once.
        index: per-lane arrays (a tuple, leading lane axis): what ``make`` reads a lane by.
        make: a module-level function (its name keys the compiled programs kept on disk).
    """

    source: object
    index: tuple
    make: object

    @property
    def n_lanes(self) -> int:
        return int(np.shape(self.index[0])[0])


def pack(groups, curves=None) -> FitData:
    """Pack a list of muscles, each ``(x_tuple, y)`` of 1-D arrays, into a padded batch.

    ``curves``, if given, is a list of 1-D integer arrays (curve id of each sample); by
    default every sample of a muscle is in curve 0. The groups are concatenated and packed
    by :func:`pack_rows`.
    """
    if not groups:
        raise ValueError("no muscles to fit")
    n_x = len(groups[0][0])
    sizes = np.array([len(y) for _, y in groups], dtype=np.int64)
    codes = np.repeat(np.arange(len(groups)), sizes)
    xs = tuple(_concat([x[j] for x, _ in groups]) for j in range(n_x))
    y = _concat([y for _, y in groups])
    curve = None if curves is None else np.concatenate([np.ravel(c) for c in curves])
    return pack_rows(codes, xs, y, curve, n_muscles=len(groups))


def _concat(arrays) -> np.ndarray:
    return np.concatenate([np.asarray(a, dtype=np.float64).ravel() for a in arrays])


def pack_rows(codes, x, y, curve=None, n_muscles: int | None = None) -> FitData:
    """Pack samples given row by row into a padded batch, one lane per muscle.

    Args:
        codes: muscle of every row, integers 0 … M − 1 (``pd.factorize`` of a muscle
            column); within a muscle the rows keep their order.
        x: model inputs, a tuple of 1-D arrays aligned with ``codes``.
        y: measured output, 1-D, aligned with ``codes``.
        curve: optional curve id of every row; ids are made dense within each muscle
            (0, 1, … in increasing order of id). Default: every row in curve 0.
        n_muscles: M (default ``codes.max() + 1``); a muscle with no rows is all padding.

    Padding repeats the muscle's first sample in ``x`` (so that the model stays finite
    there), has y = 0, weight 0 and curve −1. Every lane has :func:`padded_rows` of the
    largest muscle's row count (and the number of muscles): files of nearby lengths pack
    to one shape, so that they share compiled programs. No loop over muscles: the rows
    sorted by muscle (stable; no sort where each muscle is one block, in order), then one
    masked assignment per array (lane k's first ``counts[k]`` places, in row-major order,
    are its rows in order), with no index array of the rows: the first packing of 10,000
    muscles of 300 rows in a process took 0.17-0.32 s, against 0.21-0.47 s by a scatter of
    row indices (benchmarks/README.md, "Packing the lanes by a mask").
    """
    codes = np.asarray(codes, dtype=np.int64)
    n = len(codes)
    m = int(codes.max()) + 1 if n_muscles is None else int(n_muscles)
    if m == 0:
        raise ValueError("no muscles to fit")
    counts = np.bincount(codes, minlength=m)
    starts = np.cumsum(counts) - counts
    n_max = padded_rows(int(counts.max()) if n else 0, m)
    if np.all(codes[1:] >= codes[:-1]):
        order = None  # each muscle one block, in order: no sort
        first = starts
    else:
        order = np.argsort(codes, kind="stable")
        first = order[np.minimum(starts, n - 1)]
    empty = counts == 0
    first = np.where(empty, 0, first)
    full = order is None and n == m * n_max  # every muscle one block of n_max rows
    mask = None if full else np.arange(n_max)[None, :] < counts[:, None]  # (m, n_max)

    def scatter(values, fill, dtype=np.float64):
        if full:  # the rows are the batch already, row-major
            return np.broadcast_to(np.asarray(values, dtype=dtype), (n,)).reshape(m, n_max)
        if np.ndim(values) == 0:  # the weight, a curve of 0: the mask itself
            return np.where(mask, np.asarray(values, dtype=dtype), np.asarray(fill, dtype=dtype))
        out = np.empty((m, n_max), dtype=dtype)
        out[...] = fill
        out[mask] = values if order is None else np.asarray(values)[order]
        return out

    def x_lane(a):
        a = np.asarray(a, dtype=np.float64)
        pad = np.where(empty, 0.0, a[first]) if n else np.zeros(m)
        return scatter(a, pad[:, None])

    curve_ids = 0 if curve is None else _dense_within(codes, np.asarray(curve), order)
    # device_put, not jnp.asarray: JAX stages a NumPy array through a compiled program of
    # its shape (lax.stage), compiled (or read from the disk cache) once per shape.
    return FitData(
        x=tuple(jax.device_put(x_lane(a)) for a in x),
        y=jax.device_put(scatter(np.asarray(y, dtype=np.float64), 0.0)),
        w=jax.device_put(scatter(1.0, 0.0)),
        curve=jax.device_put(scatter(curve_ids, -1, dtype=np.int64)),
    )


def padded_lanes(n: int, chunk: int, lane_size: int = 1) -> int:
    """Lanes of a compiled call that takes ``n`` ≤ ``chunk`` lanes at once, each of
    ``lane_size`` numbers (its rows, say): where the call is small (n × lane_size ≤
    ``SMALL_BATCH_SAMPLES``) the next power of two, so that files of 3 and of 4 muscles, or
    compare's folds of a muscle with 4 curves and one with 5, run one program; in a larger
    call, whose arithmetic counts, the next multiple of 8 (at most 7 lanes of padding).
    Never more than ``chunk``."""
    if n <= 1:
        return max(n, 1)
    if n * max(lane_size, 1) <= SMALL_BATCH_SAMPLES:
        return min(chunk, 1 << (n - 1).bit_length())
    return min(chunk, -(-n // 8) * 8)


def _dense_within(codes, ids, order) -> np.ndarray:
    """Curve ids made dense within each muscle: the rank of each id among the distinct ids
    of its muscle (what ``np.unique(ids_of_muscle, return_inverse=True)`` gives)."""
    n = len(codes)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    ids = ids.astype(np.int64, copy=False) if ids.dtype.kind in "iub" else ids
    if order is None and ids.dtype.kind == "i":
        # Already dense (0 at each muscle's first row, then steps of 0 or 1, as curves
        # found in file order are): nothing to do.
        new_muscle = np.ones(n, dtype=bool)
        new_muscle[1:] = codes[1:] != codes[:-1]
        step = np.diff(ids, prepend=0)
        if np.all(np.where(new_muscle, ids == 0, (step == 0) | (step == 1))):
            return ids
    o = np.lexsort((ids, codes))
    c_s, i_s = codes[o], ids[o]
    new_muscle = np.ones(n, dtype=bool)
    new_muscle[1:] = c_s[1:] != c_s[:-1]
    new_id = new_muscle.copy()
    new_id[1:] |= i_s[1:] != i_s[:-1]
    rank = np.cumsum(new_id) - 1
    first_rank = rank[np.flatnonzero(new_muscle)]
    dense = np.empty(n, dtype=np.int64)
    dense[o] = rank - first_rank[np.cumsum(new_muscle) - 1]
    return dense


#: Lanes (muscles, replicates) per compiled call. Bounds memory: the variable-projection
#: scan and the earlier profile intervals (an optimistix solve per interval end) needed
#: ~0.4 and ~0.9 MB of temporaries per lane of 300 samples, so 10,000 muscles in one call
#: needed 3.6 and 8.7 GB. (The profile intervals now take 12 ends per muscle as lanes, in
#: chunks of as many muscles as make ``CPU_CHUNK_LANES`` ends on the CPU.)
CHUNK_LANES = 2048
#: Lanes per compiled call on the CPU: a chunk's arrays (1.2 MB each at 300 samples) stay
#: in the caches, and every core gets chunks of its own (1000 muscles: two calls side by
#: side); 512 was the fastest chunk of the Sárosi kernels measured at 10,000 muscles and no
#: slower than one call at 1000 (benchmarks/README.md, "Figures that used to live in
#: docstrings", (c)).
CPU_CHUNK_LANES = 512


def items_per_call(lanes_per_item: int = 1, *, n_samples: int | None = None,
                   max_lane_samples: int | None = None, max_lanes: int | None = None,
                   devices=None) -> int:
    """pamid's one lane sizer: how many items (muscles, a muscle's interval ends, candidate
    sets × folds) one compiled call of :func:`map_lanes` takes, per device.

    - On CPU devices, ``CPU_CHUNK_LANES`` lanes shared among an item's ``lanes_per_item``
      lanes (a call's arrays stay in the caches: the profile intervals' 2·p ends of a
      muscle); on others, ``CHUNK_LANES`` items (``devices``: default
      :func:`pamid._lanes._sharding.lane_devices`).
    - With ``max_lane_samples`` (and ``n_samples`` per lane): at most the largest power of
      two of lanes whose lanes × samples stay within it, and at most ``max_lanes``, so that
      every call of a given sample count has one shape whatever the number of lanes (the
      diagnosis's refits: :func:`pamid._diagnose._static._run_lanes`).
    """
    devices = lane_devices() if devices is None else devices
    if devices[0].platform == "cpu":
        size = max(1, CPU_CHUNK_LANES // max(int(lanes_per_item), 1))
    else:
        size = CHUNK_LANES
    if max_lane_samples is not None:
        fit = max(1, max_lane_samples // max(int(n_samples or 1), 1))
        if max_lanes is not None:
            fit = min(fit, max_lanes)
        size = min(size, 1 << (fit.bit_length() - 1))
    return size


def map_lanes(fn, *arrays, chunk: int | None = None, cache_key: tuple | None = None,
              of_lanes: int | None = None):
    """Apply ``fn`` to the arrays (pytrees with a leading lane axis) in chunks of lanes.

    Every chunk has the same size, so ``fn`` compiles once: on one device the last chunk
    is the last ``chunk`` lanes (those the chunk before it holds too are dropped from its
    outputs), on several it is padded by repeating its final lane. ``fn`` must treat its
    lanes independently. Outputs are pytrees of arrays with a leading lane axis,
    concatenated as NumPy arrays.

    With several devices (:func:`pamid._lanes._sharding.lane_devices`: all of this process's
    GPUs, or those chosen with ``use_devices``) every chunk holds up to ``chunk`` lanes per
    device, padded to a multiple of the device count, and is split evenly across the devices
    along the lane axis; ``fn`` (a jitted, vmapped function) then runs partitioned, each
    device on its own lanes. With one device nothing of this happens.

    ``cache_key``: a name for ``fn`` and everything it closes over; on one device, calls then
    go through the exported program kept on disk when :mod:`._export_cache` is on.

    ``of_lanes``: the lanes of the batch these were taken from (a few muscles of a file,
    say); a subset of a batch of more lanes than a call takes runs in the batch's own calls
    (:func:`call_layout`), one compiled shape however many lanes the subset has.

    A process that has compiled so many programs that it nears the system's limit on its
    memory regions drops them first (:func:`._programs.release_if_crowded`): a long study
    would otherwise die of a segmentation fault inside XLA.
    """
    import jax

    release_if_crowded()
    leaves = jax.tree.leaves(arrays)
    n = leaves[0].shape[0]
    devices = lane_devices()
    if chunk is None:
        chunk = items_per_call(devices=devices)
    if len(devices) > 1:
        return _map_lanes_sharded(fn, arrays, n, chunk, devices)
    # One device picked with use_devices or jax.default_device: run there, named in every
    # worker thread (jax.default_device is a per-thread setting).
    pinned = chosen_devices() is not None or jax.config.jax_default_device is not None
    device = devices[0] if pinned else None
    cpu = devices[0].platform == "cpu"
    if cache_key is not None:
        fn = functools.partial(_export_cache.call, cache_key, fn)
    elif _export_cache.only_cached():
        raise _export_cache.NotCached("a call that is not kept on disk")
    return _map_lanes_one_device(fn, arrays, n, chunk, device, cpu, of_lanes)


def map_shared(fn, source, *lanes, chunk: int, cache_key: tuple | None = None):
    """``fn(source, *lanes)`` over the lanes (pytrees with a leading lane axis) in calls of
    exactly ``chunk`` lanes, fewer lanes padded by repeating the last: one compiled shape
    whatever the number of lanes. ``source`` (arrays every lane reads, a
    :class:`LaneView`'s) is an argument of every call, and of the program kept on disk
    under ``cache_key`` (on one device), not a constant of it."""
    n = int(np.shape(jax.tree.leaves(lanes)[0])[0])
    if n < chunk:
        idx = np.minimum(np.arange(chunk), n - 1)
        lanes = jax.tree.map(lambda a: np.asarray(a)[idx], lanes)
    if cache_key is not None and len(lane_devices()) == 1:
        def call(*part):
            return _export_cache.call(cache_key, fn, source, *part)
    else:
        def call(*part):
            return fn(source, *part)
    return jax.tree.map(lambda a: a[:n], map_lanes(call, *lanes, chunk=chunk))


def call_layout(n: int, chunk: int, cpu: bool = True, lane_size: int = 1,
                of_lanes: int | None = None) -> tuple[int, bool]:
    """How :func:`map_lanes` calls its function on one device for ``n`` lanes in calls of
    at most ``chunk``: the lanes of a call, and whether a call's arrays are NumPy views of
    those given (on the CPU, where the lanes take several calls) rather than the given arrays
    themselves (one call) or slices of them on the device. A compiled call is keyed by the
    arrays' type as well as their shapes (``prepare_fit`` makes the same calls). Fewer lanes
    than a call takes are padded to :func:`padded_lanes` (``lane_size``: the numbers of the
    largest array per lane), on the host (NumPy). Lanes taken from a batch of ``of_lanes``
    lanes, more than a call takes, run in that batch's calls: ``chunk`` lanes."""
    if n > chunk or (of_lanes or 0) > chunk:
        return chunk, cpu or n < chunk
    size = padded_lanes(n, chunk, lane_size)
    return size, size != n


def _map_lanes_one_device(fn, arrays, n, chunk, device, cpu, of_lanes=None):
    import jax

    lane_size = max(int(np.prod(np.shape(a)[1:])) for a in jax.tree.leaves(arrays))
    size, host = call_layout(n, chunk, cpu, lane_size, of_lanes)
    if size == n:
        return jax.tree.map(np.asarray, fn(*arrays))

    def call(part):
        if device is None:
            return fn(*part)
        with jax.default_device(device):
            return fn(*part)

    if size > n:  # one call of more lanes than given: the last one repeated, then dropped
        out = call(jax.tree.map(lambda a: _lanes(np.asarray(a), 0, n, size), arrays))
        return jax.tree.map(lambda a: np.asarray(a)[:n], out)
    starts = range(0, n, chunk)

    def run(start):
        # Contiguous slices, no copies (a gather of the same lanes is slower:
        # benchmarks/README.md, "Figures that used to live in docstrings", (d)): the last
        # chunk is the last ``chunk`` lanes, and the outputs of those that the chunk before
        # it holds too are dropped. (The lanes are independent, so they come out the same
        # in either chunk; padding the last chunk by copying cost 1 ms of a 13 ms fit of
        # 1000 muscles.)
        first = min(start, n - chunk)
        out = call(jax.tree.map(lambda a: a[first : first + chunk], arrays))
        return jax.tree.map(lambda a: np.asarray(a)[start - first :], out)

    if host:
        # On the CPU as NumPy (no copy): slicing a JAX array is an operation queued on the
        # device behind the running chunks (the same README section, (d)).
        arrays = jax.tree.map(np.asarray, arrays)
    workers = min(len(starts), _cpu_workers() if cpu else 1)
    if workers > 1:
        # A CPU device runs pamid's small kernels on one core per call, and calls made from
        # several threads run side by side (JAX releases the GIL while XLA runs): two
        # threads on two cores nearly halve the Sárosi solve of 10,000 muscles
        # (benchmarks/README.md, "Figures that used to live in docstrings", (d)).
        outputs = list(_pool(workers).map(run, starts))
    else:
        outputs = [run(start) for start in starts]
    return jax.tree.map(lambda *xs: np.concatenate(xs, axis=0), *outputs)


def _lanes(a, start, stop, size):
    """Lanes start…stop−1 of ``a``, padded to ``size`` lanes by repeating the last."""
    part = a[start:stop]
    if stop - start == size:
        return part
    pad = part[-1:]
    reps = (size - (stop - start),) + (1,) * (part.ndim - 1)
    xp = np if isinstance(part, np.ndarray) else jnp
    return xp.concatenate([part, xp.tile(pad, reps)], axis=0)


@functools.cache
def _pool(workers: int) -> concurrent.futures.ThreadPoolExecutor:
    """A pool of ``workers`` threads kept for the life of the process: starting threads
    for every call is a noticeable share of a small batch (benchmarks/README.md, "Figures
    that used to live in docstrings", (d))."""
    return concurrent.futures.ThreadPoolExecutor(workers, thread_name_prefix="pamid-lanes")


def _cpu_workers() -> int:
    """Threads that feed one CPU device: one per core available to this process. (An
    accelerator runs each call across all of itself: one thread.)"""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _map_lanes_sharded(fn, arrays, n, chunk, devices):
    """:func:`map_lanes` over several devices: each call's lanes split evenly across them."""
    import jax

    sharding = lane_sharding(tuple(devices))
    size = lanes_per_call(n, chunk, len(devices))
    outputs = []
    for start in range(0, n, size):
        stop = min(start + size, n)
        if size == n:  # one call, no padding: the arrays go to the devices as they are
            part = jax.tree.map(lambda a: jax.device_put(a, sharding), arrays)
        else:
            part = jax.tree.map(
                lambda a: jax.device_put(_lanes(a, start, stop, size), sharding), arrays
            )
        out = jax.tree.map(np.asarray, fn(*part))
        outputs.append(jax.tree.map(lambda a: a[: stop - start], out))
    if len(outputs) == 1:
        return outputs[0]
    return jax.tree.map(lambda *xs: np.concatenate(xs, axis=0), *outputs)
