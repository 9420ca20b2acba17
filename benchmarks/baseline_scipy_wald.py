"""The script a user writes for one new file: pandas + curve_fit, three starts, Wald intervals.

Reads a bench CSV in pamid's format (``muscle`` optional, ``pressure_kPa``,
``contraction_pct``, ``force_N``), fits Sárosi eq. 2.1 to each muscle with
``scipy.optimize.curve_fit`` from three starts (Sárosi Table 3-1 with a3 = −0.1, −0.3 and
−1.0 %⁻¹), keeps the one of least SSE, and prints one JSON object with each constant's
value, standard error and Student-t 95 % interval. It does not import pamid, as a user's
own script would not; ``benchmarks/latency.py`` times it beside ``pamid fit``.

    python benchmarks/baseline_scipy_wald.py bench.csv > fit.json
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings

import numpy as np
import pandas as pd
from scipy import stats
from scipy.optimize import OptimizeWarning, curve_fit

NAMES = ("a1", "a2", "a3", "a4", "a5", "a6")
TABLE_3_1 = (-4.35572689, 281.2237983, -0.32866293, -9.27034945, 302.2010663, -263.691854)
A3_STARTS = (-0.1, -0.3, -1.0)


def sarosi(x, a1, a2, a3, a4, a5, a6):
    p, k = x  # pressure in bar, contraction in %
    return (a1 * p + a2) * np.exp(a3 * k) + a4 * k * p + a5 * p + a6


def fit_one(p, k, y):
    best = None
    for a3 in A3_STARTS:
        start = list(TABLE_3_1)
        start[2] = a3
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", OptimizeWarning)
                popt, pcov = curve_fit(sarosi, (p, k), y, p0=start, maxfev=20000)
        except RuntimeError:
            continue
        sse = float(np.sum((sarosi((p, k), *popt) - y) ** 2))
        if best is None or sse < best[2]:
            best = (popt, pcov, sse)
    return best


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv")
    args = parser.parse_args(argv)
    frame = pd.read_csv(args.csv)
    if "muscle" not in frame:
        frame["muscle"] = None
    muscles = []
    for muscle, rows in frame.groupby("muscle", sort=False, dropna=False):
        p = rows["pressure_kPa"].to_numpy() / 100.0
        k = rows["contraction_pct"].to_numpy()
        y = rows["force_N"].to_numpy()
        best = fit_one(p, k, y)
        if best is None:
            muscles.append({"muscle": None if pd.isna(muscle) else str(muscle), "n": len(y),
                            "converged": False})
            continue
        popt, pcov, sse = best
        se = np.sqrt(np.diag(pcov))
        t = stats.t.ppf(0.975, len(y) - len(popt))
        muscles.append({
            "muscle": None if pd.isna(muscle) else str(muscle),
            "n": int(len(y)),
            "rmse_N": float(np.sqrt(sse / len(y))),
            "params": {name: {"value": float(v), "se": float(s),
                              "ci95": [float(v - t * s), float(v + t * s)]}
                       for name, v, s in zip(NAMES, popt, se, strict=True)},
        })
    json.dump({"model": "sarosi", "fitter": "scipy.optimize.curve_fit, 3 starts",
               "muscles": muscles}, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
