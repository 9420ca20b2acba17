"""pamid's one Levenberg–Marquardt loop (pamid._fit._engine) against known answers."""

import jax
import jax.numpy as jnp
import numpy as np

from pamid._fit._engine import CONVERGED, RESULT_NAMES, levenberg_marquardt


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
