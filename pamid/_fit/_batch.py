"""Ragged groups of samples (one per muscle) packed into padded arrays with weights.

Every batched computation in pamid sees arrays of shape (M, n_max): M muscles (or
bootstrap replicates, or synthetic data sets) by the largest sample count, with weight 0
on the padding. A weight may also be a count (a bootstrap replicate that draws a curve
twice gives its samples weight 2), which weighted least squares treats exactly as
repeated rows.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ._sharding import chosen_devices, lane_devices, lane_sharding, lanes_per_call


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


def pack(groups, curves=None) -> FitData:
    """Pack a list of muscles, each ``(x_tuple, y)`` of 1-D arrays, into a padded batch.

    ``curves``, if given, is a list of 1-D integer arrays (curve id of each sample); by
    default every sample of a muscle is in curve 0.
    """
    if not groups:
        raise ValueError("no muscles to fit")
    n_x = len(groups[0][0])
    n_max = max(len(y) for _, y in groups)
    m = len(groups)
    xs = np.zeros((n_x, m, n_max))
    y = np.zeros((m, n_max))
    w = np.zeros((m, n_max))
    curve = np.full((m, n_max), -1, dtype=np.int64)
    for i, (x_i, y_i) in enumerate(groups):
        n = len(y_i)
        for j in range(n_x):
            xs[j, i, :n] = x_i[j]
            # Padding repeats the first sample so that the model stays finite there.
            xs[j, i, n:] = x_i[j][0] if n else 0.0
        y[i, :n] = y_i
        w[i, :n] = 1.0
        curve[i, :n] = 0 if curves is None else _dense_ids(curves[i])
    return FitData(
        x=tuple(jnp.asarray(a) for a in xs),
        y=jnp.asarray(y),
        w=jnp.asarray(w),
        curve=jnp.asarray(curve),
    )


def _dense_ids(ids) -> np.ndarray:
    _, inverse = np.unique(np.asarray(ids), return_inverse=True)
    return inverse.astype(np.int64)


#: Lanes (muscles, replicates) per compiled call. Bounds memory: the variable-projection
#: scan and the profile intervals need ~0.4 and ~0.9 MB of temporaries per lane of 300
#: samples, so 10,000 muscles in one call needed 3.6 and 8.7 GB.
CHUNK_LANES = 2048


def map_lanes(fn, *arrays, chunk: int | None = None):
    """Apply ``fn`` to the arrays (pytrees with a leading lane axis) in chunks of lanes.

    Every chunk has the same size (the last is padded by repeating its final lane, and the
    padding is dropped), so ``fn`` compiles once. Outputs are pytrees of arrays with a
    leading lane axis, concatenated as NumPy arrays.

    With several devices (:func:`pamid._fit._sharding.lane_devices`: all of this process's
    GPUs, or those chosen with ``use_devices``) every chunk holds up to ``chunk`` lanes per
    device, padded to a multiple of the device count, and is split evenly across the devices
    along the lane axis; ``fn`` (a jitted, vmapped function) then runs partitioned, each
    device on its own lanes. With one device nothing of this happens.
    """
    import jax

    chunk = CHUNK_LANES if chunk is None else chunk
    leaves = jax.tree.leaves(arrays)
    n = leaves[0].shape[0]
    devices = lane_devices()
    if len(devices) > 1:
        return _map_lanes_sharded(fn, arrays, n, chunk, devices)
    if chosen_devices() is not None:  # one device picked with use_devices: run there
        with jax.default_device(devices[0]):
            return _map_lanes_one_device(fn, arrays, n, chunk)
    return _map_lanes_one_device(fn, arrays, n, chunk)


def _map_lanes_one_device(fn, arrays, n, chunk):
    import jax

    if n <= chunk:
        return jax.tree.map(np.asarray, fn(*arrays))
    outputs = []
    for start in range(0, n, chunk):
        stop = min(start + chunk, n)
        idx = np.minimum(np.arange(start, start + chunk), stop - 1)
        part = jax.tree.map(lambda a: a[idx], arrays)
        out = jax.tree.map(np.asarray, fn(*part))
        outputs.append(jax.tree.map(lambda a: a[: stop - start], out))
    return jax.tree.map(lambda *xs: np.concatenate(xs, axis=0), *outputs)


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
            idx = np.minimum(np.arange(start, start + size), stop - 1)
            part = jax.tree.map(lambda a: jax.device_put(a[idx], sharding), arrays)
        out = jax.tree.map(np.asarray, fn(*part))
        outputs.append(jax.tree.map(lambda a: a[: stop - start], out))
    if len(outputs) == 1:
        return outputs[0]
    return jax.tree.map(lambda *xs: np.concatenate(xs, axis=0), *outputs)
