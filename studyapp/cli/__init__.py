"""The ``studyapp`` command line.

Each area registers its own sub-commands (``register(subparsers)`` in ``<area>/cli.py``) so this file
stays a dispatcher and the areas stay independent.
"""
from __future__ import annotations

import argparse
import importlib
import logging
import sys

from studyapp import __version__
from studyapp.errors import StudyappError

_COMMAND_MODULES = (
    "studyapp.motion.cli",   # inspect, convert
    "studyapp.render.cli",   # render, view
    "studyapp.study.design_cli",   # validate, schedule
    "studyapp.study.session_cli",  # run, export, bundle, merge
    "studyapp.models.cli",   # generate
    "studyapp.ui.cli",       # doctor
    "studyapp.demo_cli",     # demo
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="studyapp",
        description="Run side-by-side user studies of gesture-generation models.",
    )
    parser.add_argument("--version", action="version", version=f"studyapp {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="print debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in _COMMAND_MODULES:
        importlib.import_module(name).register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format="%(levelname)s: %(message)s",
    )
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    try:
        return int(args.func(args) or 0)
    except StudyappError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `studyapp inspect --json | head`: the reader left, nothing to report
        sys.stderr.close()
        return 0
    except OSError as exc:
        # a path the user gave cannot be read or written (missing folder, permissions, full disk)
        where = exc.filename or ""
        print(f"error: {where}{': ' if where else ''}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
