"""The `pamid` command end to end, in a subprocess, as a user meets it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import pamid

PAMID = [sys.executable, "-m", "pamid._cli"]


@pytest.fixture(scope="module")
def env(cli_env):
    return cli_env


def run(args, env, cwd=None):
    return subprocess.run(PAMID + args, capture_output=True, text=True, env=env, cwd=cwd,
                          timeout=600)


@pytest.fixture(scope="module")
def two_muscle_csv(tmp_path_factory):
    import jax
    import jax.numpy as jnp

    theta = np.asarray(pamid.sarosi.table_3_1().to_vector())
    thetas = jnp.asarray(np.stack([theta, theta * np.array([1.05, 0.97, 1.02, 1.0, 0.99, 1.01])]))
    frame = pamid.simulate_sarosi_bench(
        jax.random.key(7), pamid.Sarosi.from_vector(thetas),
        pamid.SarosiProtocol(min_force_N=10.0, pressures_kPa=(200.0, 400.0, 600.0)),
        muscle_ids=["left", "right"],
    )
    path = tmp_path_factory.mktemp("data") / "bench.csv"
    frame.to_csv(path, index=False)
    return path


def test_fit_json_schema(two_muscle_csv, env, tmp_path):
    before = two_muscle_csv.read_bytes()
    out = tmp_path / "out"
    res = run(["fit", str(two_muscle_csv), "--json", "--out", str(out)], env)
    assert res.returncode == 0, res.stderr
    payload = json.loads(res.stdout)  # exactly one JSON object
    assert payload["model"] == "sarosi"
    assert [m["muscle"] for m in payload["muscles"]] == ["left", "right"]
    for m in payload["muscles"]:
        assert isinstance(m["n"], int) and m["n"] == 180
        assert m["converged"] is True
        assert m["rmse_N"] > 0 and 0.999 < m["r"] <= 1.0
        assert list(m["params"]) == ["a1", "a2", "a3", "a4", "a5", "a6"]
        for p in m["params"].values():
            lo, hi = p["ci95"]
            assert lo < p["value"] < hi
            plo, phi = p["ci95_profile"]
            assert plo < p["value"] < phi
    # Plots and the JSON copy exist; the input file is untouched.
    for name in ("fit_left.png", "residuals_left.png", "fit_right.png", "rmse_histogram.png"):
        assert (out / name).stat().st_size > 10_000
    assert json.loads((out / "fit.json").read_text())["muscles"][0]["muscle"] == "left"
    assert two_muscle_csv.read_bytes() == before


def test_the_process_ends_with_the_commands_exit_code_and_whole_output(two_muscle_csv, env,
                                                                        tmp_path):
    """The command ends its process without the interpreter's teardown (_cli._end_process):
    stdout is complete, stderr has its lines, the exit code is the command's; a caller that
    runs a command in its own process through ``main`` gets the code back."""
    res = run(["fit", str(two_muscle_csv), "--json", "--intervals", "wald"], env)
    assert res.returncode == 0, res.stderr
    assert len(json.loads(res.stdout)["muscles"]) == 2  # the whole object, flushed
    bad = tmp_path / "bad.csv"
    bad.write_text("pressure_kPa,force_N,contraction_pct\n100,abc,1\n")
    res = run(["fit", str(bad), "--json"], env)
    assert res.returncode == 2 and "row 1" in res.stderr and "'abc'" in res.stderr
    script = ("from pamid._cli import main\n"
              f"code = main(['fit', {str(bad)!r}, '--json'])\n"
              "print('still here', code)\n")
    res = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env=env, timeout=600)
    assert res.returncode == 0 and res.stdout.strip() == "still here 2", res.stderr


def test_fit_table_and_bootstrap(two_muscle_csv, env):
    res = run(["fit", str(two_muscle_csv), "--bootstrap", "200", "--intervals", "wald"], env)
    assert res.returncode == 0, res.stderr
    assert "muscle left: n = 180" in res.stdout
    assert "bootstrap low" in res.stdout and "Wald intervals with Student-t" in res.stdout


def test_censored_rows_warn_and_single_muscle_gives_null_id(tmp_path, env):
    theta = pamid.sarosi.table_3_1()
    rows = [(p, k, float(pamid.sarosi.sarosi_force(theta, p / 100, k)))
            for p in (200.0, 300.0, 400.0, 500.0) for k in np.linspace(0, 15, 12)]
    frame = pd.DataFrame(rows, columns=["pressure_kPa", "contraction_pct", "force_N"])
    frame.loc[len(frame)] = (100.0, 24.0, 0.0)  # a censored point of a published map
    path = tmp_path / "map.csv"
    frame.to_csv(path, index=False)
    res = run(["fit", str(path), "--json", "--intervals", "wald"], env)
    assert res.returncode == 0, res.stderr
    assert "dropped 1 censored" in res.stderr
    payload = json.loads(res.stdout)
    assert payload["muscles"][0]["muscle"] is None
    assert payload["n_censored_dropped"] == 1
    np.testing.assert_allclose(payload["muscles"][0]["params"]["a3"]["value"],
                               pamid.sarosi.TABLE_3_1["a3"]["value"], rtol=1e-8)


@pytest.mark.parametrize(
    "content, expected",
    [
        (None, r"not found|does not exist|no such file"),
        ("", r"empty"),
        ("pressure_kPa,contraction_pct,force_N\n100,1,abc\n", r"column 'force_N', row 1"),
        ("pressure_atm,contraction_pct,force_N\n1,1,10\n", r"pressure_atm"),
    ],
)
def test_bad_input_exit_2_without_traceback(tmp_path, env, content, expected):
    path = tmp_path / "bad.csv"
    if content is not None:
        path.write_text(content)
    res = run(["fit", str(path), "--json"], env)
    assert res.returncode == 2
    assert "Traceback" not in res.stderr
    assert str(path) in res.stderr
    import re

    assert re.search(expected, res.stderr, re.IGNORECASE), res.stderr
    assert res.stdout == ""


def test_demo_writes_table_and_plots(tmp_path, env):
    out = tmp_path / "demo"
    res = run(["demo", "--out", str(out)], env)
    assert res.returncode == 0, res.stderr
    assert "published" in res.stdout and "zeta" in res.stdout
    # a slip element the fit held at 0 (absent) is said to be so, not printed as [nan, nan]
    assert "held at its bound: no interval" in res.stdout and "nan" not in res.stdout
    summary = json.loads((out / "demo.json").read_text())
    assert summary["muscles"][0]["converged"] is True
    # a slip weight's Wald interval crosses 0 on this file; it is cut at its physical bound
    # (a weight ≥ 0) and says so, in the JSON and in the text
    hyst = summary["diagnosis"]["constants"][0]["effects"]["hysteresis"]
    cut = {k: c for k, c in hyst.items() if c.get("ci95_cut_at_bound")}
    assert cut and all(c["ci95"][0] == 0.0 <= c["value"] <= c["ci95"][1] for c in cut.values())
    assert "(cut at its physical bound)" in res.stdout
    assert 0 < summary["hysteresis_damping_400kPa_50kg"]["zeta"] < 1
    assert (out / "fit_DMSP-20-400N.png").exists()


def test_bundled_default_data_is_what_the_virtual_bench_makes():
    from pamid._virtual._default import default_bench_path, simulate_default_bench

    bundled = pd.read_csv(default_bench_path())
    fresh = simulate_default_bench()
    assert list(bundled.columns) == list(fresh.columns)
    for col in ("pressure_kPa", "contraction_pct", "force_N", "direction", "time_s"):
        np.testing.assert_allclose(bundled[col].to_numpy(), fresh[col].to_numpy(), atol=1e-6)


def test_installed_command_exists():
    exe = Path(sys.executable).with_name("pamid")
    assert exe.exists(), "pip install should create the pamid command next to python"
