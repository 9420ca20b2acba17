"""experiments/close_the_loop_aarl.py --quick on the measured AARL 10 mm file: it runs, and
its summary.json agrees with what is known of the file (data README) and with itself.

The quick run is the one notebook 04 makes: the notebook is executed here, top to bottom
(also without the file), and the checks read what its run wrote; the file's checks are
skipped when the file is absent (it is never copied into the repository)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "experiments" / "close_the_loop_aarl.py"
NOTEBOOK = ROOT / "notebooks" / "04_close_the_loop.ipynb"
DATA = ROOT.parent / "shared" / "data" / "aarl_festo10mm_isometric.csv"
#: Resting lengths of the six muscles (data README: 83–382 mm; LoadAll10mmData_New.m).
L0_MM = {"Festo10mm_lc10cm": 83.0, "Festo10mm_lc15cm": 132.0, "Festo10mm_lc20cm": 182.0,
         "Festo10mm_lc25cm": 233.0, "Festo10mm_lc30cm": 281.0, "Festo10mm_lc40cm": 382.0}


def _script():
    spec = importlib.util.spec_from_file_location("close_the_loop_aarl", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def notebook(tmp_path_factory, run_notebook):
    """The folder notebook 04 wrote into (its ``tempfile.mkdtemp()``), after it ran."""
    folder = tmp_path_factory.mktemp("notebook04")
    run_notebook(NOTEBOOK, folder)
    return folder


@pytest.fixture(scope="module")
def quick(notebook):
    if not DATA.is_file():
        pytest.skip(f"{DATA} absent")
    summaries = list(notebook.glob("*/close_the_loop_aarl/summary.json"))
    assert len(summaries) == 1, summaries
    return summaries[0].parent, json.loads(summaries[0].read_text())


@pytest.mark.slow
def test_notebook_04_runs_top_to_bottom(notebook):
    # It ran in the fixture (a failing cell raises there); its virtual bench files are there.
    assert len(list(notebook.glob("*/bench_two_effects.csv"))) == 1


def test_absent_file_is_skipped_with_exit_0(tmp_path, capsys):
    assert _script().main(["--data", str(tmp_path / "none.csv"), "--out",
                           str(tmp_path / "out")]) == 0
    assert capsys.readouterr().out.startswith("skipped: file absent")
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_the_file_as_the_readme_describes_it(quick):
    _, s = quick
    assert s["n_muscles_in_file"] == 6
    assert s["n_rows_in_file"] == 61515
    assert s["l0_mm"] == L0_MM
    assert s["muscles"] == ["Festo10mm_lc10cm", "Festo10mm_lc40cm"]
    assert s["n_rows_diagnosed"] == 2 * s["rows_per_muscle"] == 4400


@pytest.mark.slow
def test_baseline_and_diagnosis(quick):
    _, s = quick
    for m, b in s["baseline"].items():
        assert b["converged"] and b["n"] == 2200
        # The data README: a per-muscle Sárosi fit leaves "about 10–15 N" (all rows).
        assert 8.0 < b["rmse_N"] < 16.0, (m, b["rmse_N"])
        assert b["max_error_N"] > 3 * b["rmse_N"]  # the slack starts of contracted trials
        for name, c in b["params"].items():
            lo, hi = c["ci95_cluster"]
            assert lo <= c["value"] <= hi, (m, name)
        assert b["residual_lag1"] > 0.3  # correlated within curves (README: 0.55–0.87)
    fits = [s["diagnosis_pooled"], *s["diagnosis_per_muscle"].values()]
    assert set(s["diagnosis_per_muscle"]) == set(s["muscles"])
    for d in fits:
        assert d["rmse_after_N"] <= d["rmse_before_N"]
        assert d["cv_rmse_after_N"] <= d["cv_rmse_before_N"]
        for e in d["selected"]:
            column = e["effect"].split(":", 1)[1] if ":" in e["effect"] else None
            if column in ("src_row", "source_row"):
                assert "not physical" in e["kind"]  # never passed off as a finding
    # The pooled diagnosis starts from the same baseline as the per-muscle fits.
    n = sum(b["n"] for b in s["baseline"].values())
    sse = sum(b["rmse_N"] ** 2 * b["n"] for b in s["baseline"].values())
    assert s["diagnosis_pooled"]["rmse_before_N"] == pytest.approx((sse / n) ** 0.5, rel=1e-4)


@pytest.mark.slow
def test_bins_cover_every_row(quick):
    _, s = quick
    bins = s["bins"]
    n = s["n_rows_diagnosed"]
    assert sum(r["n"] for r in bins["by_level_and_pressure"]) == n
    assert sum(r["n"] for r in bins["by_time_since_step"]) == n
    assert {r["level"] for r in bins["by_level_and_pressure"]} == {0, 1, 2, 3}  # 4 lengths
    assert [r["repeat"] for r in bins["by_repeat"]] == [0, 1, 2]  # 3 repeats per length
    for table in ("by_level_and_pressure", "by_time_since_step", "by_repeat"):
        for r in bins[table]:
            assert r["rmse_before_N"] >= abs(r["mean_before_N"])
    assert s["unexplained_text"]


@pytest.mark.slow
def test_length_study_on_six_lengths(quick):
    _, s = quick
    ls = s["length_study"]
    assert ls["muscles"] == list(L0_MM) and ls["l0_mm"] == list(L0_MM.values())
    assert ls["cv"] == "trials" and ls["n_folds"] == 5
    opts = {o["name"]: o for o in ls["options"]}
    assert [opts[k]["n_params"] for k in ("per_muscle", "smooth_linear", "smooth_log",
                                          "pooled")] == [36, 12, 12, 6]
    # One set of constants for all six lengths is far worse on held-out trials than one
    # fit per muscle: the forces of these muscles differ by more than eq. 2.1 can share.
    assert opts["pooled"]["cv_rmse_N"] > 1.5 * opts["per_muscle"]["cv_rmse_N"]
    assert ls["best"] != "pooled"
    for o in opts.values():
        assert o["rmse_N"] <= o["cv_rmse_N"] * 1.05
    assert "any length" in ls["verdict"]


@pytest.mark.slow
def test_plots_and_report_written(quick):
    out, s = quick
    assert sorted(s["plots"]) == sorted(["force_vs_pressure_before_after.png",
                                         "residual_vs_time_since_step.png",
                                         "residual_vs_repeat.png", "constants_vs_l0.png"])
    for name in s["plots"]:
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = (out / "report.txt").read_text()
    assert "What stays unexplained" in text and "Length study" in text
