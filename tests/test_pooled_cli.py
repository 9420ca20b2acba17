"""``pamid compare --pooled`` and ``pamid predict`` (issue #31): the JSON contract, the
files, errors in one line; the measured AARL file (skipped where ../shared/data is absent).
The pooled models themselves: tests/test_pooled.py."""

from __future__ import annotations

import json
from pathlib import Path

import jax
import numpy as np
import pandas as pd
import pytest

import pamid
from pamid._cli import main
from pamid._virtual._population import simulate_population_bench

ROOT = Path(__file__).resolve().parents[1]
AARL = ROOT.parent / "shared" / "data" / "aarl_festo10mm_isometric.csv"
L0_TRAIN = tuple(np.geomspace(80.0, 400.0, 8))


def _write(frame: pd.DataFrame, path: Path) -> Path:
    frame.to_csv(path, index=False)
    return path


def _write_json(result, path: Path) -> Path:
    path.write_text(json.dumps(result.to_dict()))
    return path


@pytest.fixture(scope="module")
def population_file(tmp_path_factory):
    """Eight virtual muscles of the Bolen law, 5 % spread about it, 3 N noise."""
    frame = simulate_population_bench(jax.random.key(0), L0_TRAIN, spread=0.05, noise_N=3.0)
    return _write(frame, tmp_path_factory.mktemp("pop") / "population.csv")


@pytest.fixture(scope="module")
def population_comparison(population_file):
    return pamid.compare_pooled(pamid.load_bench(population_file), kinds=())


@pytest.mark.slow
def test_compare_pooled_json_contract_and_predict_cli(population_file, tmp_path, capsys):
    out = tmp_path / "cmp"
    code = main(["compare", str(population_file), "--pooled", "--json", "--out", str(out),
                 "--max-plots", "0"])
    assert code == 0
    payload = json.loads(capsys.readouterr().out)
    pooled = payload["pooled"]
    names = [e["model"] for e in pooled]
    assert set(names) == {"sarosi_shared", "sarosi_smooth", "sarosi_nearest", "bolen2026",
                          "bolen2026_lab_code"}
    rmse = [e["lomo_rmse_N"] for e in pooled if e["converged"]]
    assert rmse == sorted(rmse)  # ranked by LOMO RMSE
    for e in pooled:
        assert {"model", "lomo_rmse_N", "lomo_rmse_pct_fmax", "muscles"} <= set(e)
        assert [m["muscle"] for m in e["muscles"]] == [f"V{i:02d}" for i in range(8)]
        assert all(m["lomo_rmse_N"] > 0 for m in e["muscles"])
        fmax = payload["pooled_fmax_N"]
        assert e["lomo_rmse_pct_fmax"] == pytest.approx(100 * e["lomo_rmse_N"] / fmax)
    assert (out / "pooled_lomo.png").is_file()
    saved = json.loads((out / "compare.json").read_text())
    assert [e["model"] for e in saved["pooled"]] == names

    code = main(["predict", str(out / "compare.json"), "--l0-mm", "350", "--diameter-mm",
                 "10", "--pressure-kPa", "300,600", "--json", "--out", str(tmp_path / "p")])
    assert code == 0
    pred = json.loads(capsys.readouterr().out)
    assert pred["model"] == names[0] and pred["descriptors"]["l0_mm"] == 350.0
    assert len(pred["points"]) == 2 * 21
    for point in pred["points"]:
        assert 0.0 <= point["low_N"] <= point["force_N"] <= point["high_N"]
        if point["force_N"] > 0:
            assert point["low_N"] < point["force_N"] < point["high_N"]
    assert (tmp_path / "p" / "prediction.png").is_file()
    # The table, and a model named.
    assert main(["predict", str(out / "compare.json"), "--l0-mm", "120", "--model",
                 "sarosi_smooth"]) == 0
    assert "model sarosi_smooth" in capsys.readouterr().out


def test_predict_refuses_what_the_fit_cannot_say(population_file, population_comparison,
                                                 tmp_path, capsys):
    path = _write_json(population_comparison, tmp_path / "fit.json")
    assert main(["predict", str(path), "--l0-mm", "300", "--diameter-mm", "20"]) == 2
    err = capsys.readouterr().err
    assert "diameter_mm = 10" in err and "Traceback" not in err
    assert main(["predict", str(tmp_path / "none.json"), "--l0-mm", "300"]) == 2
    assert "no such file" in capsys.readouterr().err
    assert main(["predict", str(population_file), "--l0-mm", "300"]) == 2
    assert "not a JSON file" in capsys.readouterr().err
    assert main(["predict", str(path), "--l0-mm", "300", "--model", "nope"]) == 2
    assert "no pooled model 'nope'" in capsys.readouterr().err
    # Beyond the tested lengths: predicted, and said to be an extrapolation.
    entry = population_comparison.models[0].to_dict()
    assert "extrapolation" in pamid.predict_muscle(entry, l0_mm=600.0).notes[0]


def test_measured_aarl_file(tmp_path):
    """The AARL 10 mm file (every 10th row: the same six muscles, lengths 83–382 mm): the
    Bolen law at the lab code's coefficients and fitted, each muscle predicted from the
    other five (experiments/README.md §11 has the full file)."""
    if not AARL.is_file():
        pytest.skip(f"{AARL} absent")
    frame = pd.read_csv(AARL).iloc[::10]
    bench = pamid.load_bench(_write(frame, tmp_path / "aarl.csv"))
    result = pamid.compare_pooled(bench, kinds=())
    lab, fitted = result.model("bolen2026_lab_code"), result.model("bolen2026")
    assert len(lab.muscles) == 6
    assert 15.0 < lab.lomo_rmse_N < 30.0  # 22.2 N on the full file
    assert fitted.converged and 15.0 < fitted.lomo_rmse_N < 30.0
