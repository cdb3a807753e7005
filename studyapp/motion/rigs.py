"""Which joint of a rig is which humanoid bone: built-in maps, fuzzy matching, the user's name maps.

:func:`detect_name_map` tries every built-in map of :mod:`studyapp.motion.humanoid` (BEAT, ZEGGS,
Mixamo with any ``mixamorigN:`` prefix, CMU in both namings, Xia/PFNN, LAFAN1, Bandai-Namco, SMPL, VRM)
and keeps the one that covers most required bones. Bones it still lacks are looked for by
:func:`fuzzy_name_map`, which reads names as words (``L_UpperArm``, ``upperarm.l``, ``Bip01 L Forearm``,
``thigh_r``) and follows the hierarchy from the hips up to the head for the spine. What no rule finds is
what a ``name_map`` in the design must give: :func:`missing_bones_message` lists the file's joints and
the bones still missing, and :func:`name_map_template` writes the TOML to fill in.

>>> from studyapp.motion.skeleton import Skeleton
>>> import numpy as np
>>> names = ("pelvis", "spine_01", "neck_01", "head", "clavicle_l", "upperarm_l", "lowerarm_l", "hand_l",
...          "clavicle_r", "upperarm_r", "lowerarm_r", "hand_r", "thigh_l", "calf_l", "foot_l", "thigh_r",
...          "calf_r", "foot_r")
>>> parents = [-1, 0, 1, 2, 1, 4, 5, 6, 1, 8, 9, 10, 0, 12, 13, 0, 15, 16]
>>> m = detect_name_map(Skeleton(names, np.array(parents), np.zeros((18, 3))))
>>> m["upperarm_l"], m["calf_r"], m["spine_01"], m["clavicle_l"]
('LeftUpperArm', 'RightLowerLeg', 'Spine', 'LeftShoulder')
"""
from __future__ import annotations

import re

from studyapp.errors import InputError
from studyapp.motion.humanoid import BUILTIN_MAPS, HUMANOID_BONES, REQUIRED_BONES
from studyapp.motion.skeleton import Skeleton

__all__ = ["recognise_rig", "detect_name_map", "merge_name_map", "fuzzy_name_map", "missing_bones_message", "name_map_template"]


def _strip_namespace(name: str) -> str:
    for sep in (":", "|"):
        if sep in name:
            name = name.rsplit(sep, 1)[1]
    return name


def _apply_map(names: tuple[str, ...], table: dict[str, str]) -> dict[str, str]:
    """Match a built-in table to joint names: exact (case-insensitive) first, then without namespace prefix.

    Joints are visited deepest-first (reverse depth-first order), so when a table names one bone for
    two joints of a chain (BEAT ``Neck``, ``Neck1``) the upper joint gets it and the lower one's
    rotation is composed into it by :func:`~studyapp.motion.retarget.retarget`.
    """
    exact = {k.lower(): v for k, v in table.items()}
    bare = {_strip_namespace(k).lower(): v for k, v in table.items()}
    out: dict[str, str] = {}
    used: set[str] = set()
    for pass_table, key in ((exact, str.lower), (bare, lambda n: _strip_namespace(n).lower())):
        for n in reversed(names):
            if n in out:
                continue
            bone = pass_table.get(key(n))
            if bone is not None and bone not in used:
                out[n] = bone
                used.add(bone)
    return out


# -- fuzzy matching ----------------------------------------------------------------------------------------

_LEFT = {"l", "left", "lft", "lf"}
_RIGHT = {"r", "right", "rt", "rgt"}
_END = {"end", "nub", "site", "tip", "top", "headend", "headtop", "dummy", "twist", "roll", "helper", "ik"}
#: Sided body parts: the words that name them (checked in order, the first match wins).
_SIDED_PARTS: tuple[tuple[str, tuple[frozenset[str], ...]], ...] = (
    ("Toes", (frozenset({"toe"}), frozenset({"toes"}), frozenset({"toebase"}), frozenset({"ball"}))),
    ("Foot", (frozenset({"foot"}), frozenset({"ankle"}))),
    ("LowerLeg", (frozenset({"lower", "leg"}), frozenset({"calf"}), frozenset({"shin"}), frozenset({"knee"}),
                  frozenset({"lowerleg"}), frozenset({"leg"}))),
    ("UpperLeg", (frozenset({"up", "leg"}), frozenset({"upper", "leg"}), frozenset({"upleg"}), frozenset({"thigh"}),
                  frozenset({"upperleg"}), frozenset({"hip"}))),
    ("Hand", (frozenset({"hand"}), frozenset({"wrist"}))),
    ("LowerArm", (frozenset({"fore", "arm"}), frozenset({"forearm"}), frozenset({"lower", "arm"}), frozenset({"lowerarm"}),
                  frozenset({"elbow"}), frozenset({"lowarm"}))),
    ("UpperArm", (frozenset({"upper", "arm"}), frozenset({"upperarm"}), frozenset({"up", "arm"}), frozenset({"shldr"}),
                  frozenset({"humerus"}), frozenset({"arm"}))),
    ("Shoulder", (frozenset({"clavicle"}), frozenset({"collar"}), frozenset({"shoulder"}), frozenset({"clav"}))),
)
_FINGER_WORDS = {"thumb", "index", "middle", "mid", "ring", "pinky", "little", "finger", "fingers", "metacarpal"}


def _words(name: str) -> list[str]:
    """Lower-case words of a joint name: namespace dropped, camelCase and digits split."""
    name = _strip_namespace(name)
    name = re.sub(r"(?<=[a-z])(?=[A-Z])|(?<=[A-Z])(?=[A-Z][a-z])", " ", name)
    return [w for w in re.split(r"[^A-Za-z]+", name.lower()) if w]


def _side(words: list[str], name: str) -> str | None:
    if any(w in _LEFT for w in words):
        return "Left"
    if any(w in _RIGHT for w in words):
        return "Right"
    bare = _strip_namespace(name)
    if re.match(r"^[lL](?=[A-Z])", bare):  # Daz: lShldr, lThigh
        return "Left"
    if re.match(r"^[rR](?=[A-Z])", bare):
        return "Right"
    return None


def _sided_part(words: list[str]) -> str | None:
    """The part whose most specific spelling the words contain (``upper leg`` beats ``leg``)."""
    bag = set(words)
    if bag & _FINGER_WORDS:
        return None
    best, size = None, 0
    for part, spellings in _SIDED_PARTS:
        for s in spellings:
            if s <= bag and len(s) > size:
                best, size = part, len(s)
    return best


def fuzzy_name_map(skeleton: Skeleton, taken: dict[str, str] | None = None) -> dict[str, str]:
    """Humanoid bones found by reading joint names as words, for bones ``taken`` does not map yet.

    Limbs are matched by side and part words; the spine by structure: the joints on the path from the
    hips to the head, spine words below the neck.
    """
    taken = dict(taken or {})
    used_bones = set(taken.values())
    out: dict[str, str] = {}
    words = {n: _words(n) for n in skeleton.names}

    def free(name: str, bone: str) -> bool:
        return name not in taken and name not in out and bone not in used_bones and bone not in out.values()

    # limbs: the first joint down each chain whose words name the part (a twist or end joint never does)
    for j, name in enumerate(skeleton.names):
        w = words[name]
        if set(w) & _END:
            continue
        side, part = _side(w, name), _sided_part(w)
        if side and part and free(name, f"{side}{part}"):
            out[name] = f"{side}{part}"
    # the trunk: hips = the nearest common ancestor of both upper legs (else a root named hips/pelvis)
    bone_of = {**taken, **out}
    joint_of = {b: n for n, b in bone_of.items()}
    idx = {n: i for i, n in enumerate(skeleton.names)}

    def ancestors(j: int) -> list[int]:
        chain = []
        while j >= 0:
            chain.append(j)
            j = int(skeleton.parents[j])
        return chain

    hips = joint_of.get("Hips")
    if hips is None:
        legs = [joint_of.get("LeftUpperLeg"), joint_of.get("RightUpperLeg")]
        if all(legs):
            common = [a for a in ancestors(idx[legs[0]]) if a in set(ancestors(idx[legs[1]]))]
            if common:
                hips = skeleton.names[common[0]]
        if hips is None:
            hips = next((n for n in skeleton.names if {"hips", "hip", "pelvis"} & set(words[n])
                         and _side(words[n], n) is None), None)
        if hips is not None and free(hips, "Hips"):
            out[hips] = "Hips"
    head = joint_of.get("Head") or next((n for n in skeleton.names if "head" in words[n]
                                         and not set(words[n]) & _END and _side(words[n], n) is None), None)
    if head is not None and free(head, "Head"):
        out[head] = "Head"
    if hips is None or head is None:
        return out
    path = [skeleton.names[a] for a in reversed(ancestors(idx[head]))]
    if hips not in path:
        return out
    between = path[path.index(hips) + 1: path.index(head)]
    necks = [n for n in between if "neck" in words[n]]
    if necks and free(necks[-1], "Neck"):
        out[necks[-1]] = "Neck"
    spine = [n for n in between if not necks or between.index(n) < between.index(necks[0])]
    names = {1: ("Spine",), 2: ("Spine", "Chest"), 3: ("Spine", "Chest", "UpperChest")}
    if spine:
        pick = (spine if len(spine) <= 3 else [spine[0], spine[1], spine[-1]])
        for n, bone in zip(pick, names[len(pick)]):
            if free(n, bone):
                out[n] = bone
    return out


def recognise_rig(skeleton: Skeleton) -> tuple[str, dict[str, str]]:
    """The built-in map that fits best (its name, ``"+fuzzy"`` when word matching completed it) and the
    ``{joint: bone}`` map :func:`detect_name_map` returns."""
    best: dict[str, str] = {}
    best_name, best_key = "none", (-1, -1)
    for name, table in BUILTIN_MAPS.items():
        got = _apply_map(skeleton.names, table)
        key = (sum(b in got.values() for b in REQUIRED_BONES), len(got))
        if key > best_key:
            best, best_key, best_name = got, key, name
    if best_key[0] < len(REQUIRED_BONES):
        extra = fuzzy_name_map(skeleton, best)
        if extra:
            best.update(extra)
            best_name = "fuzzy" if best_key[0] <= 0 else f"{best_name}+fuzzy"
    return best_name, best


def detect_name_map(skeleton: Skeleton) -> dict[str, str]:
    """``{joint name: humanoid bone}`` from the built-in map that matches the most joints, completed by
    :func:`fuzzy_name_map` for the required bones it lacks.

    Never raises: an unknown rig gives a partial (possibly empty) map; :func:`missing_bones_message`
    says what is missing.

    >>> from studyapp.motion.beat import beat_skeleton
    >>> m = detect_name_map(beat_skeleton())
    >>> m["RightForeArm"], m["Spine3"], "Spine2" in m
    ('RightLowerArm', 'UpperChest', False)
    """
    return recognise_rig(skeleton)[1]


def merge_name_map(skeleton: Skeleton, override: dict[str, str] | None, what: str | None = None) -> dict[str, str]:
    """Detected map with ``override`` entries (``{joint: bone}``, e.g. from a study design) on top.

    An override entry replaces whatever joint the built-in map gave that bone. Joint names in
    ``override`` match exactly first, then case-insensitively. ``what`` names the file in messages.
    """
    mapping = detect_name_map(skeleton)
    if not override:
        return mapping
    lower = {n.lower(): n for n in skeleton.names}
    known = {b.lower(): b for b in HUMANOID_BONES}
    for src, bone in override.items():
        name = src if src in skeleton.names else lower.get(src.lower())
        if name is None:
            raise InputError(what, f"name_map.{src}",
                             f"joint {src!r} is not in the skeleton ({skeleton.n_joints} joints: "
                             f"{_joint_list(skeleton)})")
        canon = known.get(str(bone).lower())
        if canon is None:
            raise InputError(what, f"name_map.{src}", f"{bone!r} is not a humanoid bone name (e.g. LeftUpperArm)")
        mapping = {k: v for k, v in mapping.items() if v != canon and k != name}
        mapping[name] = canon
    return mapping


def _joint_list(skeleton: Skeleton, limit: int = 80) -> str:
    names = list(skeleton.names)
    text = ", ".join(names[:limit])
    return text + (f", ... ({len(names) - limit} more)" if len(names) > limit else "")


def missing_bones_message(skeleton: Skeleton, mapping: dict[str, str], key: str, what: str = "skeleton") -> str:
    """One line: which required bones no joint maps to, the joints the file has, and how to fix it."""
    have = set(mapping.values())
    missing = [b for b in REQUIRED_BONES if b not in have]
    return (f"cannot retarget: this {what} ({skeleton.n_joints} joints: {_joint_list(skeleton)}) has no joint for "
            f"{', '.join(missing)}; add {key} entries (joint name = humanoid bone), e.g. "
            f"`studyapp inspect FILE --name-map-template` writes them to fill in")


def name_map_template(skeleton: Skeleton, source: str = "") -> str:
    """A TOML ``[conditions.name_map]`` table for this skeleton: found bones filled in, the missing ones
    listed as comments, every joint of the file named, ready to be completed by hand."""
    mapping = detect_name_map(skeleton)
    have = set(mapping.values())
    lines = [f"# name_map for {source or 'this skeleton'} ({skeleton.n_joints} joints)",
             "# paste under the condition that uses these files; keys are joint names, values humanoid bones",
             "[conditions.name_map]"]
    for name in skeleton.names:
        bone = mapping.get(name)
        key = f'"{name}"' if not re.fullmatch(r"[A-Za-z0-9_-]+", name) else name
        lines.append(f'{key} = "{bone}"' if bone else f"# {key} = \"\"")
    missing = [b for b in REQUIRED_BONES if b not in have]
    if missing:
        lines.append(f"# still missing (required): {', '.join(missing)}")
    return "\n".join(lines) + "\n"
