"""The names the MCMC options offer (samplers, likelihoods, the default ν): plain Python, so
that the command line can list them without importing the sampler (JAX, the models)."""

SAMPLERS = ("auto", "stacked", "emcee")
LIKELIHOODS = ("normal", "student-t")
#: Degrees of freedom of the Student-t likelihood unless told.
DEFAULT_NU = 4.0
