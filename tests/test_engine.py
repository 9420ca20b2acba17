"""pamid's one masked Levenberg–Marquardt loop (pamid._solvers) against known answers."""

import jax
import jax.numpy as jnp
import numpy as np

from pamid._solvers import CONVERGED, RESULT_NAMES, levenberg_marquardt


def _exponential(t, y):
    def linearise(p):
        model = p[0] * jnp.exp(p[1] * t) + p[2]
        jac = jnp.stack([jnp.exp(p[1] * t), p[0] * t * jnp.exp(p[1] * t),
                         jnp.ones_like(t)], axis=1)
        return model - y, jac
    return linearise


def test_recovers_an_exponential_to_rounding():
    t = jnp.linspace(0.0, 3.0, 40)
    y = 2.5 * jnp.exp(-1.3 * t) + 0.4
    sol = levenberg_marquardt(_exponential(t, y), jnp.array([1.0, -0.5, 0.0]),
                              jnp.ones(3), max_steps=100, rtol=1e-12, floor=1e-20)
    assert RESULT_NAMES[int(sol.result)] == "converged"
    np.testing.assert_allclose(sol.params, [2.5, -1.3, 0.4], rtol=1e-8)


def test_a_collinear_constant_converges_instead_of_stalling():
    """A column the others already span (a candidate effect inside the model, as a
    Legendre term in contraction is on a file with four contraction levels) makes JᵀJ
    singular. The loop must still recognise the optimum: the SSE cannot fall further.
    Before the decrement's ridge, the stopping test solved the singular JᵀJ, got NaN or an
    enormous decrement, and the lane ended 'stalled' or at 'max_steps'."""
    key = jax.random.key(0)
    t = jnp.linspace(0.0, 3.0, 200)
    noise = 0.01 * jax.random.normal(key, t.shape)
    y = 2.5 * jnp.exp(-1.3 * t) + 0.4 + noise

    def linearise(p):
        r, jac = _exponential(t, y)(p[:3])
        # p[3] multiplies a copy of the constant column: the same direction as p[2].
        return r + p[3], jnp.concatenate([jac, jnp.ones((t.shape[0], 1))], axis=1)

    sol = levenberg_marquardt(linearise, jnp.array([1.0, -0.5, 0.0, 0.0]), jnp.ones(4),
                              max_steps=100, rtol=1e-11)
    full = levenberg_marquardt(_exponential(t, y), jnp.array([1.0, -0.5, 0.0]), jnp.ones(3),
                               max_steps=100, rtol=1e-11)
    assert int(sol.result) == CONVERGED, RESULT_NAMES[int(sol.result)]
    np.testing.assert_allclose(float(sol.sse), float(full.sse), rtol=1e-9)
    np.testing.assert_allclose(float(sol.params[2] + sol.params[3]), float(full.params[2]),
                               rtol=1e-7)


def test_masked_constants_keep_their_start():
    t = jnp.linspace(0.0, 3.0, 40)
    y = 2.5 * jnp.exp(-1.3 * t) + 0.4
    sol = levenberg_marquardt(_exponential(t, y), jnp.array([1.0, -1.3, 0.0]),
                              jnp.array([1.0, 0.0, 1.0]), max_steps=100, rtol=1e-12,
                              floor=1e-20)
    assert float(sol.params[1]) == -1.3
    np.testing.assert_allclose(sol.params, [2.5, -1.3, 0.4], rtol=1e-8)


def test_box_bounds_end_on_the_constrained_optimum_scipy_finds():
    """y = 2.5·e^(−1.3 t) + 0.4 + noise with the rate bounded to [−0.8, 0]: the optimum lies on
    the bound (held there, ``free`` 0) and the other constants are SciPy's bounded
    least squares' (trust-region reflective) to its tolerance. A bound that does not bind
    changes nothing."""
    from scipy.optimize import least_squares

    key = jax.random.key(1)
    t = jnp.linspace(0.0, 3.0, 60)
    y = 2.5 * jnp.exp(-1.3 * t) + 0.4 + 0.02 * jax.random.normal(key, t.shape)
    lin = _exponential(t, y)
    lower, upper = jnp.array([-jnp.inf, -0.8, -jnp.inf]), jnp.array([jnp.inf, 0.0, jnp.inf])
    sol = levenberg_marquardt(lin, jnp.array([1.0, -0.5, 0.0]), jnp.ones(3), max_steps=200,
                              rtol=1e-14, bounds=(lower, upper))
    ref = least_squares(lambda p: np.asarray(lin(jnp.asarray(p))[0]), [1.0, -0.5, 0.0],
                        jac=lambda p: np.asarray(lin(jnp.asarray(p))[1]),
                        bounds=(np.asarray(lower), np.asarray(upper)),
                        xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert int(sol.result) == CONVERGED, RESULT_NAMES[int(sol.result)]
    assert float(sol.params[1]) == -0.8
    np.testing.assert_array_equal(sol.free, [1.0, 0.0, 1.0])
    assert not np.any(np.asarray(sol.jac)[:, 1])  # the held constant's column is out
    np.testing.assert_allclose(sol.params, ref.x, rtol=1e-7)
    np.testing.assert_allclose(float(sol.sse), 2.0 * ref.cost, rtol=1e-10)

    loose = (jnp.array([-jnp.inf, -3.0, -jnp.inf]), upper)
    free = levenberg_marquardt(lin, jnp.array([1.0, -0.5, 0.0]), jnp.ones(3), max_steps=200,
                               rtol=1e-14)
    boxed = levenberg_marquardt(lin, jnp.array([1.0, -0.5, 0.0]), jnp.ones(3), max_steps=200,
                                rtol=1e-14, bounds=loose)
    np.testing.assert_allclose(boxed.params, free.params, rtol=1e-10)
    np.testing.assert_array_equal(boxed.free, [1.0, 1.0, 1.0])
