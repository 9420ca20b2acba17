"""Where the time of pamid's batched Sárosi fit goes, piece by piece (helper of fit_batch.py).

    .venv/bin/python benchmarks/profile_pieces.py [--n 1000] [--repeats 7]

Times (median of warm calls, after one compiling call) at N muscles of virtual-bench data:
the default Sárosi solve (``pamid/_solvers/_sarosi.py``) and its parts, through the public
kernels of ``pamid.engine`` (the start; the start scanning every sample instead of a
subsample, and without its parabolic refinement; the iterations, and one full pass over the
samples as two iterations less one), the previous default (the 24-point variable-projection
start and its parts, built from ``sarosi_fit_at_a3``, then optimistix Gauss–Newton:
``solve`` of the Sárosi spec without its written-out kernels), batched LAPACK calls of the
shapes pamid uses, and, for scale, a hand-written batched Gauss–Newton (analytic Jacobian,
normal equations, fixed step count) in JAX and in NumPy from the same start: a yardstick for
what the hardware can do.
It also checks the scaling of ``bench_to_fit_data`` (from a CSV loaded with ``load_bench``),
and, at ``--cores-n`` muscles (default 10,000), how batches use the CPU: the solve with one
thread per core against one thread (this thread held to one core, as ``taskset -c 0`` would:
pamid then feeds the device from one thread), a chunk built by a gather against a slice, and
the Sárosi statistics from sums against the Jacobian/QR/SVD path (``statistics`` of the spec
without its written-out kernels). ``--only-cores`` runs that part alone;
run it under ``XLA_FLAGS=--xla_force_host_platform_device_count=2`` for the sharded solve on
two virtual devices.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import fit_batch  # noqa: E402

import pamid  # noqa: E402
from pamid.engine import (  # noqa: E402
    get_model,
    sarosi_fast_start,
    sarosi_fit_at_a3,
    sarosi_gauss_newton,
    sarosi_variable_projection_start,
    solve,
)
from pamid.engine import statistics as fit_statistics  # noqa: E402

SAROSI = get_model("sarosi")
# Without its written-out kernels: solve() runs optimistix's Gauss–Newton (the previous
# default), statistics() the Jacobian, QR and SVD per lane.
SAROSI_GENERIC = dataclasses.replace(SAROSI, written_out=False)
# The variable-projection start's grid in s = a3·κ_span (pamid/_solvers/_variable_projection.py).
VP_GRID = np.concatenate([-np.geomspace(30.0, 0.05, 20), np.geomspace(0.05, 3.0, 4)])
# Lanes per compiled call of the Sárosi kernels on the CPU (benchmarks/README.md, "Figures
# that used to live in docstrings", (c)).
CPU_CHUNK_LANES = 512


def timeit(fn, repeats):
    fn()
    walls = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t0)
    return statistics.median(walls)


@jax.jit
def grid_scan(x, y, w):
    p, k = x

    def one(p, k, y, w):
        span = jnp.max(jnp.where(w > 0, jnp.abs(k), 0.0))
        grid = VP_GRID / span
        return jax.vmap(lambda a: sarosi_fit_at_a3(a, p, k, y, w, accurate=False)[1])(grid)

    return jax.vmap(one)(p, k, y, w)


@jax.jit
def final_qr(a3, x, y, w):
    p, k = x
    return jax.vmap(lambda a, p, k, y, w: sarosi_fit_at_a3(a, p, k, y, w)[0])(a3, p, k, y, w)


@jax.jit
def batched_qr(a):
    return jnp.linalg.qr(a)


def _resid_jac(theta, p, k, y, w):
    a1, a2, a3, a4, a5, a6 = (theta[:, i : i + 1] for i in range(6))
    e = jnp.exp(a3 * k)
    r = jnp.sqrt(w) * ((a1 * p + a2) * e + a4 * k * p + a5 * p + a6 - y)
    jac = jnp.sqrt(w)[..., None] * jnp.stack(
        [p * e, e, (a1 * p + a2) * k * e, k * p, p, jnp.ones_like(p)], axis=-1
    )
    return r, jac


@jax.jit
def handwritten_gn_jax(theta, x, y, w):
    """6 Gauss–Newton steps, normal equations with column scaling, batched (yardstick)."""
    p, k = x
    for _ in range(6):
        r, jac = _resid_jac(theta, p, k, y, w)
        jtj = jnp.einsum("mni,mnj->mij", jac, jac)
        jtr = jnp.einsum("mni,mn->mi", jac, r)
        d = jnp.sqrt(jnp.diagonal(jtj, axis1=1, axis2=2))
        step = jnp.linalg.solve(jtj / (d[:, :, None] * d[:, None, :]), (jtr / d)[..., None])
        theta = theta - step[..., 0] / d
    return theta


def handwritten_gn_numpy(theta, p, k, y, w):
    theta = theta.copy()
    sw = np.sqrt(w)
    for _ in range(6):
        a1, a2, a3, a4, a5, a6 = (theta[:, i : i + 1] for i in range(6))
        e = np.exp(a3 * k)
        r = sw * ((a1 * p + a2) * e + a4 * k * p + a5 * p + a6 - y)
        jac = sw[..., None] * np.stack(
            [p * e, e, (a1 * p + a2) * k * e, k * p, p, np.ones_like(p)], axis=-1
        )
        jtj = np.einsum("mni,mnj->mij", jac, jac)
        jtr = np.einsum("mni,mn->mi", jac, r)
        d = np.sqrt(np.diagonal(jtj, axis1=1, axis2=2))
        step = np.linalg.solve(jtj / (d[:, :, None] * d[:, None, :]), (jtr / d)[..., None])
        theta = theta - step[..., 0] / d
    return theta


def cores_and_statistics(n, rep):
    """The solve on one thread per core and on one; a chunk by gather and by slice; the
    written-out Sárosi statistics and the generic ones."""
    data = fit_batch.make_data(n)[2]
    devices = jax.local_devices()
    print(f"\nN = {n}: chunks, threads and statistics ({len(devices)} device(s): {devices})")
    t_cores = timeit(lambda: solve(SAROSI, data), rep)
    if len(devices) > 1:
        print(f"  solve, sharded over {len(devices)} devices: {fit_batch.fmt_s(t_cores)}")
    # pamid feeds a CPU device from one thread per core this thread may use
    # (docs/devices.md): held to one core, it feeds it from one.
    cores = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(cores)})
    try:
        with pamid.use_devices(devices[:1]):
            t_one = timeit(lambda: solve(SAROSI, data), rep)
    finally:
        os.sched_setaffinity(0, cores)
    with pamid.use_devices(devices[:1]):
        t_threads = timeit(lambda: solve(SAROSI, data), rep)
    print(f"  solve on one device, one thread per core ({len(cores)}): "
          f"{fit_batch.fmt_s(t_threads)}; one thread: {fit_batch.fmt_s(t_one)}")
    chunk = CPU_CHUNK_LANES
    parts = (data.x, data.y, data.w)
    idx = np.arange(chunk)
    t_gather = timeit(lambda: jax.block_until_ready(jax.tree.map(lambda a: a[idx], parts)), rep)
    t_slice = timeit(
        lambda: jax.block_until_ready(jax.tree.map(lambda a: a[:chunk], parts)), rep
    )
    part = jax.tree.map(lambda a: a[:chunk], parts)
    t_call = timeit(lambda: jax.block_until_ready(sarosi_gauss_newton(*part)), rep)
    print(f"  one chunk of {chunk} lanes: gathered {fit_batch.fmt_s(t_gather)}, sliced "
          f"{fit_batch.fmt_s(t_slice)}; its solve {fit_batch.fmt_s(t_call)}")
    theta = solve(SAROSI, data)[0]
    fast = fit_statistics(SAROSI, theta, data)
    generic = fit_statistics(SAROSI_GENERIC, theta, data)
    t_fast = timeit(lambda: fit_statistics(SAROSI, theta, data), rep)
    t_generic = timeit(lambda: fit_statistics(SAROSI_GENERIC, theta, data), rep)
    inv_diff = np.max(np.abs(np.asarray(fast[1]) - np.asarray(generic[1]))
                      / np.abs(np.asarray(generic[1])))
    print(f"  statistics: from sums {fit_batch.fmt_s(t_fast)}, Jacobian/QR/SVD per lane "
          f"{fit_batch.fmt_s(t_generic)}; (JᵀJ)⁻¹ equal to {inv_diff:.1e}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument(
        "--bench-sizes",
        type=int,
        nargs="*",
        default=[500, 1000, 2000],
        help="N for the load_bench/bench_to_fit_data scaling check",
    )
    parser.add_argument("--cores-n", type=int, default=10000,
                        help="N of the chunks/threads/statistics section (0: skip it)")
    parser.add_argument("--only-cores", action="store_true", help="run that section alone")
    args = parser.parse_args(argv)
    n, rep = args.n, args.repeats
    if args.only_cores:
        cores_and_statistics(args.cores_n, rep)
        return 0
    _, groups, data, _, _ = fit_batch.make_data(n)
    x, y, w = data.x, data.y, data.w
    rows = []

    def add(label, seconds):
        rows.append((label, seconds))
        print(f"  {label}: {fit_batch.fmt_s(seconds)}", flush=True)

    print(f"N = {n}, {int(np.asarray(w).sum(axis=1).max())} samples per muscle", flush=True)
    add(
        "solve(gauss-newton) total, default (written-out GN)",
        timeit(lambda: solve(SAROSI, data), rep),
    )
    add(
        "  start alone (subsample + coarse scan + refinement)",
        timeit(lambda: jax.block_until_ready(sarosi_fast_start(x, y, w)), rep),
    )
    add(
        "    start on every sample (no subsample)",
        timeit(lambda: jax.block_until_ready(sarosi_fast_start(x, y, w, n_sub=y.shape[1])),
               rep),
    )
    add(
        "    scan alone (no refinement)",
        timeit(lambda: jax.block_until_ready(sarosi_fast_start(x, y, w, n_refine=0)), rep),
    )
    start = sarosi_fast_start(x, y, w)
    add(
        "  iterations from that start",
        timeit(lambda: jax.block_until_ready(sarosi_gauss_newton(x, y, w, start)), rep),
    )
    steps = np.asarray(sarosi_gauss_newton(x, y, w, start)[2])
    print(f"    (passes over the data: max {steps.max()}, median {np.median(steps):g})")
    # One more pass: two iterations from the start less one (the second is a full pass:
    # no lane's first step is below the tolerance), the step's 6×6 solve included.
    two, one = (timeit(lambda k=k: jax.block_until_ready(
        sarosi_gauss_newton(x, y, w, start, max_steps=k)), rep) for k in (2, 1))
    add("    one full pass over the samples (22 sums + 1 maximum), and its step", two - one)
    add(
        "previous default: VP start + optimistix GN",
        timeit(
            lambda: solve(SAROSI_GENERIC, data,
                          theta0=sarosi_variable_projection_start(x, y, w)),
            rep,
        ),
    )
    add(
        "  VP start (grid 24 + 6 refinements + QR)",
        timeit(lambda: jax.block_until_ready(sarosi_variable_projection_start(x, y, w)), rep),
    )
    add(
        "    grid scan alone (24 normal-equation solves)",
        timeit(lambda: jax.block_until_ready(grid_scan(x, y, w)), rep),
    )
    theta0 = sarosi_variable_projection_start(x, y, w)
    add(
        "    final accurate QR solve alone",
        timeit(lambda: jax.block_until_ready(final_qr(theta0[:, 2], x, y, w)), rep),
    )
    add(
        "  Gauss-Newton (optimistix) from the VP start",
        timeit(lambda: solve(SAROSI_GENERIC, data, theta0=theta0), rep),
    )
    a = jnp.asarray(np.random.default_rng(0).standard_normal((n, y.shape[1], 6)))
    add(
        f"  one batched jnp.linalg.qr of ({n}, {y.shape[1]}, 6)",
        timeit(lambda: jax.block_until_ready(batched_qr(a)), rep),
    )
    add(
        "yardstick: hand-written JAX GN, 6 steps, from VP start",
        timeit(lambda: jax.block_until_ready(handwritten_gn_jax(theta0, x, y, w)), rep),
    )
    th_np0 = np.asarray(theta0)
    p_np, k_np, y_np, w_np = (np.asarray(v) for v in (*x, y, w))
    add(
        "yardstick: hand-written NumPy GN, 6 steps, from VP start",
        timeit(lambda: handwritten_gn_numpy(th_np0, p_np, k_np, y_np, w_np), rep),
    )
    ref = solve(SAROSI, data)[0]
    th_j = np.asarray(handwritten_gn_jax(theta0, x, y, w))
    th_n = handwritten_gn_numpy(th_np0, p_np, k_np, y_np, w_np)
    rel_j = np.max(np.abs(th_j - ref) / np.abs(ref))
    rel_n = np.max(np.abs(th_n - ref) / np.abs(ref))
    print(f"  (yardstick vs pamid optimum: max rel diff JAX {rel_j:.1e}, NumPy {rel_n:.1e})")

    if args.bench_sizes:
        print("\nload_bench + bench_to_fit_data scaling (CSV written by the virtual bench)")
        with tempfile.TemporaryDirectory() as tmp:
            for m in args.bench_sizes:
                frame = fit_batch.make_data(m)[0]
                path = Path(tmp) / f"b{m}.csv"
                frame.to_csv(path, index=False)
                t0 = time.perf_counter()
                bench = pamid.load_bench(path)
                t1 = time.perf_counter()
                pamid.bench_to_fit_data(bench)
                t2 = time.perf_counter()
                print(
                    f"  N={m}: load_bench {fit_batch.fmt_s(t1 - t0)}, "
                    f"bench_to_fit_data {fit_batch.fmt_s(t2 - t1)}",
                    flush=True,
                )
    if args.cores_n:
        cores_and_statistics(args.cores_n, rep)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
