"""The ``microbearing`` command line: evaluate, sweep and optimize from a shell, serve the API,
reproduce the paper, calibrate on measurements, train and query surrogates.

Stored models (surrogates, calibrations) live in the data folder of the server
(``--data-dir``, else ``$MICROBEARING_DATA_DIR``, else the user data folder); a command that only
reads them never creates that folder or its database.

Exit codes: 0 success; 1 an unexpected failure; 2 invalid arguments or input (the message names the
field); 3 an infeasible design problem (no design meets the limits); 4 a file that cannot be read or
written.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .settings import ENV_PREFIX

#: Exit codes of the command line (see the module docstring).
EXIT_OK, EXIT_FAILURE, EXIT_INVALID, EXIT_INFEASIBLE, EXIT_FILE = 0, 1, 2, 3, 4


class CommandError(Exception):
    """A failure the command reports in one line on stderr, with its exit code."""

    def __init__(self, message: str, code: int):
        super().__init__(message)
        self.code = code


def _paper(args: argparse.Namespace) -> int:
    from microbearing.physics import paper

    print(paper.report(args.convention))
    if args.plot:
        paper.plot(args.plot, args.convention)
        print(f"wrote {args.plot}")
    return 0


def _serve(args: argparse.Namespace) -> int:
    import uvicorn

    if args.data_dir is not None:
        # Every worker process builds its app from the environment.
        os.environ[f"{ENV_PREFIX}DATA_DIR"] = str(Path(args.data_dir).expanduser().resolve())
    if args.workers > 1 and "PROMETHEUS_MULTIPROC_DIR" not in os.environ:
        # Before the workers start: they sum their metrics in files (service/observability.py).
        from .observability import prepare_multiprocess_dir
        from .settings import Settings

        prepare_multiprocess_dir(Settings().data_dir)
    # Requests are logged as JSON lines with their request id by service/observability.py;
    # uvicorn's own lines (startup, shutdown, errors) are JSON too.
    # Connections bounded (service/connections.py): header time and size limits, a connection cap
    # within the open-file limit; the limit is raised first, for the workers to inherit.
    from .connections import accept_backlog, raise_fd_limit
    from .observability import uvicorn_log_config
    from .settings import Settings

    raise_fd_limit()
    uvicorn.run("microbearing.service.app:app",
                host=args.host, port=args.port, workers=args.workers, access_log=False,
                log_config=uvicorn_log_config(), http="microbearing.service.connections:BoundedHttpProtocol",
                backlog=accept_backlog(Settings()))
    return 0


def _calibrate(args: argparse.Namespace) -> int:
    from microbearing.calibrate import DataError, calibrate, parse_assignments, read_csv

    try:
        text = Path(args.data).read_bytes()
    except OSError as exc:
        print(f"microbearing calibrate: cannot read {args.data}: {exc}", file=sys.stderr)
        return EXIT_FILE
    fit = [name.strip() for name in (args.fit or "").split(",") if name.strip()]
    try:
        factors = [name.strip() for name in (args.factors or "").split(",") if name.strip()]
        dataset, intake = read_csv(text, parse_assignments(args.fixed), args.separator, args.decimal, factors)
        print(f"{args.data}: {intake.summary()}", file=sys.stderr)
        report = calibrate(dataset, fit, folds=args.folds)
    except DataError as exc:
        print(f"microbearing calibrate: {args.data}: {exc}", file=sys.stderr)
        return 2
    except ValueError as exc:
        print(f"microbearing calibrate: {exc}", file=sys.stderr)
        return 2
    print(report.text())
    if args.plots:
        folder = Path(args.plots)
        folder.mkdir(parents=True, exist_ok=True)
        for name, png in report.plots.items():
            (folder / f"{name}.png").write_bytes(png)
            print(f"wrote {folder / f'{name}.png'}")
    if args.json:
        Path(args.json).write_text(json.dumps({**report.to_dict(), "intake": intake.to_dict()}, indent=1))
        print(f"wrote {args.json}")
    return 0


def _read(path: str) -> bytes:
    """The bytes of ``path`` ("-": standard input)."""
    try:
        return sys.stdin.buffer.read() if path == "-" else Path(path).read_bytes()
    except OSError as exc:
        raise CommandError(f"cannot read {path}: {exc.strerror or exc}", EXIT_FILE) from None


def _write(path: str | None, text: str) -> None:
    """Write ``text`` to ``path`` (None or "-": standard output)."""
    if path in (None, "-"):
        sys.stdout.write(text)
        return
    try:
        Path(path).write_text(text, encoding="utf-8")
    except OSError as exc:
        raise CommandError(f"cannot write {path}: {exc.strerror or exc}", EXIT_FILE) from None


def _write_png(path: str, image: bytes) -> None:
    """Write a PNG image to the file ``path``."""
    try:
        Path(path).write_bytes(image)
    except OSError as exc:
        raise CommandError(f"cannot write {path}: {exc.strerror or exc}", EXIT_FILE) from None


def _problem_error(problem: Any, data_dir: Path | str | None = None) -> CommandError:
    """A service :class:`~service.problems.ProblemError` as a command error naming the fields (and, for
    something not found, the data folder or PostgreSQL database it was looked for in)."""
    from .optimizations import INFEASIBLE_TYPE

    detail = problem.detail
    if problem.status == 404 and isinstance(data_dir, str):
        detail += f" (looked in the PostgreSQL database {data_dir}, MICROBEARING_DATABASE_URL)"
    elif problem.status == 404 and data_dir is not None:
        detail += (f" (looked in the data folder {data_dir}; --data-dir or MICROBEARING_DATA_DIR names "
                   "another)")
    lines = [detail] + [f"  {item.get('pointer') or item.get('parameter')}: {item['detail']}"
                                for item in problem.errors or [] if item["detail"] not in problem.detail]
    code = EXIT_INFEASIBLE if problem.type == INFEASIBLE_TYPE else (
        EXIT_INVALID if 400 <= problem.status < 500 else EXIT_FAILURE)
    return CommandError("\n".join(lines), code)


def _request(path: str, model: Any) -> Any:
    """The JSON request in ``path``, validated as ``model`` (a pydantic model or type adapter)."""
    from pydantic import TypeAdapter, ValidationError

    from .problems import body_problem

    text = _read(path)
    try:
        document = json.loads(text)
    except ValueError as exc:
        raise CommandError(f"{path} is not JSON: {exc}", EXIT_INVALID) from None
    try:
        return TypeAdapter(model).validate_python(document)
    except ValidationError as exc:
        raise _problem_error(body_problem(exc, document)) from None


@contextmanager
def _progress_bar(description: str) -> Iterator[Callable[[float], None]]:
    """A progress callback (fraction done, 0..1) drawing a bar on stderr when it is a terminal."""
    from tqdm import tqdm

    with tqdm(total=1000, desc=description, unit="‰", disable=None, file=sys.stderr,
              bar_format="{desc}: {percentage:3.0f}%|{bar}| {elapsed}<{remaining}") as bar:
        def update(fraction: float) -> None:
            bar.update(max(0, round(1000 * fraction) - bar.n))

        yield update


def _named_values(items: list[str], lists: bool = False) -> dict[str, list[Any]]:
    """``NAME=VALUE`` (``NAME=VALUE[,VALUE...]`` with ``lists``) physics inputs, each value parsed in its
    kind (whole numbers, numbers, true/false)."""
    from microbearing import physics
    from microbearing.physics.columns import unknown_column

    form = "NAME=VALUE[,VALUE...]" if lists else "NAME=VALUE"
    values: dict[str, list[Any]] = {}
    for item in items:
        name, sep, text = item.partition("=")
        reading = _reading(name.strip()) if sep else None
        spec = None if reading is None else physics.PARAMETERS.get(reading.name)
        if spec is None:
            known = unknown_column(name.strip(), physics.PARAMETERS) if sep else "no '='"
            raise CommandError(f"{item!r}: expected {form}; {known}", EXIT_INVALID)
        if spec.name in values:
            raise CommandError(f"{item!r}: {spec.name} is given twice", EXIT_INVALID)
        parts = text.split(",") if lists else [text]
        values[spec.name] = [_converted(reading, _value(spec, part.strip(), name)) for part in parts]
    return values


def _reading(name: str) -> Any:
    """How a NAME (or a CSV header) is read by the column registry (``speed [mm/s]`` as speed_m_s / 1000),
    or None when it is not readable."""
    from microbearing.physics.columns import ColumnError, read_name

    try:
        return read_name(name)
    except ColumnError:
        return None


def _converted(reading: Any, value: Any) -> Any:
    """A value in the unit of the physics input ``reading`` reads (whole counts and booleans as they are)."""
    return reading.convert(value) if reading.reading and not isinstance(value, bool) else value


def _slip_warnings(inputs: dict[str, Any]) -> list[str]:
    """The API's unit-slip warnings of the inputs (:func:`physics.columns.input_slips`), also on stderr."""
    from microbearing.physics.columns import input_slips

    warnings = input_slips(inputs)
    for warning in warnings:
        print(f"warning: {warning}", file=sys.stderr)
    return warnings


def _assignments(items: list[str]) -> dict[str, Any]:
    """``NAME=VALUE`` physics inputs, parsed in their kinds (whole numbers, numbers, true/false)."""
    return {name: values[0] for name, values in _named_values(items).items()}


def _value(spec: Any, text: str, where: str) -> Any:
    """One value of a physics input from text."""
    try:
        if spec.kind == "bool":
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError
            return text.lower() in ("true", "1")
        return int(text) if spec.kind == "int" else float(text)
    except ValueError:
        kind = {"bool": "true or false", "int": "a whole number"}.get(spec.kind, "a number")
        raise CommandError(f"{where}: {text!r} is not {kind} [{spec.unit}]", EXIT_INVALID) from None


def _csv_points(path: str) -> tuple[dict[str, Any], int]:
    """The columns of a CSV file of physics inputs (a header row of input names, one row per point)."""
    import csv
    import io

    import numpy as np

    from microbearing import physics

    text = _read(path).decode("utf-8-sig", errors="replace")
    rows = list(csv.reader(io.StringIO(text)))
    if len(rows) < 2:
        raise CommandError(f"{path}: expected a header row of input names and at least one row", EXIT_INVALID)
    from microbearing.physics.columns import unknown_column

    sent = [name.strip() for name in rows[0]]
    readings = [_reading(name) for name in sent]
    header = [None if r is None or r.name not in physics.PARAMETERS else r.name for r in readings]
    unknown = [name for name, read in zip(sent, header, strict=True) if read is None]
    if unknown:
        raise CommandError(f"{path}: {unknown_column(unknown[0], physics.PARAMETERS)}", EXIT_INVALID)
    if len(set(header)) != len(header):
        raise CommandError(f"{path}: columns must be distinct physics inputs; got a repeated column",
                           EXIT_INVALID)
    columns: dict[str, list[Any]] = {name: [] for name in header}
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise CommandError(f"{path}:{line}: {len(row)} values for {len(header)} columns", EXIT_INVALID)
        for name, reading, text in zip(header, readings, row, strict=True):
            value = _value(physics.PARAMETERS[name], text.strip(), f"{path}:{line}:{reading.sent}")
            columns[name].append(_converted(reading, value))
    return {name: np.asarray(values) for name, values in columns.items()}, len(rows) - 1


def _evaluate(args: argparse.Namespace) -> int:
    from microbearing import physics

    from .evaluation import evaluate_point
    from .executor import evaluate_in_chunks
    from .models import physics_in
    from .problems import ProblemError
    from .schemas.base import with_folding_safe_names
    from .store import to_json
    from .tables import csv_text

    outputs = [name.strip() for name in (args.outputs or "").split(",") if name.strip()] or None
    wrong = [name for name in outputs or [] if name not in physics.OUTPUTS]
    if wrong:
        raise CommandError(f"--outputs: unknown {', '.join(wrong)}; one of {', '.join(physics.OUTPUTS)}",
                           EXIT_INVALID)
    fixed = _assignments(args.inputs)
    try:
        if args.csv is None:
            point = evaluate_point({**_defaults(fixed), **fixed}, args.convention)
            chosen = {name: point[name] for name in outputs or point}
            document = with_folding_safe_names({"convention": args.convention, **chosen})
            warnings = _slip_warnings(fixed)
            if warnings:
                document["input_warnings"] = warnings
            _write(args.output, to_json(document) + "\n")
            return EXIT_OK
        columns, count = _csv_points(args.csv)
        _slip_warnings({**fixed, **columns})
        clash = sorted(set(columns) & set(fixed))
        if clash:
            raise CommandError(f"{', '.join(clash)} given both as a column and NAME=VALUE", EXIT_INVALID)
        with _progress_bar(f"evaluate {count} points") as progress:
            results = evaluate_in_chunks(None, {**fixed, **columns}, count, outputs,
                                         physics_in(args.convention), progress=progress)
    except ProblemError as problem:
        raise _problem_error(problem) from None
    import numpy as np

    # every input the rows were evaluated at: the file's columns, then the NAME=VALUE ones
    given = {name: np.full(count, value) for name, value in fixed.items()}
    _write(args.output, csv_text({**columns, **given, **results}))
    return EXIT_OK


def _defaults(given: dict[str, Any]) -> dict[str, Any]:
    """Every physics input left out of ``given`` at its default (required ones are an error)."""
    from microbearing import physics

    missing = [n for n, p in physics.PARAMETERS.items() if p.required and n not in given]
    if missing:
        raise CommandError(f"required inputs missing: {', '.join(f'{n}=VALUE' for n in missing)}",
                           EXIT_INVALID)
    return {n: p.default for n, p in physics.PARAMETERS.items() if not p.required}


def _sweep(args: argparse.Namespace) -> int:
    from .problems import ProblemError
    from .schemas.sweeps import SweepRequest
    from .settings import Settings
    from .store import to_json
    from .sweeps import design_columns, run_sweep
    from .tables import csv_text, sweep_table

    request = _request(args.request, SweepRequest)
    try:
        plan = design_columns(request, Settings().max_sweep_points)
        with _progress_bar(f"sweep of {plan.count} points") as progress:
            document = run_sweep(request, plan, progress=progress)
    except ProblemError as problem:
        raise _problem_error(problem) from None
    as_csv = args.format == "csv" or (args.format is None and str(args.output or "").endswith(".csv"))
    _write(args.output, csv_text(sweep_table(document)) if as_csv else to_json(document) + "\n")
    return EXIT_OK


def _data_dir(args: argparse.Namespace) -> Path | str:
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


def _open_store(args: argparse.Namespace, write: bool = False) -> Any:
    """The store of the data folder; for a read, an error naming the folder when it has no database
    (the folder and database are never created by a read). With MICROBEARING_DATABASE_URL and no
    --data-dir: the server's PostgreSQL database."""
    from .settings import Settings
    from .store import DATABASE_NAME, Store

    folder = _data_dir(args)
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


def _optimize(args: argparse.Namespace) -> int:
    from .optimizations import pareto_png, prepare, run
    from .problems import ProblemError
    from .schemas.optimizations import OptimizationRequest
    from .store import to_json

    request = _request(args.request, OptimizationRequest)
    if args.plot and request.pareto is None:
        raise CommandError("--plot draws a Pareto front: add \"pareto\" to the request", EXIT_INVALID)
    # Calibrated and surrogate models are read from the server's data folder.
    store = _open_store(args) if request.model != "physics" else None
    try:
        plan = prepare(store, request)
        with _progress_bar("optimize") as progress:
            document = run(plan, progress=progress)
    except ProblemError as problem:
        raise _problem_error(problem, _data_dir(args)) from None
    finally:
        if store is not None:
            store.close()
    _write(args.output, to_json(document) + "\n")
    if args.plot:
        _write_png(args.plot, pareto_png(document))
    return EXIT_OK


def _surrogate_train(args: argparse.Namespace) -> int:
    from .problems import ProblemError
    from .schemas.surrogates import SurrogateRequest
    from .store import to_json
    from .surrogates import prepare_training, train_surrogate

    request = _request(args.request, SurrogateRequest)
    store = _open_store(args, write=request.model == "physics")
    try:
        space, mu_model = prepare_training(store, request)
        with _progress_bar(f"train a surrogate on up to {request.budget} evaluations") as progress:
            document = train_surrogate(store, space, request, progress=progress, mu_model=mu_model)
    except ProblemError as problem:
        raise _problem_error(problem, _data_dir(args)) from None
    finally:
        store.close()
    _write(args.output, to_json(document) + "\n")
    print(f"stored {document['model_id']} in {_data_dir(args)}", file=sys.stderr)
    return EXIT_OK


def _columns(items: list[str]) -> dict[str, Any]:
    """``NAME=VALUE[,VALUE...]`` physics inputs as columns (one value broadcasts)."""
    return {name: values[0] if len(values) == 1 else values
            for name, values in _named_values(items, lists=True).items()}


def _surrogate_predict(args: argparse.Namespace) -> int:
    from .problems import ProblemError
    from .store import to_json
    from .surrogates import predict

    identifier = args.id.removeprefix("surrogate:")
    points = _columns(args.inputs)
    store = _open_store(args)
    try:
        document = predict(store, identifier, points)
    except ProblemError as problem:
        raise _problem_error(problem, _data_dir(args)) from None
    finally:
        store.close()
    _write(args.output, to_json(document) + "\n")
    return EXIT_OK


def _surrogate_list(args: argparse.Namespace) -> int:
    from .store import to_json
    from .surrogates import surrogate_views

    store = _open_store(args)
    try:
        views = surrogate_views(store)
    finally:
        store.close()
    if args.json:
        _write(args.output, to_json({"surrogates": views}) + "\n")
        return EXIT_OK
    lines = [f"{len(views)} surrogate(s) in {_data_dir(args)}"]
    for view in views:
        space = ", ".join(f"{name} [{low:g}, {high:g}]" for name, (low, high) in view["space"].items())
        lines.append(f"{view['model_id']}  {view['created_at']}  {view['n_train']} evaluations  {space}")
    _write(args.output, "\n".join(lines) + "\n")
    return EXIT_OK


def _experiments(args: argparse.Namespace) -> int:
    from types import SimpleNamespace

    from .experiments import first_experiments_job, next_experiments_job, plan_png
    from .problems import ProblemError
    from .schemas.experiments import FirstExperimentsRequest, NextExperimentsRequest
    from .store import to_json

    request = _request(args.request, NextExperimentsRequest if args.calibration else FirstExperimentsRequest)
    # A calibration is read from the server's data folder, as optimize reads calibrated models.
    store = _open_store(args) if args.calibration else None
    try:
        work = (next_experiments_job(store, args.calibration.removeprefix("calibrated:"), request)
                if store is not None else first_experiments_job(request))
        with _progress_bar("experiments") as progress:
            document = work(SimpleNamespace(progress=progress, job_id=None))
    except ProblemError as problem:
        raise _problem_error(problem, _data_dir(args) if store is not None else None) from None
    finally:
        if store is not None:
            store.close()
    _write(args.output, to_json(document) + "\n")
    if args.plot:
        _write_png(args.plot, plan_png(document))
    return EXIT_OK


def _json_command(sub: Any, name: str, func: Callable[[argparse.Namespace], int], *, help: str,
                  description: str, examples: list[str]) -> argparse.ArgumentParser:
    """A subcommand reading a JSON request file and writing its result, with examples in its help."""
    command = sub.add_parser(name, help=help, description=description,
                             formatter_class=argparse.RawDescriptionHelpFormatter,
                             epilog="examples:\n" + "".join(f"  {line}\n" for line in examples))
    command.add_argument("request", help="JSON request file ('-': stdin)")
    command.add_argument("-o", "--output", metavar="FILE", help="write here instead of stdout")
    command.set_defaults(func=func)
    return command


def _add_evaluate(sub: Any, conventions: list[str]) -> None:
    from microbearing import physics

    e = sub.add_parser(
        "evaluate", help="friction of one design point, or of every row of a CSV file (to CSV)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Evaluate the friction model. With NAME=VALUE inputs only: one point, printed as the "
                    "JSON of POST /v1/friction. With --csv: every row of the file (a header of input names), "
                    "written as CSV with the inputs then the outputs; NAME=VALUE inputs apply to every row.",
        epilog="examples:\n"
               "  microbearing evaluate balls=4 load_N=0.008826 speed_m_s=0.05 mu_pivot=1\n"
               "  microbearing evaluate balls=4 load_N=0.0088 speed_m_s=0.05 --outputs mu,mu_contact\n"
               "  microbearing evaluate --csv points.csv balls=4 --outputs mu -o friction.csv")
    e.add_argument("inputs", nargs="*", metavar="NAME=VALUE", help="physics inputs in their units")
    e.add_argument("--csv", metavar="FILE", help="CSV of points, one column per input ('-': stdin)")
    e.add_argument("--outputs", metavar="NAME,...", help="outputs to give (default: all)")
    e.add_argument("--convention", choices=conventions, default=physics.DEFAULT_CONVENTION)
    e.add_argument("-o", "--output", metavar="FILE", help="write here instead of stdout")
    e.set_defaults(func=_evaluate)


def _add_json_commands(sub: Any) -> None:
    """``sweep``, ``optimize`` and ``experiments``: a JSON request file in the schema of their route."""
    w = _json_command(
        sub, "sweep", _sweep, help="a grid or design of experiments from a JSON request (as POST /v1/sweeps)",
        description="Run the sweep described by a JSON file in the schema of POST /v1/sweeps; write its "
                    "result (JSON, the schema SweepResult) or its table as CSV.",
        examples=['echo \'{"design": "grid", "fixed": {"load_N": 0.0088}, "outputs": ["mu"],',
                  '      "axes": {"balls": {"start": 4, "stop": 12, "num": 3},',
                  '               "speed_m_s": {"start": 0, "stop": 0.15, "num": 4}}}\' > grid.json',
                  "microbearing sweep grid.json -o grid.csv",
                  "microbearing sweep grid.json --format json > grid.json.out"])
    w.add_argument("--format", choices=["json", "csv"], help="output format (default: csv for a .csv output "
                                                               "file, else json)")

    o = _json_command(
        sub, "optimize", _optimize,
        help="the least-friction design from a JSON request (as POST /v1/optimizations)",
        description="Solve the design problem of a JSON file in the schema of POST /v1/optimizations and "
                    "write the result as JSON (the schema OptimizationResult). Exit code 3 when no design "
                    "meets the limits (the message names the conflicting ones).",
        examples=['echo \'{"bounds": {"balls": [4, 24], "groove_angle_deg": [35, 70], '
                  '"load_N": [0.001, 0.05]},',
                  '      "fixed": {"speed_m_s": 0.05}, "constraints": {"max_contact_pressure_Pa": 1e9}}\' '
                  "> problem.json",
                  "microbearing optimize problem.json -o best.json",
                  'microbearing optimize front.json --plot front.png   # a request with "pareto"'])
    o.add_argument("--plot", metavar="FILE.png", help="draw the Pareto front (requests with \"pareto\")")

    x = _json_command(
        sub, "experiments", _experiments,
        help="which measurements to take next, with an optimality bound (as POST /v1/experiments, or "
             "/v1/calibrations/{id}/next-experiments with --calibration)",
        description="Propose runs from a JSON request and write the result as JSON (the schema "
                    "ExperimentsResult). Without --calibration: a first design on the declared physics "
                    "(the schema FirstExperimentsRequest); with it: the next runs for a calibration stored "
                    "in the server's data folder (NextExperimentsRequest; goal discriminate, parameters or "
                    "predict).",
        examples=['echo \'{"runs": 12, "goal": "discriminate", "space": {"balls": {"low": 4, "high": 8},',
                  '      "load_N": {"low": 0.003, "high": 0.03, "spacing": "log"}, "speed_m_s": [0.05],',
                  '      "relative_humidity": {"low": 0.2, "high": 0.9}}}\' > next.json',
                  "microbearing experiments next.json --calibration calibrated:<id> -o runs.json "
                  "--plot runs.png",
                  'echo \'{"runs": 8, "fit_parameters": ["mu_pivot"], "space": {"balls": {"values": [4, 8]},',
                  '      "load_N": {"low": 0.001, "high": 0.03}, "speed_m_s": [0.05]}}\' > first.json',
                  "microbearing experiments first.json -o first-runs.json"])
    x.add_argument("--calibration", metavar="ID", help="a stored calibration (its id or calibrated:<id>)")
    x.add_argument("--plot", metavar="FILE.png", help="draw the runs over the data taken (and the rivals)")
    _data_dir_option(o)


def _add_paper_and_serve(sub: Any) -> None:
    from microbearing import physics

    p = sub.add_parser("paper", help="reproduce the numerical cases of Olaru et al. (2005)",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Print the paper's cases A and B computed beside its published values.",
                       epilog="examples:\n"
                              "  microbearing paper\n"
                              "  microbearing paper --plot paper.png        # Figs. 5-6 redrawn\n"
                              "  microbearing paper --convention derjaguin")
    p.add_argument("--plot", metavar="FILE.png", help="draw mu against speed as the paper's Figs. 5-6")
    p.add_argument("--convention", choices=list(physics.CONVENTIONS), default=physics.DEFAULT_CONVENTION)
    p.set_defaults(func=_paper)

    s = sub.add_parser("serve", help="start the REST service (uvicorn)",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Start the REST service; settings come from MICROBEARING_* variables. "
                                   "The start log names the data folder (jobs and stored models).",
                       epilog="examples:\n"
                              "  microbearing serve                          # http://127.0.0.1:8000/docs\n"
                              "  microbearing serve --data-dir ./data --port 8080\n"
                              "  MICROBEARING_API_KEYS=secret microbearing serve --host 0.0.0.0 --workers 2")
    s.add_argument("--host", default="127.0.0.1", help="interface to listen on (default: %(default)s)")
    s.add_argument("--port", type=int, default=8000, help="TCP port (default: %(default)s)")
    s.add_argument("--data-dir", type=Path, default=None,
                   help="SQLite folder (default: $MICROBEARING_DATA_DIR, else the user data dir)")
    s.add_argument("--workers", type=int, default=1, help="server processes (default: 1)")
    s.set_defaults(func=_serve)


def _add_calibrate(sub: Any) -> None:
    c = sub.add_parser("calibrate", help="calibrate the model on measured CSV data, name the missing effect",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Fit the declared parameters on log mu, search the residual for a missing "
                                   "effect, and report the held-out error before and after. The CSV may be a "
                                   "spreadsheet export (comma, semicolon or tab; decimal comma; units in the "
                                   "header such as 'speed [mm/s]', converted to SI); how it was read is "
                                   "printed on stderr.",
                       epilog="examples:\n"
                              "  microbearing calibrate measured.csv --fit mu_pivot --plots plots/\n"
                              "  microbearing calibrate export.csv --fixed balls=4 "
                              "--fit mu_pivot,adhesion_energy_J_m2\n"
                              "  microbearing calibrate export.csv --separator semicolon --decimal comma "
                              "--json report.json")
    c.add_argument("data", help="CSV with physics input columns, mu_measured, optionally mu_measured_std, "
                                "and any condition columns")
    c.add_argument("--separator", choices=["comma", "semicolon", "tab"], help="column separator (default: "
                                                                            "detected)")
    c.add_argument("--decimal", choices=["point", "comma"], help="decimal mark (default: detected)")
    c.add_argument("--fit", metavar="NAME,...", help="declared parameters to fit, e.g. mu_pivot,mu_ball")
    c.add_argument("--fixed", metavar="NAME=VALUE", nargs="+", action="extend", default=[],
                   help="physics inputs fixed for every row, in their units (e.g. balls=4)")
    c.add_argument("--folds", type=int, default=5, help="cross-validation folds (default: %(default)s)")
    c.add_argument("--factors", metavar="NAME,...",
                   help="condition columns of integer codes to read as group labels (a column of text labels "
                        "is one anyway)")
    c.add_argument("--plots", metavar="DIR", help="write the residual plots (PNG) into DIR")
    c.add_argument("--json", metavar="FILE", help="write the full report, with the calibrated model, as JSON")
    c.set_defaults(func=_calibrate)


def _data_dir_option(command: argparse.ArgumentParser) -> None:
    """``--data-dir`` on a command that reads the store."""
    command.add_argument("--data-dir", type=Path, default=None,
                         help="data folder of stored models (default: $MICROBEARING_DATA_DIR, else the "
                              "user data dir)")


def _add_surrogate(sub: Any) -> None:
    g = sub.add_parser("surrogate",
                       help="train, query and list Gaussian-process surrogates (as /v1/surrogates)",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Surrogates stored in the server's data folder: train one from a JSON "
                                   "request (the schema of POST /v1/surrogates), predict with it, list them.",
                       epilog="examples:\n"
                              "  microbearing surrogate train request.json -o surrogate.json\n"
                              "  microbearing surrogate predict surrogate:<id> load_N=0.002,0.02 "
                              "speed_m_s=0.05\n"
                              "  microbearing surrogate list --data-dir ./data")
    actions = g.add_subparsers(dest="action", required=True)

    t = _json_command(
        actions, "train", _surrogate_train, help="train a surrogate and store it (prints its JSON)",
        description="Train the surrogate described by a JSON file in the schema of POST /v1/surrogates and "
                    "store it in the data folder; write its description (the schema SurrogateResult).",
        examples=['echo \'{"space": {"load_N": [0.001, 0.05], "speed_m_s": [0.001, 0.2]}, '
                  '"fixed": {"balls": 4}, "budget": 30}\' > request.json',
                  "microbearing surrogate train request.json -o surrogate.json"])
    _data_dir_option(t)
    r = actions.add_parser("predict", help="predict mu with its 95 %% interval at points",
                           formatter_class=argparse.RawDescriptionHelpFormatter,
                           description="Predict mu, its 95 % interval and whether each point lies inside "
                                       "the trained space (the answer of POST /v1/surrogates/{id}/predict).",
                           epilog="examples:\n"
                                  "  microbearing surrogate predict surrogate:<id> load_N=0.002,0.02 "
                                  "speed_m_s=0.05\n"
                                  "  microbearing surrogate predict <id> load_N=0.01 speed_m_s=0.1 "
                                  "-o mu.json")
    r.add_argument("id", help="the surrogate: surrogate:<id> or <id>")
    r.add_argument("inputs", nargs="+", metavar="NAME=VALUE[,VALUE...]",
                   help="every dimension of the surrogate, in its unit; one value broadcasts")
    r.add_argument("-o", "--output", metavar="FILE", help="write here instead of stdout")
    _data_dir_option(r)
    r.set_defaults(func=_surrogate_predict)
    li = actions.add_parser("list", help="list the stored surrogates",
                            formatter_class=argparse.RawDescriptionHelpFormatter,
                            description="List the surrogates of the data folder, newest first.",
                            epilog="examples:\n"
                                   "  microbearing surrogate list\n"
                                   "  microbearing surrogate list --json -o surrogates.json")
    li.add_argument("--json", action="store_true", help="the full descriptions as JSON (GET /v1/surrogates)")
    li.add_argument("-o", "--output", metavar="FILE", help="write here instead of stdout")
    _data_dir_option(li)
    li.set_defaults(func=_surrogate_list)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    from microbearing import physics

    from .routes.meta import package_version

    parser = argparse.ArgumentParser(prog="microbearing", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_evaluate(sub, list(physics.CONVENTIONS))
    _add_json_commands(sub)
    _add_paper_and_serve(sub)
    _add_calibrate(sub)
    _add_surrogate(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``microbearing`` console script; returns the exit code."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except CommandError as error:
        print(f"microbearing {args.command}: {error}", file=sys.stderr)
        return error.code


if __name__ == "__main__":
    sys.exit(main())
