"""The participant's ranking of the three slots, per criterion (pure logic, no drawing).

Each criterion has three places, best to worst. A slot (0 = left, 1 = middle, 2 = right) is put in a
place by dragging its chip there, by clicking chips in order best -> worst (each click fills the next
free place), or by pressing 1 / 2 / 3 on the keyboard (same as clicking). Dropping a chip on an occupied
place swaps the two; clicking a placed chip takes it out again. The result is a strict order, which
:meth:`RankingState.ranks` turns into the ``{criterion: {slot: rank}}`` that ``Session.submit_ranking``
takes.

>>> r = RankingState(["realism", "synchronization"])
>>> r.click("realism", 2); r.click("realism", 0); r.click("realism", 1)
>>> r.order["realism"], r.is_complete("realism"), r.all_complete()
([2, 0, 1], True, False)
>>> r.drop("synchronization", 1, 0); r.drop("synchronization", 0, 0)   # second drop takes place 0
>>> r.order["synchronization"]
[0, None, None]
>>> r.ranks()["realism"]
{0: 2, 1: 3, 2: 1}
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class RankingState:
    """Places (best first) per criterion; ``None`` marks an empty place."""

    criteria: list[str]
    order: dict[str, list[int | None]] = field(default_factory=dict)
    #: Criterion the keyboard acts on (moves on by itself when one is complete).
    active: int = 0

    def __post_init__(self) -> None:
        for c in self.criteria:
            self.order.setdefault(c, [None, None, None])

    # -- queries -----------------------------------------------------------------------------------
    def place_of(self, criterion: str, slot: int) -> int | None:
        places = self.order[criterion]
        return places.index(slot) if slot in places else None

    def unplaced(self, criterion: str) -> list[int]:
        return [s for s in range(3) if s not in self.order[criterion]]

    def is_complete(self, criterion: str) -> bool:
        return None not in self.order[criterion]

    def all_complete(self) -> bool:
        return all(self.is_complete(c) for c in self.criteria)

    def ranks(self) -> dict[str, dict[int, int]]:
        """``{criterion: {slot: rank 1..3}}`` for every complete criterion."""
        return {c: {s: p.index(s) + 1 for s in range(3)} for c, p in self.order.items() if None not in p}

    # -- edits -------------------------------------------------------------------------------------
    def drop(self, criterion: str, slot: int, place: int) -> None:
        """Put ``slot`` at ``place``; whatever was there moves to where ``slot`` came from (or out)."""
        places = self.order[criterion]
        old = self.place_of(criterion, slot)
        other = places[place]
        places[place] = slot
        if old is not None and old != place:
            places[old] = other
        self._follow(criterion)

    def click(self, criterion: str, slot: int) -> None:
        """A placed chip goes back out; an unplaced one fills the next free place."""
        places = self.order[criterion]
        old = self.place_of(criterion, slot)
        if old is not None:
            places[old] = None
            return
        if None in places:
            places[places.index(None)] = slot
        self._follow(criterion)

    def clear(self, criterion: str) -> None:
        self.order[criterion] = [None, None, None]

    def key_slot(self, slot: int) -> None:
        """Keyboard: place ``slot`` in the active criterion (same as clicking its chip)."""
        if not self.criteria:
            return
        crit = self.criteria[self.active]
        if self.place_of(crit, slot) is None:
            self.click(crit, slot)

    def move_active(self, step: int) -> None:
        if self.criteria:
            self.active = (self.active + step) % len(self.criteria)

    def _follow(self, criterion: str) -> None:
        # After completing the active criterion the keyboard moves to the next unfinished one.
        if self.criteria and self.criteria[self.active] == criterion and self.is_complete(criterion):
            for k in range(1, len(self.criteria) + 1):
                j = (self.active + k) % len(self.criteria)
                if not self.is_complete(self.criteria[j]):
                    self.active = j
                    return
