"""The numerical cases of Olaru et al. (2005) and the ranges the paper reports.

The paper computes two bearings of Lin et al. (2004) at 27 degC, 40 % RH, over a
slider speed of 0 to 150 mm/s:

* case A: 4 balls that do not touch, a slider of 0.9 g, μs = 0.5 and 1; Fig. 5
  plots the per-contact coefficient ``mu_contact`` without (5a) and with (5b)
  ball-race adhesion;
* case B: 18 balls (9 per groove) touching, a slider of 0.4 g, μs = 1,
  μb = 0.5 and 1; Fig. 6 plots the global ``mu``.

The interfacial energy γ is not printed; the quoted pull-off forces of
200-300 uN give γ ≈ 0.15-0.22 J/m² through eq 1, and 0.18 J/m² reproduces both
figures.
"""

from __future__ import annotations

import textwrap
from dataclasses import dataclass, field

import numpy as np

from .bearing import evaluate

__all__ = ["STANDARD_GRAVITY_M_S2", "PaperCase", "PAPER_CASES", "case_range", "report", "plot"]

#: Standard gravity used to turn slider masses into loads. [m/s^2]
STANDARD_GRAVITY_M_S2 = 9.80665

#: Slider speeds of the paper's figures, 0 to 150 mm/s. [m/s]
PAPER_SPEEDS_M_S = np.linspace(0.0, 0.150, 151)


@dataclass(frozen=True)
class PaperCase:
    """One curve family of the paper's figures.

    Attributes
    ----------
    name : str
        Short key.
    title : str
        What the case is.
    output : str
        ``"mu_contact"`` (Fig. 5) or ``"mu"`` (Fig. 6).
    reported : tuple of float
        The range of the output the paper reports over 0-150 mm/s. [1]
    params : dict
        Fixed inputs of :func:`physics.evaluate` (SI).
    varied : tuple
        ``(parameter name, values)`` of the curves in the figure.
    """

    name: str
    title: str
    output: str
    reported: tuple[float, float]
    params: dict = field(default_factory=dict)
    varied: tuple = ()


_COMMON = {"ball_diameter_m": 285e-6, "groove_angle_deg": 54.7}

#: The paper's three cases, keyed by name.
PAPER_CASES: dict[str, PaperCase] = {
    c.name: c
    for c in [
        PaperCase(
            "A_no_adhesion", "Case A, 4 balls apart, 0.9 g, no adhesion (Fig. 5a)",
            "mu_contact", (0.002, 0.005),
            {**_COMMON, "balls": 4, "load_N": 0.9e-3 * STANDARD_GRAVITY_M_S2,
             "adhesion_energy_J_m2": 0.0, "balls_touching": False},
            ("mu_pivot", (0.5, 1.0)),
        ),
        PaperCase(
            "A_adhesion", "Case A, 4 balls apart, 0.9 g, adhesion 0.18 J/m^2 (Fig. 5b)",
            "mu_contact", (0.007, 0.012),
            {**_COMMON, "balls": 4, "load_N": 0.9e-3 * STANDARD_GRAVITY_M_S2,
             "adhesion_energy_J_m2": 0.18, "balls_touching": False},
            ("mu_pivot", (0.5, 1.0)),
        ),
        PaperCase(
            "B", "Case B, 18 balls touching, 0.4 g, mu_s = 1, adhesion 0.18 J/m^2 (Fig. 6)",
            "mu", (0.25, 0.55),
            {**_COMMON, "balls": 18, "load_N": 0.4e-3 * STANDARD_GRAVITY_M_S2,
             "adhesion_energy_J_m2": 0.18, "balls_touching": True, "mu_pivot": 1.0},
            ("mu_ball", (0.5, 1.0)),
        ),
    ]
}


def case_curves(case: PaperCase, speeds_m_s=PAPER_SPEEDS_M_S, convention="olaru2005"):
    """The case's output against speed, one curve per varied value.

    Parameters
    ----------
    case : PaperCase
        One of :data:`PAPER_CASES`. [-]
    speeds_m_s : array_like
        Slider speeds. [m/s]
    convention : str
        See :data:`physics.CONVENTIONS`. [-]

    Returns
    -------
    numpy.ndarray
        Shape ``(len(case.varied[1]), len(speeds_m_s))``. [1]
    """
    name, values = case.varied
    result = evaluate(convention=convention, **case.params,
                      **{name: np.asarray(values)[:, None]},
                      speed_m_s=np.asarray(speeds_m_s)[None, :])
    return getattr(result, case.output)


def case_range(case: PaperCase, convention="olaru2005") -> tuple[float, float]:
    """Minimum and maximum of the case's output over its curves and 0-150 mm/s.

    Parameters
    ----------
    case : PaperCase
        One of :data:`PAPER_CASES`; its curves are evaluated at the 151 speeds
        of :data:`PAPER_SPEEDS_M_S`, 0 to 0.150 m/s. [-]
    convention : str, default "olaru2005"
        A key of :data:`physics.CONVENTIONS`. [-]

    Returns
    -------
    tuple of float
        (minimum, maximum) of ``case.output`` (``mu_contact`` or ``mu``),
        comparable with ``case.reported``. [1]

    Examples
    --------
    >>> [round(v, 3) for v in case_range(PAPER_CASES["B"])]  # the paper reports 0.25-0.55
    [0.306, 0.566]
    """
    curves = case_curves(case, convention=convention)
    return float(curves.min()), float(curves.max())


def report(convention="olaru2005") -> str:
    """A table of each case's computed range beside the paper's, as text.

    Parameters
    ----------
    convention : str, default "olaru2005"
        A key of :data:`physics.CONVENTIONS`. [-]

    Returns
    -------
    str
        One line per case of :data:`PAPER_CASES`: its title, output, the
        computed (minimum-maximum) range of the friction coefficient over
        0-150 mm/s and the paper's range, both [1] (dimensionless), then the
        measured values of Lin et al. [1].
    """
    lines = [f"{'case':<72} {'output':<11} {'computed':>17} {'paper':>15}"]
    for case in PAPER_CASES.values():
        lo, hi = case_range(case, convention)
        plo, phi = case.reported
        lines.append(f"{case.title:<72} {case.output:<11} {lo:8.4f}-{hi:<8.4f} {plo:7.3f}-{phi:<7.3f}")
    lines.append("Lin et al. (2004) measured, case A conditions: dynamic 0.007 (average), static 0.01.")
    return "\n".join(lines)


def plot(path, convention="olaru2005"):
    """Draw μ against speed as the paper's Figs. 5a, 5b and 6, into a PNG file.

    Parameters
    ----------
    path : str or path-like
        Output file. The format follows the extension (PNG, PDF, SVG).
    convention : str
        See :data:`physics.CONVENTIONS`.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), constrained_layout=True)
    speeds_mm_s = PAPER_SPEEDS_M_S * 1e3
    for ax, case in zip(axes, PAPER_CASES.values(), strict=True):
        curves = case_curves(case, convention=convention)
        name, values = case.varied
        for curve, value in zip(curves, values, strict=True):
            ax.plot(speeds_mm_s, curve, label=f"{name} = {value:g}")
        ax.axhspan(*case.reported, color="0.85", label="range reported in the paper")
        ax.set_title(textwrap.fill(case.title, 48), fontsize=9)
        ax.set_xlabel("slider speed [mm/s]")
        ax.set_ylabel(f"{case.output} [-]")
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.savefig(path, dpi=120)
    plt.close(fig)
