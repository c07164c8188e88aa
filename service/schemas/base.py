"""Base models and the fields built from :data:`physics.PARAMETERS` and :data:`physics.OUTPUTS`.

Request bodies derive from :class:`StrictModel`: unknown fields, strings or booleans for
numbers, NaN and infinities are rejected with 422. Build physics inputs with
:func:`parameter_fields` rather than repeating names, units or bounds::

    MyRequest = pydantic.create_model(
        "MyRequest", __base__=StrictModel,
        **parameter_fields(optional=True),          # every physics input, all optional
        iterations=(WholeNumber, Field(ge=1, le=1000, description="Optimizer iterations [1].")),
    )
"""

from __future__ import annotations

from collections.abc import Callable
from enum import StrEnum
from typing import Annotated, Any, TypeVar

import numpy as np
from fastapi import Request
from fastapi.exceptions import RequestValidationError
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    StrictBool,
    ValidationError,
    WrapValidator,
)
from pydantic_core import from_json
from starlette.concurrency import run_in_threadpool
from starlette.requests import ClientDisconnect

from microbearing import physics
from microbearing.physics.columns import ColumnError, Reading, read_name
from microbearing.physics.spans import NO_SPACING, no_range

from ..jsonguard import is_json_media_type
from ..problems import VALIDATION_TYPE, ProblemError, not_json_problem
from .number_lists import array_column, lift_number_lists, place_arrays

__all__ = [
    "RAW_BODY_MODELS",
    "REQUIRED_INPUTS",
    "absent_at",
    "given_at",
    "in_one_place",
    "only_with_model",
    "physics_value_schema",
    "Convention",
    "DateTimeText",
    "ConventionName",
    "Output",
    "OutputName",
    "ResponseModel",
    "StrictModel",
    "FOLDING_SAFE_NAMES",
    "NEXT_URL",
    "add_raw_body_schemas",
    "with_folding_safe_names",
    "output_fields",
    "parameter_description",
    "parameter_fields",
    "parameter_type",
    "LIFT_BODY_BYTES",
    "lifted_document",
    "parse_json_body",
    "read_body",
    "raw_json_body",
    "read_column_keys",
    "check_column_keys",
    "ColumnKeys",
    "CheckedColumnKeys",
    "UNIT_KEYS",
    "read_value",
    "PairSpelling",
    "RangeSpelling",
]

ModelT = TypeVar("ModelT", bound=BaseModel)


class StrictModel(BaseModel):
    """Base of request bodies: strict types, no unknown fields, finite numbers only."""

    model_config = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


class ResponseModel(BaseModel):
    """Base of response bodies."""

    model_config = ConfigDict(extra="forbid")


# Named enums (one schema component each, one enum class in a generated client). Strict models
# only take enum instances from Python objects, so these fields validate leniently: a JSON string.
Convention = StrEnum("Convention", {name: name for name in physics.CONVENTIONS})
Output = StrEnum("Output", {name: name for name in physics.OUTPUTS})
#: One of :data:`physics.CONVENTIONS`.
ConventionName = Annotated[Convention, Field(strict=False)]
#: One of :data:`physics.OUTPUTS`.
OutputName = Annotated[Output, Field(strict=False)]


#: An ISO 8601 / RFC 3339 UTC timestamp as the store writes it ("2026-01-31T12:00:00.000Z"); typed
#: ``format: date-time`` in the spec so generated clients parse it into a datetime.
DateTimeText = Annotated[str, Field(json_schema_extra={"format": "date-time"})]


#: The ``next_url`` field of a page of a list (``GET /v1/jobs``, ``/v1/calibrations``, ``/v1/surrogates``).
NEXT_URL: Any = Field(default=None, description=(
    "Path of the next page (same filters, page_token set); null on the last page."))


def parameter_description(spec: physics.Parameter) -> str:
    """Field description: meaning, unit in brackets and allowed range."""
    default = "" if spec.required else f" Default {spec.default!r}."
    return f"{spec.description} [{spec.unit}] Allowed: {spec.range_text()}.{default}"


def whole_number(value: Any) -> Any:
    """A JSON number without a fraction written with one (``2.0``), as the integer it is."""
    return int(value) if type(value) is float and value.is_integer() else value


#: ``int`` of a request field: a whole number written with a fraction (``2.0``) is taken, since JSON
#: Schema's ``integer`` (what the spec says) includes it; ``2.5``, strings and booleans stay refused.
WholeNumber = Annotated[int, BeforeValidator(whole_number)]


def parameter_type(spec: physics.Parameter) -> Any:
    """The annotated scalar type of one parameter, with its bounds as schema constraints.

    A whole-number parameter takes ``2.0`` (:data:`WholeNumber`), alone and as an element of a
    column (``"balls": [4.0, 6.0]``; the check adds about 3 ms to the validation of a column of
    100,000 balls, ``bench/whole_columns.py``).
    """
    if spec.kind == "bool":
        return StrictBool
    bounds: dict[str, float] = {}
    if spec.minimum is not None:
        bounds["gt" if spec.exclusive_minimum else "ge"] = spec.minimum
    if spec.maximum is not None:
        bounds["lt" if spec.exclusive_maximum else "le"] = spec.maximum
    if spec.kind == "int":
        whole_bounds = Field(**{key: int(value) for key, value in bounds.items()})
        return Annotated[int, whole_bounds, BeforeValidator(whole_number)]
    return Annotated[float, Field(allow_inf_nan=False, **bounds)]


def _refused_elements(spec: physics.Parameter) -> Callable[[np.ndarray], np.ndarray]:
    """``refused(array)``: True at each element :func:`parameter_type` may refuse (outside the parameter's
    bounds, not finite, not whole for a whole number; every element of a yes/no parameter)."""
    def refused(values: np.ndarray) -> np.ndarray:
        if spec.kind == "bool":
            return np.ones(values.shape, dtype=bool)
        with np.errstate(invalid="ignore"):
            out = ~np.isfinite(values)
            if spec.minimum is not None:
                out |= values <= spec.minimum if spec.exclusive_minimum else values < spec.minimum
            if spec.maximum is not None:
                out |= values >= spec.maximum if spec.exclusive_maximum else values > spec.maximum
            if spec.kind == "int":
                out |= values != np.round(values)
        return out
    return refused


def parameter_fields(*, columns: bool = False, optional: bool = False,
                     names: list[str] | None = None) -> dict[str, Any]:
    """``create_model`` field definitions for physics parameters.

    Parameters
    ----------
    columns : bool, default False
        Accept a scalar or a list per field (columnar batches), or a float64 array where a large body's
        list was read into one (:mod:`.number_lists`).
    optional : bool, default False
        Make every field optional with default None (e.g. the fixed values of a sweep);
        otherwise required parameters are required and the others default from the table.
    names : list of str, optional
        Only these parameters (default: all of :data:`physics.PARAMETERS`).

    Returns
    -------
    dict
        ``{name: (type, FieldInfo)}``.
    """
    fields: dict[str, Any] = {}
    for name in names or list(physics.PARAMETERS):
        spec = physics.PARAMETERS[name]
        scalar = parameter_type(spec)
        kind = (Annotated[scalar | list[scalar], WrapValidator(array_column(scalar, _refused_elements(spec)))]
                if columns else scalar)
        description = parameter_description(spec)
        if columns:
            description += " A scalar or a list; lists share one length and scalars broadcast."
        if optional:
            fields[name] = (kind | None, Field(default=None, description=description))
        elif spec.required:
            fields[name] = (kind, Field(description=description))
        else:
            fields[name] = (kind, Field(default=spec.default, description=description))
    return fields


#: Unit suffixes whose letters mean another unit once a client generator folds them to lower case
#: (``_Nm``, newton metre, would read as ``_nm``, nanometre), with the spelling that survives folding.
_FOLDING_SAFE_SUFFIXES = {"_Nm": "_newton_metre"}

#: Outputs answered under a second, folding-safe name: ``{physics name: alias}``. The answer carries
#: both with the same value; a generated client reads the alias (``pivoting_moment_newton_metre``).
FOLDING_SAFE_NAMES = {
    name: name[: -len(suffix)] + safe
    for name in physics.OUTPUTS for suffix, safe in _FOLDING_SAFE_SUFFIXES.items() if name.endswith(suffix)
}


def with_folding_safe_names(document: dict[str, Any]) -> dict[str, Any]:
    """``document`` (outputs by physics name) with the alias of :data:`FOLDING_SAFE_NAMES` beside each
    output it holds, the same value under both names; changes ``document`` in place and returns it.

    >>> with_folding_safe_names({"mu": 0.1, "pivoting_moment_Nm": 2e-9})
    {'mu': 0.1, 'pivoting_moment_Nm': 2e-09, 'pivoting_moment_newton_metre': 2e-09}
    """
    for name, alias in FOLDING_SAFE_NAMES.items():
        if name in document:
            document[alias] = document[name]
    return document


def output_fields(*, columns: bool = False, optional: bool = False) -> dict[str, Any]:
    """``create_model`` field definitions for the outputs of :data:`physics.OUTPUTS`, and the
    folding-safe aliases of :data:`FOLDING_SAFE_NAMES`.

    Parameters
    ----------
    columns : bool, default False
        Lists of numbers instead of numbers.
    optional : bool, default False
        Fields may be absent (when the client chose some outputs).
    """
    fields: dict[str, Any] = {}
    kind: Any = list[float] if columns else float
    for name, (unit, meaning) in physics.OUTPUTS.items():
        descriptions = {name: f"{meaning} [{unit}]"}
        if name in FOLDING_SAFE_NAMES:
            descriptions[FOLDING_SAFE_NAMES[name]] = (
                f"{meaning} [{unit}]; the value of {name}, under a name that keeps its unit when a "
                "client generator folds case")
        for field, description in descriptions.items():
            if optional:
                fields[field] = (kind | None, Field(default=None, description=description))
            else:
                fields[field] = (kind, Field(description=description))
    return fields


#: Bodies up to this size [bytes] are validated on the event loop; a thread hop costs more.
_INLINE_BODY_BYTES = 64 * 1024
#: Largest body a refusal parses again to name its keys as sent (a union's tag is no key; a key sent with
#: its unit, "load [mN]", is named so): a 228 MiB batch's document cost as much again as its validation,
#: beyond the bound of large requests. Larger refusals name each key as the schema read it. [bytes]
_DOCUMENT_BODY_BYTES = 16 * 2**20
#: Bodies over this size of a model with ``array_objects`` have their long lists of numbers read straight
#: into arrays (:mod:`.number_lists`): a 228 MiB batch of six columns held 1.0 GB more while validated
#: from its text, 0.1 GB so. [bytes]
LIFT_BODY_BYTES = 4 * 2**20

#: Models of request bodies that routes parse themselves (see :func:`raw_json_body`).
RAW_BODY_MODELS: dict[str, type[BaseModel]] = {}


def raw_json_body(model: type[BaseModel], examples: dict[str, Any] | None = None) -> dict[str, Any]:
    """``openapi_extra`` documenting ``model`` as the JSON body of a route that parses it itself, with its
    named ``examples`` (:func:`.examples.media_examples`).

    Large bodies (a million points) are faster to validate straight from bytes with
    ``model.model_validate_json`` in a worker thread than through FastAPI's ``json.loads`` on
    the event loop; such a route takes ``request: Request``, calls :func:`parse_json_body`, and
    passes ``openapi_extra=raw_json_body(Model)`` so the spec still shows the body.
    """
    RAW_BODY_MODELS[model.__name__] = model
    media: dict[str, Any] = {"schema": {"$ref": f"#/components/schemas/{model.__name__}"}}
    if examples:
        media["examples"] = examples
    return {"requestBody": {"required": True, "content": {"application/json": media}},
            "responses": {"415": {"description": "Unsupported Media Type"}}}


async def parse_json_body(request: Request, model: type[ModelT]) -> ModelT:
    """Validate the raw JSON body of ``request`` as ``model`` (in a worker thread when large).

    A model that names ``array_objects`` (a class attribute: top-level fields whose members take arrays,
    :func:`parameter_fields` with ``columns``) gets the long lists of numbers of a body over 4 MiB there
    as float64 arrays, never as Python floats (:mod:`.number_lists`).

    Raises
    ------
    fastapi.exceptions.RequestValidationError
        Answered as a 400 (malformed JSON) or 422 problem with JSON pointers.
    ProblemError
        415 when the body is declared as something else than JSON (a missing type is read as JSON).
    """
    headers = request.scope["headers"]
    content_type = next((value for name, value in headers if name.lower() == b"content-type"), None)
    if not is_json_media_type(content_type):
        raise not_json_problem(content_type.split(b";", 1)[0].strip().decode("latin-1"))
    body = await read_body(request)
    if len(body) > LIFT_BODY_BYTES and getattr(model, "array_objects", None):
        lifted = await run_in_threadpool(lifted_document, body, model.array_objects)
        if lifted is not None:
            del body  # the arrays and a few keys are all that is left of it
            return await run_in_threadpool(_validate_lifted, model, lifted)
    try:
        if len(body) <= _INLINE_BODY_BYTES:
            return model.model_validate_json(body)
        return await run_in_threadpool(model.model_validate_json, body)
    except ValidationError as exc:
        errors = _body_errors(exc)
    # The parsed document lets the error handler tell field names from union tags. pydantic's parser
    # reads the same documents as json.loads (NaN, big integers, the last of duplicate keys) three times
    # as fast: a 238 MiB batch refused by its schema took 16-24 s more with json.loads, holding the GIL.
    if len(body) > _DOCUMENT_BODY_BYTES:  # the refusal names keys as the schema read them (see above)
        raise RequestValidationError(errors, body=None)
    try:
        document = from_json(body)
    except ValueError as exc:
        if "recursion limit" in str(exc):  # too deep (normally refused by service.jsonguard)
            raise ProblemError(400, "The request body nests arrays or objects too deeply.",
                               title="Malformed JSON", type_=VALIDATION_TYPE) from None
        document = None
    raise RequestValidationError(errors, body=document)


def _body_errors(exc: ValidationError) -> list[dict[str, Any]]:
    """A refusal's errors located in the body. Each error's input only tells its kind (a list, a number): a
    stand-in of that kind, so that the lists a large body was read into (hundreds of MB) are freed before
    anything else is parsed."""
    return [{**error, "loc": ("body", *error["loc"]), "input": _stand_in(error.get("input"))}
            for error in exc.errors(include_url=False)]


def lifted_document(body: bytes | bytearray, array_objects: frozenset[str] = frozenset(),
                    everywhere: bool = False) -> Any | None:
    """The document of a large body with its long lists of numbers read as arrays
    (:mod:`.number_lists`: in the members of ``array_objects``, or ``everywhere``), or None (no such list,
    or anything unusual: the plain parse answers)."""
    lifted = lift_number_lists(body)
    return None if lifted is None else place_arrays(lifted, array_objects, everywhere)


def _validate_lifted(model: type[ModelT], document: Any) -> ModelT:
    """``model`` validated from a lifted document; a refusal names keys as the schema read them."""
    try:
        return model.model_validate(document)
    except ValidationError as exc:
        errors = _body_errors(exc)
    raise RequestValidationError(errors, body=None)


def _stand_in(value: Any) -> Any:
    """A value of the same JSON kind as ``value`` that holds nothing large: an empty list or object for a
    container, a string cut to 64 characters; numbers, literals and short bytes as they are."""
    if isinstance(value, list | tuple | np.ndarray):
        return []
    if isinstance(value, dict):
        return {}
    if isinstance(value, str | bytes) and len(value) > 64:
        return value[:64]
    return value


async def read_body(request: Request) -> bytes | bytearray:
    """The whole body, read as ``await request.body()`` reads it but without its async generator.

    The generator costs more than validating a single point's body, which
    :class:`service.jsonguard.JsonGuardMiddleware` has already joined into one message. A body of several
    messages grows one buffer (in place, for a large one), never joined from its pieces: joining held it
    twice over.
    """
    body: bytearray | None = None
    while True:
        message = await request.receive()
        if message["type"] != "http.request":
            raise ClientDisconnect()
        piece, more = message.get("body", b""), message.get("more_body", False)
        if body is None:
            if not more:
                return piece
            body = bytearray()
        body += piece
        if not more:
            return body


def add_raw_body_schemas(spec: dict[str, Any]) -> dict[str, Any]:
    """Add the JSON schemas of :data:`RAW_BODY_MODELS` to the components of an OpenAPI ``spec``."""
    schemas = spec.setdefault("components", {}).setdefault("schemas", {})
    for name, model in sorted(RAW_BODY_MODELS.items()):
        schema = model.model_json_schema(ref_template="#/components/schemas/{model}")
        for def_name, definition in schema.pop("$defs", {}).items():
            schemas.setdefault(def_name, definition)
        schemas[name] = schema
    return spec


# Cross-field rules in JSON Schema: what the server checks across fields, said in the spec so that
# clients and test generators (schemathesis) send what it accepts. A place is a path of keys from the
# body's root (("fixed", "balls"), ("speed_m_s",)); a null value counts as absent on the server.

def given_at(place: tuple[str, ...], value: dict[str, Any] | None = None) -> dict[str, Any]:
    """JSON Schema: a non-null value at ``place`` (of the schema ``value`` when given)."""
    *parents, name = place
    schema: dict[str, Any] = {"required": [name], "properties": {name: value or {"not": {"type": "null"}}}}
    for parent in reversed(parents):
        schema = {"required": [parent], "properties": {parent: schema}}
    return schema


def absent_at(place: tuple[str, ...]) -> dict[str, Any]:
    """JSON Schema: nothing at ``place`` (its parents may be absent too)."""
    *parents, name = place
    schema: dict[str, Any] = {"not": {"required": [name]}}
    for parent in reversed(parents):
        schema = {"properties": {parent: schema}}
    return schema


def in_one_place(*places: tuple[tuple[str, ...], dict[str, Any] | None]) -> dict[str, Any]:
    """JSON Schema: a value at exactly one of ``places`` (each ``(place, value schema or None)``)."""
    return {"anyOf": [{"allOf": [given_at(place, value), *(absent_at(other) for other, _ in places
                                                          if other != place)]}
                      for place, value in places]}


def only_with_model(field: str, prefix: str = "calibrated:") -> dict[str, Any]:
    """JSON Schema: ``field`` absent, null or empty unless ``model`` names a stored model (``prefix<id>``)."""
    return {"anyOf": [{"properties": {field: {"anyOf": [{"type": "null"}, {"maxProperties": 0}]}}},
                      {"required": ["model"], "properties": {"model": {"pattern": f"^{prefix}"}}}]}


def physics_value_schema(name: str) -> dict[str, Any]:
    """JSON Schema of a (non-null) value of the physics input ``name``, with its bounds."""
    spec = physics.PARAMETERS[name]
    schema: dict[str, Any] = {"type": {"int": "integer", "bool": "boolean"}.get(spec.kind, "number")}
    if spec.minimum is not None:
        schema["exclusiveMinimum" if spec.exclusive_minimum else "minimum"] = spec.minimum
    if spec.maximum is not None:
        schema["exclusiveMaximum" if spec.exclusive_maximum else "maximum"] = spec.maximum
    return schema


def read_value(reading: Reading, value: Any, range_object: bool = False) -> Any:
    """``value`` in the unit of the column ``reading`` reads it as: a number, a list of them, a set
    (``{"values": [...]}``) or a grid's axis (``{start, stop, num}``, its values and ends converted), or a
    range (``{low, high}`` or an object with those attributes, answered as ``[low, high]``, or with
    ``range_object`` as the JSON object it was, its ends converted: a body's field then says whether it
    takes a range); text as it is."""
    if isinstance(value, bool | str):
        return value
    if isinstance(value, int | float):
        return reading.convert(value) if reading.reading else value
    if isinstance(value, np.ndarray):  # a large body's column (.number_lists)
        return reading.convert(value) if reading.reading else value
    if isinstance(value, list | tuple):
        return [read_value(reading, v) for v in value]
    if isinstance(value, dict) and {"values", "start", "stop"} & set(value):  # a grid's axis, a set
        return {key: read_value(reading, v) if key in ("values", "start", "stop") else v
                for key, v in value.items()}
    ends = [value.get(end) if isinstance(value, dict) else getattr(value, end, None)
            for end in ("low", "high")]
    if None in ends:
        return value
    low, high = (read_value(reading, end) for end in ends)
    return {**value, "low": low, "high": high} if range_object and isinstance(value, dict) else [low, high]


def read_column_keys(columns: dict[str, Any] | None) -> dict[str, Any] | None:
    """Columns with the physics inputs by the names the calibration upload reads its header as, values
    converted to their units; conditions as sent.

    A physics input's key may be the upload's header (``speed [mm/s]`` is ``speed_m_s``, ``load [g]`` a
    slider's weight ``load_N``): :func:`physics.columns.read_name`, the reading of every door. A condition
    (``relative humidity [%]``, ``temp_F``) keeps its key and value: it is read against the columns of the
    model the request names (:func:`service.calibrations.read_conditions`), which may spell it otherwise
    (``RH``, ``temp_degC``), and a refusal names it as sent. A range ``{low, high}`` is answered as
    ``[low, high]``.

    Raises
    ------
    ValueError
        Naming the key: a unit not known or not of its quantity, or two keys read as one physics input.
    """
    if columns is None:
        return None
    read: dict[str, Any] = {}
    for key, value in columns.items():
        try:
            reading = read_name(key)
        except ColumnError as exc:
            raise ValueError(f"{key}: {exc}") from None
        if reading.name not in physics.PARAMETERS:
            reading = Reading(key, key)
        if reading.name in read:
            raise ValueError(f"{key}: another key is read as {reading.name} too; keep one")
        read[reading.name] = read_value(reading, value)
    return read


#: A mapping of columns whose keys are read as the upload reads its header (:func:`read_column_keys`).
ColumnKeys = AfterValidator(read_column_keys)


def check_column_keys(columns: dict[str, Any] | None) -> dict[str, Any] | None:
    """Columns kept as sent, keys checked as :func:`read_column_keys` reads them (a unit not known or
    not of its quantity, two keys read as one physics input): for a door that reads the keys against its
    model itself and names them as sent (UM-Bridge's ``config.fixed``)."""
    read_column_keys(columns)
    return columns


#: A mapping of columns kept as sent, its keys checked (:func:`check_column_keys`).
CheckedColumnKeys = AfterValidator(check_column_keys)
#: What a description of such a mapping says about its keys.
UNIT_KEYS = (" A key may carry its unit as the upload's header does (e.g. 'relative humidity [%]', "
             "'temperature [degF]', temp_F), converted as the upload converts it; a value in another unit "
             "of a column's quantity than the calibration data's is converted too, and one that looks like a "
             "unit slip (a humidity fraction of 50) is refused.")

#: The physics inputs without a default: every request must give them somewhere.
REQUIRED_INPUTS = [name for name, spec in physics.PARAMETERS.items() if spec.required]


def _range_spelling(value: Any, number: bool = True) -> Any:
    """A range spelled as an object, ``{"low": a, "high": b}``, read as the pair ``[a, b]``, as every route
    reads a range (an optimization's bounds and conditions, an experiment space's, a surrogate's space, a
    sweep's ranges); a set of values, and what is no range (:func:`physics.spans.no_range`; a number only
    where ``number`` is False), refused in words. Null is left to the field (an optional one's default, as a
    stored request dumps it)."""
    if value is None:
        return value
    refused = no_range(value, number)
    if refused is not None:
        raise ValueError(refused)
    if isinstance(value, dict) and "spacing" in value:  # where the whole range counts
        raise ValueError(NO_SPACING)
    if isinstance(value, dict) and "values" in value:
        raise ValueError("a set of values is no range here: a range is [low, high] or {\"low\": low, "
                         "\"high\": high}")
    if isinstance(value, dict) and set(value) == {"low", "high"}:
        return [value["low"], value["high"]]
    if isinstance(value, dict):
        raise ValueError(f"a range spelled as an object has the keys low and high, and only those; got "
                         f"{', '.join(map(str, value)) or 'none'}")
    return value


#: The pair [low, high] of a range, also spelled {low, high}, or one number.
RangeSpelling = BeforeValidator(_range_spelling)
#: The pair [low, high] of a range, also spelled {low, high}: a number refused in words.
PairSpelling = BeforeValidator(lambda value: _range_spelling(value, number=False))
