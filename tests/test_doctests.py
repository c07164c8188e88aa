"""The examples in the docstrings of every module, run through the installed names (microbearing.physics...).

pytest's own doctest collection would import the source folders as top-level packages (``physics``),
a second copy of every module beside ``microbearing.physics``; so the folders are not collected and
their examples run here, on the modules the package installs.
"""

from __future__ import annotations

import doctest
import importlib
import io
import pkgutil

import pytest

import microbearing


def _modules() -> list[str]:
    names = []
    for sub in microbearing.SUBPACKAGES:
        package = importlib.import_module(f"microbearing.{sub}")
        names.append(package.__name__)
        names += [info.name for info in pkgutil.walk_packages(package.__path__, f"{package.__name__}.")
                  if ".root_package" not in info.name]  # the folder that is `microbearing` itself
    return sorted(names)


MODULES = _modules()
#: Modules of an optional extra, with the package they need (skipped without it).
OPTIONAL = {"microbearing.service.store_postgres": "psycopg_pool"}


def _available(name: str) -> bool:
    try:
        importlib.import_module(OPTIONAL.get(name, name))
    except ImportError:
        return False
    return True


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    if not _available(name):
        pytest.skip(f"{name} needs {OPTIONAL[name]} (an optional extra), not installed")
    module = importlib.import_module(name)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)  # pytest's default flags
    report = io.StringIO()
    for test in doctest.DocTestFinder().find(module, name):
        runner.run(test, out=report.write)
    assert runner.failures == 0, report.getvalue()


def test_the_walk_reaches_the_examples():
    tried = sum(len(test.examples) for name in MODULES if _available(name)
                for test in doctest.DocTestFinder().find(importlib.import_module(name), name))
    assert len(MODULES) > 40 and tried > 80, (len(MODULES), tried)
