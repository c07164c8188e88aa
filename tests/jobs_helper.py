"""Waiting for jobs in the tests: one polling loop, with a deadline and a message that says why it failed.

``wait_job`` polls ``GET /v1/jobs/{id}`` (any client with ``get(url, headers=...)``: a TestClient, an
httpx client of a live server) until the job's status is one of ``until`` (every final status by
default); ``finished_job`` insists that it succeeded, naming the job's problem when it did not;
``job_result`` fetches the result of a succeeded job. ``wait_until`` is the loop itself, for a job
read another way (a ``JobManager`` row).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

#: The statuses a job ends in.
FINISHED = ("succeeded", "failed", "cancelled")


def wait_until(read: Callable[[], dict], what: str,
               until: tuple[str, ...] | Callable[[dict], bool] = FINISHED, timeout_s: float = 120.0,
               interval_s: float = 0.05,
               on_poll: Callable[[dict], None] | None = None) -> dict:
    """Call ``read()`` until the job it returns is done; that job.

    Parameters
    ----------
    read : callable
        Returns the job as a dict with ``status``.
    what : str
        The job, for the message (its location or id).
    until : tuple of str or callable
        Statuses that end the wait, or a predicate of the job.
    timeout_s : float
        The test fails when the job is not done after this long [s], naming its last state.
    interval_s : float
        Pause between reads [s].
    on_poll : callable, optional
        Called with every job read (e.g. to record its progress).
    """
    done = until if callable(until) else (lambda job: job["status"] in until)
    deadline = time.monotonic() + timeout_s
    while True:
        job = read()
        if on_poll is not None:
            on_poll(job)
        if done(job):
            return job
        assert time.monotonic() < deadline, f"job {what} not done after {timeout_s:g} s: {job}"
        time.sleep(interval_s)


def _location(response_or_location: Any) -> str:
    if isinstance(response_or_location, str):
        return response_or_location
    response = response_or_location
    assert response.status_code == 202, response.text
    return response.headers["location"]


def wait_job(client: Any, response_or_location: Any, *, headers: dict[str, str] | None = None,
             until: tuple[str, ...] | Callable[[dict], bool] = FINISHED, timeout_s: float = 120.0,
             interval_s: float = 0.05, on_poll: Callable[[dict], None] | None = None) -> dict:
    """The job of a 202 answer (or at its ``/v1/jobs/{id}`` location) once done (see :func:`wait_until`)."""
    location = _location(response_or_location)
    return wait_until(lambda: client.get(location, headers=headers).json(), location, until, timeout_s,
                      interval_s, on_poll)


def finished_job(client: Any, response_or_location: Any, *, headers: dict[str, str] | None = None,
                 timeout_s: float = 120.0, interval_s: float = 0.05,
                 on_poll: Callable[[dict], None] | None = None) -> dict:
    """The job once it succeeded; the test fails with the job's problem when it failed or was cancelled."""
    job = wait_job(client, response_or_location, headers=headers, timeout_s=timeout_s, interval_s=interval_s,
                   on_poll=on_poll)
    assert job["status"] == "succeeded", f"job {job.get('id')} {job['status']}: {job.get('error') or job}"
    return job


def job_result(client: Any, response_or_location: Any, *, headers: dict[str, str] | None = None,
               timeout_s: float = 120.0, interval_s: float = 0.05) -> dict:
    """The result of the job once it succeeded (``GET`` its ``result_url``)."""
    job = finished_job(client, response_or_location, headers=headers, timeout_s=timeout_s,
                       interval_s=interval_s)
    return client.get(job["result_url"], headers=headers).json()
