"""Which motion a design can play: the (condition, stimulus) pairs some trial of some design row shows.

A pair ``(c, s)`` is *played* when some trial shows condition ``c`` moving with the motion made for stimulus
``s`` (``motion_path(design, c, s, k)``). Only played pairs need motion files: ``validate`` reports a
missing file of a played pair, ships, checks and prerenders those, and ignores every other combination.

The rules are the schedule's (:mod:`studyapp.study.schedule`), read off for all rows at once. With
``blocks = design.trial_blocks`` (the one implicit rank block ``"main"`` of a design without ``[[blocks]]``):

* every block plays each of its *figures* (its conditions; a rating block's hidden ``reference`` too) on
  each of its ``stimuli``: a rank trial shows all three conditions, a rating trial every figure, and over
  the design's rows a pairwise block shows every pair of its conditions, a mismatch block every condition,
  on every stimulus of the block;
* a mismatch block also plays each condition on the *source* clips of its stimuli (:func:`mismatch_sources`:
  the block's other stimuli sharing the stimulus's ``match_tag`` value), which are block stimuli themselves;
* practice clips are trials of the first block: its figures on each practice clip (a mismatch first block
  also on the clip's sources);
* attention checks are trials of the first ``rank`` block: its three conditions on each check's clip (a
  ``frozen`` slot shows the first frame of its condition's motion, so that file is played too); a design
  whose blocks have no rank block asks no checks.

Every sample of a played pair counts as played (``samples = N``: files ``1..N``). Which sample a row shows
is row arithmetic that a change to the row count reshuffles, so all of them are required, as before.

``tests/study/test_played_pairs.py`` checks these rules against every trial of every row of every shipped
design and example and of block designs built for the test.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from studyapp.study.design.model import Block, Design


def mismatch_sources(design: Design, block: Block, stimulus_id: str) -> list[str]:
    """The block's other stimuli sharing the stimulus's ``match_tag`` value, in block order (the clips whose
    motion a mismatch trial of ``stimulus_id`` may play)."""
    tags = {s.id: s.tags for s in design.stimuli}
    value = tags.get(stimulus_id, {}).get(block.match_tag)
    return [o for o in block.stimuli if o != stimulus_id and value is not None
            and tags.get(o, {}).get(block.match_tag) == value]


def played_pairs(design: Design) -> dict[str, tuple[str, ...]]:
    """Condition id -> the stimuli whose motion some trial plays for it (see the module notes), both in design
    order; a condition no trial shows maps to ``()``.

    >>> from studyapp.resources import demo_design
    >>> from studyapp.study.design import load_design
    >>> d = load_design(demo_design())
    >>> played_pairs(d)["synced"] == tuple(s.id for s in d.stimuli)
    True
    """
    blocks = design.trial_blocks
    shown: dict[str, set[str]] = {c.id: set() for c in design.conditions}

    def play(conditions: tuple[str, ...], stimuli: list[str]) -> None:
        for c in conditions:
            shown.setdefault(c, set()).update(stimuli)

    def with_sources(block: Block, sid: str) -> list[str]:
        return [sid] + (mismatch_sources(design, block, sid) if block.paradigm == "mismatch" else [])

    for block in blocks:
        for sid in block.stimuli:
            play(block.figures, with_sources(block, sid))
    if blocks:
        for sid in design.practice:
            play(blocks[0].figures, with_sources(blocks[0], sid))
    first_rank = next((b for b in blocks if b.paradigm == "rank"), None)
    if first_rank is not None:
        for check in design.attention_checks:
            play(first_rank.conditions, [check.stimulus])
    order = [s.id for s in design.stimuli]
    return {c.id: tuple(s for s in order if s in shown[c.id]) for c in design.conditions}
