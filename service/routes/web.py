"""``/ui/``: the lab's web page, a thin client of this REST API served from the package.

The page (``service/web/``: one HTML file, one script, one style sheet, an icon; no build step, nothing loaded
from elsewhere) walks the loop an experimentalist closes: upload a spreadsheet, read the calibration
report, ask friction at points, plan the next runs, design over an operating envelope, and list or
delete the stored models. Every call it makes is an ordinary API call with the key the user pastes
(``Authorization: Bearer <key>``, kept in the browser's sessionStorage).

The page's own files hold no data and are open without a key (:data:`PAGE_PATHS`, listed in
:data:`service.security.OPEN_PATHS`); the API calls they make need the key as any client's do. The
files are answered with a Content-Security-Policy that admits scripts, styles and connections to
this origin only (images also as ``blob:``, the plots fetched with the key), so the page cannot load
or send anything elsewhere. The routes are not in the OpenAPI spec: they are not part of the API.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter
from fastapi.responses import RedirectResponse, Response

from ..problems import ProblemError

__all__ = ["CONTENT_SECURITY_POLICY", "PAGE_FILES", "PAGE_PATH", "PAGE_PATHS", "router"]

#: Where the page is served.
PAGE_PATH = "/ui"
#: The folder of the page's files in the package (``microbearing/service/web``).
_FOLDER = Path(__file__).resolve().parent.parent / "web"
#: Each file of the page and its media type; ``index.html`` is also the folder's address ``/ui/``.
PAGE_FILES = {"index.html": "text/html; charset=utf-8", "app.js": "text/javascript; charset=utf-8",
              "app.css": "text/css; charset=utf-8", "icon.svg": "image/svg+xml"}
#: Paths of the page (relative to the ASGI root path; ``/`` redirects to it), readable without an API key.
PAGE_PATHS = frozenset({"/", PAGE_PATH, f"{PAGE_PATH}/", *(f"{PAGE_PATH}/{name}" for name in PAGE_FILES)})

#: Scripts, styles and connections from this origin only; plots are shown from blob: URLs (fetched
#: with the key); no frames, no plugins, no forms posted anywhere.
CONTENT_SECURITY_POLICY = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' blob:; "
                           "connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
_HEADERS = {"Content-Security-Policy": CONTENT_SECURITY_POLICY, "X-Content-Type-Options": "nosniff",
            "Referrer-Policy": "no-referrer", "Cache-Control": "no-cache"}

router = APIRouter(include_in_schema=False)


@router.get("/")
def root() -> RedirectResponse:
    """The bare address -> the page (a lab opening the server in a browser finds it)."""
    return RedirectResponse(f"{PAGE_PATH}/", status_code=307)


@router.get(PAGE_PATH)
def page_folder() -> RedirectResponse:
    """``/ui`` -> ``/ui/`` (relative links of the page resolve under the folder)."""
    return RedirectResponse(f"{PAGE_PATH}/", status_code=308)


@router.get(f"{PAGE_PATH}/")
def page() -> Response:
    """The page."""
    return page_file("index.html")


@router.get(PAGE_PATH + "/{name}")
def page_file(name: str) -> Response:
    """A file of the page (only those of :data:`PAGE_FILES`: no path from the request reaches the disk)."""
    media_type = PAGE_FILES.get(name)
    if media_type is None:
        raise ProblemError(404, f"The page has no file {name[:100]!r}; it has {', '.join(PAGE_FILES)}.")
    return Response((_FOLDER / name).read_bytes(), media_type=media_type, headers=_HEADERS)
