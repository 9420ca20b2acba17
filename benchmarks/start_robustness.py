"""How the settings of the Sárosi solver's start (``pamid/_solvers/_sarosi.py``) trade speed
against reaching the optimum, on synthetic muscles harder than the benchmark's.

    .venv/bin/python benchmarks/start_robustness.py [--muscles 512]

Data sets (virtual bench, Sárosi's protocol, ``--muscles`` each): the benchmark's (Table 3-1
± 3 %), constants ± 30 %, a3 drawn so that s = a3·κ_max lies in (−25, −1) (a steep
exponential) or in (−3, 2) (nearly linear: the exponential term is hard to tell from
a4·κ·p + a5·p + a6, and the optimum is ill-determined), load-cell noise 20 N, and a ±3 N/bar
hysteresis loop. The reference for each muscle: Gauss–Newton from a dense start (52 grid
points over all samples, 10 refinements). For each start setting: the time of start + solve
for the benchmark's muscles (median of warm calls), and per data set the muscles that end
with a higher SSE than the reference (relative 1e-9), the muscles the reference fits that
are not converged, and the median / largest number of passes. Last, what one muscle that
runs out of passes costs a batch of 1000 regular ones.
"""

from __future__ import annotations

import argparse
import inspect
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

import pamid
from pamid import FitData
from pamid.engine import get_model, sarosi_fast_start, sarosi_gauss_newton, solve

# The start's default settings: the defaults of sarosi_fast_start.
START_GRID, START_SAMPLES, START_REFINE = (
    inspect.signature(sarosi_fast_start).parameters[name].default
    for name in ("grid", "n_sub", "n_refine"))
TABLE_3_1 = np.asarray(pamid.sarosi.table_3_1().to_vector(), dtype=float)
DENSE_GRID = tuple(
    float(s) for s in np.concatenate([-np.geomspace(60.0, 0.02, 40), np.geomspace(0.02, 6.0, 12)])
)


def dataset(seed, n, spread, noise_N, hysteresis=0.0, s_range=None):
    k_theta, k_noise, k_a3 = jax.random.split(jax.random.key(seed), 3)
    z = np.asarray(jax.random.normal(k_theta, (n, 6)))
    theta = TABLE_3_1 * (1 + spread * z)
    protocol = pamid.SarosiProtocol(
        min_force_N=10.0, noise_sd_N=noise_N, hysteresis_N_per_bar=hysteresis
    )
    if s_range is not None:
        s = jax.random.uniform(k_a3, (n,), minval=s_range[0], maxval=s_range[1])
        theta[:, 2] = np.asarray(s) / protocol.kappa_max_pct
    frame = pamid.simulate_sarosi_bench(k_noise, pamid.Sarosi.from_vector(theta), protocol)
    groups = [
        ((f["pressure_kPa"].to_numpy() / 100.0, f["contraction_pct"].to_numpy()),
         f["force_N"].to_numpy())
        for _, f in frame.groupby("muscle", sort=False)
    ]
    return pamid.pack_muscles(groups)


def sse(theta, data):
    (p, k), y, w = data.x, data.y, data.w
    a1, a2, a3, a4, a5, a6 = (jnp.asarray(theta)[:, i : i + 1] for i in range(6))
    r = (a1 * p + a2) * jnp.exp(a3 * k) + a4 * k * p + a5 * p + a6 - y
    return np.asarray(jnp.sum(w * r * r, -1))


def grid(n_neg, n_pos):
    return tuple(
        float(s)
        for s in np.concatenate([-np.geomspace(30.0, 0.05, n_neg), np.geomspace(0.05, 3.0, n_pos)])
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--muscles", type=int, default=512, help="muscles per data set (512)")
    args = ap.parse_args(argv)
    n = args.muscles
    sets = {
        "benchmark": dataset(1, n, 0.03, 2.0),
        "±30 %": dataset(2, n, 0.3, 2.0),
        "s in (−25, −1)": dataset(3, n, 0.1, 2.0, s_range=(-25, -1)),
        "s in (−3, 2)": dataset(4, n, 0.1, 2.0, s_range=(-3, 2)),
        "noise 20 N": dataset(5, n, 0.1, 20.0),
        "hysteresis ±3 N/bar": dataset(6, n, 0.1, 2.0, hysteresis=3.0),
    }
    reference = {}
    for name, d in sets.items():
        start = sarosi_fast_start(d.x, d.y, d.w, grid=DENSE_GRID, n_sub=400, n_refine=10)
        theta, ok, _ = sarosi_gauss_newton(d.x, d.y, d.w, start)
        reference[name] = (sse(theta, d), np.asarray(ok))
        print(f"reference, {name}: {np.mean(ok):.1%} converged", flush=True)

    default = (START_GRID, START_SAMPLES, START_REFINE)
    settings = {
        f"default: grid {len(START_GRID)}, {START_SAMPLES} samples, "
        f"{START_REFINE} refinements": default,
        "grid 15, 128 samples, 4 refinements": (START_GRID, 128, 4),
        "grid 15, 32 samples, 4 refinements": (START_GRID, 32, 4),
        "grid 12, 64 samples, 4 refinements": (grid(9, 3), 64, 4),
        "grid 15, 64 samples, 2 refinements": (START_GRID, 64, 2),
    }
    print(f"\n{n} muscles per data set; cells: worse SSE / not converged / passes median, max")
    names = list(sets)
    header = ["start setting", "time"] + names
    rows = []
    for label, (g, n_sub, n_refine) in settings.items():
        fit = jax.jit(
            lambda x, y, w, g=g, n_sub=n_sub, n_refine=n_refine: sarosi_gauss_newton(
                x, y, w, sarosi_fast_start(x, y, w, grid=g, n_sub=n_sub, n_refine=n_refine)
            )
        )
        bench = sets["benchmark"]
        jax.block_until_ready(fit(bench.x, bench.y, bench.w))
        walls = []
        for _ in range(9):
            t0 = time.perf_counter()
            jax.block_until_ready(fit(bench.x, bench.y, bench.w))
            walls.append(time.perf_counter() - t0)
        row = [label, f"{1e3 * statistics.median(walls):.2f} ms"]
        for name in names:
            d = sets[name]
            theta, ok, steps = (np.asarray(a) for a in fit(d.x, d.y, d.w))
            ref_sse, ref_ok = reference[name]
            worse = int(np.sum(sse(theta, d) > ref_sse * (1 + 1e-9) + 1e-12))
            lost = int(np.sum(~ok & ref_ok))
            row.append(f"{worse} / {lost} / {np.median(steps):.0f}, {steps.max()}")
        rows.append(row)
        print(" | ".join(row), flush=True)
    widths = [max(len(str(r[i])) for r in [header] + rows) for i in range(len(header))]
    print()
    for r in [header] + rows:
        print("  ".join(str(c).ljust(w) for c, w in zip(r, widths)))
    straggler_cost(sets["s in (−3, 2)"])
    return 0


def straggler_cost(hard):
    """What one muscle that runs out of passes costs a batch: 1000 benchmark muscles alone,
    and with one such muscle added (``solve``, default settings, median of 5 warm calls)."""
    sarosi = get_model("sarosi")
    _, ok, steps = (np.asarray(a) for a in sarosi_gauss_newton(hard.x, hard.y, hard.w))
    slow = np.flatnonzero(~ok & (steps == steps.max()))
    if slow.size == 0:
        print("\nno muscle of the hard set ran out of passes")
        return
    regular = dataset(7, 1000, 0.03, 2.0)
    one = slow[:1]
    mixed = FitData(*(
        jax.tree.map(lambda a, b: np.concatenate([np.asarray(a), np.asarray(b)[one]]), r, h)
        for r, h in zip(regular, hard)
    ))
    print("\nwhat one muscle that runs out of passes costs a batch (solve, median of 5):")
    for label, data in (("1000 benchmark muscles", regular), ("the same + 1 such muscle", mixed)):
        solve(sarosi, data)
        walls = []
        for _ in range(5):
            t0 = time.perf_counter()
            _, ok, steps = solve(sarosi, data)
            walls.append(time.perf_counter() - t0)
        print(f"  {label}: {1e3 * statistics.median(walls):.1f} ms, "
              f"{int(ok.sum())}/{ok.size} converged, largest number of passes {steps.max()}")


if __name__ == "__main__":
    raise SystemExit(main())
