"""Sampling many muscles: a loop of emcee samplers against pamid's stacked ensembles.

    .venv/bin/python benchmarks/mcmc_batch.py            # M = 1, 10, 100, 1000
    .venv/bin/python benchmarks/mcmc_batch.py --quick    # M = 1, 10, 100, fewer steps
    .venv/bin/python benchmarks/mcmc_batch.py --json out.json

What is measured:

1. Data. M muscles, constants = Sárosi Table 3-1 × (1 + 0.03·normal), Sárosi's protocol
   on the virtual bench (300 samples per muscle), fixed keys. Walkers (W = 32 per muscle)
   start in pamid's ball around each least-squares optimum; every sampler runs the same
   moves (80% differential evolution, 20% stretch) on the same posterior, so the chains
   mix alike and time per step is the comparison.
2. One log-probability call for 16 walkers of one muscle (the size emcee asks for with
   vectorize=True): NumPy, jitted JAX (vmap over walkers) with the NumPy↔JAX conversions
   emcee's call needs, and the jitted JAX call alone. Median of 2000 calls.
3. Time per step of all M ensembles, median of 3 repeats after a warm-up:
   - ``emcee+jax``: a loop of M ``emcee.EnsembleSampler(vectorize=True)``, log-probability
     = the jitted JAX function (what ``fit_mcmc(sampler="emcee")`` runs);
   - ``emcee+numpy``: the same loop with the NumPy log-probability;
   - ``stacked``: pamid's ensembles of all M muscles advanced by one jitted call per
     chunk of steps (``lax.scan``), every proposal of every muscle in one ``vmap``-ped
     log-probability evaluation (what ``fit_mcmc(sampler="stacked")`` runs).
   Compilation (the first call) is reported apart. emcee loops over more than
   ``--emcee-max`` muscles are timed on ``--emcee-max`` muscles and scaled linearly
   (marked ``*``): the loop's cost is per muscle.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_compilation_cache", False)  # compile time is measured

import emcee  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import pamid  # noqa: E402
from pamid import engine  # noqa: E402
from pamid.io import write_text_atomic  # noqa: E402

SAROSI = engine.get_model("sarosi")

PROTOCOL = pamid.SarosiProtocol(min_force_N=10.0)
TABLE_3_1 = np.asarray(pamid.sarosi.table_3_1().to_vector(), dtype=float)
W = 32
THIN = 10


def make_data(m, seed=0):
    rng = np.random.default_rng(seed)
    theta = TABLE_3_1 * (1 + 0.03 * rng.normal(size=(m, 6)))
    frame = pamid.simulate_sarosi_bench(jax.random.key(seed), pamid.Sarosi.from_vector(theta),
                                        PROTOCOL)
    groups = [((g["pressure_kPa"].to_numpy() / 100.0, g["contraction_pct"].to_numpy()),
               g["force_N"].to_numpy()) for _, g in frame.groupby("muscle", sort=True)]
    return pamid.pack_muscles(groups)


def start_ball(data, prior, log_prob):
    ls = pamid.fit_least_squares(data)
    return engine.initial_walkers(jax.random.key(1), ls, prior, log_prob, data, W, 0.1)


def time_call(fn, n=2000):
    fn()
    ts = []
    for _ in range(n):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return statistics.median(ts)


def per_call(data, prior):
    """One log-probability call, 16 walkers, one muscle."""
    start = start_ball(pamid.pack_muscles([((np.asarray(data.x[0][0]),
                                              np.asarray(data.x[1][0])),
                                             np.asarray(data.y[0]))]),
                       prior, engine.walker_log_prob(SAROSI, prior, "normal", 4.0))[0, :16]
    x = tuple(np.asarray(a[0]) for a in data.x)
    y, w = np.asarray(data.y[0]), np.asarray(data.w[0])
    f_np = engine.numpy_log_prob("sarosi", prior)
    f_jax = engine.ensemble_log_prob(SAROSI, prior, "normal", 4.0)
    xj, yj, wj = tuple(jnp.asarray(a) for a in x), jnp.asarray(y), jnp.asarray(w)
    zj = jnp.asarray(start)
    np.testing.assert_allclose(f_np(start, x, y, w), np.asarray(f_jax(zj, xj, yj, wj)),
                               rtol=1e-10)
    return {
        "numpy_us": 1e6 * time_call(lambda: f_np(start, x, y, w)),
        "jax_with_conversion_us": 1e6 * time_call(
            lambda: np.asarray(f_jax(jnp.asarray(start), xj, yj, wj))),
        "jax_call_only_us": 1e6 * time_call(lambda: f_jax(zj, xj, yj, wj).block_until_ready()),
    }


def emcee_loop(data, start, prior, kind, n_steps, repeats):
    """Seconds per step of a loop of emcee samplers (kind: "jax" or "numpy")."""
    m = data.n_muscles
    moves = [(emcee.moves.DEMove(), engine.DE_FRACTION),
             (emcee.moves.StretchMove(), 1 - engine.DE_FRACTION)]
    if kind == "jax":
        f = engine.ensemble_log_prob(SAROSI, prior, "normal", 4.0)
        fns = []
        for i in range(m):
            xi = tuple(a[i] for a in data.x)
            fns.append(lambda z, xi=xi, i=i: np.asarray(f(jnp.asarray(z), xi, data.y[i],
                                                             data.w[i])))
    else:
        f = engine.numpy_log_prob("sarosi", prior)
        fns = []
        for i in range(m):
            xi = tuple(np.asarray(a[i]) for a in data.x)
            yi, wi = np.asarray(data.y[i]), np.asarray(data.w[i])
            fns.append(lambda z, xi=xi, yi=yi, wi=wi: f(z, xi, yi, wi))
    samplers = [emcee.EnsembleSampler(W, 7, fn, vectorize=True, moves=moves) for fn in fns]
    states = [np.asarray(start[i]) for i in range(m)]
    t = time.perf_counter()  # warm-up: compilation for both call shapes (32 and 16)
    for i, s in enumerate(samplers):
        states[i] = s.run_mcmc(states[i], 1, thin_by=THIN)
    first = time.perf_counter() - t
    runs = []
    for _ in range(repeats):
        t = time.perf_counter()
        for i, s in enumerate(samplers):
            states[i] = s.run_mcmc(states[i], n_steps // THIN, thin_by=THIN)
        runs.append((time.perf_counter() - t) / n_steps)
    return first, statistics.median(runs)


def stacked(data, start, prior, n_steps, repeats):
    log_prob = engine.walker_log_prob(SAROSI, prior, "normal", 4.0)
    t = time.perf_counter()
    backend = engine.StackedSampler(log_prob, jax.random.key(2), start, data,
                                    engine.DE_FRACTION)
    backend.advance(200, THIN)
    first = time.perf_counter() - t
    runs = []
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(n_steps // 200):
            backend.advance(200, THIN)
        runs.append((time.perf_counter() - t) / n_steps)
    return first, statistics.median(runs)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", help="write every number to this JSON file")
    ap.add_argument("--emcee-max", type=int, default=100)
    args = ap.parse_args(argv)
    sizes = (1, 10, 100) if args.quick else (1, 10, 100, 1000)
    repeats = 2 if args.quick else 3
    prior = pamid.default_prior(SAROSI)

    env = {
        "date": datetime.datetime.now().isoformat(timespec="seconds"),
        "python": platform.python_version(), "jax": jax.__version__,
        "emcee": emcee.__version__, "numpy": np.__version__,
        "cpu_count": os.cpu_count(), "load_average_1min": os.getloadavg()[0],
        "backend": jax.default_backend(), "walkers": W, "samples_per_muscle": 300,
    }
    print(f"pamid MCMC batch benchmark — {env['date']}, JAX {env['jax']} "
          f"({env['backend']}), emcee {env['emcee']}, {env['cpu_count']} CPUs, "
          f"load {env['load_average_1min']:.1f}")

    data1 = make_data(1)
    calls = per_call(data1, prior)
    print("\nOne log-probability call, 16 walkers × 300 samples (median of 2000):")
    print(f"  NumPy                           {calls['numpy_us']:8.1f} µs")
    print(f"  JAX jit(vmap), with conversions {calls['jax_with_conversion_us']:8.1f} µs")
    print(f"  JAX jit(vmap), call alone       {calls['jax_call_only_us']:8.1f} µs")

    rows = []
    print(f"\nTime per step of all M ensembles ({W} walkers each; ms per step, and µs per "
          "muscle-step):")
    print(f"  {'M':>5}  {'emcee+jax':>16}  {'emcee+numpy':>16}  {'stacked':>16}  "
          f"{'jax/stacked':>11}  {'numpy/stacked':>13}  compile stacked / emcee+jax")
    for m in sizes:
        data = make_data(m, seed=m)
        start = start_ball(data, prior, engine.walker_log_prob(SAROSI, prior, "normal", 4.0))
        n_steps = {1: 2000, 10: 1000}.get(m, 200)
        if args.quick:
            n_steps = max(200, n_steps // 2)
        m_e = min(m, args.emcee_max)
        scale = m / m_e
        sub = pamid.pack_muscles([((np.asarray(data.x[0][i]), np.asarray(data.x[1][i])),
                                   np.asarray(data.y[i])) for i in range(m_e)])
        first_j, step_j = emcee_loop(sub, start[:m_e], prior, "jax", n_steps, repeats)
        _, step_n = emcee_loop(sub, start[:m_e], prior, "numpy", n_steps, repeats)
        first_s, step_s = stacked(data, start, prior, n_steps, repeats)
        step_j, step_n = step_j * scale, step_n * scale
        mark = "*" if scale > 1 else " "
        rows.append({"M": m, "steps_timed": n_steps, "emcee_muscles_timed": m_e,
                     "emcee_jax_s_per_step": step_j, "emcee_numpy_s_per_step": step_n,
                     "stacked_s_per_step": step_s, "stacked_first_call_s": first_s,
                     "emcee_jax_first_call_s": first_j})
        print(f"  {m:5d}  {1e3 * step_j:7.2f}{mark}({1e6 * step_j / m:5.0f})  "
              f"{1e3 * step_n:7.2f}{mark}({1e6 * step_n / m:5.0f})  "
              f"{1e3 * step_s:7.2f} ({1e6 * step_s / m:5.1f})  {step_j / step_s:11.1f}  "
              f"{step_n / step_s:13.1f}  {first_s:5.1f} s / {first_j:4.1f} s")
    print("\n* emcee loop timed on the first --emcee-max muscles and scaled linearly.")
    fastest = "stacked" if all(r["stacked_s_per_step"] < min(r["emcee_jax_s_per_step"],
                                                             r["emcee_numpy_s_per_step"])
                               for r in rows) else "mixed"
    print(f"Faster at every M: {fastest}.  fit_mcmc(sampler='auto') uses "
          f"'{engine.AUTO_SAMPLER}'.")
    if args.json:
        write_text_atomic(args.json, json.dumps({"environment": env, "per_call": calls,
                                                 "per_step": rows}, indent=2) + "\n")
        print(f"numbers written to {Path(args.json)}")


if __name__ == "__main__":
    main()
