"""``/manual/``: the docs site, built from the Markdown shipped in the package and served by the service.

A lab on a network without internet access reads the manual where it runs the service. The pages
(``docs/``, installed as ``microbearing.docs``) are built with mkdocs on the first request, into the data
folder (``<data dir>/manual/<digest>``, the digest of the sources and of mkdocs' version, so a new version
of the package builds its own site and never serves an old one), then served from there. Several
processes on one folder each build into a folder of their own and keep the first one renamed into place.

The pages hold no data and are open without a key (:data:`PREFIX` in
:data:`service.security.OPEN_PATH_PREFIXES`). They are answered with a Content-Security-Policy that
admits this origin only (the theme's inline script is replaced by a file, and highlight.js from a CDN is
off: ``docs/mkdocs.yml``), so the manual loads nothing from elsewhere. Only files of the built site are
served: a path is resolved inside the site's folder, or answered 404. The routes are not in the OpenAPI
spec: they are not part of the API.
"""

from __future__ import annotations

import hashlib
import logging
import mimetypes
import os
import shutil
import tempfile
import threading
from pathlib import Path

from fastapi import APIRouter, Request
from fastapi.responses import RedirectResponse, Response

from ..problems import ProblemError

__all__ = ["CONTENT_SECURITY_POLICY", "PREFIX", "build_site", "router", "source_digest", "sources"]

#: Where the manual is served.
PREFIX = "/manual"
#: Scripts (the theme's and the search's worker), styles, fonts and images from this origin only; the
#: theme's style sheets use data: images; a few of its elements carry style attributes.
CONTENT_SECURITY_POLICY = ("default-src 'none'; script-src 'self'; worker-src 'self'; connect-src 'self'; "
                           "style-src 'self' 'unsafe-inline'; font-src 'self'; img-src 'self' data:; "
                           "base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
_HEADERS = {"Content-Security-Policy": CONTENT_SECURITY_POLICY, "X-Content-Type-Options": "nosniff",
            "Referrer-Policy": "no-referrer", "Cache-Control": "no-cache"}

logger = logging.getLogger("microbearing.service.manual")
_LOCK = threading.Lock()
#: The built site of each data folder in this process.
_SITES: dict[Path, Path] = {}

router = APIRouter(include_in_schema=False)


def sources() -> Path:
    """The folder of the manual's sources: ``mkdocs.yml``, ``pages/`` and ``theme/``."""
    from microbearing import docs

    return Path(docs.__file__).resolve().parent


def source_digest(folder: Path, mkdocs_version: str) -> str:
    """A digest of every source file (its path and bytes) and of mkdocs' version [hex, 16 digits]."""
    digest = hashlib.sha256(mkdocs_version.encode())
    for path in sorted(p for p in folder.rglob("*") if p.is_file() and "__pycache__" not in p.parts):
        digest.update(path.relative_to(folder).as_posix().encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:16]


def build_site(source: Path, site: Path, strict: bool = False) -> None:
    """Build the manual of ``source`` (its ``mkdocs.yml``) into the folder ``site`` with mkdocs.

    Parameters
    ----------
    source : pathlib.Path
        The folder of the sources (:func:`sources`).
    site : pathlib.Path
        The folder to write the site into (created).
    strict : bool
        Whether a warning (a broken link, a page left out of the navigation) fails the build.
    """
    from mkdocs.commands.build import build
    from mkdocs.config import load_config

    mkdocs_logger = logging.getLogger("mkdocs")
    level = mkdocs_logger.level
    mkdocs_logger.setLevel(logging.WARNING)  # its progress lines are not the service's to log
    try:
        config = load_config(config_file=str(source / "mkdocs.yml"), site_dir=str(site), strict=strict)
        build(config)
    finally:
        mkdocs_logger.setLevel(level)


def _site(data_dir: Path) -> Path:
    """The built site of this data folder, built on first use."""
    with _LOCK:
        site = _SITES.get(data_dir)
        if site is not None and site.is_dir():
            return site
        try:
            import mkdocs
        except ImportError:
            raise ProblemError(503, "The manual is built with mkdocs, which is not installed here: "
                                    "pip install mkdocs (or reinstall microbearing with its dependencies)."
                               ) from None
        source = sources()
        site = data_dir / "manual" / source_digest(source, mkdocs.__version__)
        if not site.is_dir():
            try:
                _build_into(source, site)
            except OSError as exc:
                raise ProblemError(503, f"The manual cannot be built into {site.parent}: "
                                        f"{exc.strerror or exc}.") from exc
        _SITES[data_dir] = site
        return site


def _build_into(source: Path, site: Path) -> None:
    """Build in a folder of this process's own, then rename it to ``site`` (unless another process did)."""
    site.parent.mkdir(parents=True, exist_ok=True)
    building = Path(tempfile.mkdtemp(prefix=".build-", dir=site.parent))
    try:
        build_site(source, building / "site")
        try:
            os.rename(building / "site", site)
        except OSError:
            if not site.is_dir():
                raise
        else:
            logger.info("built the manual into %s", site)
    finally:
        shutil.rmtree(building, ignore_errors=True)


@router.get(PREFIX)
def manual_folder() -> RedirectResponse:
    """``/manual`` -> ``/manual/`` (the pages' relative links resolve under the folder)."""
    return RedirectResponse(f"{PREFIX}/", status_code=308)


@router.get(PREFIX + "/{path:path}")
def manual_file(path: str, request: Request) -> Response:
    """A file of the built site; a folder's address answers its ``index.html``."""
    site = _site(Path(request.app.state.settings.data_dir)).resolve()
    target = (site / path).resolve()
    if target.is_dir():
        if path and not path.endswith("/"):
            return RedirectResponse(f"{PREFIX}/{path}/", status_code=308)
        target = target / "index.html"
    if not target.is_relative_to(site) or not target.is_file():
        raise ProblemError(404, f"The manual has no page {path[:200]!r}; its contents are at {PREFIX}/.")
    media_type = mimetypes.guess_type(target.name)[0] or "application/octet-stream"
    if media_type.startswith("text/") or media_type in ("application/javascript", "application/json"):
        media_type += "; charset=utf-8"
    return Response(target.read_bytes(), media_type=media_type, headers=_HEADERS)
