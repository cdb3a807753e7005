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
* **Neutral condition tokens.** The shipped design has ``k`` conditions ``x1 .. xk``, ``k`` the most
  figures one trial shows (3 for a design without blocks; a rating block's figures; 2 for pairwise and
  mismatch). A shipped trial carries one token per figure it shows, ``x1 .. xn``, and which of its figures
  each token stands for is shuffled independently for every shipped stimulus (a salted permutation), so a
  token means nothing across trials and the conditions carry no design order. The key maps (shipped
  stimulus, token) back to (real stimulus, real condition, sample). Only the motion a trial plays is
  shipped (:func:`~studyapp.study.design.played_pairs`): a condition needs no file for a clip of a block it
  is not in.
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
  (``{x1 = "<hash>", ...}``, every token of its trial) plus ``speaker`` where the avatar depends on it. The
  shipped ``[[blocks]]`` name the tokens their trials carry (``x1 .. xn``), so the shipped design's played
  pairs are exactly its files.
* **Response paradigms.** ``schedule.json`` gives each trial its ``block`` and ``paradigm``; the shipped
  ``[[blocks]]`` keep what the participant's screens need (paradigm, criteria, instructions, levels, reasons,
  anchors) and name tokens and shipped stimuli instead of conditions and clips (no ``reference``: the hidden
  reference is a token like the others; a mismatch block's clips share one constant tag). A token stands
  for (condition, the clip whose motion it plays, sample) within its trial: a mismatch trial has two tokens
  for its one condition, one playing the clip's own motion and one the other clip's. The mismatched motion
  is written as the lab session plays it under this trial (cut, held or looped to the trial's length) and
  named by a salted hash of (condition, source clip, trial clip, sample), so its name links it to no other
  file.
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
the session must score it. A mismatch trial shows two motions of one condition by design (participants are
told so); its mismatched file is a file of its own, but its frames are those of the source clip's file, so
someone comparing the numbers inside BVH files (not their names) could link the two clips' files of that
condition.
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
    #: ``schedule.json``: participant id -> {"row": r, "trials": [[stimulus, [slots], practice, check], ...]};
    #: with ``[[blocks]]`` each trial ends with ``{"block": ..., "paradigm": ...}``
    schedules: dict[str, dict[str, Any]]
    #: key part: shipped stimulus -> {participant, trial_index, stimulus, conditions {token: real},
    #: samples {token: sample}, motions {token: real stimulus whose motion the token plays}}
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
    # one token per figure of the fullest trial (a mismatch trial shows its one condition twice: two)
    any_mismatch = any(b.paradigm == "mismatch" for b in design.trial_blocks)
    toks = tokens(max(_block_tokens(b) for b in design.trial_blocks))
    common, converted = _condition_settings(design, raw)
    if any_mismatch:
        # every motion shipped for a mismatch study is already as long as the trials it plays in (the
        # mismatched ones are written fitted to theirs): "hold" only covers rounding, and tells the
        # participant's validation that shipped clips, which share one match tag, may be of any length
        common.setdefault("motion_end", "hold")
    media: dict[str, bytes] = {}
    origin: dict[str, str] = {}

    def add(data: bytes, suffix: str, label: str, slot: str = "") -> str:
        name = f"media/m_{opaque('file', slot + hashlib.sha256(data).hexdigest(), 12)}{suffix.lower()}"
        media[name] = data
        origin[name] = label
        return name

    motion_names: dict[tuple[str, str, int], str] = {}
    mismatched_names: dict[tuple[str, str, str, int], str] = {}

    def mismatched_file(cond: Condition, source: Stimulus, trial: Stimulus, k: int) -> str:
        """The motion of ``cond`` for ``source`` as it plays under ``trial`` (see the module notes)."""
        got = mismatched_names.get((cond.id, source.id, trial.id, k))
        if got is None:
            slot = f"mismatch\0{cond.id}\0{source.id}\0{trial.id}\0{k}\0"
            label = f"{cond.id} on {source.id} under {trial.id}" + (f" sample {k}" if cond.samples > 1 else "")
            got = add(convert(cond, source, k, _trial_seconds(trial)), ".bvh", label + " (as played)", slot)
            mismatched_names[(cond.id, source.id, trial.id, k)] = got
        return got

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
    block_sids: dict[str, list[str]] = {}
    for pid, row in roster.items():
        entries = []
        for plan in participant_schedule(design, pid, row):
            sid = opaque("trial", f"{pid}\0{plan.trial_index}", 12)
            stim = design.stimulus(plan.stimulus_id)
            sample_of = {cid.removeprefix(FROZEN_PREFIX): k for cid, k in zip(plan.slots, plan.samples)}
            # what each token stands for in this trial: (condition, whose motion, sample)
            figures = _trial_figures(plan, [c.id for c in conds], sample_of)
            random.Random(opaque("tokens", f"{pid}\0{plan.trial_index}", 32)).shuffle(figures)
            real_of = {tok: f[0] for tok, f in zip(toks, figures)}
            motion_of = {tok: f[1] for tok, f in zip(toks, figures)}
            slot_tokens = _slot_tokens(plan, dict(zip(toks, figures)))
            tags: dict[str, str] = {}
            if needs_speaker and "speaker" in stim.tags:
                tags["speaker"] = stim.tags["speaker"]
            for tok, (real, source, k) in zip(toks, figures):
                name = (motion_file(design.condition(real), stim, k) if source == stim.id else
                        mismatched_file(design.condition(real), design.stimulus(source), stim, k))
                tags[tok] = Path(name).stem[len("m_"):]
            if plan.paradigm == "mismatch":
                tags[_MATCH_TAG] = "1"  # every shipped mismatch clip shares it: the shipped block validates
            entry: dict[str, Any] = {"id": sid, "audio": shared_file(stim.audio)}
            if stim.face is not None:
                entry["face"] = shared_file(stim.face)
            if stim.head is not None:
                entry["head"] = shared_file(stim.head)
            if stim.duration_s is not None:
                entry["duration_s"] = stim.duration_s
            entry["tags"] = dict(sorted(tags.items()))
            stimuli[sid] = entry
            # a design with [[blocks]] adds each trial's block and paradigm (one without keeps the old layout)
            entries.append([sid, slot_tokens, bool(plan.is_practice), bool(plan.is_attention_check)]
                           + ([{"block": plan.block, "paradigm": plan.paradigm}] if design.blocks else []))
            trials[sid] = {"participant": pid, "trial_index": plan.trial_index, "stimulus": stim.id,
                           "conditions": real_of, "samples": {tok: f[2] for tok, f in zip(toks, figures)},
                           "motions": motion_of}
            block_sids.setdefault(plan.block, []).append(sid)
            token_of = {real: tok for tok, real in real_of.items()}  # a known-worst check's token (rank trials)
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
    if design.blocks:
        out["blocks"] = [_shipped_block(b, toks, sorted(block_sids.get(b.id, []))) for b in design.blocks]
    if "avatar" in raw:
        av = dict(raw["avatar"])
        if av.get("model", "builtin") != "builtin":
            av["model"] = shared_file(resolve(design, av["model"]))
        if "by_speaker" in av:
            av["by_speaker"] = {k: v if v == "builtin" else shared_file(resolve(design, v))
                                for k, v in av["by_speaker"].items()}
        out["avatar"] = av
    return Shipped(design=out, media=media, origin=origin, schedules=schedules, trials=trials)


#: The tag every shipped mismatch clip carries (one value for all), the shipped mismatch blocks' match_tag.
_MATCH_TAG = "match"


def _block_tokens(block: Any) -> int:
    """Figures one trial of the block shows, so tokens its shipped trials carry: 3 rank, 2 pairwise, 2
    mismatch (its condition on the clip's own motion and on the other clip's), every figure for rating."""
    return {"rank": 3, "pairwise": 2, "mismatch": 2}.get(block.paradigm, len(block.figures))


def _trial_figures(plan: Any, conditions: list[str], sample_of: Mapping[str, int]) -> list[tuple[str, str, int]]:
    """``(condition, stimulus whose motion, sample)`` for each token of a trial, in design order before the
    shuffle: the trial's conditions on its clip (a design without blocks: all three, every trial); a mismatch
    trial's one condition on its own clip and on the other clip. Only what the trial plays is shipped, so a
    condition's motion for a clip no trial plays it on is never needed (see
    :func:`~studyapp.study.design.played_pairs`)."""
    if plan.paradigm == "mismatch":
        own = next(i for i in range(len(plan.slots)) if plan.motion_stimulus(i) == plan.stimulus_id)
        return [(plan.slots[i], plan.motion_stimulus(i), plan.samples[i]) for i in (own, 1 - own)]
    shown = {c.removeprefix(FROZEN_PREFIX) for c in plan.slots}
    return [(c, plan.stimulus_id, sample_of.get(c, 1)) for c in conditions if c in shown]


def _slot_tokens(plan: Any, figure_of: Mapping[str, tuple[str, str, int]]) -> list[str]:
    """The token shown in each slot of the plan (a frozen slot keeps its prefix)."""
    out = []
    for i, c in enumerate(plan.slots):
        bare = c.removeprefix(FROZEN_PREFIX)
        want = (bare, plan.motion_stimulus(i))
        tok = next(t for t, f in figure_of.items() if (f[0], f[1]) == want)
        out.append((FROZEN_PREFIX if c.startswith(FROZEN_PREFIX) else "") + tok)
    return out


def _shipped_block(block: Any, toks: list[str], sids: list[str]) -> dict[str, Any]:
    """A block of the shipped design: what the screens need, tokens and shipped clips for ids (module notes)."""
    # the tokens its trials carry (each shipped trial names tokens x1 .. xn, shuffled over its figures), so
    # the shipped design's played pairs are exactly the shipped motion files
    out: dict[str, Any] = {"id": block.id, "paradigm": block.paradigm, "criteria": list(block.criteria),
                           "conditions": toks[:_block_tokens(block)], "stimuli": sids}
    if block.instructions:
        out["instructions"] = block.instructions
    if block.paradigm in ("pairwise", "mismatch"):
        out["levels"] = block.levels
    if block.paradigm == "pairwise" and block.reasons:
        out["reasons"] = list(block.reasons)
    if block.paradigm == "mismatch":
        out["match_tag"] = _MATCH_TAG
    if block.paradigm == "rating" and block.anchors:
        out["anchors"] = list(block.anchors)
    return out


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
    """The joints of the condition's skeleton, read from its first clip some trial plays (a condition of a
    block has files only for that block's clips); none for a condition no trial shows."""
    from studyapp.study.design import played_pairs
    from studyapp.study.stimuli import load_condition_motion

    clips = played_pairs(design)[cond.id]
    if not clips:
        return set()
    motion = load_condition_motion(design, cond, design.stimulus(clips[0]))
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
