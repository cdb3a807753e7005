"""Checks shared by every table of a design: types against the declared keys, ids, and where a key sits.

Every problem is collected with the line of its key (tomllib reports no positions), so one run of
``validate`` lists them all.
"""
from __future__ import annotations

import bisect
import difflib
import re
from pathlib import Path
from typing import Any, Sequence

from studyapp.study.design.model import Problem
from studyapp.study.design.schema import ID_RE, TYPE_NAMES, DesignFile, toml_keys

_TOP_KEYS = toml_keys(DesignFile)


class Collector:
    """Gathers problems and points each at the line of its key (tomllib reports no positions)."""

    def __init__(self, path: Path, text: str) -> None:
        self.path = str(path)
        self.lines = text.splitlines()
        self.problems: list[Problem] = []
        self._index: _LineIndex | None = None

    def add(self, key: str, message: str, fix: str = "") -> None:
        self.problems.append(Problem(self.path, key, message, fix, self._line_of(key)))

    def line_of(self, key: str) -> int | None:
        """The line of a dotted key (None when it cannot be placed)."""
        return self._line_of(key)

    def _line_of(self, key: str) -> int | None:
        """Best-effort line number of a dotted key like ``stimuli[2].audio`` or ``slots.labels``."""
        parts = re.findall(r"([A-Za-z0-9_\-]+)(?:\[(\d+)\])?", key)
        if not parts:
            return None
        if self._index is None:  # one pass over the file for all problems (a design may have thousands)
            self._index = _LineIndex(self.lines)
        ix = self._index
        start, end = 0, len(self.lines)
        head, idx = parts[0]
        if idx:  # array of tables: find the idx-th "[[head]]"
            hits = ix.arrays.get(head, [])
            if not hits:  # an inline list (practice = [...]): its element sits on the key's line
                hit = ix.assignments.get(head)
                return None if hit is None else hit + 1
            if len(hits) <= int(idx):
                return None
            start = hits[int(idx)]
            end = _after(ix.array_headers, start, end)
            if len(parts) == 1:
                return start + 1
            rest = parts[1:]
        else:
            hit = ix.tables.get(head)
            if hit is None:
                hit = ix.assignments.get(head)
            if hit is None:  # a problem with a whole array of tables: point at its first block
                first = ix.arrays.get(head)
                return None if not first else first[0] + 1
            if not re.match(r"^\s*\[", self.lines[hit]):
                return hit + 1
            start = hit
            if len(parts) == 1:
                return start + 1
            rest = parts[1:]
            # The table ends at the next header that is not one of its own sub-tables.
            own = re.compile(rf"^\s*\[\s*{re.escape(head)}\.")
            end = next((i for i in ix.headers[bisect.bisect_right(ix.headers, start):]
                        if not own.match(self.lines[i])), end)
        found = start
        for name, _ in rest:  # each deeper part is searched for after the line of the one before
            deeper = re.compile(rf"^\s*\[?\s*[\w.\-\[]*?{re.escape(name)}\s*[=\]]")
            for i in range(found, end):
                if deeper.match(self.lines[i]):
                    found = i
                    break
            else:
                break
        return found + 1


class _LineIndex:
    """Where the headers and keys of a design's text are, found in one pass (0-based line numbers)."""

    def __init__(self, lines: Sequence[str]) -> None:
        self.arrays: dict[str, list[int]] = {}     # "[[name]]" -> its lines, in order
        self.tables: dict[str, int] = {}           # "[name]" -> its first line
        self.assignments: dict[str, int] = {}      # "name = " -> its first line
        self.headers: list[int] = []               # every line starting with "["
        self.array_headers: list[int] = []         # every line starting with "[["
        for i, ln in enumerate(lines):
            if m := _ARRAY_HEADER.match(ln):
                self.arrays.setdefault(m.group(1), []).append(i)
            elif m := _TABLE_HEADER.match(ln):
                self.tables.setdefault(m.group(1), i)
            if m := _ASSIGNMENT.match(ln):
                self.assignments.setdefault(m.group(1), i)
            if _ANY_HEADER.match(ln):
                self.headers.append(i)
                if _ANY_ARRAY.match(ln):
                    self.array_headers.append(i)


_ARRAY_HEADER = re.compile(r"^\s*\[\[\s*([A-Za-z0-9_\-]+)\s*\]\]")
_TABLE_HEADER = re.compile(r"^\s*\[\s*([A-Za-z0-9_\-]+)\s*\]")
_ASSIGNMENT = re.compile(r"^\s*([A-Za-z0-9_\-]+)\s*=")
_ANY_HEADER = re.compile(r"^\s*\[")
_ANY_ARRAY = re.compile(r"^\s*\[\[")


def _after(sorted_lines: list[int], start: int, default: int) -> int:
    """The first of ``sorted_lines`` after ``start``, else ``default``."""
    k = bisect.bisect_right(sorted_lines, start)
    return sorted_lines[k] if k < len(sorted_lines) else default


def did_you_mean(word: str, options: Sequence[str]) -> str:
    close = difflib.get_close_matches(word, list(options), n=1, cutoff=0.6)
    return f"did you mean {close[0]!r}?" if close else f"allowed keys: {', '.join(sorted(options))}"


def check_table(col: Collector, table: Any, cls: type, where: str) -> dict:
    """Type-check one table against the keys its class declares; returns only the well-typed keys."""
    schema = toml_keys(cls)
    if not isinstance(table, dict):
        col.add(where, f"must be a table, got {type(table).__name__}", f"write it as [{where}] with key = value lines")
        return {}
    good: dict = {}
    for key, value in table.items():
        kpath = f"{where}.{key}" if where else key
        if key not in schema:
            if where and key in _TOP_KEYS and not where.startswith(("conditions", "stimuli")):
                # TOML puts every key after a [table] header into that table: a classic slip.
                col.add(kpath, f"unknown key {key!r} in [{where.split('[')[0]}]",
                        f"`{key}` is a top-level key: move it above the first [table] header")
            else:
                col.add(kpath, f"unknown key {key!r}", did_you_mean(key, schema))
            continue
        types, _ = schema[key]
        ok = isinstance(value, types) and not (bool not in types and isinstance(value, bool))
        if not ok:
            want = " or ".join(TYPE_NAMES[t] for t in types)
            col.add(kpath, f"must be {want}, got {type(value).__name__} {value!r}"[:200], f"write {key} as {want}")
            continue
        good[key] = value
    for key, (types, required) in schema.items():
        if required and key not in table:
            fix = f"add [[{key}]] blocks (see study_designs/example_beat.toml)" if types == (list,) else f"add {key} = ..."
            col.add(f"{where}.{key}" if where else key, "is required but missing", fix)
    return good


def check_array(col: Collector, raw: dict, name: str, cls: type) -> list[tuple[int, dict]]:
    items = raw.get(name, [])
    out = []
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            col.add(f"{name}[{i}]", "must be a table", f"write each entry as a [[{name}]] block")
            continue
        out.append((i, check_table(col, item, cls, f"{name}[{i}]")))
    return out


def check_ids(col: Collector, name: str, entries: list[tuple[int, dict]], what: str) -> None:
    seen: dict[str, int] = {}
    for i, e in entries:
        ident = e.get("id")
        if ident is None:
            continue
        if not ID_RE.match(ident):
            col.add(f"{name}[{i}].id", f"{what} id {ident!r} may only hold letters, digits, '_', '-' and '.'",
                    "rename it, e.g. " + repr(re.sub(r"[^A-Za-z0-9_.\-]", "_", ident) or "c1"))
        if ident in seen:
            col.add(f"{name}[{i}].id", f"duplicate {what} id {ident!r} (also {name}[{seen[ident]}])",
                    f"give every {what} its own id")
        else:
            seen[ident] = i
