"""The computing commands of ``microbearing``: ``evaluate`` (the physics, or a stored calibration with its
interval), ``sweep``, ``optimize`` and ``experiments``, each answering as its API route does.

A stored model is named by ``--model`` with the id ``calibrate`` or ``surrogate train`` printed (or its
reference, ``calibrated:<id>``); it is read from the data folder (``--data-dir``).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from contextlib import closing
from dataclasses import dataclass, field
from typing import Any

from .cli_common import (
    EXIT_INVALID,
    EXIT_OK,
    CommandError,
    add_command,
    as_typed,
    assignments,
    data_dir,
    data_dir_option,
    defaults,
    model_reference,
    open_store,
    progress_bar,
    read_bytes,
    read_request,
    reading,
    say_warnings,
    slip_warnings,
    value_of,
    write_png,
    write_text,
)

__all__ = ["Points", "add_evaluate", "add_json_commands", "read_points"]


@dataclass(frozen=True)
class Points:
    """The points of a CSV file to evaluate (:func:`read_points`).

    Attributes
    ----------
    inputs : dict of str to numpy.ndarray
        Physics inputs by name, in SI (converted from the unit of the header).
    conditions : dict of str to list
        Other columns by their header and in its unit, as sent (the calibrated model reads them as
        ``/v1/friction`` reads its conditions): numbers, or labels of a factor.
    count : int
        Rows [1].
    lines : list of int
        Each row's line in the file (for a refusal's words).
    sent : dict of str to Reading
        How each physics input sent under another header or unit was read (``load [mN]``), to write it
        back so (:meth:`inputs_as_sent`).
    """

    inputs: dict[str, Any]
    conditions: dict[str, list[Any]]
    count: int
    lines: list[int] = field(default_factory=list)
    sent: dict[str, Any] = field(default_factory=dict)

    def rows(self, stop: int) -> Points:
        """The first ``stop`` rows."""
        return Points({n: v[:stop] for n, v in self.inputs.items()},
                      {n: v[:stop] for n, v in self.conditions.items()}, stop, self.lines[:stop], self.sent)

    def inputs_as_sent(self) -> dict[str, Any]:
        """The physics inputs under the file's headers, in its units (``load [mN]`` 10, not ``load_N``
        0.01): an answer's columns read as the file's own, so it can be read back in as it is."""
        import numpy as np

        def back(reading, values):  # to 12 significant digits: a cell typed 13.2 is written 13.2 again
            return [float(f"{v:.12g}") for v in reading.sent_value(np.asarray(values, dtype=float))]

        return {(r.sent.strip() if (r := self.sent.get(name)) else name): (back(r, values) if r else values)
                for name, values in self.inputs.items()}


def read_points(path: str, separator: str | None, decimal: str | None) -> Points:
    """The points of a CSV file read as ``calibrate`` reads measurements
    (:func:`calibrate.tabular.read_table`: comma, semicolon or tab, decimal comma, units in the header),
    one row per point.

    How the file was read is printed on stderr, as ``calibrate`` prints it.
    """
    import numpy as np

    from microbearing import physics
    from microbearing.calibrate import DataError
    from microbearing.calibrate.tabular import read_table

    try:
        table = read_table(read_bytes(path), separator, decimal)
    except DataError as exc:
        raise CommandError(f"{path}: {'; '.join(DataError.describe(e) for e in exc.errors)}",
                           EXIT_INVALID) from None
    if table.columns is None:
        raise CommandError(f"{path}: every column needs a name in the header row (physics inputs such as "
                           "load [mN], speed [mm/s])", EXIT_INVALID)
    rows, sent_rows = table.converted_rows(), table.converted_rows(units=False)
    if not rows:
        raise CommandError(f"{path}: expected a header row of input names and at least one row", EXIT_INVALID)
    print(f"{path}: {table.intake.summary()}", file=sys.stderr)
    # a physics input by its SI name, converted; a condition by its header and in its unit, as sent: the
    # model reads it as /v1/friction does, and a refusal names it so. An output's column (a file a sweep
    # or this command wrote) is left out, said: the answer computes it again.
    keys = [c.name if c.name in physics.PARAMETERS else c.sent.strip() for c in table.columns]
    # the physics' outputs and a calibrated model's interval and domain flag
    answer_columns = {*physics.OUTPUTS, "mu_effect", "mu_lower", "mu_upper", "in_domain"}
    answers = [key for key in keys if key in answer_columns]
    if answers:
        print(f"{path}: column(s) {', '.join(answers)} are outputs, not inputs: left out", file=sys.stderr)
    values: dict[str, list[Any]] = {key: [] for key in keys}
    lines = table.intake.row_lines  # each row's line in the file (after a sep= line, one further)

    def line_of(number: int) -> int:
        return lines[number] if number < len(lines) else number + table.intake.header_line + 1

    text_at: dict[str, str] = {}  # a condition column's first text cell, where
    for number, (row, sent_row) in enumerate(zip(rows, sent_rows, strict=True)):
        line = line_of(number)
        if len(row) != len(table.columns):
            raise CommandError(f"{path}: line {line}: {len(row)} values for {len(table.columns)} "
                               "columns", EXIT_INVALID)
        for column, key, text, sent in zip(table.columns, keys, row, sent_row, strict=True):
            if key in answers:
                continue
            spec = physics.PARAMETERS.get(column.name)
            where = f"{path}: line {line}, column {column.sent}"
            value = value_of(spec, text, where) if spec is not None else _condition(sent)
            if spec is None and isinstance(value, str):
                text_at.setdefault(key, f"{where}: {sent.strip()!r}")
            values[key].append(value)
    for key, where in text_at.items():  # numbers and labels in one column: the first label is the slip
        if any(not isinstance(v, str) for v in values[key]):
            raise CommandError(f"{where} is not a number, though the column's other cells are; only a "
                               f"factor column holds labels", EXIT_INVALID)
    for key in answers:
        del values[key]
    inputs = {name: np.asarray(column) for name, column in values.items() if name in physics.PARAMETERS}
    for j, column in enumerate(table.columns):  # a value out of range refused at its line, as typed
        if column.name in inputs:
            _check_column(path, column, inputs[column.name], [r[j] for r in sent_rows], line_of)
    conditions = {name: column for name, column in values.items() if name not in physics.PARAMETERS}
    sent = {column.name: column for column in table.columns if column.name in inputs and column.reading}
    return Points(inputs, conditions, len(rows), [line_of(number) for number in range(len(rows))], sent)


def _by_line(batch: Callable[[Points], dict[str, Any]], points: Points, path: str) -> dict[str, Any]:
    """``batch(points)``; a refusal of a condition column of the file is said at the line of the first row
    that brings it (the fewest first rows refused, found by halving: a few calls, on the error path only),
    as a physics cell's is."""
    from .problems import ProblemError

    try:
        return batch(points)
    except ProblemError as exc:
        keys = {_condition_key(str(e.get("pointer", ""))): str(e.get("detail")) for e in exc.errors or []}
        key = next((k for k in keys if k in points.conditions), None)
        if key is None or not points.lines:
            raise
        refused, kept = points.count, 0  # the first `refused` rows are refused, the first `kept` are not
        while refused - kept > 1:
            middle = (refused + kept) // 2
            try:
                batch(points.rows(middle))
                kept = middle
            except ProblemError:
                refused = middle
        raise CommandError(f"{path}: line {points.lines[refused - 1]}, column {key}: "
                           f"{points.conditions[key][refused - 1]!r}: {keys[key]}", EXIT_INVALID) from None


def _condition_key(pointer: str) -> str | None:
    """The condition key a problem's JSON pointer names (``/conditions/RH (%)``), unescaped; else None."""
    if not pointer.startswith("/conditions/"):
        return None
    return pointer.removeprefix("/conditions/").replace("~1", "/").replace("~0", "~")


def _check_column(path: str, column: Any, values: Any, sent: list[str],
                  line_of: Callable[[int], int]) -> None:
    """A physics input's column within its range (:func:`physics.validate`), else refused at the file line
    (``line_of`` a row's number) of its first bad cell, by the value as typed."""
    from microbearing import physics

    try:
        physics.validate(column.name, values)
        return
    except ValueError:
        pass
    for number, value in enumerate(values.tolist()):  # only on the error path: find the cell
        try:
            physics.validate(column.name, value)
        except ValueError as exc:
            said = as_typed(column.sent, sent[number], column.name, value)
            raise CommandError(f"{path}: line {line_of(number)}, column {column.sent}: {exc}{said}",
                               EXIT_INVALID) from None


def _condition(text: str) -> float | str:
    """A condition's cell: a number, else a factor's label."""
    try:
        return float(text)
    except ValueError:
        return text


#: What a calibrated model answers besides the physics outputs (``evaluate --model``).
_MODEL_OUTPUTS = ("mu_effect", "mu_lower", "mu_upper")


def _outputs(text: str | None, model: bool = False) -> list[str] | None:
    from microbearing import physics

    outputs = [name.strip() for name in (text or "").split(",") if name.strip()] or None
    known = [*physics.OUTPUTS, *(_MODEL_OUTPUTS if model else ())]
    wrong = [name for name in outputs or [] if name not in known]
    if wrong:
        raise CommandError(f"--outputs: unknown {', '.join(wrong)}; one of {', '.join(known)}", EXIT_INVALID)
    return outputs


def evaluate(args: argparse.Namespace) -> int:
    """``microbearing evaluate``: the physics at a point or at every row of a CSV file, or a stored
    calibration's mu with its 95 % interval (``--model``)."""
    from microbearing import physics

    from .evaluation import evaluate_point
    from .executor import evaluate_in_chunks
    from .models import physics_in
    from .schemas.base import with_folding_safe_names
    from .store import to_json
    from .tables import csv_text

    outputs = _outputs(args.outputs, args.model is not None)
    if args.model is not None:
        return _evaluate_model(args, outputs)
    convention = args.convention or physics.DEFAULT_CONVENTION
    fixed = assignments(args.inputs)
    if args.csv is None:
        point = evaluate_point({**defaults(fixed), **fixed}, convention)
        chosen = {name: point[name] for name in outputs or point}
        document = with_folding_safe_names({"convention": convention, **chosen})
        warnings = slip_warnings(fixed, args.inputs)
        if warnings:
            document["input_warnings"] = warnings
        write_text(args.output, to_json(document) + "\n")
        return EXIT_OK
    points = read_points(args.csv, args.separator, args.decimal)
    if points.conditions:
        from microbearing.physics.columns import unknown_column

        name = next(iter(points.conditions))
        raise CommandError(f"{args.csv}: {unknown_column(name, physics.PARAMETERS)}; a condition column is "
                           "read by a calibrated model only (--model ID)", EXIT_INVALID)
    _refuse_clash(points.inputs, fixed)
    slip_warnings({**fixed, **points.inputs}, args.inputs)
    with progress_bar(f"evaluate {points.count} points") as progress:
        results = evaluate_in_chunks(None, {**fixed, **points.inputs}, points.count, outputs,
                                     physics_in(convention), progress=progress)
    write_text(args.output, csv_text({**points.inputs_as_sent(), **_broadcast(fixed, points.count),
                                      **results}))
    return EXIT_OK


def _broadcast(values: dict[str, Any], count: int) -> dict[str, Any]:
    """Every NAME=VALUE input the rows were evaluated at, as a column."""
    import numpy as np

    return {name: np.full(count, value) for name, value in values.items()}


def _refuse_clash(columns: dict[str, Any], given: dict[str, Any]) -> None:
    clash = sorted(set(columns) & set(given))
    if clash:
        raise CommandError(f"{', '.join(clash)} given both as a column and NAME=VALUE", EXIT_INVALID)


def _refuse_unreadable(name: str) -> None:
    """A condition's NAME no door reads (``temp_K_C`` states two units, ``RH [furlong]``), refused in the
    words and at the field the API's schema refuses it in."""
    from microbearing.physics.columns import ColumnError, read_name

    from .problems import pointer_at, validation_problem

    try:
        read_name(name)
    except ColumnError as exc:
        raise validation_problem([{"pointer": pointer_at("/conditions", name), "detail": f"{name}: {exc}"}]
                                 ) from None


def _inputs_and_conditions(items: list[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    """``NAME=VALUE`` items split into physics inputs (parsed, converted) and conditions (a number or a
    label each, under the name as sent: the calibrated model reads its unit)."""
    from microbearing import physics

    inputs, conditions = [], {}
    for item in items:
        name, sep, text = item.partition("=")
        read = reading(name.strip()) if sep else None
        if read is not None and read.name in physics.PARAMETERS:
            inputs.append(item)
        elif sep and name.strip():
            _refuse_unreadable(name.strip())
            conditions[name.strip()] = _condition(text.strip())
        else:
            raise CommandError(f"{item!r}: expected NAME=VALUE", EXIT_INVALID)
    return assignments(inputs), conditions


def _evaluate_model(args: argparse.Namespace, outputs: list[str] | None) -> int:
    """``evaluate --model``: the answer of /v1/friction (a point, as JSON) or /v1/friction/batch (the rows
    of --csv, as CSV) for a stored calibration, with mu's 95 % interval."""
    from microbearing import physics

    from .calibrations import evaluate_batch_with_model, evaluate_point_with_model
    from .schemas.base import with_folding_safe_names
    from .settings import Settings
    from .store import to_json
    from .tables import csv_text

    inputs, conditions = _inputs_and_conditions(args.inputs)
    points = read_points(args.csv, args.separator, args.decimal) if args.csv is not None else None
    with closing(open_store(args)) as store:
        reference = model_reference(store, args.model, ("calibrated",), data_dir(args))
        if points is None:
            document = evaluate_point_with_model(store, reference, inputs, conditions or None,
                                                 args.convention)
        else:
            _refuse_clash(points.inputs, inputs)
            _refuse_clash(points.conditions, conditions)

            def batch(rows: Points) -> dict[str, Any]:
                every = {**inputs, **{name: column.tolist() for name, column in rows.inputs.items()}}
                return evaluate_batch_with_model(store, None, reference, every,
                                                 {**conditions, **rows.conditions}, outputs, args.convention,
                                                 Settings().max_batch_points)

            document = _by_line(batch, points, args.csv)
    warnings = slip_warnings({**inputs, **(points.inputs if points is not None else {})}, args.inputs)
    say_warnings(document.get("domain_warnings") or [])
    if points is None:
        if outputs:
            document = {k: v for k, v in document.items() if k not in physics.OUTPUTS or k in outputs}
        if warnings:
            document["input_warnings"] = warnings
        write_text(args.output, to_json(with_folding_safe_names(document)) + "\n")
        return EXIT_OK
    import numpy as np

    answers = {name: value for name, value in document.items()
               if isinstance(value, np.ndarray) and value.shape == (points.count,)}
    write_text(args.output, csv_text({**points.inputs_as_sent(), **points.conditions,
                                      **_broadcast({**inputs, **conditions}, points.count), **answers}))
    return EXIT_OK


def sweep(args: argparse.Namespace) -> int:
    """``microbearing sweep``: a grid or design of experiments, as POST /v1/sweeps."""
    from .schemas.sweeps import SweepRequest
    from .settings import Settings
    from .store import to_json
    from .sweeps import design_columns, run_sweep
    from .tables import csv_text, sweep_table

    request = read_request(args.request, SweepRequest)
    plan = design_columns(request, Settings().max_sweep_points)
    with progress_bar(f"sweep of {plan.count} points") as progress:
        document = run_sweep(request, plan, progress=progress)
    say_warnings(document.get("input_warnings", []))
    as_csv = args.format == "csv" or (args.format is None and str(args.output or "").endswith(".csv"))
    write_text(args.output, csv_text(sweep_table(document)) if as_csv else to_json(document) + "\n")
    return EXIT_OK


def optimize(args: argparse.Namespace) -> int:
    """``microbearing optimize``: the least-friction design, as POST /v1/optimizations; ``--model`` names
    the stored model the request's ``model`` would."""
    from .optimizations import pareto_png, prepare, run
    from .schemas.optimizations import OptimizationRequest
    from .store import to_json

    store, overrides = None, None
    try:
        if args.model is not None and args.model != "physics":
            store = open_store(args)
            overrides = {"model": model_reference(store, args.model, ("calibrated", "surrogate"),
                                                  data_dir(args))}
        request = read_request(args.request, OptimizationRequest, overrides or (
            {"model": "physics"} if args.model == "physics" else None))
        if args.plot and request.pareto is None:
            raise CommandError("--plot draws a Pareto front: add \"pareto\" to the request", EXIT_INVALID)
        # Calibrated and surrogate models are read from the server's data folder.
        if store is None and request.model != "physics":
            store = open_store(args)
        plan = prepare(store, request)
        with progress_bar("optimize") as progress:
            document = run(plan, progress=progress)
    finally:
        if store is not None:
            store.close()
    say_warnings(document.get("input_warnings", []))
    write_text(args.output, to_json(document) + "\n")
    if args.plot:
        write_png(args.plot, pareto_png(document))
    return EXIT_OK


def experiments(args: argparse.Namespace) -> int:
    """``microbearing experiments``: a first design on the physics, or the next runs for a stored
    calibration (``--model``), as POST /v1/experiments and /v1/calibrations/{id}/next-experiments."""
    from types import SimpleNamespace

    from .experiments import first_experiments_job, next_experiments_job, plan_png
    from .schemas.experiments import FirstExperimentsRequest, NextExperimentsRequest
    from .store import to_json

    request = read_request(args.request, NextExperimentsRequest if args.model else FirstExperimentsRequest)
    # A calibration is read from the server's data folder, as optimize reads calibrated models.
    store = open_store(args) if args.model else None
    try:
        if store is not None:
            reference = model_reference(store, args.model, ("calibrated",), data_dir(args))
            work = next_experiments_job(store, reference.removeprefix("calibrated:"), request)
        else:
            work = first_experiments_job(request)
        with progress_bar("experiments") as progress:
            document = work(SimpleNamespace(progress=progress, job_id=None))
    finally:
        if store is not None:
            store.close()
    write_text(args.output, to_json(document) + "\n")
    if args.plot:
        write_png(args.plot, plan_png(document))
    return EXIT_OK


def _json_command(sub: Any, name: str, func: Any, *, help: str, description: str,
                  examples: list[str]) -> argparse.ArgumentParser:
    """A subcommand reading a JSON request file and writing its result, with examples in its help."""
    command = add_command(sub, name, func, help=help, description=description, examples=examples)
    command.add_argument("request", help="JSON request file ('-': stdin)")
    command.add_argument("-o", "--output", metavar="FILE", help="write here instead of stdout")
    return command


def _dialect_options(command: argparse.ArgumentParser) -> None:
    """``--separator`` and ``--decimal`` of a CSV file (detected when not given)."""
    command.add_argument("--separator", choices=["comma", "semicolon", "tab"],
                         help="column separator of --csv (default: detected)")
    command.add_argument("--decimal", choices=["point", "comma"], help="decimal mark of --csv (default: "
                                                                      "detected)")


def add_evaluate(sub: Any, conventions: list[str]) -> None:
    e = add_command(
        sub, "evaluate", evaluate,
        help="friction of one design point, or of every row of a CSV file (to CSV); a stored calibration's "
             "with its interval (--model)",
        description="Evaluate the friction model. With NAME=VALUE inputs only: one point, printed as the "
                    "JSON of POST /v1/friction. With --csv: every row of the file (a header of input names, "
                    "read as calibrate reads a spreadsheet: comma, semicolon or tab, decimal comma, units "
                    "such as 'speed [mm/s]'), written as CSV with the inputs then the outputs; NAME=VALUE "
                    "inputs apply to every row. With --model ID (the id calibrate printed): the stored "
                    "calibration's mu with its 95 % interval (mu_lower, mu_upper) and whether the point "
                    "lies in its data's domain; conditions its terms read are NAME=VALUE too (e.g. "
                    "relative_humidity=0.5) or columns of the file. Inputs beyond what a micro bearing "
                    "sees (speed_m_s above 10, load_N above 1) are answered with the API's unit-slip "
                    "warning.",
        examples=["microbearing evaluate balls=4 load_N=0.008826 speed_m_s=0.05 mu_pivot=1",
                  "microbearing evaluate balls=4 \"load [mN]=8.8\" \"speed [mm/s]=50\" --outputs mu",
                  "microbearing evaluate --csv points.csv balls=4 --outputs mu -o friction.csv",
                  "microbearing evaluate --model <id> balls=4 load_N=0.0088 speed_m_s=0.05 "
                  "relative_humidity=0.5",
                  "microbearing evaluate --model <id> --csv runs.csv -o predicted.csv  # with the interval"])
    e.add_argument("inputs", nargs="*", metavar="NAME=VALUE", help="physics inputs in their units (and, with "
                   "--model, conditions)")
    e.add_argument("--csv", metavar="FILE", help="CSV of points, one column per input ('-': stdin)")
    _dialect_options(e)
    e.add_argument("--outputs", metavar="NAME,...", help="outputs to give (default: all)")
    e.add_argument("--model", metavar="ID", help="a stored calibration: the id calibrate printed, or "
                                                 "calibrated:<id>")
    e.add_argument("--convention", choices=conventions, default=None,
                   help="reading of the paper's ball-ball terms (default: olaru2005; a stored model's own)")
    e.add_argument("-o", "--output", metavar="FILE", help="write here instead of stdout")
    data_dir_option(e)


def add_json_commands(sub: Any) -> None:
    """``sweep``, ``optimize`` and ``experiments``: a JSON request file in the schema of their route."""
    w = _json_command(
        sub, "sweep", sweep, help="a grid or design of experiments from a JSON request (as POST /v1/sweeps)",
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
        sub, "optimize", optimize,
        help="the least-friction design from a JSON request (as POST /v1/optimizations), on the physics or "
             "a stored model (--model)",
        description="Solve the design problem of a JSON file in the schema of POST /v1/optimizations and "
                    "write the result as JSON (the schema OptimizationResult). A robust design is a request "
                    "with ranges: speed_m_s [low, high], conditions {name: [low, high]}, tolerances; "
                    "objective mu_upper bounds the 95 % upper end of a stored model's mu. --model ID (the id "
                    "calibrate or surrogate train printed) sets the request's model. Exit code 3 when no "
                    "design meets the limits (the message names the conflicting ones).",
        examples=['echo \'{"bounds": {"balls": [4, 24], "groove_angle_deg": [35, 70], '
                  '"load_N": [0.001, 0.05]},',
                  '      "fixed": {"speed_m_s": 0.05}, "constraints": {"max_contact_pressure_Pa": 1e9}}\' '
                  "> problem.json",
                  "microbearing optimize problem.json -o best.json",
                  'echo \'{"objective": "mu_upper", "speed_m_s": [0.01, 0.1], "bounds": {"balls": [4, 8],',
                  '      "groove_angle_deg": [45, 60], "load_N": [0.0044, 0.0132]},',
                  '      "conditions": {"relative_humidity": [0.3, 0.7]}}\' > robust.json',
                  "microbearing optimize robust.json --model <id> -o robust-design.json",
                  'microbearing optimize front.json --plot front.png   # a request with "pareto"'])
    o.add_argument("--model", metavar="ID", help="the stored model to optimize: the id calibrate or "
                                                 "surrogate train printed (or calibrated:<id>, "
                                                 "surrogate:<id>, physics); replaces the request's model")
    o.add_argument("--plot", metavar="FILE.png", help="draw the Pareto front (requests with \"pareto\")")
    data_dir_option(o)

    x = _json_command(
        sub, "experiments", experiments,
        help="which measurements to take next, with an optimality bound (as POST /v1/experiments, or "
             "/v1/calibrations/{id}/next-experiments with --model)",
        description="Propose runs from a JSON request and write the result as JSON (the schema "
                    "ExperimentsResult). Without --model: a first design on the declared physics "
                    "(the schema FirstExperimentsRequest); with it: the next runs for a calibration stored "
                    "in the data folder (NextExperimentsRequest; goal discriminate, parameters or "
                    "predict).",
        examples=['echo \'{"runs": 12, "goal": "discriminate", "space": {"balls": {"low": 4, "high": 8},',
                  '      "load_N": {"low": 0.003, "high": 0.03, "spacing": "log"}, "speed_m_s": [0.05],',
                  '      "relative_humidity": {"low": 0.2, "high": 0.9}}}\' > next.json',
                  "microbearing experiments next.json --model <id> -o runs.json --plot runs.png",
                  'echo \'{"runs": 8, "fit_parameters": ["mu_pivot"], "space": {"balls": {"values": [4, 8]},',
                  '      "load_N": {"low": 0.001, "high": 0.03}, "speed_m_s": [0.05]}}\' > first.json',
                  "microbearing experiments first.json -o first-runs.json"])
    x.add_argument("--model", "--calibration", dest="model", metavar="ID",
                   help="a stored calibration: the id calibrate printed, or calibrated:<id>")
    x.add_argument("--plot", metavar="FILE.png", help="draw the runs over the data taken (and the rivals)")
    data_dir_option(x)
