"""The blinded design a bundle ships: one opaque stimulus per participant and trial, neutral condition tokens.

What a remote participant's PC receives must not let anyone group one model's files across clips -- not a
file name, a tag, the order of a list or a key that only some conditions have. This module builds, from the
lab design and the bundle's roster, everything inside the zip that describes the study, plus the *key* that
maps it back (kept by the experimenter):

* **Trials, not stimuli.** Each (roster participant, trial) of the real schedule
  (:func:`studyapp.study.schedule.participant_schedule`, computed here in the lab) becomes its own shipped
  stimulus with an opaque id (a salted hash of participant and trial index). ``schedule.json`` lists each
  participant's trials in order -- shipped stimulus, slots, practice and attention-check flags -- and the
  participant's session plays exactly that list, so the slots shown are the real schedule.
* **Neutral condition tokens.** The shipped design has ``k`` conditions ``x1 .. xk`` (``k`` real ones);
  which real condition each token stands for is shuffled independently for every shipped stimulus (a salted
  permutation), so a token means nothing across trials and the conditions carry no design order. The key
  maps (shipped stimulus, token) back to (real stimulus, real condition, sample).
* **The same keys for every condition.** Each token condition is ``{id, motion = "media/m_{xi}.bvh"}`` and
  only keys whose value is the same for every real condition (an ``fps`` or ``motion_end`` all of them set
  alike, the union of the conditions' ``name_map`` when it changes no condition's own mapping). Motion that
  is not a plain BVH file played as it is -- NPZ/NPY arrays (``template``, ``representation``, ``fps`` ...),
  SMPL files on the lab's body model, live models, BVH read with an ``fps`` override the others do not
  share, and motion whose ``motion_end`` the others do not share -- is converted before bundling to BVH: the
  frames the lab session plays, on the skeleton it plays them on (cut to the trial and with the end rule
  applied, where the end rule is not shared).
* **Media names.** A motion file is named by a salted hash of (real condition, real stimulus, sample and its
  bytes), so equal bytes used by two clips still get two names, and the same file serves every participant
  who sees that condition on that clip: a name never links two clips of one model, and the zip holds each
  file once. Audio, face and head files are named by a salted hash of their bytes (shared by the trials of
  one clip; they are the same for every condition). A shipped stimulus's tags are the tokens' file hashes
  (``{x1 = "<hash>", ...}``, every token on every stimulus) plus ``speaker`` where the avatar depends on it.
* **No schedule inputs.** The shipped design has no ``seed``, ``ordering``, ``slot_assignment``,
  ``practice`` or stimulus order (stimuli are listed by opaque id); attention checks name their shipped
  trial and, for a ``known-worst`` check, that trial's token of the known-worst condition.

What this does not hide, stated plainly: which design position sits in which slot is public arithmetic of
the row and the trial's place (:mod:`studyapp.study.ordering`), and the row is in ``schedule.json``; the seed
enters only with ``random`` ordering or slot assignment. Someone who reads studyapp's source and that file can
group the figures of one model across their own trials (not name the model). A secret row would not help:
motion files shared by several participants' trials give it away once two of them are compared. With random
ordering or slots a small seed can be found by trying every one; ``bundle`` says so then (see
:func:`seed_matters`).
A ``known-worst`` attention check tells which file of that one check clip is the known-worst condition, as
the session must score it.
"""
from __future__ import annotations

import hashlib
import random
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from studyapp.errors import InputError
from studyapp.study.design import FROZEN_PREFIX, Condition, Design, Stimulus

#: Top-level design keys the shipped design leaves out: the schedule's inputs and the lists rebuilt here.
_DROPPED = ("conditions", "stimuli", "practice", "attention_checks", "seed", "ordering", "ordering_version",
            "slot_assignment")
#: A seed below this can be found by trying every one (see the module notes).
SAFE_SEED = 2 ** 40


def seed_matters(design: Design) -> bool:
    """Whether the design's seed enters the schedule: only ``random`` ordering or slot assignment draw from it
    (balanced ones are arithmetic of the row, see :mod:`studyapp.study.ordering`)."""
    return design.ordering == "random" or design.slot_assignment == "random"


@dataclass
class Shipped:
    """Everything inside a bundle that describes the study, and the key that maps it back."""

    #: the shipped ``study.toml`` as a TOML table
    design: dict[str, Any]
    #: bundle name (``media/m_<hex>.<ext>``) -> bytes
    media: dict[str, bytes]
    #: bundle name -> where the file came from (for the key)
    origin: dict[str, str]
    #: ``schedule.json``: participant id -> {"row": r, "trials": [[stimulus, [slots], practice, check], ...]}
    schedules: dict[str, dict[str, Any]]
    #: key part: shipped stimulus -> {participant, trial_index, stimulus, conditions {token: real},
    #: samples {token: sample}}
    trials: dict[str, dict[str, Any]] = field(default_factory=dict)


def tokens(n: int) -> list[str]:
    """The shipped condition ids: ``x1 .. xn``, meaning nothing across trials."""
    return [f"x{i + 1}" for i in range(n)]


def ship_design(design: Design, raw: Mapping[str, Any], roster: Mapping[str, int], salt: str,
                convert: Callable[[Condition, Stimulus, int, float | None], bytes]) -> Shipped:
    """The blinded design for ``roster`` (participant id -> design row); see the module notes.

    ``convert(condition, stimulus, sample, fit_to)`` returns BVH bytes of the motion the lab session plays
    (``fit_to``: cut to that many seconds with the condition's ``motion_end`` applied, else None).
    """
    from studyapp.study.design import motion_path, resolve
    from studyapp.study.schedule import participant_schedule

    def opaque(kind: str, text: str, n: int) -> str:
        return hashlib.sha256(f"{salt}\0{kind}\0{text}".encode()).hexdigest()[:n]

    conds = list(design.conditions)
    toks = tokens(len(conds))
    common, converted = _condition_settings(design, raw)
    media: dict[str, bytes] = {}
    origin: dict[str, str] = {}

    def add(data: bytes, suffix: str, label: str, slot: str = "") -> str:
        name = f"media/m_{opaque('file', slot + hashlib.sha256(data).hexdigest(), 12)}{suffix.lower()}"
        media[name] = data
        origin[name] = label
        return name

    motion_names: dict[tuple[str, str, int], str] = {}

    def motion_file(cond: Condition, stim: Stimulus, k: int) -> str:
        got = motion_names.get((cond.id, stim.id, k))
        if got is None:
            slot = f"motion\0{cond.id}\0{stim.id}\0{k}\0"
            if cond.id in converted:
                fit = _trial_seconds(stim) if converted[cond.id] == "fit" else None
                label = f"{cond.id} on {stim.id}" + (f" sample {k}" if cond.samples > 1 else "") + " (as played)"
                got = add(convert(cond, stim, k, fit), ".bvh", label, slot)
            else:
                path = motion_path(design, cond, stim, k)
                got = add(path.read_bytes(), ".bvh", str(path), slot)
            motion_names[(cond.id, stim.id, k)] = got
        return got

    shared: dict[Path, str] = {}

    def shared_file(path: Path) -> str:
        if path not in shared:
            shared[path] = add(path.read_bytes(), path.suffix, str(path))
        return shared[path]

    needs_speaker = bool(raw.get("avatar", {}).get("by_speaker")) if isinstance(raw.get("avatar"), dict) else False
    stimuli: dict[str, dict[str, Any]] = {}
    trials: dict[str, dict[str, Any]] = {}
    schedules: dict[str, dict[str, Any]] = {}
    checks_raw = list(raw.get("attention_checks", []))
    checks: list[dict[str, Any]] = []
    for pid, row in roster.items():
        entries = []
        for plan in participant_schedule(design, pid, row):
            sid = opaque("trial", f"{pid}\0{plan.trial_index}", 12)
            order = [c.id for c in conds]
            random.Random(opaque("tokens", f"{pid}\0{plan.trial_index}", 32)).shuffle(order)
            real_of = dict(zip(toks, order))
            token_of = {real: tok for tok, real in real_of.items()}
            sample_of = {cid.removeprefix(FROZEN_PREFIX): k for cid, k in zip(plan.slots, plan.samples)}
            stim = design.stimulus(plan.stimulus_id)
            tags: dict[str, str] = {}
            if needs_speaker and "speaker" in stim.tags:
                tags["speaker"] = stim.tags["speaker"]
            for tok, real in real_of.items():
                name = motion_file(design.condition(real), stim, sample_of.get(real, 1))
                tags[tok] = Path(name).stem[len("m_"):]
            entry: dict[str, Any] = {"id": sid, "audio": shared_file(stim.audio)}
            if stim.face is not None:
                entry["face"] = shared_file(stim.face)
            if stim.head is not None:
                entry["head"] = shared_file(stim.head)
            if stim.duration_s is not None:
                entry["duration_s"] = stim.duration_s
            entry["tags"] = dict(sorted(tags.items()))
            stimuli[sid] = entry
            slots = [(FROZEN_PREFIX if c.startswith(FROZEN_PREFIX) else "") + token_of[c.removeprefix(FROZEN_PREFIX)]
                     for c in plan.slots]
            entries.append([sid, slots, bool(plan.is_practice), bool(plan.is_attention_check)])
            trials[sid] = {"participant": pid, "trial_index": plan.trial_index, "stimulus": stim.id,
                           "conditions": real_of, "samples": {tok: sample_of.get(real, 1)
                                                              for tok, real in real_of.items()}}
            if plan.is_attention_check:
                check = next(i for i, c in enumerate(design.attention_checks) if c.stimulus == plan.stimulus_id)
                c_raw = dict(checks_raw[check])
                c_raw["stimulus"] = sid
                if "condition" in c_raw:
                    c_raw["condition"] = token_of[c_raw["condition"]]
                checks.append(c_raw)
        schedules[pid] = {"row": int(row), "trials": entries}

    out = {k: v for k, v in raw.items() if k not in _DROPPED}
    out["conditions"] = [{"id": tok, "motion": f"media/m_{{{tok}}}.bvh", **common} for tok in toks]
    out["stimuli"] = [stimuli[sid] for sid in sorted(stimuli)]
    if checks:
        out["attention_checks"] = sorted(checks, key=lambda c: c["stimulus"])
    if "avatar" in raw:
        av = dict(raw["avatar"])
        if av.get("model", "builtin") != "builtin":
            av["model"] = shared_file(resolve(design, av["model"]))
        if "by_speaker" in av:
            av["by_speaker"] = {k: v if v == "builtin" else shared_file(resolve(design, v))
                                for k, v in av["by_speaker"].items()}
        out["avatar"] = av
    return Shipped(design=out, media=media, origin=origin, schedules=schedules, trials=trials)


def _trial_seconds(stim: Stimulus) -> float:
    from studyapp.study.stimuli import load_audio
    from studyapp.study.timeline import trial_duration

    return float(trial_duration(stim.duration_s, load_audio(stim.audio).duration))


def _condition_settings(design: Design, raw: Mapping[str, Any]) -> tuple[dict[str, Any], dict[str, str]]:
    """The keys every token condition carries, and the conditions whose motion is converted before bundling
    (``"plain"``: written as BVH as played; ``"fit"``: also cut to the trial with its own ``motion_end``)."""
    conds = list(design.conditions)
    ends = {c.motion_end for c in conds}
    rates = {c.fps for c in conds}
    common: dict[str, Any] = {}
    converted: dict[str, str] = {}
    for c in conds:
        # an fps every condition shares stays a key of all of them; one of a few is written into its files
        if c.model is not None or c.body_model is not None or c.is_array or (len(rates) > 1 and c.fps is not None):
            converted[c.id] = "plain"
        if len(ends) > 1 and c.motion_end is not None:
            converted[c.id] = "fit"
    if len(rates) == 1 and None not in rates:
        common["fps"] = next(iter(rates))
    if len(ends) == 1 and None not in ends:
        common["motion_end"] = next(iter(ends))
    union: dict[str, str] = {}
    for c in conds:
        for src, bone in c.name_map.items():
            if union.setdefault(src, bone) != bone:
                raise InputError(design.path, f"conditions.{c.id}.name_map.{src}",
                                 f"maps {src!r} to {bone!r} where another condition maps it to {union[src]!r}; a "
                                 "bundle gives every condition the same keys (so none can be told apart), so "
                                 "the conditions' name maps must agree on every joint they share")
    if union:
        for c in conds:
            extra = sorted(set(union) - set(c.name_map))
            if extra:
                names = _joint_names(design, c)
                clash = [j for j in extra if j in names]
                if clash:
                    raise InputError(design.path, f"conditions.{c.id}.name_map",
                                     f"another condition's name map names joint {clash[0]!r}, which this "
                                     "condition's skeleton has but does not map; a bundle gives every condition "
                                     f"the same name map, so add {clash[0]!r} to this condition's name_map")
        common["name_map"] = dict(sorted(union.items()))
    return common, converted


def _joint_names(design: Design, cond: Condition) -> set[str]:
    from studyapp.study.stimuli import load_condition_motion

    motion = load_condition_motion(design, cond, design.stimuli[0])
    return set(motion.skeleton.names)


def converter(design: Design) -> Callable[[Condition, Stimulus, int, float | None], bytes]:
    """``convert`` for :func:`ship_design`: the motion the lab session plays, written as BVH."""
    from studyapp.motion.bvh import write_bvh
    from studyapp.study.stimuli import load_condition_motion
    from studyapp.study.timeline import fit_motion

    def convert(cond: Condition, stim: Stimulus, k: int, fit_to: float | None) -> bytes:
        motion = load_condition_motion(design, cond, stim, k)
        if fit_to is not None:
            motion = fit_motion(motion, fit_to, cond.motion_end)
        with tempfile.TemporaryDirectory(prefix="studyapp-bundle-") as tmp:
            path = Path(tmp) / "motion.bvh"
            write_bvh(motion, path)
            return path.read_bytes()

    return convert
