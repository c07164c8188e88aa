r"""The minimum-friction design problem as a disciplined geometric program (DGP) in cvxpy.

For a fixed ball count z every term of μ is log-log convex in the two
continuous design variables, the tangent of the groove angle t = tan θ and the
load G. With sec θ = (1 + t²)^½ (a posynomial raised to a positive power, so
log-log convex) the equations of :func:`physics.evaluate` read

.. math::

    Q_0 &= G \sec\theta / (2 z)                       &\text{(eq 7)}\\
    Q   &= Q_0 + c + \sqrt{2 c Q_0 + c^2},\quad c = 6\pi\gamma R   &\text{(eq 8)}\\
    M_P &= k_P Q^{4/3},\ M_{ER} = k_{ER} Q^{1.33},\ F_R = k_R Q^{0.47}  &\text{(eqs 3, 9, 15, 16)}\\
    \mu &= \frac{z}{G}\Big[\frac{2}{d} M_b \sec\theta + \frac{4}{d} M_P\, t
           + \frac{4}{d} M_{ER} + 4 F_R\Big]      &\text{(eqs 20-23)}

with M_b the (design-independent) ball-ball moment per contact pair, absent
for z = 1 (a single ball has no neighbour: that count gets its own structure). Sums,
products, positive powers and square roots of log-log convex expressions are
log-log convex, so μ is exactly representable (no approximation) and so are
the limits: the peak pressure 3Q/(2πa²) = k_p Q^{1/3}, the friction force
μ G, and the load per ball G / z. All coefficients (c, k_P, k_ER, k_R, k_p,
M_b) are read from :func:`physics.evaluate` itself at a reference design, so
the DGP uses the physics' own constants and conventions; only the exponents
are restated here, and ``tests/test_optimize.py`` checks that the DGP value
equals the physics to rounding.

The groove angle is the variable t = tan θ, with θ in [θ_lo, θ_hi] becoming
the monomial bounds tan θ_lo <= t <= tan θ_hi; θ = arctan t is monotone, so
the box maps one to one. The ball count z is a ``cp.Parameter(pos=True)``:
the problem is DPP, so one compiled problem is re-solved for every z, and
problems of the same structure (the same non-zero terms and limits) are
compiled once per process and reused, their coefficients being parameters too.

Every upper limit L enters as ``value <= L (1 - SAFETY_MARGIN)`` so that the
solver's feasibility tolerance cannot produce a design that breaks a limit when
re-evaluated with the exact physics (the minimum load is a plain bound on G:
the solver's load is clipped onto it instead); the margin (1e-7 relative) is far below any engineering
significance and is reported in the certificate.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import cvxpy as cp
import numpy as np

from microbearing import physics

from .problem import DesignProblem

__all__ = [
    "SAFETY_MARGIN",
    "Coefficients",
    "DesignGP",
    "coefficients",
    "design_gp",
    "build_design_gp",
    "LIMIT_NAMES",
    "BallCountResolver",
    "cached_structures",
    "clear_cache",
]

#: Relative tightening of every limit in the DGP (see module docstring). [1]
SAFETY_MARGIN = 1e-7
#: Exponent of Q in M_P = (3/8) μs Q a with a = (R Q / E*)^(1/3) (eqs 3, 16). [1]
PIVOT_EXPONENT = 4.0 / 3.0
#: Exponent of Q in M_ER (eq 15). [1]
HYSTERESIS_EXPONENT = 1.33
#: Exponent of Q (through W) in Houpert's F_R (eq 9). [1]
ROLLING_EXPONENT = 0.47
#: Exponent of Q in the peak pressure 3Q / (2π a²). [1]
PRESSURE_EXPONENT = 1.0 / 3.0

#: The limits a DGP may carry, besides the box bounds; each is "max" or "min".
LIMIT_NAMES = {
    "max_contact_pressure_Pa": "max",
    "max_friction_force_N": "max",
    "min_load_capacity_N": "min",
    "max_load_per_ball_N": "max",
}


@dataclass(frozen=True)
class Coefficients:
    """Design-independent constants of the DGP, read from :func:`physics.evaluate`.

    The ``*_coefficient`` fields are coefficients k of monomials k Q^n in the
    contact load Q [N], so their unit is that of the quantity over N^n.

    Attributes
    ----------
    adhesion_load_N : float
        c = 6πγR, so that Q = Q0 + c + sqrt(2 c Q0 + c²); 0 without adhesion. [N]
    pivoting_coefficient : float
        k_P in M_P = k_P Q^(4/3). [N*m / N^(4/3) = m / N^(1/3)]
    hysteresis_coefficient : float
        k_ER in M_ER = k_ER Q^1.33. [N*m / N^1.33 = m / N^0.33]
    rolling_coefficient : float
        k_R in F_R = k_R Q^0.47 at the design speed. [N / N^0.47 = N^0.53]
    ball_ball_moment_Nm : float
        M_b per contact pair as used in eq 20 (0 when balls do not touch), for two
        balls or more (one ball has none). [N*m]
    pressure_coefficient : float
        k_p in p0 = k_p Q^(1/3). [Pa / N^(1/3)]
    contact_radius_coefficient : float
        k_a = (R / E*)^(1/3) in a = k_a Q^(1/3) (eq 3). [m / N^(1/3)]
    ball_diameter_m : float
        d. [m]
    """

    adhesion_load_N: float
    pivoting_coefficient: float
    hysteresis_coefficient: float
    rolling_coefficient: float
    ball_ball_moment_Nm: float
    pressure_coefficient: float
    contact_radius_coefficient: float
    ball_diameter_m: float


def coefficients(problem: DesignProblem) -> Coefficients:
    """Read the DGP's constants from the physics at a reference design.

    Parameters
    ----------
    problem : DesignProblem
        Fixed parameters, speed and convention.

    Returns
    -------
    Coefficients
        Constants such that the DGP expressions equal the physics outputs.

    Notes
    -----
    At z = 1, θ = 45°, G = 1 N the physics gives Q, M_P, M_ER, F_R and p0;
    dividing by the known powers of Q yields k_P, k_ER, k_R and k_p. c is half
    the adhesion part of Q at Q0 = 0, i.e. twice the pull-off force 3πγR. A
    single ball has no neighbour, so M_b per pair = μ_ball_ball G cos θ d / (2 z)
    (from eqs 20-23) is read at the fewest balls that may touch, z = 2
    (:data:`physics.bearing.MIN_BALLS_TOUCHING`); :func:`design_gp` leaves it out
    below.
    """
    theta_deg, load, balls = 45.0, 1.0, physics.bearing.MIN_BALLS_TOUCHING
    r = physics.evaluate(convention=problem.convention, **problem.physics_inputs(1, theta_deg, load))
    pair = physics.evaluate(convention=problem.convention, outputs=["mu_ball_ball"],
                            **problem.physics_inputs(balls, theta_deg, load))
    q = float(r.contact_load_adhesive_N)
    d = float(problem.fixed["ball_diameter_m"])
    return Coefficients(
        adhesion_load_N=2.0 * float(r.adhesion_force_N),
        pivoting_coefficient=float(r.pivoting_moment_Nm) / q**PIVOT_EXPONENT,
        hysteresis_coefficient=float(r.hysteresis_moment_Nm) / q**HYSTERESIS_EXPONENT,
        rolling_coefficient=float(r.rolling_force_N) / q**ROLLING_EXPONENT,
        ball_ball_moment_Nm=float(pair.mu_ball_ball) * load * np.cos(np.deg2rad(theta_deg)) * d / (2 * balls),
        pressure_coefficient=float(r.max_contact_pressure_Pa) / q**PRESSURE_EXPONENT,
        contact_radius_coefficient=float(r.contact_radius_m) / q ** (1.0 / 3.0),
        ball_diameter_m=d,
    )


@dataclass
class DesignGP:
    """A compiled-once DGP for one structure, with named variables, expressions and parameters.

    Attributes
    ----------
    tan_theta, load_N : cvxpy.Variable
        t = tan θ [1] and G [N].
    balls : cvxpy.Parameter
        Ball count z. [1]
    params : dict of cvxpy.Parameter
        Coefficients and limits by name (bounds ``tan_theta_min`` ...,
        ``load_N_min`` ...; limits by their :data:`LIMIT_NAMES` name).
    expressions : dict of cvxpy.Expression
        ``sec_theta``, ``contact_load_N`` (Q0), ``contact_load_adhesive_N`` (Q), ``contact_radius_m`` (a),
        ``pivoting_moment_Nm``, ``hysteresis_moment_Nm``, ``rolling_force_N``,
        ``ball_race_force_N``, ``mu``, ``friction_force_N``,
        ``max_contact_pressure_Pa``, ``load_per_ball_N``.
    constraints : dict of cvxpy.Constraint
        By name: the four box bounds and the limits present.
    problem : cvxpy.Problem
        Minimize μ subject to ``constraints``; DGP and DPP.
    lock : threading.Lock
        Hold it while assigning parameters and solving.
    """

    tan_theta: cp.Variable
    load_N: cp.Variable
    balls: cp.Parameter
    params: dict[str, cp.Parameter]
    expressions: dict[str, cp.Expression]
    constraints: dict[str, cp.Constraint]
    problem: cp.Problem
    lock: threading.Lock

    def assign(self, values: dict[str, float], balls: int) -> None:
        """Set every parameter (hold :attr:`lock`).

        Parameters
        ----------
        values : dict
            Parameter values by name, from :func:`design_gp`. [SI units]
        balls : int
            Ball count z. [1]
        """
        for name, param in self.params.items():
            param.value = values[name]
        self.balls.value = balls


_TERMS = ("adhesion_load_N", "pivoting_coefficient", "rolling_coefficient", "ball_ball_moment_Nm")


def build_design_gp(terms: frozenset[str], limits: frozenset[str], phase_one: bool = False) -> DesignGP:
    """Build the DGP for a structure: which optional terms and limits are present.

    Parameters
    ----------
    terms : frozenset of str
        The non-zero optional coefficients among ``adhesion_load_N``,
        ``pivoting_coefficient``, ``rolling_coefficient``, ``ball_ball_moment_Nm`` (a zero
        coefficient cannot be a positive DGP parameter, so its term is left out). [-]
    limits : frozenset of str
        Names of :data:`LIMIT_NAMES` to include. [-]
    phase_one : bool, default False
        Build the phase-I problem instead: minimize s >= 0 with every limit
        relaxed by the factor s (``value <= s L``, ``value >= L / s``) and the
        box bounds kept hard. It is always feasible (the box is not empty) and
        the limits can all be met exactly when its optimum is s <= 1. [-]

    Returns
    -------
    DesignGP
        Variables, parameters (unset), expressions, constraints and problem;
        with ``phase_one`` the slack is ``expressions["slack"]``.

    Raises
    ------
    RuntimeError
        If the problem is not DGP or not DPP (a programming error).
    """
    t = cp.Variable(pos=True, name="tan_theta")
    g = cp.Variable(pos=True, name="load_N")
    z = cp.Parameter(pos=True, name="balls")
    names = ["hysteresis_coefficient", "pressure_coefficient", "contact_radius_coefficient",
             "ball_diameter_m", "tan_theta_min", "tan_theta_max", "load_N_min", "load_N_max",
             *sorted(terms), *sorted(limits)]
    p = {n: cp.Parameter(pos=True, name=n) for n in names}

    sec = cp.power(1 + t**2, 0.5)
    q0 = g * sec / (2 * z)
    if "adhesion_load_N" in terms:
        c = p["adhesion_load_N"]
        q = q0 + c + cp.sqrt(2 * c * q0 + c**2)
    else:
        q = q0
    m_er = p["hysteresis_coefficient"] * q**HYSTERESIS_EXPONENT
    inner = 4 * m_er / p["ball_diameter_m"]
    e = {"sec_theta": sec, "contact_load_N": q0, "contact_load_adhesive_N": q, "hysteresis_moment_Nm": m_er}
    if "pivoting_coefficient" in terms:
        e["pivoting_moment_Nm"] = p["pivoting_coefficient"] * q**PIVOT_EXPONENT
        inner = inner + 4 * e["pivoting_moment_Nm"] * t / p["ball_diameter_m"]
    if "rolling_coefficient" in terms:
        e["rolling_force_N"] = p["rolling_coefficient"] * q**ROLLING_EXPONENT
        inner = inner + 4 * e["rolling_force_N"]
    if "ball_ball_moment_Nm" in terms:
        inner = inner + 2 * p["ball_ball_moment_Nm"] * sec / p["ball_diameter_m"]
    e["ball_race_force_N"] = inner
    e["friction_force_N"] = z * inner
    e["mu"] = z * inner / g
    e["max_contact_pressure_Pa"] = p["pressure_coefficient"] * q**PRESSURE_EXPONENT
    # reported; M_P uses k_P Q^(4/3)
    e["contact_radius_m"] = p["contact_radius_coefficient"] * q ** (1.0 / 3.0)
    e["load_per_ball_N"] = g / z

    k_up = 1.0 - SAFETY_MARGIN
    cons = {
        "groove_angle_deg_min": t >= p["tan_theta_min"],
        "groove_angle_deg_max": t <= p["tan_theta_max"],
        "load_N_min": g >= p["load_N_min"],
        "load_N_max": g <= p["load_N_max"],
    }
    measured = {"max_contact_pressure_Pa": e["max_contact_pressure_Pa"],
                "max_friction_force_N": e["friction_force_N"],
                "max_load_per_ball_N": e["load_per_ball_N"]}
    slack = cp.Variable(pos=True, name="slack") if phase_one else 1.0
    for name in sorted(limits):
        if LIMIT_NAMES[name] == "max":
            cons[name] = measured[name] <= k_up * p[name] * slack
        else:
            cons[name] = g * slack >= p[name]
    objective = e["mu"]
    if phase_one:
        e["slack"] = objective = slack
    prob = cp.Problem(cp.Minimize(objective), list(cons.values()))
    # an explicit check, not an assert (asserts vanish under python -O): the certificate relies on it
    if not (prob.is_dgp(dpp=True) and prob.is_dpp("dgp")):
        raise RuntimeError(f"the design problem for limits {sorted(limits)} (phase one: {phase_one}) "
                           "is not DGP and DPP; the global-optimality certificate would not hold")
    return DesignGP(t, g, z, p, e, cons, prob, threading.Lock())


class BallCountResolver:
    """Fast re-solves of one :class:`DesignGP` over ball counts, exploiting how z enters the cone program.

    After cvxpy's change of variables to logarithms, the parameter z appears
    only as log z in affine expressions, so the compiled cone program
    min c'x + d s.t. b - A x in K has A and c independent of z, and b and the
    objective offset d affine in log z. The program is compiled (by cvxpy) at
    z = 1 and z = e, and the affine map is checked at z = 2 (A and c equal,
    b and d as predicted, to 1e-12); each ball count then only sets
    b = b_1 + log z (b_e - b_1) and d likewise, and hands the program to
    Clarabel through cvxpy's own solver interface and solution inversion.
    This skips cvxpy's per-solve parameter handling (~4x faster) and gives
    the solutions cvxpy would give (to the solver tolerance).

    Parameters
    ----------
    gp : DesignGP
        With every parameter but the ball count assigned; hold ``gp.lock``
        while building and using the resolver.

    Raises
    ------
    ValueError
        When the program does not have that structure (then use ``gp.problem.solve``).
    """

    def __init__(self, gp: DesignGP):
        self.gp = gp
        compiled = {}
        for z in (1.0, np.e, 2.0):
            gp.balls.value = z
            data, chain, inverse = gp.problem.get_problem_data(cp.CLARABEL, gp=True)
            compiled[z] = (data, chain, inverse, inverse[-1].inverse_data[cp.settings.OFFSET])
        self.data, self.chain, self.inverse, self.offset = compiled[1.0]
        data_e, _, _, offset_e = compiled[np.e]
        data_2, _, _, offset_2 = compiled[2.0]
        for other in (data_e, data_2):
            if (self.data["A"] != other["A"]).nnz or not np.array_equal(self.data["c"], other["c"]):
                raise ValueError("the cone matrix or cost depends on the ball count")
        self.b_slope = data_e["b"] - self.data["b"]
        self.offset_slope = offset_e - self.offset
        log2 = np.log(2.0)
        if not (np.allclose(self.data["b"] + log2 * self.b_slope, data_2["b"], rtol=1e-12, atol=1e-12)
                and np.isclose(self.offset + log2 * self.offset_slope, offset_2, rtol=1e-12, atol=1e-12)):
            raise ValueError("the cone program is not affine in log(balls)")
        self.inverse[-1].solver_options = {}

    def solve(self, balls: int) -> tuple[str, float | None, float | None, float | None]:
        """Solve for one ball count.

        Parameters
        ----------
        balls : int
            Ball count z. [1]

        Returns
        -------
        status : str
            cvxpy status (``optimal``, ``infeasible``, ...).
        value : float or None
            Optimal objective (μ, or the phase-I slack). [1]
        tan_theta : float or None
            Optimal tan θ. [1]
        load_N : float or None
            Optimal G. [N]
        """
        log_z = np.log(balls)
        data = {**self.data, "b": self.data["b"] + log_z * self.b_slope}
        self.inverse[-1].inverse_data[cp.settings.OFFSET] = self.offset + log_z * self.offset_slope
        raw = self.chain.solver.solve_via_data(data, False, False, {})
        # a phase-I program far from feasible has a log-objective above 709: its slack is inf, i.e. infeasible
        with np.errstate(over="ignore"):
            solution = self.chain.invert(raw, self.inverse)
        primal = solution.primal_vars or {}
        t, g = primal.get(self.gp.tan_theta.id), primal.get(self.gp.load_N.id)
        return (solution.status, None if solution.opt_val is None else float(solution.opt_val),
                None if t is None else float(t), None if g is None else float(g))


_CACHE: dict[tuple[frozenset[str], frozenset[str], bool], DesignGP] = {}
_CACHE_LOCK = threading.Lock()


def cached_structures() -> int:
    """How many DGP structures (terms, limits, phase I) :func:`design_gp` holds compiled. [1]"""
    with _CACHE_LOCK:
        return len(_CACHE)


def clear_cache() -> None:
    """Forget every compiled DGP, so that the next :func:`design_gp` builds and compiles anew.

    For benchmarks that time a cold start; the service never needs it (a
    structure's DGP is reused by every problem of that structure).
    """
    with _CACHE_LOCK:
        _CACHE.clear()


def design_gp(problem: DesignProblem, limits: frozenset[str] | None = None,
              phase_one: bool = False, balls: int | None = None) -> tuple[DesignGP, dict[str, float]]:
    """The cached DGP of a problem's structure and the parameter values of the problem.

    Parameters
    ----------
    problem : DesignProblem
        The design problem.
    limits : frozenset of str, optional
        Which of the problem's limits to include; all of them by default
        (``groove_length_m`` restricts the ball counts, not the DGP). [-]
    phase_one : bool, default False
        The phase-I problem of :func:`build_design_gp` instead. [-]
    balls : int, optional
        The ball count z to be solved. The structure depends on it: below
        :data:`physics.bearing.MIN_BALLS_TOUCHING` a ball has no neighbour and the
        ball-ball term is left out (as the physics leaves it out). None: the
        structure of two or more balls. [1]

    Returns
    -------
    gp : DesignGP
        Shared between calls: hold ``gp.lock`` around ``gp.assign`` and the solves.
    values : dict
        Parameter values for ``gp.assign``. [SI units]
    """
    coef = coefficients(problem)
    values = {
        "adhesion_load_N": coef.adhesion_load_N, "pivoting_coefficient": coef.pivoting_coefficient,
        "hysteresis_coefficient": coef.hysteresis_coefficient,
        "rolling_coefficient": coef.rolling_coefficient,
        "ball_ball_moment_Nm": coef.ball_ball_moment_Nm, "pressure_coefficient": coef.pressure_coefficient,
        "contact_radius_coefficient": coef.contact_radius_coefficient,
        "ball_diameter_m": coef.ball_diameter_m,
        "tan_theta_min": float(np.tan(np.deg2rad(problem.bounds.groove_angle_deg[0]))),
        "tan_theta_max": float(np.tan(np.deg2rad(problem.bounds.groove_angle_deg[1]))),
        "load_N_min": problem.bounds.load_N[0], "load_N_max": problem.bounds.load_N[1],
        **{n: v for n, v in problem.constraints.active_limits().items() if n in LIMIT_NAMES},
    }
    alone = balls is not None and not physics.bearing.ball_ball_contact(True, balls)
    terms = frozenset(n for n in _TERMS if values[n] > 0 and not (alone and n == "ball_ball_moment_Nm"))
    present = frozenset(n for n in LIMIT_NAMES if n in values)
    limits = present if limits is None else frozenset(limits) & present
    key = (terms, limits, phase_one)
    with _CACHE_LOCK:
        if key not in _CACHE:
            _CACHE[key] = build_design_gp(terms, limits, phase_one)
        gp = _CACHE[key]
    return gp, {n: values[n] for n in gp.params}
