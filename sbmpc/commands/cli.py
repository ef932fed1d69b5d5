"""The ``sbmpc`` command line. Exit codes: 0 success, 1 negative answer, 2 bad input."""
from __future__ import annotations

import argparse
import sys

from ..errors import InputError, NoResult


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line and exit code 2."""

    def error(self, message):  # noqa: D401
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="sbmpc", description="Motion planning for skid-steered robots with the "
                "closed-loop dynamic model of Yu et al. (2010).")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)
    from . import diagnose, plan, run, simulate
    simulate.add_parser(sub)
    plan.add_parsers(sub)
    diagnose.add_parsers(sub)
    run.add_parsers(sub)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"sbmpc {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except NoResult as exc:
        print(f"sbmpc {args.command}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"sbmpc {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
