"""One router per REST resource, and the pattern to add one.

Adding a resource
-----------------
1. Models: request bodies derive from :class:`service.schemas.base.StrictModel`
   (``extra="forbid"``, strict types, finite numbers only); responses from
   :class:`~service.schemas.base.ResponseModel`. Put them in ``service/schemas/<resource>.py``.
   Physics inputs come from :func:`~service.schemas.base.parameter_fields` (names, units,
   bounds and defaults from :data:`physics.PARAMETERS`; never list them by hand). Every field
   has a description ending with its unit in brackets. Unions carry a required tag
   (``Field(discriminator="kind")``).
2. Router: ``service/routes/<resource>.py`` defines ``router = APIRouter(prefix="/v1/<resource>",
   tags=["<resource>"])``. Give every route an ``operation_id`` that reads well in a generated
   client (``create_surrogate``, ``get_surrogate``) and
   ``responses=problem_responses(<extra codes>)`` so its errors are documented as
   ``application/problem+json``. Register it by adding ``<resource>.router`` to
   :data:`service.app.ROUTERS`, then run ``python -m microbearing.service.openapi`` and commit
   ``openapi/openapi.json`` (a test fails while the spec is stale).
3. Errors: raise :class:`service.problems.ProblemError` (``ProblemError(404, "There is no
   surrogate 'x'.")``) or :func:`service.problems.validation_problem` (``[{"pointer": "/fixed/load_N",
   "detail": "..."}]``) for 422. Domain code raises ``ValueError``; catch it in the route and
   turn it into a 422 problem naming the field. Never let a client's input cause a 500.
4. CPU-heavy work in a route: a plain ``def`` route, or ``await run_in_threadpool(fn, ...)``
   in an ``async def`` one, so the event loop keeps serving. Dependencies are annotated
   aliases from :mod:`service.deps`: ``settings: SettingsDep``, ``store: StoreDep``,
   ``jobs: JobsDep``.
5. Large JSON bodies (columns of a million numbers): take ``request: Request``, validate with
   ``await parse_json_body(request, Model)`` and pass ``openapi_extra=raw_json_body(Model)``
   (:mod:`service.schemas.base`); answer large results with
   ``Response(service.store.json_bytes(doc), media_type="application/json")``.
   A route that takes nothing but ``request: Request`` and returns a ``Response`` is served
   through Starlette's plain route (:class:`service.app.PlainRoute`), which skips FastAPI's
   per-request handling (about 110 us); it stays in the OpenAPI spec as declared.

Running work as a job
---------------------
::

    from ..deps import JobsDep
    from ..jobs import JobContext
    from .jobs import ACCEPTED_RESPONSE, accepted

    @router.post("", operation_id="create_optimization", status_code=202,
                 responses={**ACCEPTED_RESPONSE, **problem_responses()})
    def create_optimization(body: OptimizationRequest, jobs: JobsDep):
        def work(ctx: JobContext) -> dict:
            result = optimize.run(..., progress=ctx.progress)   # ctx.progress also checks cancel
            return {"design": ..., "mu": ...}                  # JSON-ready; arrays allowed
        return accepted(jobs.submit("optimization", body.model_dump(mode="json"), work))

Pass the job's inputs, and declare how any process rebuilds its work from them as one entry of
:data:`service.job_kinds.JOB_KIND_TABLE` (the app registers that table at start; a route registers
nothing), so that the job survives restarts and can run in any server process sharing the data folder
(see :mod:`service.jobs`; work submitted without ``inputs`` is failed by a restart). The route builds
its work with the same function the table's entry uses::

    # service/job_kinds.py
    def optimization_work(plan, executor) -> Work:
        return lambda ctx: run(plan, progress=ctx.progress, executor=executor)

    def _optimization(inputs: dict, runtime) -> Work:
        body = OptimizationRequest.model_validate_json(json.dumps(inputs))
        return optimization_work(prepare(runtime.store, body), runtime.executor)

    JOB_KIND_TABLE = (..., JobKind("optimization", _optimization, rule="..."), ...)

    # the route
    request = body.model_dump(mode="json")
    return accepted(jobs.submit("optimization", request, optimization_work(plan, executor), inputs=request))

The client polls ``GET /v1/jobs/{id}`` (status, progress, ``result_url`` or ``error``) and
fetches ``GET /v1/jobs/{id}/result``; ``DELETE /v1/jobs/{id}`` cancels. A result holding a table
under ``"columns"`` (name -> list) is also served as CSV (``Accept: text/csv``). Raising
``ValueError`` in ``work`` fails the job with a 422 problem; ``ProblemError`` with its own.

Storing a model
---------------
::

    from ..deps import StoreDep

    def create_surrogate(body: ..., store: StoreDep):
        model_id = store.save_model("surrogate", {"inputs": [...], "r2": 0.998}, {"coef": coef})
        ...
    stored = store.load_model(model_id)        # None when unknown -> ProblemError(404, ...)
    stored.metadata, stored.arrays["coef"]

Metadata is JSON text, arrays are ``.npz`` bytes loaded without pickle. Inside a job, use the
``store`` captured from the route's dependency.
"""
