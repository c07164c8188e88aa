"""Published elastic properties of ball and race materials used in micro bearings.

Each :class:`Material` gives Young's modulus and Poisson's ratio at room
temperature with its source. :func:`material_parameters` turns a ball and a race
material into the keyword arguments of :func:`physics.evaluate`.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Material", "MATERIALS", "material_parameters"]


@dataclass(frozen=True)
class Material:
    """Elastic properties of one material.

    Attributes
    ----------
    name : str
        Key in :data:`MATERIALS`.
    youngs_modulus_Pa : float
        Young's modulus E. [Pa]
    poisson_ratio : float
        Poisson's ratio ν. [1]
    density_kg_m3 : float
        Density. [kg/m^3]
    source : str
        Where the values come from.
    """

    name: str
    youngs_modulus_Pa: float
    poisson_ratio: float
    density_kg_m3: float
    source: str


#: Ball and race materials, keyed by name.
MATERIALS: dict[str, Material] = {
    m.name: m
    for m in [
        Material("stainless_steel", 2.1e11, 0.3, 7900.0,
                 "Olaru et al., COMEC 2005 (the balls of Lin et al. 2004)."),
        Material("aisi_440c", 2.0e11, 0.28, 7650.0,
                 "AISI 440C martensitic bearing steel, ASM Handbook vol. 1 (1990)."),
        Material("aisi_52100", 2.1e11, 0.29, 7810.0,
                 "AISI 52100 bearing steel, Harris and Kotzalas, Rolling Bearing Analysis (2006)."),
        Material("silicon", 1.5e11, 0.3, 2330.0,
                 "Olaru et al., COMEC 2005 (isotropic value used for the grooves)."),
        Material("silicon_110", 1.69e11, 0.064, 2330.0,
                 "Single-crystal Si along <110>, Hopcroft, Nix, Kenny, J. MEMS 19(2), 2010."),
        Material("silicon_nitride", 3.1e11, 0.27, 3200.0,
                 "Hot-pressed Si3N4 bearing balls, Harris and Kotzalas (2006)."),
        Material("borosilicate_glass", 6.4e10, 0.2, 2230.0,
                 "Borosilicate glass (Pyrex 7740 / Borofloat 33) manufacturer data."),
        Material("fused_silica", 7.25e10, 0.17, 2200.0,
                 "Fused quartz, manufacturer data (Heraeus)."),
        Material("sapphire", 3.45e11, 0.29, 3980.0,
                 "Single-crystal Al2O3, c-axis average, Kyocera data."),
        Material("ruby", 3.7e11, 0.29, 3980.0,
                 "Synthetic ruby balls, precision ball manufacturer data."),
    ]
}


def material_parameters(ball: str, race: str) -> dict[str, float]:
    """The elastic inputs of :func:`physics.evaluate` for a ball and race material.

    Parameters
    ----------
    ball, race : str
        Keys of :data:`MATERIALS`.

    Returns
    -------
    dict
        ``ball_youngs_modulus_Pa`` [Pa], ``ball_poisson_ratio`` [1],
        ``race_youngs_modulus_Pa`` [Pa], ``race_poisson_ratio`` [1].

    Raises
    ------
    ValueError
        For an unknown material name.

    Examples
    --------
    >>> material_parameters("silicon_nitride", "silicon")["ball_youngs_modulus_Pa"]
    310000000000.0
    """
    for label, key in (("ball", ball), ("race", race)):
        if key not in MATERIALS:
            raise ValueError(f"{label} material must be one of {', '.join(MATERIALS)}; got {key!r}")
    b, r = MATERIALS[ball], MATERIALS[race]
    return {
        "ball_youngs_modulus_Pa": b.youngs_modulus_Pa,
        "ball_poisson_ratio": b.poisson_ratio,
        "race_youngs_modulus_Pa": r.youngs_modulus_Pa,
        "race_poisson_ratio": r.poisson_ratio,
    }
