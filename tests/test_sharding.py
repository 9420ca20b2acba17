"""Batches spread over several devices give the one-device answers.

Several CPU devices exist only if JAX is told before it starts
(``--xla_force_host_platform_device_count``), so the sharded fit runs in a subprocess,
``tests/sharded_fit_check.py``, on two virtual devices. A fit of two ``jax.distributed``
processes on localhost (``pamid fit --stream --processes 2``) is tested in
``tests/test_fit_stream.py``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pamid._lanes import _batch
from pamid._lanes._sharding import lane_devices, lanes_per_call, use_devices

ROOT = Path(__file__).resolve().parent.parent


def _env(n_devices: int | None = None) -> dict:
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    if n_devices:
        flag = f"--xla_force_host_platform_device_count={n_devices}"
        env["XLA_FLAGS"] = f"{env.get('XLA_FLAGS', '')} {flag}".strip()
    return env


@pytest.mark.parametrize(
    ("n", "chunk", "n_devices", "expected"),
    [(37, 2048, 2, 38), (38, 2048, 2, 38), (37, 8, 2, 16), (1, 2048, 4, 4), (100, 10, 3, 30)],
)
def test_lanes_per_call(n, chunk, n_devices, expected):
    # At most `chunk` lanes per device, and a multiple of the device count.
    assert lanes_per_call(n, chunk, n_devices) == expected


def test_use_devices_needs_a_device():
    with pytest.raises(ValueError, match="at least one device"):
        with use_devices([]):
            pass


def test_lane_devices_default_and_chosen():
    assert lane_devices() == tuple(jax.local_devices())
    cpu = jax.devices("cpu")[0]
    with use_devices([cpu]):
        assert lane_devices() == (cpu,)
    with jax.default_device(cpu):
        assert lane_devices() == (cpu,)
    assert lane_devices() == tuple(jax.local_devices())


def test_one_device_map_lanes_known_answer():
    """On one device map_lanes chunks, pads and trims as before; use_devices changes nothing."""
    calls = []

    @jax.jit
    def fn(a, b):
        calls.append(a.shape[0])  # runs at trace time: one entry per compiled shape
        return {"sum": a + b[:, 0], "twice": 2 * b}

    a = np.arange(7.0)
    b = np.stack([10 * a, a], axis=1)
    for devices in (None, jax.local_devices()[:1]):
        if devices is None:
            out = _batch.map_lanes(fn, a, jnp.asarray(b), chunk=3)
        else:
            with use_devices(devices):
                out = _batch.map_lanes(fn, a, jnp.asarray(b), chunk=3)
        np.testing.assert_array_equal(out["sum"], 11 * a)
        np.testing.assert_array_equal(out["twice"], 2 * b)
        assert isinstance(out["sum"], np.ndarray)
    # 7 lanes as 3 + 3 + 1 padded to 3: one compiled shape (traced again under
    # use_devices, whose jax.default_device is part of jit's cache key).
    assert set(calls) == {3}


def test_sharded_fit_equals_one_device():
    """37 muscles on two virtual CPU devices: the public fit (Wald and profile intervals)
    equals the one-device fit to 1e-12, each device's lanes equal a one-device fit of those
    lanes, and the compiled batch is really split (two partitions of 19 lanes)."""
    proc = subprocess.run(
        [sys.executable, str(ROOT / "tests" / "sharded_fit_check.py")],
        env=_env(2),
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["n_devices"] == 2
    fit = out["fit"]
    for key in ("theta", "ci95", "ci95_profile", "sse"):
        assert fit[key] <= 1e-12, (key, fit[key])
    assert fit["converged_equal"] and fit["n_converged"] == 37
    # Sharding happened: the function saw arrays on two devices, 19 lanes each (37 + 1
    # padding), and XLA compiled two partitions of 19 lanes on the Auto mesh axis.
    assert out["seen_by_fn"] == [[2, [19]]]
    assert out["hlo"] == {
        "num_partitions": ["2"],
        "lane_shapes": ["19"],
        "mesh_axis_types": "(Auto,)",
    }
    # Per device: each device's lanes equal a one-device fit of exactly those lanes.
    for name in ("start", "gauss-newton"):
        assert out[name]["per_device_theta"] <= 1e-12, (name, out[name])
    gn = out["gauss-newton"]
    assert gn["per_device_converged_equal"] and gn["converged_equal"]
    assert gn["theta_vs_one_device"] <= 1e-12
    # jaxopt's Levenberg–Marquardt runs sharded; its stopping rule leaves ~1e-8 of rounding
    # in the answer, as one-device batches of another size do.
    assert out["jaxopt"]["converged_equal"]
    assert out["jaxopt"]["theta_vs_one_device"] <= 1e-6
    # Chunks and devices together: 8 lanes per device and call → 3 calls of 16 lanes.
    assert out["chunked"]["calls"] == [16, 16, 16]
    # (JᵀJ)⁻¹ through an SVD of the column-scaled Jacobian: XLA's batched SVD rounds
    # differently for another batch size (measured 4.5e-11 relative), at the scale of
    # the matrix's condition number times the unit roundoff.
    assert out["chunked"]["sse"] <= 1e-12 and out["chunked"]["jtj_inv"] <= 1e-9


def test_one_lane_sizer_for_fits_intervals_and_refits():
    """``items_per_call`` (pamid/_lanes/_batch.py) sizes every batched call: a fit's muscles,
    a muscle's 2·p interval ends, the diagnosis's refits by their samples (a power of two,
    at most CALL_LANES, at most CALL_LANE_SAMPLES lane-samples, SMALL_CALL_LANE_SAMPLES in a
    small diagnosis)."""
    import jax

    from pamid._diagnose._static import (
        CALL_LANE_SAMPLES,
        CALL_LANES,
        SMALL_CALL_LANE_SAMPLES,
        _refit_call_lanes,
    )
    from pamid._lanes._batch import CHUNK_LANES, CPU_CHUNK_LANES, items_per_call

    cpu = jax.devices("cpu")
    assert items_per_call(devices=cpu) == CPU_CHUNK_LANES
    assert items_per_call(12, devices=cpu) == CPU_CHUNK_LANES // 12
    refits = {n: items_per_call(n_samples=n, max_lane_samples=CALL_LANE_SAMPLES,
                                max_lanes=CALL_LANES, devices=cpu)
              for n in (64, 128, 512, 1024, 1500, 3000, 100_000)}
    assert refits == {64: 64, 128: 64, 512: 16, 1024: 8, 1500: 4, 3000: 2, 100_000: 1}
    # A small diagnosis (one or a few muscles) takes half as many lane-samples a call.
    small = {n: items_per_call(n_samples=n, max_lane_samples=SMALL_CALL_LANE_SAMPLES,
                               max_lanes=CALL_LANES, devices=cpu) for n in (64, 512, 2048)}
    assert small == {64: 64, 512: 8, 2048: 2}
    # What a diagnosis's refits take: one muscle of 2,048 rows is small, 100 of 512 are not.
    assert _refit_call_lanes(1, 2048) == small[2048] == 2
    assert _refit_call_lanes(1, 512) == small[512] == 8
    assert _refit_call_lanes(100, 512) == refits[512] == 16

    class Gpu:
        platform = "gpu"

    assert items_per_call(12, devices=(Gpu(),)) == CHUNK_LANES
