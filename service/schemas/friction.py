"""Bodies of ``/v1/friction`` and ``/v1/friction/batch``, built from the physics tables."""

from __future__ import annotations

from collections.abc import Collection
from typing import Annotated, Any, ClassVar

from pydantic import AfterValidator, BeforeValidator, Field, PrivateAttr, create_model, model_validator

from microbearing import physics
from microbearing.physics.columns import ColumnError, Reading, read_name

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
    read_value,
)
from .calibrations import MODEL_FIELDS, MODEL_RESPONSE_FIELDS

__all__ = ["INPUT_KEYS", "INPUT_WARNINGS", "FrictionBatchPoints", "FrictionBatchRequest",
           "FrictionBatchResponse", "FrictionRequest", "FrictionResponse", "InputKeys", "read_input_keys"]

#: What a description says about the names of physics inputs.
INPUT_KEYS = (" An input may be sent under a name with its unit, as a calibration upload's header (e.g. "
              "'speed [mm/s]', speed_mm_s, 'load [mN]', load_mN), converted as the upload converts it; two "
              "names of one input are refused.")


def read_input_keys(body: Any, fields: Collection[str] = ()) -> Any:
    """A body's physics inputs sent under a name with a unit (``speed [mm/s]``, ``load_mN``), renamed
    to the input and converted, as :func:`physics.columns.read_name` reads a calibration upload's header.

    The body's own ``fields`` and every other key are left as sent: a name no door reads is refused by
    the schema (``extra="forbid"``), which names it.

    Raises
    ------
    ValueError
        Naming the key, when another key is read as the same input.
    """
    return _read_keys(body, fields)[0]


def _read_keys(body: Any, fields: Collection[str]
               ) -> tuple[Any, dict[str, tuple[str, Any]], dict[str, Reading]]:
    """:func:`read_input_keys`'s body, each input it renamed (input -> (key as sent, value as sent)) and
    how (input -> its :class:`physics.columns.Reading`)."""
    if not isinstance(body, dict):
        return body, {}, {}
    read: dict[str, Any] = {}
    sent: dict[str, tuple[str, Any]] = {}
    readings: dict[str, Reading] = {}
    for key, value in body.items():
        reading = None
        if isinstance(key, str) and key not in fields:
            try:
                reading = read_name(key)
            except ColumnError:
                reading = None  # an unknown unit: the schema names the key
        # renamed also without a conversion: load [N] is load_N
        if reading is None or reading.name not in physics.PARAMETERS or reading.name == key:
            read[key] = value
            continue
        if reading.name in body or reading.name in read:
            raise ValueError(f"{key}: another key is read as {reading.name} too; keep one")
        # a range object stays one (its ends converted): a batch's column is no range, an envelope's is
        read[reading.name], sent[reading.name] = read_value(reading, value, range_object=True), (key, value)
        readings[reading.name] = reading
    return read, sent, readings


class InputKeys(StrictModel):
    """A body whose physics inputs may be sent under names with units (:func:`read_input_keys`); each
    renamed one keeps its key and value as sent (:meth:`sent_as`), for a later refusal's words."""

    _sent: dict[str, tuple[str, Any]] = PrivateAttr(default_factory=dict)
    _readings: dict[str, Reading] = PrivateAttr(default_factory=dict)

    @model_validator(mode="wrap")
    @classmethod
    def _read_input_keys(cls, body: Any, handler: Any) -> Any:
        read, sent, readings = _read_keys(body, cls.model_fields)
        return handler(read).with_sent(sent, readings)

    def with_sent(self, sent: dict[str, tuple[str, Any]],
                  readings: dict[str, Reading] | None = None) -> InputKeys:
        """This body, remembering the keys and values its renamed inputs were sent as (:meth:`sent_as`) and
        how they were read (:attr:`readings`)."""
        self._sent = dict(sent)
        self._readings = dict(readings or {})
        return self

    @property
    def readings(self) -> dict[str, Reading]:
        """How each renamed input was read from its key as sent (``load [mN]``: x 0.001), for words in the
        request's units."""
        return dict(self._readings)

    @property
    def renamed(self) -> dict[str, tuple[str, Any]]:
        """Every input of this body that was renamed: input -> (key as sent, value as sent)."""
        return dict(self._sent)

    def columns(self, *, sent_only: bool = False) -> dict[str, Any]:
        """Each input's value as validated (a scalar, a list, or a large body's array), without the
        serialization of ``model_dump``; only those sent with ``sent_only``."""
        sent = self.model_fields_set
        return {name: getattr(self, name) for name in type(self).model_fields
                if not sent_only or name in sent}

    def sent_as(self, name: str) -> tuple[str, Any] | None:
        """The key and value a physics input ``name`` of this body was sent as, when it was renamed
        (``("load [mN]", [20, 5])`` for load_N); None when it was sent under its own name."""
        return self._sent.get(name)


_CONVENTION = (ConventionName, Field(
    default=Convention(physics.DEFAULT_CONVENTION),
    description="Reading of the paper's ambiguous ball-ball terms; a calibrated model uses its own (naming "
                "another is a 422)."))

FrictionRequest = create_model(
    "FrictionRequest", __base__=InputKeys,
    __doc__="One design point: the physics inputs by name; optional ones take their defaults." + INPUT_KEYS,
    convention=_CONVENTION, **parameter_fields(), **MODEL_FIELDS,
)

#: The answer's warnings of inputs that look like a unit slip (physics.slips.input_slips).
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
    "FrictionBatchPoints", __base__=InputKeys,
    __doc__="Design points as columns: each input a scalar or a list; lists share one length." + INPUT_KEYS,
    **parameter_fields(columns=True),
)


def _one_kind(value: Any) -> Any:
    """A condition's list holds numbers or labels, never both: one sentence, not each member's of the
    union (``["0.5", 0.6]`` had its valid 0.6 called "not a valid string")."""
    if isinstance(value, list):
        texts = [i for i, v in enumerate(value) if isinstance(v, str)]
        if texts and len(texts) < len(value):  # the odd one out: text among numbers, or the reverse
            odd = texts[0] if len(texts) <= len(value) - len(texts) else next(
                i for i, v in enumerate(value) if not isinstance(v, str))
            raise ValueError(f"a list holds numbers or a factor column's labels, not both: element {odd} is "
                             f"{value[odd]!r} among {'numbers' if odd in texts else 'labels'}; send numbers "
                             f"as numbers")
    return value


#: A condition column of a batch: one value or label for every point, or a list of one per point.
_ConditionColumn = Annotated[float | str | list[float] | list[str], BeforeValidator(_one_kind)]


def _once_each(names: list[str] | None) -> list[str] | None:
    """The names in their first order, each once."""
    return None if names is None else list(dict.fromkeys(names))


class FrictionBatchRequest(StrictModel):
    """Many design points as columns, and the outputs wanted."""

    #: The long lists of numbers of ``points`` in a large body are read as arrays (parse_json_body).
    array_objects: ClassVar[frozenset[str]] = frozenset({"points"})

    points: FrictionBatchPoints = Field(description="The inputs, column by column.")  # type: ignore[valid-type]
    outputs: Annotated[list[OutputName] | None, AfterValidator(_once_each)] = Field(  # type: ignore[valid-type]
        default=None, min_length=1, description=(
            "Outputs to return (default: all of them; a name given twice is returned once); with a "
            "calibrated model, mu brings mu_effect, mu_lower and mu_upper [1]."))
    convention: ConventionName = Field(  # type: ignore[valid-type]
        default=Convention(physics.DEFAULT_CONVENTION), description=(
            "Reading of the paper's ambiguous ball-ball terms; a calibrated model uses its own (naming "
            "another is a 422)."))
    model: str = MODEL_FIELDS["model"][1]
    conditions: Annotated[dict[str, _ConditionColumn] | None, ColumnKeys] = Field(
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
