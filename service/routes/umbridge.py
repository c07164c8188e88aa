"""``/umbridge``: every model over the UM-Bridge protocol (see :mod:`service.umbridge`).

Not in the OpenAPI document: the protocol is specified by UM-Bridge, and its errors take the
protocol's form rather than RFC 9457 problems.
"""

from __future__ import annotations

from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

import numpy as np
from fastapi import APIRouter, Request
from fastapi.responses import Response
from fastapi.routing import APIRoute
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool

from microbearing import physics

from ..deps import SettingsDep, StoreDep
from ..models import Model, list_references
from ..problems import ProblemError
from ..schemas.base import LIFT_BODY_BYTES, lifted_document, read_body
from ..schemas.umbridge import (
    UMBridgeApplyJacobianRequest,
    UMBridgeEvaluateRequest,
    UMBridgeGradientRequest,
    UMBridgeRequest,
)
from ..security import ANONYMOUS
from ..settings import Settings
from ..store import REQUESTER, Store, json_bytes
from ..umbridge import (
    PREFIX,
    PROTOCOL_VERSION,
    SUPPORT,
    ProtocolError,
    Setup,
    apply_jacobian,
    evaluate,
    find_model,
    gradient,
    name_of,
    protocol_error,
    validation_error,
)

__all__ = ["router"]

RequestT = TypeVar("RequestT", bound=UMBridgeRequest)
#: Requests with at most this many input values are answered on the event loop; a thread hop costs more.
_INLINE_VALUES = 4096
#: Bodies up to this size [bytes] are validated on the event loop.
_INLINE_BYTES = 64 * 1024


class ProtocolRoute(APIRoute):
    """A route answering :class:`ProtocolError` and problems in the protocol's error form."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()

        async def protocol_handler(request: Request) -> Response:
            try:
                return await handler(request)
            except ProtocolError as exc:
                return exc.response()
            except ProblemError as exc:
                return protocol_error(exc.status, exc.detail).response(exc.headers)

        return protocol_handler


router = APIRouter(prefix=PREFIX, include_in_schema=False, route_class=ProtocolRoute)


def _answer(document: dict[str, Any]) -> Response:
    return Response(json_bytes(document), media_type="application/json")


async def _model(store: Store, name: str, convention: str = physics.DEFAULT_CONVENTION) -> Model:
    """:func:`find_model`, in a worker thread when it reads the store; without a key, the physics only."""
    if REQUESTER.get() is ANONYMOUS and name != "physics":
        raise ProtocolError("Unauthorized", "This model needs a key: put it in the URL as the password, "
                            "http://umbridge:<key>@host:port/umbridge.", status=401)
    if name == "physics":
        return find_model(store, name, convention)
    return await run_in_threadpool(find_model, store, name, convention)


async def _parse(request: Request, schema: type[RequestT], store: Store,
                 settings: Settings) -> tuple[RequestT, Setup]:
    """The request and its :class:`Setup`; an unknown model is named before any other invalid field."""
    raw: Any = await read_body(request)
    if len(raw) > LIFT_BODY_BYTES:
        # A long list of numbers has no place in a request (an input vector is one point's few inputs): read
        # as an array, it is refused without becoming Python floats (238 MiB of them held 2.5 GB).
        document = await run_in_threadpool(lifted_document, raw, frozenset(), True)
        if document is not None:
            raw = document
            await _refuse_long_vectors(document, store)
    try:
        if not isinstance(raw, bytes | bytearray):
            body = await run_in_threadpool(schema.model_validate, raw)
        elif len(raw) <= _INLINE_BYTES:
            body = schema.model_validate_json(raw)
        else:
            body = await run_in_threadpool(schema.model_validate_json, raw)
    except ValidationError as exc:
        error = validation_error(exc)  # raised below, once the inputs the exception holds are freed
    else:
        error = None
    if error is not None:
        small = not isinstance(raw, bytes | bytearray) or len(raw) <= _INLINE_BYTES
        await _model(store, name_of(raw) if small else await run_in_threadpool(name_of, raw))
        raise error
    convention = physics.DEFAULT_CONVENTION if body.config.convention is None else str(body.config.convention)
    model = await _model(store, body.name, convention)
    return body, Setup.of(model, body.config, settings.max_batch_points)


async def _refuse_long_vectors(document: Any, store: Store) -> None:
    """``InvalidInput`` for an input vector read as an array (a lifted long list): a vector holds one point's
    few inputs. The model is named first, as for every refusal."""
    vectors = document.get("input") if isinstance(document, dict) else None
    if not isinstance(vectors, list):
        return
    long = next((index for index, vector in enumerate(vectors) if isinstance(vector, np.ndarray)), None)
    if long is not None:
        await _model(store, name_of(document))
        raise ProtocolError("InvalidInput", f"input[{long}]: {len(vectors[long])} values; expected one per "
                                            "input of the model (config.inputs)")


@router.get("/Info")
async def info(store: StoreDep) -> Response:
    """The protocol version and every model's name."""
    if REQUESTER.get() is ANONYMOUS:  # without a key: the physics only, never a stored model
        return _answer({"protocolVersion": PROTOCOL_VERSION, "models": ["physics"]})
    models = await run_in_threadpool(list_references, store)
    return _answer({"protocolVersion": PROTOCOL_VERSION, "models": models})


@router.post("/ModelInfo")
async def model_info(request: Request, store: StoreDep, settings: SettingsDep) -> Response:
    """What the model supports."""
    await _parse(request, UMBridgeRequest, store, settings)
    return _answer({"support": SUPPORT})


@router.post("/InputSizes")
async def input_sizes(request: Request, store: StoreDep, settings: SettingsDep) -> Response:
    """Values per input vector, one entry per point of ``config.points``."""
    _, setup = await _parse(request, UMBridgeRequest, store, settings)
    return _answer({"inputSizes": setup.input_sizes})


@router.post("/OutputSizes")
async def output_sizes(request: Request, store: StoreDep, settings: SettingsDep) -> Response:
    """Values per output vector, one entry per point of ``config.points``."""
    _, setup = await _parse(request, UMBridgeRequest, store, settings)
    return _answer({"outputSizes": setup.output_sizes})


@router.post("/Evaluate")
async def evaluate_model(request: Request, store: StoreDep, settings: SettingsDep) -> Response:
    """The output vectors of the input vectors."""
    body, setup = await _parse(request, UMBridgeEvaluateRequest, store, settings)
    if setup.points * len(setup.inputs) <= _INLINE_VALUES:
        content = evaluate(setup, body.input)
    else:
        content = await run_in_threadpool(evaluate, setup, body.input)
    return Response(content, media_type="application/json")


@router.post("/Gradient")
async def gradient_of_model(request: Request, store: StoreDep, settings: SettingsDep) -> Response:
    """``sens`` times the Jacobian of output vector ``outWrt`` with respect to input vector ``inWrt``."""
    body, setup = await _parse(request, UMBridgeGradientRequest, store, settings)
    return _answer({"output": await run_in_threadpool(gradient, setup, body.input, body.outWrt, body.inWrt,
                                                      body.sens)})


@router.post("/ApplyJacobian")
async def apply_jacobian_of_model(request: Request, store: StoreDep, settings: SettingsDep) -> Response:
    """The Jacobian of output vector ``outWrt`` with respect to input vector ``inWrt``, times ``vec``."""
    body, setup = await _parse(request, UMBridgeApplyJacobianRequest, store, settings)
    return _answer({"output": await run_in_threadpool(apply_jacobian, setup, body.input, body.outWrt,
                                                      body.inWrt, body.vec)})


@router.post("/ApplyHessian")
async def apply_hessian_of_model(request: Request, store: StoreDep) -> Response:
    """Not supported (see :data:`service.umbridge.SUPPORT`): ``UnsupportedFeature`` for a known model."""
    name = name_of(await read_body(request))
    await _model(store, name)
    raise ProtocolError("UnsupportedFeature", f"ApplyHessian is not supported by {name}")
