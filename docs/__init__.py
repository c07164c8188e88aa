"""The manual's sources, package data without code: ``mkdocs.yml``, the pages (``pages/``) and the theme's
override (``theme/``). :mod:`microbearing.service.routes.manual` builds them with mkdocs and serves the site
at ``/manual/``; ``mkdocs build --strict`` from the repository's root builds the same site.
"""
