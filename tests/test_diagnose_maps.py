"""Issue #30, item 6: in a force map with no time, the structure is named by the covariate
that carries it, never ``time_order``, and the covariate term can be selected.

A 60-point map (10 pressures × 6 contractions of a DMSP-10 muscle, Sárosi eq. 2.1 with the
constants ../shared/data/README.md quotes, plus 8·sin(π·z) N of z the contraction scaled to
[−1, 1]: a shape in the contraction that eq. 2.1 lacks; 2 N noise), published as tables
are: no time, rows sorted by contraction, then by pressure. Before: the folds held out whole
contraction levels (the curves of such a table), eq. 2.1 alone predicted a held-out level
at a CV RMSE of 96 N, nothing was selected, and the report named ``time_order``; on the
same map sorted by pressure the covariate's refit ran out of steps in a flat valley (a2 and
the Legendre terms trade off) and was not selected either.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import pamid
from pamid._diagnose._api import diagnose
from pamid._diagnose._result import unexplained
from pamid.report import diagnosis_report

DMSP10 = np.array([-9.2194029, 203.7012413, -0.34221042, -3.2255991, 109.2038216,
                   -208.372034])
MARTENS = Path(__file__).resolve().parents[2] / "shared" / "data" / "martens_dmsp10_250.csv"


def _map(path, contraction_first: bool):
    rng = np.random.default_rng(1)
    pressures, contractions = np.linspace(150.0, 600.0, 10), np.arange(0.0, 16.0, 3.0)
    if contraction_first:
        k, p = (a.ravel() for a in np.meshgrid(contractions, pressures, indexing="ij"))
    else:
        p, k = (a.ravel() for a in np.meshgrid(pressures, contractions, indexing="ij"))
    force = np.asarray(pamid.sarosi.sarosi_force(pamid.Sarosi.from_vector(DMSP10),
                                                 p / 100.0, k))
    force = force + 8.0 * np.sin(np.pi * (k - 7.5) / 7.5) + rng.normal(0.0, 2.0, p.size)
    frame = pd.DataFrame({"muscle": "M", "pressure_kPa": p, "contraction_pct": k,
                          "force_N": force.round(2)})
    frame[frame["force_N"] > 0].to_csv(path, index=False)
    return path


@pytest.mark.parametrize("contraction_first", [True, False], ids=["by_contraction",
                                                                 "by_pressure"])
def test_contraction_structure_of_a_map_is_selected_by_its_covariate(tmp_path,
                                                                     contraction_first):
    d = diagnose(_map(tmp_path / "map.csv", contraction_first))
    assert not d.order_is_time and d.to_dict()["order_is_time"] is False
    assert d.selected == ["covariate:contraction_pct"]
    assert d.rmse_after < 0.6 * d.rmse_before
    assert d.cv_rmse_after < 0.7 * d.cv_rmse_before < 3.5  # interpolation, not 96 N
    assert "time_order" not in d.unexplained
    assert "never by a time order" in diagnosis_report(d)


def _analysis(shares: dict[str, tuple[float, float]], white: bool) -> dict:
    p = 0.5 if white else 1e-6
    return {"covariates": {c: {"p_value": pv, "explained_fraction": share}
                           for c, (pv, share) in shares.items()},
            "runs": {"p_value": p}, "ljung_box": {"p_value": p, "lag1_autocorrelation": 0.4}}


def test_a_map_names_the_covariate_that_carries_its_row_order_structure():
    # contraction p = 0.002 (24 % of the variance): below the 1e-3 of "unexplained" alone
    a = _analysis({"pressure_kPa": (0.3, 0.05), "contraction_pct": (0.002, 0.24),
                   "direction": (1e-9, 0.5)}, white=False)
    assert unexplained(a) == ["direction", "time_order"]
    assert unexplained(a, order_is_time=False) == ["direction", "contraction_pct"]
    quiet = _analysis({"pressure_kPa": (0.3, 0.05), "contraction_pct": (0.2, 0.04)},
                      white=False)
    assert unexplained(quiet, order_is_time=False) == []  # nothing carries it: not named
    white = _analysis({"contraction_pct": (0.002, 0.24)}, white=True)
    assert unexplained(white, order_is_time=False) == []


def test_time_order_still_named_where_rows_have_time(tmp_path):
    """Sweeps with a time column keep their time order (the curve finder's order)."""
    from pamid._diagnose._static import order_is_time

    frame = pamid.simulate_sarosi_bench(
        __import__("jax").random.key(0), pamid.sarosi.table_3_1(),
        pamid.SarosiProtocol(min_force_N=10.0))
    bench = pamid.load_bench(_write(tmp_path / "sweeps.csv", frame))
    assert order_is_time([bench.curves])
    no_time = pamid.load_bench(_write(tmp_path / "no_time.csv", frame.drop(columns="time_s")))
    assert order_is_time([no_time.curves])  # sweeps out and back: the order of a motion


def _write(path, frame):
    frame.to_csv(path, index=False)
    return path


def test_martens_map_is_a_map(tmp_path):
    if not MARTENS.exists():
        pytest.skip(f"{MARTENS} absent")
    with pytest.warns(pamid.CensoredRowsWarning):  # its 45 censored rows
        d = diagnose(MARTENS)
    assert not d.order_is_time
    assert "time_order" not in d.unexplained


def test_a_map_gets_no_time_order_plot(tmp_path, capsys):
    """`pamid diagnose --out` on a map wrote residual_time_order.png, a residual 'in time
    order' for rows that have none; it writes the other outputs and says why not that one."""
    from pamid._cli import main

    out = tmp_path / "diag"
    assert main(["diagnose", str(_map(tmp_path / "map.csv", True)), "--json",
                 "--out", str(out)]) == 0
    written = {p.name for p in out.iterdir() if not p.name.startswith(".")}  # not the manifest
    assert written == {"diagnosis.json", "report.txt", "residuals_before_after.png"}
    assert "no residual_time_order.png: the rows are a map" in capsys.readouterr().err
