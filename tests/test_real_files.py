"""The measured files of ../shared/data, as a new user meets them: the commands run on the
file as it comes (trials whose clock restarts, a logged pressure with an offset and valve
transients) and write readable results. Skipped when the data are absent."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.image
import numpy as np
import pytest

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
AARL = DATA / "aarl_festo10mm_isometric.csv"
MARTENS = DATA / "martens_dmsp10_250.csv"

pytestmark = pytest.mark.skipif(not AARL.exists(), reason="measured data not present")


def test_fit_of_the_real_isometric_file_with_plots(tmp_path, pamid_cli):
    before = AARL.read_bytes()
    out = tmp_path / "fit"
    proc = pamid_cli(["fit", str(AARL), "--out", str(out), "--json"])
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    doc = json.loads(proc.stdout)
    assert [m["n"] for m in doc["muscles"]] == [11184, 10089, 10950, 10463, 9596, 9233]
    assert all(m["converged"] for m in doc["muscles"])
    # the scale the data README gives for a SciPy fit of both branches: 10-15 N
    assert all(5.0 < m["rmse_N"] < 20.0 for m in doc["muscles"])
    assert len(doc["plots"]) == 13
    for name in doc["plots"]:
        image = matplotlib.image.imread(out / name)
        assert image.shape[0] > 300 and image.shape[1] > 300
    assert AARL.read_bytes() == before  # the input is never written


def test_diagnose_of_the_real_isometric_file(tmp_path, pamid_cli):
    # A subsample of whole curves keeps the suite's time (the whole file: about a minute,
    # 1.5 GB; benchmarks/README.md, the diagnose_aarl row); the file is read as it comes.
    # 6,000 rows keep two curves of every setting (4 contraction levels × 2 directions) of
    # every muscle, one row in 8 of them (test_max_rows_keeps_every_level below).
    out = tmp_path / "diag"
    proc = pamid_cli(["diagnose", str(AARL), "--json", "--max-rows", "6000", "--out", str(out)])
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["rows_total"] == 61515
    assert 0 < doc["rows_used"] <= 6000
    assert "of 96 of 144 curves" in doc["subsample"]
    assert doc["rmse_after"] <= doc["rmse_before"]
    for name in ("diagnosis.json", "report.txt", "residuals_before_after.png",
                 "residual_time_order.png"):
        assert (out / name).stat().st_size > 0


@pytest.mark.skipif(not MARTENS.exists(), reason="measured data not present")
def test_fit_of_the_martens_force_map(tmp_path, pamid_cli):
    proc = pamid_cli(["fit", str(MARTENS), "--json", "--out", str(tmp_path / "m")])
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["n_censored_dropped"] > 0 and doc["muscles"][0]["converged"]


@pytest.mark.skipif(not AARL.exists(), reason="measured data not present")
def test_max_rows_keeps_every_level_of_every_muscle():
    """A new user's --max-rows 6000 kept two curves per muscle, both at one contraction
    level: the baseline could not be determined and diagnose stopped (exit 2)."""
    import pamid
    from pamid._diagnose._api import subsample_curves

    bench = pamid.load_bench(AARL)
    sub, note = subsample_curves(bench, 6000)
    assert len(sub.frame) <= 6000 and "of 96 of 144 curves" in note
    kept = bench.frame["source_row"].isin(sub.frame["source_row"]).to_numpy()

    def levels(rows):  # distinct held contraction levels of each muscle (the file's curves)
        muscle = bench.frame["muscle"].to_numpy()
        return {m: len(np.unique(np.round(bench.curves.level[rows & (muscle == m)], 1)))
                for m in bench.muscles}

    assert levels(kept) == levels(np.ones_like(kept)) == dict.fromkeys(bench.muscles, 4)
