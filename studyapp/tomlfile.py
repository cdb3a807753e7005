"""TOML in and out, in one place: the standard library's reader (``tomli`` on Python 3.10) and ``tomli_w``.

:func:`loads` refuses arrays and inline tables nested more than :data:`MAX_DEPTH` deep before the reader
sees them (the reader recurses once per level, so 100,000 ``[`` would end in a ``RecursionError``); the
refusal is a :class:`TOMLDecodeError` that names the line and column like the reader's own errors.

>>> loads(dumps({"title": "T", "conditions": [{"id": "a", "fps": 15.0}]}))["conditions"][0]["fps"]
15.0
>>> loads("x = " + "[" * 100 + "]" * 100)
Traceback (most recent call last):
...
tomllib.TOMLDecodeError: arrays and inline tables nest more than 32 deep (at line 1, column 37)
"""
from __future__ import annotations

import re
import sys

import tomli_w

if sys.version_info >= (3, 11):
    import tomllib as _reader
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as _reader

TOMLDecodeError = _reader.TOMLDecodeError
dumps = tomli_w.dumps

#: Deepest nesting of arrays / inline tables read (study designs nest 2 deep).
MAX_DEPTH = 32

#: Largest TOML text read (characters): a study design with thousands of stimuli is a few hundred kB.
MAX_CHARS = 4 << 20

# what cannot hold a structural bracket: strings (multi-line first) and comments. Written as unrolled
# loops (runs of plain characters matched at once), not a lazy per-character alternation, whose
# backtracking state grows with the string (a 10 MB line took 1.5 GB).
_OPAQUE = re.compile(r'"""[^"\\]*(?:(?:\\.|"(?!""))[^"\\]*)*"""|\'\'\'[^\']*(?:\'(?!\'\')[^\']*)*\'\'\''
                     r'|"[^"\\\n]*(?:\\.[^"\\\n]*)*"|\'[^\'\n]*\'|#[^\n]*', re.S)


def _too_deep(text: str) -> int | None:
    """Offset of the first bracket nested deeper than :data:`MAX_DEPTH`, or ``None``."""
    if text.count("[") + text.count("{") <= MAX_DEPTH:
        return None
    depth = 0
    last = 0
    for m in _OPAQUE.finditer(text):
        at = _scan(text, last, m.start(), depth)
        if isinstance(at, tuple):
            return at[0]
        depth, last = at, m.end()
    at = _scan(text, last, len(text), depth)
    return at[0] if isinstance(at, tuple) else None


def _scan(text: str, start: int, stop: int, depth: int) -> int | tuple[int]:
    """Depth after ``text[start:stop]``, or ``(offset,)`` where it first passes the limit."""
    for m in re.finditer(r"[\[\]{}]", text[start:stop]):
        depth += 1 if m.group() in "[{" else -1
        if depth > MAX_DEPTH:
            return (start + m.start(),)
    return depth


def loads(text: str) -> dict:
    """The TOML document in ``text`` (see the module docstring for the nesting limit)."""
    if len(text) > MAX_CHARS:
        raise TOMLDecodeError(f"the file holds {len(text):,} characters; a TOML file read here has at most "
                              f"{MAX_CHARS:,}")
    at = _too_deep(text)
    if at is not None:
        line = text.count("\n", 0, at) + 1
        col = at - (text.rfind("\n", 0, at) + 1) + 1
        raise TOMLDecodeError(f"arrays and inline tables nest more than {MAX_DEPTH} deep (at line {line}, column {col})")
    return _reader.loads(text)


__all__ = ["loads", "dumps", "TOMLDecodeError", "MAX_DEPTH", "MAX_CHARS"]
