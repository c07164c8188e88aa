"""The ``microbearing`` command line."""

from __future__ import annotations

import argparse
import sys


def _paper(args: argparse.Namespace) -> int:
    from physics import paper

    print(paper.report(args.convention))
    if args.plot:
        paper.plot(args.plot, args.convention)
        print(f"wrote {args.plot}")
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
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``microbearing`` console script."""
    args = build_parser().parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
