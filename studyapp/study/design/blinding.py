"""Blinding: no text a participant reads may name a condition, by its id or by its ``label``.

A condition's label (the name the analysis shows) is the experimenter's: like the id it never appears on a
participant's screen, and a bundle leaves it out of the design it ships (:mod:`studyapp.study.bundle`).

>>> from studyapp.study.design import load_design
>>> from studyapp.resources import demo_design
>>> conditions_named_in(load_design(demo_design(), check_files=False), "results of synced.csv")
['synced']
"""
from __future__ import annotations

import re
from typing import TYPE_CHECKING

from studyapp.study.design.texts import LANGUAGES as BUILTIN

if TYPE_CHECKING:
    from studyapp.study.design.model import Design


def visible_text_leaks(design: Design) -> list[tuple[str, str]]:
    """``(key, name)`` for every participant-visible text that names a condition (whole word), ``name`` being
    the condition's id or, when only that is named, its label (see :func:`conditions_named_in`).

    Slot labels are the design's own neutral names (A/B/C) and are not checked.

    >>> from studyapp.resources import demo_design
    >>> from studyapp.study.design import load_design
    >>> visible_text_leaks(load_design(demo_design(), check_files=False))
    []
    """
    texts = {"title": design.title, "instructions": design.instructions, "consent": design.consent,
             "completion": design.completion}
    texts.update({f"texts.{k}": v for k, v in design.texts.items() if v != BUILTIN.get(design.language, {}).get(k)})
    for i, c in enumerate(design.criteria):
        texts[f"criteria[{i}]"] = " ".join((c.label, c.question, c.explanation))
    for i, q in enumerate(design.questionnaire):
        texts[f"questionnaire[{i}]"] = " ".join((q.text, *q.anchors, *q.options))
    for i, b in enumerate(design.blocks):  # a block's id is recorded, never shown
        texts[f"blocks[{i}]"] = " ".join((b.instructions, *b.reasons, *b.anchors))
    return [(key, cid) for key, text in texts.items() for cid in conditions_named_in(design, text)]


def conditions_named_in(design: Design, text: str) -> list[str]:
    """The design's conditions that ``text`` names as a whole word, ignoring case (``_``, ``-`` and ``.``
    separate words, so a file name such as ``ours_vs_base.zip`` names ``ours``): one entry per condition, its
    id when the id is named, else its label when the label is.

    >>> from studyapp.resources import demo_design
    >>> from studyapp.study.design import load_design
    >>> conditions_named_in(load_design(demo_design(), check_files=False), "demo_synced-v2.zip")
    ['synced']
    """
    found = []
    for cond in design.conditions:
        for name in (cond.id, cond.label):
            if name is not None and _names(text, name):
                found.append(name)
                break
    return found


def _names(text: str, name: str) -> bool:
    """Whether ``text`` holds ``name`` as a whole word (or words), ignoring case."""
    # names of one or two characters ("a", "B1") are opaque already and would match ordinary words
    name = name.strip()
    return len(name) > 2 and re.search(rf"(?<![A-Za-z0-9]){re.escape(name)}(?![A-Za-z0-9])", text,
                                       flags=re.IGNORECASE) is not None
