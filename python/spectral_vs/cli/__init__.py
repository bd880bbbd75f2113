"""The ``spectral-vs`` command line: ``align``, ``align-views``, ``demo``, ``translate`` and
``servo-sim``, one module per subcommand (each adds its parser and runs it)."""

from __future__ import annotations

import argparse
import sys

import spectral_vs as svs
from spectral_vs.cli import align, demo, servo_sim, translate, views
from spectral_vs.cli.common import InputError, _strip_argument

SUBCOMMANDS = (align, views, demo, translate, servo_sim)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="spectral-vs",
        description="Correspondence-free point cloud registration in the spectral domain.",
    )
    parser.add_argument("--version", action="version", version=f"spectral_vs {svs.__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for subcommand in SUBCOMMANDS:
        subcommand.add_parser(commands, argparse.RawDescriptionHelpFormatter)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except InputError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    except (ValueError, OSError) as error:
        print(f"error: {_strip_argument(str(error))}", file=sys.stderr)
        return 2
