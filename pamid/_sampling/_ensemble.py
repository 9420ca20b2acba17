"""The ensemble kernel: M independent ensembles of walkers, stacked (M, W, d), advanced
together by pure functions of an explicit PRNG key, and the moves that propose their steps.

The walkers of one ensemble only ever move relative to walkers of the same ensemble, so the
M ensembles stay independent (one per muscle in :func:`pamid.fit_mcmc`), while one call of
the vectorised log-posterior evaluates every proposal of every ensemble.

A **move** is a function with one signature::

    move(keys, active, complement) -> (proposal, log_correction)

``active`` (M, h, d) are the walkers to update, ``complement`` (M, n, d) the walkers of the
same ensembles they move against, ``keys`` four independent PRNG keys. It returns the
proposals (M, h, d) and the log of the Metropolis–Hastings correction (M, h) (for an
affine-invariant move, the log of the Jacobian factor). Settings are keyword arguments bound
with :func:`functools.partial` (``partial(stretch_move, a=3.0)``). The kernel draws the move
of each walker from a weighted mixture, independently of the state, so any mixture of valid
moves is valid. Every move of a mixture gets the same four keys: :func:`stretch_move` and
:func:`de_move` draw the partner ``j`` from the same key, which is how the fused version of
this kernel drew it, and keeps its results bit for bit.

Keys: a half step splits its key in six: 0 picks each walker's move, 1–4 go to the moves,
5 decides acceptance.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp

STRETCH_A = 2.0

#: ``move(keys, active, complement) -> (proposal, log_correction)`` (module text).
Move = Callable[[jax.Array, jax.Array, jax.Array], tuple[jax.Array, jax.Array]]


class EnsembleState(NamedTuple):
    """Walkers of M independent ensembles: positions (M, W, d) and log-posteriors (M, W)."""

    position: jax.Array
    log_prob: jax.Array


def _partner(key, complement, m, h):
    j = jax.random.randint(key, (m, h), 0, complement.shape[1])
    return j, jnp.take_along_axis(complement, j[..., None], axis=1)


def stretch_move(keys, active, complement, *, a: float = STRETCH_A):
    """Goodman & Weare's stretch move (2010, eq. 10–11; emcee's ``StretchMove``):
    x' = c_j + z·(x − c_j), z ~ g(z) ∝ 1/√z on [1/a, a], with the correction z^(d−1).
    Uses ``keys[0]`` for z and ``keys[1]`` for the partner j."""
    m, h, d = active.shape
    _, c_j = _partner(keys[1], complement, m, h)
    z = jnp.square((a - 1.0) * jax.random.uniform(keys[0], (m, h), active.dtype) + 1.0) / a
    return active + (z - 1.0)[..., None] * (active - c_j), (d - 1.0) * jnp.log(z)


def de_move(keys, active, complement, *, gamma0: float | None = None):
    """The differential-evolution move (ter Braak 2006; emcee's ``DEMove``):
    x' = x + γ·(c_j − c_k), j ≠ k, γ = γ0·(1 + 10⁻⁵·N(0, 1)), γ0 = 2.38/√(2d) unless given;
    symmetric, so no correction. Uses ``keys[1]`` for j, ``keys[2]`` for k, ``keys[3]``
    for the jitter of γ."""
    m, h, d = active.shape
    n_c = complement.shape[1]
    gamma0 = 2.38 / math.sqrt(2 * d) if gamma0 is None else gamma0
    j, c_j = _partner(keys[1], complement, m, h)
    k = (j + jax.random.randint(keys[2], (m, h), 1, n_c)) % n_c  # any walker but j
    c_k = jnp.take_along_axis(complement, k[..., None], axis=1)
    gamma = gamma0 * (1.0 + 1e-5 * jax.random.normal(keys[3], (m, h), active.dtype))
    return active + gamma[..., None] * (c_j - c_k), jnp.zeros((m, h), active.dtype)


#: pamid's default mixture: 80 % differential evolution, 20 % stretch (the reasons are in
#: :mod:`pamid._sampling._mcmc`'s module text).
DEFAULT_MOVES: tuple[tuple[Move, float], ...] = ((de_move, 0.8), (stretch_move, 0.2))


def _propose(key_select, keys, active, complement, moves):
    """Each walker's proposal from the move drawn for it with the mixture's weights."""
    weights = [float(w) for _, w in moves]
    if len(moves) == 0 or min(weights) < 0.0 or sum(weights) <= 0.0:
        raise ValueError(f"moves: give (move, weight) pairs with weights ≥ 0 and a positive "
                         f"sum, got weights {weights}")
    proposal, log_correction = moves[0][0](keys, active, complement)
    if len(moves) == 1:
        return proposal, log_correction
    total, edges, cum = sum(weights), [], 0.0
    for w in weights[:-1]:
        cum += w
        edges.append(cum / total)
    u = jax.random.uniform(key_select, active.shape[:2], active.dtype)
    which = sum((u >= e).astype(jnp.int32) for e in edges)
    for i, (move, _) in enumerate(moves[1:], start=1):
        p_i, c_i = move(keys, active, complement)
        proposal = jnp.where((which == i)[..., None], p_i, proposal)
        log_correction = jnp.where(which == i, c_i, log_correction)
    return proposal, log_correction


def _half_step(key, active, lp_active, complement, log_prob_fn, moves):
    """Metropolis–Hastings update of every walker of ``active`` (M, h, d) against the
    ``complement`` walkers of the same ensemble, with the move drawn per walker."""
    m, h, _ = active.shape
    keys = jax.random.split(key, 6)
    proposal, log_correction = _propose(keys[0], keys[1:5], active, complement, moves)
    lp_new = log_prob_fn(proposal)
    log_u = jnp.log(jax.random.uniform(keys[5], (m, h), active.dtype))
    accept = log_u < log_correction + lp_new - lp_active
    return (jnp.where(accept[..., None], proposal, active),
            jnp.where(accept, lp_new, lp_active), accept)


def ensemble_init(position, log_prob_fn: Callable) -> EnsembleState:
    """The state of walkers at ``position`` (M, W, d); ``log_prob_fn`` maps (M, W, d) to
    (M, W)."""
    position = jnp.asarray(position)
    return EnsembleState(position, log_prob_fn(position))


def ensemble_step(key, state: EnsembleState, log_prob_fn: Callable,
                  moves: tuple[tuple[Move, float], ...] = DEFAULT_MOVES,
                  ) -> tuple[EnsembleState, jax.Array]:
    """One step of every ensemble: the first half of the walkers moves against the second,
    then the second against the updated first (emcee's red-blue scheme). ``log_prob_fn``
    maps (M, h, d) to (M, h); ``moves`` is a mixture of (move, weight) pairs (module text).
    Returns the new state and the accepted moves per ensemble (M,).

    The two halves run as a two-iteration loop, so the log-posterior appears once in the
    compiled program (compilation time is what a short run costs)."""
    pos, lp = state
    m, n_walkers, _ = pos.shape
    h = n_walkers // 2

    def half(carry, xs):
        pos, lp, acc = carry
        k, first = xs
        start, other = first * h, (1 - first) * h
        active = jax.lax.dynamic_slice_in_dim(pos, start, h, axis=1)
        comp = jax.lax.dynamic_slice_in_dim(pos, other, h, axis=1)
        lp_active = jax.lax.dynamic_slice_in_dim(lp, start, h, axis=1)
        new, lp_new, accepted = _half_step(k, active, lp_active, comp, log_prob_fn, moves)
        pos = jax.lax.dynamic_update_slice_in_dim(pos, new, start, axis=1)
        lp = jax.lax.dynamic_update_slice_in_dim(lp, lp_new, start, axis=1)
        return (pos, lp, acc + accepted.sum(axis=1, dtype=acc.dtype)), None

    acc0 = jnp.zeros(m, jnp.int32)
    (pos, lp, acc), _ = jax.lax.scan(half, (pos, lp, acc0),
                                     (jax.random.split(key, 2), jnp.arange(2)))
    return EnsembleState(pos, lp), acc


def run_ensembles(key, state: EnsembleState, log_prob_fn: Callable, n_draws: int,
                  thin: int = 1, moves: tuple[tuple[Move, float], ...] = DEFAULT_MOVES):
    """``n_draws · thin`` steps of every ensemble in one ``lax.scan`` (no Python between
    steps; wrap it in ``jax.jit`` with ``n_draws``, ``thin`` and ``moves`` static). Keeps
    every ``thin``-th state. Returns (last state, positions (n_draws, M, W, d),
    log-posteriors (n_draws, M, W), accepted moves per ensemble (M,))."""

    def step(state, k):
        return ensemble_step(k, state, log_prob_fn, moves)

    def draw(state, k):
        state, acc = jax.lax.scan(step, state, jax.random.split(k, thin))
        return state, (state.position, state.log_prob, acc.sum(axis=0))

    state, (pos, lp, acc) = jax.lax.scan(draw, state, jax.random.split(key, n_draws))
    return state, pos, lp, acc.sum(axis=0)
