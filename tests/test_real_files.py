"""The measured files of ../shared/data, as a new user meets them: the commands run on the
file as it comes (trials whose clock restarts, a logged pressure with an offset and valve
transients) and write readable results. Skipped when the data are absent."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import matplotlib.image
import pytest

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
AARL = DATA / "aarl_festo10mm_isometric.csv"
MARTENS = DATA / "martens_dmsp10_250.csv"
PAMID = [sys.executable, "-m", "pamid._cli"]

pytestmark = pytest.mark.skipif(not AARL.exists(), reason="measured data not present")


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    cache = tmp_path_factory.mktemp("jax-cache")
    return {**os.environ, "PAMID_CACHE_DIR": str(cache), "JAX_PLATFORMS": "cpu"}


def run(args, env):
    return subprocess.run(PAMID + args, capture_output=True, text=True, env=env, timeout=900)


def test_fit_of_the_real_isometric_file_with_plots(tmp_path, env):
    before = AARL.read_bytes()
    out = tmp_path / "fit"
    proc = run(["fit", str(AARL), "--out", str(out), "--json"], env)
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


def test_diagnose_of_the_real_isometric_file(tmp_path, env):
    # A subsample of whole curves keeps the suite's time (the whole file: about 2 minutes,
    # 1.2 GB; benchmarks/README.md); the file is read as it comes.
    out = tmp_path / "diag"
    proc = run(["diagnose", str(AARL), "--json", "--max-rows", "8000", "--out", str(out)], env)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["rows_total"] == 61515
    assert 0 < doc["rows_used"] <= 8000
    assert "whole curves" in doc["subsample"]
    assert doc["rmse_after"] <= doc["rmse_before"]
    for name in ("diagnosis.json", "report.txt", "residuals_before_after.png",
                 "residual_time_order.png"):
        assert (out / name).stat().st_size > 0


@pytest.mark.skipif(not MARTENS.exists(), reason="measured data not present")
def test_fit_of_the_martens_force_map(tmp_path, env):
    proc = run(["fit", str(MARTENS), "--json", "--out", str(tmp_path / "m")], env)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    assert doc["n_censored_dropped"] > 0 and doc["muscles"][0]["converged"]
