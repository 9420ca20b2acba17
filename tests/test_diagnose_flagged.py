"""Issue #30, item 5: one muscle whose constant the data do not determine never refuses the
whole file.

Real isometric tests of five muscles, one tested at three contraction levels: ``pamid fit``
gave that muscle its best fit within bounds (a3 held on its bound), ``pamid diagnose`` exited
1 for the whole file. Here a virtual isometric file of three muscles, AARL's valve stairs
with a hidden inflate/deflate hysteresis (±9 N at 3 bar: h1 = 3 N/bar), the third muscle
clamped at 0, 10 and 20 % as set (no length noise, as AARL logs the set length) and its
10 % level's force 11 N low, so that the intercepts of its three levels fall, rise and no
exponential of eq. 2.1 fits them (a3 runs off, :mod:`tests.test_fit_status`): that muscle is
fitted within bounds, flagged, and diagnosed with the others (its hysteresis found too);
exit 0. A muscle with no usable fit at all (one pressure level) is left out, flagged, and
the others diagnosed (a file of such muscles alone is still refused:
``test_a_baseline_the_data_cannot_determine_is_not_diagnosed``).
"""

from __future__ import annotations

import json

import jax
import numpy as np
import pandas as pd
import pytest

import pamid
from pamid._diagnose._api import diagnose
from pamid._virtual._isometric import virtual_lab_file
from pamid.report import diagnosis_report

OPTIONS = dict(transient_N_per_kPa=0.0, pressure_offset_kPa=0.0, min_force_N=None,
               hysteresis_N_at_3_bar=9.0)


@pytest.fixture(scope="module")
def three_levels_file(tmp_path_factory):
    ab = virtual_lab_file(jax.random.key(5), "isometric_stairs", 1000, n_muscles=2,
                          muscle_ids=["A", "B"], **OPTIONS)
    c = virtual_lab_file(jax.random.key(6), "isometric_stairs", 400, muscle_ids=["C"],
                         levels=(0.0, 10.0, 20.0), level_unit="pct",
                         contraction_noise_pct=0.0, **OPTIONS)
    # Table 3-1's intercepts at 10 and 20 %: −253.2 and −263.3 N; 11 N off the 10 % level
    # puts it below the 20 % one.
    c.loc[c["contraction_pct"].round().eq(10.0), "force_N"] -= 11.0
    path = tmp_path_factory.mktemp("flagged") / "three_levels.csv"
    pd.concat([ab, c]).to_csv(path, index=False)
    return path


def test_the_muscle_is_not_identifiable_in_a_fit(three_levels_file):
    fit = pamid.fit_least_squares(pamid.load_bench(three_levels_file), intervals=("wald",))
    assert fit.status[:2] == ("converged", "converged")
    assert fit.status[2] == "not_identifiable"
    assert "best fit within bounds: a3 = -3 (at its lower bound)" in fit.message(2)


def test_one_unidentified_muscle_is_flagged_and_diagnosed_with_the_others(
        three_levels_file, tmp_path, capsys):
    # One diagnosis, through the command (it was run once as a library call and once more
    # as a command: 92 s and 60 s in one process, nearly all of each compiling, since the
    # command runs the exported programs): its JSON is the Diagnosis's to_dict(), its
    # report.txt diagnosis_report().
    from pamid._cli import main

    capsys.readouterr()
    assert main(["diagnose", str(three_levels_file), "--json", "--out", str(tmp_path)]) == 0
    printed = json.loads(capsys.readouterr().out)
    written = json.loads((tmp_path / "diagnosis.json").read_text())
    assert printed == written
    d = printed
    assert d["groups"] == ["A", "B", "C"]
    assert [f["muscle"] for f in d["muscles_flagged"]] == ["C"]
    flag = d["muscles_flagged"][0]
    assert flag["diagnosed"] and flag["status"] == "not_identifiable"
    assert flag["why"].startswith("a3 is not determined by these data")
    assert d["selected"] == ["hysteresis"]
    for entry in d["constants"]:  # the hysteresis of every muscle, C's included
        h1 = entry["effects"]["hysteresis"]["h1"]
        assert h1["ci95"][0] < 3.0 < h1["ci95"][1], entry["muscle"]
    assert [e["baseline_status"] for e in d["constants"]] == ["converged", "converged",
                                                             "not_identifiable"]
    assert d["constants"][2]["base"]["a3"] == pytest.approx(-3.0)  # held on its bound
    assert "flagged: muscle C: a3 is not determined" in (tmp_path / "report.txt").read_text()


def _map(rng, theta, pressures_bar, contractions_pct, muscle):
    p, k = (a.ravel() for a in np.meshgrid(pressures_bar, contractions_pct))
    force = np.asarray(pamid.sarosi.sarosi_force(pamid.Sarosi.from_vector(theta), p, k))
    return pd.DataFrame({"muscle": muscle, "pressure_kPa": 100.0 * p,
                         "force_N": force + rng.normal(0.0, 1.0, p.size),
                         "contraction_pct": k})


def test_a_muscle_with_no_usable_fit_is_left_out_and_the_others_diagnosed(tmp_path, theta31):
    rng = np.random.default_rng(3)
    grid = (np.linspace(1.0, 6.0, 11), np.linspace(0.0, 20.0, 9))
    frame = pd.concat([_map(rng, theta31, *grid, "A"), _map(rng, theta31, *grid, "B"),
                       _map(rng, theta31, [3.0], np.linspace(0.0, 20.0, 20), "one pressure")])
    path = tmp_path / "maps.csv"
    frame.to_csv(path, index=False)
    d = diagnose(path)
    assert d.groups == ["A", "B"]
    assert d.to_dict()["muscles_flagged"] == [
        {"muscle": "one pressure", "status": "not_identifiable",
         "why": d.muscles_flagged[0]["why"], "diagnosed": False}]
    assert "cannot determine all 6 constants" in d.muscles_flagged[0]["why"]
    assert d.selected == []
    assert "left out of the diagnosis" in diagnosis_report(d)
