"""Bodies of ``/v1/friction`` and ``/v1/friction/batch``, built from the physics tables."""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, create_model

from microbearing import physics

from .base import (
    UNIT_KEYS,
    ColumnKeys,
    Convention,
    ConventionName,
    OutputName,
    ResponseModel,
    StrictModel,
    output_fields,
    parameter_fields,
)
from .calibrations import MODEL_FIELDS, MODEL_RESPONSE_FIELDS

__all__ = ["INPUT_WARNINGS", "FrictionBatchPoints", "FrictionBatchRequest", "FrictionBatchResponse",
           "FrictionRequest", "FrictionResponse"]

_CONVENTION = (ConventionName, Field(
    default=Convention(physics.DEFAULT_CONVENTION),
    description="Reading of the paper's ambiguous ball-ball terms; a calibrated model uses its own (naming "
                "another is a 422)."))

FrictionRequest = create_model(
    "FrictionRequest", __base__=StrictModel,
    __doc__="One design point: the physics inputs by name; optional ones take their defaults.",
    convention=_CONVENTION, **parameter_fields(), **MODEL_FIELDS,
)

#: The answer's warnings of inputs that look like a unit slip (physics.columns.input_slips).
INPUT_WARNINGS = (list[str] | None, Field(default=None, description=(
    "Physics inputs that look like a unit slip, in the words with which a calibration upload refuses "
    "them (e.g. speed_m_s above 10 m/s: mm/s?); the model answers as asked. Absent when none.")))

FrictionResponse = create_model(
    "FrictionResponse", __base__=ResponseModel,
    __doc__="Every output of the friction model for one design point.",
    convention=(ConventionName, Field(description="Convention used.")), **output_fields(),
    **MODEL_RESPONSE_FIELDS, input_warnings=INPUT_WARNINGS,
)

FrictionBatchPoints = create_model(
    "FrictionBatchPoints", __base__=StrictModel,
    __doc__="Design points as columns: each input a scalar or a list; lists share one length.",
    **parameter_fields(columns=True),
)


class FrictionBatchRequest(StrictModel):
    """Many design points as columns, and the outputs wanted."""

    points: FrictionBatchPoints = Field(description="The inputs, column by column.")  # type: ignore[valid-type]
    outputs: list[OutputName] | None = Field(  # type: ignore[valid-type]
        default=None, min_length=1, description=(
            "Outputs to return (default: all of them); with a calibrated model, mu brings mu_effect, "
            "mu_lower and mu_upper [1]."))
    convention: ConventionName = Field(  # type: ignore[valid-type]
        default=Convention(physics.DEFAULT_CONVENTION), description=(
            "Reading of the paper's ambiguous ball-ball terms; a calibrated model uses its own (naming "
            "another is a 422)."))
    model: str = MODEL_FIELDS["model"][1]
    conditions: Annotated[dict[str, float | str | list[float] | list[str]] | None, ColumnKeys] = Field(
        default=None, description=(
        "Condition columns of the calibration data for a calibrated model, e.g. relative_humidity [1] "
        "[unit of each column as in the calibration data]: a number for every point or a list of one "
        "value per point (lists share the points' length). Those the model's terms read are required; "
        "a column the calibration never saw is refused (422 naming it). A factor column takes group "
        "labels (one, or one per point): a known group at its own level, a new one with the spread "
        "between groups in the interval." + UNIT_KEYS))


_LIST_OF_POINTS = " One value per point, in the order of the points."

FrictionBatchResponse = create_model(
    "FrictionBatchResponse", __base__=ResponseModel,
    __doc__="The chosen outputs as columns, one value per point, in the order of the points.",
    **output_fields(columns=True, optional=True),
    model=MODEL_RESPONSE_FIELDS["model"],
    **{name: (list[float] | None, Field(default=None, description=MODEL_RESPONSE_FIELDS[name][1].description
                                        + _LIST_OF_POINTS))
       for name in ("mu_effect", "mu_lower", "mu_upper")},
    in_domain=(list[bool] | None, Field(default=None, description=(
        "Whether each point lies within the range of every column of the calibration data (false: an "
        "extrapolation; domain_warnings says where). Absent for physics and for models calibrated "
        "before domains existed." + _LIST_OF_POINTS))),
    domain_warnings=(list[str] | None, Field(default=None, description=(
        "One sentence per input or condition outside the calibration data over the whole batch, naming "
        "the column, its values there (in the column's unit), the range and the number of points "
        "outside (absent for physics)."))),
    input_warnings=INPUT_WARNINGS,
)
