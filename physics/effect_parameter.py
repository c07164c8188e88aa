"""One fitted parameter of an effect or a drift law (:mod:`physics.effects`, :mod:`physics.drift_laws`):
its name with its unit, bounds and the values a micro ball bearing plausibly shows."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["EffectParameter"]


@dataclass(frozen=True)
class EffectParameter:
    """One fitted parameter of an :class:`Effect`.

    Attributes
    ----------
    name : str
        Name with its unit (``drag_force_N``).
    unit : str
        SI unit, ``"1"`` for dimensionless, ``"driver"`` for the unit of the driving column.
    description : str
        Meaning in one sentence.
    minimum, maximum : float
        Bounds of the fit (may be infinite).
    plausible : (float, float) or None
        The values a micro ball bearing plausibly shows, in ``unit`` (a calibration names a fitted
        value outside them implausible); None: any value within the bounds.
    within_data : bool
        Whether the value is a scale of the driver (a decay length, a Stribeck speed) that must lie
        within reach of the data's driver values: a decay far beyond them is a trend, not this law.
    """

    name: str
    unit: str
    description: str
    minimum: float
    maximum: float
    plausible: tuple[float, float] | None = None
    within_data: bool = False
