"""The public model protocol, pamid.ForceModel: a user's force law fits as written.

The Quadratic of the issue is fitted from Python and from the command line (``--model
file.py:Class``), by least squares and by MCMC; its constants are recovered on virtual data
within their intervals; a nonlinear law starts by itself from far off; a model written
wrong ends in one line that names the file and the line.
"""

from __future__ import annotations

import json

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest
from force_models import QUADRATIC_SOURCE, Quadratic

import pamid
from pamid._fit._spec import CULLINAN, SAROSI, ModelDefinitionError, get_model, spec_from_model
from pamid._fit._start import linear_constants

TRUE = {"c0": 5.0, "c1": 1.2, "c2": -12.0, "c3": 0.01}
NOISE_N = 2.0


class Decaying(pamid.ForceModel):
    """A saturating law: F = a·p·exp(b·κ) + c (a test model, two constants linear)."""

    a: float = 1.0
    b: float = -0.05
    c: float = 0.0
    units = {"a": "N/bar", "b": "1/%", "c": "N"}
    inputs = ("pressure_bar", "contraction_pct")
    bounds = {"b": (-2.0, 0.0)}

    def __call__(self, pressure_bar, contraction_pct):
        return self.a * pressure_bar * jnp.exp(self.b * contraction_pct) + self.c


def _sweeps(model, n_muscles, rng, noise=NOISE_N):
    """A bench frame of sweeps at five pressures, the force from ``model`` plus noise."""
    rows = []
    for m in range(n_muscles):
        for p_kpa in (100.0, 200.0, 300.0, 400.0, 500.0):
            kappa = np.linspace(0.0, 20.0, 30)
            inputs = {"pressure_kPa": p_kpa, "pressure_bar": p_kpa / 100.0,
                      "contraction_pct": kappa}
            force = np.asarray(model(*(inputs[i] for i in type(model).inputs)))
            force = force + rng.normal(0.0, noise, kappa.size)
            rows += [(f"M{m}", p_kpa, k, f) for k, f in zip(kappa, force)]
    return pd.DataFrame(rows, columns=["muscle", "pressure_kPa", "contraction_pct", "force_N"])


def _load(frame, tmp_path):
    path = tmp_path / "bench.csv"
    frame.to_csv(path, index=False)
    return pamid.load_bench(path)


@pytest.fixture(scope="module")
def quadratic_csv(tmp_path_factory):
    folder = tmp_path_factory.mktemp("quadratic")
    (folder / "models.py").write_text(QUADRATIC_SOURCE)
    frame = _sweeps(Quadratic(**TRUE), 2, np.random.default_rng(7))
    frame.to_csv(folder / "bench.csv", index=False)
    return folder


def test_the_issue_file_fits_from_the_command_line(quadratic_csv, pamid_cli):
    out = pamid_cli(["fit", quadratic_csv / "bench.csv", "--model",
                     f"{quadratic_csv / 'models.py'}:Quadratic", "--json"])
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert doc["model"] == "quadratic"
    assert doc["units"] == {"force": "N", "pressure": "kPa", "contraction": "%"}
    for muscle in doc["muscles"]:
        assert muscle["converged"]
        assert list(muscle["params"]) == ["c0", "c1", "c2", "c3"]
        assert muscle["params"]["c3"]["unit"] == "N/(kPa*%)"
        for name, value in TRUE.items():
            lo, hi = muscle["params"][name]["ci95"]
            assert lo < value < hi, (name, lo, value, hi)


def test_the_issue_file_samples_by_mcmc_from_the_command_line(quadratic_csv, pamid_cli):
    out = pamid_cli(["fit", quadratic_csv / "bench.csv", "--model",
                     f"{quadratic_csv / 'models.py'}:Quadratic", "--method", "mcmc", "--json",
                     "--seed", "3"])
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    assert set(doc["prior"]) == {"c0", "c1", "c2", "c3", "sigma"}
    for muscle in doc["muscles"]:
        for name, value in TRUE.items():
            lo, hi = muscle["params"][name]["hdi95"]
            assert lo < value < hi, (name, lo, value, hi)
            # The posterior mean sits by the least-squares optimum (flat priors).
            ls = muscle["params"][name]["ls"]
            width = hi - lo
            assert abs(muscle["params"][name]["value"] - ls["value"]) < 0.1 * width


def test_wald_intervals_cover_the_true_constants_on_virtual_muscles(tmp_path):
    """40 virtual muscles: each constant inside its 95 % interval about 95 % of the time."""
    bench = _load(_sweeps(Quadratic(**TRUE), 40, np.random.default_rng(11)), tmp_path)
    result = pamid.fit_least_squares(bench, Quadratic)
    assert result.converged.all()
    assert result.param_names == ("c0", "c1", "c2", "c3")
    truth = np.array(list(TRUE.values()))
    inside = (result.ci95[..., 0] < truth) & (truth < result.ci95[..., 1])
    coverage = inside.mean(axis=0)
    assert np.all(coverage >= 0.85), coverage  # binomial(40, 0.95): P(< 34) ≈ 0.2 %
    # The least-squares answer of a linear model: the same as a direct solve.
    f = bench.for_muscle("M0")
    p, k = f["pressure_kPa"].to_numpy(), f["contraction_pct"].to_numpy()
    design = np.column_stack([np.ones_like(p), p, k, p * k])
    direct = np.linalg.lstsq(design, f["force_N"].to_numpy(), rcond=None)[0]
    np.testing.assert_allclose(result.theta[0], direct, rtol=1e-9, atol=1e-9)


def test_a_linear_law_is_solved_in_one_step_and_kept_within_bounds(tmp_path):
    """A model linear in every constant is fitted by its one Gauss–Newton step (the
    weighted least-squares solve): one step, the optimum of an iterated fit; where the
    optimum lies past a bound, the bounded loop takes over and marks the constant."""
    bench = _load(_sweeps(Quadratic(**TRUE), 3, np.random.default_rng(4)), tmp_path)
    spec = get_model(Quadratic)
    free = pamid.fit_least_squares(bench, Quadratic)
    assert free.converged.all() and (free.n_steps == 1).all()
    data = pamid.bench_to_fit_data(bench, Quadratic)
    iterated = pamid.engine.solve(spec, data, theta0=free.theta + 1.0)  # optimistix, iterated
    np.testing.assert_allclose(free.theta, iterated[0], rtol=1e-10)
    bounded = pamid.fit_least_squares(bench, Quadratic, bounds=(
        np.array([-np.inf, -np.inf, -np.inf, -np.inf]), np.array([np.inf, np.inf, -13.0, np.inf])))
    assert (bounded.theta[:, 2] == -13.0).all()
    assert set(bounded.status) == {"at_bound"}


def test_a_start_first_made_inside_a_trace_holds_no_tracer():
    """The generic start is made on first use and kept by the spec; made while a caller is
    traced (an exported program, say), it must hold no tracer for the calls after."""

    class Fresh(Decaying):
        pass

    spec = get_model(Fresh)
    spec.linear()  # known before the trace, as fit_lanes asks it
    x = (jnp.linspace(1.0, 5.0, 40)[None], jnp.linspace(0.0, 20.0, 40)[None])
    y = 100.0 * x[0] * jnp.exp(-0.1 * x[1]) + 3.0
    w = jnp.ones_like(y)
    traced = jax.jit(lambda x, y, w: spec.candidates(x, y, w)[0])(x, y, w)
    again = spec.candidates(x, y, w)[0]  # an UnexpectedTracerError here was the leak
    np.testing.assert_allclose(again, traced, rtol=1e-12)


def test_a_nonlinear_law_starts_by_itself_far_from_its_defaults(tmp_path):
    truth = Decaying(a=300.0, b=-0.3, c=-40.0)  # defaults: a = 1, b = -0.05, c = 0
    bench = _load(_sweeps(truth, 3, np.random.default_rng(5), noise=1.0), tmp_path)
    result = pamid.fit_least_squares(bench, Decaying)
    assert result.converged.all()
    # At the global optimum: within 4 standard errors of the truth (a local optimum or a
    # start left where it was would be hundreds of them away).
    z = (result.theta - np.array([300.0, -0.3, -40.0])) / result.se
    assert np.all(np.abs(z) < 4.0), z
    assert result.spec.source.startswith("A saturating law")
    assert result.spec.units == {"force": "N", "pressure": "bar", "contraction": "%"}


def test_inputs_in_other_units_are_converted_exactly(tmp_path):
    """pressure_bar is pressure_kPa / 100, bit for bit, as the Sárosi kernels need."""
    bench = _load(_sweeps(Quadratic(**TRUE), 1, np.random.default_rng(1)), tmp_path)
    x = SAROSI.x_from_frame(bench.frame)
    assert np.array_equal(x[0], bench.frame["pressure_kPa"].to_numpy() / 100.0)


def test_linear_constants_are_found_from_second_derivatives():
    from pamid._models._sarosi import Sarosi

    assert SAROSI.model_class is Sarosi and SAROSI.kernels is not None
    linear = linear_constants(SAROSI.predict, 6, ("pressure_bar", "contraction_pct"),
                              [-4.0, 280.0, -0.3, -9.0, 300.0, -260.0])
    assert linear.tolist() == [True, True, False, True, True, True]
    linear = linear_constants(CULLINAN.predict, 5, ("pressure_kPa", "contraction_mm"),
                              [0.0] * 5)
    assert linear.all()
    spec = get_model(Decaying)
    assert linear_constants(spec.predict, 3, Decaying.inputs, [1.0, -0.05, 0.0]).tolist() == [
        True, False, True]


def test_builtin_models_are_force_models_like_any_other():
    from pamid._models._cullinan import Cullinan
    from pamid._models._sarosi import Sarosi, table_3_1

    assert issubclass(Sarosi, pamid.ForceModel) and issubclass(Cullinan, pamid.ForceModel)
    assert get_model(Sarosi) is SAROSI
    model = table_3_1()
    f = model(jnp.array([3.0]), jnp.array([10.0]))
    np.testing.assert_allclose(f, SAROSI.predict(model.to_vector(), (3.0, 10.0)))
    # Fields marked static are settings, not constants.

    class WithSetting(pamid.ForceModel):
        r0_mm: float = eqx.field(static=True, default=5.0)
        k: float = 1.0
        units = {"k": "N/(kPa*mm^2)"}
        inputs = ("pressure_kPa",)

        def __call__(self, pressure_kPa):
            return self.k * pressure_kPa * self.r0_mm**2

    spec = spec_from_model(WithSetting)
    assert spec.param_names == ("k",)
    np.testing.assert_allclose(spec.predict(jnp.array([2.0]), (jnp.array([10.0]),)), 500.0)


@pytest.mark.parametrize("body, message", [
    ("class A(pamid.ForceModel):\n    c: float = 1.0\n    inputs = ('pressure_kPa',)\n"
     "    def __call__(self, p):\n        return self.c * p\n",
     r"A\.units has no unit for c"),
    ("class A(pamid.ForceModel)\n    c: float = 1.0\n",
     r"models\.py, line 2: syntax error"),
    ("class A(pamid.ForceModel):\n    c: float = 1.0\n    units = {'c': 'N'}\n"
     "    inputs = ('pressure_kPa',)\n    def __call__(self, p):\n"
     "        return self.c * not_defined\n",
     r"models\.py, line 7: A\.__call__ failed on test inputs \(NameError"),
    ("class A(pamid.ForceModel):\n    c: float = 1.0\n    units = {'c': 'N'}\n"
     "    inputs = ('pressure_kPa',)\n    def __call__(self, p):\n        return self.c\n",
     r"returned shape \(\) for inputs of shape \(8,\)"),
    ("class B(pamid.ForceModel):\n    pass\n", r"no class 'A'; pamid\.ForceModel classes in it: B"),
    ("class A:\n    pass\n", r"A is not a pamid\.ForceModel subclass"),
    ("raise RuntimeError('boom')\n", r"models\.py, line 2: the model file failed to run"),
])
def test_a_model_written_wrong_ends_in_one_line(tmp_path, quadratic_csv, pamid_cli, body,
                                                message):
    (tmp_path / "models.py").write_text("import pamid\n" + body)
    out = pamid_cli(["fit", quadratic_csv / "bench.csv", "--model",
                     f"{tmp_path / 'models.py'}:A"])
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    import re

    assert re.search(message, lines[0]), lines[0]


def test_unknown_model_names_the_choices(quadratic_csv, pamid_cli, tmp_path):
    out = pamid_cli(["fit", quadratic_csv / "bench.csv", "--model", "sarosy"])
    assert out.returncode == 2
    assert "unknown model 'sarosy'" in out.stderr and "sarosi" in out.stderr
    # The options are checked while the file is read; their error still comes first, as
    # when they were checked before reading.
    for option, message in ((["--model", "sarosy"], "unknown model 'sarosy'"),
                            (["--bounds", "a9=0:1"], "no constant 'a9'")):
        out = pamid_cli(["fit", tmp_path / "absent.csv", *option])
        assert out.returncode == 2 and message in out.stderr, out.stderr
        assert len(out.stderr.strip().splitlines()) == 1


def test_a_nonlinear_constant_without_a_default_is_named(tmp_path):
    class NoStart(pamid.ForceModel):
        a: float
        b: float
        units = {"a": "N", "b": "1/kPa"}
        inputs = ("pressure_kPa",)

        def __call__(self, pressure_kPa):
            return self.a * jnp.exp(self.b * pressure_kPa)

    bench = _load(pd.DataFrame({
        "pressure_kPa": np.linspace(100, 500, 20), "contraction_pct": 0.0,
        "force_N": np.linspace(10, 50, 20)}), tmp_path)
    with pytest.raises(ModelDefinitionError, match=r"give b a default \(its start value\)"):
        pamid.fit_least_squares(bench, NoStart)


def test_the_model_is_a_pytree_under_jit_vmap_and_grad():
    model = Quadratic(**TRUE)
    p = jnp.linspace(100.0, 500.0, 5)
    k = jnp.full(5, 10.0)
    g = jax.grad(lambda m: jnp.sum(m(p, k)))(model)
    np.testing.assert_allclose(g.c1, jnp.sum(p))
    batched = jax.vmap(lambda c: Quadratic(c, 1.2, -12.0, 0.01)(p, k))(jnp.arange(3.0))
    assert batched.shape == (3, 5)
    np.testing.assert_allclose(jax.jit(lambda m: m(p, k))(model), model(p, k))


def test_written_out_kernels_are_found_by_the_model_class():
    """Kernels are registered by class (``KERNELS``), not carried by a spec: every complete
    view of Sarosi has them, a view of part of it, one made from an instance (whose values
    are the start) and one with ``written_out=False`` have not; the old spelling still
    is read with a warning."""
    import dataclasses

    from pamid._fit._spec import KERNELS
    from pamid._models._cullinan import Cullinan
    from pamid._models._sarosi import Sarosi, table_3_1

    assert Sarosi in KERNELS and Cullinan not in KERNELS and CULLINAN.kernels is None
    assert spec_from_model(Sarosi).kernels is SAROSI.kernels is KERNELS[Sarosi]()
    assert spec_from_model(Sarosi, params=("a1", "a2", "a3", "a4", "a5")).kernels is None
    assert spec_from_model(table_3_1()).kernels is None
    # pamid's own classes key their programs on disk by the view's data; a view made from
    # an instance starts from its values, which no key names, and keys none
    assert spec_from_model(Sarosi).program_key == SAROSI.program_key is not None
    assert spec_from_model(table_3_1()).program_key is None
    generic = dataclasses.replace(SAROSI, written_out=False)
    assert generic.kernels is None and generic.program_key != SAROSI.program_key
    # The registered start stays: only the solvers and statistics are generic.
    assert generic.candidates is None
    with pytest.warns(DeprecationWarning, match="ModelSpec.kernels"):
        assert SAROSI.fast_path is SAROSI.kernels and generic.fast_path is None

