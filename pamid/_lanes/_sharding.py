"""Lanes (muscles, replicates) spread over several devices of one process.

:func:`pamid._lanes._batch.map_lanes` puts each chunk of lanes on a one-axis mesh of devices,
split evenly along the lane axis (a ``NamedSharding``), and calls the same jitted, vmapped
function as on one device: XLA partitions the compiled batch so that every device runs its
own lanes, and only the stopping tests of the solvers' while loops are reduced across
devices (an all-reduce of one flag per iteration). Nothing in the fitting code changes.

Why this way (measured with jax 0.12, optimistix 0.1, equinox 0.13, jaxopt 0.8.5 on two
virtual CPU devices; see docs/devices.md):

- a mesh with ``AxisType.Auto`` (GSPMD-style propagation from the inputs' sharding) runs
  every solver path (optimistix Gauss–Newton and Levenberg–Marquardt, jaxopt's
  Levenberg–Marquardt and the L-BFGS-B that bounded fits used then, variable projection),
  the statistics and the profile intervals;
- ``jax.make_mesh`` defaults to ``AxisType.Explicit`` axes, under which the optimistix fit
  fails in equinox's closure conversion ("Closure-converted function called with different
  dynamic arguments") and the jaxopt fit with "Resource axis: lanes ... is not found in
  mesh";
- ``jax.shard_map`` around the vmapped optimistix fit fails in its linearisation
  ("linearized function called on tangent values inconsistent with the original primal
  values"); jaxopt's fit works there.

The mesh spans the devices of this process only (``jax.local_devices()``): under
``jax.distributed`` every process fits its own muscles on its own devices, and the outputs
can be read back to NumPy without any cross-process transfer.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools

import jax
import numpy as np
from jax.sharding import AxisType, Mesh, NamedSharding, PartitionSpec

#: Name of the mesh axis along which lanes are split.
LANE_AXIS = "lanes"

_DEVICES: contextvars.ContextVar[tuple | None] = contextvars.ContextVar(
    "pamid_lane_devices", default=None
)


def lane_devices() -> tuple:
    """The devices batched fits spread their lanes over.

    Those given to :func:`use_devices` where one is active; else, inside
    ``jax.default_device(d)``, that one device (or every local device of a backend named
    there, e.g. ``"cpu"``); otherwise every device of this process on JAX's default backend
    (``jax.local_devices()``): all GPUs of the machine, or the single CPU device (which
    itself uses all cores).
    """
    chosen = chosen_devices()
    if chosen is not None:
        return chosen
    default = jax.config.jax_default_device
    if default is None:
        return tuple(jax.local_devices())
    if isinstance(default, str):
        return tuple(jax.local_devices(backend=default))
    return (default,)


def chosen_devices() -> tuple | None:
    """The devices of the innermost active :func:`use_devices` block, or None."""
    return _DEVICES.get()


@contextlib.contextmanager
def use_devices(devices):
    """Within the block, batched fits run on ``devices`` (a sequence of JAX devices).

    One device turns sharding off (``use_devices(jax.local_devices()[:1])``); several split
    every chunk of lanes evenly across them. The devices must belong to this process.
    """
    devices = tuple(devices)
    if not devices:
        raise ValueError("use_devices needs at least one device")
    foreign = [d for d in devices if d.process_index != jax.process_index()]
    if foreign:
        raise ValueError(f"devices {foreign} do not belong to this process")
    token = _DEVICES.set(devices)
    try:
        yield devices
    finally:
        _DEVICES.reset(token)


@functools.lru_cache(maxsize=8)
def lane_sharding(devices: tuple) -> NamedSharding:
    """Arrays split along their first (lane) axis over ``devices``, other axes whole.

    The mesh axis is ``Auto`` on purpose (``jax.make_mesh`` now defaults to ``Explicit``,
    under which the optimistix and jaxopt fits fail; see the module docstring).
    """
    mesh = Mesh(np.asarray(devices, dtype=object), (LANE_AXIS,), axis_types=(AxisType.Auto,))
    return NamedSharding(mesh, PartitionSpec(LANE_AXIS))


def lanes_per_call(n: int, chunk: int, n_devices: int) -> int:
    """Lanes of one sharded call: ``chunk`` per device at most, padded to a multiple of the
    device count so that every device gets the same number."""
    per_device = min(chunk, -(-n // n_devices))
    return per_device * n_devices
