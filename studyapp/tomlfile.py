"""TOML in and out, in one place: the standard library's reader (``tomli`` on Python 3.10) and ``tomli_w``.

>>> loads(dumps({"title": "T", "conditions": [{"id": "a", "fps": 15.0}]}))["conditions"][0]["fps"]
15.0
"""
from __future__ import annotations

import sys

import tomli_w

if sys.version_info >= (3, 11):
    import tomllib as _reader
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as _reader

TOMLDecodeError = _reader.TOMLDecodeError
loads = _reader.loads
dumps = tomli_w.dumps

__all__ = ["loads", "dumps", "TOMLDecodeError"]
