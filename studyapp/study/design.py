"""Study designs: TOML files that say what a study shows, in which order, and what it asks.

A design is read in two passes. The first pass (:func:`validate_design`) collects *every* problem in the
file -- syntax, unknown keys, wrong types, missing or mismatched stimulus files, skeletons that cannot be
retargeted -- so an experimenter fixes them all in one go instead of one per run. Only a design without
problems becomes a :class:`Design` (:func:`load_design`).

The format is documented by example in ``study_designs/example_beat.toml``. Paths in a design are relative
to the design file. A condition's ``motion`` is a pattern: ``{stimulus}`` is replaced by the stimulus id and
``{<tag>}`` by the stimulus's tag of that name (e.g. ``{speaker}``).

Example
-------
>>> from studyapp.resources import demo_design
>>> d = load_design(demo_design())
>>> [c.id for c in d.conditions]
['synced', 'lagged', 'static']
>>> motion_path(d, d.conditions[0], d.stimuli[0]).name
'clip01.bvh'
"""
from __future__ import annotations

import difflib
import hashlib
import json
import math
import os
import re
import string
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

from studyapp.errors import InputError
from studyapp.study.timeline import MOTION_END_CHOICES

# ---------------------------------------------------------------------------------------------------------
# Data classes


@dataclass
class Condition:
    """One model (or source of motion) compared in the study.

    Attributes
    ----------
    id: short name recorded with every answer; never shown to participants.
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
    """

    id: str
    motion: str | None = None
    model: str | None = None
    fps: float | None = None
    representation: str | None = None
    template: str | None = None
    rotation_order: str | None = None
    name_map: dict[str, str] = field(default_factory=dict)
    joints: tuple[str, ...] | None = None
    degrees: bool = True
    motion_end: str | None = None

    @property
    def is_live(self) -> bool:
        """True when the motion comes from an ONNX model run on the stimulus rather than from files."""
        return self.model is not None

    @property
    def is_array(self) -> bool:
        """True when the motion files are NPZ/NPY rotation arrays (read with template, representation, fps)."""
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

    id: str
    audio: Path
    face: Path | None = None
    head: Path | None = None
    tags: dict[str, str] = field(default_factory=dict)
    duration_s: float | None = None
    in_rotation: bool = True


@dataclass
class Criterion:
    """One question the three motions are ranked on (rank 1 = best)."""

    id: str
    label: str
    question: str
    explanation: str


#: The three criteria of the published study; used when a design has no ``[[criteria]]``.
DEFAULT_CRITERIA: tuple[Criterion, ...] = (
    Criterion("realism", "Realism", "Which motion looks most realistic?",
              "Natural human movement: no odd body orientation, no jitter, no frozen or robotic poses."),
    Criterion("synchronization", "Synchronization", "Which motion is best synchronized with the speech?",
              "The gestures follow the rhythm and intonation of the speech: emphasis in the voice comes with "
              "movement, pauses with calm."),
    Criterion("diversity", "Diversity", "Which motion is most diverse?",
              "Rich and varied gestures: not motionless, not the same movement repeated over and over."),
)


@dataclass
class Playback:
    """What the participant may do while watching a trial."""

    must_watch_fully: bool = True   # answers unlock only after the clip played to its end once
    allow_replay: bool = True       # replay the current clip (never earlier ones)
    allow_ties: bool = False        # may two slots share a rank
    pause_on_focus_loss: bool = True  # pause playback when the window loses focus


#: Attention-check kinds and what they show (see :class:`AttentionCheck`).
ATTENTION_KINDS = ("frozen", "known-worst")


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


#: ``model = "builtin:reference"`` runs the reference ONNX model shipped with studyapp.
BUILTIN_REFERENCE = "builtin:reference"

#: Prefix of the pseudo condition id of a frozen attention-check slot.
FROZEN_PREFIX = "frozen:"


@dataclass
class QuestionItem:
    """One questionnaire item, asked after the last trial.

    ``scale`` groups Likert items into one construct (Cronbach's alpha is computed per scale);
    ``anchors`` label the lowest and highest point.
    """

    id: str
    kind: str  # "likert" or "text"
    text: str
    scale: str | None = None
    points: int = 7
    anchors: tuple[str, str] = ("Strongly disagree", "Strongly agree")


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
    ordering: str = "balanced-latin-square"
    slot_assignment: str = "balanced"
    slot_labels: tuple[str, str, str] | None = None
    practice: list[str] = field(default_factory=list)
    attention_checks: list[AttentionCheck] = field(default_factory=list)
    playback: Playback = field(default_factory=Playback)
    questionnaire: list[QuestionItem] = field(default_factory=list)
    max_attention_failures: int | None = None
    seed: int = 1
    design_hash: str = ""
    groups: dict[str, str] = field(default_factory=dict)

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


class DesignError(InputError):
    """A design has problems; ``problems`` lists all of them, the message shows one per line."""

    def __init__(self, path: str | Path, problems: list[Problem]) -> None:
        self.problems = list(problems)
        n = len(self.problems)
        body = "\n".join(f"  {p}" for p in self.problems)
        super().__init__(path, None, f"{n} problem{'s' if n != 1 else ''} in the design:\n{body}")


# ---------------------------------------------------------------------------------------------------------
# Schema: key -> (accepted python types, required, description used in fix hints)

_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")
ORDERINGS = ("balanced-latin-square", "random", "fixed")
SLOT_ASSIGNMENTS = ("balanced", "random")
SLOT_LABELS = {"ABC": ("A", "B", "C"), "LMR": ("L", "M", "R"), "123": ("1", "2", "3"), "none": None}
#: Rotation representations of NPZ/NPY arrays (see studyapp.motion.rotations.to_quat), plus common aliases.
REPRESENTATIONS = ("euler", "axis_angle", "quat", "quat_wxyz", "sixd", "sixd_rows", "matrix")
# "6d"/"rot6d" are left out on purpose: the two 6D layouts cannot be told apart from the numbers, so a
# design must say which one (sixd = Zhou's columns, sixd_rows = PyTorch3D's rows).
_REPR_ALIASES = {"axis-angle": "axis_angle", "axisangle": "axis_angle", "rotvec": "axis_angle",
                 "quaternion": "quat", "quat_xyzw": "quat", "rotmat": "matrix"}
QUESTION_KINDS = ("likert", "text")
MOTION_SUFFIXES = (".bvh", ".npz", ".npy")
AVATAR_SUFFIXES = (".glb", ".gltf", ".vrm")

_STR, _NUM, _INT, _BOOL = (str,), (int, float), (int,), (bool,)
_TOP = {
    "title": (_STR, True), "instructions": (_STR, False), "practice": ((list,), False),
    "conditions": ((list,), True), "stimuli": ((list,), True), "criteria": ((list,), False),
    "avatar": ((dict,), False), "ordering": ((dict,), False), "slots": ((dict,), False),
    "attention_checks": ((list,), False), "playback": ((dict,), False), "questionnaire": ((list,), False),
    "participants": ((dict,), False),
}
_CONDITION = {"id": (_STR, True), "motion": (_STR, False), "model": (_STR, False), "fps": (_NUM, False),
              "representation": (_STR, False), "template": (_STR, False), "rotation_order": (_STR, False),
              "name_map": ((dict,), False), "joints": ((list,), False), "degrees": (_BOOL, False),
              "motion_end": (_STR, False)}
_STIMULUS = {"id": (_STR, True), "audio": (_STR, True), "face": (_STR, False), "head": (_STR, False),
             "tags": ((dict,), False), "duration_s": (_NUM, False), "in_rotation": (_BOOL, False)}
_CRITERION = {"id": (_STR, True), "label": (_STR, False), "question": (_STR, True), "explanation": (_STR, False)}
_AVATAR = {"model": (_STR, False), "by_speaker": ((dict,), False)}
_ORDERING = {"method": (_STR, False), "seed": (_INT, False)}
_SLOTS = {"assignment": (_STR, False), "labels": (_STR, False)}
_ATTENTION = {"stimulus": (_STR, True), "kind": (_STR, False), "criterion": (_STR, False), "rank": (_INT, False),
              "condition": (_STR, False)}
_PLAYBACK = {"must_watch_fully": (_BOOL, False), "allow_replay": (_BOOL, False), "allow_ties": (_BOOL, False),
             "pause_on_focus_loss": (_BOOL, False)}
_QUESTION = {"id": (_STR, True), "kind": (_STR, False), "text": (_STR, True), "scale": (_STR, False),
             "points": (_INT, False), "anchors": ((list,), False)}
_PARTICIPANTS = {"max_attention_failures": (_INT, False), "groups": ((dict,), False)}

_TYPE_NAMES = {str: "a string", int: "an integer", float: "a number", bool: "true or false", list: "a list",
               dict: "a table"}


class _Collector:
    """Gathers problems and points each at the line of its key (tomllib reports no positions)."""

    def __init__(self, path: Path, text: str) -> None:
        self.path = str(path)
        self.lines = text.splitlines()
        self.problems: list[Problem] = []

    def add(self, key: str, message: str, fix: str = "") -> None:
        self.problems.append(Problem(self.path, key, message, fix, self._line_of(key)))

    def _line_of(self, key: str) -> int | None:
        """Best-effort line number of a dotted key like ``stimuli[2].audio`` or ``slots.labels``."""
        parts = re.findall(r"([A-Za-z0-9_\-]+)(?:\[(\d+)\])?", key)
        if not parts:
            return None
        start, end = 0, len(self.lines)
        head, idx = parts[0]
        if idx:  # array of tables: find the idx-th "[[head]]"
            hits = [i for i, ln in enumerate(self.lines) if re.match(rf"^\s*\[\[\s*{re.escape(head)}\s*\]\]", ln)]
            if not hits:  # an inline list (practice = [...]): its element sits on the key's line
                hit = next((i for i, ln in enumerate(self.lines) if re.match(rf"^\s*{re.escape(head)}\s*=", ln)), None)
                return None if hit is None else hit + 1
            if len(hits) <= int(idx):
                return None
            start = hits[int(idx)]
            nxt = [i for i, ln in enumerate(self.lines) if i > start and re.match(r"^\s*\[\[", ln)]
            end = nxt[0] if nxt else end
            if len(parts) == 1:
                return start + 1
            rest = parts[1:]
        else:
            hit = next((i for i, ln in enumerate(self.lines) if re.match(rf"^\s*\[\s*{re.escape(head)}\s*\]", ln)), None)
            if hit is None:
                hit = next((i for i, ln in enumerate(self.lines) if re.match(rf"^\s*{re.escape(head)}\s*=", ln)), None)
            if hit is None:  # a problem with a whole array of tables: point at its first block
                hit = next((i for i, ln in enumerate(self.lines)
                            if re.match(rf"^\s*\[\[\s*{re.escape(head)}\s*\]\]", ln)), None)
                return None if hit is None else hit + 1
            if not re.match(r"^\s*\[", self.lines[hit]):
                return hit + 1
            start = hit
            if len(parts) == 1:
                return start + 1
            rest = parts[1:]
            # The table ends at the next header that is not one of its own sub-tables.
            nxt = [i for i, ln in enumerate(self.lines) if i > start and re.match(r"^\s*\[", ln)
                   and not re.match(rf"^\s*\[\s*{re.escape(head)}\.", ln)]
            end = nxt[0] if nxt else end
        found = start
        for name, _ in rest:  # each deeper part is searched for after the line of the one before
            for i in range(found, end):
                if re.match(rf"^\s*\[?\s*[\w.\-\[]*?{re.escape(name)}\s*[=\]]", self.lines[i]):
                    found = i
                    break
            else:
                break
        return found + 1


def _did_you_mean(word: str, options: Sequence[str]) -> str:
    close = difflib.get_close_matches(word, list(options), n=1, cutoff=0.6)
    return f"did you mean {close[0]!r}?" if close else f"allowed keys: {', '.join(sorted(options))}"


def _check_table(col: _Collector, table: Any, schema: dict, where: str) -> dict:
    """Type-check one table against its schema; returns only the well-typed keys."""
    if not isinstance(table, dict):
        col.add(where, f"must be a table, got {type(table).__name__}", f"write it as [{where}] with key = value lines")
        return {}
    good: dict = {}
    for key, value in table.items():
        kpath = f"{where}.{key}" if where else key
        if key not in schema:
            if where and key in _TOP and not where.startswith(("conditions", "stimuli")):
                # TOML puts every key after a [table] header into that table: a classic slip.
                col.add(kpath, f"unknown key {key!r} in [{where.split('[')[0]}]",
                        f"`{key}` is a top-level key: move it above the first [table] header")
            else:
                col.add(kpath, f"unknown key {key!r}", _did_you_mean(key, schema))
            continue
        types, _ = schema[key]
        ok = isinstance(value, types) and not (bool not in types and isinstance(value, bool))
        if not ok:
            want = " or ".join(_TYPE_NAMES[t] for t in types)
            col.add(kpath, f"must be {want}, got {type(value).__name__} {value!r}"[:200], f"write {key} as {want}")
            continue
        good[key] = value
    for key, (types, required) in schema.items():
        if required and key not in table:
            fix = f"add [[{key}]] blocks (see study_designs/example_beat.toml)" if types == (list,) else f"add {key} = ..."
            col.add(f"{where}.{key}" if where else key, "is required but missing", fix)
    return good


def _check_array(col: _Collector, raw: dict, name: str, schema: dict) -> list[tuple[int, dict]]:
    items = raw.get(name, [])
    out = []
    for i, item in enumerate(items):
        if not isinstance(item, dict):
            col.add(f"{name}[{i}]", "must be a table", f"write each entry as a [[{name}]] block")
            continue
        out.append((i, _check_table(col, item, schema, f"{name}[{i}]")))
    return out


def _check_ids(col: _Collector, name: str, entries: list[tuple[int, dict]], what: str) -> None:
    seen: dict[str, int] = {}
    for i, e in entries:
        ident = e.get("id")
        if ident is None:
            continue
        if not _ID_RE.match(ident):
            col.add(f"{name}[{i}].id", f"{what} id {ident!r} may only hold letters, digits, '_', '-' and '.'",
                    "rename it, e.g. " + repr(re.sub(r"[^A-Za-z0-9_.\-]", "_", ident) or "c1"))
        if ident in seen:
            col.add(f"{name}[{i}].id", f"duplicate {what} id {ident!r} (also {name}[{seen[ident]}])",
                    f"give every {what} its own id")
        else:
            seen[ident] = i


# ---------------------------------------------------------------------------------------------------------
# Paths, patterns and file facts


def resolve(design: Design | Path | str, relpath: str | Path) -> Path:
    """Absolute path of a file named in a design (relative paths are relative to the design file).

    >>> resolve(Path("/studies/a.toml"), "clips/c1.wav").as_posix()
    '/studies/clips/c1.wav'
    """
    base = Path(getattr(design, "path", design)).resolve().parent
    p = Path(os.path.expanduser(str(relpath)))
    return p if p.is_absolute() else (base / p).resolve()


def pattern_fields(pattern: str) -> list[str]:
    """Placeholder names used in a motion pattern (``{stimulus}``, ``{speaker}``, ...)."""
    try:
        return [f for _, f, _, _ in string.Formatter().parse(pattern) if f is not None]
    except ValueError:
        return ["<unbalanced braces>"]


def motion_path(design: Design, condition: Condition | str, stimulus: Stimulus | str) -> Path:
    """The motion file of one condition for one stimulus (the condition's pattern filled in)."""
    cond = design.condition(condition) if isinstance(condition, str) else condition
    stim = design.stimulus(stimulus) if isinstance(stimulus, str) else stimulus
    if cond.motion is None:
        raise ValueError(f"condition {cond.id!r} is a live model ({cond.model}); it has no motion files")
    return resolve(design, cond.motion.format(**{**stim.tags, "stimulus": stim.id}))


def model_path(design: Design, condition: Condition) -> Path:
    """The ONNX file of a live condition (``builtin:reference``: the reference model shipped with studyapp)."""
    if condition.model is None:
        raise ValueError(f"condition {condition.id!r} has motion files, not a live model")
    if condition.model == BUILTIN_REFERENCE:
        from studyapp.models.reference import shipped_reference_model

        return shipped_reference_model()
    return resolve(design, condition.model)


_HASH_CACHE: dict[tuple[str, int, int], str] = {}


def _file_digest(path: Path) -> str:
    try:
        st = path.stat()
    except OSError:
        return "missing"
    if not path.is_file():
        return "not a file"
    key = (str(path), st.st_mtime_ns, st.st_size)
    if key not in _HASH_CACHE:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
        _HASH_CACHE[key] = h.hexdigest()
    return _HASH_CACHE[key]


def _design_hash(design_bytes: bytes, files: dict[str, Path]) -> str:
    """sha256 over the design file and every file it references, so any changed stimulus changes it."""
    h = hashlib.sha256(design_bytes)
    for name in sorted(files):
        h.update(f"\0{name}\0{_file_digest(files[name])}".encode())
    return h.hexdigest()


# ---------------------------------------------------------------------------------------------------------
# Parsing


def _parse(path: Path, check_files: bool) -> tuple[Design | None, list[Problem]]:
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        return None, [Problem(str(path), "", f"cannot read the design file: {exc.strerror or exc}",
                              "check the path")]
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        return None, [Problem(str(path), "", f"not UTF-8 text (byte {exc.start})", "save the file as UTF-8")]
    col = _Collector(path, text)
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"\(at line (\d+), column (\d+)\)", str(exc))
        msg = re.sub(r"\s*\(at line \d+, column \d+\)", "", str(exc))
        line = int(m.group(1)) if m else None
        where = f"line {m.group(1)}, column {m.group(2)}" if m else ""
        return None, [Problem(str(path), where, f"TOML syntax error: {msg}",
                              "see https://toml.io; strings need quotes, tables [name], lists [a, b]", line)]

    top = _check_table(col, raw, _TOP, "")
    conds = _check_array(col, top, "conditions", _CONDITION)
    stims = _check_array(col, top, "stimuli", _STIMULUS)
    crits = _check_array(col, top, "criteria", _CRITERION)
    checks = _check_array(col, top, "attention_checks", _ATTENTION)
    questions = _check_array(col, top, "questionnaire", _QUESTION)
    avatar = _check_table(col, top.get("avatar", {}), _AVATAR, "avatar")
    ordering = _check_table(col, top.get("ordering", {}), _ORDERING, "ordering")
    slots = _check_table(col, top.get("slots", {}), _SLOTS, "slots")
    playback = _check_table(col, top.get("playback", {}), _PLAYBACK, "playback")
    participants = _check_table(col, top.get("participants", {}), _PARTICIPANTS, "participants")
    _check_ids(col, "conditions", conds, "condition")
    _check_ids(col, "stimuli", stims, "stimulus")
    _check_ids(col, "criteria", crits, "criterion")
    _check_ids(col, "questionnaire", questions, "questionnaire item")

    # -- conditions
    conditions: list[Condition] = []
    ids_ok = [e.get("id") for _, e in conds if e.get("id")]
    if "conditions" not in top:
        pass  # reported as a missing required key
    elif len(conds) < 2:
        col.add("conditions", f"{len(conds)} condition(s) given; a comparison needs at least 2, and the "
                "three-slot viewer needs exactly 3", "add [[conditions]] blocks until there are 3")
    elif len(conds) != 3:
        col.add("conditions", f"{len(conds)} conditions given; the three-slot viewer shows exactly 3 per trial",
                "keep exactly 3 [[conditions]] (make one design per set of three models)")
    for i, e in conds:
        key = f"conditions[{i}]"
        if ("motion" in e) == ("model" in e):
            col.add(key, "needs exactly one of `motion` (file pattern) or `model` (ONNX file)"
                    + (", not both" if "motion" in e else ""),
                    'add motion = "motion/<model>/{stimulus}.bvh" or model = "model.onnx"')
        if "fps" in e and not (e["fps"] > 0 and math.isfinite(e["fps"])):
            col.add(f"{key}.fps", f"must be a positive frame rate, got {e['fps']}", "e.g. fps = 15")
        rep = e.get("representation")
        if rep is not None:
            rep = _REPR_ALIASES.get(rep.lower(), rep.lower())
            if rep in ("6d", "rot6d", "rotation_6d"):
                col.add(f"{key}.representation", f"{e['representation']!r} is ambiguous: 6D rotations come in two "
                        "layouts that the numbers cannot tell apart",
                        'representation = "sixd" (Zhou et al.: first two matrix columns) or "sixd_rows" '
                        "(PyTorch3D matrix_to_rotation_6d: first two rows)")
                rep = None
            elif rep not in REPRESENTATIONS:
                col.add(f"{key}.representation", f"unknown rotation representation {e['representation']!r}",
                        _did_you_mean(rep, REPRESENTATIONS).replace("allowed keys", "allowed values"))
        ro = e.get("rotation_order")
        if ro is not None and (not re.fullmatch(r"[XYZ]{3}", ro.upper()) or len(set(ro.upper())) != 3):
            col.add(f"{key}.rotation_order", f"{ro!r} is not an Euler order", 'use three different axes, e.g. "XYZ"')
        motion_end = e.get("motion_end")
        if motion_end is not None and motion_end not in MOTION_END_CHOICES:
            col.add(f"{key}.motion_end", f"unknown motion_end {motion_end!r}",
                    'use "hold" (freeze on the last frame) or "loop" (start again from the first)')
            motion_end = None
        nm = e.get("name_map", {})
        bad = [k for k, v in nm.items() if not isinstance(v, str)]
        for k in bad:
            col.add(f"{key}.name_map.{k}", "must map a joint name to a bone name (a string)", f'{k} = "LeftHand"')
        if "motion" in e:
            fields = pattern_fields(e["motion"])
            if not fields:
                col.add(f"{key}.motion", f"pattern {e['motion']!r} has no {{stimulus}} (or {{tag}}) placeholder, so "
                        "every stimulus would get the same motion file", 'e.g. motion = "motion/model_a/{stimulus}.bvh"')
            if not e["motion"].lower().endswith(MOTION_SUFFIXES):
                col.add(f"{key}.motion", f"motion files must be {', '.join(MOTION_SUFFIXES)}, got {e['motion']!r}",
                        "convert them first (studyapp convert) or fix the pattern's extension")
            if e["motion"].lower().endswith((".npz", ".npy")):
                # Arrays carry neither skeleton, nor rotation layout, nor frame rate: the condition must say.
                if "template" not in e:
                    col.add(f"{key}.template", "NPZ/NPY motion needs a template BVH for its skeleton",
                            'add template = "template.bvh" (a BVH of the skeleton the arrays drive)')
                if "representation" not in e:
                    col.add(f"{key}.representation", "NPZ/NPY motion needs its rotation representation",
                            f'add representation = "axis_angle" (one of {", ".join(REPRESENTATIONS)})')
                if "fps" not in e:
                    col.add(f"{key}.fps", "NPZ/NPY motion carries no frame rate",
                            "add the model's output rate, e.g. fps = 15")
            else:
                for k in ("joints", "degrees", "representation"):
                    if k in e:
                        col.add(f"{key}.{k}", f"`{k}` is for NPZ/NPY motion arrays; {e['motion']!r} is not one",
                                f"remove {k}")
        joints = e.get("joints")
        if joints is not None and (not joints or not all(isinstance(j, str) for j in joints)):
            col.add(f"{key}.joints", "must list template joint names (strings), one per array joint, in order",
                    'e.g. joints = ["Spine", "Spine1", "Neck", ...]')
            joints = None
        if "model" in e and "motion" not in e:
            for k in ("joints", "degrees", "representation", "rotation_order"):
                if k in e:  # a live model declares its own output; a setting here would be silently ignored
                    col.add(f"{key}.{k}", f"`{k}` is for NPZ/NPY motion arrays, not for a live model",
                            f"remove {k} (the model's output is read as its contract declares)")
        if "model" in e and e["model"] != BUILTIN_REFERENCE and not e["model"].lower().endswith(".onnx"):
            col.add(f"{key}.model", f"{e['model']!r} is not an .onnx file", "export the model to ONNX")
        if e.get("id"):
            conditions.append(Condition(
                id=e["id"], motion=e.get("motion"), model=e.get("model"),
                fps=float(e["fps"]) if "fps" in e else None,
                representation=rep, template=e.get("template"),
                rotation_order=ro.upper() if ro else None,
                name_map={k: v for k, v in nm.items() if isinstance(v, str)},
                joints=tuple(joints) if joints else None, degrees=bool(e.get("degrees", True)),
                motion_end=motion_end,
            ))

    # -- stimuli
    stimuli: list[Stimulus] = []
    if "stimuli" in top and not stims:
        col.add("stimuli", "no stimuli", "add [[stimuli]] blocks with id, audio and face")
    for i, e in stims:
        key = f"stimuli[{i}]"
        tags = e.get("tags", {})
        for k, v in tags.items():
            if not isinstance(v, (str, int, float)) or isinstance(v, bool):
                col.add(f"{key}.tags.{k}", "tag values must be strings", f'{k} = "value"')
        if "duration_s" in e and not e["duration_s"] > 0:
            col.add(f"{key}.duration_s", f"must be positive, got {e['duration_s']}", "remove it or give seconds > 0")
        if e.get("id") and "audio" in e:
            stimuli.append(Stimulus(
                id=e["id"], audio=resolve(path, e["audio"]),
                face=resolve(path, e["face"]) if "face" in e else None,
                head=resolve(path, e["head"]) if "head" in e else None,
                tags={k: str(v) for k, v in tags.items() if not isinstance(v, (dict, list, bool))},
                duration_s=float(e["duration_s"]) if "duration_s" in e else None,
                in_rotation=bool(e.get("in_rotation", True)),
            ))
    # Every stimulus that has an id counts as known, even one with another problem (say, no audio): a
    # reference to it from `practice` or an attention check is not a second problem.
    stim_ids = [e["id"] for _, e in stims if e.get("id")]
    if stimuli and not any(s.in_rotation for s in stimuli):
        col.add("stimuli", "every stimulus has in_rotation = false: there are no rated trials",
                "set in_rotation = true (the default) on the clips to be rated")

    # -- criteria
    if "criteria" in top:
        criteria = [Criterion(e["id"], e.get("label", e["id"].capitalize()), e["question"], e.get("explanation", ""))
                    for _, e in crits if e.get("id") and "question" in e]
    else:
        criteria = [replace(c) for c in DEFAULT_CRITERIA]  # copies: an edit to one design must not reach others
    if "criteria" in top and not crits:
        col.add("criteria", "empty list of criteria", "remove `criteria` to use the default three, or add some")
    # As for stimuli: a criterion with a problem of its own is still known by its id to attention checks.
    crit_ids = [e["id"] for _, e in crits if e.get("id")] if "criteria" in top else [c.id for c in criteria]

    # -- avatar
    avatar_default = avatar.get("model", "builtin")
    by_speaker = {}
    for k, v in avatar.get("by_speaker", {}).items():
        if not isinstance(v, str):
            col.add(f"avatar.by_speaker.{k}", "must be \"builtin\" or a glTF/VRM path", f'{k} = "builtin"')
        else:
            by_speaker[k] = v
    speakers = {str(e.get("tags", {}).get("speaker")) for _, e in stims if "speaker" in e.get("tags", {})}
    for k in by_speaker:
        if k not in speakers:
            col.add(f"avatar.by_speaker.{k}", f"no stimulus has tags.speaker = {k!r}",
                    _did_you_mean(k, sorted(x for x in speakers if x)).replace("allowed keys", "speakers"))
    for akey, name in [("avatar.model", avatar_default)] + [(f"avatar.by_speaker.{k}", v) for k, v in by_speaker.items()]:
        if name != "builtin" and not name.lower().endswith(AVATAR_SUFFIXES):
            col.add(akey, f"{name!r} is neither \"builtin\" nor a .glb/.gltf/.vrm file", 'use "builtin" or a glTF file')

    # -- ordering and slots
    method = ordering.get("method", "balanced-latin-square")
    if method not in ORDERINGS:
        col.add("ordering.method", f"unknown ordering {method!r}",
                _did_you_mean(method, ORDERINGS).replace("allowed keys", "allowed values"))
    assignment = slots.get("assignment", "balanced")
    if assignment not in SLOT_ASSIGNMENTS:
        col.add("slots.assignment", f"unknown slot assignment {assignment!r}",
                _did_you_mean(assignment, SLOT_ASSIGNMENTS).replace("allowed keys", "allowed values"))
    labels_raw = slots.get("labels", "ABC")
    if labels_raw not in SLOT_LABELS:
        col.add("slots.labels", f"unknown slot labels {labels_raw!r}", 'use "ABC", "LMR", "123" or "none"')
    labels = SLOT_LABELS.get(labels_raw, ("A", "B", "C"))

    # -- practice and attention checks
    practice = top.get("practice", [])
    for j, sid in enumerate(practice):
        if sid not in stim_ids:
            col.add(f"practice[{j}]", f"unknown stimulus {sid!r}",
                    _did_you_mean(str(sid), stim_ids).replace("allowed keys", "stimuli"))
    attention: list[AttentionCheck] = []
    for i, e in checks:
        key = f"attention_checks[{i}]"
        kind = e.get("kind", "frozen")
        if "stimulus" in e and e["stimulus"] not in stim_ids:
            col.add(f"{key}.stimulus", f"unknown stimulus {e['stimulus']!r}",
                    _did_you_mean(e["stimulus"], stim_ids).replace("allowed keys", "stimuli"))
        if kind not in ATTENTION_KINDS:
            col.add(f"{key}.kind", f"unknown attention check kind {kind!r}", 'use "frozen" or "known-worst"')
        crit = e.get("criterion", "realism")
        if crit not in crit_ids:
            col.add(f"{key}.criterion", f"unknown criterion {crit!r}",
                    _did_you_mean(crit, crit_ids).replace("allowed keys", "criteria"))
        rank = e.get("rank", 3)
        if rank not in (1, 2, 3):
            col.add(f"{key}.rank", f"rank must be 1, 2 or 3, got {rank}", "3 means ranked last")
        expected: dict = {"criterion": crit, "rank": rank}
        if kind == "known-worst":
            if "condition" not in e:
                col.add(f"{key}.condition", "a known-worst check must name the condition expected at `rank`",
                        f'condition = "{ids_ok[-1] if ids_ok else "static"}"')
            elif e["condition"] not in ids_ok:
                col.add(f"{key}.condition", f"unknown condition {e['condition']!r}",
                        _did_you_mean(e["condition"], ids_ok).replace("allowed keys", "conditions"))
            else:
                expected["condition"] = e["condition"]
        elif "condition" in e:
            col.add(f"{key}.condition", "only known-worst checks name a condition (frozen checks replace a slot)",
                    'remove it or set kind = "known-worst"')
        if "stimulus" in e:
            attention.append(AttentionCheck(e["stimulus"], kind, expected))

    # -- questionnaire
    items: list[QuestionItem] = []
    for i, e in questions:
        key = f"questionnaire[{i}]"
        kind = e.get("kind", "likert")
        if kind not in QUESTION_KINDS:
            col.add(f"{key}.kind", f"unknown item kind {kind!r}", 'use "likert" or "text"')
        points = e.get("points", 7 if kind == "likert" else 0)
        if kind == "likert" and not 2 <= points <= 11:
            col.add(f"{key}.points", f"a Likert item needs 2..11 points, got {points}", "e.g. points = 7")
        anchors = e.get("anchors", ["Strongly disagree", "Strongly agree"] if kind == "likert" else ["", ""])
        if len(anchors) != 2 or not all(isinstance(a, str) for a in anchors):
            col.add(f"{key}.anchors", "must be two strings: the labels of the lowest and highest point",
                    'anchors = ["Strongly disagree", "Strongly agree"]')
            anchors = ["", ""]
        if e.get("id") and "text" in e:
            items.append(QuestionItem(e["id"], kind, e["text"], e.get("scale"), points if kind == "likert" else 0,
                                      (anchors[0], anchors[1])))

    # -- participants
    maxfail = participants.get("max_attention_failures")
    if maxfail is not None and maxfail < 0:
        col.add("participants.max_attention_failures", "must be 0 or more", "e.g. 1")
    groups = {}
    for k, v in participants.get("groups", {}).items():
        if isinstance(v, (dict, list)):
            col.add(f"participants.groups.{k}", "group labels must be strings", f'{k} = "v1"')
        else:
            groups[k] = str(v)

    design = Design(
        path=path.resolve(), title=top.get("title", ""), instructions=top.get("instructions", "").strip(),
        conditions=conditions, stimuli=stimuli, criteria=criteria, avatar=avatar_default,
        avatar_by_speaker=by_speaker, ordering=method, slot_assignment=assignment, slot_labels=labels,
        practice=[str(p) for p in practice], attention_checks=attention, playback=Playback(**playback),
        questionnaire=items, max_attention_failures=maxfail, seed=int(ordering.get("seed", 1)), groups=groups,
    )
    for key, cid in visible_text_leaks(design):
        col.add(key, f"participants read this text and it names condition {cid!r}: that unblinds the study",
                "reword the text, or give the condition another id")
    files = referenced_files(design, col)
    if check_files:
        from studyapp.study.stimuli import check_stimulus_files

        # File contents are checked even when the design has other problems, so one run reports them all.
        # A design with problems may be only partly built; should a check trip over that, say so instead of
        # crashing, since fixing the reported problems comes first anyway.
        partial = bool(col.problems)
        try:
            found = check_stimulus_files(design)
        except Exception as exc:
            if not partial:
                raise
            found = [("", f"stimulus files not checked ({type(exc).__name__}: {exc})",
                      "fix the problems above and validate again")]
        for key, message, fix in found:
            col.add(key, message, fix)
    design.design_hash = _design_hash(data, {k: p for k, p in files.items()})
    return design, col.problems


def referenced_files(design: Design, col: _Collector | None = None) -> dict[str, Path]:
    """Every file a design refers to, keyed by the design key it comes from (``stimuli[0].audio``, ...).

    Motion files are keyed ``conditions[i].motion[<stimulus id>]``. With ``col`` given, missing files are
    reported there, one problem per file.
    """
    files: dict[str, Path] = {}
    for i, s in enumerate(design.stimuli):
        files[f"stimuli[{i}].audio"] = s.audio
        if s.face is not None:
            files[f"stimuli[{i}].face"] = s.face
        if s.head is not None:
            files[f"stimuli[{i}].head"] = s.head
    for i, c in enumerate(design.conditions):
        if c.model is not None:
            files[f"conditions[{i}].model"] = model_path(design, c)
        if c.template is not None:
            files[f"conditions[{i}].template"] = resolve(design, c.template)
        if c.motion is not None and pattern_fields(c.motion):
            for s in design.stimuli:
                try:
                    files[f"conditions[{i}].motion[{s.id}]"] = motion_path(design, c, s)
                except (KeyError, IndexError, ValueError) as exc:
                    if col is not None:
                        col.add(f"conditions[{i}].motion", f"pattern {c.motion!r} uses {exc} but stimulus "
                                f"{s.id!r} has no such tag", "add the tag to that stimulus or use only {stimulus}")
    if design.avatar != "builtin":
        files["avatar.model"] = resolve(design, design.avatar)
    for k, v in design.avatar_by_speaker.items():
        if v != "builtin":
            files[f"avatar.by_speaker.{k}"] = resolve(design, v)
    if col is not None:
        for key, p in files.items():
            if not p.is_file():
                what = key.split(".")[-1].split("[")[0]
                if ".motion[" in key:
                    ckey, stim = key[:-1].split(".motion[")
                    cond = design.conditions[int(ckey.split("[")[1].rstrip("]"))].id
                    col.add(f"{ckey}.motion", f"motion file of condition {cond!r} for stimulus {stim!r} not "
                            f"found: {p}", "generate or copy it there, or fix the pattern")
                else:
                    col.add(key, f"{what} file not found: {p}", "fix the path (relative to the design file)")
    return files


def visible_text_leaks(design: Design) -> list[tuple[str, str]]:
    """``(key, condition id)`` for every participant-visible text that names a condition (whole word).

    Slot labels are the design's own neutral names (A/B/C) and are not checked.

    >>> from studyapp.resources import demo_design
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
    >>> conditions_named_in(load_design(demo_design(), check_files=False), "demo_synced-v2.zip")
    ['synced']
    """
    # ids of one or two characters ("a", "B1") are opaque already and would match ordinary words
    return [cond.id for cond in design.conditions if len(cond.id) > 2
            and re.search(rf"(?<![A-Za-z0-9]){re.escape(cond.id)}(?![A-Za-z0-9])", text, flags=re.IGNORECASE)]


def validate_design(path: str | Path, *, check_files: bool = True) -> list[Problem]:
    """Every problem of a design file; an empty list means the design can run.

    ``check_files=False`` skips reading stimulus files (durations, skeletons) but still reports missing ones.

    >>> from studyapp.resources import demo_design
    >>> validate_design(demo_design())
    []
    """
    return _parse(Path(path), check_files)[1]


def load_design(path: str | Path, *, check_files: bool = True) -> Design:
    """Read and validate a design; raises :class:`DesignError` listing all problems."""
    design, problems = _parse(Path(path), check_files)
    if problems or design is None:
        raise DesignError(path, problems)
    return design


def problems_to_json(problems: list[Problem]) -> str:
    return json.dumps([p.to_json() for p in problems], indent=2)
