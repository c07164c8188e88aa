"""The ``microbearing`` command line: evaluate, sweep and optimize from a shell, serve the API,
reproduce the paper, calibrate on measurements (the model stored), plan the next experiments, and train,
query, list and delete stored models.

Stored models (calibrations, surrogates) live in the data folder of the server (``--data-dir``, else
``$MICROBEARING_DATA_DIR``, else the user data folder): ``calibrate`` prints the id of the model it
stores, and ``evaluate``, ``optimize`` and ``experiments`` take it as ``--model ID``. A command that only
reads them never creates that folder or its database.

Exit codes: 0 success; 1 an unexpected failure; 2 invalid arguments or input (the message names the
field); 3 an infeasible design problem (no design meets the limits); 4 a file that cannot be read or
written. Every failure is one line on stderr.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from .cli_common import (
    EXIT_FAILURE,
    EXIT_FILE,
    EXIT_INFEASIBLE,
    EXIT_INVALID,
    EXIT_OK,
    CommandError,
    add_command,
    data_dir,
    problem_error,
)
from .settings import ENV_PREFIX

__all__ = ["EXIT_FAILURE", "EXIT_FILE", "EXIT_INFEASIBLE", "EXIT_INVALID", "EXIT_OK", "CommandError",
           "build_parser", "main"]


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


def _add_paper_and_serve(sub: Any) -> None:
    from microbearing import physics

    p = add_command(sub, "paper", _paper, help="reproduce the numerical cases of Olaru et al. (2005)",
                    description="Print the paper's cases A and B computed beside its published values.",
                    examples=["microbearing paper",
                              "microbearing paper --plot paper.png        # Figs. 5-6 redrawn",
                              "microbearing paper --convention derjaguin"])
    p.add_argument("--plot", metavar="FILE.png", help="draw mu against speed as the paper's Figs. 5-6")
    p.add_argument("--convention", choices=list(physics.CONVENTIONS), default=physics.DEFAULT_CONVENTION)

    s = add_command(sub, "serve", _serve, help="start the REST service (uvicorn)",
                    description="Start the REST service; settings come from MICROBEARING_* variables. "
                                "The start log names the data folder (jobs and stored models).",
                    examples=["microbearing serve                          # http://127.0.0.1:8000/docs",
                              "microbearing serve --data-dir ./data --port 8080",
                              "MICROBEARING_API_KEYS=secret microbearing serve --host 0.0.0.0 --workers 2"])
    s.add_argument("--host", default="127.0.0.1", help="interface to listen on (default: %(default)s)")
    s.add_argument("--port", type=int, default=8000, help="TCP port (default: %(default)s)")
    s.add_argument("--data-dir", type=Path, default=None,
                   help="SQLite folder (default: $MICROBEARING_DATA_DIR, else the user data dir)")
    s.add_argument("--workers", type=int, default=1, help="server processes (default: 1)")


def _package_version() -> str:
    """The installed version, as GET /v1/version says it (read here, not from routes.meta, whose import
    of the API and the calibration would cost every command seconds)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("microbearing")
    except PackageNotFoundError:
        return "0+unknown"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    from microbearing import physics

    from .cli_compute import add_evaluate, add_json_commands
    from .cli_models import add_calibrate, add_calibrations, add_surrogate

    parser = argparse.ArgumentParser(prog="microbearing", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"%(prog)s {_package_version()}")
    sub = parser.add_subparsers(dest="command", required=True)
    add_evaluate(sub, list(physics.CONVENTIONS))
    add_json_commands(sub)
    _add_paper_and_serve(sub)
    add_calibrate(sub)
    add_calibrations(sub)
    add_surrogate(sub)
    return parser


def _command_name(args: argparse.Namespace) -> str:
    """The command as typed, e.g. ``calibrations delete``."""
    action = getattr(args, "action", None)
    return f"{args.command} {action}" if action else args.command


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``microbearing`` console script; returns the exit code.

    A failure is one line on stderr naming the command (no traceback; MICROBEARING_CLI_TRACEBACK=1 shows
    the traceback of an unexpected one).
    """
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except CommandError as error:
        code, message = error.code, str(error)
    except Exception as exc:
        # The API's problems (imported now: a command that raises none need not load FastAPI)
        from .problems import ProblemError

        if isinstance(exc, ProblemError):
            error = problem_error(exc, data_dir(args) if exc.status == 404 else None)
            code, message = error.code, str(error)
        elif os.environ.get(f"{ENV_PREFIX}CLI_TRACEBACK"):
            raise
        else:
            code, message = EXIT_FAILURE, f"unexpected failure: {type(exc).__name__}: {exc}"
    print(f"microbearing {_command_name(args)}: {' '.join(message.split())}", file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
