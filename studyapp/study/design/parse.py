"""Read a design file: every problem in one pass, each pointing at its line, then the :class:`Design`.

The keys each table accepts, and their defaults, come from the classes that declare them
(:mod:`.schema`, :mod:`.model`); this module checks values and how they refer to each other.
"""
from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

from studyapp import tomlfile
from studyapp.motion.rotations import REPRESENTATIONS as _REPRESENTATION_WIDTHS
from studyapp.study.design.blinding import visible_text_leaks
from studyapp.study.design.checks import Collector, check_array, check_ids, check_table, did_you_mean
from studyapp.study.design.files import (design_hash, has_sample_field, pattern_fields, pattern_problem, referenced_files,
                                         resolve)
from studyapp.study.design.model import (DEFAULT_CRITERIA, AttentionCheck, Block, Condition, Criterion, Design,
                                             DesignWarning, Display, Playback, Problem, QuestionItem, Stimulus,
                                             criterion_aspect)
from studyapp.study.design.schema import (ASPECTS, ATTENTION_KINDS, AVATAR_SUFFIXES, BUILTIN_REFERENCE,
                                              MOTION_SUFFIXES, ORDERINGS, PARADIGMS, PREFERENCE_LEVELS,
                                              QUESTION_KINDS, RATING_FIGURES, SLOT_ASSIGNMENTS,
                                              SLOT_LABELS, AttentionCheckTable, AvatarTable, BlockTable,
                                              DesignFile, OnlineTable, OrderingTable, ParticipantsTable, SlotsTable,
                                              key_default)
from studyapp.study.design.texts import LANGUAGES, language_code
from studyapp.study.design.texts import fields as text_fields
from studyapp.study.design.texts import table as texts_table
from studyapp.study.timeline import MOTION_END_CHOICES

#: Rotation representations of NPZ/NPY arrays (those :mod:`studyapp.motion.rotations` reads).
REPRESENTATIONS = tuple(_REPRESENTATION_WIDTHS)
# "6d"/"rot6d" are left out on purpose: the two 6D layouts cannot be told apart from the numbers, so a
# design must say which one (sixd = Zhou's columns, sixd_rows = PyTorch3D's rows).
_REPR_ALIASES = {"axis-angle": "axis_angle", "axisangle": "axis_angle", "rotvec": "axis_angle",
                 "quaternion": "quat", "quat_xyzw": "quat", "rotmat": "matrix"}
#: Every table of a design file and the class declaring its keys ("" is the top level).
TABLES: dict[str, type] = {"": DesignFile, "conditions": Condition, "stimuli": Stimulus, "criteria": Criterion,
                           "avatar": AvatarTable, "ordering": OrderingTable, "slots": SlotsTable,
                           "attention_checks": AttentionCheckTable, "playback": Playback,
                           "questionnaire": QuestionItem, "participants": ParticipantsTable,
                           "display": Display, "blocks": BlockTable, "online": OnlineTable}


# ---------------------------------------------------------------------------------------------------------
# One function per part of the design


def _conditions(col: Collector, top: dict, conds: list[tuple[int, dict]]) -> list[Condition]:
    conditions: list[Condition] = []
    if "conditions" not in top:
        pass  # reported as a missing required key
    elif top.get("blocks"):  # each block checks how many of the conditions it shows (see _blocks)
        if not conds:
            col.add("conditions", "no conditions", "add [[conditions]] blocks")
    elif len(conds) < 2:
        col.add("conditions", f"{len(conds)} condition(s) given; a comparison needs at least 2, and the "
                "three-slot viewer needs exactly 3", "add [[conditions]] blocks until there are 3")
    elif len(conds) != 3:
        col.add("conditions", f"{len(conds)} conditions given; the three-slot viewer shows exactly 3 per trial",
                "keep exactly 3 [[conditions]] (make one design per set of three models)")
    for i, e in conds:
        cond = parse_condition(col, f"conditions[{i}]", e)
        if cond is not None:
            conditions.append(cond)
    _labels(col, conds)
    return conditions


def _labels(col: Collector, conds: list[tuple[int, dict]]) -> None:
    """Each condition's ``label``: one line of text, and the names the analysis shows (label, else id) unique,
    so no two rows of a results table can read the same."""
    seen: dict[str, tuple[int, bool]] = {}  # folded name -> (index, whether it is a label)
    for i, e in conds:
        label = e.get("label")
        if label is not None and not label.strip():
            col.add(f"conditions[{i}].label", "is empty", "write the name the analysis should show, or remove label")
            continue
        if label is not None and any(ch < " " or ch == "\x7f" for ch in label):
            col.add(f"conditions[{i}].label", f"{label!r} holds a line break or control character",
                    "write the label on one line (it heads table rows and figure axes)")
            continue
        name = (label if label is not None else e.get("id") or "").strip()
        if not name:
            continue
        folded = name.casefold()
        if folded in seen and (label is not None or seen[folded][1]):  # two ids alike: check_ids' concern
            j = seen[folded][0]
            col.add(f"conditions[{i}].label" if label is not None else f"conditions[{i}].id",
                    f"{name!r} names conditions[{j}] too (as its label or id, ignoring case), so the analysis "
                    "could not tell the two apart", "give every condition its own label")
        elif folded not in seen:
            seen[folded] = (i, label is not None)


def parse_condition(col: Collector, key: str, e: dict, *, pattern: bool = True) -> Condition | None:
    """One well-typed ``[[conditions]]`` table (``e``) checked and turned into a :class:`Condition`; problems
    go to ``col`` under ``key``. ``pattern`` False: ``motion`` names one file, not a pattern."""
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
                    did_you_mean(rep, REPRESENTATIONS).replace("allowed keys", "allowed values"))
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
        fields = pattern_fields(e["motion"]) if pattern else ["stimulus"]
        problem = pattern_problem(e["motion"]) if pattern else None
        if problem is not None:
            col.add(f"{key}.motion", f"pattern {e['motion'][:120]!r}: {problem}",
                    'use only {stimulus}, {sample} and tag names in braces, e.g. motion = "motion/model_a/{stimulus}.bvh"')
        elif not fields:
            col.add(f"{key}.motion", f"pattern {e['motion']!r} has no {{stimulus}} (or {{tag}}) placeholder, so "
                    "every stimulus would get the same motion file", 'e.g. motion = "motion/model_a/{stimulus}.bvh"')
        if not e["motion"].lower().endswith(MOTION_SUFFIXES):
            col.add(f"{key}.motion", f"motion files must be {', '.join(MOTION_SUFFIXES)}, got {e['motion']!r}",
                    "convert them first (studyapp convert) or fix the pattern's extension")
        if e["motion"].lower().endswith((".npz", ".npy")):
            # Raw arrays carry neither skeleton, nor rotation layout, nor frame rate; SMPL-family files carry all
            # three. Only reading a file tells them apart: a design's pattern is checked file by file by
            # stimuli.check_stimulus_files, one named file (`view`) here.
            if not pattern and not is_smpl_file(Path(e["motion"])):
                for problem in missing_array_settings(key, *(e.get(k) for k in ("template", "representation", "fps"))):
                    col.add(*problem)
        else:
            for k in ("joints", "degrees", "representation", "body_model"):
                if k in e:
                    col.add(f"{key}.{k}", f"`{k}` is for NPZ/NPY motion arrays; {e['motion']!r} is not one",
                            f"remove {k}")
    samples = _samples(col, key, e) if pattern else 1  # one named file (`view`) has no samples
    joints = e.get("joints")
    if joints is not None and (not joints or not all(isinstance(j, str) for j in joints)):
        col.add(f"{key}.joints", "must list template joint names (strings), one per array joint, in order",
                'e.g. joints = ["Spine", "Spine1", "Neck", ...]')
        joints = None
    if "model" in e and "motion" not in e:
        for k in ("joints", "degrees", "representation", "rotation_order", "body_model"):
            if k in e:  # a live model declares its own output; a setting here would be silently ignored
                col.add(f"{key}.{k}", f"`{k}` is for NPZ/NPY motion arrays, not for a live model",
                        f"remove {k} (the model's output is read as its contract declares)")
    if "model" in e and e["model"] != BUILTIN_REFERENCE and not e["model"].lower().endswith(".onnx"):
        col.add(f"{key}.model", f"{e['model']!r} is not an .onnx file", "export the model to ONNX")
    if e.get("id"):
        return Condition(
            id=e["id"], label=e["label"].strip() if e.get("label", "").strip() else None, motion=e.get("motion"), model=e.get("model"),
            fps=float(e["fps"]) if "fps" in e else None,
            representation=rep, template=e.get("template"),
            rotation_order=ro.upper() if ro else None,
            name_map={k: v for k, v in nm.items() if isinstance(v, str)},
            joints=tuple(joints) if joints else None, degrees=bool(e.get("degrees", key_default(Condition, "degrees"))),
            motion_end=motion_end,
            body_model=e.get("body_model"), samples=samples,
        )
    return None


def _samples(col: Collector, key: str, e: dict) -> int:
    """The condition's ``samples`` (1 when absent or wrong), checked against its pattern's ``{sample}``."""
    samples = e.get("samples", key_default(Condition, "samples"))
    has_field = "motion" in e and has_sample_field(e["motion"])
    if samples < 1:
        col.add(f"{key}.samples", f"must be 1 or more, got {samples}", "the number of motion files per stimulus, e.g. 5")
        return 1
    if "model" in e and "samples" in e and "motion" not in e:
        col.add(f"{key}.samples", "a live model gives one motion per stimulus; `samples` is for motion files",
                "remove samples")
        return 1
    if samples > 1 and "motion" in e and not has_field:
        col.add(f"{key}.samples", f"samples = {samples} but the pattern {e['motion']!r} has no {{sample}} "
                "placeholder, so every sample would be the same file",
                'put {sample} (1..samples) in the pattern, e.g. motion = "gen/{stimulus}/sample_{sample}.npz"')
    if has_field and "samples" not in e:
        col.add(f"{key}.motion", f"pattern {e['motion']!r} has a {{sample}} placeholder but the condition gives no "
                "`samples`", "add samples = N (how many files per stimulus; {sample} takes 1..N)")
    return samples


def is_smpl_file(path: Path) -> bool:
    """Whether an NPZ/NPY motion file is an SMPL-family file, which carries its own skeleton, layout and rate."""
    from studyapp.motion.smpl import recognise_smpl

    return path.is_file() and recognise_smpl(path) is not None


def missing_array_settings(key: str, template: Any, representation: Any, fps: Any) -> list[tuple[str, str, str]]:
    """``(key, message, fix)`` for each setting a raw rotation array's condition lacks (``None``): arrays carry
    no skeleton, rotation layout or frame rate."""
    out = []
    if template is None:
        out.append((f"{key}.template", "NPZ/NPY motion that is not an SMPL/SMPL-H/SMPL-X file needs a template "
                    "BVH for its skeleton", 'add template = "template.bvh" (a BVH of the skeleton the arrays drive)'))
    if representation is None:
        out.append((f"{key}.representation", "NPZ/NPY motion needs its rotation representation",
                    f'add representation = "axis_angle" (one of {", ".join(REPRESENTATIONS)})'))
    if fps is None:
        out.append((f"{key}.fps", "NPZ/NPY motion carries no frame rate", "add the model's output rate, e.g. fps = 15"))
    return out


def condition_from_settings(settings: dict[str, Any], source: str | Path) -> tuple[Condition | None, list[Problem]]:
    """A condition from settings given outside a design file (``studyapp view``'s options), with the
    checks and meaning of a ``[[conditions]]`` table whose ``motion`` names one file, not a pattern.

    Returns the condition (None when unusable) and the problems, keyed by the setting (``fps``, ...).

    >>> cond, problems = condition_from_settings({"motion": "out.npy", "representation": "6d"}, "out.npy")
    >>> [p.key for p in problems]
    ['representation', 'template', 'fps']
    >>> condition_from_settings({"motion": "a.bvh", "rotation_order": "zyx"}, "a.bvh")[0].rotation_order
    'ZYX'
    """
    col = Collector(Path(source), "")
    entry = check_table(col, {"id": "view", **settings}, Condition, "view")
    cond = parse_condition(col, "view", entry, pattern=False)
    for p in col.problems:
        p.key = p.key.removeprefix("view").removeprefix(".")
    return cond, col.problems


def _stimuli(col: Collector, top: dict, stims: list[tuple[int, dict]], path: Path) -> list[Stimulus]:
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
                in_rotation=bool(e.get("in_rotation", key_default(Stimulus, "in_rotation"))),
            ))
    if stimuli and not any(s.in_rotation for s in stimuli):
        col.add("stimuli", "every stimulus has in_rotation = false: there are no rated trials",
                "set in_rotation = true (the default) on the clips to be rated")
    return stimuli


def _texts(col: Collector, language: str, overrides: dict) -> dict[str, str]:
    """The design's participant texts: its language's table with ``[texts]`` laid over it (checked)."""
    if language not in LANGUAGES:
        col.add("language", f"no built-in texts for language {language!r}",
                "use " + " or ".join(f'"{k}"' for k in LANGUAGES) + " (and [texts] for anything else)")
    base = texts_table(language)
    out = {}
    for k, v in overrides.items():
        if k not in base:
            col.add(f"texts.{k}", f"unknown text key {k!r}",
                    did_you_mean(k, list(base)).replace("allowed keys", "text keys"))
        elif not isinstance(v, str):
            col.add(f"texts.{k}", "must be a string", f'"{k}" = "..."')
        elif text_fields(v) != text_fields(base[k]):
            want = ", ".join(f"{{{f}}}" for f in sorted(text_fields(base[k]))) or "no {fields}"
            col.add(f"texts.{k}", f"must hold the same fields as the built-in text ({want})",
                    f"the built-in text is: {base[k]!r}")
        else:
            out[k] = v
    return {**base, **out}


def _criteria(col: Collector, top: dict, crits: list[tuple[int, dict]],
              texts: dict[str, str] | None = None) -> list[Criterion]:
    if "criteria" not in top and texts is not None:
        # the default three, worded in the design's language
        return [Criterion(c.id, texts[f"criteria.{c.id}.label"], texts[f"criteria.{c.id}.question"],
                          texts[f"criteria.{c.id}.explanation"], aspect=c.aspect) for c in DEFAULT_CRITERIA]
    if "criteria" in top:
        for i, e in crits:
            if e.get("aspect") is not None and e["aspect"] not in ASPECTS:
                col.add(f"criteria[{i}].aspect", f"unknown aspect {e['aspect']!r}",
                        'use "motion" (realism, human-likeness) or "speech" (appropriateness, synchronization)')
        criteria = [Criterion(e["id"], e.get("label", e["id"].capitalize()), e["question"],
                              e.get("explanation", key_default(Criterion, "explanation")),
                              e.get("aspect") if e.get("aspect") in ASPECTS else None)
                    for _, e in crits if e.get("id") and "question" in e]
    else:
        criteria = [replace(c) for c in DEFAULT_CRITERIA]  # copies: an edit to one design must not reach others
    if "criteria" in top and not crits:
        col.add("criteria", "empty list of criteria", "remove `criteria` to use the default three, or add some")
    return criteria


def _avatar(col: Collector, avatar: AvatarTable, stims: list[tuple[int, dict]]) -> tuple[str, dict[str, str]]:
    avatar_default = avatar.model
    by_speaker = {}
    for k, v in avatar.by_speaker.items():
        if not isinstance(v, str):
            col.add(f"avatar.by_speaker.{k}", "must be \"builtin\" or a glTF/VRM path", f'{k} = "builtin"')
        else:
            by_speaker[k] = v
    speakers = {str(e.get("tags", {}).get("speaker")) for _, e in stims if "speaker" in e.get("tags", {})}
    for k in by_speaker:
        if k not in speakers:
            col.add(f"avatar.by_speaker.{k}", f"no stimulus has tags.speaker = {k!r}",
                    did_you_mean(k, sorted(x for x in speakers if x)).replace("allowed keys", "speakers"))
    for akey, name in [("avatar.model", avatar_default)] + [(f"avatar.by_speaker.{k}", v) for k, v in by_speaker.items()]:
        if name != "builtin" and not name.lower().endswith(AVATAR_SUFFIXES):
            col.add(akey, f"{name!r} is neither \"builtin\" nor a .glb/.gltf/.vrm file", 'use "builtin" or a glTF file')
    return avatar_default, by_speaker


def _avatar_bone_map(col: Collector, avatar: AvatarTable) -> dict[str, str]:
    """``[avatar.bone_map]`` entries naming humanoid bones (joint names are checked against the file by validate)."""
    from studyapp.render.avatar_rig import canonical_bone

    bone_map = {}
    for k, v in avatar.bone_map.items():
        if not isinstance(v, str):
            col.add(f"avatar.bone_map.{k}", "must map an avatar joint name to a humanoid bone name (a string)",
                    f'"{k}" = "LeftUpperArm"')
        elif canonical_bone(v) is None:
            col.add(f"avatar.bone_map.{k}", f"{v!r} is not a Unity humanoid bone name",
                    "use Hips, Spine, Chest, UpperChest, Neck, Head, LeftShoulder, LeftUpperArm, LeftLowerArm, "
                    "LeftHand, LeftUpperLeg, LeftLowerLeg, LeftFoot, LeftToes, LeftIndexProximal, ...")
        else:
            bone_map[k] = v
    return bone_map


def _ordering_and_slots(col: Collector, ordering: OrderingTable, slots: SlotsTable):
    if ordering.method not in ORDERINGS:
        col.add("ordering.method", f"unknown ordering {ordering.method!r}",
                did_you_mean(ordering.method, ORDERINGS).replace("allowed keys", "allowed values"))
    if slots.assignment not in SLOT_ASSIGNMENTS:
        col.add("slots.assignment", f"unknown slot assignment {slots.assignment!r}",
                did_you_mean(slots.assignment, SLOT_ASSIGNMENTS).replace("allowed keys", "allowed values"))
    if slots.labels not in SLOT_LABELS:
        col.add("slots.labels", f"unknown slot labels {slots.labels!r}", 'use "ABC", "LMR", "123" or "none"')
    return SLOT_LABELS.get(slots.labels, ("A", "B", "C"))


def _attention_checks(col: Collector, checks: list[tuple[int, dict]], stim_ids: list[str], crit_ids: list[str],
                      ids_ok: list[str]) -> list[AttentionCheck]:
    attention: list[AttentionCheck] = []
    for i, e in checks:
        key = f"attention_checks[{i}]"
        kind = e.get("kind", key_default(AttentionCheckTable, "kind"))
        if "stimulus" in e and e["stimulus"] not in stim_ids:
            col.add(f"{key}.stimulus", f"unknown stimulus {e['stimulus']!r}",
                    did_you_mean(e["stimulus"], stim_ids).replace("allowed keys", "stimuli"))
        if kind not in ATTENTION_KINDS:
            col.add(f"{key}.kind", f"unknown attention check kind {kind!r}", 'use "frozen" or "known-worst"')
        crit = e.get("criterion", key_default(AttentionCheckTable, "criterion"))
        if crit not in crit_ids:
            col.add(f"{key}.criterion", f"unknown criterion {crit!r}",
                    did_you_mean(crit, crit_ids).replace("allowed keys", "criteria"))
        rank = e.get("rank", key_default(AttentionCheckTable, "rank"))
        if rank not in (1, 2, 3):
            col.add(f"{key}.rank", f"rank must be 1, 2 or 3, got {rank}", "3 means ranked last")
        expected: dict = {"criterion": crit, "rank": rank}
        if kind == "known-worst":
            if "condition" not in e:
                col.add(f"{key}.condition", "a known-worst check must name the condition expected at `rank`",
                        f'condition = "{ids_ok[-1] if ids_ok else "static"}"')
            elif e["condition"] not in ids_ok:
                col.add(f"{key}.condition", f"unknown condition {e['condition']!r}",
                        did_you_mean(e["condition"], ids_ok).replace("allowed keys", "conditions"))
            else:
                expected["condition"] = e["condition"]
        elif "condition" in e:
            col.add(f"{key}.condition", "only known-worst checks name a condition (frozen checks replace a slot)",
                    'remove it or set kind = "known-worst"')
        if "stimulus" in e:
            attention.append(AttentionCheck(e["stimulus"], kind, expected))
    return attention


#: Keys of ``[[blocks]]`` that only some paradigms read: given to another paradigm they would do nothing.
_BLOCK_KEY_PARADIGMS = {"levels": ("pairwise", "mismatch"), "reasons": ("pairwise",), "match_tag": ("mismatch",),
                        "reference": ("rating",), "anchors": ("rating",)}


def _id_list(col: Collector, key: str, given: list, known: list[str], what: str) -> list[str]:
    """The ids of ``given`` that name one of ``known`` (problems for the others, once each)."""
    out: list[str] = []
    for j, x in enumerate(given):
        if not isinstance(x, str) or x not in known:
            col.add(f"{key}[{j}]", f"unknown {what} {x!r}", did_you_mean(str(x), known).replace("allowed keys", what))
        elif x in out:
            col.add(f"{key}[{j}]", f"{what} {x!r} is listed twice", "list each once")
        else:
            out.append(x)
    return out


def _strings(col: Collector, key: str, given: list, example: str) -> tuple[str, ...]:
    if not all(isinstance(x, str) and x.strip() for x in given) or len(set(given)) != len(given):
        col.add(key, "must be a list of different, non-empty strings", example)
        return ()
    return tuple(x.strip() for x in given)


def _blocks(col: Collector, blocks: list[tuple[int, dict]], cond_ids: list[str], stimuli: list[Stimulus],
            stim_ids: list[str], criteria: list[Criterion]) -> list[Block]:
    """``[[blocks]]`` checked against the conditions, stimuli and criteria they name (see :class:`Block`)."""
    out: list[Block] = []
    crit_ids = [c.id for c in criteria]
    rotation = [s.id for s in stimuli if s.in_rotation]
    tags = {s.id: s.tags for s in stimuli}
    for i, e in blocks:
        key = f"blocks[{i}]"
        paradigm = e.get("paradigm", key_default(BlockTable, "paradigm"))
        if paradigm not in PARADIGMS:
            col.add(f"{key}.paradigm", f"unknown paradigm {paradigm!r}",
                    "use " + ", ".join(f'"{p}"' for p in PARADIGMS))
        for name, kinds in _BLOCK_KEY_PARADIGMS.items():
            if name in e and paradigm in PARADIGMS and paradigm not in kinds:
                col.add(f"{key}.{name}", f"only {' and '.join(kinds)} blocks have {name}",
                        f'remove {name}, or set paradigm = "{kinds[0]}"')
        crits = _id_list(col, f"{key}.criteria", e["criteria"], crit_ids, "criteria") if "criteria" in e else crit_ids
        if "criteria" in e and not e["criteria"]:
            col.add(f"{key}.criteria", "empty list of criteria", "name at least one criterion, or remove criteria")
        conds = _id_list(col, f"{key}.conditions", e["conditions"], cond_ids, "conditions") \
            if "conditions" in e else list(cond_ids)
        stims = _id_list(col, f"{key}.stimuli", e["stimuli"], stim_ids, "stimuli") if "stimuli" in e else rotation
        if not stims:
            col.add(f"{key}.stimuli", "the block has no stimuli", "name at least one stimulus, or remove stimuli")
        levels = e.get("levels", key_default(BlockTable, "levels"))
        if levels not in PREFERENCE_LEVELS:
            col.add(f"{key}.levels", f"levels must be 5 or 3, got {levels}",
                    "5: clearly/slightly left, equal, slightly/clearly right; 3: left, equal, right")
            levels = 5
        reasons = _strings(col, f"{key}.reasons", e.get("reasons", []), 'reasons = ["Hand movements", "Timing"]')
        anchors = _strings(col, f"{key}.anchors", e.get("anchors", []), 'anchors = ["Bad", "Poor", "Fair", "Good", '
                           '"Excellent"]')
        if len(anchors) == 1:
            col.add(f"{key}.anchors", "one anchor cannot be spread over 0..100", "give two or more, or none")
        reference = e.get("reference")
        if reference is not None and reference not in cond_ids:
            col.add(f"{key}.reference", f"unknown condition {reference!r}",
                    did_you_mean(reference, cond_ids).replace("allowed keys", "conditions"))
            reference = None
        match_tag = e.get("match_tag", key_default(BlockTable, "match_tag"))
        n = len(conds)
        if "conditions" in e and not e["conditions"]:
            col.add(f"{key}.conditions", "empty list of conditions", "name the block's conditions, or remove it")
        elif paradigm == "rank" and n != 3:
            col.add(f"{key}.conditions", f"a rank block shows exactly 3 conditions per trial, got {n}",
                    "name exactly 3 conditions for this block")
        elif paradigm == "pairwise" and n < 2:
            col.add(f"{key}.conditions", f"a pairwise block compares at least 2 conditions, got {n}",
                    "name two or more conditions")
        elif paradigm == "rating":
            k = n + (reference is not None and reference not in conds)
            if not RATING_FIGURES[0] <= k <= RATING_FIGURES[1]:
                col.add(f"{key}.conditions", f"a rating trial shows {RATING_FIGURES[0]} to {RATING_FIGURES[1]} "
                        f"figures (the conditions and the reference), this block would show {k}",
                        "name fewer conditions (make one block per group)" if k > RATING_FIGURES[1]
                        else "name more conditions")
        if paradigm == "mismatch":
            for sid in stims:
                value = tags.get(sid, {}).get(match_tag)
                if value is None:
                    col.add(f"{key}.match_tag", f"stimulus {sid!r} has no tag {match_tag!r}, so no clip can be "
                            "mismatched with it", f'add tags.{match_tag} to stimulus {sid!r}, or set match_tag')
                elif not any(o != sid and tags.get(o, {}).get(match_tag) == value for o in stims):
                    col.add(f"{key}.stimuli", f"stimulus {sid!r} is the block's only one with {match_tag} = "
                            f"{value!r}: its mismatched motion must come from another of the block's clips "
                            "with that tag", f"add another clip with {match_tag} = {value!r} to the block, "
                            f"or drop {sid!r}")
        aspects = {criterion_aspect(c) for c in criteria if c.id in crits} - {None}
        if aspects == set(ASPECTS):
            import warnings

            where = col.path + (f":{col.line_of(f'{key}.criteria')}" if col.line_of(f"{key}.criteria") else "")
            warnings.warn(DesignWarning(
                f"{where}: {key}.criteria: block {e.get('id', i)!r} asks about motion quality and about speech "
                "together; Nagy et al. 2025 found such judgements influence each other -- consider one block "
                "per aspect"), stacklevel=2)
        if e.get("id"):
            out.append(Block(e["id"], paradigm, tuple(crits), tuple(conds), tuple(stims),
                             e.get("instructions", "").strip(), levels, reasons, match_tag, reference, anchors))
    return out


def _questionnaire(col: Collector, questions: list[tuple[int, dict]]) -> list[QuestionItem]:
    items: list[QuestionItem] = []
    for i, e in questions:
        key = f"questionnaire[{i}]"
        kind = e.get("kind", "likert")
        if kind not in QUESTION_KINDS:
            col.add(f"{key}.kind", f"unknown item kind {kind!r}", "use " + " or ".join(f'"{k}"' for k in QUESTION_KINDS))
        # keys that belong to another kind are a mistake worth one message each (they would do nothing)
        for name, kinds in (("points", ("likert",)), ("anchors", ("likert",)), ("options", ("choice",)),
                            ("multiple", ("choice",)), ("min", ("number",)), ("max", ("number",)),
                            ("integer", ("number",))):
            if name in e and kind in QUESTION_KINDS and kind not in kinds:
                col.add(f"{key}.{name}", f"only {' and '.join(kinds)} items have {name}", f"remove {name}, or "
                        f'set kind = "{kinds[0]}"')
        points = e.get("points", key_default(QuestionItem, "points") if kind == "likert" else 0)
        if kind == "likert" and not 2 <= points <= 11:
            col.add(f"{key}.points", f"a Likert item needs 2..11 points, got {points}", "e.g. points = 7")
        anchors = e.get("anchors", list(key_default(QuestionItem, "anchors")) if kind == "likert" else ["", ""])
        if kind == "likert" and (len(anchors) != 2 or not all(isinstance(a, str) for a in anchors)):
            col.add(f"{key}.anchors", "must be two strings: the labels of the lowest and highest point",
                    'anchors = ["Strongly disagree", "Strongly agree"]')
        if len(anchors) != 2 or not all(isinstance(a, str) for a in anchors):
            anchors = ["", ""]
        options = e.get("options", [])
        if kind == "choice":
            if not all(isinstance(o, str) and o.strip() for o in options) or len(options) < 2:
                col.add(f"{key}.options", "a choice item needs a list of at least two non-empty strings",
                        'options = ["Yes", "No"]')
                options = []
            elif len(set(options)) != len(options):
                col.add(f"{key}.options", "the same option is listed twice", "list each option once")
                options = []
        lo, hi = e.get("min"), e.get("max")
        if kind == "number":
            if lo is None or hi is None:
                col.add(f"{key}.{'min' if lo is None else 'max'}", "a number item needs a range: min and max",
                        "e.g. min = 18, max = 99")
            elif not lo < hi:
                col.add(f"{key}.max", f"max ({hi}) must be larger than min ({lo})", "swap them")
            elif e.get("integer") and int(lo) != lo:
                col.add(f"{key}.min", "an integer item's range must start at a whole number", f"min = {math.ceil(lo)}")
        if e.get("id") and "text" in e:
            items.append(QuestionItem(e["id"], kind, e["text"], e.get("scale"), points if kind == "likert" else 0,
                                      (anchors[0], anchors[1]), tuple(str(o) for o in options),
                                      bool(e.get("multiple", False)), None if lo is None else float(lo),
                                      None if hi is None else float(hi), bool(e.get("integer", False))))
    return items


def _display(col: Collector, display: dict) -> Display:
    from studyapp.render.camera import FRAMINGS

    if display.get("framing", key_default(Display, "framing")) not in FRAMINGS:
        col.add("display.framing", f"unknown framing {display['framing']!r}",
                did_you_mean(display["framing"], FRAMINGS).replace("allowed keys", "allowed values"))
        display.pop("framing")
    return Display(**display)


def _participants(col: Collector, participants: ParticipantsTable) -> tuple[int | None, dict[str, str]]:
    maxfail = participants.max_attention_failures
    if maxfail is not None and maxfail < 0:
        col.add("participants.max_attention_failures", "must be 0 or more", "e.g. 1")
    groups = {}
    for k, v in participants.groups.items():
        if isinstance(v, (dict, list)):
            col.add(f"participants.groups.{k}", "group labels must be strings", f'{k} = "v1"')
        else:
            groups[k] = str(v)
    return maxfail, groups


# ---------------------------------------------------------------------------------------------------------
# The whole file


def _online(col: Collector, online: OnlineTable) -> OnlineTable:
    if not float(online.abandon_after_min) > 0:
        col.add("online.abandon_after_min", "must be more than 0 minutes", "e.g. 120 (two hours)")
        online.abandon_after_min = key_default(OnlineTable, "abandon_after_min")
    url = online.completion_url.strip()
    if url and not url.lower().startswith(("https://", "http://")):
        col.add("online.completion_url", f"{url!r} is not a web address",
                'e.g. "https://app.prolific.com/submissions/complete?cc=C1234ABC"')
        online.completion_url = ""
    return online


def _read(path: Path) -> tuple[bytes, str, dict] | Problem:
    try:
        data = path.read_bytes()
    except OSError as exc:
        return Problem(str(path), "", f"cannot read the design file: {exc.strerror or exc}", "check the path")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        return Problem(str(path), "", f"not UTF-8 text (byte {exc.start})", "save the file as UTF-8")
    try:
        return data, text, tomlfile.loads(text)
    except tomlfile.TOMLDecodeError as exc:
        m = re.search(r"\(at line (\d+), column (\d+)\)", str(exc))
        msg = re.sub(r"\s*\(at line \d+, column \d+\)", "", str(exc))
        line = int(m.group(1)) if m else None
        where = f"line {m.group(1)}, column {m.group(2)}" if m else ""
        return Problem(str(path), where, f"TOML syntax error: {msg}",
                       "see https://toml.io; strings need quotes, tables [name], lists [a, b]", line)


def _keys_with_nul(node: object, key: str = "") -> list[str]:
    """Dotted keys (``stimuli[0].audio``) of every string or key in the TOML data that holds a NUL."""
    if isinstance(node, str):
        return [key or "<top>"] if "\0" in node else []
    if isinstance(node, dict):
        return [k for name, v in node.items()
                for k in ([f"{key}.{name}".lstrip(".")] if "\0" in name else _keys_with_nul(v, f"{key}.{name}".lstrip(".")))]
    if isinstance(node, list):
        return [k for i, v in enumerate(node) for k in _keys_with_nul(v, f"{key}[{i}]")]
    return []


def parse_design(path: Path, check_files: bool) -> tuple[Design | None, list[Problem]]:
    """The design in ``path`` (None when it cannot be read) and every problem found in it."""
    path = Path(path)
    got = _read(path)
    if isinstance(got, Problem):
        return None, [got]
    data, text, raw = got
    col = Collector(path, text)
    for key in _keys_with_nul(raw):
        col.add(key, "contains a NUL character (\\u0000), which no file name or text may hold",
                "delete it (a damaged file? check the rest of it too)")
    if col.problems:  # paths holding NUL cannot even be looked up: nothing below can be checked
        return None, col.problems
    top = check_table(col, raw, DesignFile, "")
    conds = check_array(col, top, "conditions", Condition)
    stims = check_array(col, top, "stimuli", Stimulus)
    crits = check_array(col, top, "criteria", Criterion)
    checks = check_array(col, top, "attention_checks", AttentionCheckTable)
    questions = check_array(col, top, "questionnaire", QuestionItem)
    block_entries = check_array(col, top, "blocks", BlockTable)
    avatar = AvatarTable(**check_table(col, top.get("avatar", {}), AvatarTable, "avatar"))
    ordering = OrderingTable(**check_table(col, top.get("ordering", {}), OrderingTable, "ordering"))
    slots = SlotsTable(**check_table(col, top.get("slots", {}), SlotsTable, "slots"))
    playback = check_table(col, top.get("playback", {}), Playback, "playback")
    display = _display(col, check_table(col, top.get("display", {}), Display, "display"))
    participants = ParticipantsTable(**check_table(col, top.get("participants", {}), ParticipantsTable,
                                                    "participants"))
    online = _online(col, OnlineTable(**check_table(col, top.get("online", {}), OnlineTable, "online")))
    check_ids(col, "conditions", conds, "condition")
    check_ids(col, "stimuli", stims, "stimulus")
    check_ids(col, "criteria", crits, "criterion")
    check_ids(col, "questionnaire", questions, "questionnaire item")
    check_ids(col, "blocks", block_entries, "block")

    conditions = _conditions(col, top, conds)
    ids_ok = [e.get("id") for _, e in conds if e.get("id")]
    stimuli = _stimuli(col, top, stims, path)
    # Every stimulus that has an id counts as known, even one with another problem (say, no audio): a
    # reference to it from `practice` or an attention check is not a second problem.
    stim_ids = [e["id"] for _, e in stims if e.get("id")]
    language = top.get("language", key_default(DesignFile, "language"))
    language = language_code(language) if isinstance(language, str) else language
    texts = _texts(col, language, top.get("texts", {}))
    criteria = _criteria(col, top, crits, texts)
    # As for stimuli: a criterion with a problem of its own is still known by its id to attention checks.
    crit_ids = [e["id"] for _, e in crits if e.get("id")] if "criteria" in top else [c.id for c in criteria]
    avatar_default, by_speaker = _avatar(col, avatar, stims)
    bone_map = _avatar_bone_map(col, avatar)
    labels = _ordering_and_slots(col, ordering, slots)
    practice = top.get("practice", key_default(DesignFile, "practice"))
    for j, sid in enumerate(practice):
        if sid not in stim_ids:
            col.add(f"practice[{j}]", f"unknown stimulus {sid!r}",
                    did_you_mean(str(sid), stim_ids).replace("allowed keys", "stimuli"))
    blocks = _blocks(col, block_entries, ids_ok, stimuli, stim_ids, criteria)
    rank_blocks = [b for b in blocks if b.paradigm == "rank"]
    if blocks and checks and not rank_blocks:
        col.add("attention_checks", "attention checks are asked in the first rank block, and this design has none",
                'add a [[blocks]] entry with paradigm = "rank", or remove the attention checks')
    if blocks and blocks[0].paradigm == "mismatch":  # practice clips are trials of the first block
        first = blocks[0]
        tag_of = {s.id: s.tags.get(first.match_tag) for s in stimuli}
        for j, sid in enumerate(top.get("practice", [])):
            if sid in tag_of and not any(o != sid and tag_of.get(o) == tag_of[sid] is not None for o in first.stimuli):
                col.add(f"practice[{j}]", f"practice clip {sid!r} opens the mismatch block {first.id!r}, but none of "
                        f"that block's clips shares its {first.match_tag} to mismatch it with",
                        f"give it tags.{first.match_tag} of one of the block's clips, or drop it from practice")
    if blocks and rank_blocks:  # a check is scored on a criterion its block asks
        for i, e in checks:
            crit = e.get("criterion", key_default(AttentionCheckTable, "criterion"))
            if crit in crit_ids and crit not in rank_blocks[0].criteria:
                col.add(f"attention_checks[{i}].criterion", f"criterion {crit!r} is not asked in block "
                        f"{rank_blocks[0].id!r}, the rank block attention checks belong to",
                        "use one of " + ", ".join(repr(c) for c in rank_blocks[0].criteria))
    attention = _attention_checks(col, checks, stim_ids, crit_ids,
                                  list(rank_blocks[0].conditions) if rank_blocks else ids_ok)
    items = _questionnaire(col, questions)
    maxfail, groups = _participants(col, participants)

    design = Design(
        path=path.resolve(), title=top.get("title", ""), instructions=top.get("instructions", "").strip(),
        consent=top.get("consent", "").strip(), completion=top.get("completion", "").strip(),
        language=language, texts=texts,
        conditions=conditions, stimuli=stimuli, criteria=criteria, avatar=avatar_default,
        avatar_by_speaker=by_speaker, avatar_bone_map=bone_map, ordering=ordering.method, slot_assignment=slots.assignment,
        slot_labels=labels, practice=[str(p) for p in practice], attention_checks=attention,
        playback=Playback(**playback), display=display, questionnaire=items, max_attention_failures=maxfail,
        seed=int(ordering.seed), groups=groups, blocks=blocks, online=online,
    )
    for key, cid in visible_text_leaks(design):
        col.add(key, f"participants read this text and it names condition {cid!r}: that unblinds the study",
                "reword the text, or give the condition another id or label")
    files = referenced_files(design, col)
    if check_files:
        from studyapp.study.design.fonts import font_problem

        no_font = font_problem(design)
        if no_font is not None:
            col.add(*no_font)
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
        # An array setting the parser refused (representation = "6d") reaches the file check as missing; its
        # parse problem already says what to write there.
        refused = {p.key for p in col.problems if p.key.rsplit(".", 1)[-1] in ("template", "representation", "fps")}
        for key, message, fix in found:
            if key not in refused:
                col.add(key, message, fix)
    design.design_hash = design_hash(data, {k: p for k, p in files.items()})
    return design, col.problems


