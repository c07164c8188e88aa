"""The UM-Bridge protocol (version 1.0): every model of the service for UQ tools.

UM-Bridge clients (``umbridge.HTTPModel(url, name)`` in Python, and the C++, R, Julia and MATLAB
clients, QMCPy, PyMC and MUQ through them) call ``GET /Info``, ``POST /ModelInfo``,
``/InputSizes``, ``/OutputSizes``, ``/Evaluate``, ``/Gradient`` and ``/ApplyJacobian`` under
the URL they are given; the service answers under :data:`PREFIX`, so the URL is
``http://host:8000/umbridge``. Models are named by their reference (:func:`service.models.resolve`):
``physics``, ``calibrated:<id>``, ``surrogate:<id>``.

How a model is laid out (:class:`Setup`, from the request's ``config``): each input vector is
one point holding the varying inputs (``config.inputs``, by default the model's inputs without a
default value) in order and in their units; the other inputs take ``config.fixed`` or their
default. An input of ``config.inputs`` or ``config.fixed`` may be named with its unit as a calibration
upload's header is (``load [mN]``, ``speed_mm_s``, ``relative humidity [%]``, ``temp_F``): its values
are then in that unit, converted through the column registry (:mod:`physics.columns`), and derivatives
are taken with respect to it. Each output vector holds ``config.outputs`` (``["mu"]`` by default) for
its point.
``config.points`` (1 by default) points make one request: ``input`` then holds that many vectors.
Points are independent, so the Jacobian of output vector ``i`` with respect to input vector
``j`` is zero for ``i != j``. Derivatives are taken with respect to the continuous inputs; a count
or flag among ``config.inputs`` (``balls``, ``balls_touching``) is held, its column of the Jacobian
zero, so the physics' default inputs (balls, load, speed) differentiate without a config.

Errors are the protocol's ``{"error": {"type", "message"}}`` (:class:`ProtocolError`), the
message naming the field (``input[0][1] (load_N): ...``, ``config.fixed.balls: ...``); a problem
answered by the rest of the app on these paths (401, 413, a malformed body) is rewritten into
that form by :class:`ProtocolErrorMiddleware`.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, StrictStr, ValidationError
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from microbearing import physics
from microbearing.physics.columns import Reading, match_column, read_key, unknown_column
from microbearing.physics.slips import input_slips, read_slip, unstated_unit

from .models import InputError, Model, ModelError, jacobian, resolve
from .problems import PROBLEM_MEDIA_TYPE, ProblemError
from .schemas.umbridge import PREFIX, UMBridgeConfig
from .security import app_path
from .store import Store, json_bytes

__all__ = ["FLAG_OUTPUT", "PREFIX", "PROTOCOL_VERSION", "SUPPORT", "ProtocolError", "ProtocolErrorMiddleware",
           "Setup", "apply_jacobian", "evaluate", "find_model", "gradient", "name_of", "protocol_error",
           "validation_error"]

PROTOCOL_VERSION = 1.0
#: What every model supports (second derivatives of finite differences would not be trustworthy).
SUPPORT = {"Evaluate": True, "Gradient": True, "ApplyJacobian": True, "ApplyHessian": False}
#: The output that flags points outside a model's domain (1) or inside (0). [1]
FLAG_OUTPUT = "outside_domain"
_LISTED_ERRORS = 5


class ProtocolError(Exception):
    """An error answered in the protocol's form, ``{"error": {"type", "message"}}``.

    Parameters
    ----------
    type_ : str
        ``InvalidInput``, ``ModelNotFound``, ``UnsupportedFeature`` (the protocol's), or
        ``Unauthorized``, ``Unavailable``, ``InternalError``.
    message : str
        What is wrong, naming the field.
    status : int, default 400
        HTTP status (the protocol answers 400 to its own errors; limits keep 413, keys 401). [1]
    """

    def __init__(self, type_: str, message: str, status: int = 400):
        super().__init__(message)
        self.type = type_
        self.message = message
        self.status = status

    def response(self, headers: dict[str, str] | None = None) -> Response:
        """The error as a JSON response."""
        return Response(json_bytes({"error": {"type": self.type, "message": self.message}}),
                        status_code=self.status, media_type="application/json", headers=headers)


def protocol_error(status: int, detail: str) -> ProtocolError:
    """The protocol's form of a problem answered with ``status`` (a 404 is a model not found)."""
    if status == 404:
        return ProtocolError("ModelNotFound", detail)
    if status in (400, 415, 422):
        return ProtocolError("InvalidInput", detail)
    kind = {401: "Unauthorized", 403: "Unauthorized", 405: "UnsupportedFeature", 413: "InvalidInput",
            429: "Unavailable", 503: "Unavailable"}.get(status, "InternalError")
    return ProtocolError(kind, detail, status)


def validation_error(exc: ValidationError) -> ProtocolError:
    """An ``InvalidInput`` error naming the fields pydantic refused (``input[3][1]``, ``config.points``)."""
    items = []
    for error in exc.errors(include_url=False)[:_LISTED_ERRORS]:
        where = "".join(f"[{part}]" if isinstance(part, int) else f".{part}"
                        for part in error["loc"]).lstrip(".")
        # a validator's refusal in its own words, as /v1 says it (pydantic prefixes them "Value error, ")
        message = error["msg"]
        message = message.removeprefix("Value error, ") if error["type"] == "value_error" else message
        items.append(f"{where or 'body'}: {message}")
    more = exc.error_count() - len(items)
    return ProtocolError("InvalidInput", "; ".join(items) + (f"; and {more} more" if more > 0 else ""))


class _Named(BaseModel):
    """A request's model name alone: the rest is parsed but never made into Python objects."""

    model_config = ConfigDict(extra="ignore")
    name: StrictStr


def name_of(body: bytes | bytearray | Any) -> str:
    """The model name of a request (its raw body or, for a large one, its parsed document), read before
    the rest so that an unknown model is named first."""
    try:
        named = (_Named.model_validate_json(body) if isinstance(body, bytes | bytearray)
                 else _Named.model_validate(body))
    except ValidationError as exc:
        if any(error["type"] == "json_invalid" for error in exc.errors()):
            raise ProtocolError("InvalidInput", "the body must be a JSON object") from None
        raise ProtocolError("InvalidInput", "name: required, a model name from /Info") from None
    return named.name


def _read_fixed(model: Model, fixed: dict[str, Any]) -> tuple[dict[str, Any], dict[str, str], dict[str, str]]:
    """``config.fixed`` by the model's input names: another unit of a condition's quantity converted
    (:func:`physics.columns.match_column`), a condition that looks like a unit slip refused, each value
    checked; with the key each was sent under and, for a value converted, the key and value as typed
    (``cycles [kcycles]: -1``), for messages."""
    read, sent_as, typed_as = {}, {}, {}
    for sent, value in fixed.items():
        # the model's inputs and the other condition columns of its data (as /v1/friction takes them)
        reading = read_key(sent, model.column_checks) or Reading(sent, sent)  # none: named below
        name = reading.name
        if name in read:
            raise ProtocolError("InvalidInput", f"config.fixed.{sent}: another key is read as {name} too; "
                                                "keep one")
        # judged as sent (27 under a kelvin name is degC) and as read
        text = isinstance(value, bool | str)  # a flag, or a factor column's group label
        check = model.column_checks.get(name)
        kind = None if check is None else check.kind
        if check is not None and ((isinstance(value, str) and kind != "label")
                                  or (isinstance(value, bool) and kind not in ("bool", "label"))):
            raise ProtocolError("InvalidInput", f"config.fixed.{sent}: must be a number, not {value!r}: "
                                                f"only a factor column takes a label, a flag true or false")
        message = (None if name in physics.PARAMETERS or text
                   else unstated_unit(reading, model.headers) or read_slip(reading, value))
        converted = bool(reading.reading) and not text
        typed, value = value, reading.convert(value) if converted else value
        if message is not None:
            raise ProtocolError("InvalidInput", f"config.fixed.{sent}: {message}")
        if check is not None:
            try:
                value = check.check(value)
            except InputError as exc:  # the value as typed beside the one judged (-50 in mm/s: -0.05 m/s)
                said = f" (sent as {sent}: {typed:g})" if converted else ""
                raise ProtocolError("InvalidInput", f"config.fixed.{sent}: {exc}{said}") from None
        read[name], sent_as[name] = value, sent
        if converted:
            typed_as[name] = f"{sent}: {typed:g}"
    return read, sent_as, typed_as


def _refuse_unread(model: Model, inputs: list[str], given: dict[str, Any], sent_as: dict[str, str]) -> None:
    """A surrogate reads its dimensions only: an input that is none varied, or fixed at another value than
    the one it was trained at (its answer would be the trained value's), is refused, as its REST predict
    refuses it."""
    if model.kind != "surrogate":
        return
    trained = {name: spec.default for name, spec in model.inputs.items() if spec.default is not None}
    varied = [name for name in inputs if name in trained]
    if varied:
        raise ProtocolError("InvalidInput", f"config.inputs: {varied[0]} is not a dimension of "
                            f"{model.reference} (trained at {trained[varied[0]]!r}): it cannot vary; "
                            "leave it out")
    for name, value in given.items():
        if name in trained and not isinstance(value, str) and float(value) != float(trained[name]):
            raise ProtocolError("InvalidInput", f"config.fixed.{sent_as.get(name, name)}: {model.reference} "
                                f"{model.unread_words(name, value)}")


def _keys_of(name: str, sent_inputs: list[str], inputs: list[str], fixed_as_sent: dict[str, str]) -> str:
    """The keys an input was given under, in config.inputs and config.fixed, quoted, and what they read as."""
    keys = [sent for sent, read in zip(sent_inputs, inputs, strict=True) if read == name]
    keys += [fixed_as_sent[name]] if name in fixed_as_sent else []
    keys = list(dict.fromkeys(keys))
    return " and ".join(map(repr, keys)) + ("" if keys == [name] else f" (read as {name})")


def _read_inputs(model: Model, names: Sequence[str]) -> tuple[list[str], tuple[Reading | None, ...]]:
    """``config.inputs`` by the model's input names, with the reading of each sent in another unit (None:
    read as sent); a name no column matches is kept, for :meth:`Setup.of` to name."""
    inputs, readings = [], []
    for name in names:
        reading = None
        if name not in model.column_checks:  # an input, or a condition of the data no term reads
            try:
                reading = match_column(name, model.column_checks)
            except ValueError:
                reading = None
        refused = None if reading is None else unstated_unit(reading, model.headers)
        if refused is not None:  # read in another unit than the calibration's data gave: as every door
            raise ProtocolError("InvalidInput", f"config.inputs: {refused}")
        inputs.append(name if reading is None else reading.name)
        readings.append(reading if reading is not None and (reading.reading or reading.sent != reading.name)
                        else None)  # converted, or renamed (relative_humidity [1]): named as sent
    return inputs, tuple(readings)


def find_model(store: Store, name: str, convention: str = physics.DEFAULT_CONVENTION) -> Model:
    """The model of a protocol name (a reference), or ``ModelNotFound``."""
    try:
        return resolve(store, name, "name", convention=convention)
    except ProblemError:  # malformed (422) or unknown (404): either way no such model
        raise ProtocolError("ModelNotFound", f"there is no model {name[:200]!r}; /Info lists the "
                            "models") from None


@dataclass(frozen=True)
class Setup:
    """A model laid out by a request's ``config`` (see the module docstring).

    Attributes
    ----------
    model : Model
        The model.
    inputs : list of str
        The varying inputs, in the order of each input vector.
    fixed : dict
        Checked values of the inputs that do not vary (besides the defaults).
    outputs : list of str
        The outputs of each output vector.
    points : int
        Points per request. [1]
    readings : tuple of physics.columns.Reading or None
        Per varying input, how its values are converted from the unit it was named in (None: its own).
    fixed_as_sent : dict of str to str
        The key of ``config.fixed`` each fixed input was sent under (messages name it).
    fixed_as_typed : dict of str to str
        Of each fixed input sent in another unit, its key and value as typed (``cycles [kcycles]: -1``).
    """

    model: Model
    inputs: list[str]
    fixed: dict[str, Any]
    outputs: list[str]
    points: int
    readings: tuple[Reading | None, ...] = ()
    fixed_as_sent: dict[str, str] = field(default_factory=dict)
    fixed_as_typed: dict[str, str] = field(default_factory=dict)

    @classmethod
    def of(cls, model: Model, config: UMBridgeConfig, max_points: int) -> Setup:
        """Check ``config`` against ``model``.

        Raises
        ------
        ProtocolError
            ``InvalidInput`` naming the field of ``config``; 413 for more points than ``max_points``.
        """
        convention = config.convention
        if convention is not None and model.kind != "physics" and str(convention) != model.convention:
            raise ProtocolError("InvalidInput", f"config.convention: {model.reference} uses convention "
                                f"{model.convention!r}; omit convention")
        if config.points > max_points:
            raise ProtocolError("InvalidInput", f"config.points: {config.points} points per request; the "
                                f"limit is {max_points} (MICROBEARING_MAX_BATCH_POINTS)", status=413)
        given, fixed_as_sent, fixed_as_typed = _read_fixed(model, config.fixed)
        inputs, readings = _read_inputs(model, config.inputs or [n for n in model.default_inputs
                                                                 if n not in given])
        for part, names, known in (("config.inputs", inputs, model.column_checks),
                                   ("config.fixed", list(given), model.column_checks)):
            for name in names:
                if name not in known:
                    raise ProtocolError("InvalidInput", f"{part}: {name!r} is not an input of "
                                        f"{model.reference}: {unknown_column(name, known)}")
        repeated = sorted({n for n in inputs if inputs.count(n) > 1} | (set(inputs) & set(given)))
        if repeated:
            # each named by its keys as sent ("load [mN]" in config.inputs, load_N in config.fixed)
            said = [_keys_of(name, list(config.inputs or inputs), inputs, fixed_as_sent) for name in repeated]
            raise ProtocolError("InvalidInput", f"config.inputs: {'; '.join(said)} given twice (an input "
                                "varies, in config.inputs, or is fixed, in config.fixed)")
        missing = [n for n in model.default_inputs if n not in inputs and n not in given]
        if missing:
            raise ProtocolError("InvalidInput", f"config.fixed: {model.reference} needs "
                                f"{', '.join(missing)}: vary it in config.inputs or give it in config.fixed")
        _refuse_unread(model, inputs, given, fixed_as_sent)
        fixed = given  # checked by _read_fixed
        available = [*model.outputs, FLAG_OUTPUT]
        unknown = [n for n in config.outputs if n not in available]
        if unknown or len(set(config.outputs)) < len(config.outputs):
            raise ProtocolError("InvalidInput", f"config.outputs: each once, from {', '.join(available)}; "
                                f"got {config.outputs}")
        return cls(model, inputs, fixed, list(config.outputs), config.points, readings, fixed_as_sent,
                   fixed_as_typed)

    @property
    def input_sizes(self) -> list[int]:
        """Values per input vector, one entry per point. [1]"""
        return [len(self.inputs)] * self.points

    @property
    def output_sizes(self) -> list[int]:
        """Values per output vector, one entry per point. [1]"""
        return [len(self.outputs)] * self.points

    def columns(self, vectors: Sequence[Sequence[float]]) -> dict[str, Any]:
        """The input vectors as columns of the model's inputs, with the fixed values (the model checks)."""
        if len(vectors) != self.points:
            raise ProtocolError("InvalidInput", f"input: {len(vectors)} vectors for config.points = "
                                f"{self.points}; set config.points to the number of points")
        for index, vector in enumerate(vectors):
            if len(vector) != len(self.inputs):
                raise ProtocolError("InvalidInput", f"input[{index}]: {len(vector)} values; expected "
                                    f"{len(self.inputs)}, one per input of config.inputs "
                                    f"({', '.join(self.inputs)})")
        table = np.asarray(vectors, dtype=np.float64).reshape(self.points, len(self.inputs))
        for j, name in enumerate(self.inputs):
            # a condition's values judged for a unit slip as sent, as config.fixed and every other door
            given = self.readings[j] if j < len(self.readings) else None
            reading = given if given is not None else Reading(name, name)
            message = None if name in physics.PARAMETERS else read_slip(reading, table[:, j])
            if message is not None:
                raise ProtocolError("InvalidInput", f"{self.field(name, '*')}: {message}")
        for j, reading in enumerate(self.readings):
            if reading is not None:
                table[:, j] = reading.convert(table[:, j])
        return {**self.fixed, **{name: self.model.column_checks[name].coerce(table[:, j])
                                 for j, name in enumerate(self.inputs)}}

    @contextmanager
    def pointing(self) -> Iterator[None]:
        """A context turning :class:`InputError` and problems into ``InvalidInput`` naming the field."""
        try:
            yield
        except InputError as exc:
            raise ProtocolError("InvalidInput", f"{self.where(exc)}: {exc}{self.as_sent(exc.name)}") from None
        except ProblemError as exc:
            raise protocol_error(exc.status, exc.detail) from None
        except ModelError as exc:  # a law's domain: named by the input or fixed key as sent
            raise ProtocolError("InvalidInput", "; ".join(self.field_error(e) for e in exc.errors)) from None

    def field_error(self, error: dict[str, str]) -> str:
        """A model's refusal of a column (``{"pointer": "/conditions/RH", "detail": ...}``) as this request's
        field: ``input[*][j] (key as sent)`` or ``config.fixed.<key as sent>``; other pointers as they are."""
        pointer, detail = str(error.get("pointer", "")), str(error.get("detail", ""))
        name = pointer.rsplit("/", 1)[-1]
        if name not in self.inputs and name not in self.fixed:
            return f"{pointer}: {detail}"
        return f"{self.field(name, '*')}: {detail}{self.as_sent(name)}"

    def as_sent(self, name: str) -> str:
        """`` (sent as <key>[: <value as typed>], read as <name>)`` for another key, or ""."""
        sent = self.fixed_as_typed.get(name) or self.sent_key(name)
        return "" if sent == name else f" (sent as {sent}, read as {name})"

    def sent_key(self, name: str) -> str:
        """The key an input of the model was sent under: in ``config.inputs`` or ``config.fixed``."""
        if name in self.inputs:
            j = self.inputs.index(name)
            reading = self.readings[j] if j < len(self.readings) else None
            return name if reading is None else reading.sent
        return self.fixed_as_sent.get(name, name)

    def field(self, name: str, point: int | str = 0) -> str:
        """The request field of an input: ``input[point][position] (key as sent)`` or
        ``config.fixed.<key as sent>``; ``config`` for another name."""
        if name in self.inputs:
            return f"input[{point}][{self.inputs.index(name)}] ({self.sent_key(name)})"
        if name in self.fixed:
            return f"config.fixed.{self.sent_key(name)}"
        return "config"

    def where(self, error: InputError) -> str:
        """The request field of an input error (:meth:`field`, at the point it names)."""
        return self.field(error.name, 0 if error.index is None else error.index)

    def real_outputs(self) -> list[str]:
        """:attr:`outputs` without the domain flag (what the model computes); mu when only the flag."""
        return [n for n in self.outputs if n != FLAG_OUTPUT] or ["mu"]


def evaluate(setup: Setup, vectors: Sequence[Sequence[float]]) -> bytes:
    """The JSON answer of Evaluate: ``{"output": [...]}``, one vector of ``config.outputs`` per point, and
    ``"warnings"`` when physics inputs look like a unit slip (:func:`physics.slips.input_slips`, the words
    of ``/v1/friction``'s ``input_warnings``; the model answers as asked). The protocol's clients read
    ``output`` and pass over the rest."""
    columns = setup.columns(vectors)
    warnings = input_slips(columns)
    with setup.pointing():
        result = setup.model.evaluate(columns, setup.real_outputs())
    values = {**result.values, FLAG_OUTPUT: result.outside_domain.astype(float)}
    table = np.column_stack([np.broadcast_to(values[name], (setup.points,)) for name in setup.outputs])
    # Written from one flat list: a Python list per point would cost ten times the model.
    numbers = json_bytes(table.ravel().tolist())[1:-1].split(b",")
    width = table.shape[1]
    rows = numbers if width == 1 else [b",".join(numbers[i:i + width]) for i in range(0, len(numbers), width)]
    tail = b',"warnings":' + json_bytes(warnings) + b"}" if warnings else b"}"
    return b'{"output":[[' + b"],[".join(rows) + b"]]" + tail


def _jacobian_at(setup: Setup, vectors: Sequence[Sequence[float]], out_wrt: int, in_wrt: int) -> np.ndarray:
    """d output vector ``out_wrt`` / d input vector ``in_wrt``, shape (outputs, inputs)."""
    for part, index in (("outWrt", out_wrt), ("inWrt", in_wrt)):
        if index >= setup.points:
            raise ProtocolError("InvalidInput", f"{part}: {index} is not the index of a vector; there are "
                                f"{setup.points} (config.points)")
    if FLAG_OUTPUT in setup.outputs:
        raise ProtocolError("InvalidInput", f"config.outputs: {FLAG_OUTPUT} is a flag without a derivative; "
                            "leave it out of Gradient and ApplyJacobian")
    columns = setup.columns(vectors)
    if out_wrt != in_wrt:  # points are independent
        return np.zeros((len(setup.outputs), len(setup.inputs)))
    # the data's conditions no term reads enter the domain check only: no derivative depends on them
    point = {name: value[in_wrt] if np.ndim(value) else value for name, value in columns.items()
             if name in setup.model.inputs}
    # Counts and flags are held: their columns stay zero.
    continuous = [j for j, name in enumerate(setup.inputs)
                  if name in setup.model.inputs and setup.model.inputs[name].continuous]
    matrix = np.zeros((len(setup.outputs), len(setup.inputs)))
    with setup.pointing():
        if not continuous:
            setup.model.check(point)  # the point is still checked
            return matrix
        try:
            matrix[:, continuous] = jacobian(setup.model, point, [setup.inputs[j] for j in continuous],
                                             setup.outputs)[0]
        except InputError as exc:  # the derivative at this point: name the vector asked for
            raise InputError(exc.name, in_wrt, str(exc)) from None
    for j, reading in enumerate(setup.readings):  # with respect to the input in the unit it was named in
        if reading is not None:
            matrix[:, j] *= reading.scale
    return matrix


def _checked_length(field: str, values: Sequence[float], length: int, what: str) -> np.ndarray:
    if len(values) != length:
        raise ProtocolError("InvalidInput", f"{field}: {len(values)} values; expected {length}, "
                            f"one per {what}")
    return np.asarray(values, dtype=np.float64)


def gradient(setup: Setup, vectors: Sequence[Sequence[float]], out_wrt: int, in_wrt: int,
             sens: Sequence[float]) -> list[float]:
    """``sens`` times the Jacobian of output vector ``out_wrt`` with respect to input vector ``in_wrt``."""
    weights = _checked_length("sens", sens, len(setup.outputs), "output of config.outputs")
    return (weights @ _jacobian_at(setup, vectors, out_wrt, in_wrt)).tolist()


def apply_jacobian(setup: Setup, vectors: Sequence[Sequence[float]], out_wrt: int, in_wrt: int,
                   vec: Sequence[float]) -> list[float]:
    """The Jacobian of output vector ``out_wrt`` with respect to input vector ``in_wrt``, times ``vec``."""
    direction = _checked_length("vec", vec, len(setup.inputs), "input of config.inputs")
    return (_jacobian_at(setup, vectors, out_wrt, in_wrt) @ direction).tolist()


class ProtocolErrorMiddleware:
    """Rewrite problems answered on the protocol's paths (401, 413, a malformed body) into its error form.

    The rest of the app answers such requests before they reach a protocol route, as RFC 9457
    problems; a UM-Bridge client reads ``{"error": {"type", "message"}}``. The status and the other
    headers (``WWW-Authenticate``, ``X-Request-ID``) are kept.

    Parameters
    ----------
    app : ASGI app
        The wrapped application.
    """

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or not app_path(scope).startswith(PREFIX + "/"):
            await self.app(scope, receive, send)
            return
        start: Message | None = None
        chunks: list[bytes] = []

        async def rewrite(message: Message) -> None:
            nonlocal start
            if message["type"] == "http.response.start":
                headers = dict(message.get("headers", []))
                if headers.get(b"content-type", b"").split(b";")[0] == PROBLEM_MEDIA_TYPE.encode():
                    start = message
                    return
            elif start is not None and message["type"] == "http.response.body":
                chunks.append(message.get("body", b""))
                if message.get("more_body", False):
                    return
                status = start["status"]
                detail = str(json.loads(b"".join(chunks)).get("detail", ""))
                # Here a 404 or 405 is a path or method the protocol does not have, not a model.
                kind = "UnsupportedFeature" if status in (404, 405) else protocol_error(status, detail).type
                body = json_bytes({"error": {"type": kind, "message": detail}})
                headers = [(k, v) for k, v in start.get("headers", [])
                           if k.lower() not in (b"content-type", b"content-length")]
                headers += [(b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode())]
                await send({**start, "headers": headers})
                await send({"type": "http.response.body", "body": body})
                return
            await send(message)

        await self.app(scope, receive, rewrite)
