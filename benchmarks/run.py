"""Every benchmark in one table: pamid beside its reference, measured in the same run.

    .venv/bin/python benchmarks/run.py            # full: static fits N = 1 … 100,000, etc.
    .venv/bin/python benchmarks/run.py --quick    # small sizes, fewer repeats (a few minutes)
    .venv/bin/python benchmarks/run.py --json     # a JSON list of rows on stdout (the table
                                                  # and progress go to stderr)

Rows (pamid | reference):

- ``static fit``: ``pamid.fit_least_squares`` (Sárosi eq. 2.1, Wald intervals) on N
  virtual-bench muscles (``fit_batch.make_data``: Table 3-1 × (1 + 0.03·normal), Sárosi's
  protocol, 300 samples each) | a loop of ``scipy.optimize.least_squares`` (analytic
  Jacobian, lm, tolerances 1e-12) and, in a second row, a loop of ``curve_fit``, both from
  the Table 3-1 constants (``fit_batch.scipy_ls_loop`` / ``curve_fit_loop``). Above 10,000
  muscles the 10,000 simulated muscles are repeated (simulating is slower than fitting).
- ``cullinan fit``: ``pamid.fit_least_squares(..., "cullinan")`` (Cullinan eq. 3, A–E) on N
  muscles with the traditional-PAM constants × (1 + 0.03·normal) on the static bench grid
  of :func:`pamid.simulate_braided_pam_bench`, 2 N noise | a ``least_squares`` loop with the
  analytic Jacobian of eq. 3.
- ``decays exact`` / ``decays rk4`` (RK4 in the full run only): :func:`pamid.simulate_oscillator`
  on N decays of 4 s at 1 kHz (``simulate_batch.decay_params``) | a ``solve_ivp`` loop
  (DOP853, rtol 1e-8, atol 1e-10: the cheapest setting reaching RK4's accuracy, see
  simulate_batch.py).
- ``mcmc``: pamid's stacked ensembles (32 walkers per muscle, 80 % differential evolution,
  20 % stretch) | a loop of emcee samplers with the same moves and a plain NumPy
  log-probability. Besides time, samples per second and effective samples per second (the
  smallest ESS over the constants and σ, emcee's autocorrelation estimator on both).
- ``diagnose``: `pamid diagnose`'s first selection step on a 100-muscle file hiding a
  hysteresis loop (baseline + every candidate, on all data and on each held-out fold, every
  muscle: one batched call) | the same refits as a loop of ``least_squares`` (lm, analytic
  Jacobian); the whole diagnosis end to end is reported beside it.
- ``diagnose_aarl``: the same on the measured AARL 10 mm file (``../shared/data/
  aarl_festo10mm_isometric.csv``, 61,515 rows, 6 muscles; skipped with a line when absent;
  in the full run, and in ``--quick`` only when named by ``--only``): the first selection
  step | the SciPy loop on every muscle (``--quick``: 2, scaled), on the candidates it can
  reproduce by hand (those left out are named in the row); then
  ``pamid.diagnose(load_bench(path))`` in a process of its own, first call and warm, its
  peak RSS, what it selected and the RMSE before → after, against issue #16's targets
  (≤ 60 s, ≤ 4 GB).
- ``latency``: a lab's new one-muscle file (issue 29; ``latency.py`` has the whole study):
  `pamid fit`, `compare` and `diagnose` as commands, each with a compilation cache of its
  own, first on a file of one row count (empty cache: its time less the warm one is the
  row's "compile") and then on a new file of another row count in the same size class
  (the row's time) | the pandas + ``curve_fit`` script a user writes for the file
  (``baseline_scipy_wald.py``: three starts, Wald intervals), median of three runs. The
  "speedup" is below 1 where pamid takes longer. 600 rows (``--quick``), also 2,000 (full).

Method. Every (row, side, N) runs in its own subprocess, so that its peak memory
(``VmHWM``, see :func:`_peak_rss_mb`; imports and data included) is its own. pamid: "compile" =
first call − steady time (the persistent compilation cache is off), "pamid_s" = median of
warm calls with the results converted to NumPy. References larger than the cap are timed on
the first muscles (decays) and scaled linearly (``reference_extrapolated``); their results
are compared with pamid's on those muscles (``max_rel_diff``; decays: max |Δangle| in rad).
Cost growth: the slope of log(time) against log(N) over N ≥ 100, flagged when above 1.1.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
SLOPE_FLAG = 1.1
SIM_MAX = 10_000  # static fits: muscles simulated; larger N repeat them

SIZES = {
    "static": {"quick": (1, 100, 1000), "full": (1, 100, 1000, 10_000, 100_000)},
    "cullinan": {"quick": (1, 100, 1000), "full": (1, 100, 1000, 10_000)},
    "decays": {"quick": (1, 100, 1000), "full": (1, 100, 1000, 10_000)},
    "decays_rk4": {"quick": (), "full": (1, 100, 1000, 10_000)},  # quick: the default only
    "mcmc": {"quick": (1, 100), "full": (1, 10, 100, 1000)},
}
#: Largest reference loop actually run (the rest scaled linearly).
REF_MAX = {
    "static": {"quick": 300, "full": 1000},
    "cullinan": {"quick": 300, "full": 1000},
    "decays": {"quick": 30, "full": 100},
    "decays_rk4": {"quick": 30, "full": 100},
    "mcmc": {"quick": 5, "full": 100},
}
DECAY = {"seconds": 4.0, "method": "DOP853", "rtol": 1e-8, "atol": 1e-10}
MCMC_STEPS = {"quick": 1000, "full": 2000}


def say(*parts, file=None):
    print(*parts, file=file or sys.stderr, flush=True)


# --------------------------------------------------------------------------------------
# Workers: each runs in its own process and prints one "RESULT {json}" line.
# --------------------------------------------------------------------------------------


def _peak_rss_mb() -> float:
    """Peak resident memory of this process in MB.

    Linux: ``VmHWM`` of /proc/self/status. ``resource.getrusage(...).ru_maxrss`` is not
    used there because it carries over across fork + exec: every worker would report at
    least the parent's peak at the moment it was started (measured: a child of a 313 MB
    parent reported 313 MB, its VmHWM 13 MB). Elsewhere ``ru_maxrss`` (KiB on Linux-likes,
    bytes on macOS).
    """
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return int(line.split()[1]) / 1024.0  # kB
    except OSError:
        pass
    import resource

    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / 2**20 if sys.platform == "darwin" else peak / 1024.0


def _time_pamid(fn, repeats):
    """First call (compile + run) after a cache clear, then the median of warm calls."""
    import jax

    jax.clear_caches()
    t = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t
    walls = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        walls.append(time.perf_counter() - t)
    steady = statistics.median(walls)
    return {"pamid_s": steady, "first_s": first, "compile_s": max(first - steady, 0.0)}, out


def _time_reference(fn, repeats, min_total_s=2.0):
    """Median of up to ``repeats`` runs (fewer where one run already takes ``min_total_s``)."""
    walls = []
    out = None
    while len(walls) < repeats and (not walls or sum(walls) < min_total_s):
        t = time.perf_counter()
        out = fn()
        walls.append(time.perf_counter() - t)
    return statistics.median(walls), out


def _static_data(path, n_ref):
    import jax.numpy as jnp
    import numpy as np

    import pamid

    # An NpzFile reads (and decompresses) an array at every z[key]: read each one once.
    with np.load(path) as z:
        x0, x1, y, w, curve = (z[k] for k in ("x0", "x1", "y", "w", "curve"))
    data = pamid.FitData(
        x=(jnp.asarray(x0), jnp.asarray(x1)),
        y=jnp.asarray(y),
        w=jnp.asarray(w),
        curve=jnp.asarray(curve),
    )
    groups = []
    for i in range(min(n_ref, y.shape[0])):
        keep = w[i] > 0
        groups.append(((x0[i, keep], x1[i, keep]), y[i, keep]))
    return data, groups


def _cullinan_data(n, seed=3):
    """N muscles of Cullinan eq. 3 (A–E): the traditional-PAM constants × (1 + 0.03·normal),
    on the grid of the virtual static bench (StaticBenchProtocol), load-cell noise 2 N."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    import pamid

    k_grid, k_theta, k_noise = jax.random.split(jax.random.key(seed), 3)
    grid = pamid.simulate_braided_pam_bench(k_grid, pamid.cullinan.braided_pam())
    p = grid["pressure_kPa"].to_numpy()
    y = grid["contraction_mm"].to_numpy()
    base = np.asarray(pamid.cullinan.traditional_pam().to_vector(with_g=False))
    theta = base * (1.0 + 0.03 * np.asarray(jax.random.normal(k_theta, (n, 5))))
    force = np.asarray(pamid.cullinan.cullinan_force(
        pamid.Cullinan.from_vector(theta[:, None, :]), p, y))
    force = force + 2.0 * np.asarray(jax.random.normal(k_noise, force.shape))
    shape = force.shape
    data = pamid.FitData(
        x=(jnp.broadcast_to(p, shape), jnp.broadcast_to(y, shape)),
        y=jnp.asarray(force),
        w=jnp.ones(shape),
        curve=jnp.zeros(shape, dtype=int),
    )
    return data, p, y, force


def _cullinan_scipy_loop(p, y, force, n):
    """least_squares per muscle, analytic Jacobian of eq. 3 (linear in A–E), from zeros."""
    import numpy as np
    from scipy.optimize import least_squares

    jac = np.stack([np.ones_like(p), p, -y, -p * y, -y * y], axis=1)
    theta = np.empty((n, 5))
    for i in range(n):
        res = least_squares(
            lambda th, f=force[i]: jac @ th - f,
            np.zeros(5),
            jac=lambda th: jac,
            method="lm",
            x_scale="jac",
            ftol=1e-12,
            xtol=1e-12,
            gtol=1e-12,
        )
        theta[i] = res.x
    return theta


def _emcee_numpy(data, start, prior, n_steps, thin):
    """A loop of emcee samplers, NumPy log-probability; returns seconds and (M, draws, W, d)."""
    import emcee
    import numpy as np

    from pamid import engine

    f = engine.numpy_log_prob("sarosi", prior)
    moves = [
        (emcee.moves.DEMove(), engine.DE_FRACTION),
        (emcee.moves.StretchMove(), 1 - engine.DE_FRACTION),
    ]
    samplers, states = [], []
    for i in range(data.n_muscles):
        xi = tuple(np.asarray(a[i]) for a in data.x)
        yi, wi = np.asarray(data.y[i]), np.asarray(data.w[i])
        sampler = emcee.EnsembleSampler(
            start.shape[1],
            start.shape[2],
            lambda z, xi=xi, yi=yi, wi=wi: f(z, xi, yi, wi),
            vectorize=True,
            moves=moves,
        )
        sampler.random_state = np.random.RandomState(i).get_state()  # fixed, per muscle
        samplers.append(sampler)
        states.append(np.asarray(start[i]))
    t = time.perf_counter()
    for i, s in enumerate(samplers):
        states[i] = s.run_mcmc(states[i], n_steps // thin, thin_by=thin)
    seconds = time.perf_counter() - t
    return seconds, np.stack([s.get_chain() for s in samplers])


def _ess(chain, thin):
    """Per muscle, the smallest effective sample size over the coordinates, from a chain
    (M, draws, W, d), with emcee's integrated-time estimator (pamid's copy)."""
    import numpy as np

    from pamid.engine import integrated_time

    tau_draws = np.maximum(integrated_time(chain), 1.0)  # (M, d), in draws
    n = chain.shape[1] * chain.shape[2]
    return (n / tau_draws).min(axis=-1), tau_draws.max() * thin


def worker(spec: dict) -> dict:
    import jax

    jax.config.update("jax_enable_compilation_cache", False)  # compile time is measured
    import numpy as np

    sys.path.insert(0, str(HERE))
    bench, side, n, quick = spec["bench"], spec["side"], spec["n"], spec["quick"]
    repeats = 3 if quick else 5
    n_ref = min(n, spec["ref_max"])
    out = {}
    result = None

    if bench in ("static", "static_curve_fit"):
        data, groups = _static_data(spec["data"], n_ref)
        out["rss_setup_mb"] = _peak_rss_mb()
        if side == "pamid":
            import pamid

            timing, fit = _time_pamid(lambda: pamid.fit_least_squares(data), repeats)
            out.update(timing, converged=float(np.mean(fit.converged)))
            result = fit.theta[:n_ref]
        else:
            import fit_batch

            if bench == "static":
                fn = lambda: fit_batch.scipy_ls_loop(groups, fit_batch.TABLE_3_1, "lm", 1e-12)[0]  # noqa: E731
            else:
                fn = lambda: fit_batch.curve_fit_loop(groups, fit_batch.TABLE_3_1)  # noqa: E731
            seconds, result = _time_reference(fn, repeats)
            out["reference_s"] = seconds * n / n_ref

    elif bench == "diagnose":
        extra, result = bench_diagnose_worker(spec)
        out.update(extra)

    elif bench == "cullinan":
        data, p, y, force = _cullinan_data(n)
        out["rss_setup_mb"] = _peak_rss_mb()
        if side == "pamid":
            import pamid

            timing, fit = _time_pamid(lambda: pamid.fit_least_squares(data, "cullinan"), repeats)
            out.update(timing, converged=float(np.mean(fit.converged)))
            result = fit.theta[:n_ref]
        else:
            seconds, result = _time_reference(
                lambda: _cullinan_scipy_loop(p, y, force, n_ref), repeats
            )
            out["reference_s"] = seconds * n / n_ref

    elif bench in ("decays_exact", "decays_rk4"):
        import jax.numpy as jnp
        import simulate_batch

        import pamid

        zeta, fn_hz, angle0 = simulate_batch.decay_params(n)
        out["rss_setup_mb"] = _peak_rss_mb()
        if side == "pamid":
            osc = pamid.DampedOscillator.from_modal(jnp.asarray(zeta), jnp.asarray(fn_hz), 0.46)
            method = bench.split("_")[1]
            timing, angle = _time_pamid(
                lambda: np.asarray(
                    pamid.simulate_oscillator(
                        osc,
                        jnp.asarray(angle0),
                        duration_s=DECAY["seconds"],
                        method=method,
                        with_rate=False,
                    ).angle_rad
                ),
                repeats,
            )
            out.update(timing)
            result = angle[:n_ref]
        else:
            ts = np.arange(int(DECAY["seconds"] * 1000) + 1) / 1000.0
            seconds, result = _time_reference(
                lambda: simulate_batch.scipy_decays(
                    zeta[:n_ref],
                    fn_hz[:n_ref],
                    angle0[:n_ref],
                    ts,
                    DECAY["method"],
                    DECAY["rtol"],
                    DECAY["atol"],
                ),
                1 if n_ref > 10 else repeats,
            )
            out["reference_s"] = seconds * n / n_ref

    elif bench == "mcmc":
        import mcmc_batch

        import pamid
        from pamid import engine

        sarosi = engine.get_model("sarosi")
        prior = pamid.default_prior(sarosi)
        log_prob = engine.walker_log_prob(sarosi, prior, "normal", 4.0)
        data = mcmc_batch.make_data(n, seed=n)
        start = mcmc_batch.start_ball(data, prior, log_prob)
        out["rss_setup_mb"] = _peak_rss_mb()
        n_steps, thin, walkers = spec["mcmc_steps"], mcmc_batch.THIN, mcmc_batch.W
        if side == "pamid":
            backend = engine.StackedSampler(
                log_prob, jax.random.key(2), start, data, engine.DE_FRACTION
            )
            # Chunks of 200 steps, as fit_mcmc runs them (the chunk length is static: one
            # compilation); the first chunk compiles and serves as burn-in.
            t = time.perf_counter()
            backend.advance(200, thin)
            first = time.perf_counter() - t
            t = time.perf_counter()
            chain = np.concatenate(
                [backend.advance(200, thin)[0] for _ in range(n_steps // 200)], axis=1
            )
            seconds = time.perf_counter() - t
            out.update(
                pamid_s=seconds, first_s=first, compile_s=max(first - seconds * 200 / n_steps, 0.0)
            )
        else:
            sub = jax.tree.map(lambda a: a[:n_ref], data)
            seconds, chain = _emcee_numpy(sub, start[:n_ref], prior, n_steps, thin)
            seconds *= n / n_ref
            out["reference_s"] = seconds
        ess, tau_max = _ess(chain, thin)
        total_ess = float(ess.sum()) * n / chain.shape[0]
        out.update(
            steps=n_steps,
            samples_per_s=n * walkers * n_steps / seconds,
            ess_per_s=total_ess / seconds,
            tau_max_steps=float(tau_max),
        )
    else:
        raise ValueError(f"unknown benchmark {bench!r}")

    out["peak_rss_mb"] = _peak_rss_mb()
    if result is not None and spec.get("result"):
        np.save(spec["result"], np.asarray(result))
    return out


# --------------------------------------------------------------------------------------
# The parent: data, subprocesses, table.
# --------------------------------------------------------------------------------------


def run_worker(spec: dict, timeout: float) -> dict:
    t = time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, __file__, "--worker", json.dumps(spec)],
            capture_output=True,
            text=True,
            timeout=timeout,
        )
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:.0f} s"}
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        tail = proc.stderr.strip().splitlines()[-3:]
        return {"error": f"exit {proc.returncode}: " + " | ".join(tail)}
    res = json.loads(lines[-1][len("RESULT ") :])
    res["wall_s"] = time.perf_counter() - t
    return res


def _revision() -> str:
    sys.path.insert(0, str(HERE))
    import fit_batch

    return fit_batch._revision()  # "git <hash>", "+dirty" with uncommitted changes in pamid/


def make_static_data(sizes, tmp: Path) -> dict:
    """Simulate once (``fit_batch.make_data``) and store the packed arrays for the workers."""
    import numpy as np

    sys.path.insert(0, str(HERE))
    import fit_batch

    paths = {}
    cache = {}
    for n in sizes:
        m = min(n, SIM_MAX)
        if m not in cache:
            t = time.perf_counter()
            data = fit_batch.make_data(m)[2]  # (frame, groups, FitData, thetas, pack seconds)
            cache[m] = {
                "x0": np.asarray(data.x[0]),
                "x1": np.asarray(data.x[1]),
                "y": np.asarray(data.y),
                "w": np.asarray(data.w),
                "curve": np.asarray(data.curve),
            }
            say(f"  simulated {m} muscles in {time.perf_counter() - t:.1f} s")
        reps = -(-n // m)
        arrays = {k: np.concatenate([v] * reps)[:n] if reps > 1 else v for k, v in cache[m].items()}
        paths[n] = tmp / f"static_{n}.npz"
        np.savez(paths[n], **arrays)
    return paths


ROWS = (
    # (bench, label, reference label, sizes key)
    ("static", "static fit (Sárosi)", "scipy least_squares loop (analytic J)", "static"),
    ("static_curve_fit", "static fit (Sárosi)", "scipy curve_fit loop", "static"),
    ("cullinan", "cullinan fit (eq. 3)", "scipy least_squares loop (analytic J)", "cullinan"),
    ("decays_exact", "decays, exact", "solve_ivp loop (DOP853 rtol 1e-8)", "decays"),
    ("decays_rk4", "decays, RK4", "solve_ivp loop (DOP853 rtol 1e-8)", "decays_rk4"),
    ("mcmc", "mcmc, stacked ensembles", "emcee loop, NumPy log-prob", "mcmc"),
)


def compare(bench, a, b):
    """pamid's result against the reference's, on the reference's muscles."""
    import numpy as np

    a, b = np.asarray(a, float), np.asarray(b, float)
    if bench.startswith("decays"):
        return float(np.max(np.abs(a - b)))  # rad
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


def _row(name, n, reference, p, r, extrapolated) -> dict:
    """One table row from the two workers' results (``p``: pamid's, ``r``: the reference's)."""
    row = {
        "name": name,
        "n": n,
        "pamid_s": p.get("pamid_s"),
        "reference": reference,
        "reference_s": r.get("reference_s"),
        "speedup": None,
        "compile_s": p.get("compile_s"),
        "first_call_s": p.get("first_s"),
        "pamid_peak_rss_mb": p.get("peak_rss_mb"),
        "reference_peak_rss_mb": r.get("peak_rss_mb"),
        "reference_extrapolated": extrapolated,
    }
    if row["pamid_s"] and row["reference_s"]:
        row["speedup"] = row["reference_s"] / row["pamid_s"]
    return row


def make_diagnose_data(n: int, tmp: Path) -> Path:
    """A bench file of ``n`` muscles (Table 3-1 × (1 + 0.03·normal)) hiding a hysteresis loop
    of 9 N at 3 bar, so that the diagnosis has something to find and refit."""
    import jax

    import pamid
    from pamid.io import write_frame_atomic

    theta = pamid.sarosi.table_3_1().to_vector()
    thetas = theta * (1.0 + 0.03 * jax.random.normal(jax.random.key(11), (n, 6)))
    proto = pamid.SarosiProtocol(min_force_N=10.0, effects=(pamid.InjectedHysteresis(9.0),))
    frame = pamid.simulate_sarosi_bench(jax.random.key(12), pamid.Sarosi.from_vector(thetas), proto)
    path = tmp / f"diagnose_{n}.csv"
    write_frame_atomic(path, frame)
    return path


def _diagnose_first_step(path):
    """The problem and the first selection step's sets (baseline + every candidate)."""
    import pamid
    from pamid.engine import StaticDiagnosisProblem, get_model

    problem = StaticDiagnosisProblem(pamid.load_bench(path), get_model("sarosi"))
    return problem, [(), *[(c,) for c in problem.candidate_names]]


#: The transform effects the SciPy loop reproduces by hand (Sárosi eq. 2.1 only): the rig's
#: compliance F = F_model(p, κ + c·F) and the pressure sensor's offset F = F_model(p + δ, κ).
SCIPY_TRANSFORMS = ("compliance", "sensor_offset")


def _scipy_left_out(problem) -> list[str]:
    """Candidates of ``problem`` whose refits the SciPy loop cannot reproduce by hand: the
    transform effects other than :data:`SCIPY_TRANSFORMS`. (Feature effects are linear in
    their constants; the loop reads their columns from ``problem.features``.)"""
    return [e.name for e in problem.effects
            if e.transform is not None and e.name not in SCIPY_TRANSFORMS]


def _scipy_refits(problem, sets, n_ref):
    """The first selection step done by hand: one ``scipy.optimize.least_squares`` (lm) per
    (set, muscle, fold), analytic Jacobian: Sárosi eq. 2.1's partial derivatives, the
    effects' feature columns (``problem.features``), the sensor offset δ (kPa) through
    ∂F/∂p, and the compliance's implicit law F = F_model(p + δ, κ + c·F), solved by Newton
    steps and differentiated implicitly (every derivative over 1 − c·∂F_model/∂κ); a lane
    whose optimum leaves the bounds the diagnosis keeps (the model's; a slip element's
    weight ≥ 0) is solved again within them (trf). Returns the training SSE of every lane,
    in pamid's lane order, for the muscles < n_ref.
    ``sets`` may name no candidate of :func:`_scipy_left_out`."""
    import numpy as np
    from scipy.optimize import least_squares

    k = 6
    out = []
    for s in sets:
        cols = [c for name in s for c in problem.effect(name).columns]
        comp, offset = "compliance" in s, "sensor_offset" in s
        n_tr = comp + offset
        model_lo, model_hi = problem.spec.bounds or ((-np.inf,) * k, (np.inf,) * k)
        lower = np.array([*model_lo, *(-np.inf,) * n_tr, *(problem.col_bounds[c][0]
                                                          for c in cols)])
        upper = np.array([*model_hi, *(np.inf,) * n_tr, *(problem.col_bounds[c][1]
                                                         for c in cols)])
        for m in range(n_ref):
            w_all = np.asarray(problem.data.w[m])
            p_bar, kappa = (np.asarray(x[m]) for x in problem.data.x)
            y = np.asarray(problem.data.y[m])
            for fold in range(problem.n_folds + 1):
                train = (w_all > 0) & ((problem.fold[m] != fold - 1) | (fold == 0))
                feats = problem.features[m, fold][:, cols]
                pp, kk, yy, ff = p_bar[train], kappa[train], y[train], feats[train]
                sw = np.sqrt(w_all[train])

                def force(v, pp=pp, kk=kk):
                    """F, ∂F_model/∂κ, ∂F_model/∂p, and the inputs the muscle feels."""
                    a1, a2, a3, a4, a5, a6 = v[:k]
                    c = v[k] if comp else 0.0
                    pe = pp + v[k + comp] / 100.0 if offset else pp  # δ in kPa, p in bar

                    def law(kc):
                        e = np.exp(a3 * kc)
                        return ((a1 * pe + a2) * e + a4 * kc * pe + a5 * pe + a6,
                                a3 * (a1 * pe + a2) * e + a4 * pe)

                    f = law(kk)[0]
                    for _ in range(50 if comp else 0):  # Newton on F − F_model(p, κ + c·F)
                        g, g_k = law(kk + c * f)
                        step = (f - g) / (1.0 - c * g_k)
                        f = f - step
                        if np.max(np.abs(step)) <= 1e-13 * (1.0 + np.max(np.abs(f))):
                            break
                    kc = kk + c * f
                    e = np.exp(a3 * kc)
                    return f, law(kc)[1], a1 * e + a4 * kc + a5, pe, kc, e

                def resid(v, ff=ff, yy=yy, sw=sw):
                    return sw * (force(v)[0] + ff @ v[k + n_tr:] - yy)

                def jac(v, ff=ff, sw=sw):
                    a1, a2 = v[:2]
                    f, g_k, g_p, pe, kc, e = force(v)
                    nl = [pe * e, e, (a1 * pe + a2) * kc * e, kc * pe, pe, np.ones_like(pe)]
                    nl += [g_k * f] * comp + [g_p / 100.0] * offset  # ∂/∂c, ∂/∂δ
                    nl = np.column_stack(nl)
                    if comp:  # implicit differentiation of F = F_model(p + δ, κ + c·F)
                        nl = nl / (1.0 - v[k] * g_k)[:, None]
                    return sw[:, None] * np.column_stack([nl, ff])

                v0 = np.concatenate([problem.theta0[m], np.zeros(n_tr + len(cols))])
                with np.errstate(over="ignore", invalid="ignore"):  # lm rejects such trials
                    sol = least_squares(resid, v0, jac=jac, method="lm",
                                        ftol=1e-12, xtol=1e-12, gtol=1e-12)
                    if np.any(sol.x < lower) or np.any(sol.x > upper):
                        # Outside the bounds pamid's lanes keep (the model's, a3 ≤ 0 …, and
                        # a slip element's weight ≥ 0): the same problem within them.
                        start = np.clip(sol.x, lower, upper)
                        sol = least_squares(resid, start, jac=jac, method="trf",
                                            bounds=(lower, upper), x_scale="jac",
                                            ftol=1e-12, xtol=1e-12, gtol=1e-12)
                out.append(float(sol.fun @ sol.fun))
    return np.asarray(out)


def _diagnose_end_to_end(path) -> dict:
    """``pamid.diagnose(pamid.load_bench(path))`` twice: the first call compiles (the
    persistent cache is off), the second is the warm time; what it selected, RMSE before
    and after."""
    import pamid

    walls, cpus = [], []
    for _ in range(2):
        t, c = time.perf_counter(), time.process_time()
        d = pamid.diagnose(pamid.load_bench(path))
        walls.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    return {"end_to_end_s": walls[1], "end_to_end_first_s": walls[0],
            "end_to_end_compile_s": max(walls[0] - walls[1], 0.0),
            "end_to_end_cpu_s": cpus[1], "selected": d.selected,
            "rmse_before": d.rmse_before, "rmse_after": d.rmse_after,
            "rows_used": d.rows_used, "rows_total": d.rows_total}


def bench_diagnose_worker(spec: dict) -> tuple[dict, object]:
    """One side of a diagnose row. "pamid": the first selection step, then (unless
    ``spec["end_to_end"] == "alone"``) the whole diagnosis warm in the same process;
    "end_to_end": only :func:`_diagnose_end_to_end`, so that its peak memory is its own;
    "reference": the SciPy loop on the first ``ref_max`` muscles, on the candidate sets it
    can reproduce (:func:`_scipy_left_out`)."""
    import numpy as np

    if spec["side"] == "end_to_end":
        return _diagnose_end_to_end(spec["data"]), None
    problem, sets = _diagnose_first_step(spec["data"])
    left_out = set(_scipy_left_out(problem))
    compared = [i for i, s in enumerate(sets) if not left_out & set(s)]
    out = {"candidates": problem.candidate_names, "left_out": sorted(left_out),
           "lanes": len(sets) * problem.data.y.shape[0] * (problem.n_folds + 1)}
    n, n_ref = spec["n"], min(spec["n"], spec["ref_max"])
    if spec["side"] == "pamid":
        import pamid

        def step():
            fits = problem.evaluate(sets)
            return (np.stack([f.sse for f in fits]),  # (sets, muscles)
                    np.stack([f.converged for f in fits]))

        timing, (sse, ok) = _time_pamid(step, spec.get("repeats") or (3 if spec["quick"] else 5))
        out.update(timing, compared=[" + ".join(sets[i]) or "baseline" for i in compared],
                   converged=ok[compared, :n_ref].tolist())
        if spec.get("end_to_end") != "alone":
            pamid.diagnose(spec["data"])  # compiles the later steps' shapes too
            t = time.perf_counter()
            d = pamid.diagnose(spec["data"])
            out["end_to_end_s"] = time.perf_counter() - t
            out["selected"] = d.selected
        result = sse[compared, :n_ref]
    else:
        ref_sets = [sets[i] for i in compared]
        seconds, lanes = _time_reference(lambda: _scipy_refits(problem, ref_sets, n_ref), 1,
                                         min_total_s=0.0)
        out["reference_s"] = seconds * n / n_ref
        folds = problem.n_folds + 1
        result = lanes.reshape(len(ref_sets), n_ref, folds)[:, :, 0]  # full-data lanes
    return out, result


#: The measured file of the ``diagnose_aarl`` row (``../shared/data/README.md``); the row is
#: skipped without it.
AARL_FILE = HERE.parent.parent / "shared" / "data" / "aarl_festo10mm_isometric.csv"
#: ``diagnose_aarl``: SciPy loop on at most this many of its 6 muscles; warm repeats.
AARL_REF_MAX = {"quick": 2, "full": 6}
AARL_REPEATS = 3


def bench_diagnose(args, tmp: Path, timeout: float, path: Path | None = None) -> list[dict]:
    """`pamid diagnose`'s first selection step (baseline and every candidate refitted on all
    data and on each held-out fold, all muscles: one batched call) beside the same refits as
    a SciPy loop; the whole diagnosis end to end as well.

    ``path`` None: a 100-muscle virtual file hiding a hysteresis loop (the ``diagnose`` row;
    the end to end runs in pamid's process). A bench file (the ``diagnose_aarl`` row): that
    file as it is, the SciPy loop on up to :data:`AARL_REF_MAX` muscles, and
    ``pamid.diagnose(load_bench(path))`` in a process of its own, cold and warm, with its
    peak memory, what it selected and the RMSE before and after."""
    import numpy as np

    mode = "quick" if args.quick else "full"
    if path is None:
        n, ref_max, tag = 100, 10 if args.quick else 100, "diagnose"
        path = make_diagnose_data(n, tmp)
        name, what = "diagnose, first selection step", "100 muscles"
        sides = ("pamid", "reference")
    else:
        import pamid

        bench = pamid.load_bench(path)
        n, ref_max, tag = len(bench.muscles), AARL_REF_MAX[mode], "diagnose_aarl"
        name = "diagnose AARL 10 mm, first selection step"
        what = f"AARL 10 mm file, {len(bench.frame):,} rows, {n} muscles, own process"
        sides = ("pamid", "reference", "end_to_end")
        del bench
    spec = {"bench": "diagnose", "n": n, "quick": args.quick, "ref_max": ref_max,
            "data": str(path), "end_to_end": "alone" if "end_to_end" in sides else "after",
            "repeats": AARL_REPEATS if tag == "diagnose_aarl" else None}
    res = {}
    for side in sides:
        say(f"  {tag} N={n} {side} …")
        out_path = tmp / f"{tag}_{side}.npy"
        res[side] = run_worker({**spec, "side": side, "result": str(out_path)}, timeout)
        res[side]["result_path"] = str(out_path)
    p, r = res["pamid"], res["reference"]
    e2e = res.get("end_to_end", p)
    reference = "scipy least_squares loop, same refits"
    if tag == "diagnose_aarl":
        left = ", ".join(r.get("left_out", [])) or "none"
        reference += (f" ({min(n, ref_max)} of {n} muscles"
                      f"{', scaled' if n > ref_max else ''}; candidates left out: {left})")
    row = _row(name, n, reference, p, r, n > ref_max)
    row.update(diagnose_label=what, diagnose_end_to_end_s=e2e.get("end_to_end_s"),
               diagnose_selected=e2e.get("selected"))
    if "end_to_end" in res:
        row.update({f"diagnose_{k}": e2e.get(k) for k in (
            "end_to_end_first_s", "end_to_end_compile_s", "end_to_end_cpu_s", "rmse_before",
            "rmse_after", "rows_used", "rows_total")}, diagnose_peak_rss_mb=e2e.get("peak_rss_mb"),
            diagnose_candidates=p.get("candidates"), diagnose_lanes=p.get("lanes"))
    pa, ra = Path(p["result_path"]), Path(r["result_path"])
    if pa.is_file() and ra.is_file():
        a, b = np.load(pa), np.load(ra)
        rel = np.abs(a - b) / np.maximum(np.abs(b), 1e-300)
        row["max_diff"] = float(np.max(rel))
        ok = np.asarray(p.get("converged", np.ones(a.shape, bool)), bool)
        if ok.shape == a.shape and not ok.all():  # pamid's LM stopped at its step cap
            sets = np.asarray(p["compared"])
            row.update(max_diff_converged=float(np.max(rel[ok], initial=0.0)),
                       lanes_compared=int(a.size), lanes_not_converged={
                           str(x): int(np.sum(~ok[sets == x])) for x in sets[~ok.all(axis=1)]},
                       max_diff_not_converged=float(np.max(rel[~ok])),
                       scipy_lower_not_converged=int(np.sum(b[~ok] < a[~ok])))
    errors = [f"{s}: {x['error']}" for s, x in res.items() if "error" in x]
    if errors:
        row["error"] = "; ".join(errors)
        say(f"    {row['error']}")
    return [row]


#: ``latency``: rows of the one-muscle files, per mode.
LATENCY_ROWS = {"quick": (600,), "full": (600, 2000)}


def bench_latency(args, tmp: Path, timeout: float) -> list[dict]:
    """A lab's new one-muscle file, command by command, beside the SciPy script: the
    scenarios "empty cache" and "new file, warm class" of ``latency.py`` (its helpers make
    the files and time the commands), one table row per command and row count."""
    import latency

    py = sys.executable
    env = dict(os.environ)
    rows = []
    for n in LATENCY_ROWS["quick" if args.quick else "full"]:
        folder = tmp / f"latency_{n}"
        folder.mkdir()
        files = latency.one_muscle_files(folder, n, 1000 + n, env, py)
        ref = latency.scipy_time(py, files["B"], env, folder, 3)
        for command in latency.COMMANDS:
            say(f"  latency {command} {n} rows …")
            cache = folder / f"cache-{command}"
            cache.mkdir()
            cmd_env = {**env, "PAMID_CACHE_DIR": str(cache)}
            first, warm = (latency.run([py, "-m", "pamid", command, str(files[k]), "--json"],
                                       cmd_env, folder, timeout) for k in "AB")
            row = {"name": f"pamid {command}, new one-muscle file", "n": n,
                   "pamid_s": warm["wall_s"], "first_call_s": first["wall_s"],
                   "compile_s": max(first["wall_s"] - warm["wall_s"], 0.0),
                   "reference": "pandas + curve_fit script (Wald)", "reference_s": ref,
                   "speedup": ref / warm["wall_s"], "reference_extrapolated": False}
            bad = [f"exit {r['rc']}: {r['stderr'][-300:]}" for r in (first, warm) if r["rc"]]
            if bad:
                row["error"] = "; ".join(bad)
                say(f"    {row['error']}")
            rows.append(row)
    return rows


def _diagnose_lines(row) -> list[str]:
    """The lines printed under the table for one diagnose row."""
    if not row.get("diagnose_end_to_end_s"):
        return []
    selected = ", ".join(row["diagnose_selected"]) or "nothing"
    lines = []
    if row.get("lanes_not_converged"):
        from pamid.engine import DIAGNOSIS_MAX_STEPS as MAX_ITER

        where = ", ".join(f"{k} on {v} muscle{'s' * (v > 1)}"
                          for k, v in row["lanes_not_converged"].items())
        n_bad = sum(row["lanes_not_converged"].values())
        lines.append(
            f"  {row['name']}: SSE within {row['max_diff_converged']:.1e} of SciPy's on the "
            f"{row['lanes_compared'] - n_bad} of {row['lanes_compared']} full-data lanes "
            f"(set × muscle) where pamid's LM converged; {n_bad} stopped at its {MAX_ITER} "
            f"steps unconverged ({where}): there up to "
            f"{row['max_diff_not_converged']:.1e}, SciPy's lower in "
            f"{row['scipy_lower_not_converged']}")
    if row.get("diagnose_peak_rss_mb") is None:
        return [f"diagnose end to end ({row['diagnose_label']}, warm): "
                f"{row['diagnose_end_to_end_s']:.2f} s; selected {selected}", *lines]
    warm, first = row["diagnose_end_to_end_s"], row["diagnose_end_to_end_first_s"]
    mb = row["diagnose_peak_rss_mb"]
    met = lambda ok: "met" if ok else "NOT met"  # noqa: E731
    return [
        f"diagnose end to end ({row['diagnose_label']}): warm {warm:.2f} s (CPU "
        f"{row['diagnose_end_to_end_cpu_s']:.1f} s; first call {first:.2f} s, compile "
        f"{row['diagnose_end_to_end_compile_s']:.2f} s), peak RSS "
        f"{mb:,.0f} MB; selected {selected}; RMSE {row['diagnose_rmse_before']:.2f} → "
        f"{row['diagnose_rmse_after']:.2f} N",
        f"  first step: {len(row['diagnose_candidates'] or [])} candidates + baseline, "
        f"{row['diagnose_lanes']} lanes (set × muscle × fold); targets: ≤ 60 s "
        f"{met(warm <= 60.0)} warm, {met(first <= 60.0)} on the first call; ≤ 4 GB "
        f"{met(mb <= 4096.0)}",
        *lines,
    ]


def log_log_slope(ns, ts):
    import numpy as np

    pts = [(n, t) for n, t in zip(ns, ts, strict=True) if n >= 100 and t and t > 0]
    if len(pts) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="small sizes, fewer repeats")
    ap.add_argument("--json", action="store_true", help="print the rows as JSON on stdout")
    ap.add_argument("--only", help="comma-separated benchmarks: "
                    + ",".join([*(r[0] for r in ROWS), "diagnose", "diagnose_aarl", "latency"])
                    + " (diagnose_aarl: the full run, or --quick when named)")
    ap.add_argument("--timeout", type=float, help="seconds per subprocess (900; quick 300)")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print("RESULT " + json.dumps(worker(json.loads(args.worker))), flush=True)
        return 0

    mode = "quick" if args.quick else "full"
    timeout = args.timeout or (300.0 if args.quick else 900.0)
    chosen = [r for r in ROWS if not args.only or r[0] in args.only.split(",")]
    out_text = sys.stderr if args.json else sys.stdout
    t_start = time.perf_counter()

    import jax
    import numpy as np

    import pamid

    sys.path.insert(0, str(HERE))
    from fit_batch import fmt_s, table  # the same formatting as fit_batch.py's tables

    machine = {
        "date": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
        "jax": jax.__version__,
        "backend": jax.default_backend(),
        "devices": [str(d) for d in jax.devices()],
        "pamid": pamid.__version__,
        "revision": _revision(),
        "load_average_start": os.getloadavg()[0],
    }
    say(
        f"pamid benchmarks ({mode}) — {machine['date']}; {machine['platform']}; "
        f"{machine['cpus']} CPUs; JAX {machine['jax']} ({machine['backend']}, "
        f"{len(machine['devices'])} device(s)); load {machine['load_average_start']:.2f}; "
        f"pamid {machine['pamid']} at {machine['revision']}",
        file=out_text,
    )

    rows = []
    with tempfile.TemporaryDirectory(prefix="pamid-run-") as tmp_name:
        tmp = Path(tmp_name)
        static_paths = {}
        if any(r[3] == "static" for r in chosen):
            say("static-fit data (fit_batch.make_data):")
            static_paths = make_static_data(SIZES["static"][mode], tmp)
        for bench, label, ref_label, key in chosen:
            for n in SIZES[key][mode]:
                spec = {
                    "bench": bench,
                    "n": n,
                    "quick": args.quick,
                    "ref_max": REF_MAX[key][mode],
                    "mcmc_steps": MCMC_STEPS[mode],
                    "data": str(static_paths.get(n, "")),
                }
                res = {}
                for side in ("pamid", "reference"):
                    if side == "pamid" and bench == "static_curve_fit":
                        res["pamid"] = next(  # the same pamid fit as the row above
                            (r["_pamid"] for r in rows if r["bench"] == "static" and r["n"] == n),
                            None,
                        )
                        if res["pamid"] is not None:
                            continue
                    path = tmp / f"{bench}_{n}_{side}.npy"
                    say(f"  {bench} N={n} {side} …")
                    res[side] = run_worker({**spec, "side": side, "result": str(path)}, timeout)
                    res[side]["result_path"] = str(path)
                p, r = res["pamid"], res["reference"]
                row = _row(label, n, ref_label, p, r, n > REF_MAX[key][mode])
                row.update(bench=bench, _pamid=p)
                for k in ("samples_per_s", "ess_per_s", "tau_max_steps", "steps"):
                    if k in p:
                        row[f"pamid_{k}"] = p[k]
                        row[f"reference_{k}"] = r.get(k)
                if "converged" in p:
                    row["pamid_converged"] = p["converged"]
                pa, ra = Path(p.get("result_path", "")), Path(r.get("result_path", ""))
                if pa.is_file() and ra.is_file():
                    row["max_diff"] = compare(bench, np.load(pa), np.load(ra))
                errors = [
                    f"{s}: {x['error']}"
                    for s, x in (("pamid", p), ("reference", r))
                    if "error" in x
                ]
                if errors:
                    row["error"] = "; ".join(errors)
                    say(f"    {row['error']}")
                rows.append(row)

        diagnose = []
        only = args.only.split(",") if args.only else None
        if not only or "diagnose" in only:
            diagnose = bench_diagnose(args, tmp, timeout)
        if (only and "diagnose_aarl" in only) or (not only and not args.quick):
            if AARL_FILE.is_file():
                diagnose += bench_diagnose(args, tmp, timeout, AARL_FILE)
            else:
                say(f"diagnose_aarl skipped: no measured file at {AARL_FILE} "
                    "(see ../shared/data/README.md)", file=out_text)
        latency_rows = bench_latency(args, tmp, timeout) if not only or "latency" in only else []
    for row in rows:
        row.pop("_pamid", None)
        row.pop("bench", None)
    rows.extend(diagnose)
    rows.extend(latency_rows)

    # ---- the table ----
    lines = []
    for row in rows:
        mark = "*" if row.get("reference_extrapolated") else ""
        lines.append(
            [
                row["name"],
                row["n"],
                fmt_s(row["pamid_s"]),
                fmt_s(row.get("compile_s")),
                row["reference"],
                fmt_s(row["reference_s"]) + mark,
                f"{row['speedup']:.1f}×" if row.get("speedup") else "—",
                f"{row['pamid_peak_rss_mb']:.0f}" if row.get("pamid_peak_rss_mb") else "—",
                f"{row['reference_peak_rss_mb']:.0f}" if row.get("reference_peak_rss_mb") else "—",
                f"{row['max_diff']:.1e}" if row.get("max_diff") is not None else "—",
            ]
        )
    if lines:  # none where the only row asked for was skipped
        say("", file=out_text)
        say(
            table(
                [
                    "benchmark",
                    "N",
                    "pamid",
                    "compile",
                    "reference",
                    "ref time",
                    "speedup",
                    "pamid MB",
                    "ref MB",
                    "max diff",
                ],
                lines,
            ),
            file=out_text,
        )
        say(
            "  pamid = median warm call; compile = first call − warm call; * reference timed on "
            "the first muscles and scaled linearly; MB = peak RSS of the subprocess (imports and "
            "data included); max diff = largest relative difference of the fitted constants "
            "(decays: |Δangle| in rad; diagnose: of the full-data SSE of every set) on the "
            "reference's muscles.",
            file=out_text,
        )
    for row in diagnose:
        for line in _diagnose_lines(row):
            say(line, file=out_text)

    mc = [r for r in rows if "pamid_ess_per_s" in r]
    if mc:
        say("", file=out_text)
        say(
            table(
                [
                    "mcmc",
                    "N",
                    "steps",
                    "pamid samples/s",
                    "pamid ESS/s",
                    "emcee samples/s",
                    "emcee ESS/s",
                    "ESS/s ratio",
                ],
                [
                    [
                        r["name"],
                        r["n"],
                        r["pamid_steps"],
                        f"{r['pamid_samples_per_s']:.3g}",
                        f"{r['pamid_ess_per_s']:.3g}",
                        f"{r['reference_samples_per_s']:.3g}"
                        if r.get("reference_samples_per_s")
                        else "—",
                        f"{r['reference_ess_per_s']:.3g}" if r.get("reference_ess_per_s") else "—",
                        f"{r['pamid_ess_per_s'] / r['reference_ess_per_s']:.1f}×"
                        if r.get("reference_ess_per_s")
                        else "—",
                    ]
                    for r in mc
                ],
            ),
            file=out_text,
        )
        say(
            "  ESS: per muscle the smallest over the constants and σ (emcee's estimator), "
            "summed over muscles; samples = walkers × steps.",
            file=out_text,
        )

    slopes = []
    for bench, label, ref_label, _ in chosen:
        sel = [r for r in rows if r["name"] == label and r["reference"] == ref_label]
        for who, key in (("pamid", "pamid_s"), ("reference", "reference_s")):
            if who == "pamid" and bench == "static_curve_fit":
                continue
            use = [
                r
                for r in sel
                if r["n"] >= 100 and (who == "pamid" or not r["reference_extrapolated"])
            ]
            s = log_log_slope([r["n"] for r in use], [r[key] for r in use])
            if s is not None:
                name = label if who == "pamid" else ref_label
                flag = "SUPERLINEAR" if s > SLOPE_FLAG else ""
                span = f"{min(r['n'] for r in use)}–{max(r['n'] for r in use)}"
                slopes.append([name, span, f"{s:.2f}", flag])
    if slopes:
        say("", file=out_text)
        say(
            table(["cost growth (log-log slope, N ≥ 100)", "N", "slope", "flag"], slopes),
            file=out_text,
        )
        say(
            f"  flagged when the slope exceeds {SLOPE_FLAG}; references only over the N they "
            "were actually run at (scaled ones grow linearly by construction).",
            file=out_text,
        )

    machine["load_average_end"] = os.getloadavg()[0]
    machine["total_s"] = time.perf_counter() - t_start
    say(
        f"\ntotal {machine['total_s']:.0f} s; load average at end "
        f"{machine['load_average_end']:.2f}",
        file=out_text,
    )
    if args.json:
        print(json.dumps(rows, indent=1), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
