"""A pooled model: one fit over every muscle of a file, constants as functions of descriptors.

Each constant θ_j of a base model (Sárosi eq. 2.1 by default) takes one of three roles:

* ``shared``: one value for every muscle (Sárosi's "any diameter and length");
* ``smooth``: θ_j = α_j + Σ_d β_jd·g_d, g_d = ln(d/d_ref) of the muscle's descriptors
  (:mod:`._descriptors`; α_j is θ_j at the reference muscle);
* ``per_muscle``: one value per muscle. A muscle that was not fitted (a new one, or one left
  out) takes the mean of the fitted muscles' values: the least-squares stand-in for the
  population mean of a hierarchical model.

The pooled model is again a :class:`~pamid._fit._spec.ModelSpec`, fitted by pamid's batched
least squares; its inputs are the base model's, then the muscle's index, then the features
g_d. Constants are laid out constant by constant: ``a1`` (shared), ``a2``, ``a2_ln_l0_mm``
(smooth in l0), ``a3_m0`` … ``a3_m5`` (per muscle).
"""

from __future__ import annotations

import dataclasses
import functools

import jax.numpy as jnp
import numpy as np

from .._fit._spec import ModelSpec

ROLES = ("shared", "smooth", "per_muscle")


def parse_roles(text: str | None, param_names: tuple[str, ...],
                default: str = "smooth") -> tuple[str, ...]:
    """Roles of every constant from ``"a1=shared,a3=per_muscle"`` (others: ``default``)."""
    roles = dict.fromkeys(param_names, default)
    for item in (text or "").split(","):
        if not item.strip():
            continue
        name, sep, role = (s.strip() for s in item.partition("="))
        if not sep or role not in ROLES:
            raise ValueError(f"--roles: write NAME=ROLE with ROLE one of {', '.join(ROLES)}, "
                             f"not {item.strip()!r}")
        if name not in roles:
            raise ValueError(f"--roles: the model has no constant {name!r}; its constants "
                             f"are {', '.join(param_names)}")
        roles[name] = role
    return tuple(roles[n] for n in param_names)


def layout(base: ModelSpec, roles: tuple[str, ...], descriptors: tuple[str, ...],
           n_muscles: int) -> tuple[tuple[str, ...], tuple[tuple[int, int], ...]]:
    """(names of the pooled constants, (offset, count) of each base constant's block)."""
    names, blocks = [], []
    for name, role in zip(base.param_names, roles, strict=True):
        start = len(names)
        if role == "shared":
            names.append(name)
        elif role == "smooth":
            names += [name] + [f"{name}_ln_{d}" for d in descriptors]
        elif role == "per_muscle":
            names += [f"{name}_m{i}" for i in range(n_muscles)]
        else:
            raise ValueError(f"unknown role {role!r}; choose one of {ROLES}")
        blocks.append((start, len(names) - start))
    return tuple(names), tuple(blocks)


@dataclasses.dataclass(frozen=True, eq=False, kw_only=True)
class Pooled(ModelSpec):
    """The pooled model of ``base`` (module text): a model that wraps a model. Its inputs
    are the base model's, then the muscle's index, then the features of ``descriptors``;
    ``blocks`` is each base constant's (offset, count) in ``theta`` (:func:`layout`). Made
    by :func:`pooled_spec`."""

    base: ModelSpec
    roles: tuple[str, ...]
    descriptors: tuple[str, ...]
    blocks: tuple[tuple[int, int], ...]

    def _constants(self, theta, muscle, g):
        """(n, p) constants of each row from the pooled theta (k,), the rows' muscle index
        (n,) and features (n, D)."""
        cols = []
        for role, (o, c) in zip(self.roles, self.blocks, strict=True):
            if role == "shared":
                cols.append(jnp.broadcast_to(theta[o], muscle.shape))
            elif role == "smooth":
                value = theta[o] + (g @ theta[o + 1:o + c] if self.descriptors else 0.0)
                cols.append(jnp.broadcast_to(value, muscle.shape))
            else:
                cols.append(jnp.take(theta[o:o + c], muscle, mode="clip"))
        return jnp.stack(cols, axis=-1)

    def predict(self, theta, x):
        n_desc = len(self.descriptors)
        inputs = x[:len(x) - 1 - n_desc]
        muscle = jnp.asarray(x[len(inputs)]).astype(jnp.int32)
        g = (jnp.stack(x[len(inputs) + 1:], axis=-1) if n_desc
             else jnp.zeros(muscle.shape + (0,)))
        return self.base.predict(self._constants(theta, muscle, g), tuple(inputs))

    def start(self, x, y, w):
        base_x = tuple(x[:len(x) - 1 - len(self.descriptors)])
        theta0 = self.base.start(base_x, y, w)  # (L, p): the base model on the pooled rows
        parts = []
        for j, (role, (_, c)) in enumerate(zip(self.roles, self.blocks, strict=True)):
            value = theta0[:, j:j + 1]
            if role == "smooth":
                parts += [value, jnp.zeros((theta0.shape[0], c - 1))]
            else:
                parts.append(jnp.repeat(value, c, axis=1))
        return jnp.concatenate(parts, axis=1)

    def to_x(self, *cols):
        k = len(self.base.columns)
        return (*self.base.to_x(*cols[:k]), *cols[k:])


@functools.cache
def pooled_spec(base: ModelSpec, roles: tuple[str, ...], descriptors: tuple[str, ...],
                n_muscles: int) -> Pooled:
    """The pooled model of ``base`` with these roles (module text), for ``n_muscles``
    muscles and the descriptors ``descriptors`` (their features, in this order, are the last
    inputs). Cached, so that one spec (and its compiled programs) serves every call."""
    names, blocks = layout(base, roles, descriptors, n_muscles)
    bounds = None
    if base.bounds is not None:
        lo, hi = [], []
        for j, (role, (_, c)) in enumerate(zip(roles, blocks, strict=True)):
            blo, bhi = base.bounds[0][j], base.bounds[1][j]
            if role == "smooth":
                lo += [blo] + [-np.inf] * (c - 1)
                hi += [bhi] + [np.inf] * (c - 1)
            else:
                lo += [blo] * c
                hi += [bhi] * c
        bounds = (tuple(lo), tuple(hi))
    units = {}
    for name, role, (o, c) in zip(base.param_names, roles, blocks, strict=True):
        for k in range(c):
            units[names[o + k]] = (base.param_units[name] if role != "smooth" or k == 0
                                   else f"{base.param_units[name]} per e-fold")
    label = "-".join(f"{n}:{r}" for n, r in zip(base.param_names, roles, strict=True))
    return Pooled(
        base=base, roles=roles, descriptors=descriptors, blocks=blocks,
        name=f"{base.name}_pooled[{label}]",
        param_names=names,
        param_units=units,
        units=dict(base.units),
        columns=(*base.columns, "muscle_index", *(f"ln_{d}" for d in descriptors)),
        source=f"{base.source}, pooled over muscles ({label})",
        bounds=bounds,
    )


def mean_per_muscle(theta: np.ndarray, base: ModelSpec, roles: tuple[str, ...],
                    descriptors: tuple[str, ...], n_muscles: int, muscle: int,
                    among: np.ndarray) -> np.ndarray:
    """``theta`` (k,) with the per-muscle constants of ``muscle`` set to their mean over the
    muscles ``among`` (indices): how a muscle the fit did not see is predicted."""
    _, blocks = layout(base, roles, descriptors, n_muscles)
    out = np.array(theta, dtype=np.float64, copy=True)
    for role, (o, _) in zip(roles, blocks, strict=True):
        if role == "per_muscle":
            out[o + muscle] = np.mean(out[o + np.asarray(among)])
    return out
