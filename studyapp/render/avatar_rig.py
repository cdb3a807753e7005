"""An avatar's humanoid bones: which joint is which bone, which way the figure faces, is it humanoid at all.

The retargeting code (:mod:`studyapp.motion.retarget`) recognises joints named as Unity, BEAT, Mixamo or
VRM name them. Characters with their own names (RobotExpressive's ``UpperArm.L``, CesiumMan's
``Skeleton_arm_joint_L__4_``) need a bone map from the design: ``[avatar.bone_map]`` entries
``joint name = humanoid bone``. This module checks those entries, merges them with what is recognised,
and measures the figure's facing from its rest pose.

Facing: with +Y up, the figure's left-right axis (left minus right hip, else shoulder) crossed with up
gives forward, ``forward = (left - right) x up``. The built-in avatar has its left side at +X and faces
+Z (towards the camera):

>>> import numpy as np
>>> from studyapp.render.avatar import default_skeleton
>>> from studyapp.motion.fk import rest_global_transforms
>>> sk = default_skeleton()
>>> pos = rest_global_transforms(sk)[:, :3, 3]
>>> rest_facing(pos, {b: sk.index(b) for b in ("LeftUpperLeg", "RightUpperLeg")}).round(6).tolist()
[0.0, 0.0, 1.0]
>>> bone_map_problems(sk.names, {"Hips": "Hips", "Tail": "Spine", "LeftHand": "LeftPaw"})
[('Tail', "joint 'Tail' is not in the avatar"), ('LeftHand', "'LeftPaw' is not a humanoid bone name")]
"""
from __future__ import annotations

import math

import numpy as np

from studyapp.motion.humanoid import HUMANOID_BONES, REQUIRED_BONES
from studyapp.motion.skeleton import Skeleton

#: Pairs of bones whose rest positions give the left-right axis, most reliable first.
LATERAL_PAIRS = (("LeftUpperLeg", "RightUpperLeg"), ("LeftUpperArm", "RightUpperArm"),
                 ("LeftShoulder", "RightShoulder"), ("LeftHand", "RightHand"), ("LeftFoot", "RightFoot"))

_BONE_CANON = {b.lower(): b for b in HUMANOID_BONES}
BONE_MAP_FIX = ("use joint names the avatar has (`studyapp inspect AVATAR` lists them) and Unity humanoid bone "
                "names (Hips, Spine, Chest, UpperChest, Neck, Head, LeftShoulder, LeftUpperArm, LeftLowerArm, "
                "LeftHand, LeftUpperLeg, LeftLowerLeg, LeftFoot, ...)")


def parse_bone_map(text: str) -> dict[str, str]:
    """``"joint=Bone,joint=Bone"`` (the command-line form of ``[avatar.bone_map]``) as a dict.

    >>> parse_bone_map("UpperArm.L=LeftUpperArm, LowerArm.L = LeftLowerArm")
    {'UpperArm.L': 'LeftUpperArm', 'LowerArm.L': 'LeftLowerArm'}
    """
    out = {}
    for item in filter(None, (p.strip() for p in text.split(","))):
        joint, sep, bone = item.partition("=")
        if not sep or not joint.strip() or not bone.strip():
            raise ValueError(f"{item!r} is not joint=Bone")
        out[joint.strip()] = bone.strip()
    return out


def canonical_bone(name: str) -> str | None:
    """The Unity humanoid bone ``name`` means (any case), or None.

    >>> canonical_bone("leftupperarm"), canonical_bone("Paw")
    ('LeftUpperArm', None)
    """
    return _BONE_CANON.get(str(name).lower()) if isinstance(name, str) else None


def _joint_lookup(names: tuple[str, ...], aliases: dict[str, str] | None) -> dict[str, str]:
    out = {n.lower(): n for n in names}
    for alias, joint in (aliases or {}).items():
        out.setdefault(alias.lower(), joint)
    out.update({n: n for n in names})  # exact names win over case-folded ones
    return out


def bone_map_problems(names: tuple[str, ...], bone_map: dict, aliases: dict[str, str] | None = None
                      ) -> list[tuple[str, str]]:
    """``(entry, problem)`` for every bad ``[avatar.bone_map]`` entry: unknown joint, unknown bone, a bone
    given twice. ``aliases`` maps other names of a joint (a VRM node's own name) to its joint name."""
    lookup = _joint_lookup(names, aliases)
    problems = []
    seen: dict[str, str] = {}
    for joint, bone in bone_map.items():
        if not isinstance(bone, str):
            problems.append((joint, "must map a joint name to a bone name (a string)"))
            continue
        canon = canonical_bone(bone)
        if lookup.get(joint, lookup.get(str(joint).lower())) is None:
            problems.append((joint, f"joint {joint!r} is not in the avatar"))
        elif canon is None:
            problems.append((joint, f"{bone!r} is not a humanoid bone name"))
        elif canon in seen:
            problems.append((joint, f"bone {canon} is already given to joint {seen[canon]!r}"))
        else:
            seen[canon] = joint
    return problems


def resolve_bone_map(names: tuple[str, ...], bone_map: dict | None, aliases: dict[str, str] | None = None
                     ) -> dict[str, str]:
    """The good entries of ``bone_map`` as ``{joint name as the skeleton spells it: canonical bone}``."""
    if not bone_map:
        return {}
    bad = {j for j, _ in bone_map_problems(names, bone_map, aliases)}
    lookup = _joint_lookup(names, aliases)
    return {lookup.get(j, lookup.get(j.lower())): canonical_bone(b) for j, b in bone_map.items() if j not in bad}


def humanoid_map(skeleton: Skeleton, bone_map: dict[str, str] | None) -> dict[str, str]:
    """``{joint: humanoid bone}``: names recognised as the retargeting recognises them, ``bone_map`` on top."""
    from studyapp.motion.retarget import merge_name_map

    return merge_name_map(skeleton, bone_map or None)


def missing_bones(skeleton: Skeleton, bone_map: dict[str, str] | None) -> list[str]:
    """Required humanoid bones no joint maps to (empty for a usable humanoid avatar)."""
    found = set(humanoid_map(skeleton, bone_map).values())
    return [b for b in REQUIRED_BONES if b not in found]


def not_humanoid_message(skeleton: Skeleton, missing: list[str]) -> str:
    """What to tell the user when an avatar lacks required bones (its joints listed, the way out named)."""
    joints = ", ".join(skeleton.names[:40]) + (f", ... ({skeleton.n_joints} in all)" if skeleton.n_joints > 40 else "")
    return (f"not a humanoid avatar: no bones for {', '.join(missing)} (joints: {joints}); "
            "give [avatar.bone_map] entries (joint name = humanoid bone) or another avatar")


#: An avatar whose rest pose leans its hips-to-head line further than this from +Y is not an upright figure.
MAX_REST_LEAN_DEG = 45.0


def not_upright_problem(skeleton: Skeleton, bone_map: dict[str, str] | None) -> str | None:
    """What to tell the user when an avatar's rest pose does not stand (its Hips and Head, found by name or
    bone map, more than 45 degrees from +Y: a four-legged animal such as Fox.glb), else None. Checked before
    missing bones, since no bone map makes such a figure humanoid: with its legs mapped, human motion
    rendered the fox stood on end."""
    from studyapp.motion.fk import rest_joint_positions

    by_bone = {b: skeleton.index(j) for j, b in humanoid_map(skeleton, bone_map).items()}
    if "Hips" not in by_bone or "Head" not in by_bone:
        return None
    pos = rest_joint_positions(skeleton)
    up = pos[by_bone["Head"]] - pos[by_bone["Hips"]]
    n = float(np.linalg.norm(up))
    lean = 90.0 if n < 1e-12 else math.degrees(math.acos(max(-1.0, min(1.0, float(up[1]) / n))))
    if lean <= MAX_REST_LEAN_DEG:
        return None
    return (f"not a humanoid avatar: its rest pose does not stand upright (hips to head {lean:.0f} degrees from "
            "up, as in a four-legged or lying figure), so human motion cannot play on it; use a humanoid avatar "
            "(standing in a T- or A-pose)")


def rest_facing(positions: np.ndarray, bones: dict[str, int]) -> np.ndarray | None:
    """Unit forward vector in the XZ plane from rest joint positions ``(J, 3)``, or None when no left/right
    pair of bones is known (or the pair is vertical)."""
    for left, right in LATERAL_PAIRS:
        if left in bones and right in bones:
            lateral = np.asarray(positions[bones[left]], float) - np.asarray(positions[bones[right]], float)
            fwd = np.cross(lateral, [0.0, 1.0, 0.0])
            fwd[1] = 0.0
            n = float(np.linalg.norm(fwd))
            if n > 1e-6 * max(float(np.linalg.norm(lateral)), 1e-12):
                return fwd / n
    return None


def yaw_to_face_z(forward: np.ndarray) -> float:
    """Angle (radians, about +Y, right-handed) that turns XZ direction ``forward`` onto +Z.

    >>> round(math.degrees(yaw_to_face_z(np.array([0.0, 0.0, -1.0]))), 6) % 360
    180.0
    """
    return -math.atan2(float(forward[0]), float(forward[2]))


def yaw_matrix(angle: float) -> np.ndarray:
    """4x4 rotation about +Y by ``angle`` radians."""
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    m[0, 0], m[0, 2], m[2, 0], m[2, 2] = c, s, -s, c
    return m


def avatar_problems(path, bone_map: dict | None) -> list[tuple[str | None, str, str]]:
    """Problems ``(design key or None, message, fix)`` with an avatar file and a design's bone map: the file
    cannot be read, a bone-map entry is bad (one problem each), or required humanoid bones are missing."""
    from pathlib import Path

    from studyapp.errors import InputError
    from studyapp.render.gltf import load_gltf

    path = Path(path)
    try:
        avatar = load_gltf(path, bone_map=bone_map or None)
    except InputError as exc:
        return [(None, f"cannot use the avatar {path.name}: {', '.join(p for p in (exc.where, exc.problem) if p)}",
                 "fix or re-export the avatar (`studyapp inspect AVATAR` shows what is read)")]
    out: list[tuple[str | None, str, str]] = [
        (f"avatar.bone_map.{joint}", f"{problem} ({path.name})", BONE_MAP_FIX)
        for joint, problem in bone_map_problems(avatar.skeleton.names, bone_map or {}, avatar.joint_aliases)]
    missing = missing_bones(avatar.skeleton, avatar.bone_map)
    if (upright := not_upright_problem(avatar.skeleton, avatar.bone_map)) is not None:
        out.append((None, f"{path.name}: {upright}", "use another avatar"))
    elif missing:
        out.append((None, f"{path.name}: {not_humanoid_message(avatar.skeleton, missing)}",
                    'add [avatar.bone_map] entries ("joint name" = "HumanoidBone") or use another avatar'))
    return out
