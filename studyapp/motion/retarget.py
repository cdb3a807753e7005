"""Retargeting motion between skeletons by humanoid bone names.

Method (what Unity's Mecanim does in spirit): both skeletons live in a +Y-up world. For every
humanoid bone mapped on both sides, the target joint's *global* rotation in each frame is

    G_t(f) = Y * G_s(f) * G_s0^-1 * Y^-1 * C * G_t0

with ``G_s(f)`` the source joint's global rotation, ``G_s0`` / ``G_t0`` the source / target global rest
rotations, ``Y`` a turn about +Y that makes the two rigs face the same way (VRM 0.x faces -Z, most
others +Z) and ``C`` a per-bone rest correction: the shortest rotation taking the target bone's
rest direction (towards its mapped child) onto the source bone's, so a T-pose source drives an
A-pose target correctly. Because only global rotations are copied, the rotation of a source joint
without a counterpart (BEAT ``Spine2``, ``Neck``) ends up in the next mapped bone below it
(``UpperChest``, ``Neck`` = BEAT ``Neck1``).
Unmapped target joints keep their rest local rotation. The hips move by the source hips' displacement
from rest (or from the first frame, for files that keep the standing height in the hips' channels) scaled
by the ratio of hip heights (which also converts units).

>>> from studyapp.motion.beat import beat_skeleton
>>> from studyapp.motion.skeleton import Motion
>>> m = Motion.rest(beat_skeleton(), n_frames=2, fps=15)
>>> out = retarget(m, beat_skeleton())
>>> out.n_frames, out.fps, out.skeleton.n_joints
(2, 15.0, 75)
"""
from __future__ import annotations

import math

import numpy as np

from studyapp.errors import InputError
from studyapp.motion.fk import global_transforms, rest_global_transforms
from studyapp.motion.humanoid import BUILTIN_MAPS, HUMANOID_BONES, REQUIRED_BONES
from studyapp.motion.rotations import matrix_to_quat, quat_between, quat_inverse, quat_multiply, quat_rotate
from studyapp.motion.skeleton import Motion, Skeleton

__all__ = ["detect_name_map", "merge_name_map", "retarget", "facing_direction", "hip_height"]

# the child bone whose direction defines each bone's "direction" for the rest correction
_DIRECTION_CHILD: dict[str, tuple[str, ...]] = {
    "Hips": ("Spine", "Chest", "UpperChest", "Neck", "Head"),
    "Spine": ("Chest", "UpperChest", "Neck", "Head"),
    "Chest": ("UpperChest", "Neck", "Head"),
    "UpperChest": ("Neck", "Head"),
    "Neck": ("Head",),
}
for _s in ("Left", "Right"):
    _DIRECTION_CHILD.update({
        f"{_s}Shoulder": (f"{_s}UpperArm",),
        f"{_s}UpperArm": (f"{_s}LowerArm",),
        f"{_s}LowerArm": (f"{_s}Hand",),
        f"{_s}Hand": (f"{_s}MiddleProximal", f"{_s}IndexProximal", f"{_s}RingProximal", f"{_s}LittleProximal"),
        f"{_s}UpperLeg": (f"{_s}LowerLeg",),
        f"{_s}LowerLeg": (f"{_s}Foot",),
        f"{_s}Foot": (f"{_s}Toes",),
    })
    for _f in ("Thumb", "Index", "Middle", "Ring", "Little"):
        _DIRECTION_CHILD[f"{_s}{_f}Proximal"] = (f"{_s}{_f}Intermediate",)
        _DIRECTION_CHILD[f"{_s}{_f}Intermediate"] = (f"{_s}{_f}Distal",)


def _strip_namespace(name: str) -> str:
    for sep in (":", "|"):
        if sep in name:
            name = name.rsplit(sep, 1)[1]
    return name


def _apply_map(names: tuple[str, ...], table: dict[str, str]) -> dict[str, str]:
    """Match a built-in table to joint names: exact (case-insensitive) first, then without namespace prefix.

    Joints are visited deepest-first (reverse depth-first order), so when a table names one bone for
    two joints of a chain (BEAT ``Neck``, ``Neck1``) the upper joint gets it and the lower one's
    rotation is composed into it by :func:`retarget`.
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


def detect_name_map(skeleton: Skeleton) -> dict[str, str]:
    """``{joint name: humanoid bone}`` from the built-in map that matches the most joints.

    Never raises: an unknown rig gives a partial (possibly empty) map; :func:`retarget` reports the
    missing required bones.

    >>> from studyapp.motion.beat import beat_skeleton
    >>> m = detect_name_map(beat_skeleton())
    >>> m["RightForeArm"], m["Spine3"], "Spine2" in m
    ('RightLowerArm', 'UpperChest', False)
    """
    best: dict[str, str] = {}
    best_key = (-1, -1)
    for table in BUILTIN_MAPS.values():
        got = _apply_map(skeleton.names, table)
        key = (sum(b in got.values() for b in REQUIRED_BONES), len(got))
        if key > best_key:
            best, best_key = got, key
    return best


def merge_name_map(skeleton: Skeleton, override: dict[str, str] | None) -> dict[str, str]:
    """Detected map with ``override`` entries (``{joint: bone}``, e.g. from a study design) on top.

    An override entry replaces whatever joint the built-in map gave that bone. Joint names in
    ``override`` match exactly first, then case-insensitively.
    """
    mapping = detect_name_map(skeleton)
    if not override:
        return mapping
    lower = {n.lower(): n for n in skeleton.names}
    known = {b.lower(): b for b in HUMANOID_BONES}
    for src, bone in override.items():
        name = src if src in skeleton.names else lower.get(src.lower())
        if name is None:
            raise InputError(None, f"name_map.{src}", f"joint {src!r} is not in the skeleton ({skeleton.n_joints} joints)")
        canon = known.get(str(bone).lower())
        if canon is None:
            raise InputError(None, f"name_map.{src}", f"{bone!r} is not a humanoid bone name (e.g. LeftUpperArm)")
        mapping = {k: v for k, v in mapping.items() if v != canon and k != name}
        mapping[name] = canon
    return mapping


def _rest_points(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    g = rest_global_transforms(skeleton)
    return g[:, :3, 3], g


def hip_height(skeleton: Skeleton, hips: int) -> float:
    """Height of the hips above the lowest joint of the rest pose (file units)."""
    pos, _ = _rest_points(skeleton)
    return float(pos[hips, 1] - pos[:, 1].min())


def facing_direction(skeleton: Skeleton, bones: dict[str, int]) -> np.ndarray:
    """Unit forward vector (in the XZ plane) of a rig's rest pose: up x (left - right) flipped to forward.

    Uses the upper legs, else the upper arms, else the shoulders; ``+Z`` when none are mapped.
    """
    pos, _ = _rest_points(skeleton)
    for left, right in (("LeftUpperLeg", "RightUpperLeg"), ("LeftUpperArm", "RightUpperArm"), ("LeftShoulder", "RightShoulder")):
        if left in bones and right in bones:
            lateral = pos[bones[left]] - pos[bones[right]]
            fwd = np.cross(lateral, [0.0, 1.0, 0.0])
            fwd[1] = 0.0
            n = np.linalg.norm(fwd)
            if n > 1e-9:
                return fwd / n
    return np.array([0.0, 0.0, 1.0])


def _yaw_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Quaternion turning about +Y that takes XZ direction ``a`` to ``b`` (exact for opposite directions)."""
    angle = math.atan2(a[2], a[0]) - math.atan2(b[2], b[0])  # rotation about +Y: x->-z is positive
    return np.array([0.0, math.sin(angle / 2), 0.0, math.cos(angle / 2)])


def _direction_child(bone: str, mapped: set[str]) -> str | None:
    for child in _DIRECTION_CHILD.get(bone, ()):
        if child in mapped:
            return child
    return None


def retarget(
    source: Motion,
    target: Skeleton,
    name_map: dict[str, str] | None = None,
    target_map: dict[str, str] | None = None,
) -> Motion:
    """``source`` played on the ``target`` skeleton (same fps and frame count).

    ``name_map`` / ``target_map`` are ``{joint: humanoid bone}`` entries for the source / target rig
    that override (or complete) the detected built-in maps. Raises :class:`InputError` listing every
    required humanoid bone that either side cannot map.
    """
    smap = merge_name_map(source.skeleton, name_map)
    tmap = merge_name_map(target, target_map)
    s_bone = {b: source.skeleton.index(j) for j, b in smap.items()}
    t_bone = {b: target.index(j) for j, b in tmap.items()}
    missing_s = [b for b in REQUIRED_BONES if b not in s_bone]
    missing_t = [b for b in REQUIRED_BONES if b not in t_bone]
    if missing_s or missing_t:
        parts = []
        if missing_s:
            parts.append(f"source skeleton ({source.skeleton.n_joints} joints) has no joint for {', '.join(missing_s)}")
        if missing_t:
            parts.append(f"target skeleton ({target.n_joints} joints) has no joint for {', '.join(missing_t)}")
        raise InputError(
            source.source or None, "name map",
            "cannot retarget: " + "; ".join(parts) + ". Add name_map entries (joint name = humanoid bone).",
        )
    bones = [b for b in HUMANOID_BONES if b in s_bone and b in t_bone]
    both = set(bones)

    s_pos0, s_g0 = _rest_points(source.skeleton)
    t_pos0, t_g0 = _rest_points(target)
    s_q0 = matrix_to_quat(s_g0[:, :3, :3])
    t_q0 = matrix_to_quat(t_g0[:, :3, :3])
    yaw = _yaw_between(facing_direction(source.skeleton, s_bone), facing_direction(target, t_bone))

    s_glob = global_transforms(source.skeleton, source.rotations, source.translations)
    f = source.n_frames
    t_glob_q = np.empty((f, target.n_joints, 4))
    set_global = np.zeros(target.n_joints, dtype=bool)
    for b in bones:
        sj, tj = s_bone[b], t_bone[b]
        child = _direction_child(b, both)
        if child is not None:
            d_s = quat_rotate(yaw, s_pos0[s_bone[child]] - s_pos0[sj])
            d_t = t_pos0[t_bone[child]] - t_pos0[tj]
            corr = quat_between(d_t, d_s)
        else:
            corr = np.array([0.0, 0.0, 0.0, 1.0])
        # world-space delta of the source bone since its rest pose, turned into the target's facing
        gs = matrix_to_quat(s_glob[:, sj, :3, :3])
        delta = quat_multiply(quat_multiply(yaw, quat_multiply(gs, quat_inverse(s_q0[sj]))), quat_inverse(yaw))
        t_glob_q[:, tj] = quat_multiply(delta, quat_multiply(corr, t_q0[tj]))
        set_global[tj] = True

    # local rotations: walk the target in depth-first order
    rot = np.empty((f, target.n_joints, 4))
    glob = np.empty((f, target.n_joints, 4))
    for j in range(target.n_joints):
        p = int(target.parents[j])
        if set_global[j]:
            glob[:, j] = t_glob_q[:, j]
            rot[:, j] = glob[:, j] if p < 0 else quat_multiply(quat_inverse(glob[:, p]), glob[:, j])
        else:
            rot[:, j] = target.rest_rotations[j]
            glob[:, j] = rot[:, j] if p < 0 else quat_multiply(glob[:, p], rot[:, j])
    rot /= np.linalg.norm(rot, axis=-1, keepdims=True)

    trans = np.broadcast_to(target.offsets, (f, target.n_joints, 3)).copy()
    sh, th = s_bone["Hips"], t_bone["Hips"]
    h_s, h_t = hip_height(source.skeleton, sh), hip_height(target, th)
    if h_s > 1e-9 and h_t > 1e-9:
        scale = h_t / h_s
    elif source.skeleton.unit_scale and target.unit_scale:
        scale = source.skeleton.unit_scale / target.unit_scale
    else:
        scale = 1.0
    # The hips travel relative to where the source stands at rest. Some exporters (BEAT, DiffSHEG's demo
    # conversions) keep the skeleton's rest hips on the floor and put the standing height in the hips'
    # position channels; a displacement from that rest would lift the target by a whole hip height. When
    # the first frame stands about one hip height above the rest hips, that height is part of the rest.
    s_ref = s_pos0[sh].copy()
    lift = float(s_glob[0, sh, 1, 3] - s_ref[1])
    if h_s > 1e-9 and abs(lift - h_s) < 0.2 * h_s:
        s_ref[1] += h_s
    disp = quat_rotate(yaw, s_glob[:, sh, :3, 3] - s_ref) * scale
    hips_world = t_pos0[th] + disp
    ph = int(target.parents[th])
    if ph < 0:
        trans[:, th] = hips_world
    else:
        # hips' parent (e.g. an armature node) is never animated: express the point in its rest frame
        pg = t_g0[ph]
        trans[:, th] = (hips_world - pg[:3, 3]) @ np.linalg.inv(pg[:3, :3]).T
    return Motion(target, float(source.fps), rot, trans, source=source.source)
