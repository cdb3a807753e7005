"""The ``studyapp`` command line: the application shell, on top of every domain package.

Each command module here registers its own sub-commands (``register(subparsers)``) and this file stays a
dispatcher. The shell imports the domain packages (``motion``, ``render``, ``study``, ``ui``, ...); none of
them imports the shell, so they form a one-way stack (``tests/test_architecture.py`` checks it).
"""
from __future__ import annotations

import argparse
import logging
import sys
import warnings
from pathlib import Path

from studyapp import __version__
from studyapp.cli import demo, design, doctor, models, motion, planning, prerender, render, serve, session
from studyapp.cli.extras import missing_extra_line
from studyapp.errors import StudyappError

_COMMAND_MODULES = (
    motion,    # inspect, convert
    render,    # render, view
    prerender, # prerender
    design,    # validate, schedule
    session,   # run, export, bundle, key, merge
    models,    # generate
    doctor,    # doctor
    demo,      # demo
    planning,  # metrics, plan
    serve,     # serve (the browser study server)
)


_PACKAGE = str(Path(__file__).resolve().parents[1])
_python_format = warnings.formatwarning


def _format_warning(message, category, filename, lineno, line=None) -> str:
    """studyapp's own warnings (a design's notes, a reader's workaround) as one line, as ``validate`` prints
    them: the experimenter reads them, so Python's ``file:line: Category`` and the source line under it would
    only hide the message. Warnings of other packages keep Python's format."""
    if str(filename).startswith(_PACKAGE):
        return f"note: {message}\n"
    return _python_format(message, category, filename, lineno, line)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="studyapp",
        description="Run side-by-side user studies of gesture-generation models.",
    )
    parser.add_argument("--version", action="version", version=f"studyapp {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="print debug messages")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in _COMMAND_MODULES:
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    warnings.formatwarning = _format_warning
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
    except ModuleNotFoundError as exc:
        # a participant's install reaching an experimenter's command: say which extra to install
        line = missing_extra_line(exc, args.command)
        if line is None:
            raise
        print(f"error: {line}", file=sys.stderr)
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
