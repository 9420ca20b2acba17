"""Which start settings reach the best optimum: fits from k starts per muscle on real files.

For every model of pamid and every muscle of the real files in ``../shared/data`` (the
Martens & Boblan DMSP-10-250 map, the AARL 10 mm isometric tests) and the bundled virtual
file, ``pamid.fit_least_squares(..., starts=k)`` for k = 1, 2, 4, 8, against the best SSE
any setting reached; for Sárosi also against SciPy's ``least_squares`` (lm, analytic model,
tolerances 1e-12) from 50 values of a3 (−60 … +5 over the muscle's contraction span), its
linear constants solved for each. Prints one row per model × file × k: muscles whose SSE is
within 1e-6 (relative) of the best, the worst relative excess, and the fit's time.

    .venv/bin/python benchmarks/start_settings.py [--models sarosi,cullinan] [--no-scipy]
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

import pamid
from pamid import bench_to_fit_data, fit_least_squares
from pamid.engine import get_model, model_names

ROOT = Path(__file__).resolve().parents[1]
FILES = [(ROOT.parent / "shared/data/martens_dmsp10_250.csv", {"l0_mm": 250.0}),
         (ROOT.parent / "shared/data/aarl_festo10mm_isometric.csv", {}),
         (ROOT / "pamid/data/sarosi_dmsp20_400_virtual.csv", {})]
STARTS = (1, 2, 4, 8)


def scipy_sarosi(bench) -> np.ndarray:
    """Per muscle, the best SSE of SciPy least_squares from 50 a3 starts."""
    from scipy.optimize import least_squares

    data = bench_to_fit_data(bench, "sarosi", curves=False)
    out = []
    for i in range(data.n_muscles):
        w = np.asarray(data.w[i]) > 0
        p, k, y = (np.asarray(a[i])[w] for a in (*data.x, data.y))

        def resid(t):
            with np.errstate(over="ignore", invalid="ignore"):
                return (t[0] * p + t[1]) * np.exp(t[2] * k) + t[3] * k * p + t[4] * p + t[5] - y

        best = np.inf
        for s in np.concatenate([-np.geomspace(60, 0.01, 40), np.geomspace(0.01, 5, 10)]):
            a3 = s / k.max()
            e = np.exp(a3 * k)
            b = np.linalg.lstsq(np.stack([p * e, e, k * p, p, np.ones_like(p)], 1), y,
                                rcond=None)[0]
            try:
                r = least_squares(resid, [b[0], b[1], a3, b[2], b[3], b[4]], method="lm",
                                  xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=5000)
            except ValueError:
                continue
            sse = float(np.sum(r.fun**2))
            if np.isfinite(sse):
                best = min(best, sse)
        out.append(best)
    return np.asarray(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", default=",".join(model_names()))
    parser.add_argument("--no-scipy", action="store_true")
    args = parser.parse_args()
    warnings.simplefilter("ignore")
    print("| model | file | starts | muscles at the best | worst excess SSE | status | s |")
    print("|---|---|---|---|---|---|---|")
    for path, options in FILES:
        if not path.exists():
            print(f"(skipped: {path} absent)")
            continue
        bench = pamid.load_bench(path, **options)
        for model in args.models.split(","):
            if any(c not in bench.frame for c in get_model(model).columns):
                continue
            sse, status, seconds = {}, {}, {}
            for k in STARTS:
                fit_least_squares(bench, model, starts=k)  # compile
                t0 = time.perf_counter()
                fit = fit_least_squares(bench, model, starts=k)
                seconds[k] = time.perf_counter() - t0
                sse[k], status[k] = fit.sse, fit.status
            best = np.min(np.stack(list(sse.values())), axis=0)
            if model == "sarosi" and not args.no_scipy:
                sse["scipy 50 a3"] = scipy_sarosi(bench)
                best = np.minimum(best, sse["scipy 50 a3"])
            for k, v in sse.items():
                excess = (v - best) / best
                counts = {s: list(status.get(k, ())).count(s) for s in set(status.get(k, ()))}
                print(f"| {model} | {path.name} | {k} | {int(np.sum(excess < 1e-6))}/{len(v)} | "
                      f"{np.max(excess):.2e} | "
                      f"{', '.join(f'{n} {s}' for s, n in sorted(counts.items()))} | "
                      f"{seconds.get(k, float('nan')):.2f} |", flush=True)


if __name__ == "__main__":
    main()
