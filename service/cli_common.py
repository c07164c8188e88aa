"""What every ``microbearing`` command shares: exit codes, one-line errors, files in and out, NAME=VALUE
inputs, the data folder of stored models and the references to them, and help with examples.

:mod:`service.cli` builds the parser and runs a command; :mod:`service.cli_compute` (evaluate, sweep,
optimize, experiments) and :mod:`service.cli_models` (calibrate, calibrations, surrogate) hold the
commands.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

__all__ = ["EXIT_FAILURE", "EXIT_FILE", "EXIT_INFEASIBLE", "EXIT_INVALID", "EXIT_OK", "CommandError",
           "add_command", "as_typed", "assignments", "columns_of", "converted", "data_dir", "data_dir_option",
           "defaults", "model_reference", "named_values", "open_store", "problem_error", "progress_bar",
           "read_bytes", "read_request", "reading", "say_warnings", "slip_warnings", "value_of", "write_png",
           "write_text"]

#: Exit codes of the command line (see :mod:`service.cli`).
EXIT_OK, EXIT_FAILURE, EXIT_INVALID, EXIT_INFEASIBLE, EXIT_FILE = 0, 1, 2, 3, 4

#: A stored model's id: 32 hexadecimal digits, alone or after its kind (calibrated:, surrogate:).
_MODEL_ID = re.compile(r"^(?:(calibrated|surrogate):)?([0-9a-f]{32})$")
#: The store's kind of each reference prefix.
_STORE_KINDS = {"calibrated": "calibration", "surrogate": "surrogate"}


class CommandError(Exception):
    """A failure the command reports in one line on stderr, with its exit code."""

    def __init__(self, message: str, code: int):
        super().__init__(message)
        self.code = code


def add_command(sub: Any, name: str, func: Callable[[argparse.Namespace], int] | None, *, help: str,
                description: str, examples: list[str]) -> argparse.ArgumentParser:
    """A subcommand running ``func`` (None: a group of subcommands that run their own), with ``examples``
    (shell lines) at the end of its ``--help``."""
    command = sub.add_parser(name, help=help, description=description,
                             formatter_class=argparse.RawDescriptionHelpFormatter,
                             epilog="examples:\n" + "".join(f"  {line}\n" for line in examples))
    if func is not None:
        command.set_defaults(func=func)
    return command


def read_bytes(path: str) -> bytes:
    """The bytes of ``path`` ("-": standard input)."""
    try:
        return sys.stdin.buffer.read() if path == "-" else Path(path).read_bytes()
    except OSError as exc:
        raise CommandError(f"cannot read {path}: {exc.strerror or exc}", EXIT_FILE) from None


def write_text(path: str | None, text: str) -> None:
    """Write ``text`` to ``path`` (None or "-": standard output)."""
    if path in (None, "-"):
        sys.stdout.write(text)
        return
    try:
        Path(path).write_text(text, encoding="utf-8")
    except OSError as exc:
        raise CommandError(f"cannot write {path}: {exc.strerror or exc}", EXIT_FILE) from None


def write_png(path: str, image: bytes) -> None:
    """Write a PNG image to the file ``path``."""
    try:
        Path(path).write_bytes(image)
    except OSError as exc:
        raise CommandError(f"cannot write {path}: {exc.strerror or exc}", EXIT_FILE) from None


def problem_error(problem: Any, folder: Path | str | None = None) -> CommandError:
    """A service :class:`~service.problems.ProblemError` as a one-line command error naming the fields
    (and, for something not found, the data folder or PostgreSQL database it was looked for in)."""
    from .optimizations import INFEASIBLE_TYPE

    detail = problem.detail
    if problem.status == 404 and isinstance(folder, str):
        detail += f" (looked in the PostgreSQL database {folder}, MICROBEARING_DATABASE_URL)"
    elif problem.status == 404 and folder is not None:
        detail += (f" (looked in the data folder {folder}; --data-dir or MICROBEARING_DATA_DIR names "
                   "another)")
    items = [f"{item.get('pointer') or item.get('parameter')}: {item['detail']}"
             for item in problem.errors or [] if item["detail"] not in problem.detail]
    code = EXIT_INFEASIBLE if problem.type == INFEASIBLE_TYPE else (
        EXIT_INVALID if 400 <= problem.status < 500 else EXIT_FAILURE)
    return CommandError("; ".join([detail, *items]), code)


def read_request(path: str, model: Any, overrides: dict[str, Any] | None = None) -> Any:
    """The JSON request in ``path``, with ``overrides`` set at its top level, validated as ``model`` (a
    pydantic model or type adapter)."""
    from pydantic import TypeAdapter, ValidationError

    from .problems import body_problem

    text = read_bytes(path)
    try:
        document = json.loads(text)
    except ValueError as exc:
        raise CommandError(f"{path} is not JSON: {exc}", EXIT_INVALID) from None
    if overrides and isinstance(document, dict):
        document = {**document, **overrides}
    try:
        return TypeAdapter(model).validate_python(document)
    except ValidationError as exc:
        raise problem_error(body_problem(exc, document)) from None


@contextmanager
def progress_bar(description: str) -> Iterator[Callable[[float], None]]:
    """A progress callback (fraction done, 0..1) drawing a bar on stderr when it is a terminal."""
    from tqdm import tqdm

    with tqdm(total=1000, desc=description, unit="‰", disable=None, file=sys.stderr,
              bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining}") as bar:
        def update(fraction: float) -> None:
            bar.update(max(0, round(1000 * fraction) - bar.n))

        yield update


def named_values(items: list[str], lists: bool = False) -> dict[str, list[Any]]:
    """``NAME=VALUE`` (``NAME=VALUE[,VALUE...]`` with ``lists``) physics inputs, each value parsed in its
    kind (whole numbers, numbers, true/false) and converted from the unit its name states."""
    from microbearing import physics
    from microbearing.physics.columns import unknown_column

    form = "NAME=VALUE[,VALUE...]" if lists else "NAME=VALUE"
    values: dict[str, list[Any]] = {}
    for item in items:
        name, sep, text = item.partition("=")
        read = reading(name.strip()) if sep else None
        spec = None if read is None else physics.PARAMETERS.get(read.name)
        if spec is None:
            known = unknown_column(name.strip(), physics.PARAMETERS) if sep else "no '='"
            raise CommandError(f"{item!r}: expected {form}; {known}", EXIT_INVALID)
        if spec.name in values:
            raise CommandError(f"{item!r}: {spec.name} is given twice", EXIT_INVALID)
        parts = text.split(",") if lists else [text]
        values[spec.name] = [converted(read, value_of(spec, part.strip(), name)) for part in parts]
        for part, value in zip(parts, values[spec.name], strict=True):
            try:  # refused here, by the name and value as typed (the API's /load [mN] alike)
                physics.validate(spec.name, value)
            except ValueError as exc:
                key = name.strip()
                said = as_typed(key, part, spec.name, value)
                raise CommandError(f"{key}: {exc}{said}", EXIT_INVALID) from None
    return values


def as_typed(key: str, typed: str, name: str, value: float) -> str:
    """What a refusal adds about an input typed under another key: `` (sent as load [mN]: -5, read as
    load_N: -0.005)``; nothing when it was typed under its own name."""
    key = key.strip()
    return "" if key == name else f" (sent as {key}: {typed.strip()}, read as {name}: {value:g})"


def reading(name: str) -> Any:
    """How a NAME (or a CSV header) is read by the column registry (``speed [mm/s]`` as speed_m_s / 1000),
    or None when it is not readable."""
    from microbearing.physics.columns import ColumnError, read_name

    try:
        return read_name(name)
    except ColumnError:
        return None


def converted(read: Any, value: Any) -> Any:
    """A value in the unit of the physics input ``read`` reads (whole counts and booleans as they are)."""
    return read.convert(value) if read.reading and not isinstance(value, bool) else value


def slip_warnings(inputs: dict[str, Any], items: list[str] | None = None) -> list[str]:
    """The API's unit-slip warnings of the inputs (:func:`physics.slips.input_slips`), also on stderr;
    ``items``: the ``NAME=VALUE`` arguments, each judged as typed (``load [mN]=2000`` in mN)."""
    from microbearing.physics.slips import input_slips

    sent: dict[str, tuple[str, Any]] = {}
    for item in items or []:
        name, _, text = item.partition("=")
        read = reading(name.strip())
        if read is not None and read.name != name.strip():
            sent[read.name] = (name.strip(), [part.strip() for part in text.split(",")])
    warnings = input_slips(inputs, sent)
    say_warnings(warnings)
    return warnings


def say_warnings(warnings: Iterable[str] | None) -> None:
    """A result's warnings on stderr, one ``warning: ...`` line each: every command says them beside its
    output, which ``-o`` may send to a file (the JSON keeps them too)."""
    for warning in warnings or []:
        print(f"warning: {warning}", file=sys.stderr)


def assignments(items: list[str]) -> dict[str, Any]:
    """``NAME=VALUE`` physics inputs, parsed in their kinds (whole numbers, numbers, true/false)."""
    return {name: values[0] for name, values in named_values(items).items()}


def columns_of(items: list[str]) -> dict[str, Any]:
    """``NAME=VALUE[,VALUE...]`` physics inputs as columns (one value broadcasts)."""
    return {name: values[0] if len(values) == 1 else values
            for name, values in named_values(items, lists=True).items()}


def value_of(spec: Any, text: str, where: str) -> Any:
    """One value of a physics input from text."""
    try:
        if spec.kind == "bool":
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError
            return text.lower() in ("true", "1")
        if spec.kind == "int":  # 6.0 is the API's 6; 6.5 is left to physics.validate, refused in its words
            number = float(text)
            return int(number) if number.is_integer() else number
        return float(text)
    except ValueError:
        kind = {"bool": "true or false", "int": "a whole number"}.get(spec.kind, "a number")
        # the unit of the input's own name; a key sent under another (load [mN]) states its own
        unit = f" [{spec.unit}]" if where.endswith(spec.name) else ""
        raise CommandError(f"{where}: {text!r} is not {kind}{unit}", EXIT_INVALID) from None


def defaults(given: dict[str, Any]) -> dict[str, Any]:
    """Every physics input left out of ``given`` at its default (required ones are an error)."""
    from microbearing import physics

    missing = [n for n, p in physics.PARAMETERS.items() if p.required and n not in given]
    if missing:
        raise CommandError(f"required inputs missing: {', '.join(f'{n}=VALUE' for n in missing)}",
                           EXIT_INVALID)
    return {n: p.default for n, p in physics.PARAMETERS.items() if not p.required}


def data_dir_option(command: argparse.ArgumentParser) -> None:
    """``--data-dir`` on a command that reads or writes the store."""
    command.add_argument("--data-dir", type=Path, default=None,
                         help="data folder of stored models, the server's (default: $MICROBEARING_DATA_DIR, "
                              "else the user data dir)")


def data_dir(args: argparse.Namespace) -> Path | str:
    """Where the stored models are: --data-dir, else the server's PostgreSQL database (its URL without the
    password) when MICROBEARING_DATABASE_URL is set, else the server's data folder."""
    from .settings import Settings

    given = getattr(args, "data_dir", None)
    if given is not None:
        return Path(given).expanduser().resolve()
    settings = Settings()
    url = settings.database_url.get_secret_value()
    if url:
        from .store import redacted_url

        return redacted_url(url)
    return Path(settings.data_dir)


def open_store(args: argparse.Namespace, write: bool = False) -> Any:
    """The store of the data folder; for a read, an error naming the folder when it has no database
    (the folder and database are never created by a read). With MICROBEARING_DATABASE_URL and no
    --data-dir: the server's PostgreSQL database."""
    from .settings import Settings
    from .store import DATABASE_NAME, Store

    folder = data_dir(args)
    if isinstance(folder, str):  # PostgreSQL
        from .deps import DataFolderError, open_database

        try:
            return open_database(Settings())
        except DataFolderError as exc:
            raise CommandError(str(exc), EXIT_FAILURE) from None
    if not write and not (folder / DATABASE_NAME).is_file():
        raise CommandError(f"no stored models: the data folder {folder} has no database {DATABASE_NAME} "
                           "(--data-dir or MICROBEARING_DATA_DIR names the server's folder)", EXIT_INVALID)
    return Store(folder)


def model_reference(store: Any, given: str, kinds: tuple[str, ...], folder: Path | str,
                    argument: str = "--model") -> str:
    """The reference (``calibrated:<id>``, ``surrogate:<id>``) of a stored model given by its id, as
    ``calibrate`` and ``surrogate train`` print it, or by its reference; ``physics`` stays itself.

    Parameters
    ----------
    store : Store
        Where the model is looked up (a bare id names whichever kind of ``kinds`` has it).
    given : str
        ``<id>``, ``calibrated:<id>``, ``surrogate:<id>`` or ``physics``.
    kinds : tuple of str
        The references the command takes: ``"physics"``, ``"calibrated"``, ``"surrogate"``.
    folder : Path or str
        The data folder (or database) looked in, named when the model is not there.
    argument : str, default "--model"
        The command's argument that gave it, named in a refusal (``id`` for ``delete``).

    Raises
    ------
    CommandError
        A malformed reference, a kind the command does not take, or an id stored under no such kind.
    """
    shapes = " or ".join("physics" if k == "physics" else f"{k}:<id>" for k in kinds)
    if given == "physics" and "physics" in kinds:
        return given
    match = _MODEL_ID.match(given.strip().lower())
    if match is None or (match.group(1) is not None and match.group(1) not in kinds):
        raise CommandError(f"{argument}: expected an id (32 hexadecimal digits) or {shapes}; got {given!r}",
                           EXIT_INVALID)
    if match.group(1) is not None:
        return f"{match.group(1)}:{match.group(2)}"
    for kind in kinds:
        if kind in _STORE_KINDS and store.has_model(match.group(2), _STORE_KINDS[kind]):
            return f"{kind}:{match.group(2)}"
    what = " or ".join("calibration" if k == "calibrated" else k for k in kinds if k != "physics")
    where = f"the PostgreSQL database {folder}" if isinstance(folder, str) else f"the data folder {folder}"
    raise CommandError(f"there is no {what} {match.group(2)} in {where} (deleted, or stored elsewhere: "
                       "--data-dir or MICROBEARING_DATA_DIR names the server's folder)", EXIT_INVALID)
