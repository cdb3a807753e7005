"""The participant's ranking of the three slots, per criterion (pure logic, no drawing).

Each criterion has three places, best to worst. A slot (0 = left, 1 = middle, 2 = right) is put in a
place by dragging its chip there, by clicking chips in order best -> worst (each click fills the next
free place), or by pressing 1 / 2 / 3 on the keyboard (same as clicking). Dropping a chip on an occupied
place swaps the two; clicking a placed chip takes it out again. Without ties the result is a strict
order, which :meth:`RankingState.ranks` turns into the ``{criterion: {slot: rank}}`` that
``Session.submit_ranking`` takes.

>>> r = RankingState(["realism", "synchronization"])
>>> r.click("realism", 2); r.click("realism", 0); r.click("realism", 1)
>>> r.order["realism"], r.is_complete("realism"), r.all_complete()
([2, 0, 1], True, False)
>>> r.drop("synchronization", 1, 0); r.drop("synchronization", 0, 0)   # second drop takes place 0
>>> r.order["synchronization"]
[0, None, None]
>>> r.ranks()["realism"]
{0: 2, 1: 3, 2: 1}

Ties (only when the design sets ``[playback] allow_ties``): between neighbouring places there is a
*link*; a tied link makes the two places equal. Links belong to places, not to figures, so moving figures
around keeps the ties where the participant put them. Ranks follow the competition convention ("1, 1, 3":
tied places share the better rank, the next place keeps its own number), which is what
:func:`studyapp.study.session.normalise_ranks` documents and what the session turns into average ranks.
On the keyboard, ``=`` toggles the link above the next free place, so typing ``1 = 2 3`` means "left and
middle equal best, right last".

>>> t = RankingState(["realism"], allow_ties=True)
>>> t.key_slot(0); t.key_tie(); t.key_slot(1); t.key_slot(2)
>>> t.ties["realism"], t.ranks()["realism"]
([True, False], {0: 1, 1: 1, 2: 3})
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

#: Ordinal names of the ranks 1..3, for captions.
ORDINALS = ("1st", "2nd", "3rd")


@dataclass
class RankingState:
    """Places (best first) per criterion; ``None`` marks an empty place."""

    criteria: list[str]
    order: dict[str, list[int | None]] = field(default_factory=dict)
    #: Criterion the keyboard acts on (moves on by itself when one is complete).
    active: int = 0
    #: Whether the design lets two or three slots share a rank; without it no link can ever be tied.
    allow_ties: bool = False
    #: Per criterion, ``ties[c][k]``: places ``k`` and ``k + 1`` are equal.
    ties: dict[str, list[bool]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for c in self.criteria:
            self.order.setdefault(c, [None, None, None])
            self.ties.setdefault(c, [False, False])

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

    def place_rank(self, criterion: str, place: int) -> int:
        """Rank 1..3 that ``place`` stands for: its own number, or the best place it is tied up to."""
        links = self.ties[criterion]
        while place > 0 and links[place - 1]:
            place -= 1
        return place + 1

    def is_tied(self, criterion: str, place: int) -> bool:
        """Does ``place`` share its rank with a neighbour?"""
        links = self.ties[criterion]
        return (place > 0 and links[place - 1]) or (place < 2 and links[place])

    def ranks(self) -> dict[str, dict[int, int]]:
        """``{criterion: {slot: rank 1..3}}`` for every complete criterion (competition ranks with ties)."""
        out = {}
        for c, places in self.order.items():
            if None not in places:
                out[c] = {s: self.place_rank(c, places.index(s)) for s in range(3)}
        return out

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

    def toggle_tie(self, criterion: str, link: int) -> None:
        """Make places ``link`` and ``link + 1`` equal, or different again (ignored without ``allow_ties``)."""
        if self.allow_ties and link in (0, 1):
            self.ties[criterion][link] = not self.ties[criterion][link]

    def clear(self, criterion: str) -> None:
        self.order[criterion] = [None, None, None]
        self.ties[criterion] = [False, False]

    def key_slot(self, slot: int) -> None:
        """Keyboard: place ``slot`` in the active criterion (same as clicking its chip)."""
        if not self.criteria:
            return
        crit = self.criteria[self.active]
        if self.place_of(crit, slot) is None:
            self.click(crit, slot)

    def key_tie(self) -> None:
        """Keyboard ``=``: the next figure placed in the active criterion ties with the one above it.

        Toggles the link above the first free place, so a second ``=`` takes it back; does nothing while
        no figure is placed yet or every place is filled (then the links are clicked, or Backspace
        starts the question over).
        """
        if not self.criteria or not self.allow_ties:
            return
        crit = self.criteria[self.active]
        places = self.order[crit]
        if None not in places:
            return
        free = places.index(None)
        if free > 0:
            self.toggle_tie(crit, free - 1)

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


def order_and_ties(ranks: Mapping[int, int]) -> tuple[list[int], list[bool]]:
    """The places and links that enter ``{slot: rank}`` (the inverse of :meth:`RankingState.ranks`).

    Slots of equal rank keep left-to-right order. Raises ``ValueError`` unless the ranks are competition
    ranks (a permutation of 1..3, or ties like 1,1,3 / 1,2,2 / 1,1,1), the only ones the panel can show.

    >>> order_and_ties({0: 3, 1: 1, 2: 1})
    ([1, 2, 0], [True, False])
    """
    if set(ranks) != {0, 1, 2}:
        raise ValueError(f"ranks for slots 0, 1, 2 expected, got {ranks!r}")
    order = sorted(range(3), key=lambda s: (ranks[s], s))
    ties = [ranks[order[k]] == ranks[order[k + 1]] for k in range(2)]
    probe = RankingState(["c"], allow_ties=True)
    probe.order["c"], probe.ties["c"] = list(order), list(ties)
    if probe.ranks()["c"] != {s: ranks[s] for s in range(3)}:
        raise ValueError(f"{dict(ranks)!r} are not competition ranks (tied slots share the better rank)")
    return order, ties
