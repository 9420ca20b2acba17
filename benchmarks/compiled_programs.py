"""Compiled programs read back from disk against lowering each for JAX's cache (issue 29).

    .venv/bin/python benchmarks/compiled_programs.py
    .venv/bin/python benchmarks/compiled_programs.py --rounds 5 --json compiled.json
    .venv/bin/python benchmarks/compiled_programs.py --layer prefetch

`pamid fit`, `compare` and `diagnose` on one-muscle files, each command a process of its
own as a user runs it, on one warm cache (``PAMID_CACHE_DIR`` of the benchmark's own, filled
by a first run of each command on each file), with the layer that keeps each compiled
program beside its exported one (``pamid/_lanes/_export_cache.py``, ``.xla`` entries) on
and off (``PAMID_COMPILED_CACHE=off``: every program is converted to MLIR, hashed and
looked up in JAX's cache, as before that layer). The two settings alternate, round after
round, so that the machine's state moves both alike; medians are printed, with SciPy's
script on the same file (``baseline_scipy_wald.py``) measured in the same run as the
reference a user has: the ratio is pamid's time over the script's.

With ``--layer prefetch``, the layer compared is the other one: the programs the last run
of the same kind called, read back on a thread of their own while the command computes
(``_export_cache.expect``), on and off (``PAMID_PREFETCH=off``: each is read where it is
first called), with the compiled programs read back in both.

Files: the bundled data set (300 rows), a virtual one-muscle file of 713 rows and, where
``../shared/data`` is beside the repository, the Martens & Boblan force map (85 rows) and
every 8th row of one AARL muscle (``Festo10mm_lc20cm``, 1,369 rows), as ``latency.py``
takes them.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import statistics
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

from latency import one_muscle_files, run, scipy_time  # noqa: E402

COMMANDS = ("fit", "compare", "diagnose")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--commands", default=",".join(COMMANDS))
    parser.add_argument("--json", metavar="PATH")
    parser.add_argument("--layer", choices=("compiled", "prefetch"), default="compiled",
                        help="compare the compiled programs read back (default) or their "
                             "prefetch, on and off")
    args = parser.parse_args(argv)
    commands = [c for c in args.commands.split(",") if c]
    py = sys.executable
    tmp = Path(tempfile.mkdtemp(prefix="pamid-compiled-"))
    base = {**os.environ, "PAMID_CACHE_DIR": str(tmp / "cache")}
    files = {"bundled, 300 rows": ROOT / "pamid" / "data" / "sarosi_dmsp20_400_virtual.csv",
             "virtual, 713 rows": one_muscle_files(tmp, 713, 1713, base, py)["A"]}
    shared = ROOT.parent / "shared" / "data"
    if shared.is_dir():
        import pandas as pd

        files["Martens map, 85 rows"] = shared / "martens_dmsp10_250.csv"
        aarl = pd.read_csv(shared / "aarl_festo10mm_isometric.csv")
        one = tmp / "aarl_lc20cm_every8.csv"
        aarl[aarl["muscle"] == "Festo10mm_lc20cm"].iloc[::8].to_csv(one, index=False)
        files["AARL muscle, 1,369 rows"] = one
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    switch = {"compiled": "PAMID_COMPILED_CACHE", "prefetch": "PAMID_PREFETCH"}[args.layer]
    words = {"compiled": ("read back", "lowered"), "prefetch": ("read ahead", "on call")}[
        args.layer]
    print(f"{'compiled programs read back' if args.layer == 'compiled' else 'programs read ahead'}"
          f", {date}; {os.cpu_count()} CPUs; load average {os.getloadavg()[0]:.2f}", flush=True)
    settings = {"on": base, "off": {**base, switch: "off"}}
    rows = []
    for label, path in files.items():
        ref = scipy_time(py, path, base, tmp, args.rounds)
        for command in commands:
            cmd = [py, "-m", "pamid", command, str(path), "--json"]
            first = run(cmd, settings["on"], tmp)  # compiles, keeps both kinds of entry
            times = {"on": [], "off": []}
            for r in range(args.rounds):
                for name in (("off", "on") if r % 2 else ("on", "off")):
                    rec = run(cmd, settings[name], tmp)
                    if rec["rc"] != 0:
                        raise SystemExit(f"{command} {path} ({name}) exited {rec['rc']}: "
                                         f"{rec['stderr']}")
                    times[name].append(rec["wall_s"])
            on, off = (statistics.median(times[k]) for k in ("on", "off"))
            row = {"file": label, "command": command, "first_run_s": round(first["wall_s"], 2),
                   "read_back_s": [round(t, 3) for t in times["on"]],
                   "lowered_s": [round(t, 3) for t in times["off"]],
                   "scipy_s": round(ref, 3), "ratio_read_back": round(on / ref, 2),
                   "ratio_lowered": round(off / ref, 2), "saved_s": round(off - on, 3)}
            rows.append(row)
            print(f"  {label:<24} {command:<9} {words[0]} {on:5.2f} s "
                  f"({row['ratio_read_back']:.2f}× SciPy)  {words[1]} {off:5.2f} s "
                  f"({row['ratio_lowered']:.2f}×)  saved {off - on:+.2f} s  SciPy {ref:.2f} s",
                  flush=True)
    print(f"load average at the end {os.getloadavg()[0]:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps({"date": date, "layer": args.layer,
                                               "rows": rows}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
