"""The stored-model commands of ``microbearing``: ``calibrate`` (stores its model, as POST /v1/calibrations
does), ``calibrations list|delete`` and ``surrogate train|predict|list|delete``.

Every command here reads or writes the store of the data folder (``--data-dir``, else
``$MICROBEARING_DATA_DIR``, else the user data folder; the server's PostgreSQL database with
MICROBEARING_DATABASE_URL): the one the service uses, through its own functions
(:func:`service.calibrations.store_calibration`, :meth:`service.store.Store.delete_model`), so that what
the command line stores the API serves and what it deletes is gone for both.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from contextlib import closing
from pathlib import Path
from typing import Any

from .cli_common import (
    EXIT_INVALID,
    EXIT_OK,
    CommandError,
    add_command,
    columns_of,
    data_dir,
    data_dir_option,
    model_reference,
    open_store,
    progress_bar,
    read_bytes,
    read_request,
    say_warnings,
    write_text,
)

__all__ = ["add_calibrate", "add_calibrations", "add_surrogate"]

#: Problems of a data file listed in the one-line error (the rest counted).
_LISTED_PROBLEMS = 5


def _data_error(path: str, exc: Any) -> CommandError:
    """A :class:`calibrate.DataError` as one line naming the first problems (row and column)."""
    from microbearing.calibrate import DataError

    listed = [DataError.describe(e) for e in exc.errors[:_LISTED_PROBLEMS]]
    more = len(exc.errors) - len(listed)
    tail = f"; ... and {more} more" if more > 0 else ""
    return CommandError(f"{path}: {'; '.join(listed)}{tail}", EXIT_INVALID)


def calibrate_command(args: argparse.Namespace) -> int:
    """``microbearing calibrate``: fit, report and store the calibrated model (its id printed)."""
    from microbearing.calibrate import DataError, calibrate, parse_assignments, read_csv

    text = read_bytes(args.data)
    fit = [name.strip() for name in (args.fit or "").split(",") if name.strip()]
    factors = [name.strip() for name in (args.factors or "").split(",") if name.strip()]
    try:
        dataset, intake = read_csv(text, parse_assignments(args.fixed), args.separator, args.decimal, factors)
    except DataError as exc:
        raise _data_error(args.data, exc) from None
    print(f"{args.data}: {intake.summary()}", file=sys.stderr)
    # Opened (and its room checked) before the fit, so that a folder that cannot hold it fails now.
    store = None if args.no_store else open_store(args, write=True)
    try:
        if store is not None:
            store.check_model_room()
        try:
            with progress_bar("calibrate") as progress:
                # folds None: the library's default (calibrate.default_folds), as at the API's doors
                report = calibrate(dataset, fit, folds=args.folds, convention=args.convention,
                                   progress=progress)
        except DataError as exc:
            raise _data_error(args.data, exc) from None
        except ValueError as exc:
            raise CommandError(str(exc), EXIT_INVALID) from None
        stored = None
        if store is not None:
            from .calibrations import store_calibration

            stored = store_calibration(store, report, dataset, intake.to_dict())
    finally:
        if store is not None:
            store.close()
    _write_report(args, report, intake, stored)
    return EXIT_OK


def _write_report(args: argparse.Namespace, report: Any, intake: Any, stored: dict[str, Any] | None) -> None:
    """The report (unless --quiet), plots, JSON, and the stored calibration's id."""
    if not args.quiet:
        print(report.text())
    if args.plots:
        folder = Path(args.plots)
        folder.mkdir(parents=True, exist_ok=True)
        for name, png in report.plots.items():
            (folder / f"{name}.png").write_bytes(png)
            print(f"wrote {folder / f'{name}.png'}", file=sys.stderr if args.quiet else sys.stdout)
    if args.json:
        document = {**report.to_dict(), "intake": intake.to_dict()}
        if stored is not None:
            document = {"id": stored["id"], "model_id": stored["model_id"], **document}
        write_text(args.json, json.dumps(document, indent=1))
        print(f"wrote {args.json}", file=sys.stderr if args.quiet else sys.stdout)
    if stored is None:
        return
    if args.quiet:
        print(stored["id"])
        return
    print(f"stored calibration {stored['id']} in {data_dir(args)}: use it as --model {stored['id']} "
          f"(the API's model {stored['model_id']})")


def calibrations_list(args: argparse.Namespace) -> int:
    """``microbearing calibrations list``: the stored calibrations, newest first."""
    from .calibrations import KIND, calibration_summary
    from .store import to_json

    with closing(open_store(args)) as store:
        summaries = [calibration_summary(row) for row in store.list_models(KIND)]
    if args.json:
        write_text(args.output, to_json({"calibrations": summaries}) + "\n")
        return EXIT_OK
    lines = [f"{len(summaries)} calibration(s) in {data_dir(args)}"]
    for s in summaries:
        effects = ", ".join(s["effects"]) or "no effect"
        lines.append(f"{s['id']}  {s['created_at']}  {s['n_points']} points  fitted "
                     f"{', '.join(s['fit_parameters']) or 'nothing'}  {effects}  relative error "
                     f"{s['error_before']['relative_rmse']:.3g} -> {s['error_after']['relative_rmse']:.3g}")
    write_text(args.output, "\n".join(lines) + "\n")
    return EXIT_OK


def calibrations_delete(args: argparse.Namespace) -> int:
    """``microbearing calibrations delete ID``: the calibration, and its data in every finished job."""
    from .calibrations import delete_calibration

    return _delete(args, "calibrated", "calibration", delete_calibration)


def surrogate_train(args: argparse.Namespace) -> int:
    from .schemas.surrogates import SurrogateRequest
    from .store import to_json
    from .surrogates import prepare_training, train_surrogate

    request = read_request(args.request, SurrogateRequest)
    with closing(open_store(args, write=request.model == "physics")) as store:
        space, mu_model = prepare_training(store, request)
        with progress_bar(f"train a surrogate on up to {request.budget} evaluations") as progress:
            document = train_surrogate(store, space, request, progress=progress, mu_model=mu_model)
    say_warnings(document.get("warnings", []))
    write_text(args.output, to_json(document) + "\n")
    print(f"stored {document['model_id']} in {data_dir(args)}", file=sys.stderr)
    return EXIT_OK


def surrogate_predict(args: argparse.Namespace) -> int:
    from .store import to_json
    from .surrogates import predict

    points = columns_of(args.inputs)
    with closing(open_store(args)) as store:
        document = predict(store, args.id.removeprefix("surrogate:"), points)
    say_warnings(document.get("warnings"))
    write_text(args.output, to_json(document) + "\n")
    return EXIT_OK


def surrogate_list(args: argparse.Namespace) -> int:
    from .store import to_json
    from .surrogates import surrogate_views

    with closing(open_store(args)) as store:
        views = surrogate_views(store)
    if args.json:
        write_text(args.output, to_json({"surrogates": views}) + "\n")
        return EXIT_OK
    lines = [f"{len(views)} surrogate(s) in {data_dir(args)}"]
    for view in views:
        space = ", ".join(f"{name} [{_shown(name, low)}, {_shown(name, high)}]"
                          for name, (low, high) in view["space"].items())
        learned = "" if view["model"] == "physics" else f"  of {view['model']}" + "".join(
            f", {key} {value}" for key, value in (view.get("conditions") or {}).items())
        lines.append(f"{view['model_id']}  {view['created_at']}  {view['n_train']} evaluations  {space}"
                     f"{learned}")
    write_text(args.output, "\n".join(lines) + "\n")
    return EXIT_OK


def _shown(name: str, value: Any) -> str:
    """A space's end as the API shows it (true/false for a boolean input).

    >>> _shown("balls_touching", 1.0), _shown("load_N", 0.002)
    ('true', '0.002')
    """
    from microbearing import physics

    return str(bool(value)).lower() if physics.PARAMETERS[name].kind == "bool" else f"{value:g}"


def surrogate_delete(args: argparse.Namespace) -> int:
    """``microbearing surrogate delete ID``: the surrogate, and its data in every finished job."""
    from .surrogates import delete_stored

    return _delete(args, "surrogate", "surrogate", delete_stored)


def _delete(args: argparse.Namespace, kind: str, label: str, delete: Callable[[Any, str], Any]) -> int:
    """Delete the model ``args.id`` of ``kind`` (``calibrated`` or ``surrogate``) from the store with
    ``delete`` (which also erases its data from finished jobs) and say so."""
    with closing(open_store(args)) as store:
        model_id = model_reference(store, args.id, (kind,), data_dir(args), "id").removeprefix(f"{kind}:")
        delete(store, model_id)
    print(f"deleted {label} {model_id} from {data_dir(args)}")
    return EXIT_OK


def add_calibrate(sub: Any) -> None:
    from microbearing import physics

    c = add_command(
        sub, "calibrate", calibrate_command,
        help="calibrate the model on measured CSV data, name the missing effect, store the model",
        description="Fit the declared parameters on log mu, search the residual for a missing effect, and "
                    "report the held-out error before and after. The CSV may be a spreadsheet export "
                    "(comma, semicolon or tab; decimal comma; units in the header such as 'speed [mm/s]', "
                    "converted to SI); how it was read is printed on stderr. The calibrated model is stored "
                    "in the data folder (as POST /v1/calibrations stores it; --no-store not to) and its id "
                    "printed last: evaluate, optimize and experiments take it as --model ID.",
        examples=["microbearing calibrate measured.csv --fit mu_pivot --plots plots/",
                  "microbearing calibrate export.csv --fixed balls=4 --fit mu_pivot,adhesion_energy_J_m2",
                  "microbearing calibrate export.csv --separator semicolon --decimal comma --json out.json",
                  "ID=$(microbearing calibrate lab.csv --fit mu_pivot --quiet --data-dir ./data)",
                  "microbearing calibrate lab.csv --fit mu_pivot --no-store   # report only"])
    c.add_argument("data", help="CSV with physics input columns, mu_measured, optionally mu_measured_std, "
                                "and any condition columns")
    c.add_argument("--separator", choices=["comma", "semicolon", "tab"], help="column separator (default: "
                                                                            "detected)")
    c.add_argument("--decimal", choices=["point", "comma"], help="decimal mark (default: detected)")
    c.add_argument("--fit", metavar="NAME,...", help="declared parameters to fit, e.g. mu_pivot,mu_ball")
    c.add_argument("--fixed", metavar="NAME=VALUE", nargs="+", action="extend", default=[],
                   help="physics inputs fixed for every row, in their units (e.g. balls=4)")
    c.add_argument("--folds", type=int, default=None,
                   help="cross-validation folds (default: 5, or half the rows when there are fewer than 10)")
    c.add_argument("--factors", metavar="NAME,...",
                   help="condition columns of integer codes to read as group labels (a column of text labels "
                        "is one anyway)")
    c.add_argument("--convention", choices=list(physics.CONVENTIONS), default=physics.DEFAULT_CONVENTION,
                   help="reading of the paper's ball-ball terms (default: %(default)s)")
    c.add_argument("--plots", metavar="DIR", help="write the residual plots (PNG) into DIR")
    c.add_argument("--json", metavar="FILE", help="write the full report, with the calibrated model, as JSON")
    c.add_argument("--no-store", action="store_true", help="do not store the calibrated model")
    c.add_argument("-q", "--quiet", action="store_true", help="print only the stored model's id on stdout")
    data_dir_option(c)


def add_calibrations(sub: Any) -> None:
    g = add_command(
        sub, "calibrations", None, help="list or delete the stored calibrations (as /v1/calibrations)",
        description="The calibrations stored in the data folder (by calibrate or POST /v1/calibrations): "
                    "list them, or delete one with its data (the jobs that made or used it keep their status "
                    "and lose their request and result).",
        examples=["microbearing calibrations list --data-dir ./data",
                  "microbearing calibrations delete <id> --data-dir ./data"])
    actions = g.add_subparsers(dest="action", required=True)
    li = add_command(actions, "list", calibrations_list, help="list the stored calibrations",
                     description="List the calibrations of the data folder, newest first: id, date, rows, "
                                 "fitted parameters, effects found, held-out relative error before -> after.",
                     examples=["microbearing calibrations list",
                               "microbearing calibrations list --json -o calibrations.json"])
    li.add_argument("--json", action="store_true", help="the summaries as JSON (GET /v1/calibrations)")
    li.add_argument("-o", "--output", metavar="FILE", help="write here instead of stdout")
    data_dir_option(li)
    de = add_command(actions, "delete", calibrations_delete, help="delete a stored calibration and its data",
                     description="Delete a calibration (report, model, plots, data) as DELETE "
                                 "/v1/calibrations/{id} does; the finished jobs naming it lose their request "
                                 "and result.",
                     examples=["microbearing calibrations delete 0123456789abcdef0123456789abcdef",
                               "microbearing calibrations delete calibrated:<id> --data-dir ./data"])
    de.add_argument("id", help="the calibration: <id> or calibrated:<id>")
    data_dir_option(de)


def add_surrogate(sub: Any) -> None:
    g = add_command(
        sub, "surrogate", None, help="train, query, list and delete Gaussian-process surrogates (as "
                                     "/v1/surrogates)",
        description="Surrogates stored in the server's data folder: train one from a JSON request (the "
                    "schema of POST /v1/surrogates), predict with it, list them, delete one.",
        examples=["microbearing surrogate train request.json -o surrogate.json",
                  "microbearing surrogate predict surrogate:<id> load_N=0.002,0.02 speed_m_s=0.05",
                  "microbearing surrogate list --data-dir ./data",
                  "microbearing surrogate delete <id>"])
    actions = g.add_subparsers(dest="action", required=True)
    t = add_command(
        actions, "train", surrogate_train, help="train a surrogate and store it (prints its JSON)",
        description="Train the surrogate described by a JSON file in the schema of POST /v1/surrogates and "
                    "store it in the data folder; write its description (the schema SurrogateResult).",
        examples=['echo \'{"space": {"load_N": [0.001, 0.05], "speed_m_s": [0.001, 0.2]}, '
                  '"fixed": {"balls": 4}, "budget": 30}\' > request.json',
                  "microbearing surrogate train request.json -o surrogate.json"])
    t.add_argument("request", help="JSON request file ('-': stdin)")
    t.add_argument("-o", "--output", metavar="FILE", help="write here instead of stdout")
    data_dir_option(t)
    r = add_command(actions, "predict", surrogate_predict,
                    help="predict mu with its 95 %% interval at points",
                    description="Predict mu, its 95 % interval and whether each point lies inside the "
                                "trained space (the answer of POST /v1/surrogates/{id}/predict).",
                    examples=["microbearing surrogate predict surrogate:<id> load_N=0.002,0.02 "
                              "speed_m_s=0.05",
                              "microbearing surrogate predict <id> load_N=0.01 speed_m_s=0.1 -o mu.json"])
    r.add_argument("id", help="the surrogate: surrogate:<id> or <id>")
    r.add_argument("inputs", nargs="+", metavar="NAME=VALUE[,VALUE...]",
                   help="every dimension of the surrogate, in its unit; one value broadcasts")
    r.add_argument("-o", "--output", metavar="FILE", help="write here instead of stdout")
    data_dir_option(r)
    li = add_command(actions, "list", surrogate_list, help="list the stored surrogates",
                     description="List the surrogates of the data folder, newest first.",
                     examples=["microbearing surrogate list",
                               "microbearing surrogate list --json -o surrogates.json"])
    li.add_argument("--json", action="store_true", help="the full descriptions as JSON (GET /v1/surrogates)")
    li.add_argument("-o", "--output", metavar="FILE", help="write here instead of stdout")
    data_dir_option(li)
    de = add_command(actions, "delete", surrogate_delete, help="delete a stored surrogate",
                     description="Delete a surrogate as DELETE /v1/surrogates/{id} does; the finished jobs "
                                 "naming it lose their request and result.",
                     examples=["microbearing surrogate delete surrogate:<id>",
                               "microbearing surrogate delete <id> --data-dir ./data"])
    de.add_argument("id", help="the surrogate: <id> or surrogate:<id>")
    data_dir_option(de)
