"""Positioning control of PAMs: the proportional valve, Sárosi's sliding-mode controller,
the rigs of his Sections 2.4 and 3.3 simulated with encoder and sampling, and the muscle's
temperature. See ``_positioning`` for the model and its assumptions."""
