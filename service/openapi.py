"""Write the OpenAPI spec of the service to ``openapi/openapi.json``.

Run ``python -m microbearing.service.openapi``.

The file is committed; generated clients and the tests use it, and a test fails when it
differs from what the code produces (run this command after changing a route or a schema).
``--check`` exits with status 1 instead of writing when the file is stale.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

__all__ = ["SPEC_PATH", "main", "spec_text"]

#: Where the committed spec lives, relative to the repository root.
SPEC_PATH = Path(__file__).resolve().parent.parent / "openapi" / "openapi.json"


def spec_text() -> str:
    """The OpenAPI document of the service as stable JSON text (sorted keys, 2-space indent)."""
    from .app import create_app

    return json.dumps(create_app().openapi(), indent=2, sort_keys=True, ensure_ascii=False) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write (or with ``--check`` verify) the spec file; returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m microbearing.service.openapi", description=__doc__)
    parser.add_argument("--output", type=Path, default=SPEC_PATH, help="file to write (default: %(default)s)")
    parser.add_argument("--check", action="store_true", help="exit 1 if the file is stale instead of writing")
    args = parser.parse_args(argv)
    text = spec_text()
    if args.check:
        current = args.output.read_text(encoding="utf-8") if args.output.exists() else ""
        if current != text:
            print(f"{args.output} is stale; run: python -m microbearing.service.openapi", file=sys.stderr)
            return 1
        return 0
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text(text, encoding="utf-8")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
