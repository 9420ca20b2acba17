"""What the size classes cost once compiled: a warm fit on rows padded to their class,
beside the same fit on exactly the rows (one process, warm calls, medians).

    .venv/bin/python benchmarks/padding_overhead.py
    .venv/bin/python benchmarks/padding_overhead.py --sizes 1,100,1000 --calls 40

The data are ``run.py``'s static rows (``fit_batch.make_data``: Sárosi eq. 2.1, Table 3-1 ±
3 %, 300 samples a muscle). ``pamid.pack_muscles`` packs them to their size class
(``pamid.engine.padded_rows``: 512 columns for one muscle, 312 for 100 or more); the exact
batch is a :class:`pamid.FitData` of 300 columns made by hand. Both are fitted by
``pamid.fit_least_squares`` (solve, statistics, Wald intervals), compiled first, then timed
``--calls`` times each, alternating. Prints the medians and their ratio, and checks that the
constants agree.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import jax
import numpy as np

import pamid

HERE = Path(__file__).resolve().parent


def exact_batch(groups) -> pamid.FitData:
    """The muscles as a batch of exactly their rows (all of one length here)."""
    n = max(len(y) for _, y in groups)
    assert all(len(y) == n for _, y in groups), "make_data gives muscles of one length"
    stack = lambda arrays: jax.device_put(np.stack(arrays))  # noqa: E731
    return pamid.FitData(x=(stack([x[0] for x, _ in groups]), stack([x[1] for x, _ in groups])),
                         y=stack([y for _, y in groups]), w=stack([np.ones(n)] * len(groups)),
                         curve=stack([np.zeros(n, dtype=np.int64)] * len(groups)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="1,100,1000", help="muscles")
    parser.add_argument("--calls", type=int, default=40)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(HERE))
    from fit_batch import make_data

    print(f"{'muscles':>7} {'rows':>5} {'class':>5}  {'exact':>9}  {'padded':>9}  ratio  "
          "max |Δθ|/|θ|")
    for m in (int(s) for s in args.sizes.split(",")):
        _, groups, _, _, _ = make_data(m)
        padded, exact = pamid.pack_muscles(groups), exact_batch(groups)
        fits = {}
        for name, data in (("exact", exact), ("padded", padded)):
            fits[name] = pamid.fit_least_squares(data, intervals=("wald",))  # compile
        times = {"exact": [], "padded": []}
        for _ in range(args.calls):
            for name, data in (("exact", exact), ("padded", padded)):
                t0 = time.perf_counter()
                pamid.fit_least_squares(data, intervals=("wald",))
                times[name].append(time.perf_counter() - t0)
        med = {k: statistics.median(v) for k, v in times.items()}
        diff = np.max(np.abs(fits["padded"].theta - fits["exact"].theta)
                      / np.abs(fits["exact"].theta))
        print(f"{m:>7} {exact.y.shape[1]:>5} {padded.y.shape[1]:>5}  {med['exact'] * 1e3:7.2f} ms"
              f"  {med['padded'] * 1e3:7.2f} ms  {med['padded'] / med['exact']:5.2f}  {diff:.1e}",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
