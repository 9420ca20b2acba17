"""A PAM lifting a hanging mass: Sárosi's pendulous system (Fig. 2-3, eq. 2.2, Fig. 3-6).

Equation of motion, Sárosi eq. 2.2:

    m·ẍ = −F_spring[κ(x)] − c[κ(x)]·ẋ + m·g

with F_spring the static force of eq. 2.1 at the constant pressure, and the damping
coefficient c(κ) = ζ·c_cr = ζ·2·√(k(κ)·m) (eq. 2.6 and 2.10) from the stiffness k(κ) of
eq. 2.9, so that c varies with the contraction as Sárosi's Fig. 3-4 and 3-5 show.

Sign convention
---------------
The muscle hangs from a fixed support and holds the mass at its lower end (Fig. 2-3). In
eq. 2.2 gravity enters as +m·g and the muscle force as −F_spring, so eq. 2.2's x points
DOWN (the direction of gravity). The muscle shortens when the mass rises, so its contraction
is κ = −100·x/l0 with x measured from the position at which the muscle has its nominal
length l0. pamid's state is the SHORTENING s = −x = l0 − l (m, positive when the muscle is
shorter than l0, i.e. the mass is above the l0 position), κ = 100·s/l0 in %, and eq. 2.2
reads

    m·s̈ = F_spring(κ(s)) − c(κ(s))·ṡ − m·g.

At rest F_spring(κ) = m·g. This is the reading under which the system is stable: F falls
with κ (eq. 2.8 is negative), so a rise of the mass lowers the muscle force and gravity
pulls it back. Reading eq. 2.2 with κ = +100·x/l0 instead would make the equilibrium
unstable (the linearised stiffness would be −k), and could not settle as Fig. 3-6 does. The
"displacement" Sárosi reports (49.8 mm at rest, 50 mm at the start) is this shortening s;
it is what :func:`simulate_lifting_mass` returns as ``contraction_m``.

A muscle cannot push: the force is clipped at 0 N (slack muscle, free fall) where eq. 2.1
would go negative, far beyond the contraction any load here reaches.

Damping ratio
-------------
ζ is a field of :class:`LiftingMass`. Sárosi takes it from the hysteresis loop of the
force–contraction curve (eq. 2.3–2.5: ζ = ΔU/U0), which needs the constants of both branches;
:func:`zeta_from_hysteresis` computes it from an upper and a lower :class:`~pamid.Sarosi`,
and :func:`hysteresis_branches` builds the two branches around one set of constants with
a loop of a given height. Table 3-1 gives only the one (averaged) set, so the paper's ζ for
Fig. 3-6 cannot be recovered; pamid's default (:data:`DEFAULT_HYSTERESIS_N_PER_BAR`) is the
loop of pamid's bundled virtual-bench data set (±3 N per bar around Table 3-1, the loop that
``pamid demo`` fits), integrated over the contraction range of that bench's sweep at the
given pressure. Any constant ζ can be given instead.

Integrator (chosen by measurement, ``benchmarks/simulate_batch.py``, section 1)
---------------------------------------------------------------------------------
Reference: ``scipy.integrate.solve_ivp(method="DOP853", rtol=1e-10, atol=1e-12)``, run by
run. Batch: 1000 runs of 5 s with output at 1 kHz (pressures 300–500 kPa, loads 30–70 kg,
released within ±15 mm of the static solution; run 0 is Fig. 3-6). Each candidate at the
cheapest setting that keeps every run within 1e-9 m of the reference (the encoder reads
1e-5 m): RK4 in ``lax.scan`` at one step per sample, diffrax's Tsit5 and Kvaerno5 with a PID
controller, and the ``solve_ivp`` loop; the table of errors, steps, compile and run times is
in benchmarks/README.md, "Figures that used to live in docstrings", (b).

RK4 wins: at a 1 kHz output grid one RK4 step per sample is already 13× more accurate than
needed, while the adaptive solver, though it takes 5× fewer steps, runs its step loop in
lockstep across the vmapped batch and pays for dense output at 5001 points. The system is
not stiff (ω_n ≈ 14 rad/s, ζ < 1), so the implicit Kvaerno5 only adds cost.
:func:`simulate_lifting_mass` therefore uses RK4 with ``substeps`` steps per output sample
(default 1); :func:`lifting_mass_substeps` gives how many a run needs (a light mass on the
stiff muscle moves at hundreds of Hz, which ``pamid simulate lifting-mass`` follows so).
A muscle that goes slack (force clipped at 0 N, far above the equilibrium)
puts a kink in the right-hand side, where every fixed- or adaptive-step method drops to
first order; the benchmark keeps its runs taut.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._models._hysteresis import hysteresis_damping
from .._models._sarosi import (
    TABLE_3_1_L0_MM,
    Sarosi,
    contraction_at_force_pct,
    sarosi_force,
    sarosi_stiffness,
    table_3_1,
)
from .._units import KPA_PER_BAR
from ._oscillator import batch_apply, rk4_scan, sample_times

__all__ = [
    "DEFAULT_HYSTERESIS_N_PER_BAR",
    "STANDARD_GRAVITY_M_PER_S2",
    "LiftingMass",
    "LiftingMassRun",
    "default_zeta",
    "hysteresis_branches",
    "lifting_mass_damping",
    "lifting_mass_equilibrium",
    "lifting_mass_force",
    "lifting_mass_stiffness",
    "lifting_mass_substeps",
    "loop_range_pct",
    "settling",
    "simulate_lifting_mass",
    "zeta_from_hysteresis",
]

#: g used by default. Sárosi does not state his value; 9.81 m/s² is MATLAB/Simulink's usual.
STANDARD_GRAVITY_M_PER_S2 = 9.81
#: Half height of the default hysteresis loop, N per bar: the loop of pamid's bundled data
#: set (``pamid._virtual._default.default_protocol``, ``hysteresis_N_per_bar``).
DEFAULT_HYSTERESIS_N_PER_BAR = 3.0
#: Contraction bracket (in %) searched for the static equilibrium.
EQUILIBRIUM_BRACKET_PCT = (-10.0, 50.0)


class LiftingMass(eqx.Module):
    """Sárosi's pendulous system (Fig. 2-3): a PAM at constant pressure holding a mass.

    Fields (any may carry leading batch axes): ``muscle`` (Sárosi eq. 2.1 constants),
    ``pressure_kPa`` (gauge), ``mass_kg``, ``zeta`` (damping ratio of eq. 2.10), ``l0_m``
    (nominal length), ``gravity_m_per_s2``.
    """

    muscle: Sarosi
    pressure_kPa: Float[Array, "..."]
    mass_kg: Float[Array, "..."]
    zeta: Float[Array, "..."]
    l0_m: Float[Array, "..."]
    gravity_m_per_s2: Float[Array, "..."]

    def __init__(self, muscle: Sarosi | None = None, pressure_kPa=400.0, mass_kg=50.0,
                 zeta=0.05, l0_m=None, gravity_m_per_s2=STANDARD_GRAVITY_M_PER_S2):
        self.muscle = table_3_1() if muscle is None else muscle
        self.pressure_kPa = jnp.asarray(pressure_kPa, float)
        self.mass_kg = jnp.asarray(mass_kg, float)
        self.zeta = jnp.asarray(zeta, float)
        self.l0_m = jnp.asarray(TABLE_3_1_L0_MM / 1000.0 if l0_m is None else l0_m, float)
        self.gravity_m_per_s2 = jnp.asarray(gravity_m_per_s2, float)


def _kappa_pct(model: LiftingMass, contraction_m):
    return 100.0 * jnp.asarray(contraction_m, float) / model.l0_m


def lifting_mass_force(model: LiftingMass, contraction_m: ArrayLike) -> Float[Array, "..."]:
    """F_spring in N at shortening ``contraction_m`` (Sárosi eq. 2.1, κ = 100·s/l0), ≥ 0."""
    p_bar = model.pressure_kPa / KPA_PER_BAR
    return jnp.maximum(sarosi_force(model.muscle, p_bar, _kappa_pct(model, contraction_m)), 0.0)


def lifting_mass_stiffness(model: LiftingMass, contraction_m: ArrayLike) -> Float[Array, "..."]:
    """k(κ) in N/m, Sárosi eq. 2.7–2.9 (positive: force gained per metre of lengthening)."""
    p_bar = model.pressure_kPa / KPA_PER_BAR
    return sarosi_stiffness(model.muscle, p_bar, _kappa_pct(model, contraction_m), model.l0_m)


def lifting_mass_damping(model: LiftingMass, contraction_m: ArrayLike) -> Float[Array, "..."]:
    """c(κ) = ζ·2·√(k(κ)·m) in N·s/m, Sárosi eq. 2.6 and 2.10."""
    k = jnp.maximum(lifting_mass_stiffness(model, contraction_m), 0.0)
    return model.zeta * 2.0 * jnp.sqrt(k * model.mass_kg)


def _rhs(model: LiftingMass):
    def rhs(y):
        s, v = y[0], y[1]
        accel = (
            lifting_mass_force(model, s) - lifting_mass_damping(model, s) * v
        ) / model.mass_kg - model.gravity_m_per_s2
        return jnp.stack([v, accel])

    return rhs


@eqx.filter_jit
def lifting_mass_equilibrium(model: LiftingMass) -> Float[Array, "..."]:
    """The static solution: the shortening s (m) at which F_spring(κ(s)) = m·g.

    Eq. 2.1 falls monotonically with κ at constant pressure, so the root is unique; it is
    bracketed in κ ∈ [−10 %, 50 %] and found by bisection, then one Newton step is taken from
    the (gradient-stopped) bisection point, which makes the result differentiable with the
    implicit-function derivative ds/dθ = −(∂f/∂θ)/(∂f/∂s). NaN where the load is outside
    what the muscle can hold in the bracket. Broadcasts over batch axes.
    """
    lo_pct, hi_pct = EQUILIBRIUM_BRACKET_PCT
    weight = model.mass_kg * model.gravity_m_per_s2
    p_bar = model.pressure_kPa / KPA_PER_BAR
    shape = jnp.broadcast_shapes(
        *(jnp.shape(x) for x in jax.tree_util.tree_leaves(model))
    )

    def f(kappa):  # unclipped eq. 2.1 minus the weight; decreasing in κ
        return sarosi_force(model.muscle, p_bar, kappa) - weight

    lo = jnp.full(shape, lo_pct)
    hi = jnp.full(shape, hi_pct)
    inside = (f(lo) > 0) & (f(hi) < 0)

    def body(_, bracket):
        lo, hi = bracket
        mid = 0.5 * (lo + hi)
        above = f(mid) > 0
        return jnp.where(above, mid, lo), jnp.where(above, hi, mid)

    lo, hi = jax.lax.fori_loop(0, 64, body, (jax.lax.stop_gradient(lo), jax.lax.stop_gradient(hi)))
    k0 = jax.lax.stop_gradient(0.5 * (lo + hi))
    _, slope = jax.jvp(f, (k0,), (jnp.ones_like(k0),))
    kappa = k0 - f(k0) / slope  # one Newton step: exact value, implicit derivative
    return jnp.where(inside, kappa * model.l0_m / 100.0, jnp.nan)


def hysteresis_branches(
    muscle: Sarosi, *, per_bar_N: ArrayLike = 0.0, constant_N: ArrayLike = 0.0
) -> tuple[Sarosi, Sarosi]:
    """Upper (extending, F_f) and lower (contracting, F_a) branches around ``muscle``.

    The loop is F_f − F_a = 2·(per_bar_N·p + constant_N): a half height proportional to the
    pressure (the virtual bench's ``hysteresis_N_per_bar``; it moves a5 by ±per_bar_N) plus a
    constant one (it moves a6 by ±constant_N).
    """
    h_p, h_c = jnp.asarray(per_bar_N, float), jnp.asarray(constant_N, float)
    upper = Sarosi(muscle.a1, muscle.a2, muscle.a3, muscle.a4, muscle.a5 + h_p, muscle.a6 + h_c)
    lower = Sarosi(muscle.a1, muscle.a2, muscle.a3, muscle.a4, muscle.a5 - h_p, muscle.a6 - h_c)
    return upper, lower


def zeta_from_hysteresis(
    upper: Sarosi,
    lower: Sarosi,
    pressure_kPa: ArrayLike,
    kappa_min_pct: ArrayLike,
    kappa_max_pct: ArrayLike,
) -> Float[Array, "..."]:
    """ζ = ΔU/U0 of the hysteresis loop over [κ_min, κ_max] at a pressure, Sárosi eq. 2.3–2.5.

    (A thin wrapper of :func:`pamid.sarosi.hysteresis_damping`; ζ depends on neither the load nor
    the point of the loop at which the stiffness is taken.)
    """
    out = hysteresis_damping(
        upper, lower, jnp.asarray(pressure_kPa, float) / KPA_PER_BAR, kappa_min_pct,
        kappa_max_pct, 0.0, TABLE_3_1_L0_MM / 1000.0, 1.0,
    )
    return out["zeta"]


def loop_range_pct(muscle: Sarosi, pressure_kPa: ArrayLike) -> Float[Array, "..."]:
    """κ_max of the loop: where the bench sweep ends at this pressure (force down to 10 N,
    at most 25 %), as in pamid's virtual bench and its bundled data set."""
    p_bar = jnp.asarray(pressure_kPa, float) / KPA_PER_BAR
    return contraction_at_force_pct(muscle, p_bar, 25.0, 10.0)


@eqx.filter_jit
def default_zeta(
    muscle: Sarosi | None = None,
    pressure_kPa: ArrayLike = 400.0,
    per_bar_N: float = DEFAULT_HYSTERESIS_N_PER_BAR,
    constant_N: float = 0.0,
) -> Float[Array, "..."]:
    """ζ of pamid's default loop (±3 N/bar around ``muscle``, Table 3-1 by default) over the
    bench's contraction range at ``pressure_kPa``, Sárosi eq. 2.3–2.5."""
    muscle = table_3_1() if muscle is None else muscle
    upper, lower = hysteresis_branches(muscle, per_bar_N=per_bar_N, constant_N=constant_N)
    return zeta_from_hysteresis(upper, lower, pressure_kPa, 0.0,
                                loop_range_pct(muscle, pressure_kPa))


class LiftingMassRun(NamedTuple):
    """A simulated lifting-mass run; arrays (*batch, T) except ``time_s`` (T,)."""

    time_s: Float[Array, " T"]
    contraction_m: Float[Array, "... T"]  # shortening s = l0 − l (Sárosi's "displacement")
    velocity_m_per_s: Float[Array, "... T"]
    force_N: Float[Array, "... T"]  # F_spring, eq. 2.1
    damping_Ns_per_m: Float[Array, "... T"]  # c(κ), eq. 2.10


@eqx.filter_jit
def _simulate(model, x0, v0, n, dt, substeps):
    def one(m, s0, v0):
        ys = rk4_scan(_rhs(m), jnp.stack([s0, v0]), dt, n, substeps)
        s, v = ys[:, 0], ys[:, 1]
        return s, v, lifting_mass_force(m, s), lifting_mass_damping(m, s)

    return batch_apply(one, model, x0, v0)


def simulate_lifting_mass(
    model: LiftingMass,
    x0_m: ArrayLike,
    v0_m_per_s: ArrayLike = 0.0,
    *,
    duration_s: float = 5.0,
    sample_rate_Hz: float = 1000.0,
    substeps: int = 1,
) -> LiftingMassRun:
    """Simulate Sárosi eq. 2.2 from the shortening ``x0_m`` and rate ``v0_m_per_s``.

    One run, or a batch: the model's fields and the initial state broadcast together, and
    the whole batch is one compiled, vmapped RK4 scan (see the module docstring for why
    RK4). Differentiable with respect to the model and the initial state.
    """
    if int(substeps) < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
    n, dt = sample_times(duration_s, sample_rate_Hz)
    s, v, f, c = _simulate(model, jnp.asarray(x0_m, float), jnp.asarray(v0_m_per_s, float), n,
                           dt, int(substeps))
    return LiftingMassRun(dt * jnp.arange(n), s, v, f, c)


#: RK4 step, in radians of the fastest motion (|λ|·h), that :func:`lifting_mass_substeps`
#: keeps to: 25 steps per period of the natural frequency, a phase error near 1e-4 a period.
RK4_STEP_RAD = 0.25


def lifting_mass_substeps(
    model: LiftingMass, x0_m: float, v0_m_per_s: float, sample_rate_Hz: float
) -> tuple[int, float]:
    """RK4 steps per output sample that resolve the run's fastest motion; one run (NumPy).

    The linearised motion about a shortening s has the rates λ = ω·(ζ ± √(ζ² − 1)),
    ω = √(k(s)/m) (Sárosi eq. 2.9, 2.10); the largest |λ| over the shortenings the run can
    reach (the static solution ± the amplitude that x0 and v0 give, within −10 … 50 %
    contraction) sets the step: |λ|·h ≤ :data:`RK4_STEP_RAD`. A light mass on a stiff muscle
    oscillates at hundreds of Hz, which one step per 1 kHz sample would not follow (RK4 is
    unstable beyond |λ|·h ≈ 2.8, and gives nonsense well before).

    Returns (substeps ≥ 1, the largest |λ| in 1/s); substeps is ``math.inf`` beyond 1e15.
    """
    import numpy as np

    l0 = float(model.l0_m)
    m = float(model.mass_kg)
    zeta = float(model.zeta)
    eq = float(lifting_mass_equilibrium(model))
    if not np.isfinite(eq):
        eq = float(x0_m)
    k_eq = abs(float(lifting_mass_stiffness(model, eq)))
    omega_eq = math.sqrt(k_eq / m) if k_eq > 0 else 0.0
    reach = math.hypot(x0_m - eq, v0_m_per_s / omega_eq if omega_eq > 0 else 0.0)
    lo, hi = max(eq - reach, -0.1 * l0), min(eq + reach, 0.5 * l0)
    s = np.linspace(min(lo, x0_m), max(hi, x0_m), 65)
    k = float(np.max(np.abs(np.asarray(lifting_mass_stiffness(model, s)))))
    omega = math.sqrt(k / m)
    fastest = omega * (zeta + math.sqrt(zeta**2 - 1.0) if zeta > 1.0 else 1.0)
    needed = fastest / (sample_rate_Hz * RK4_STEP_RAD)
    return (max(1, math.ceil(needed)) if needed < 1e15 else math.inf), fastest


def settling(
    time_s, contraction_m, equilibrium_m, *, band_fraction: float = 0.02, floor_m: float = 0.0
) -> dict:
    """Settling facts of one run (NumPy, not traced).

    The band is ±max(band_fraction·|s(0) − s_eq|, floor_m) around the static solution; the
    settling time is the first time after which the run stays inside it (None if it never
    does). Also the largest excursion beyond the equilibrium on the far side (overshoot).
    """
    import numpy as np

    t = np.asarray(time_s)
    s = np.asarray(contraction_m)
    dev = s - float(equilibrium_m)
    band = max(band_fraction * abs(dev[0]), floor_m)
    outside = np.nonzero(np.abs(dev) > band)[0]
    if len(outside) == 0:
        t_settle = float(t[0])
    elif outside[-1] == len(t) - 1:
        t_settle = None
    else:
        t_settle = float(t[outside[-1] + 1])
    far = -np.sign(dev[0]) * dev if dev[0] != 0 else np.abs(dev)
    return {
        "band_m": float(band),
        "settling_time_s": t_settle,
        "settled": t_settle is not None,
        "overshoot_m": float(max(far.max(), 0.0)),
    }
