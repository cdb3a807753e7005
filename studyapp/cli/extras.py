"""Which optional extra brings a package, and the one line a command prints when its extra is not installed.

A participant's install (``pip install studyapp``) has what the desktop session, a study bundle and uploads
need; the experimenter's commands need extras (pyproject.toml, README "Dependencies"). A command that reaches
a package of a missing extra ends with one line naming the command, the package and the ``pip install`` that
brings it, never an ImportError traceback: :func:`missing_extra_line` turns the ``ModuleNotFoundError`` into
that line, and the shell (:mod:`studyapp.cli`) prints it. Commands that work for minutes before they reach
the package (``prerender``, ``demo``, ``render`` of an MP4) call :func:`require` first, so they stop at once.
"""
from __future__ import annotations

import importlib.util

from studyapp.errors import InputError

#: Top-level import name -> the extra of pyproject.toml that installs it.
EXTRA_OF: dict[str, str] = {
    "pandas": "analysis",
    "scipy": "analysis",
    "matplotlib": "analysis",
    "onnxruntime": "models",
    "onnx": "models",
    "av": "video",
    "starlette": "server",
    "uvicorn": "server",
    "psycopg": "postgresql",
}


def missing_extra_line(exc: ModuleNotFoundError, command: str | None) -> str | None:
    """The user's line for a package of an extra that is not installed; None when ``exc`` is anything else.

    >>> missing_extra_line(ModuleNotFoundError("No module named 'pandas'", name="pandas"), "export")
    'studyapp export needs pandas, which is not installed: pip install "studyapp[analysis]"'
    >>> missing_extra_line(ModuleNotFoundError("x", name="numpy"), "run") is None
    True
    """
    top = (exc.name or "").partition(".")[0]
    extra = EXTRA_OF.get(top)
    if extra is None:
        return None
    what = f"studyapp {command}" if command else "this command"
    return f'{what} needs {top}, which is not installed: pip install "studyapp[{extra}]"'


def require(command: str, *modules: str, extra: str | None = None) -> None:
    """Stop ``studyapp COMMAND`` before any work when any of ``modules`` (top-level names) is not installed.

    One line names every missing package and one ``pip install`` for all their extras (or for ``extra``, when
    the command's packages come with one extra of their own, as ``serve``'s do). The packages are looked
    up without importing them (importing ``av`` or ``pandas`` costs time the command may not spend until later).
    """
    missing = [m for m in modules if not _installed(m)]
    if not missing:
        return
    extras = ",".join(dict.fromkeys(extra or EXTRA_OF.get(m, m) for m in missing))
    names = ", ".join(missing[:-1]) + (" and " if len(missing) > 1 else "") + missing[-1]
    verb = "are" if len(missing) > 1 else "is"
    # an InputError without file or place: the line is the whole message (as `serve` always said it)
    raise InputError(None, None, f'studyapp {command} needs {names}, which {verb} not installed: '
                     f'pip install "studyapp[{extras}]"')


def _installed(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # a finder that refuses the name (as the tests' participant install does)
        return False
