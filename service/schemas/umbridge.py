"""Bodies of the UM-Bridge protocol (version 1.0) served under ``/umbridge``.

The protocol's own fields (``name``, ``input``, ``config``, ``outWrt``, ``inWrt``, ``sens``,
``vec``) keep its spelling; ``config`` is this service's (:class:`UMBridgeConfig`). The
protocol is specified by UM-Bridge, not in this service's OpenAPI document.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field

from .base import CheckedColumnKeys, ConventionName, StrictModel, WholeNumber

#: Where the protocol is served: clients are given ``http://host:port/umbridge``.
PREFIX = "/umbridge"

__all__ = ["PREFIX", "UMBridgeApplyJacobianRequest", "UMBridgeConfig", "UMBridgeEvaluateRequest",
           "UMBridgeGradientRequest", "UMBridgeRequest"]


class UMBridgeConfig(StrictModel):
    """Which inputs vary, the values of the others, the outputs, and the points per request."""

    inputs: list[str] | None = Field(default=None, min_length=1, description=(
        "Inputs that vary, in the order of each input vector, by name in their units (see "
        "physics.PARAMETERS, e.g. load_N [N], groove_angle_deg [deg]; a calibrated model's condition "
        "columns). Default: the model's inputs that have no default value."))
    fixed: Annotated[dict[str, float | bool | str], CheckedColumnKeys] = Field(
        default_factory=dict, description=(
            "Values of inputs that do not vary, by name, in their units; the others take the physics "
            "default or the value the model fixed or fitted. A calibrated model also takes a factor "
            "column's group label (e.g. specimen: 'S3'; a label its data never had is a new group) and "
            "the condition columns of its data its terms do not read (checked against the data's range). "
            "A name may carry its unit as a calibration upload's header does ('speed [mm/s]', 'relative "
            "humidity [%]'), converted; a condition that looks like a unit slip (a humidity fraction of "
            "50) is refused."))
    outputs: list[str] = Field(default_factory=lambda: ["mu"], min_length=1, description=(
        "Outputs of each output vector, in order: mu [1] by default; any output of the model (the "
        "physics outputs, mu_effect [1] of a calibrated model, mu_lower and mu_upper [1] of a surrogate) "
        "and outside_domain (1 where the model's figures do not hold, else 0) [1]."))
    points: WholeNumber = Field(default=1, ge=1, description=(
        "Points per request [1]: input holds this many vectors, output answers as many."))
    convention: ConventionName | None = Field(default=None, description=(  # type: ignore[valid-type]
        "Reading of the paper's ambiguous ball-ball terms, for the physics (a stored model has its own)."))


class UMBridgeRequest(StrictModel):
    """A request naming a model: ModelInfo, InputSizes, OutputSizes, and the base of the others."""

    name: str = Field(description="A model from /umbridge/Info: physics, calibrated:<id> or surrogate:<id>.")
    config: UMBridgeConfig = Field(default_factory=UMBridgeConfig, description="See UMBridgeConfig.")


class UMBridgeEvaluateRequest(UMBridgeRequest):
    """Evaluate: one input vector per point."""

    input: list[list[float]] = Field(description=(
        "One vector per point, each holding the values of config.inputs in that order, in their units."))


class UMBridgeGradientRequest(UMBridgeEvaluateRequest):
    """Gradient: sens times the Jacobian of output vector outWrt with respect to input vector inWrt."""

    outWrt: WholeNumber = Field(ge=0, description="Index of the output vector (a point) [1].")
    inWrt: WholeNumber = Field(ge=0, description="Index of the input vector (a point) [1].")
    sens: list[float] = Field(description=(
        "Sensitivity: one value per output of config.outputs [output units]."))


class UMBridgeApplyJacobianRequest(UMBridgeEvaluateRequest):
    """ApplyJacobian: the Jacobian of output vector outWrt with respect to input vector inWrt, times vec."""

    outWrt: WholeNumber = Field(ge=0, description="Index of the output vector (a point) [1].")
    inWrt: WholeNumber = Field(ge=0, description="Index of the input vector (a point) [1].")
    vec: list[float] = Field(description="Direction: one value per input of config.inputs [input units].")
