"""The ``microbearing`` command line."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from .settings import ENV_PREFIX


def _paper(args: argparse.Namespace) -> int:
    from physics import paper

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
    from .observability import uvicorn_log_config

    # Requests are logged as JSON lines with their request id by service/observability.py;
    # uvicorn's own lines (startup, shutdown, errors) are JSON too.
    uvicorn.run("service.app:app", host=args.host, port=args.port, workers=args.workers, access_log=False,
                log_config=uvicorn_log_config())
    return 0


def _calibrate(args: argparse.Namespace) -> int:
    import json

    from calibrate import DataError, calibrate, parse_assignments, parse_csv

    try:
        text = Path(args.data).read_bytes()
    except OSError as exc:
        print(f"microbearing calibrate: cannot read {args.data}: {exc}", file=sys.stderr)
        return 2
    fit = [name.strip() for name in (args.fit or "").split(",") if name.strip()]
    try:
        dataset = parse_csv(text, parse_assignments(args.fixed))
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
        Path(args.json).write_text(json.dumps(report.to_dict(), indent=1))
        print(f"wrote {args.json}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    import physics

    parser = argparse.ArgumentParser(prog="microbearing", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("paper", help="reproduce the numerical cases of Olaru et al. (2005)")
    p.add_argument("--plot", metavar="FILE.png", help="draw mu against speed as the paper's Figs. 5-6")
    p.add_argument("--convention", choices=list(physics.CONVENTIONS), default=physics.DEFAULT_CONVENTION)
    p.set_defaults(func=_paper)

    s = sub.add_parser("serve", help="start the REST service (uvicorn)",
                       description="Start the REST service; settings come from MICROBEARING_* variables.")
    s.add_argument("--host", default="127.0.0.1", help="interface to listen on (default: %(default)s)")
    s.add_argument("--port", type=int, default=8000, help="TCP port (default: %(default)s)")
    s.add_argument("--data-dir", type=Path, default=None,
                   help="SQLite folder (default: $MICROBEARING_DATA_DIR, else the user data dir)")
    s.add_argument("--workers", type=int, default=1, help="server processes (default: 1)")
    s.set_defaults(func=_serve)

    c = sub.add_parser("calibrate", help="calibrate the model on measured CSV data, name the missing effect",
                       description="Fit the declared parameters on log mu, search the residual for a missing "
                                   "effect, and report the held-out error before and after.")
    c.add_argument("data", help="CSV with physics input columns, mu_measured, optionally mu_measured_std, "
                                "and any condition columns")
    c.add_argument("--fit", metavar="NAME,...", help="declared parameters to fit, e.g. mu_pivot,mu_ball")
    c.add_argument("--fixed", metavar="NAME=VALUE", nargs="+", action="extend", default=[],
                   help="physics inputs fixed for every row, in their units (e.g. balls=4)")
    c.add_argument("--folds", type=int, default=5, help="cross-validation folds (default: %(default)s)")
    c.add_argument("--plots", metavar="DIR", help="write the residual plots (PNG) into DIR")
    c.add_argument("--json", metavar="FILE", help="write the full report, with the calibrated model, as JSON")
    c.set_defaults(func=_calibrate)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``microbearing`` console script."""
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
