"""Pooled models across muscles (issue #31): known population laws recovered, a new muscle's
95 % predictive interval covering 95 ± 3 % of held-out virtual muscles' rows, bad descriptors
named (tests/test_pooled_cli.py: the commands and the measured AARL file)."""

from __future__ import annotations

import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest

import pamid
from pamid._models._bolen import HUNT_LAB_CODE_10MM, f620_N, normalized_force
from pamid._models._sarosi import Sarosi, sarosi_force
from pamid._pooled._descriptors import muscle_descriptors
from pamid._pooled._spec import parse_roles, pooled_spec
from pamid._virtual._population import population_emax_pct, simulate_population_bench

L0_TRAIN = tuple(np.geomspace(80.0, 400.0, 8))
#: Sárosi's constants of a DMSP-10 (shared/data/README.md), the population law at l0 = 200 mm.
DMSP10 = (-9.2194029, 203.7012413, -0.34221042, -3.2255991, 109.2038216, -208.372034)
#: Their slopes per e-fold of l0 in the virtual Sárosi population (a2 and a5 only).
SLOPES = (0.0, 30.0, 0.0, 0.0, 10.0, 0.0)


def _write(frame: pd.DataFrame, path: Path) -> Path:
    frame.to_csv(path, index=False)
    return path


def _sarosi_law(p_kpa, ratio, l0, _emax):
    g = jnp.log(l0 / 200.0)
    consts = [a + b * g for a, b in zip(DMSP10, SLOPES, strict=True)]
    return sarosi_force(Sarosi(*consts), p_kpa / 100.0, 100.0 * ratio)


@pytest.fixture(scope="module")
def population_file(tmp_path_factory):
    """Eight virtual muscles of the Bolen law, 5 % spread about it, 3 N noise."""
    frame = simulate_population_bench(jax.random.key(0), L0_TRAIN, spread=0.05, noise_N=3.0)
    return _write(frame, tmp_path_factory.mktemp("pop") / "population.csv")


def test_bolen_law_passes_through_f620_and_vanishes_at_emax():
    c = HUNT_LAB_CODE_10MM
    # F_n(0, 1) = 1 exactly; F_n(1, 1) ≈ 0 (the lab code's fit: 0.011).
    assert float(normalized_force(0.0, 1.0, c["a0"], c["a1"], c["a3"])) == pytest.approx(1.0)
    assert abs(float(normalized_force(1.0, 1.0, c["a0"], c["a1"], c["a3"]))) < 0.02
    # F620 is maxBPAforce.m's P·a1′·atan(a2′·(l0 − c)·P) at P = 620 kPa (l0 in m there).
    l0_m = 0.25
    reference = 620.0 * 0.4895 * math.atan(0.03068 * (l0_m - 0.0075) * 620.0)
    assert float(f620_N(1000 * l0_m, c["a_N"], c["b_per_m"], c["c_mm"])) == pytest.approx(
        reference, rel=1e-12)
    # A ForceModel: pure JAX under jit, vmap and grad.
    law = pamid.Bolen2026()
    args = (jnp.array([300.0, 620.0]), jnp.array([0.05, 0.1]), jnp.array([100.0, 300.0]),
            jnp.array([0.16, 0.17]))
    np.testing.assert_allclose(jax.jit(law.__call__)(*args), law(*args), rtol=1e-12)
    np.testing.assert_allclose(jax.vmap(law.__call__)(*args), law(*args), rtol=1e-12)
    dfdp = jax.grad(lambda p: law(p, 0.05, 100.0, 0.16))(300.0)
    assert float(dfdp) == pytest.approx(float(law(300.0, 0.05, 100.0, 0.16)
                                              - law(0.0, 0.05, 100.0, 0.16)) / 300.0)


def test_pooled_spec_gives_each_row_its_muscles_constants():
    base = pamid.engine.get_model("sarosi")
    roles = parse_roles("a1=shared,a3=per_muscle", base.param_names)
    assert roles == ("shared", "smooth", "per_muscle", "smooth", "smooth", "smooth")
    spec = pooled_spec(base, roles, ("l0_mm",), 2)
    assert spec.param_names[:5] == ("a1", "a2", "a2_ln_l0_mm", "a3_m0", "a3_m1")
    theta = np.array([-9.0, 200.0, 30.0, -0.3, -0.4, -3.0, 0.0, 100.0, 10.0, -200.0, 0.0])
    p_bar, kappa = np.array([3.0, 5.0]), np.array([4.0, 8.0])
    muscle, g = np.array([0.0, 1.0]), np.array([0.0, 0.5])
    got = spec.predict(jnp.asarray(theta), (p_bar, kappa, muscle, g))
    expected = [sarosi_force(Sarosi(-9.0, 200.0 + 30.0 * gi, a3, -3.0, 100.0 + 10.0 * gi,
                                    -200.0), pi, ki)
                for pi, ki, gi, a3 in zip(p_bar, kappa, g, (-0.3, -0.4), strict=True)]
    np.testing.assert_allclose(np.asarray(got), np.asarray(expected), rtol=1e-12)
    with pytest.raises(ValueError, match="no constant 'a9'"):
        parse_roles("a9=shared", base.param_names)
    with pytest.raises(ValueError, match="ROLE one of"):
        parse_roles("a1=global", base.param_names)


def test_recovers_the_bolen_population_law(tmp_path):
    truth = pamid.Bolen2026()
    frame = simulate_population_bench(jax.random.key(1), L0_TRAIN, spread=0.0, noise_N=1.0)
    bench = pamid.load_bench(_write(frame, tmp_path / "pop.csv"))
    result = pamid.compare_pooled(bench, kinds=())
    fitted = result.model("bolen2026")
    assert fitted.converged
    for name, value in zip(fitted.param_names, fitted.theta, strict=True):
        assert value == pytest.approx(getattr(truth, name), rel=0.02), name
    # Every muscle on the law: a muscle left out is predicted to the noise.
    assert fitted.lomo_rmse_N == pytest.approx(1.0, abs=0.15)
    # The ε_max line through the muscles is the population's.
    e0, e1, l0_ref = fitted.emax
    np.testing.assert_allclose(e0 + e1 * np.log(np.array([100.0, 300.0]) / l0_ref),
                               population_emax_pct([100.0, 300.0]), rtol=1e-9)


def test_recovers_sarosi_constants_smooth_in_ln_l0(tmp_path):
    frame = simulate_population_bench(jax.random.key(2), L0_TRAIN, law=_sarosi_law,
                                      spread=0.0, noise_N=1.0)
    bench = pamid.load_bench(_write(frame, tmp_path / "pop.csv"))
    result = pamid.compare_pooled(bench, kinds=("smooth", "shared"), bolen=False)
    smooth, shared = result.model("sarosi_smooth"), result.model("sarosi_shared")
    assert smooth.converged and smooth.lomo_lanes_converged == 8
    assert smooth.lomo_rmse_N == pytest.approx(1.0, abs=0.2)
    assert shared.lomo_rmse_N > 5 * smooth.lomo_rmse_N  # one set for all lengths is wrong
    ref = smooth.descriptors.ref["l0_mm"]
    consts = dict(zip(smooth.param_names, smooth.theta, strict=True))
    for j, name in enumerate(("a1", "a2", "a3", "a4", "a5", "a6")):
        slope = consts[f"{name}_ln_l0_mm"]
        at_ref = DMSP10[j] + SLOPES[j] * math.log(ref / 200.0)
        assert consts[name] == pytest.approx(at_ref, rel=0.02, abs=0.02), name
        assert slope == pytest.approx(SLOPES[j], abs=0.03 * max(abs(DMSP10[j]), 1.0)), name


def test_predictive_interval_covers_95_percent_of_new_virtual_muscles(tmp_path):
    """60 virtual populations of 8 tested muscles (5 % spread, 3 N noise); 4 new muscles
    of each, of lengths drawn log-uniform in 90–380 mm, predicted from the pooled fit: the
    95 % predictive interval holds 95 ± 3 % of their rows."""
    rng = np.random.default_rng(7)
    inside = []
    for r in range(60):
        l0_new = np.exp(rng.uniform(math.log(90.0), math.log(380.0), 4))
        frame = simulate_population_bench(jax.random.key(100 + r), (*L0_TRAIN, *l0_new),
                                          spread=0.05, noise_N=3.0)
        names = sorted(frame["muscle"].unique())
        train = frame[frame["muscle"].isin(names[:8])]
        bench = pamid.load_bench(_write(train, tmp_path / "train.csv"))
        entry = pamid.compare_pooled(bench, kinds=()).model("bolen2026").to_dict()
        for _, rows in frame[frame["muscle"].isin(names[8:])].groupby("muscle"):
            pred = pamid.predict_muscle(entry, l0_mm=rows["l0_mm"].iloc[0],
                                        pressure_kPa=rows["pressure_kPa"].to_numpy(),
                                        contraction_pct=rows["contraction_pct"].to_numpy(),
                                        points=True)
            y = rows["force_N"].to_numpy()
            inside.append(np.mean((y >= pred.low_N) & (y <= pred.high_N)))
    assert len(inside) == 240
    assert 0.92 <= float(np.mean(inside)) <= 0.98


def test_bad_descriptors_name_column_and_row(population_file, tmp_path):
    frame = pd.read_csv(population_file)
    frame.loc[5, "diameter_mm"] = 12.0
    bench = pamid.load_bench(_write(frame, tmp_path / "bad.csv"))
    with pytest.raises(pamid.BenchDataError, match="one value per muscle") as err:
        muscle_descriptors(bench, ("diameter_mm",))
    assert err.value.column == "diameter_mm" and err.value.row == 6
    with pytest.raises(pamid.BenchDataError, match="not a column"):
        muscle_descriptors(bench, ("stiffness_N_mm",))
    two = frame[frame["muscle"].isin(["V00", "V01"])]
    with pytest.raises(pamid.BenchDataError, match="at least 3 muscles"):
        pamid.compare_pooled(pamid.load_bench(_write(two, tmp_path / "two.csv")))


def test_constant_descriptor_is_left_out_with_a_note(population_file):
    bench = pamid.load_bench(population_file)
    desc = muscle_descriptors(bench, ("l0_mm", "diameter_mm"))
    assert desc.used == ("l0_mm",) and desc.constant == {"diameter_mm": 10.0}
    assert "cannot be fitted" in desc.notes[0]
    # Not described, the diameter is still known (a prediction for another is refused), and
    # l620_mm, constant here neither, is not a descriptor.
    desc = muscle_descriptors(bench)
    assert desc.constant == {"diameter_mm": 10.0} and desc.notes == ()


def _two_diameters(tmp_path) -> Path:
    """Four 10 mm muscles of the Bolen law and four of the same lengths four times as
    strong, logged as 20 mm (force ∝ D0² at one pressure and strain, Chou & Hannaford 1996)."""
    l0 = tuple(np.geomspace(100.0, 400.0, 4))
    small = simulate_population_bench(jax.random.key(1), l0, spread=0.03, noise_N=2.0)
    big = simulate_population_bench(jax.random.key(2), l0, spread=0.03, noise_N=2.0,
                                    diameter_mm=20.0, muscle_ids=[f"W{i}" for i in range(4)])
    big["force_N"] *= 4.0
    path = tmp_path / "two_diameters.csv"
    pd.concat([small, big]).to_csv(path, index=False)
    return path


def test_several_diameters_nearest_takes_the_same_diameter_and_bolen_says_why_not(tmp_path):
    """A 100 mm muscle of 10 mm takes the constants of the nearest 10 mm muscle, not of the
    100 mm one of 20 mm (which predicted it at 415 N of RMSE); the Bolen law, whose F620(l0)
    is fitted per diameter, is skipped with the reason, not fitted across diameters."""
    bench = pamid.load_bench(_two_diameters(tmp_path))
    out = pamid.compare_pooled(bench, describe=("l0_mm", "diameter_mm"), kinds=("nearest",))
    (nearest,) = out.models
    by_muscle = {x["muscle"]: x["lomo_rmse_N"] for x in nearest.muscles}
    assert by_muscle["V00"] < 40.0 and by_muscle["W0"] < 4 * 40.0
    skipped = dict(out.skipped)
    assert "10, 20 mm" in skipped["bolen2026"]
    table = pamid.report.pooled_table(out)
    assert "V00" in table and "W0" in table  # muscles of one length told apart by name
    # A new muscle takes the constants of the nearest length of its own diameter.
    entry = nearest.to_dict()
    at = {"l0_mm": 200.0, "pressure_kPa": (600.0,), "contraction_pct": (0.0,), "points": True}
    f10 = pamid.predict_muscle(entry, descriptors={"diameter_mm": 10.0}, **at).force_N[0]
    f20 = pamid.predict_muscle(entry, descriptors={"diameter_mm": 20.0}, **at).force_N[0]
    assert 3.0 < f20 / f10 < 5.0
    with pytest.raises(ValueError, match="no tested muscle has diameter_mm = 15"):
        pamid.predict_muscle(entry, descriptors={"diameter_mm": 15.0}, **at)


def test_the_lab_codes_10_mm_coefficients_are_not_used_for_other_diameters(tmp_path):
    l0 = tuple(np.geomspace(100.0, 400.0, 4))
    big = simulate_population_bench(jax.random.key(3), l0, spread=0.03, noise_N=2.0,
                                    diameter_mm=20.0)
    big["force_N"] *= 4.0
    path = tmp_path / "twenty.csv"
    big.to_csv(path, index=False)
    out = pamid.compare_pooled(pamid.load_bench(path), kinds=())
    assert [m.model for m in out.models] == ["bolen2026"]
    assert "10 mm" in dict(out.skipped)["bolen2026_lab_code"]
