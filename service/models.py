"""Model references resolved to models: the service's only part in what a model is.

A model reference is ``"physics"``, ``"calibrated:<id>"`` (a stored calibration,
:mod:`service.calibrations`) or ``"surrogate:<id>"`` (a stored surrogate,
:mod:`service.surrogates`). :func:`resolve` turns a reference into a :class:`Model`,
and it is the only place that does: /v1/friction and /v1/friction/batch with a calibrated model,
/v1/optimizations, surrogate training on a calibrated model and the UM-Bridge protocol
(:mod:`service.umbridge`) all get their model here; a physics batch and sweeps, which evaluate
the physics only, take its model from :func:`physics_in`. Batches and sweeps evaluate their model
chunk by chunk (:func:`service.executor.evaluate_in_chunks`). A single physics point of
/v1/friction calls :func:`service.evaluation.evaluate_point` directly: it is dominated by
per-request overhead.

What a model is (:class:`Model`, :class:`ModelInput`, :func:`jacobian`, ...) lives under the library,
in :mod:`physics.model`, :mod:`calibrate.model_view` and :mod:`surrogate.model_view`; it is re-exported
here. A model raises :class:`ModelError` for inputs that leave no finite answer; :func:`problems`
turns it into the 422 problem the API answers.
"""

from __future__ import annotations

import dataclasses
import os
import re
import threading
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import Executor, Future, ThreadPoolExecutor
from contextlib import contextmanager
from typing import Any

from microbearing import physics, surrogate
from microbearing.calibrate import CalibratedModel
from microbearing.calibrate.model_view import CalibratedPhysicsModel
from microbearing.physics.model import (
    Evaluation,
    InputError,
    Model,
    ModelError,
    ModelInput,
    PhysicsModel,
    jacobian,
)
from microbearing.physics.model import physics_in as physics_with_execution
from microbearing.surrogate.model_view import SurrogateModel

from .problems import ProblemError, validation_problem
from .store import Store

__all__ = ["KINDS", "CalibratedPhysicsModel", "Evaluation", "InputError", "Model", "ModelError",
           "ModelInput", "PhysicsModel", "SurrogateModel", "jacobian", "list_references", "physics_in",
           "configure_physics", "problems", "resolve"]

#: Kinds of model, as the references name them: ``physics``, ``calibrated:<id>``, ``surrogate:<id>``.
KINDS = ("physics", "calibrated", "surrogate")
#: Store kind of each stored model kind (what :meth:`Store.save_model` was given).
_STORE_KINDS = {"calibrated": "calibration", "surrogate": "surrogate"}
_REFERENCE = re.compile(r"^(calibrated|surrogate):([0-9a-f]{32})$")


class _PhysicsThreads(Executor):
    """The server's threads for large physics calls: a pool made on first use in each process.

    Made lazily so that a forked child (which has none of its parent's threads) makes its own.
    """

    def __init__(self, threads: int):
        self.threads = threads
        self._lock = threading.Lock()
        self._pool: ThreadPoolExecutor | None = None
        self._pid = 0

    def submit(self, fn: Callable, /, *args, **kwargs) -> Future:
        with self._lock:
            if self._pid != os.getpid():
                self._pool = ThreadPoolExecutor(self.threads, thread_name_prefix="physics")
                self._pid = os.getpid()
        return self._pool.submit(fn, *args, **kwargs)


#: The kernel and threads of this process's physics evaluations (batches and sweeps):
#: :func:`configure_physics` sets them from the server's settings.
_physics_execution = physics.ExecutionOptions()


def configure_physics(kernel: str, threads: int) -> None:
    """Evaluate the physics of batches and sweeps with ``kernel``, large calls on ``threads`` threads.

    Parameters
    ----------
    kernel : {"numpy", "numba"}
        ``MICROBEARING_PHYSICS_KERNEL``.
    threads : int
        ``MICROBEARING_PHYSICS_THREADS``: threads sharing one large call; 0: one per usable CPU. [1]
    """
    global _physics_execution
    if not threads:
        threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    executor = _PhysicsThreads(threads) if threads > 1 else None
    _physics_execution = physics.ExecutionOptions(kernel, threads, executor)


def physics_in(convention: str = physics.DEFAULT_CONVENTION) -> PhysicsModel:
    """The physics in one convention, evaluated as :func:`configure_physics` set (the server's settings)."""
    return physics_with_execution(convention, _physics_execution)


def stored_calibrated(metadata: Mapping[str, Any]) -> CalibratedModel:
    """The calibrated model of a stored calibration's metadata. One stored before the upload's headers were
    kept with the model (:attr:`calibrate.CalibratedModel.headers` empty) has them back from its report's
    intake (each column's header as sent -> the column it was read as), so that a key at prediction that
    states no unit is judged against the upload's unit, not the column's own."""
    model = CalibratedModel.from_json(metadata["model"])
    if model.headers:
        return model
    headers = _intake_headers(metadata)
    return dataclasses.replace(model, headers=headers) if headers else model


def _intake_headers(metadata: Mapping[str, Any]) -> dict[str, str]:
    """Each column sent under another name, by its report's intake: column -> its header as sent.

    >>> _intake_headers({"report": {"intake": {"columns": {"temp_F": "temp_K", "balls": "balls"}}}})
    {'temp_K': 'temp_F'}
    """
    intake = (metadata.get("report") or {}).get("intake") or {}
    columns = intake.get("columns") or {}
    return {str(name): str(sent) for sent, name in columns.items() if str(sent) != str(name)}


@contextmanager
def problems() -> Iterator[None]:
    """A context turning a model's :class:`ModelError` into the 422 problem naming its fields."""
    try:
        yield
    except ModelError as exc:
        raise validation_problem(exc.errors) from None


def resolve(store: Store, reference: str, pointer: str = "/model", *, kinds: Sequence[str] = KINDS,
            convention: str = physics.DEFAULT_CONVENTION) -> Model:
    """The :class:`Model` of a reference.

    Parameters
    ----------
    store : Store
        Where calibrations and surrogates are kept.
    reference : str
        ``"physics"``, ``"calibrated:<id>"`` or ``"surrogate:<id>"``.
    pointer : str
        JSON pointer of the reference in the request, for errors.
    kinds : sequence of str
        The kinds of :data:`KINDS` the caller accepts.
    convention : str
        Convention of the physics (a stored model has its own).

    Returns
    -------
    Model

    Raises
    ------
    ProblemError
        422 for a malformed reference or a kind not in ``kinds``, 404 for an unknown stored model.
    """
    reference = str(reference)
    match = _REFERENCE.match(reference)
    kind = "physics" if reference == "physics" else match.group(1) if match else None
    if kind not in kinds:
        shapes = " or ".join("'physics'" if k == "physics" else f"'{k}:<id>'" for k in kinds)
        raise validation_problem([{"pointer": pointer, "detail": f"must be {shapes}; got {reference!r}"}])
    if kind == "physics":
        return physics_in(str(convention))
    model_id = match.group(2)
    if kind == "surrogate":
        # The store rebuilds an estimator once (a refit) and keeps it, after checking that the
        # requesting key may see it; service.surrogates reads the same cache.
        estimator = store.rebuilt(model_id, _STORE_KINDS[kind],
                                  lambda stored: surrogate.from_dict(stored.metadata["model"]))
        if estimator is None:
            raise ProblemError(404, f"There is no surrogate {model_id!r}.")
        return SurrogateModel(reference, estimator)
    model = store.rebuilt(model_id, _STORE_KINDS[kind], lambda stored: CalibratedPhysicsModel(
        reference, stored_calibrated(stored.metadata)))
    if model is None:
        raise ProblemError(404, f"There is no calibrated model {reference!r}.")
    return model


def list_references(store: Store) -> list[str]:
    """Every model reference the caller may use: ``physics``, then stored models, newest first.

    The store answers only the rows the requesting API key may see (:data:`service.store.REQUESTER`).
    """
    references = ["physics"]
    for kind, store_kind in _STORE_KINDS.items():
        references += [f"{kind}:{row['id']}" for row in store.list_models(store_kind)]
    return references
