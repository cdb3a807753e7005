"""Design keys, each declared once: a TOML key is a dataclass field carrying its accepted types.

The runtime classes (:mod:`.model`) declare the keys of the tables that mirror them (``[[conditions]]``,
``[[stimuli]]``, ``[[criteria]]``, ``[playback]``, ``[[questionnaire]]``); the tables that only feed the
design (``[avatar]``, ``[ordering]``, ``[slots]``, ``[[attention_checks]]``, ``[participants]``,
``[[blocks]]`` and the top level) are declared here. The parser checks a table against :func:`toml_keys` of its class and takes
defaults from the class, so adding a key is adding one field.

>>> toml_keys(OrderingTable)
{'method': ((<class 'str'>,), False), 'seed': ((<class 'int'>,), False)}
>>> OrderingTable().method
'balanced-latin-square'
"""
from __future__ import annotations

import re
from dataclasses import MISSING, dataclass, field, fields
from typing import Any

STR, NUM, INT, BOOL, LIST, TABLE = (str,), (int, float), (int,), (bool,), (list,), (dict,)
TYPE_NAMES = {str: "a string", int: "an integer", float: "a number", bool: "true or false", list: "a list",
              dict: "a table"}

ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")
ORDERINGS = ("balanced-latin-square", "random", "fixed")
SLOT_ASSIGNMENTS = ("balanced", "random")
SLOT_LABELS = {"ABC": ("A", "B", "C"), "LMR": ("L", "M", "R"), "123": ("1", "2", "3"), "none": None}
#: Questionnaire item kinds (see :class:`~.model.QuestionItem`); only ``likert`` answers are analysed as numbers.
QUESTION_KINDS = ("likert", "choice", "number", "text")
MOTION_SUFFIXES = (".bvh", ".npz", ".npy")
AVATAR_SUFFIXES = (".glb", ".gltf", ".vrm")
#: Attention-check kinds and what they show (see :class:`~.model.AttentionCheck`).
ATTENTION_KINDS = ("frozen", "known-worst")
#: ``model = "builtin:reference"`` runs the reference ONNX model shipped with studyapp.
BUILTIN_REFERENCE = "builtin:reference"
#: Prefix of the pseudo condition id of a frozen attention-check slot.
FROZEN_PREFIX = "frozen:"
#: Response paradigms of a ``[[blocks]]`` entry (see :class:`~.model.Block`).
PARADIGMS = ("rank", "pairwise", "mismatch", "rating")
#: Preference scales of pairwise and mismatch blocks: the number of levels and the values a level takes
#: (negative = the LEFT figure preferred, positive = the RIGHT one, 0 = no preference).
PREFERENCE_LEVELS = {5: (-2, -1, 0, 1, 2), 3: (-1, 0, 1)}
#: How many figures a rating trial shows (its conditions plus the hidden reference).
RATING_FIGURES = (2, 4)
#: Criterion aspects (``[[criteria]] aspect``): Nagy et al. 2025 ask for motion quality and speech
#: alignment to be judged in separate blocks.
ASPECTS = ("motion", "speech")


def key(types: tuple[type, ...], *, required: bool = False, default: Any = MISSING,
        default_factory: Any = MISSING) -> Any:
    """A dataclass field that is also a design key accepting values of ``types``."""
    meta = {"toml": tuple(types), "required": required}
    if default_factory is not MISSING:
        return field(default_factory=default_factory, metadata=meta)
    if default is not MISSING:
        return field(default=default, metadata=meta)
    return field(metadata=meta)


def toml_keys(cls: type) -> dict[str, tuple[tuple[type, ...], bool]]:
    """``{key: (accepted types, required)}`` of a class's design keys, in declaration order."""
    return {f.name: (f.metadata["toml"], f.metadata["required"]) for f in fields(cls) if "toml" in f.metadata}


def key_default(cls: type, name: str) -> Any:
    """The default a class declares for one key."""
    f = next(f for f in fields(cls) if f.name == name)
    return f.default_factory() if f.default_factory is not MISSING else f.default


@dataclass
class DesignFile:
    """The top level of a design file."""

    title: str = key(STR, required=True, default="")
    instructions: str = key(STR, default="")
    #: what participants agree to on the first page ("" = the built-in text); ``{minutes}`` is replaced
    consent: str = key(STR, default="")
    #: the last page's text after a completed study: thanks, debriefing ("" = the built-in thanks)
    completion: str = key(STR, default="")
    #: the built-in texts' language (see :mod:`.texts`): "en" or "zh" (Simplified Chinese)
    language: str = key(STR, default="en")
    #: overrides of built-in texts by key (see :mod:`.texts`)
    texts: dict = key(TABLE, default_factory=dict)
    practice: list = key(LIST, default_factory=list)
    conditions: list = key(LIST, required=True, default_factory=list)
    stimuli: list = key(LIST, required=True, default_factory=list)
    criteria: list = key(LIST, default_factory=list)
    avatar: dict = key(TABLE, default_factory=dict)
    ordering: dict = key(TABLE, default_factory=dict)
    slots: dict = key(TABLE, default_factory=dict)
    attention_checks: list = key(LIST, default_factory=list)
    playback: dict = key(TABLE, default_factory=dict)
    questionnaire: list = key(LIST, default_factory=list)
    participants: dict = key(TABLE, default_factory=dict)
    display: dict = key(TABLE, default_factory=dict)
    blocks: list = key(LIST, default_factory=list)
    online: dict = key(TABLE, default_factory=dict)


@dataclass
class AvatarTable:
    """``[avatar]``: the character every slot shows (``"builtin"`` or a glTF/GLB/VRM file), per speaker."""

    model: str = key(STR, default="builtin")
    by_speaker: dict = key(TABLE, default_factory=dict)
    #: avatar joint name -> Unity humanoid bone, for avatars with their own bone names
    bone_map: dict = key(TABLE, default_factory=dict)


@dataclass
class OrderingTable:
    """``[ordering]``: how clip order is drawn, and the seed of every random choice."""

    method: str = key(STR, default="balanced-latin-square")
    seed: int = key(INT, default=1)


@dataclass
class SlotsTable:
    """``[slots]``: how conditions are put in slots and what the slots are called on screen."""

    assignment: str = key(STR, default="balanced")
    labels: str = key(STR, default="ABC")


@dataclass
class AttentionCheckTable:
    """``[[attention_checks]]``: see :class:`~.model.AttentionCheck` for what each kind shows."""

    stimulus: str = key(STR, required=True, default="")
    kind: str = key(STR, default="frozen")
    criterion: str = key(STR, default="realism")
    rank: int = key(INT, default=3)
    condition: str | None = key(STR, default=None)


@dataclass
class ParticipantsTable:
    """``[participants]``: when a session ends early, and groups participants belong to."""

    max_attention_failures: int | None = key(INT, default=None)
    groups: dict = key(TABLE, default_factory=dict)


@dataclass
class BlockTable:
    """``[[blocks]]``: one block of trials and its response paradigm (see :class:`~.model.Block` for the
    meaning of each key; a design without blocks is one ``rank`` block ``"main"`` over everything)."""

    id: str = key(STR, required=True, default="")
    paradigm: str = key(STR, default="rank")
    criteria: list | None = key(LIST, default=None)
    conditions: list | None = key(LIST, default=None)
    stimuli: list | None = key(LIST, default=None)
    instructions: str = key(STR, default="")
    levels: int = key(INT, default=5)
    reasons: list = key(LIST, default_factory=list)
    match_tag: str = key(STR, default="speaker")
    reference: str | None = key(STR, default=None)
    anchors: list = key(LIST, default_factory=list)


@dataclass
class OnlineTable:
    """``[online]``: the browser study server (``studyapp serve``, :mod:`studyapp.web`).

    ``abandon_after_min``: minutes without activity after which an unfinished browser participant is taken as
    abandoned and their Latin-square row is given out again (HEMVIP2 waits 2 h). ``completion_code``: the code
    the completion page shows (Prolific's completion code). ``completion_url``: where the completion page
    sends the participant (Prolific's ``https://app.prolific.com/submissions/complete?cc=CODE``); empty: none.
    """

    abandon_after_min: float = key(NUM, default=120.0)
    completion_code: str = key(STR, default="")
    completion_url: str = key(STR, default="")
