"""The participant's preference between two figures, per criterion (pure logic, no drawing).

Used by the ``pairwise`` and ``mismatch`` paradigms. Each criterion has a scale of 5 (or 3) options, left to
right: "clearly left", "slightly left", "no preference", "slightly right", "clearly right" (3 levels drop the
"clearly" ends). An option's *value* is what ``Session.submit_preference`` takes: negative = the LEFT figure
preferred, positive = the RIGHT one, 0 = no preference (``-2..2``, or ``-1..1`` for 3 levels).

When the block lists reasons and some answer is not "no preference", the participant may tick reasons
(optional, any number); they are submitted only then (with every answer "no preference" there is nothing to
explain, and ticked reasons are dropped).

Rows and the keyboard: each criterion is a row, and the reasons form one more row while they are asked for.
The digits pick an option *in the highlighted row*: 1..5 the scale's options from left to right, or the
reasons in their listed order (toggling them); Left / Right move the highlighted question's answer one step
along its scale (starting from "no preference"); Up / Down change row; Backspace clears the highlighted
question. After a question is answered the highlight moves on by itself to the next unanswered question, then
to the reasons.

>>> p = PreferenceState(["realism", "timing"], levels=5, reasons=("Hands", "Timing"))
>>> p.options
(-2, -1, 0, 1, 2)
>>> p.key_digit(1)            # the 2nd option of the first question: "slightly left"
>>> p.answers(), p.active
({'realism': -1}, 1)
>>> p.key_digit(2); p.all_complete(), p.reasons_asked(), p.active   # "no preference"; reasons row next
(True, True, 2)
>>> p.key_digit(1); p.submitted_reasons()
['Timing']
>>> p.choose("realism", 0); p.reasons_asked(), p.submitted_reasons()
(False, [])
"""
from __future__ import annotations

from dataclasses import dataclass, field

#: Option values left to right, by number of levels.
SCALES: dict[int, tuple[int, ...]] = {5: (-2, -1, 0, 1, 2), 3: (-1, 0, 1)}


def option_keys(value: int, levels: int) -> tuple[str, str]:
    """The text key and the slot side (``"left"``/``"right"``/``""``) of an option, for its label.

    >>> option_keys(-2, 5), option_keys(1, 5), option_keys(0, 3), option_keys(-1, 3)
    (('pref.clearly', 'left'), ('pref.slightly', 'right'), ('pref.equal', ''), ('pref.better', 'left'))
    """
    if value == 0:
        return "pref.equal", ""
    side = "left" if value < 0 else "right"
    if levels == 3:
        return "pref.better", side
    return ("pref.clearly" if abs(value) == 2 else "pref.slightly"), side


@dataclass
class PreferenceState:
    """The answers on screen: ``choice[criterion]`` is an option value or None (not answered yet)."""

    criteria: list[str]
    levels: int = 5
    reasons: tuple[str, ...] = ()
    choice: dict[str, int | None] = field(default_factory=dict)
    ticked: set[str] = field(default_factory=set)
    #: The highlighted row: a criterion's index, or ``len(criteria)`` for the reasons row.
    active: int = 0

    def __post_init__(self) -> None:
        if self.levels not in SCALES:
            raise ValueError(f"a preference scale has 5 or 3 levels, not {self.levels!r}")
        self.reasons = tuple(self.reasons)
        for c in self.criteria:
            self.choice.setdefault(c, None)

    # -- queries -----------------------------------------------------------------------------------
    @property
    def options(self) -> tuple[int, ...]:
        return SCALES[self.levels]

    def is_complete(self, criterion: str) -> bool:
        return self.choice[criterion] is not None

    def all_complete(self) -> bool:
        return all(self.is_complete(c) for c in self.criteria)

    def reasons_asked(self) -> bool:
        """The reasons row shows: the block has reasons and some answer is not "no preference"."""
        return bool(self.reasons) and any(v not in (None, 0) for v in self.choice.values())

    def n_rows(self) -> int:
        return len(self.criteria) + (1 if self.reasons_asked() else 0)

    def answers(self) -> dict[str, int]:
        """``{criterion: value}`` for every answered question (what ``Session.submit_preference`` takes)."""
        return {c: v for c, v in self.choice.items() if v is not None}

    def submitted_reasons(self) -> list[str]:
        """The ticked reasons in the block's order, or none while no answer is a preference."""
        return [r for r in self.reasons if r in self.ticked] if self.reasons_asked() else []

    # -- edits -------------------------------------------------------------------------------------
    def choose(self, criterion: str, value: int) -> None:
        if value not in self.options:
            raise ValueError(f"{value!r} is not on a {self.levels}-level scale")
        self.choice[criterion] = value
        self._follow(criterion)

    def toggle_reason(self, reason: str) -> None:
        if reason in self.ticked:
            self.ticked.discard(reason)
        elif reason in self.reasons:
            self.ticked.add(reason)

    def clear(self, criterion: str) -> None:
        self.choice[criterion] = None
        self._clamp()

    def key_digit(self, k: int) -> None:
        """Keyboard: digit ``k + 1`` picks option ``k`` of the highlighted row (or toggles reason ``k``)."""
        if self.active < len(self.criteria):
            if 0 <= k < len(self.options):
                self.choose(self.criteria[self.active], self.options[k])
        elif 0 <= k < len(self.reasons):
            self.toggle_reason(self.reasons[k])

    def key_step(self, step: int) -> None:
        """Keyboard Left (-1) / Right (+1): move the highlighted question's answer one option along its scale."""
        if self.active >= len(self.criteria):
            return
        crit = self.criteria[self.active]
        opts = self.options
        cur = self.choice[crit]
        i = opts.index(0) if cur is None else opts.index(cur) + step
        self.choice[crit] = opts[min(max(i, 0), len(opts) - 1)]
        self._clamp()

    def key_clear(self) -> None:
        if self.active < len(self.criteria):
            self.clear(self.criteria[self.active])
        else:
            self.ticked.clear()

    def move_active(self, step: int) -> None:
        n = self.n_rows()
        if n:
            self.active = (self.active + step) % n

    def _clamp(self) -> None:
        # the reasons row disappears when every answer becomes "no preference"
        if self.active >= self.n_rows():
            self.active = max(0, self.n_rows() - 1)

    def _follow(self, criterion: str) -> None:
        # After answering the highlighted question, move to the next unanswered one, else to the reasons.
        self._clamp()
        if not self.criteria or self.criteria[self.active] != criterion:
            return
        n = len(self.criteria)
        for k in range(1, n + 1):
            j = (self.active + k) % n
            if not self.is_complete(self.criteria[j]):
                self.active = j
                return
        if self.reasons_asked():
            self.active = n
