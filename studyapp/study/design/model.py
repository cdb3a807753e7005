"""The validated study design: what a study shows, in which order, and what it asks.

These classes are what every other part of studyapp reads; :mod:`.parse` builds them from a TOML file.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

from studyapp.errors import InputError
from studyapp.render.camera import DEFAULT_FRAMING
from studyapp.study.design.files import resolve
from studyapp.study.design.texts import EN as EN_TEXTS
from studyapp.study.design.texts import fill
from studyapp.study.design.schema import BOOL, FROZEN_PREFIX, INT, LIST, NUM, STR, TABLE, OnlineTable, key

# ---------------------------------------------------------------------------------------------------------
# Data classes


@dataclass
class Condition:
    """One model (or source of motion) compared in the study.

    Attributes
    ----------
    id: short name recorded with every answer; never shown to participants.
    label: the name the experimenter's analysis shows for the condition (tables, figures, report text), e.g.
        ``"Ours (diffusion)"``; any one line of text, unique among the conditions; None (default): the id.
        Like the id it is never shown to, nor shipped to, participants (a bundle drops it).
    motion: path pattern of the pre-computed motion files, relative to the design file, with ``{stimulus}``.
    model: path of an ONNX gesture model run live on each stimulus instead of ``motion``.
    fps: frame rate to use instead of what the motion file says (BVH headers can lie; NPZ/NPY have none).
    representation: rotation representation of NPZ/NPY motion arrays (``euler``, ``axis_angle``, ``quat``,
        ``sixd`` (Zhou's first two matrix columns), ``sixd_rows`` (PyTorch3D's first two rows), ``matrix``).
    template: BVH whose skeleton NPZ/NPY arrays (and live model outputs) are laid onto.
    rotation_order: Euler order of NPZ/NPY euler arrays (e.g. ``"XYZ"``).
    name_map: source joint name -> humanoid bone name, for skeletons whose names are not recognised.
    joints: template joint names the columns of NPZ/NPY arrays drive, in order (default: all template
        joints, or BEAT's 47 upper-body joints for 47-joint arrays on a BEAT-like template).
    degrees: whether NPZ/NPY Euler angles are in degrees (default) or radians.
    motion_end: what the motion does when it ends before the trial (see :mod:`studyapp.study.timeline`):
        ``"hold"`` its last frame or ``"loop"`` from its first; None (default): ``validate`` refuses a motion
        shorter than the trial.
    samples: how many motion files the condition gives per stimulus (stochastic models; the GENEA
        Leaderboard asks for 5). With ``samples = N > 1`` the ``motion`` pattern must hold ``{sample}``, which
        takes the values ``1..N`` (1-based, as GENEA names its files ``sample_1`` .. ``sample_5``); the schedule
        picks one per participant and trial, balanced over participants, and every answer records it.
    body_model: the user's own SMPL/SMPL-H/SMPL-X model ``.npz`` (``J_regressor``, ``v_template``,
        ``shapedirs``) giving SMPL-family motion files their rest skeleton, shaped by each file's ``betas``;
        without it a built-in skeleton of average proportions is used. SMPL-family files need no
        ``template``, ``representation`` or ``fps``: they are recognised by their keys.
    """

    id: str = key(STR, required=True)
    label: str | None = key(STR, default=None)
    motion: str | None = key(STR, default=None)
    model: str | None = key(STR, default=None)
    fps: float | None = key(NUM, default=None)
    representation: str | None = key(STR, default=None)
    template: str | None = key(STR, default=None)
    rotation_order: str | None = key(STR, default=None)
    name_map: dict[str, str] = key(TABLE, default_factory=dict)
    joints: tuple[str, ...] | None = key(LIST, default=None)
    degrees: bool = key(BOOL, default=True)
    motion_end: str | None = key(STR, default=None)
    body_model: str | None = key(STR, default=None)
    samples: int = key(INT, default=1)

    @property
    def shown_as(self) -> str:
        """What the analysis calls the condition: its label, else its id."""
        return self.label if self.label is not None else self.id

    @property
    def is_live(self) -> bool:
        """True when the motion comes from an ONNX model run on the stimulus rather than from files."""
        return self.model is not None

    @property
    def is_array(self) -> bool:
        """True when the motion files are NPZ/NPY: rotation arrays (read with template, representation, fps)
        or SMPL-family files (recognised when read)."""
        return self.motion is not None and self.motion.lower().endswith((".npz", ".npy"))


@dataclass
class Stimulus:
    """One speech clip: audio and face are shared by all three slots, only the body motion differs.

    Attributes
    ----------
    id: short name, also the ``{stimulus}`` in motion patterns.
    audio: WAV file (absolute, resolved against the design file).
    face: ARKit blendshape animation (CSV, Live Link Face CSV, BEAT JSON, NPY) or None for a neutral face.
    head: optional head motion file shown with the face.
    tags: free labels recorded with every answer, e.g. ``speaker``; ``speaker`` also picks the avatar.
    duration_s: play only the first ``duration_s`` seconds (None: the audio's length).
    in_rotation: False for stimuli only used as practice or attention checks (outside the balanced order).
    """

    id: str = key(STR, required=True)
    audio: Path = key(STR, required=True)
    face: Path | None = key(STR, default=None)
    head: Path | None = key(STR, default=None)
    tags: dict[str, str] = key(TABLE, default_factory=dict)
    duration_s: float | None = key(NUM, default=None)
    in_rotation: bool = key(BOOL, default=True)


@dataclass
class Criterion:
    """One question the three motions are ranked on (rank 1 = best)."""

    id: str = key(STR, required=True)
    label: str = key(STR)                # default: the id, capitalised
    question: str = key(STR, required=True)
    explanation: str = key(STR, default="")
    #: what the criterion judges: "motion" (quality: realism, human-likeness, diversity) or "speech"
    #: (appropriateness, synchronization); None: guessed from its id and label (see :func:`criterion_aspect`)
    aspect: str | None = key(STR, default=None)


#: The three criteria of the published study; used when a design has no ``[[criteria]]``.
DEFAULT_CRITERIA: tuple[Criterion, ...] = (
    Criterion("realism", "Realism", "Which motion looks most realistic?",
              "Natural human movement: no odd body orientation, no jitter, no frozen or robotic poses.",
              aspect="motion"),
    Criterion("synchronization", "Synchronization", "Which motion is best synchronized with the speech?",
              "The gestures follow the rhythm and intonation of the speech: emphasis in the voice comes with "
              "movement, pauses with calm.", aspect="speech"),
    Criterion("diversity", "Diversity", "Which motion is most diverse?",
              "Rich and varied gestures: not motionless, not the same movement repeated over and over.",
              aspect="motion"),
)

#: Words that mark a criterion (id or label) as judging the speech, or the motion itself, when it gives no
#: ``aspect``.
_SPEECH_WORDS = ("sync", "speech", "appropriate", "timing", "rhythm", "semantic", "match", "fit")
_MOTION_WORDS = ("real", "natural", "human", "quality", "smooth", "divers", "plausib", "jitter")


def criterion_aspect(c: Criterion) -> str | None:
    """``"motion"``, ``"speech"`` or None (unknown): the criterion's ``aspect``, else a guess from its words.

    >>> criterion_aspect(Criterion("appropriateness", "Appropriateness", "Which fits the speech?"))
    'speech'
    >>> criterion_aspect(Criterion("human_likeness", "Human-likeness", "Which looks human?"))
    'motion'
    """
    if c.aspect is not None:
        return c.aspect
    words = f"{c.id} {c.label}".lower()
    if any(w in words for w in _SPEECH_WORDS):
        return "speech"
    if any(w in words for w in _MOTION_WORDS):
        return "motion"
    return None


@dataclass(frozen=True)
class Block:
    """One block of trials asked with one response paradigm (``[[blocks]]``).

    A design without ``[[blocks]]`` has one block ``"main"`` of paradigm ``"rank"`` over all its criteria,
    conditions and rotation stimuli: today's study, its schedule and hash unchanged.

    Attributes
    ----------
    id: unique; recorded with every answer.
    paradigm: ``rank`` (three figures ranked 1..3 per criterion), ``pairwise`` (two figures, a preference on
        ``levels`` levels per criterion, optional ``reasons``), ``mismatch`` (the same condition twice: one
        figure moves to the clip's own speech, the other plays the motion made for another clip sharing the
        stimulus's ``match_tag``; a preference as in pairwise) or ``rating`` (every figure on a 0..100 slider
        per criterion, MUSHRA-style, each slider moved before the answer counts).
    criteria, conditions, stimuli: the block's subsets of the design's (ids, in design order).
    instructions: a page shown before the block's first trial ("" = none).
    levels: pairwise/mismatch: 5 (clearly/slightly left, equal, slightly/clearly right) or 3.
    reasons: pairwise: reasons offered when the answer is not "equal" (may be empty).
    match_tag: mismatch: the stimulus tag the mismatched clip shares with the trial's clip.
    reference: rating: a hidden reference condition shown in every trial (None: none).
    anchors: rating: slider labels spread evenly over 0..100 (may be empty).
    """

    id: str
    paradigm: str
    criteria: tuple[str, ...]
    conditions: tuple[str, ...]
    stimuli: tuple[str, ...]
    instructions: str = ""
    levels: int = 5
    reasons: tuple[str, ...] = ()
    match_tag: str = "speaker"
    reference: str | None = None
    anchors: tuple[str, ...] = ()

    @property
    def figures(self) -> tuple[str, ...]:
        """The conditions a trial of the block shows: a rating block's conditions plus its reference."""
        if self.paradigm == "rating" and self.reference is not None and self.reference not in self.conditions:
            return self.conditions + (self.reference,)
        return self.conditions

    @property
    def n_slots(self) -> int:
        """Figures side by side in one trial: 3 rank, 2 pairwise and mismatch, every figure for rating."""
        return {"rank": 3, "pairwise": 2, "mismatch": 2}.get(self.paradigm, len(self.figures))


@dataclass
class Playback:
    """What the participant may do while watching a trial."""

    must_watch_fully: bool = key(BOOL, default=True)     # answers unlock only after the clip played to its end once
    allow_replay: bool = key(BOOL, default=True)         # replay the current clip (never earlier ones)
    allow_ties: bool = key(BOOL, default=False)          # may two slots share a rank
    pause_on_focus_loss: bool = key(BOOL, default=True)  # pause playback when the window loses focus


@dataclass(frozen=True)
class Display:
    """How the figures are shown (``[display]``).

    ``framing``: ``"upper-body"`` (default: hips up, the hands' whole range in view, as large as the window
    allows) or ``"full-body"`` (head to feet). See :mod:`studyapp.render.camera`.
    """

    framing: str = key(STR, default=DEFAULT_FRAMING)


@dataclass
class AttentionCheck:
    """A trial whose correct answer is known, to spot participants who do not watch.

    Rule (documented once, used by the schedule, the media loader and the session):

    * ``kind = "frozen"``: the trial plays ``stimulus`` with the usual three conditions, except that one slot
      shows a *frozen* pose -- the first frame of the condition it replaces, held for the whole clip. That
      slot's condition id is ``"frozen:<replaced id>"``. The participant passes when the frozen slot gets
      rank ``expected["rank"]`` (default 3, i.e. last) on ``expected["criterion"]`` (default realism).
    * ``kind = "known-worst"``: nothing is replaced; ``expected["condition"]`` names a condition known to be
      worst (e.g. a static pose condition) and must get rank ``expected["rank"]`` (default 3) on
      ``expected["criterion"]``.

    With ties allowed, a tie that includes the expected rank counts as a pass.

    Example
    -------
    >>> c = AttentionCheck("clip02", "frozen", {"criterion": "realism", "rank": 3})
    >>> c.passed(("synced", "frozen:lagged", "static"), {"realism": (1, 3, 2)})
    True
    >>> c.passed(("synced", "frozen:lagged", "static"), {"realism": (1, 2, 3)})
    False
    """

    stimulus: str
    kind: str = "frozen"
    expected: dict = field(default_factory=lambda: {"criterion": "realism", "rank": 3})

    @property
    def criterion(self) -> str:
        return str(self.expected.get("criterion", "realism"))

    @property
    def rank(self) -> int:
        return int(self.expected.get("rank", 3))

    def target_slot(self, slots: Sequence[str]) -> int:
        """Index (0 left, 1 middle, 2 right) of the slot whose rank decides the check."""
        for i, cid in enumerate(slots):
            if self.kind == "frozen" and cid.startswith(FROZEN_PREFIX):
                return i
            if self.kind == "known-worst" and cid == self.expected.get("condition"):
                return i
        raise ValueError(f"attention check on {self.stimulus!r}: no deciding slot among {tuple(slots)}")

    def passed(self, slots: Sequence[str], ranks: Mapping[str, Sequence[float]]) -> bool:
        """Did the participant answer as expected? ``ranks[criterion]`` lists ranks per slot (left..right).

        Works for any tie convention (shared minimum rank or averaged rank): the deciding slot's tie group
        covers the positions after the slots ranked strictly better; the check passes when the expected
        rank is one of those positions.
        """
        r = [float(x) for x in ranks[self.criterion]]
        mine = r[self.target_slot(slots)]
        better = sum(x < mine for x in r)
        better_or_equal = sum(x <= mine for x in r)
        return better + 1 <= self.rank <= better_or_equal


@dataclass
class QuestionItem:
    """One questionnaire item, asked after the last trial.

    Kinds (``kind``), and what each stores in the ``value`` column of the results' questionnaire table:

    * ``likert`` (default): ``points`` radio buttons between two ``anchors``; the chosen point 1..points.
      Must be answered. Only these are analysed as numbers; ``scale`` groups them into one construct
      (Cronbach's alpha is computed per scale).
    * ``choice``: one of ``options`` (radio buttons), or with ``multiple = true`` any of them (check
      boxes, at least one); the chosen option's text, or a JSON list of the chosen texts. Must be answered.
    * ``number``: a number typed in, from ``min`` to ``max`` (both required), a whole number when
      ``integer = true`` (e.g. age); the number as text. Must be answered.
    * ``text``: free text, may be left empty.
    """

    id: str = key(STR, required=True)
    kind: str = key(STR)  # one of schema.QUESTION_KINDS; default "likert"
    text: str = key(STR, required=True)
    scale: str | None = key(STR, default=None)
    points: int = key(INT, default=7)
    anchors: tuple[str, str] = key(LIST, default=("Strongly disagree", "Strongly agree"))
    options: tuple[str, ...] = key(LIST, default=())
    multiple: bool = key(BOOL, default=False)
    min: float | None = key(NUM, default=None)
    max: float | None = key(NUM, default=None)
    integer: bool = key(BOOL, default=False)

    @property
    def range_text(self) -> str:
        """A number item's range as a participant reads it: ``"from 18 to 99"``."""
        return f"from {plain_number(self.min)} to {plain_number(self.max)}"

    def check_answer(self, value: object) -> tuple[str | None, str | None]:
        """``(stored value, None)`` for a valid answer, else ``(None, message for the participant)``.

        >>> QuestionItem("age", "number", "Your age?", min=18, max=99, integer=True).check_answer("34")
        ('34', None)
        >>> QuestionItem("age", "number", "Your age?", min=18, max=99, integer=True).check_answer("3.5")[1]
        'Your age?: enter a whole number from 18 to 99'
        >>> QuestionItem("os", "choice", "Which?", options=("a", "b"), multiple=True).check_answer(["b", "a"])
        ('["a", "b"]', None)
        """
        import json
        import math

        if self.kind == "text":
            return ("" if value is None else str(value)), None
        if self.kind == "likert":
            try:
                iv = int(value)  # type: ignore[arg-type]
                ok = float(value) == iv and 1 <= iv <= int(self.points)  # type: ignore[arg-type]
            except (TypeError, ValueError):
                ok = False
            return (str(iv), None) if ok else (None, f"{self.text}: choose a value from 1 to {self.points}")
        if self.kind == "choice":
            if self.multiple:
                chosen = [value] if isinstance(value, str) else list(value or [])
                if chosen and all(c in self.options for c in chosen):
                    return json.dumps([o for o in self.options if o in chosen], ensure_ascii=False), None
                return None, f"{self.text}: choose at least one option"
            return (str(value), None) if value in self.options else (None, f"{self.text}: choose one option")
        lo, hi = self.min, self.max
        span = self.range_text
        try:
            x = float(str(value).strip().replace(",", "."))
        except (TypeError, ValueError):
            x = math.nan
        if self.integer:
            if math.isfinite(x) and x == int(x) and lo <= x <= hi:  # type: ignore[operator]
                return str(int(x)), None
            return None, f"{self.text}: enter a whole number {span}"
        if math.isfinite(x) and lo <= x <= hi:  # type: ignore[operator]
            return plain_number(x), None
        return None, f"{self.text}: enter a number {span}"


def plain_number(x: float | None) -> str:
    """A number as a participant reads it: ``18`` not ``18.0``."""
    return "" if x is None else (str(int(x)) if float(x) == int(x) else repr(float(x)))


@dataclass
class Design:
    """A validated study design (see :func:`load_design`)."""

    path: Path
    title: str
    instructions: str
    conditions: list[Condition]
    stimuli: list[Stimulus]
    criteria: list[Criterion]
    avatar: str = "builtin"
    avatar_by_speaker: dict[str, str] = field(default_factory=dict)
    #: ``[avatar.bone_map]``: avatar joint name -> Unity humanoid bone, for avatars with their own bone names.
    avatar_bone_map: dict[str, str] = field(default_factory=dict)
    ordering: str = "balanced-latin-square"
    slot_assignment: str = "balanced"
    slot_labels: tuple[str, str, str] | None = None
    practice: list[str] = field(default_factory=list)
    attention_checks: list[AttentionCheck] = field(default_factory=list)
    playback: Playback = field(default_factory=Playback)
    display: Display = field(default_factory=Display)
    questionnaire: list[QuestionItem] = field(default_factory=list)
    max_attention_failures: int | None = None
    seed: int = 1
    design_hash: str = ""
    groups: dict[str, str] = field(default_factory=dict)
    #: the first page's consent text and the last page's text after a completed study ("" = built-in)
    consent: str = ""
    completion: str = ""
    #: ``language`` and every built-in participant text after the design's ``[texts]`` (see :mod:`.texts`)
    language: str = "en"
    texts: dict[str, str] = field(default_factory=lambda: dict(EN_TEXTS))
    #: ``[[blocks]]`` as given (empty: one implicit rank block, see :attr:`trial_blocks`)
    blocks: list[Block] = field(default_factory=list)
    #: ``[online]``: the browser study server's settings (abandonment timeout, completion code and URL)
    online: OnlineTable = field(default_factory=OnlineTable)

    def text(self, key: str, **values: object) -> str:
        """The participant text ``key`` in this design's language, its ``{fields}`` filled from ``values``."""
        return fill(self.texts.get(key, EN_TEXTS[key]), **values)

    @property
    def trial_blocks(self) -> list[Block]:
        """The blocks in order: the design's ``[[blocks]]``, else the one implicit ``rank`` block ``"main"``."""
        if self.blocks:
            return list(self.blocks)
        return [Block("main", "rank", tuple(self.criterion_ids), tuple(self.condition_ids),
                      tuple(self.rotation_stimuli), "")]

    def block(self, block_id: str) -> Block:
        """The block of that id (``"main"``: the implicit block of a design without ``[[blocks]]``)."""
        for b in self.trial_blocks:
            if b.id == block_id:
                return b
        raise KeyError(f"no block {block_id!r} in {self.path.name}; have {[b.id for b in self.trial_blocks]}")

    def slot_labels_for(self, n: int) -> tuple[str, ...] | None:
        """The labels of ``n`` slots in the style of ``[slots] labels``: ABC -> A, B, (C, D); 123 -> 1, 2, ...;
        LMR -> L, R for two slots, L, M, R for three, and 1..n beyond; None for ``labels = "none"``.

        >>> Design(Path("x"), "", "", [], [], [], slot_labels=("L", "M", "R")).slot_labels_for(2)
        ('L', 'R')
        """
        base = self.slot_labels
        if base is None:
            return None
        if n == 3:
            return tuple(base)
        if base[0] == "L":
            return ("L", "R") if n == 2 else tuple(str(i + 1) for i in range(n))
        if base[0] == "1":
            return tuple(str(i + 1) for i in range(n))
        return tuple(chr(ord("A") + i) for i in range(n))

    def condition(self, cid: str) -> Condition:
        for c in self.conditions:
            if c.id == cid:
                return c
        raise KeyError(f"no condition {cid!r} in {self.path.name}; have {[c.id for c in self.conditions]}")

    def stimulus(self, sid: str) -> Stimulus:
        for s in self.stimuli:
            if s.id == sid:
                return s
        raise KeyError(f"no stimulus {sid!r} in {self.path.name}; have {[s.id for s in self.stimuli]}")

    @property
    def condition_ids(self) -> list[str]:
        return [c.id for c in self.conditions]

    @property
    def criterion_ids(self) -> list[str]:
        return [c.id for c in self.criteria]

    @property
    def rotation_stimuli(self) -> list[str]:
        """Ids of the stimuli in the balanced order (every stimulus not marked ``in_rotation = false``)."""
        return [s.id for s in self.stimuli if s.in_rotation]

    def avatar_for(self, stimulus: Stimulus | str) -> str:
        """``"builtin"`` or the absolute path of the glTF/VRM avatar for a stimulus (by its speaker tag)."""
        stim = self.stimulus(stimulus) if isinstance(stimulus, str) else stimulus
        name = self.avatar_by_speaker.get(stim.tags.get("speaker", ""), self.avatar)
        return name if name == "builtin" else str(resolve(self, name))


@dataclass
class Problem:
    """One thing wrong with a design: where it is, what is wrong, how to fix it."""

    path: str
    key: str
    message: str
    fix: str = ""
    line: int | None = None

    def __str__(self) -> str:
        where = f"{self.path}:{self.line}" if self.line else self.path
        text = f"{where}: {self.key}: {self.message}" if self.key else f"{where}: {self.message}"
        return f"{text} -- fix: {self.fix}" if self.fix else text

    def to_json(self) -> dict:
        return {"file": self.path, "key": self.key, "line": self.line, "message": self.message, "fix": self.fix}


class DesignWarning(UserWarning):
    """Something a design may do but probably should not (validate prints it as a note; the design runs)."""


class DesignError(InputError):
    """A design has problems; ``problems`` lists all of them, the message shows one per line."""

    def __init__(self, path: str | Path, problems: list[Problem]) -> None:
        self.problems = list(problems)
        n = len(self.problems)
        body = "\n".join(f"  {p}" for p in self.problems)
        super().__init__(path, None, f"{n} problem{'s' if n != 1 else ''} in the design:\n{body}")
