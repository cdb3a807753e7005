"""What the trial on screen asks, from its block: the paradigm, the block's questions and answer options.

The UI dispatches on ``plan.paradigm`` (``rank``, ``pairwise``, ``mismatch``, ``rating``; see the design's
``[[blocks]]``). :func:`block_view` gathers, for one :class:`~studyapp.study.schedule.TrialPlan`, what the
answer panel needs from the plan's block: its criteria (as :class:`~studyapp.study.design.Criterion`, in the
block's order), the preference scale's levels and reasons (pairwise, mismatch) and the slider anchors
(rating). A design without blocks, or a plan whose block is unknown, is today's ranking on every criterion.

:func:`slot_names` is what the figures are called on screen for a trial of ``n`` figures: the design's slot
labels for ``n`` figures when it has them (:func:`figure_labels`; missing ones continue the letters), else
Left / Right for two, Left / Middle / Right for three and letters for more. Those names label the figures
in the 3D view (:func:`scene_labels`) whenever the names are not simply their positions, so a participant
can always tell which figure a "B" or a slider belongs to. Nothing here names or groups a condition.

>>> slot_names(None, 2), slot_names(("A", "B", "C"), 2), slot_names(None, 4)
(('Left', 'Right'), ('A', 'B'), ('A', 'B', 'C', 'D'))
>>> slot_names(("A", "B", "C"), 4), scene_labels(None, 2), scene_labels(None, 4)
(('A', 'B', 'C', 'D'), None, ('A', 'B', 'C', 'D'))
"""
from __future__ import annotations

import string
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Sequence

if TYPE_CHECKING:
    from studyapp.study.design import Criterion, Design
    from studyapp.study.schedule import TrialPlan

PARADIGMS = ("rank", "pairwise", "mismatch", "rating")
#: Paradigms answered on the preference panel (two figures, a bipolar scale per criterion).
PREFERENCE = ("pairwise", "mismatch")
POSITIONS = {1: ("Figure",), 2: ("Left", "Right"), 3: ("Left", "Middle", "Right")}


@dataclass(frozen=True)
class BlockView:
    """What the answer panel of one trial shows (see the module docstring)."""

    id: str
    paradigm: str
    criteria: tuple[Criterion, ...]
    levels: int = 5
    reasons: tuple[str, ...] = ()
    anchors: tuple[str, ...] = ()
    instructions: str = ""


def _block(design: Design, block_id: str) -> Any | None:
    for b in getattr(design, "blocks", None) or ():
        if getattr(b, "id", None) == block_id:
            return b
    return None


def block_view(design: Design, plan: TrialPlan) -> BlockView:
    """The :class:`BlockView` of ``plan`` (its block's settings; today's ranking when there are none)."""
    paradigm = str(getattr(plan, "paradigm", "rank") or "rank")
    block_id = str(getattr(plan, "block", "main") or "main")
    return _view_of(design, _block(design, block_id), block_id, paradigm)


def paradigm_views(design: Design) -> list[BlockView]:
    """One :class:`BlockView` per paradigm the design uses (its first block of each), in block order; a
    design without blocks: the one ranking block."""
    out: dict[str, BlockView] = {}
    for b in getattr(design, "blocks", None) or ():
        p = str(getattr(b, "paradigm", "rank") or "rank")
        out.setdefault(p, _view_of(design, b, str(getattr(b, "id", "main")), p))
    return list(out.values()) or [_view_of(design, None, "main", "rank")]


def _view_of(design: Design, block: Any | None, block_id: str, paradigm: str) -> BlockView:
    by_id = {c.id: c for c in design.criteria}
    wanted = list(getattr(block, "criteria", None) or []) if block is not None else []
    # a block names its criteria by id (the contract); a parser may already have resolved them
    crits = tuple(by_id[c] if isinstance(c, str) else c for c in wanted if not isinstance(c, str) or c in by_id)
    if not crits:
        crits = tuple(design.criteria)
    if block is None:
        return BlockView(block_id, paradigm, crits)
    return BlockView(block_id, paradigm, crits,
                     levels=int(getattr(block, "levels", None) or 5),
                     reasons=tuple(getattr(block, "reasons", None) or ()),
                     anchors=tuple(getattr(block, "anchors", None) or ()),
                     instructions=str(getattr(block, "instructions", None) or ""))


def figure_labels(design: Design, n: int) -> tuple[str, ...] | None:
    """The design's slot labels for a trial of ``n`` figures (``[slots] labels``), or None without labels."""
    labels_for = getattr(design, "slot_labels_for", None)
    if labels_for is not None:
        return labels_for(n)
    return tuple(design.slot_labels[:n]) if design.slot_labels else None


def slot_names(labels: Sequence[str] | None, n: int) -> tuple[str, ...]:
    """What the ``n`` figures of a trial are called on screen (see the module docstring)."""
    if labels:
        given = [str(x) for x in labels][:n]
        letters = [c for c in string.ascii_uppercase if c not in given]
        return tuple(given + letters[: n - len(given)])
    return POSITIONS.get(n, tuple(string.ascii_uppercase[:n]))


def scene_labels(labels: Sequence[str] | None, n: int) -> tuple[str, ...] | None:
    """The labels drawn above the figures: the names, unless they are just the positions (no labels)."""
    names = slot_names(labels, n)
    return None if names == POSITIONS.get(n) else names
