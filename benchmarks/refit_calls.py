"""How many lane-samples one compiled call of the diagnosis's refits should take: a warm
``pamid.diagnose`` at several ``CALL_LANE_SAMPLES``, alternating in one process.

    .venv/bin/python benchmarks/refit_calls.py
    .venv/bin/python benchmarks/refit_calls.py --samples 65536,8192 --rounds 3 FILE.csv ...

A call's Levenberg–Marquardt loop runs until its slowest lane ends; a refit in a flat
valley takes every step of the budget (``pamid.engine.DIAGNOSIS_MAX_STEPS``), and the other
lanes of its call compute those steps with it. The fewer lanes a call takes, the fewer wait.
Without files: the measured AARL muscle (every 8th row of ``Festo10mm_lc20cm`` from
``../shared/data``, where it is beside the repository), two virtual one-muscle files (the
bundled data set's protocol, 713 and 2,000 rows) and the bundled file. Each setting is run
once to compile, then ``--rounds`` times, the settings alternating; prints the times, and
checks that every setting selects the same effects with the same RMSE (to 1e-9).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
AARL = ROOT.parent / "shared" / "data" / "aarl_festo10mm_isometric.csv"
BUNDLED = ROOT / "pamid" / "data" / "sarosi_dmsp20_400_virtual.csv"


def default_files(folder: Path) -> list[Path]:
    import jax
    import numpy as np
    import pandas as pd

    import pamid

    files = []
    if AARL.exists():
        aarl = pd.read_csv(AARL)
        path = folder / "aarl_lc20cm_every8.csv"
        aarl[aarl["muscle"] == "Festo10mm_lc20cm"].iloc[::8].to_csv(path, index=False)
        files.append(path)
    proto = pamid.SarosiProtocol(min_force_N=10.0, noise_sd_N=2.0, hysteresis_N_per_bar=3.0,
                                 points_per_curve=750)
    frame = pamid.simulate_sarosi_bench(jax.random.key(7), pamid.sarosi.table_3_1(), proto,
                                        muscle_ids=["DMSP-20-400N"])
    rng = np.random.default_rng(2)
    for n in (713, 2000):
        path = folder / f"virtual_{n}.csv"
        frame.iloc[np.sort(rng.choice(len(frame), n, replace=False))].to_csv(path, index=False)
        files.append(path)
    return [*files, BUNDLED]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*", type=Path)
    parser.add_argument("--samples", default="65536,16384,8192,4096",
                        help="lane-samples a call, comma-separated")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    import pamid
    from pamid.engine import diagnosis_call_lane_samples

    settings = [int(s) for s in args.samples.split(",")]
    with tempfile.TemporaryDirectory() as tmp:
        files = args.files or default_files(Path(tmp))
        print(f"refit_calls: lane-samples a call {args.samples}; rounds {args.rounds}")
        for path in files:
            bench = pamid.load_bench(path)
            times = {s: [] for s in settings}
            outcome = {}
            for round_ in range(args.rounds + 1):  # round 0 compiles
                for s in settings:
                    t0 = time.perf_counter()
                    with diagnosis_call_lane_samples(s):
                        d = pamid.diagnose(bench)
                    if round_:
                        times[s].append(time.perf_counter() - t0)
                    outcome[s] = (tuple(d.selected), d.rmse_after)
            first = outcome[settings[0]]
            same = all(o[0] == first[0] and math.isclose(o[1], first[1], rel_tol=1e-9)
                       for o in outcome.values())
            print(f"{path.name} ({len(bench.frame)} rows): "
                  f"selected {list(first[0])}, RMSE after {first[1]:.4f} N, "
                  f"{'the same for every setting' if same else 'DIFFERS between settings'}")
            for s in settings:
                shown = ", ".join(f"{t:.2f}" for t in times[s])
                print(f"  {s:>7} lane-samples a call: {shown} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
