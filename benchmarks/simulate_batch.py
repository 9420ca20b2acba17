"""Batched simulation benchmark: pamid's simulators (JAX, one vmapped call) against SciPy.

    .venv/bin/python benchmarks/simulate_batch.py            # full run (≈ 3–4 min, 2 cores)
    .venv/bin/python benchmarks/simulate_batch.py --quick    # smaller batches, fewer repeats
    .venv/bin/python benchmarks/simulate_batch.py --json out.json

Needs diffrax, which pamid does not (the ``benchmarks`` extra: ``.venv/bin/pip install -e
'.[benchmarks]'``).

What is measured
----------------
1. Integrator choice for the lifting mass (Sárosi eq. 2.2, :func:`pamid.simulate_lifting_mass`).
   Reference: ``solve_ivp(method="DOP853", rtol=1e-10, atol=1e-12)`` per run. Cases: the
   Fig. 3-6 run (400 kPa, 50 kg, x0 = 50 mm, ζ of pamid's default loop, 5 s at 1 kHz), and
   a batch of runs with pressures 300–500 kPa, loads 30–70 kg, released at rest within
   ±15 mm of the static solution. Candidates, each
   at the cheapest setting that meets the same accuracy target (max. |s − s_ref| ≤
   ``ACCURACY_M``): fixed-step RK4 in ``lax.scan`` (1 step per 1 ms sample), diffrax Tsit5
   with a PIDController, diffrax Kvaerno5 (implicit) with a PIDController; all with output
   on the 1 kHz grid. Compile time (first call) apart from the run (median of warm calls).
2. Decays of the linear oscillator (:func:`pamid.simulate_oscillator`):
   N = 1, 1000, 10 000 decays of 4 s with output at 1 kHz (4001 samples), random ζ in
   [0.02, 0.2], f_n in [1, 4] Hz, J = 0.46 kg·m², release from 3°–9° at rest; the angle is
   kept (what an encoder gives). pamid batched — ``method="exact"`` (the default: the sampled
   closed form, exact to rounding) and ``method="rk4"`` (RK4 in scan, 1 step per sample) —
   against a ``solve_ivp`` loop whose method and tolerance are the cheapest found to reach
   pamid RK4's accuracy (the looser of pamid's two; both measured against the closed form).
   The loop is timed on the first ``--scipy-max`` decays and
   extrapolated linearly to N (marked ``*``). Target: 10 000 decays at least 100× faster
   than the loop.

Timing: wall clock; "first" = first call after ``jax.clear_caches()`` (tracing +
compilation + one run), "steady" = median of warm calls, results moved to NumPy inside the
timed call. The persistent compilation cache is off in this process.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_compilation_cache", False)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import pamid  # noqa: E402
from pamid import (  # noqa: E402
    DampedOscillator,
    LiftingMass,
    lifting_mass_equilibrium,
    oscillator_response,
    simulate_lifting_mass,
    simulate_oscillator,
)
from pamid.sarosi import default_zeta, lifting_mass_damping, lifting_mass_force  # noqa: E402

ACCURACY_M = 1e-9  # lifting mass: max |s − s_ref| every candidate must meet (0.01 mm encoder)
REF = {"method": "DOP853", "rtol": 1e-10, "atol": 1e-12}
TARGET_RATIO = 100.0
DECAY_SECONDS = 4.0
RATE_HZ = 1000.0


def clock(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def measure_jax(fn, repeats):
    jax.clear_caches()
    first, out = clock(fn)
    walls = []
    for _ in range(repeats):
        wall, out = clock(fn)
        walls.append(wall)
    return {"first_s": first, "steady_s": statistics.median(walls), "steady_min_s": min(walls)}, out


# --------------------------------------------------------------------------------------
# 1. Lifting mass: integrator choice
# --------------------------------------------------------------------------------------


def lifting_rhs_np(model_row):
    """NumPy right-hand side of eq. 2.2 for one run (same formulas as pamid's)."""
    a1, a2, a3, a4, a5, a6, p_kpa, mass, zeta, l0, g = model_row
    p = p_kpa / 100.0

    def rhs(t, y):
        s, v = y
        k = 100.0 * s / l0
        e = math.exp(a3 * k)
        force = max((a1 * p + a2) * e + a4 * k * p + a5 * p + a6, 0.0)
        stiff = -(100.0 / l0) * ((a1 * p + a2) * a3 * e + a4 * p)
        c = zeta * 2.0 * math.sqrt(max(stiff, 0.0) * mass)
        return [v, (force - c * v) / mass - g]

    return rhs


def lifting_rows(model, n):
    th = np.broadcast_to(np.asarray(model.muscle.to_vector()), (n, 6))
    extra = [
        np.broadcast_to(np.asarray(x, float), (n,))
        for x in (model.pressure_kPa, model.mass_kg, model.zeta, model.l0_m, model.gravity_m_per_s2)
    ]
    return np.column_stack([th, *extra])


def lifting_reference(model, x0, ts, n):
    rows = lifting_rows(model, n)
    x0 = np.broadcast_to(np.asarray(x0, float), (n,))
    out = np.empty((n, len(ts)))
    for i in range(n):
        sol = solve_ivp(lifting_rhs_np(rows[i]), (ts[0], ts[-1]), [x0[i], 0.0], t_eval=ts, **REF)
        out[i] = sol.y[0]
    return out


def lifting_rhs(model, y):
    """Eq. 2.2 for one run, state y = (s, ds/dt): pamid's spring force and damping."""
    s, v = y[0], y[1]
    force = lifting_mass_force(model, s) - lifting_mass_damping(model, s) * v
    return jnp.stack([v, force / model.mass_kg - model.gravity_m_per_s2])


def _diffrax():
    """diffrax, which only section 1 uses: it is in the ``benchmarks`` extra, not a
    dependency of pamid (``.venv/bin/pip install -e '.[benchmarks]'``); ``benchmarks/run.py``
    imports this module for :func:`decay_params` without it."""
    try:
        import diffrax
    except ImportError:
        raise SystemExit("benchmarks/simulate_batch.py needs diffrax: "
                         ".venv/bin/pip install -e '.[benchmarks]'") from None
    return diffrax


def diffrax_lifting(solver, rtol, atol, ts):
    diffrax = _diffrax()
    term = diffrax.ODETerm(lambda t, y, m: lifting_rhs(m, y))
    saveat = diffrax.SaveAt(ts=jnp.asarray(ts))
    controller = diffrax.PIDController(rtol=rtol, atol=atol)

    @jax.jit
    def run(model, x0):
        def one(m, s0):
            sol = diffrax.diffeqsolve(
                term,
                solver,
                ts[0],
                ts[-1],
                1e-3,
                jnp.stack([s0, 0.0]),
                args=m,
                saveat=saveat,
                stepsize_controller=controller,
                max_steps=200_000,
            )
            return sol.ys[:, 0], sol.stats["num_steps"]

        # One run per lane: the model's fields broadcast to the runs.
        runs = jax.tree.map(lambda a: jnp.broadcast_to(a, x0.shape), model)
        return jax.vmap(one)(runs, x0)

    return run


def section_lifting(quick, repeats):
    print("\n1. Lifting mass (Sárosi eq. 2.2): integrator choice at equal accuracy", flush=True)
    duration = 5.0
    ts = np.arange(int(duration * RATE_HZ) + 1) / RATE_HZ
    n_batch = 200 if quick else 1000
    n_check = 10 if quick else 20
    rng = np.random.default_rng(36)
    pressure = rng.uniform(300.0, 500.0, n_batch)
    mass = rng.uniform(30.0, 70.0, n_batch)
    zeta = np.array(default_zeta(pressure_kPa=jnp.asarray(pressure)))
    zeta[0], pressure[0], mass[0] = float(default_zeta()), 400.0, 50.0  # Fig. 3-6
    batch = LiftingMass(pressure_kPa=pressure, mass_kg=mass, zeta=zeta)
    # Released within ±15 mm of the static solution: the muscle stays taut. (Released far
    # above it, a light load can rise to where eq. 2.1 reaches 0 N and the clipped force has
    # a kink; every integrator drops to first order there, the reference included.)
    x0 = np.asarray(lifting_mass_equilibrium(batch)) + rng.uniform(-0.015, 0.015, n_batch)
    x0[0] = 0.050
    sub = LiftingMass(pressure_kPa=pressure[:n_check], mass_kg=mass[:n_check], zeta=zeta[:n_check])

    t0 = time.perf_counter()
    ref = lifting_reference(sub, x0[:n_check], ts, n_check)
    ref_s = (time.perf_counter() - t0) / n_check
    print(
        f"   reference DOP853 rtol 1e-10 atol 1e-12: {ref_s * 1e3:.1f} ms per run "
        f"(accuracy checked on the first {n_check} runs; run 0 is Fig. 3-6)"
    )

    results = {}

    # RK4 in lax.scan: the smallest number of substeps meeting the target.
    for substeps in (1, 2, 4):
        run = simulate_lifting_mass(sub, x0[:n_check], duration_s=duration, substeps=substeps)
        err = float(np.abs(np.asarray(run.contraction_m) - ref).max())
        if err <= ACCURACY_M:
            break
    timing, _ = measure_jax(
        lambda: np.asarray(
            simulate_lifting_mass(batch, x0, duration_s=duration, substeps=substeps).contraction_m
        ),
        repeats,
    )
    results["rk4_scan"] = {
        "setting": f"h = {1e3 / RATE_HZ / substeps:g} ms ({substeps} step/sample)",
        "max_error_m": err,
        "steps": int(round(duration * RATE_HZ)) * substeps,
        **timing,
    }

    diffrax = _diffrax()
    for name, solver in (
        ("diffrax_tsit5", diffrax.Tsit5()),
        ("diffrax_kvaerno5", diffrax.Kvaerno5()),
    ):
        chosen = None
        # Searched from near the answer (measured: Tsit5 1e-8, Kvaerno5 1e-10): every
        # candidate compiles afresh, and Kvaerno5 takes ~15 s to compile.
        rtols = (1e-7, 1e-8, 1e-9, 1e-10) if name == "diffrax_tsit5" else (1e-9, 1e-10, 1e-11)
        for rtol in rtols:
            atol = rtol * 1e-3  # s ≈ 0.05 m: atol scaled to the state
            run = diffrax_lifting(solver, rtol, atol, ts)
            ys, steps = run(sub, jnp.asarray(x0[:n_check]))
            err = float(np.abs(np.asarray(ys) - ref).max())
            if err <= ACCURACY_M:
                chosen = (rtol, atol, err, int(np.max(steps)))
                break
        if chosen is None:
            print(f"   {name}: did not reach {ACCURACY_M:g} m")
            continue
        rtol, atol, err, steps = chosen
        run = diffrax_lifting(solver, rtol, atol, ts)
        # The implicit solver is slow: timed on a fifth of the batch, scaled up (marked †).
        n_time = n_batch // 5 if name == "diffrax_kvaerno5" else n_batch
        part = LiftingMass(
            pressure_kPa=pressure[:n_time], mass_kg=mass[:n_time], zeta=zeta[:n_time]
        )
        timing, _ = measure_jax(
            lambda run=run, part=part: np.asarray(run(part, jnp.asarray(x0[:n_time]))[0]),
            max(1, repeats - 1),
        )
        timing["steady_s"] *= n_batch / n_time
        results[name] = {
            "setting": f"rtol {rtol:g}, atol {atol:g}",
            "max_error_m": err,
            "steps": steps,
            "timed_on": n_time,
            **timing,
        }

    loop_s = ref_s * n_batch
    print(
        f"\n   {n_batch} runs of {duration:g} s, output at {RATE_HZ:g} Hz "
        f"(accuracy target {ACCURACY_M:g} m against the reference):"
    )
    print(
        f"   {'integrator':<18} {'setting':<26} {'max error [m]':>13} {'steps':>6} "
        f"{'compile+1st [s]':>15} {'run [s]':>9}"
    )
    for name, r in results.items():
        mark = "†" if r.get("timed_on", n_batch) < n_batch else " "
        print(
            f"   {name:<18} {r['setting']:<26} {r['max_error_m']:>13.2e} {r['steps']:>6d} "
            f"{r['first_s']:>15.2f} {r['steady_s']:>9.3f}{mark}"
        )
    print(
        f"   {'solve_ivp loop*':<18} {'DOP853 rtol 1e-10':<26} {'(reference)':>13} {'':>6} "
        f"{'':>15} {loop_s:>9.2f}"
    )
    print(
        "   steps: per run, the largest in the batch (RK4: fixed). † timed on a fifth of the "
        "batch and scaled; compile+1st for that fifth. * per-run reference time × runs."
    )
    best = min(results, key=lambda k: results[k]["steady_s"])
    print(f"   fastest at equal accuracy: {best}")
    # The Fig. 3-6 run itself.
    fig = LiftingMass(pressure_kPa=400.0, mass_kg=50.0, zeta=default_zeta())
    run = simulate_lifting_mass(fig, 0.050, duration_s=duration)
    eq = float(lifting_mass_equilibrium(fig))
    print(
        f"   Fig. 3-6 run: s(5 s) = {float(run.contraction_m[-1]) * 1e3:.4f} mm, F = "
        f"{float(run.force_N[-1]):.2f} N; static solution {eq * 1e3:.4f} mm"
    )
    return {
        "n_runs": n_batch,
        "duration_s": duration,
        "accuracy_target_m": ACCURACY_M,
        "reference_ms_per_run": ref_s * 1e3,
        "candidates": results,
        "chosen": best,
        "solve_ivp_loop_s_extrapolated": loop_s,
    }


# --------------------------------------------------------------------------------------
# 2. Decays of the linear oscillator: batch against a loop
# --------------------------------------------------------------------------------------


def decay_params(n, seed=7):
    rng = np.random.default_rng(seed)
    zeta = rng.uniform(0.02, 0.2, n)
    fn = rng.uniform(1.0, 4.0, n)
    angle0 = np.deg2rad(rng.uniform(3.0, 9.0, n)) * rng.choice([-1.0, 1.0], n)
    return zeta, fn, angle0


def oscillator_np(zeta, fn, inertia=0.46):
    wn = 2 * math.pi * fn
    k, c = inertia * wn**2, 2 * zeta * inertia * wn

    def rhs(t, y):
        return [y[1], (-k * y[0] - c * y[1]) / inertia]

    return rhs


def scipy_decays(zeta, fn, angle0, ts, method, rtol, atol):
    out = np.empty((len(zeta), len(ts)))
    for i in range(len(zeta)):
        sol = solve_ivp(
            oscillator_np(zeta[i], fn[i]),
            (ts[0], ts[-1]),
            [angle0[i], 0.0],
            t_eval=ts,
            method=method,
            rtol=rtol,
            atol=atol,
        )
        out[i] = sol.y[0]
    return out


def section_decays(quick, repeats, scipy_max):
    print(
        "\n2. Decays of the linear oscillator: pamid batched against a solve_ivp loop", flush=True
    )
    ts = np.arange(int(DECAY_SECONDS * RATE_HZ) + 1) / RATE_HZ
    sizes = (1, 1000, 2000) if quick else (1, 1000, 10_000)
    inertia = 0.46

    # Accuracy of pamid RK4 and of the SciPy candidates, against the closed form.
    n_acc = 20
    z, f, a0 = decay_params(n_acc, seed=1)
    osc = DampedOscillator.from_modal(z, f, inertia)
    column = DampedOscillator.from_modal(z[:, None], f[:, None], inertia)  # (n, 1) fields
    exact = np.asarray(oscillator_response(column, a0[:, None], 0.0, ts)[0])
    rk4 = np.asarray(simulate_oscillator(osc, a0, duration_s=DECAY_SECONDS, method="rk4").angle_rad)
    err_exact = float(
        np.abs(
            np.asarray(simulate_oscillator(osc, a0, duration_s=DECAY_SECONDS).angle_rad) - exact
        ).max()
    )
    err_rk4 = float(np.abs(rk4 - exact).max())
    print(
        f"   pamid max error over {n_acc} decays: RK4 (1 step per 1 ms sample) {err_rk4:.2e} "
        f"rad, exact method {err_exact:.2e} rad"
    )
    candidates = []
    for method in ("DOP853", "RK45", "LSODA"):
        for rtol in (1e-6, 1e-7, 1e-8, 1e-9, 1e-10, 1e-11):
            atol = rtol * 1e-2
            t0 = time.perf_counter()
            y = scipy_decays(z[:5], f[:5], a0[:5], ts, method, rtol, atol)
            dt = (time.perf_counter() - t0) / 5
            err = float(np.abs(y - exact[:5]).max())
            if err <= err_rk4:
                candidates.append((dt, method, rtol, atol, err))
                break
    dt, method, rtol, atol, _ = min(candidates)
    y = scipy_decays(z, f, a0, ts, method, rtol, atol)
    err_scipy = float(np.abs(y - exact).max())
    print(
        "   solve_ivp settings reaching that accuracy (time per decay): "
        + "; ".join(f"{m} rtol {r:g}: {d * 1e3:.1f} ms" for d, m, r, _, _ in candidates)
    )
    print(f"   loop baseline: {method} rtol {rtol:g} atol {atol:g}, max error {err_scipy:.2e} rad")

    rows = []
    for n in sizes:
        z, f, a0 = decay_params(n)
        osc = DampedOscillator.from_modal(jnp.asarray(z), jnp.asarray(f), inertia)
        a0j = jnp.asarray(a0)
        t_rk4, _ = measure_jax(
            lambda osc=osc, a0j=a0j: np.asarray(
                simulate_oscillator(
                    osc, a0j, duration_s=DECAY_SECONDS, method="rk4", with_rate=False
                ).angle_rad
            ),
            repeats,
        )
        t_exact, _ = measure_jax(
            lambda osc=osc, a0j=a0j: np.asarray(
                simulate_oscillator(
                    osc, a0j, duration_s=DECAY_SECONDS, method="exact", with_rate=False
                ).angle_rad
            ),
            repeats,
        )
        m = min(n, scipy_max)
        t0 = time.perf_counter()
        scipy_decays(z[:m], f[:m], a0[:m], ts, method, rtol, atol)
        loop = (time.perf_counter() - t0) * n / m
        rows.append(
            {
                "n": n,
                "rk4": t_rk4,
                "exact": t_exact,
                "loop_s": loop,
                "loop_extrapolated": m < n,
                "loop_measured_on": m,
            }
        )
        print(
            f"   N = {n:>6}: pamid exact {t_exact['steady_s']:.3f} s, RK4 "
            f"{t_rk4['steady_s']:.3f} s, loop {loop:.2f} s{'*' if m < n else ''}",
            flush=True,
        )

    print(
        f"\n   {'N':>6} {'exact first':>11} {'exact run':>9} {'RK4 first':>9} {'RK4 run':>8} "
        f"{'solve_ivp loop':>14} {'loop/exact':>10} {'loop/RK4':>8}   (seconds)"
    )
    for r in rows:
        star = "*" if r["loop_extrapolated"] else " "
        print(
            f"   {r['n']:>6} {r['exact']['first_s']:>11.2f} {r['exact']['steady_s']:>9.4f} "
            f"{r['rk4']['first_s']:>9.2f} {r['rk4']['steady_s']:>8.4f} "
            f"{r['loop_s']:>13.2f}{star} {r['loop_s'] / r['exact']['steady_s']:>10.0f} "
            f"{r['loop_s'] / r['rk4']['steady_s']:>8.0f}"
        )
    print(f"   * loop timed on the first {scipy_max} decays and extrapolated linearly.")
    last = rows[-1]
    ratio = last["loop_s"] / last["exact"]["steady_s"]
    ratio_rk4 = last["loop_s"] / last["rk4"]["steady_s"]
    verdict = "MET" if ratio >= TARGET_RATIO else "NOT MET"
    print(
        f"   target: {last['n']} decays ≥ {TARGET_RATIO:g}× faster than the loop (steady "
        f"state): exact method {ratio:.0f}× — {verdict}; RK4 {ratio_rk4:.0f}×"
    )
    return {
        "accuracy_rk4_rad": err_rk4,
        "accuracy_exact_rad": err_exact,
        "accuracy_loop_rad": err_scipy,
        "ratio_rk4_at_largest_n": ratio_rk4,
        "loop": {"method": method, "rtol": rtol, "atol": atol},
        "scipy_candidates": [
            {"method": m, "rtol": r, "ms_per_decay": d * 1e3} for d, m, r, _, _ in candidates
        ],
        "rows": rows,
        "ratio_at_largest_n": ratio,
        "target_met": ratio >= TARGET_RATIO,
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="smaller batches, fewer repeats")
    parser.add_argument("--json", help="write every number to this JSON file")
    parser.add_argument(
        "--scipy-max",
        type=int,
        default=100,
        help="time the solve_ivp loop on at most this many decays (default 100)",
    )
    args = parser.parse_args(argv)
    repeats = 2 if args.quick else 3
    print(
        f"pamid {pamid.__version__}, jax {jax.__version__}, diffrax {_diffrax().__version__}, "
        f"scipy {scipy.__version__}, numpy {np.__version__}; {platform.processor() or 'cpu'}, "
        f"{os.cpu_count()} cores, {jax.devices()[0].platform}; "
        f"{datetime.datetime.now().isoformat(timespec='seconds')}"
    )
    t0 = time.perf_counter()
    out = {
        "lifting_mass": section_lifting(args.quick, repeats),
        "decays": section_decays(args.quick, repeats, args.scipy_max),
    }
    out["total_s"] = time.perf_counter() - t0
    print(f"\ntotal {out['total_s']:.0f} s")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2, default=float) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
