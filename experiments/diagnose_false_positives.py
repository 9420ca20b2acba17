"""False positives of ``pamid diagnose`` on clean virtual files of every protocol.

A clean file holds nothing the baseline model (Sárosi eq. 2.1) lacks — only the sensors'
noise and resolution — so any effect selected there is a false positive. The files are the
protocols real labs deliver (:func:`pamid.virtual_lab_file` and
:class:`pamid.SarosiProtocol`):

* ``sweeps``: Sárosi's sweeps, 5 repeats averaged, a direction column;
* ``sweeps_noisy``: every cycle its own trial whose clock restarts, ±1 kPa pressure noise,
  no direction column in every other file;
* ``isometric_stairs``: AARL's valve steps, trials restarting time, ±1 kPa pressure noise,
  no direction column in every other file;
* ``isometric_ramp``: the same with pressure ramps.

Every file of a protocol has the same size, so that the compiled refits are reused and a
file costs about a second. Prints a table and writes ``false_positives.json`` (every file:
protocol, seed, what was selected) to ``--out`` (default
``experiments/out/diagnose_false_positives/``).

``--detect N`` also hides each effect of the isometric tests in N isometric-stairs files
(the settings of ``tests/test_diagnose_effects.py``) and counts how often exactly that
effect is selected, and the RMSE after against the same file without the effect (the
noise); written to ``detection.json``.

    .venv/bin/python experiments/diagnose_false_positives.py --files 100 --detect 20
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import pamid  # noqa: E402
from pamid import diagnose, virtual_lab_file  # noqa: E402
from pamid.io import json_ready, write_frame_atomic, write_text_atomic  # noqa: E402

PROTOCOLS = ("sweeps", "sweeps_noisy", "isometric_stairs", "isometric_ramp")
ISO_CLEAN = {"transient_N_per_kPa": 0.0, "pressure_offset_kPa": 0.0,
             "hysteresis_N_at_3_bar": 0.0, "min_force_N": None}
#: Hidden effects of the detection study: (label, the effect that must be named, protocol
#: options, direction column kept).
HIDDEN = (
    ("hysteresis", "hysteresis", {"hysteresis_N_at_3_bar": 9.0}, True),
    # friction with memory, half height 2.8 times the file's error (about 2.4 N), issue #30
    ("maxwell_slip", "hysteresis",
     {"effects": (pamid.InjectedMaxwellSlip(N_at_3_bar=6.8),)}, False),
    ("transient", "transient",
     {"transient_N_per_kPa": 0.05, "transient_tau_s": 0.3, "dwell_s": 1.0}, False),
    ("softening", "softening", {"softening": 0.05, "softening_repeats": 1.0}, False),
    ("sensor_offset", "sensor_offset", {"pressure_offset_kPa": -30.0}, False),
    ("drift", "drift", {"effects": (pamid.InjectedDrift(N_per_hour=100.0),)}, False),
    ("temperature", "temperature", {"effects": (pamid.InjectedTemperature(),)}, False),
    # a rubber softening as it warms: −0.2 % of the force per kelvin (issue #30, item 2)
    ("temperature_relative", "temperature_relative",
     {"effects": (pamid.InjectedRelativeTemperature(per_K=-0.002),)}, False),
)
DETECT_ROWS = 1260


def detection(n_files: int, tmp: Path) -> dict:
    """Each hidden effect in ``n_files`` isometric-stairs files: how often exactly it is
    selected, and the RMSE after over the RMSE of the same file without it."""
    out = {}
    for label, name, options, keep_direction in HIDDEN:
        rows = []
        for i in range(n_files):
            seed = 9000 + i
            drop = () if keep_direction else ("direction",)
            paths = []
            for tag, opts in (("clean", {}), (label, options)):
                frame = virtual_lab_file(jax.random.key(seed), "isometric_stairs", DETECT_ROWS,
                                         drop_columns=drop, **(ISO_CLEAN | opts))
                paths.append(tmp / f"{tag}_{seed}.csv")
                write_frame_atomic(paths[-1], frame)
            clean, d = diagnose(paths[0]), diagnose(paths[1])
            rows.append({"seed": seed, "selected": d.selected,
                         "rmse_after_over_noise": d.rmse_after / clean.rmse_before})
            print(f"{label:<20} seed {seed}  selected: {', '.join(d.selected) or '-'}  "
                  f"RMSE after / noise {rows[-1]['rmse_after_over_noise']:.3f}", flush=True)
        ratio = np.array([r["rmse_after_over_noise"] for r in rows])
        out[label] = {"effect": name, "files": n_files,
                      "named_alone": sum(r["selected"] == [name] for r in rows),
                     "found": sum(name in r["selected"] for r in rows),
                     "rmse_after_over_noise_median": float(np.median(ratio)),
                     "rmse_after_over_noise_max": float(np.max(ratio)), "runs": rows}
    return out


def clean_file(protocol: str, seed: int, rows: int):
    """A clean virtual file of ``protocol`` (about ``rows`` rows), made from ``seed``."""
    key = jax.random.key(seed)
    if protocol == "sweeps":
        proto = pamid.SarosiProtocol(points_per_curve=max(4, rows // 10))
        return pamid.simulate_sarosi_bench(key, pamid.sarosi.table_3_1(), proto)
    drop = ("direction",) if seed % 2 else ()
    if protocol == "sweeps_noisy":
        return virtual_lab_file(key, "sweeps_noisy", rows, hysteresis_N_per_bar=0.0,
                                min_force_N=0.0, drop_columns=drop)
    return virtual_lab_file(key, protocol, rows, drop_columns=drop, **ISO_CLEAN)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--files", type=int, default=25, help="files per protocol")
    ap.add_argument("--rows", type=int, default=600, help="rows per file (about)")
    ap.add_argument("--protocols", nargs="*", default=list(PROTOCOLS), choices=PROTOCOLS)
    ap.add_argument("--detect", type=int, default=0,
                    help="files per hidden effect in the detection study (0: none)")
    ap.add_argument("--out", type=Path,
                    default=Path(__file__).parent / "out" / "diagnose_false_positives")
    args = ap.parse_args(argv)
    runs = []
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for protocol in args.protocols:
            for i in range(args.files):
                seed = 1000 * (PROTOCOLS.index(protocol) + 1) + i
                path = Path(tmp) / f"{protocol}_{seed}.csv"
                write_frame_atomic(path, clean_file(protocol, seed, args.rows))
                d = diagnose(path)
                runs.append({"protocol": protocol, "seed": seed, "rows": d.n,
                             "direction_column": not (seed % 2 and protocol != "sweeps"),
                             "selected": d.selected, "rmse_before_N": d.rmse_before,
                             "rmse_after_N": d.rmse_after})
                mark = ", ".join(d.selected) if d.selected else "-"
                print(f"{protocol:<17} seed {seed:>5}  rows {d.n:>5}  selected: {mark}",
                      flush=True)
    seconds = time.perf_counter() - start
    summary = {}
    for protocol in args.protocols:
        mine = [r for r in runs if r["protocol"] == protocol]
        fp = [r for r in mine if r["selected"]]
        summary[protocol] = {"files": len(mine), "false_positives": len(fp),
                             "selected": sorted({e for r in fp for e in r["selected"]})}
    total = sum(s["files"] for s in summary.values())
    total_fp = sum(s["false_positives"] for s in summary.values())
    print()
    print(f"{'protocol':<17} {'files':>6} {'false positives':>16}  effects selected")
    for protocol, s in summary.items():
        print(f"{protocol:<17} {s['files']:>6} {s['false_positives']:>16}  "
              f"{', '.join(s['selected']) or '-'}")
    print(f"{'all':<17} {total:>6} {total_fp:>16}  ({100.0 * total_fp / max(total, 1):.1f} "
          f"in 100; {seconds:.0f} s)")
    args.out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(args.out / "false_positives.json", json.dumps(json_ready({
        "files_per_protocol": args.files, "rows": args.rows, "summary": summary,
        "false_positives": total_fp, "files": total, "seconds": seconds, "runs": runs,
        "rate_per_100": 100.0 * total_fp / max(total, 1)}), indent=1))
    if args.detect:
        start = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            det = detection(args.detect, Path(tmp))
        print()
        print(f"{'effect':<20} {'files':>6} {'named alone':>12} {'found':>6}  RMSE after / noise "
              "(median, max)")
        for name, r in det.items():
            print(f"{name:<20} {r['files']:>6} {r['named_alone']:>12} {r['found']:>6}  "
                  f"{r['rmse_after_over_noise_median']:.3f}, {r['rmse_after_over_noise_max']:.3f}")
        print(f"({time.perf_counter() - start:.0f} s)")
        write_text_atomic(args.out / "detection.json", json.dumps(json_ready(det), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
