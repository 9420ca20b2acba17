"""The ensemble kernel (``pamid.ensemble_step`` and its moves): one signature for every move,
the mixture of pamid's two moves is the sampler's, and a move written by a user plugs in and
samples a known posterior."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import pamid
from pamid._sampling import _arviz, _mcmc


def _gaussian_log_prob(mu):
    """(M, W, d) → (M, W): independent unit Gaussians centred on ``mu`` (M, d)."""
    def f(z):
        return -0.5 * jnp.sum(jnp.square(z - mu[:, None, :]), axis=-1)
    return f


MU = jnp.array([[0.0, 1.0, -2.0], [5.0, -5.0, 0.5]])


@pytest.mark.parametrize("move", [pamid.stretch_move, pamid.de_move,
                                  functools.partial(pamid.stretch_move, a=3.0)])
def test_every_move_has_one_signature(move):
    keys = jax.random.split(jax.random.key(0), 4)
    active = jax.random.normal(jax.random.key(1), (2, 4, 3))
    complement = jax.random.normal(jax.random.key(2), (2, 4, 3))
    proposal, log_correction = move(keys, active, complement)
    assert proposal.shape == (2, 4, 3) and log_correction.shape == (2, 4)
    assert np.all(np.isfinite(np.asarray(proposal)))


def test_stretch_move_is_the_affine_move_of_goodman_and_weare():
    # x' = c_j + z·(x − c_j): the proposal lies on the line through x and a partner, with
    # the correction (d − 1)·ln z (Goodman & Weare 2010, eq. 10–11).
    keys = jax.random.split(jax.random.key(3), 4)
    active = jax.random.normal(jax.random.key(4), (1, 6, 3))
    complement = jax.random.normal(jax.random.key(5), (1, 6, 3))
    proposal, log_correction = pamid.stretch_move(keys, active, complement)
    z = np.exp(np.asarray(log_correction) / 2.0)  # d − 1 = 2
    assert np.all((z >= 0.5 - 1e-12) & (z <= 2.0 + 1e-12))
    partner = (np.asarray(proposal) - z[..., None] * np.asarray(active)) / (1.0 - z[..., None])
    hits = [np.min(np.linalg.norm(np.asarray(complement)[0] - p, axis=1)) for p in partner[0]]
    np.testing.assert_allclose(hits, 0.0, atol=1e-9)


def test_one_move_mixture_equals_the_samplers_pure_stretch():
    lp = _gaussian_log_prob(MU)
    start = MU[:, None, :] + 0.1 * jax.random.normal(jax.random.key(6), (2, 8, 3))
    state = pamid.ensemble_init(start, lp)
    run = jax.jit(pamid.run_ensembles, static_argnums=(2, 3, 4, 5))
    _, pos, _, acc = run(jax.random.key(7), state, lp, 5, 1, ((pamid.stretch_move, 1.0),))

    def log_prob(z, mu, _y, _w):  # the sampler's signature
        return -0.5 * jnp.sum(jnp.square(z - mu))

    _, pos_s, _, acc_s = _mcmc._advance_stacked(log_prob, jax.random.key(7), state, MU,
                                                jnp.zeros(2), jnp.zeros(2), n_draws=5,
                                                thin=1, de_fraction=0.0)
    np.testing.assert_allclose(np.asarray(pos), np.asarray(pos_s), rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(np.asarray(acc), np.asarray(acc_s))


def test_a_users_move_plugs_in_and_samples_the_known_posterior():
    def random_walk(keys, active, complement, *, step=0.8):  # symmetric: no correction
        return (active + step * jax.random.normal(keys[0], active.shape, active.dtype),
                jnp.zeros(active.shape[:2], active.dtype))

    lp = _gaussian_log_prob(MU)
    start = MU[:, None, :] + 0.1 * jax.random.normal(jax.random.key(8), (2, 16, 3))
    state = pamid.ensemble_init(start, lp)
    moves = ((random_walk, 0.5), (pamid.de_move, 0.5))
    run = jax.jit(pamid.run_ensembles, static_argnums=(2, 3, 4, 5))
    _, pos, _, acc = run(jax.random.key(9), state, lp, 1500, 2, moves)
    draws = np.moveaxis(np.asarray(pos)[300:], 0, 2)  # (M, W, D, d)
    x = np.moveaxis(draws, -1, 1)  # (M, d, W, D)
    z = (x.mean(axis=(-2, -1)) - np.asarray(MU)) / _arviz.mcse_mean(x)
    assert np.all(np.abs(z) < 4.0), z
    var = draws.reshape(2, -1, 3).var(axis=1)
    np.testing.assert_allclose(var, 1.0, atol=0.15)
    rate = np.asarray(acc) / (1500 * 2 * 16)
    assert np.all((rate > 0.1) & (rate < 0.9)), rate


def test_mixture_weights_are_checked():
    lp = _gaussian_log_prob(MU)
    state = pamid.ensemble_init(MU[:, None, :] + jnp.zeros((2, 4, 3)), lp)
    with pytest.raises(ValueError, match="weights ≥ 0"):
        pamid.ensemble_step(jax.random.key(0), state, lp,
                            ((pamid.de_move, -0.5), (pamid.stretch_move, 1.5)))
