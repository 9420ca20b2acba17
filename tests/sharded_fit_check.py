"""Sharded fits against one-device fits, run by tests/test_sharding.py in a subprocess.

JAX must see several devices before it starts, so this runs as its own process, e.g.

    XLA_FLAGS=--xla_force_host_platform_device_count=2 .venv/bin/python tests/sharded_fit_check.py

and prints one JSON object of measurements (the test makes the assertions). 37 muscles: an
odd number, so that the lanes are padded to a multiple of the device count. ``--all`` adds
the bounded (L-BFGS-B) path and jaxopt's per-device comparison (slow to compile).
"""

from __future__ import annotations

import json
import re
import sys
import time

import jax
import numpy as np

import pamid
from pamid._fit._least_squares import _statistics, solve
from pamid._fit._spec import SAROSI
from pamid._lanes import _batch
from pamid._lanes._sharding import lane_devices, use_devices

N_MUSCLES = 37


def make_data(n):
    """``n`` muscles, Table 3-1 × (1 + 0.03·normal), Sárosi's protocol with 10 points per
    sweep (100 samples per muscle), fixed keys."""
    key_theta, key_noise = jax.random.split(jax.random.key(37))
    z = np.asarray(jax.random.normal(key_theta, (n, 6)))
    theta = np.asarray(pamid.sarosi.table_3_1().to_vector()) * (1.0 + 0.03 * z)
    frame = pamid.simulate_sarosi_bench(
        key_noise,
        pamid.Sarosi.from_vector(theta),
        pamid.SarosiProtocol(points_per_curve=10, min_force_N=10.0),
    )
    groups = [
        (
            (g["pressure_kPa"].to_numpy() / 100.0, g["contraction_pct"].to_numpy()),
            g["force_N"].to_numpy(),
        )
        for _, g in frame.groupby("muscle", sort=True)
    ]
    return pamid.pack_muscles(groups)


def take(data, idx):
    return jax.tree.map(lambda a: a[np.asarray(idx)], data)


def rel(a, b):
    """Largest |a − b| / |b| over finite entries; NaN/inf must sit at the same places."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    if not np.array_equal(np.isfinite(a), np.isfinite(b)):
        return float("inf")
    ok = np.isfinite(b)
    return float(np.max(np.abs(a[ok] - b[ok]) / np.maximum(np.abs(b[ok]), 1e-300), initial=0.0))


def main(full=False):
    devices = lane_devices()
    one = devices[:1]
    out = {"n_devices": len(devices), "platform": devices[0].platform}
    data = make_data(N_MUSCLES)

    # 1. The public fit, sharded (the default with two devices) against one device.
    t = time.perf_counter()
    with use_devices(one):
        ref = pamid.fit_least_squares(data, intervals=("wald", "profile"))
    fit = pamid.fit_least_squares(data, intervals=("wald", "profile"))
    out["fit"] = {
        "theta": rel(fit.theta, ref.theta),
        "ci95": rel(fit.ci95, ref.ci95),
        "ci95_profile": rel(fit.ci95_profile, ref.ci95_profile),
        "sse": rel(fit.sse, ref.sse),
        "converged_equal": bool(np.array_equal(fit.converged, ref.converged)),
        "n_converged": int(fit.converged.sum()),
        "seconds": time.perf_counter() - t,
    }

    # 2. Per device: the lanes of each device against a one-device fit of exactly those lanes
    # (37 lanes padded with lane 36 to 38, 19 per device), and against the one-device fit of
    # all 37. Fits of different batch sizes can differ in the last bits on one device too
    # (XLA's CPU kernels depend on the shape), and so can a partitioned program.
    seen = []

    def spy(t0, x, y, w):
        seen.append(
            (len(y.sharding.device_set), sorted({s.data.shape[0] for s in y.addressable_shards}))
        )
        return _statistics(SAROSI, t0, x, y, w)

    theta0 = _batch.map_lanes(SAROSI.start, data.x, data.y, data.w)
    idx = np.minimum(np.arange(38), N_MUSCLES - 1)
    halves = (idx[:19], idx[19:])
    with use_devices(one):
        starts = [np.asarray(SAROSI.start(*take((data.x, data.y, data.w), i))) for i in halves]
    joined_start = np.concatenate(starts)[:N_MUSCLES]
    out["start"] = {
        "per_device_bitwise": bool(np.array_equal(theta0, joined_start)),
        "per_device_theta": rel(theta0, joined_start),
    }
    out["seen_by_fn"] = seen
    # jaxopt's Levenberg–Marquardt stops on criteria that rounding moves: its answer is
    # determined to ~1e-8 only, and batches of other sizes on one device differ as much.
    paths = [("gauss-newton", {}), ("jaxopt", {"solver": "jaxopt-levenberg-marquardt"})]
    if full:  # L-BFGS-B compiles slowly (~12 s per shape here): only on request
        paths.append(("bounded", {"bounds": (-1e4, 1e4)}))
    for name, kwargs in paths:
        t = time.perf_counter()
        sharded = solve(SAROSI, data, theta0=theta0, **kwargs)
        with use_devices(one):
            whole = solve(SAROSI, data, theta0=theta0, **kwargs)
        out[name] = {
            "theta_vs_one_device": rel(sharded[0], whole[0]),
            "converged_equal": bool(np.array_equal(sharded[1], whole[1])),
        }
        if name == "gauss-newton" or full:
            with use_devices(one):
                parts = [solve(SAROSI, take(data, i), theta0=theta0[i], **kwargs) for i in halves]
            joined = [np.concatenate([p[k] for p in parts])[:N_MUSCLES] for k in range(3)]
            out[name]["per_device_bitwise"] = all(
                bool(np.array_equal(a, b)) for a, b in zip(sharded, joined, strict=True)
            )
            out[name]["per_device_theta"] = rel(sharded[0], joined[0])
            out[name]["per_device_converged_equal"] = bool(np.array_equal(sharded[1], joined[1]))
            out[name]["halves_vs_one_device"] = rel(joined[0], whole[0])
        out[name]["seconds"] = time.perf_counter() - t
    _batch.map_lanes(spy, theta0, data.x, data.y, data.w)

    # 3. The compiled batch is partitioned: two partitions, 19 lanes on each.
    args = _sharded_args(data, fit.theta)
    sharding = args[0].sharding
    hlo = _statistics.lower(SAROSI, *args).compile().as_text()
    out["hlo"] = {
        "num_partitions": sorted(set(re.findall(r"num_partitions=(\d+)", hlo))),
        # the rows of a lane: 100, padded to their size class
        "lane_shapes": sorted(set(re.findall(rf"f64\[(\d+),{data.y.shape[1]}\]", hlo))),
        "mesh_axis_types": str(sharding.mesh.axis_types),
    }

    # 4. Chunks and devices together: 8 lanes per device and call (the CPU devices' default
    # chunk, set to 8 here), so 37 lanes make calls of 16, 16 and 5 (padded to 16) lanes;
    # against one device, one call of 37.
    cpu_chunk = _batch.CPU_CHUNK_LANES
    _batch.CPU_CHUNK_LANES = 8
    calls = []

    def count(theta, x, y, w):
        calls.append(y.shape[0])
        return _statistics(SAROSI, theta, x, y, w)

    chunked = _batch.map_lanes(count, fit.theta, data.x, data.y, data.w)
    _batch.CPU_CHUNK_LANES = cpu_chunk
    with use_devices(one):
        whole = _batch.map_lanes(count, fit.theta, data.x, data.y, data.w)
    out["chunked"] = {
        "calls": calls[:-1],
        "sse": rel(chunked[0], whole[0]),
        "jtj_inv": rel(chunked[1], whole[1]),
    }

    print(json.dumps(out))


def _sharded_args(data, theta):
    """(theta, x, y, w) padded to 38 lanes and split over the devices as map_lanes does."""
    from pamid._lanes._sharding import lane_sharding

    sharding = lane_sharding(lane_devices())
    idx = np.minimum(np.arange(38), N_MUSCLES - 1)
    args = (theta, data.x, data.y, data.w)
    return jax.tree.map(lambda a: jax.device_put(np.asarray(a)[idx], sharding), args)


if __name__ == "__main__":
    main(full="--all" in sys.argv[1:])
