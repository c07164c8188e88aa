"""Pages of a list, newest first: ``limit`` and ``page_token`` in, ``next_url`` out.

``GET /v1/jobs``, ``GET /v1/calibrations`` and ``GET /v1/surrogates`` page the same way. A route takes
``limit`` typed by :func:`page_limit` (at most :data:`MAX_PAGE_LIMIT`; above it is a 422 naming ``limit``) and
``page_token: PageToken``, reads ``limit + 1`` rows after :func:`page_start` in the store's order
(``created_at`` then ``id``, both descending), and answers the page :func:`page_of` cuts with its
``next_url`` (the field :data:`service.schemas.base.NEXT_URL` of its answer): the same path and
filters with the last row's token, or None on the last page.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Annotated, Any
from urllib.parse import urlencode

from fastapi import Query, Request

from ..problems import validation_problem

__all__ = ["DEFAULT_PAGE_LIMIT", "MAX_PAGE_LIMIT", "PageToken", "page_limit", "page_of", "page_start"]

#: Most rows on one page [1].
MAX_PAGE_LIMIT = 100
#: Rows on a page when ``limit`` is not given [1].
DEFAULT_PAGE_LIMIT = 20


def page_limit(what: str) -> Any:
    """The type of a list route's ``limit`` (how many ``what`` a page holds), with its bounds."""
    return Annotated[int, Query(ge=1, le=MAX_PAGE_LIMIT, description=(
        f"Most {what} on one page [1] (at most {MAX_PAGE_LIMIT}).")
    )]


#: ``page_token`` of a list route: where the page starts, as ``next_url`` of the previous page gives it.
PageToken = Annotated[str | None, Query(
    max_length=128, description="Where the page starts: from next_url of the previous page.")]

_PAGE_TOKEN = re.compile(r"^(?P<created_at>[0-9T:.+\-Z]{10,40})_(?P<id>[0-9a-f]{1,64})$")


def page_start(page_token: str | None) -> tuple[str, str] | None:
    """``(created_at, id)`` of the last row of the previous page, or None for the first page.

    Raises
    ------
    ProblemError
        422 naming ``page_token`` when it is not a token of a list.
    """
    if page_token is None:
        return None
    match = _PAGE_TOKEN.match(page_token)
    if match is None:
        raise validation_problem([{"parameter": "page_token", "detail": "is not a page token of this list; "
                                   "take next_url of the previous page as it is"}])
    return match["created_at"], match["id"]


def page_of(request: Request, rows: Sequence[dict[str, Any]], limit: int,
            filters: Sequence[tuple[str, str]] = ()) -> tuple[list[dict[str, Any]], str | None]:
    """The page in ``rows`` (read with ``limit + 1`` rows: one more tells that a next page exists)
    and the path of the next page, keeping ``filters`` (query parameters), or None on the last page."""
    page = list(rows[:limit])
    if len(rows) <= limit:
        return page, None
    last = page[-1]
    query = [*filters, ("limit", str(limit)), ("page_token", f"{last['created_at']}_{last['id']}")]
    return page, f"{request.url.path}?{urlencode(query)}"
