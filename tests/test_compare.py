"""``pamid compare`` and :func:`pamid._fit._compare.compare_models`.

Virtual data drawn from a known force law (with an interaction term) are compared against a
law without it: the true law must win by cross-validated RMSE and by BIC. The folds must
hold out whole trials (or whole curves), and a held-out row must not change the fit of its
own fold (it must change the others'). A model that did not converge is never "best". The
JSON shape, the table and the exit codes of the command; the measured Martens map when it
is present.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from force_models import PLANE_SOURCE, Plane, Quadratic

import pamid
from pamid._cli import main
from pamid._fit._compare import compare_models, fold_plan
from pamid._fit._spec import MODELS, spec_from_model

ROOT = Path(__file__).resolve().parents[1]
MARTENS = ROOT.parent / "shared" / "data" / "martens_dmsp10_250.csv"

PRESSURES_KPA = (100.0, 200.0, 300.0, 400.0, 500.0, 600.0)
TRUE = (5.0, 1.2, -12.0, 0.02)  # c0 [N], c1 [N/kPa], c2 [N/%], c3 [N/(kPa·%)]
NOISE_N = 1.0


class Interaction(Quadratic):
    """F = c0 + c1·p + c2·κ + c3·p·κ (the law the data are drawn from)."""

    name = "interaction"


class Redundant(pamid.ForceModel):
    """The true law with c1 split into two constants that only their sum determines: it
    fits as well as the truth, but its fit cannot converge (rank-deficient Jacobian)."""

    c0: float = 0.0
    c1: float = 1.0
    c1b: float = 0.0
    c2: float = -10.0
    c3: float = 0.0
    units = {"c0": "N", "c1": "N/kPa", "c1b": "N/kPa", "c2": "N/%", "c3": "N/(kPa*%)"}
    inputs = ("pressure_kPa", "contraction_pct")
    name = "redundant"

    def __call__(self, pressure_kPa, contraction_pct):
        return (self.c0 + (self.c1 + self.c1b) * pressure_kPa + self.c2 * contraction_pct
                + self.c3 * pressure_kPa * contraction_pct)


def _bench_frame(seed: int, trials: bool) -> pd.DataFrame:
    """Two muscles, a sweep of κ = 0…20 % (12 points) at each of six pressures; each sweep
    a trial of its own when ``trials``."""
    rng = np.random.default_rng(seed)
    rows = []
    for muscle, scale in (("A", 1.0), ("B", 0.8)):
        for t, p in enumerate(PRESSURES_KPA):
            kappa = np.linspace(0.0, 20.0, 12)
            c0, c1, c2, c3 = TRUE
            force = scale * (c0 + c1 * p + c2 * kappa + c3 * p * kappa)
            force = force + NOISE_N * rng.standard_normal(kappa.shape)
            for k, f in zip(kappa, force):
                row = {"muscle": muscle, "pressure_kPa": p, "contraction_pct": k,
                       "force_N": f}
                if trials:
                    row["trial"] = f"T{t}"
                rows.append(row)
    return pd.DataFrame(rows)


@pytest.fixture(scope="module")
def specs():
    specs = [spec_from_model(cls) for cls in (Interaction, Plane, Redundant)]
    return {spec.name: spec for spec in specs}


@pytest.fixture(scope="module")
def trial_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("compare") / "trials.csv"
    _bench_frame(1, trials=True).to_csv(path, index=False)
    return path


@pytest.fixture(scope="module")
def trial_bench(trial_csv):
    return pamid.load_bench(trial_csv)


@pytest.fixture(scope="module")
def trial_result(trial_bench, specs):
    return compare_models(trial_bench, [specs["interaction"], specs["plane"]])


def test_true_model_wins_by_cv_and_bic(trial_result):
    d = trial_result.to_dict()
    assert [m["muscle"] for m in d["muscles"]] == ["A", "B"]
    for mu in d["muscles"]:
        assert mu["cv"] == "trials" and mu["cv_folds"] == 5 and mu["cv_units"] == 6
        assert mu["best"] == "interaction"
        by = {m["model"]: m for m in mu["models"]}
        assert by["interaction"]["cv_rmse_N"] < by["plane"]["cv_rmse_N"]
        assert by["interaction"]["bic"] < by["plane"]["bic"]
        assert by["interaction"]["rank_cv"] == by["interaction"]["rank_bic"] == 1
        # the truth's held-out error is the noise, within sampling error
        assert 0.6 * NOISE_N < by["interaction"]["cv_rmse_N"] < 1.6 * NOISE_N
        assert by["interaction"]["rmse_N"] <= by["interaction"]["cv_rmse_N"]
        assert by["interaction"]["rmse_N"] < by["interaction"]["max_abs_error_N"] < 5 * NOISE_N
        # BIC is the formula it states
        m = by["plane"]
        sse = m["rmse_N"] ** 2 * m["n"]
        assert m["bic"] == pytest.approx(m["n"] * np.log(sse / m["n"]) + 3 * np.log(m["n"]))


def test_folds_hold_out_whole_trials_and_every_row_once(trial_bench, trial_result):
    plan = trial_result.plan
    trial = trial_bench.curves.trial
    muscle = trial_bench.frame["muscle"].to_numpy()
    assert np.all(plan.fold_of_row >= 0)  # every row is held out in some fold
    for mu in ("A", "B"):
        rows = muscle == mu
        for t in np.unique(trial[rows]):
            assert len(np.unique(plan.fold_of_row[rows & (trial == t)])) == 1
    # the CV error counts every row once
    for mc in trial_result.models:
        assert np.array_equal(mc.cv_n, mc.fit.n.astype(float))


def test_curves_are_held_out_without_trials(tmp_path, specs):
    path = tmp_path / "curves.csv"
    _bench_frame(2, trials=False).to_csv(path, index=False)
    bench = pamid.load_bench(path)
    plan = fold_plan(bench, 4)
    assert plan.kind == ("curves", "curves")
    assert list(plan.n_folds) == [4, 4] and list(plan.n_units) == [6, 6]
    curve = bench.curves.curve
    muscle = bench.frame["muscle"].to_numpy()
    for mu in ("A", "B"):
        for c in np.unique(curve[muscle == mu]):
            assert len(np.unique(plan.fold_of_row[(muscle == mu) & (curve == c)])) == 1


def test_one_curve_cannot_be_cross_validated(tmp_path):
    frame = _bench_frame(3, trials=False)
    frame = frame[frame["pressure_kPa"] == 300.0]  # one sweep per muscle
    path = tmp_path / "one.csv"
    frame.to_csv(path, index=False)
    plan = fold_plan(pamid.load_bench(path))
    assert plan.kind == (None, None) and list(plan.n_folds) == [0, 0]
    assert np.all(plan.fold_of_row == -1)


def test_a_held_out_row_does_not_touch_its_folds_fit(trial_bench, trial_result, specs,
                                                     tmp_path):
    plan = trial_result.plan
    frame = trial_bench.frame.copy()
    fold0_a = (frame["muscle"].to_numpy() == "A") & (plan.fold_of_row == 0)
    assert 0 < fold0_a.sum() < (frame["muscle"] == "A").sum()
    frame.loc[fold0_a, "force_N"] += 500.0  # a wild change of the rows held out in fold 0
    path = tmp_path / "changed.csv"
    frame[["muscle", "trial", "pressure_kPa", "contraction_pct", "force_N"]].to_csv(
        path, index=False)
    changed = compare_models(pamid.load_bench(path), [specs["interaction"], specs["plane"]])
    assert np.array_equal(changed.plan.fold_of_row, plan.fold_of_row)
    for before, after in zip(trial_result.models, changed.models, strict=True):
        # fold 0 of muscle A never saw those rows: the same constants
        np.testing.assert_allclose(after.fold_theta[0, 0], before.fold_theta[0, 0],
                                   rtol=1e-7, atol=1e-9)
        # the fit to all data and the other folds of A did see them
        assert not np.allclose(after.fit.theta[0], before.fit.theta[0], rtol=1e-3)
        assert not np.allclose(after.fold_theta[0, 1], before.fold_theta[0, 1], rtol=1e-3)
        # muscle B is untouched
        np.testing.assert_allclose(after.fit.theta[1], before.fit.theta[1], rtol=1e-7,
                                   atol=1e-9)
        # and the held-out error of A grew by the change
        assert after.cv_rmse_N[0] > 10 * before.cv_rmse_N[0]


def test_a_model_that_did_not_converge_is_never_best(trial_bench, specs):
    result = compare_models(trial_bench, [specs["redundant"], specs["plane"]])
    for i, mu in enumerate(result.to_dict()["muscles"]):
        by = {m["model"]: m for m in mu["models"]}
        assert by["redundant"]["converged"] is False
        assert by["redundant"]["status"] != "converged" and by["redundant"]["message"]
        assert mu["best"] == "plane"
        assert mu["models"][0]["model"] == "plane"  # converged fits ranked first
        assert result.best(i) == "plane"


def test_json_shape(trial_result):
    d = json.loads(json.dumps(trial_result.to_dict()))
    assert set(d) >= {"muscles", "models", "skipped", "bic", "source"}
    assert d["models"] == ["interaction", "plane"]
    for mu in d["muscles"]:
        assert set(mu) >= {"muscle", "best", "cv", "models"}
        for m in mu["models"]:
            assert set(m) >= {"model", "n_params", "rmse_N", "cv_rmse_N", "bic", "converged",
                              "status", "message"}
            assert isinstance(m["converged"], bool) and isinstance(m["n_params"], int)
        assert [m["n_params"] for m in mu["models"]] == [4, 3]


@pytest.fixture
def registered(monkeypatch, specs, tmp_path):
    """The test's laws registered as pamid's own for the command line (in this process)."""
    monkeypatch.setenv("PAMID_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("PAMID_DEBUG", raising=False)
    for name, spec in specs.items():
        monkeypatch.setitem(MODELS, name, spec)


def test_cli_json_table_and_out(trial_csv, registered, tmp_path, capsys):
    law = tmp_path / "law.py"
    law.write_text(PLANE_SOURCE)
    assert main(["compare", str(trial_csv), "--models", f"interaction,{law}:Plane",
                 "--json"]) == 0
    out, err = capsys.readouterr()
    d = json.loads(out)  # exactly one object
    assert d["models"] == ["interaction", "plane"]  # the file's class, by its name
    assert [mu["best"] for mu in d["muscles"]] == ["interaction", "interaction"]
    assert "model 1/2: interaction" in err  # progress on stderr

    assert main(["compare", str(trial_csv), "--models", "interaction,plane",
                 "--out", str(tmp_path / "cmp")]) == 0
    out, _ = capsys.readouterr()
    assert "best: interaction" in out and "CV on held-out whole trials" in out
    written = json.loads((tmp_path / "cmp" / "compare.json").read_text())
    assert written["plots"] == ["models_A.png", "models_B.png", "cv_rmse.png"]
    for name in written["plots"]:
        assert (tmp_path / "cmp" / name).stat().st_size > 10_000


def test_cli_exit_1_when_no_model_converged(trial_csv, registered, capsys):
    assert main(["compare", str(trial_csv), "--models", "redundant", "--json"]) == 1
    d = json.loads(capsys.readouterr().out)
    assert [mu["best"] for mu in d["muscles"]] == [None, None]


@pytest.mark.parametrize("models, match", [
    ("interaction,nosuchmodel", "unknown model 'nosuchmodel'"),
    ("missing_file.py:Law", "missing_file.py: cannot read the model file"),
    (",", "--models: name at least one model"),
])
def test_cli_bad_model_is_one_line_exit_2(trial_csv, registered, capsys, models, match):
    assert main(["compare", str(trial_csv), "--models", models]) == 2
    out, err = capsys.readouterr()
    lines = [s for s in err.splitlines() if s.strip()]
    assert len(lines) == 1 and match in lines[0] and "Traceback" not in err
    assert out == ""


def test_cli_model_input_missing_is_exit_2(trial_csv, registered, capsys):
    # Cullinan needs the contraction in mm: the file gives % without l0.
    assert main(["compare", str(trial_csv), "--models", "cullinan,plane"]) == 2
    err = capsys.readouterr().err
    assert "cullinan model needs contraction_mm" in err and "Traceback" not in err


@pytest.mark.skipif(not MARTENS.exists(), reason="measured data not present")
def test_martens_map(tmp_path, registered, capsys):
    code = main(["compare", str(MARTENS), "--models", "sarosi,chou_hannaford", "--json"])
    d = json.loads(capsys.readouterr().out)
    assert code == 0
    (mu,) = d["muscles"]
    assert mu["cv"] == "curves"  # a published grid: no trials
    assert mu["best"] == "sarosi"
    by = {m["model"]: m for m in mu["models"]}
    assert by["sarosi"]["n"] == 40 and by["sarosi"]["cv_rmse_N"] < by["chou_hannaford"][
        "cv_rmse_N"]


def test_bounds_per_model_and_for_every_model(trial_bench, specs):
    from pamid._commands._model import parse_bounds_per_model

    chosen = [specs["interaction"], specs["plane"]]
    bounds = parse_bounds_per_model("interaction.c3=0:0.01, c1=:1.1", chosen)
    # c3 only for the model named; c1 for both models that have it; the rest their own.
    assert bounds["interaction"] == ((-np.inf, -np.inf, -np.inf, 0.0),
                                     (np.inf, 1.1, np.inf, 0.01))
    assert bounds["plane"] == ((-np.inf,) * 3, (np.inf, 1.1, np.inf))
    result = compare_models(trial_bench, chosen, bounds=bounds)
    inter = result.models[0].fit
    # The data hold c3 = 0.02 (both muscles) and c1 = 1.2 (A) / 0.96 (B): the fits stop on
    # the bounds the data would cross, and say so.
    assert np.allclose(np.asarray(inter.theta)[:, 3], 0.01)
    assert np.asarray(inter.theta)[0, 1] <= 1.1 + 1e-12
    assert [inter.status_of(i) for i in range(2)] == ["at_bound", "at_bound"]
    assert np.asarray(result.models[1].fit.theta)[:, 1].max() <= 1.1 + 1e-12


@pytest.mark.parametrize("text, match", [
    ("nosuch=0:1", "no compared model has a constant 'nosuch'"),
    ("cullinan.A=0:1", "names a model not compared"),
    ("interaction.c3=1:0", "must be below the upper bound"),
])
def test_cli_bad_bounds_is_one_line_exit_2(trial_csv, registered, capsys, text, match):
    assert main(["compare", str(trial_csv), "--models", "interaction,plane",
                 "--bounds", text]) == 2
    err = capsys.readouterr().err
    lines = [s for s in err.splitlines() if s.strip()]
    assert len(lines) == 1 and match in lines[0] and "Traceback" not in err


def test_cli_bounds_reach_the_fits(trial_csv, registered, capsys):
    assert main(["compare", str(trial_csv), "--models", "interaction,plane",
                 "--bounds", "interaction.c3=0:0.01", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    for mu in d["muscles"]:
        status = {m["model"]: m["status"] for m in mu["models"]}
        assert status == {"interaction": "at_bound", "plane": "converged"}
