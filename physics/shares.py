"""Declared physics parameters that a term may move (a drift with a condition, or a fit): how the
physics' μ moves with each, its share of μ where it has one, and the values it physically takes.

Callers (calibrate's candidates and credibility checks, optimize's certificates) read these declarations;
:mod:`physics.effects` re-exports them beside the effects and drift laws.
"""

from __future__ import annotations

from dataclasses import dataclass

from .lubrication import LOAD_EXPONENT
from .moments import HYSTERESIS_LOAD_EXPONENT

__all__ = ["CONTACT_LOAD_EXPONENTS", "DRIFT_PARAMETERS", "PARAMETER_SHARES", "ParameterShare"]


@dataclass(frozen=True)
class ParameterShare:
    """How the physics' μ moves with a declared parameter that a term may move (a drift, or a fit).

    Attributes
    ----------
    name : str
        The physics parameter (:data:`physics.PARAMETERS`).
    why : str
        Why a tribologist would suspect it drifts with a condition.
    direction : int
        +1 where μ is non-decreasing in it, -1 non-increasing (from the equations; the tests check each
        on the exact physics).
    output : str or None
        The physics output that is the parameter's share of μ, μ = rest + share with share ∝ p^exponent
        (None: it moves the contact load or radius, with no such form).
    exponent : float or None
        That power. [1]
    linear : bool
        Whether a fitted value of it has a share linear in it that is a summand of the physics'
        posynomial, μ(p + h) - μ(p) = h × output / p, non-decreasing in the angle and the speed.
    plausible : (float, float) or None
        The values the parameter physically takes in a micro ball bearing, in its unit (a fit or a
        drift that moves it outside is named implausible by the calibration).
    contact_load : bool
        Whether it moves μ only through the JKR contact load Q (eq 8), which every share of μ in
        :data:`CONTACT_LOAD_EXPONENTS` follows as a power at a fixed angle and speed (the adhesion
        energy; Q's elasticity in it is :func:`physics.contact.jkr_load_elasticity`).
    """

    name: str
    why: str
    direction: int
    output: str | None = None
    exponent: float | None = None
    linear: bool = False
    plausible: tuple[float, float] | None = None
    contact_load: bool = False


#: The parameters a drift may move, with the physics' direction in each and its share of μ: the viscosity
#: and the pressure-viscosity coefficient enter only Houpert's rolling force, as η^0.66 and (α E')^0.022
#: (eq 9); the adhesion energy raises the contact load Q (eq 8), which every moment and the rolling force
#: grow with; the surface tension and μ_b enter the ball-ball moment as factors, μ_s the pivoting moment
#: (μ_s Q a, eq 16); a Young's modulus raises E*, and μ falls with it (the pivoting moment ~ Q a,
#: a ~ E*^-1/3; the rolling force ~ E'^-0.108; the hysteresis moment does not read it).
PARAMETER_SHARES: dict[str, ParameterShare] = {s.name: s for s in [
    ParameterShare("viscosity_Pa_s", "the water film's viscosity falls as temperature rises", 1,
                   "mu_rolling", 0.66, plausible=(1e-4, 10.0)),
    ParameterShare("pressure_viscosity_1_Pa", "the pressure-viscosity coefficient falls as temperature rises",
                   1, "mu_rolling", 0.022, plausible=(1e-9, 1e-7)),
    ParameterShare("adhesion_energy_J_m2", "adhesion (capillary bridges, surface films) grows with humidity",
                   1, plausible=(1e-3, 1.0), contact_load=True),
    ParameterShare("water_surface_tension_N_m", "surface tension of water falls with temperature", 1,
                   "mu_ball_ball", 1.0, plausible=(0.05, 0.08)),
    ParameterShare("mu_pivot", "the ball-race sliding coefficient depends on coating, humidity and "
                               "temperature", 1, "mu_pivoting", 1.0, linear=True, plausible=(0.01, 1.5)),
    ParameterShare("mu_ball", "the ball-ball sliding coefficient depends on coating, humidity and "
                              "temperature", 1, "mu_ball_ball", 1.0, plausible=(0.01, 1.5)),
    # Moduli: glass (70 GPa) and silicon (130-170) to silicon nitride (310) and sapphire (about 430).
    ParameterShare("ball_youngs_modulus_Pa", "the balls' modulus depends on material and temperature", -1,
                   plausible=(5e10, 4.5e11)),
    ParameterShare("race_youngs_modulus_Pa",
                   "the races' modulus depends on material, coating and temperature", -1,
                   plausible=(5e10, 4.5e11)),
]}
#: The shares of μ (outputs of :func:`physics.evaluate`) that the JKR contact load Q moves, each a power of Q
#: at a fixed angle, speed, load and balls: the pivoting moment μ_s Q a with a ∝ Q^(1/3) (eqs 3, 16), the
#: hysteresis moment ∝ Q^1.33 (eq 15), the rolling force ∝ Q^0.47 (eq 9); the ball-ball share does not read
#: Q, and μ is the sum of the four shares (eqs 20-23).
CONTACT_LOAD_EXPONENTS: dict[str, float] = {"mu_pivoting": 4.0 / 3.0,
                                            "mu_hysteresis": HYSTERESIS_LOAD_EXPONENT,
                                            "mu_rolling": LOAD_EXPONENT}
#: Declared physics parameters that may drift with a condition, with why a tribologist would suspect it.
DRIFT_PARAMETERS: dict[str, str] = {name: share.why for name, share in PARAMETER_SHARES.items()}
