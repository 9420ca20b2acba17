"""The ``--method mcmc`` options of ``pamid fit``, defined without importing the sampler:
building the command's parser (``pamid fit --help``, ``pamid fit FILE``) must not import
JAX-heavy code that only ``--method mcmc`` runs (:mod:`pamid._commands.mcmc`)."""

from __future__ import annotations

import argparse

from .._sampling._options import DEFAULT_NU, LIKELIHOODS, SAMPLERS


def add_mcmc_arguments(parser: argparse.ArgumentParser, *, with_method: bool = True) -> None:
    """Add ``--method`` (unless ``with_method=False``) and the MCMC options to ``parser``."""
    if with_method:
        parser.add_argument("--method", default="ls", choices=["ls", "mcmc"],
                            help="ls: least squares (default); mcmc: posterior sampling of "
                                 "the constants and the noise (ensemble MCMC)")
    g = parser.add_argument_group("MCMC (--method mcmc)")
    g.add_argument("--walkers", type=int, default=32,
                   help="walkers per muscle (even, ≥ 2 × (constants + 1); default 32)")
    g.add_argument("--max-steps", type=int, default=20_000, dest="max_steps",
                   help="step budget; sampling stops earlier once the kept chain spans 50 "
                        "autocorrelation times (default 20000)")
    g.add_argument("--thin", type=int, default=10, help="keep every N-th step (default 10)")
    g.add_argument("--likelihood", default="normal", choices=list(LIKELIHOODS),
                   help="noise model: normal, or student-t for data with outliers")
    g.add_argument("--nu", type=float, default=DEFAULT_NU,
                   help=f"degrees of freedom of the Student-t likelihood (default {DEFAULT_NU:g})")
    g.add_argument("--sampler", default="auto", choices=list(SAMPLERS),
                   help="stacked: all muscles in one JAX call; emcee: one emcee sampler per "
                        "muscle; auto: the faster (stacked)")
