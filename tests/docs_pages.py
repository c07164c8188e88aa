"""The manual's pages (``docs/pages``) and the README as the tests read them: a page, a section, its code.

The docs' code blocks are run by the tests of what they show (tests/test_service_live.py runs the curl
blocks, tests/test_experiments.py and others the Python ones), so a page that stops matching the code fails.
"""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
#: The folder of the manual's pages (docs/mkdocs.yml's docs_dir).
PAGES = REPO / "docs" / "pages"


def page(name: str) -> str:
    """The Markdown of the page ``name`` (a path under docs/pages, e.g. ``"how-to/labs.md"``)."""
    return (PAGES / name).read_text(encoding="utf-8")


def section(text: str, heading: str) -> str:
    """The lines of ``text`` from the line ``heading`` (e.g. ``"## Errors"``) to the next heading of its level
    or above (lines inside code blocks, such as a shell's comments, are no headings)."""
    level = len(heading) - len(heading.lstrip("#"))
    lines, found, fenced = [], False, False
    for line in text.splitlines(keepends=True):
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and re.match(f"#{{1,{level}}} ", line):
            if found:
                break
            found = line.rstrip("\n") == heading
        if found:
            lines.append(line)
    assert found, f"no heading {heading!r}"
    return "".join(lines)


def code_blocks(text: str, language: str) -> list[str]:
    """The fenced code blocks of ``language`` (```bash, ```python) in ``text``, without their fences."""
    return re.findall(rf"```{language}\n(.*?)```", text, flags=re.S)
