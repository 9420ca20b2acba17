"""What a user writes to fit and look at a bench file: pandas, curve_fit and matplotlib.

The baseline of ``pamid fit FILE --out DIR`` in ``benchmarks/end_to_end.py``: read a bench
CSV in pamid's format (``muscle``, ``pressure_kPa``, ``contraction_pct``, ``force_N``), fit
Sárosi eq. 2.1 to each muscle with ``curve_fit`` (numerical Jacobian, started from Sárosi
Table 3-1, as ``baseline_curve_fit_script.py`` does), and save one figure per muscle: force
against pressure, the samples coloured by contraction level (the contraction rounded to
0.5 %), with the fitted model at each level drawn in the same colour. Prints one JSON
object with the constants and the figures written. It does not import pamid.

    python benchmarks/baseline_curve_fit_plots.py bench.csv OUTDIR
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy.optimize import curve_fit  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from baseline_curve_fit_script import NAMES, P0, sarosi  # noqa: E402


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("csv")
    parser.add_argument("out")
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    frame = pd.read_csv(args.csv)
    if "muscle" not in frame:
        frame["muscle"] = "muscle"
    muscles = []
    for muscle, rows in frame.groupby("muscle", sort=False):
        p_kpa = rows["pressure_kPa"].to_numpy()
        k = rows["contraction_pct"].to_numpy()
        y = rows["force_N"].to_numpy()
        popt, pcov = curve_fit(sarosi, (p_kpa / 100.0, k), y, p0=P0, maxfev=20000)

        fig, ax = plt.subplots(figsize=(7, 5))
        level = np.round(k * 2.0) / 2.0
        levels = np.unique(level)
        colours = plt.get_cmap("viridis")(np.linspace(0.0, 0.9, len(levels)))
        grid = np.linspace(0.0, p_kpa.max(), 200)
        for lev, colour in zip(levels, colours, strict=True):
            sel = level == lev
            ax.scatter(p_kpa[sel], y[sel], s=2, color=colour, alpha=0.4)
            ax.plot(grid, sarosi((grid / 100.0, np.full_like(grid, lev)), *popt), color=colour,
                    label=f"{lev:g} %")
        ax.set_xlabel("pressure (kPa)")
        ax.set_ylabel("force (N)")
        ax.set_title(f"Sárosi eq. 2.1 fit — {muscle}")
        ax.legend(title="contraction", fontsize="small")
        fig.tight_layout()
        name = f"fit_{muscle}.png"
        fig.savefig(out / name, dpi=100)
        plt.close(fig)
        muscles.append({
            "muscle": str(muscle),
            "n": int(len(y)),
            "rmse_N": float(np.sqrt(np.mean((sarosi((p_kpa / 100.0, k), *popt) - y) ** 2))),
            "params": {n: {"value": float(v), "se": float(s)}
                       for n, v, s in zip(NAMES, popt, np.sqrt(np.diag(pcov)), strict=True)},
            "plot": name,
        })
    json.dump({"model": "sarosi", "fitter": "scipy.optimize.curve_fit", "muscles": muscles,
               "seconds": time.perf_counter() - t0}, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
