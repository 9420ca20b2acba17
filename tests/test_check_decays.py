"""``pamid check-decays`` end to end on virtual decays, and the encoder-resolution gate of
the friction verdict (pamid._decays._analysis)."""

import argparse
import json
import math

import jax
import pytest

import pamid
from pamid._commands.check import register
from pamid._commands.dynamics import register as register_dynamics

J = 0.46


def run_cli(argv, capsys):
    parser = argparse.ArgumentParser(prog="pamid")
    sub = parser.add_subparsers(dest="command", required=True)
    register(sub)
    register_dynamics(sub)
    args = parser.parse_args(argv)
    code = args.func(args)
    return code, capsys.readouterr()


def test_no_friction_is_not_called_friction_when_pooled(tmp_path):
    """Three noiseless 12-bit decays without friction: the pooled map used to give
    T_c = 0.0012 N·m at p = 0.006; its amplitude loss is far below an encoder step."""
    osc = pamid.DampedOscillator.from_modal(zeta=0.05, natural_frequency_Hz=2.2,
                                            inertia_kg_m2=J)
    frame = pamid.simulate_decays(jax.random.key(0), osc, pamid.DecayProtocol())
    path = tmp_path / "decay.csv"
    frame.to_csv(path, index=False)
    report = pamid.analyze_decays(pamid.load_decay(path), J, fit=False)
    for est in report.decrement:
        assert est.amplitude_dependence["amplitude_dependent"] is False
    pooled = report.pooled.amplitude_dependence
    assert pooled["amplitude_dependent"] is False
    assert pooled["statistically_significant"] is True  # the p-value alone would flag it
    assert pooled["practically_significant"] is False
    assert pooled["coulomb_shift_rad"] < 0.1 * pooled["resolution_floor_rad"]
    assert pooled["resolution_floor_rad"] == pytest.approx(0.5 * 2 * math.pi / 4096)
    assert "Coulomb" not in pooled["note"] and "quantization" in pooled["note"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("check")
    osc = pamid.DampedOscillator.from_modal(0.05, 2.2, J, equilibrium_rad=0.01)
    protocol = pamid.DecayProtocol(n_trials=3, deflections_deg=(9.0, 6.0, -8.0),
                                   noise_sd_rad=0.5 * 2 * math.pi / 4096, hold_s=0.2)
    path = tmp / "decay.csv"
    pamid.simulate_decays(jax.random.key(3), osc, protocol).to_csv(path, index=False)
    return tmp, path


def test_check_decays_end_to_end(recorded, capsys):
    tmp, path = recorded
    code, cap = run_cli(["damping", str(path), "--inertia", str(J), "--json"], capsys)
    assert code == 0
    fit_json = tmp / "fit.json"
    fit_json.write_text(cap.out)
    out = tmp / "out"
    code, cap = run_cli(["check-decays", str(path), "--model-json", str(fit_json),
                         "--inertia", str(J), "--json", "--out", str(out)], capsys)
    assert code == 0
    payload = json.loads(cap.out)
    assert [r["trial"] for r in payload["trials"]] == ["1", "2", "3"]
    step = 2 * math.pi / 4096
    for r in payload["trials"]:
        assert r["model"] == f"trial {r['trial']}" and r["model_source"] == "trajectory fit"
        assert r["rms_error_rad"] < step  # within one encoder step
        assert abs(r["frequency_error_Hz"]) < 0.01
        assert abs(r["zeta_error"]) < 0.002
    assert sorted(payload["plots"]) == ["check_1.png", "check_2.png", "check_3.png"]
    assert (out / "check_1.png").stat().st_size > 10_000
    assert json.loads((out / "check_decays.json").read_text())["n_trials"] == 3


def test_wrong_model_shows_large_errors_and_text_output(recorded, capsys):
    tmp, path = recorded
    model = tmp / "wrong.json"
    model.write_text(json.dumps({"zeta": 0.1, "natural_frequency_Hz": 2.0}))
    code, cap = run_cli(["check-decays", str(path), "--model-json", str(model),
                         "--inertia", str(J), "--json"], capsys)
    assert code == 0
    for r in json.loads(cap.out)["trials"]:
        assert r["model"] == "pooled"
        assert r["zeta_error"] == pytest.approx(0.05, abs=0.003)
        assert r["frequency_error_Hz"] == pytest.approx(2.0 * math.sqrt(1 - 0.01) - 2.2 *
                                                        math.sqrt(1 - 0.0025), abs=0.01)
        assert r["rms_error_rad"] > 0.01
        assert r["zeta_within_recorded_ci95"] is False
    # k and c instead of ζ and f_n; text output.
    wn = 2 * math.pi * 2.2
    model.write_text(json.dumps({"stiffness_Nm_per_rad": J * wn**2,
                                 "damping_Nms_per_rad": 2 * 0.05 * J * wn}))
    code, cap = run_cli(["check-decays", str(path), "--model-json", str(model),
                         "--inertia", str(J)], capsys)
    assert code == 0 and "RMS" in cap.out and "pooled" in cap.out
    model.write_text(json.dumps({"foo": 1}))
    with pytest.raises(ValueError, match="neither zeta"):
        run_cli(["check-decays", str(path), "--model-json", str(model), "--inertia", "0.46"],
                capsys)


@pytest.mark.slow
def test_check_decays_with_posterior_draws(recorded, capsys):
    """--posterior-draws: MCMC per trial, draws simulated in one call, band and coverage."""
    tmp, path = recorded
    code, cap = run_cli(["damping", str(path), "--inertia", str(J), "--json"], capsys)
    assert code == 0
    (tmp / "fit_pd.json").write_text(cap.out)
    out = tmp / "check_pd"
    code, cap = run_cli(["check-decays", str(path), "--model-json", str(tmp / "fit_pd.json"),
                         "--inertia", str(J), "--posterior-draws", "50", "--seed", "1",
                         "--json", "--out", str(out)], capsys)
    assert code == 0
    payload = json.loads(cap.out)
    for row in payload["trials"]:
        post = row["posterior"]
        assert post["draws"] == 50 and post["converged"]
        assert 0.85 <= post["band95_coverage"] <= 1.0  # noise: half an encoder step + rounding
        lo, hi = post["zeta"]["eti95"]
        assert lo < 0.05 < hi
    assert (out / f"predictive_{payload['trials'][0]['trial']}.png").exists()
