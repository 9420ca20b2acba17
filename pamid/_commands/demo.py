"""``pamid demo``: the main job on the bundled data set (made by pamid's own virtual bench
from Sárosi Table 3-1): the fit beside Table 3-1, the hysteresis damping and the
diagnosis, written to ``--out`` (default demo-out)."""

from __future__ import annotations

import json
import time
from pathlib import Path

from .fit import fit_table


def register(subparsers) -> None:
    demo = subparsers.add_parser(
        "demo", help="fit the bundled virtual-bench data set, beside Table 3-1")
    demo.add_argument("--out", default="demo-out", help="folder for plots and demo.json")
    demo.add_argument("--seed", type=int, default=0, help="PRNG seed for the bootstrap")
    demo.set_defaults(func=run)


def run(args) -> int:
    import jax

    from .._data._bench import load_bench
    from .._fit._api import fit_least_squares
    from .._io import final_place, write_text_atomic
    from .._lanes._batch import pack
    from .._models._hysteresis import hysteresis_damping
    from .._models._sarosi import TABLE_3_1, TABLE_3_1_L0_MM, Sarosi, table_3_1_fit_json
    from .._units import KPA_PER_BAR
    from .._virtual._default import default_bench_path, default_protocol

    out = Path(args.out)
    path = default_bench_path()
    protocol = default_protocol()
    print(f"pamid demo — bundled virtual-bench data set: {path.name}")
    print(f"  simulated by pamid's virtual bench from Sárosi Table 3-1 (DMSP-20-400N, "
          f"l0 = {TABLE_3_1_L0_MM:g} mm), protocol: pressures {list(protocol.pressures_kPa)} kPa, "
          f"{protocol.points_per_curve} points per sweep, both directions, {protocol.repeats} "
          f"repeats averaged, noise {protocol.noise_sd_N} N, hysteresis "
          f"±{protocol.hysteresis_N_per_bar} N/bar.")
    bench = load_bench(path)
    t0 = time.perf_counter()
    result = fit_least_squares(bench, intervals=("wald", "profile", "bootstrap"),
                               n_bootstrap=1000, key=jax.random.key(args.seed))
    print(f"\nFit of both branches together ({time.perf_counter() - t0:.2f} s, compilation "
          "included), beside Table 3-1:\n")
    print(fit_table(result, published=TABLE_3_1))

    # Hysteresis branches and damping, Sárosi eq. 2.3–2.10, at 400 kPa with 50 kg.
    frame = bench.frame
    branches = {}
    for d, name in ((-1, "upper (extending)"), (1, "lower (contracting)")):
        sub = frame[frame["direction"] == d]
        data = pack([((sub["pressure_kPa"].to_numpy() / KPA_PER_BAR,
                       sub["contraction_pct"].to_numpy()), sub["force_N"].to_numpy())])
        branches[name] = fit_least_squares(data).theta[0]
    p_bar, mass = 4.0, 50.0
    k_hi = float(frame.loc[(frame.pressure_kPa == 400.0), "contraction_pct"].max())
    damping = hysteresis_damping(
        Sarosi.from_vector(branches["upper (extending)"]),
        Sarosi.from_vector(branches["lower (contracting)"]),
        p_bar, 0.0, k_hi, 12.5, TABLE_3_1_L0_MM / 1000.0, mass,
    )
    damping = {k: float(v) for k, v in damping.items()}
    print(f"Hysteresis damping at {p_bar * 100:g} kPa, loop over κ = 0 … {k_hi:.2f} %, "
          f"m = {mass:g} kg, stiffness at κ = 12.5 % (Sárosi eq. 2.3–2.10):")
    for key, value in damping.items():
        print(f"  {key:>22s} = {value:.6g}")

    # Closing the loop: what does eq. 2.1 miss in these data, and what does adding it gain?
    from .._diagnose._api import diagnose
    from .._report._diagnosis import constant_text, plot_diagnosis_residuals
    from .._report._fit import write_fit_plots

    diag = diagnose(bench)
    print("\nClosing the loop (pamid diagnose): the residual of eq. 2.1 against every covariate, "
          "each candidate effect refitted:")
    for row in diag.candidates[:4]:
        print(f"  {row['effect']:<26} ΔBIC {row['delta_bic']:>9.1f}   CV RMSE "
              f"{row['cv_rmse']:.3f} N   {'significant' if row['significant'] else ''}")
    print(f"  selected: {', '.join(diag.selected) or 'nothing'}; RMSE {diag.rmse_before:.3f} → "
          f"{diag.rmse_after:.3f} N, max error {diag.max_error_before:.2f} → "
          f"{diag.max_error_after:.2f} N; unexplained: {', '.join(diag.unexplained) or 'nothing'}")
    for name, consts in diag.constants[0]["effects"].items():
        for pname, c in consts.items():
            print(f"  {name} {pname} = {constant_text(c)}")

    out.mkdir(parents=True, exist_ok=True)
    plots = write_fit_plots(result, bench, out, 1)
    plot_diagnosis_residuals(diag, out / "diagnosis_residuals.png")
    plots.append("diagnosis_residuals.png")
    summary = result.to_dict()
    summary["source"] = str(path)
    summary["hysteresis_damping_400kPa_50kg"] = damping
    summary["diagnosis"] = {k: v for k, v in diag.to_dict().items()
                            if k in ("rmse_before", "rmse_after", "max_error_before",
                                     "max_error_after", "selected", "candidates",
                                     "constants", "unexplained")}
    summary["published_table_3_1"] = table_3_1_fit_json()["muscles"][0]["params"]
    summary["plots"] = plots
    write_text_atomic(out / "demo.json", json.dumps(summary, indent=2) + "\n")
    print(f"\nPlots and demo.json written to {final_place(out)}/: {', '.join(plots)}")
    return 0
