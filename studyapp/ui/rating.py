"""The participant's 0-100 ratings of k figures, per criterion (pure logic, no drawing).

Used by the ``rating`` paradigm (MUSHRA-style, as HEMVIP v1). Every criterion has one slider per figure; a
slider starts *unset* (no value, no handle position that could be mistaken for an answer) and every slider
must be moved before the answers can be submitted: :meth:`RatingState.missing` names the ones left.
:meth:`RatingState.ratings` gives ``{criterion: {slot: value}}`` for the moved sliders only, which is what
``Session.submit_ratings`` takes (it refuses a missing one). Values are whole numbers 0..100.

Anchors (the block's ``anchors``, e.g. Bad / Poor / Fair / Good / Excellent) divide the scale into equal
intervals, MUSHRA's convention: with n anchors, anchor k labels ``[100 k / n, 100 (k + 1) / n]`` and sits at
that interval's centre (:func:`anchor_centres`).

The value is written beside the slider's handle, never under it (:func:`value_text_x`).

Rows and the keyboard: sliders are rows in reading order (criterion by criterion, each figure left to
right). The highlighted slider takes the keys: Left / Right move it by 1, Page Up / Page Down by 10 (a first
press on an unset slider sets it to 50), the digits jump to :func:`digit_points` (anchor k's centre, or
k x 10 without anchors), Backspace unsets it, Up / Down change slider. Setting a slider moves the highlight on
to the next unset one.

>>> r = RatingState(["realism"], n_slots=2)
>>> r.key_point(digit_points(5)[3])        # key 4 with 5 anchors ("Good"): the centre of 60..80
>>> r.ratings(), r.active
({'realism': {0: 70}}, 1)
>>> r.missing()
[('realism', 1)]
>>> r.key_step(1); r.key_step(1); r.ratings()["realism"]
{0: 70, 1: 51}
>>> r.all_moved()
True
"""
from __future__ import annotations

from dataclasses import dataclass, field

LOW, HIGH = 0, 100


def digit_points(n_anchors: int) -> list[float]:
    """Where the number keys 1, 2, .. put a slider: the anchors' centres, or 10, 20, .. 90 without anchors.

    >>> digit_points(3), digit_points(0)[:3]
    ([16.666666666666668, 50.0, 83.33333333333333], [10.0, 20.0, 30.0])
    """
    return anchor_centres(n_anchors) if n_anchors else [10.0 * k for k in range(1, 10)]


def anchor_centres(n: int) -> list[float]:
    """Where ``n`` anchors sit on 0..100: the centres of ``n`` equal intervals.

    >>> anchor_centres(5)
    [10.0, 30.0, 50.0, 70.0, 90.0]
    """
    return [HIGH * (k + 0.5) / n for k in range(n)]


def grab_span(x0: float, x1: float, value: int, grab_min: float, pad: float = 2.0) -> tuple[float, float]:
    """Screen x range of the handle of an integer 0..100 slider spanning ``x0..x1``, as ImGui places it
    (``SliderBehaviorT``: ``pad`` px in from each end, the handle ``max(track / 101, grab_min)`` wide, its
    centre moving over the rest).

    >>> grab_span(0, 206, 0, 10), grab_span(0, 206, 100, 10), grab_span(0, 206, 50, 10)
    ((2.0, 12.0), (194.0, 204.0), (98.0, 108.0))
    """
    track = (x1 - x0) - 2 * pad
    size = min(max(track / (HIGH - LOW + 1), grab_min), track)
    centre = x0 + pad + size / 2 + (track - size) * (value - LOW) / (HIGH - LOW)
    return centre - size / 2, centre + size / 2


def value_text_x(x0: float, x1: float, value: int, text_w: float, grab_min: float, gap: float) -> float:
    """Where the value's text starts on a slider spanning ``x0..x1``: ``gap`` px beside the handle, on the side
    with more room (right of it in the lower half, left of it from 50 on), so the handle never covers it (ImGui
    centres it in the track, under the handle at 50).

    >>> value_text_x(0, 206, 0, 20, 10, 6), value_text_x(0, 206, 50, 20, 10, 6), value_text_x(0, 206, 100, 20, 10, 6)
    (18.0, 72.0, 168.0)
    """
    a, b = grab_span(x0, x1, value, grab_min)
    return b + gap if value < (LOW + HIGH) / 2 else a - gap - text_w


@dataclass
class RatingState:
    """``values[criterion][slot]``: a whole number 0..100, or None while the slider has not been moved."""

    criteria: list[str]
    n_slots: int
    values: dict[str, list[int | None]] = field(default_factory=dict)
    #: The highlighted slider, ``criterion index * n_slots + slot``.
    active: int = 0

    def __post_init__(self) -> None:
        for c in self.criteria:
            self.values.setdefault(c, [None] * self.n_slots)

    # -- queries -----------------------------------------------------------------------------------
    def rows(self) -> list[tuple[str, int]]:
        return [(c, s) for c in self.criteria for s in range(self.n_slots)]

    def missing(self) -> list[tuple[str, int]]:
        """``(criterion, slot)`` of every slider not moved yet, in reading order."""
        return [(c, s) for c, s in self.rows() if self.values[c][s] is None]

    def all_moved(self) -> bool:
        return not self.missing()

    def ratings(self) -> dict[str, dict[int, int]]:
        out: dict[str, dict[int, int]] = {}
        for c, vals in self.values.items():
            moved = {s: v for s, v in enumerate(vals) if v is not None}
            if moved:
                out[c] = moved
        return out

    # -- edits -------------------------------------------------------------------------------------
    def set(self, criterion: str, slot: int, value: float) -> None:
        """Move one slider (clamped to 0..100, rounded to a whole number)."""
        was_unset = self.values[criterion][slot] is None
        self.values[criterion][slot] = int(round(min(max(float(value), LOW), HIGH)))
        if was_unset and self.rows()[self.active] == (criterion, slot):
            self._follow()

    def unset(self, criterion: str, slot: int) -> None:
        self.values[criterion][slot] = None

    def _active_row(self) -> tuple[str, int] | None:
        rows = self.rows()
        return rows[self.active] if rows else None

    def key_step(self, step: int) -> None:
        """Keyboard: move the highlighted slider by ``step`` (an unset one starts from 50 and stays highlighted)."""
        row = self._active_row()
        if row is None:
            return
        c, s = row
        cur = self.values[c][s]
        self.values[c][s] = 50 if cur is None else int(min(max(cur + step, LOW), HIGH))

    def key_point(self, value: float) -> None:
        """Keyboard: a number key puts the highlighted slider at ``value`` (one of :func:`digit_points`)."""
        row = self._active_row()
        if row is not None:
            self.set(row[0], row[1], value)

    def key_clear(self) -> None:
        row = self._active_row()
        if row is not None:
            self.unset(*row)

    def move_active(self, step: int) -> None:
        n = len(self.rows())
        if n:
            self.active = (self.active + step) % n

    def _follow(self) -> None:
        rows = self.rows()
        for k in range(1, len(rows) + 1):
            j = (self.active + k) % len(rows)
            c, s = rows[j]
            if self.values[c][s] is None:
                self.active = j
                return
