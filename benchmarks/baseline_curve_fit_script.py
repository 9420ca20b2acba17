"""What most users write: pandas + scipy.optimize.curve_fit, one muscle at a time.

The end-to-end baseline of ``benchmarks/fit_batch.py`` (section 6): read a bench CSV in
pamid's format (``muscle``, ``pressure_kPa``, ``contraction_pct``, ``force_N``), group the
rows by muscle, fit Sárosi eq. 2.1 to each muscle with ``curve_fit`` (numerical Jacobian,
default settings, started from the constants of Sárosi Table 3-1), and print one JSON
object with each constant's value and standard error. It deliberately does not import
pamid, as a user's own script would not.

    python benchmarks/baseline_curve_fit_script.py bench.csv > fit.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
import pandas as pd
from scipy.optimize import curve_fit

NAMES = ("a1", "a2", "a3", "a4", "a5", "a6")
# Sárosi Table 3-1 (DMSP-20-400N), used as the start for every muscle.
P0 = (-4.35572689, 281.2237983, -0.32866293, -9.27034945, 302.2010663, -263.691854)


def sarosi(x, a1, a2, a3, a4, a5, a6):
    p, k = x  # pressure in bar, contraction in %
    return (a1 * p + a2) * np.exp(a3 * k) + a4 * k * p + a5 * p + a6


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    frame = pd.read_csv(args.csv)
    if "muscle" not in frame:
        frame["muscle"] = None
    muscles = []
    for muscle, rows in frame.groupby("muscle", sort=False, dropna=False):
        p = rows["pressure_kPa"].to_numpy() / 100.0
        k = rows["contraction_pct"].to_numpy()
        y = rows["force_N"].to_numpy()
        popt, pcov = curve_fit(sarosi, (p, k), y, p0=P0)
        se = np.sqrt(np.diag(pcov))
        muscles.append(
            {
                "muscle": None if pd.isna(muscle) else str(muscle),
                "n": int(len(y)),
                "params": {
                    name: {"value": float(v), "se": float(s)}
                    for name, v, s in zip(NAMES, popt, se, strict=True)
                },
            }
        )
    out = {
        "model": "sarosi",
        "fitter": "scipy.optimize.curve_fit",
        "muscles": muscles,
        "seconds": time.perf_counter() - t0,
    }
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
