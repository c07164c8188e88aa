"""Bodies of ``/v1/friction`` and ``/v1/friction/batch``, built from the physics tables."""

from __future__ import annotations

from pydantic import Field, create_model

from microbearing import physics

from .base import (
    Convention,
    ConventionName,
    OutputName,
    ResponseModel,
    StrictModel,
    output_fields,
    parameter_fields,
)
from .calibrations import MODEL_FIELDS, MODEL_RESPONSE_FIELDS

__all__ = ["FrictionBatchPoints", "FrictionBatchRequest", "FrictionBatchResponse", "FrictionRequest",
           "FrictionResponse"]

_CONVENTION = (ConventionName, Field(default=Convention(physics.DEFAULT_CONVENTION),
                                     description="Reading of the paper's ambiguous ball-ball terms."))

FrictionRequest = create_model(
    "FrictionRequest", __base__=StrictModel,
    __doc__="One design point: the physics inputs by name; optional ones take their defaults.",
    convention=_CONVENTION, **parameter_fields(), **MODEL_FIELDS,
)

FrictionResponse = create_model(
    "FrictionResponse", __base__=ResponseModel,
    __doc__="Every output of the friction model for one design point.",
    convention=(ConventionName, Field(description="Convention used.")), **output_fields(),
    **MODEL_RESPONSE_FIELDS,
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
        default=None, min_length=1, description="Outputs to return (default: all of them).")
    convention: ConventionName = _CONVENTION[1]  # type: ignore[valid-type]


FrictionBatchResponse = create_model(
    "FrictionBatchResponse", __base__=ResponseModel,
    __doc__="The chosen outputs as columns, one value per point, in the order of the points.",
    **output_fields(columns=True, optional=True),
)
