"""Blinding: no text a participant reads may name a condition.

>>> from studyapp.study.design import load_design
>>> from studyapp.resources import demo_design
>>> conditions_named_in(load_design(demo_design(), check_files=False), "results of synced.csv")
['synced']
"""
from __future__ import annotations

import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from studyapp.study.design.model import Design


def visible_text_leaks(design: Design) -> list[tuple[str, str]]:
    """``(key, condition id)`` for every participant-visible text that names a condition (whole word).

    Slot labels are the design's own neutral names (A/B/C) and are not checked.

    >>> from studyapp.resources import demo_design
    >>> from studyapp.study.design import load_design
    >>> visible_text_leaks(load_design(demo_design(), check_files=False))
    []
    """
    texts = {"title": design.title, "instructions": design.instructions}
    for i, c in enumerate(design.criteria):
        texts[f"criteria[{i}]"] = " ".join((c.label, c.question, c.explanation))
    for i, q in enumerate(design.questionnaire):
        texts[f"questionnaire[{i}]"] = " ".join((q.text, *q.anchors))
    return [(key, cid) for key, text in texts.items() for cid in conditions_named_in(design, text)]


def conditions_named_in(design: Design, text: str) -> list[str]:
    """Ids of the design's conditions that ``text`` names as a whole word, ignoring case (``_``, ``-`` and
    ``.`` separate words, so a file name such as ``ours_vs_base.zip`` names ``ours``).

    >>> from studyapp.resources import demo_design
    >>> from studyapp.study.design import load_design
    >>> conditions_named_in(load_design(demo_design(), check_files=False), "demo_synced-v2.zip")
    ['synced']
    """
    # ids of one or two characters ("a", "B1") are opaque already and would match ordinary words
    return [cond.id for cond in design.conditions if len(cond.id) > 2
            and re.search(rf"(?<![A-Za-z0-9]){re.escape(cond.id)}(?![A-Za-z0-9])", text, flags=re.IGNORECASE)]
