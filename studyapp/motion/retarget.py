"""Retargeting motion between skeletons by humanoid bone names.

Method (what Unity's Mecanim does in spirit): both skeletons live in a +Y-up world and their joints are
named onto one humanoid bone set (:mod:`studyapp.motion.rigs` recognises the rigs). For every humanoid
bone mapped on both sides, the target joint's *global* rotation in each frame is

    G_t(f) = Y * G_s(f) * X_s * X_t^T

with ``G_s(f)`` the source joint's global rotation, ``X_s`` / ``X_t`` the bone's anatomical frame in the
source's / target's local axes (:mod:`studyapp.motion.bone_frames`: along the bone, and a second
direction that fixes the twist) and ``Y`` a turn about +Y that makes the two rigs face the same way.
So a T-pose source drives an A-pose target, and a rig whose zero pose is no standing figure at all
(Bandai-Namco, LAFAN1) drives any avatar with the chest, head and hands turned as the body is.
Because only global rotations are copied, the rotation of a source joint without a counterpart (BEAT
``Spine2``, ``Neck``) ends up in the next mapped bone below it (``UpperChest``, ``Neck`` = BEAT ``Neck1``).
Unmapped target joints keep their rest local rotation. The hips move by the source hips' displacement
from rest (or from the first frame, for files that keep the standing height in the hips' channels; or
from the clip's own standing height when the rest pose does not stand) scaled by the ratio of hip
heights (which also converts units).

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
from studyapp.motion.bone_frames import body_forward, bone_axes, choose_axes, hinge_evidence, is_standing
from studyapp.motion.fk import global_transforms, rest_global_transforms
from studyapp.motion.humanoid import HUMANOID_BONES, HUMANOID_PARENT, REQUIRED_BONES
from studyapp.motion.rigs import detect_name_map, merge_name_map, missing_bones_message
from studyapp.motion.rotations import matrix_to_quat, quat_inverse, quat_multiply, quat_rotate, quat_to_matrix
from studyapp.motion.skeleton import Motion, Skeleton

__all__ = ["detect_name_map", "merge_name_map", "retarget", "facing_direction", "hip_height"]

def _rest_points(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    g = rest_global_transforms(skeleton)
    return g[:, :3, 3], g


#: Rest-pose results per rig content, so that a trial's three slots (three files on one skeleton, one avatar)
#: measure each rig once. Small and bounded: a study shows a handful of rigs.
_REST_CACHE: dict[tuple, tuple[dict[str, np.ndarray], np.ndarray, np.ndarray, np.ndarray]] = {}
_REST_CACHE_SIZE = 16


def _rest_frames(skeleton: Skeleton, bone: dict[str, int], axes) -> tuple[dict[str, np.ndarray], np.ndarray,
                                                                          np.ndarray, np.ndarray]:
    """(bone axes, forward direction, rest positions, rest transforms) of a standing rest pose, computed once
    per rig (names, hierarchy, offsets, rest rotations) and bone rules; the arrays are read-only."""
    key = (skeleton.names, skeleton.parents.tobytes(), np.asarray(skeleton.offsets, np.float64).tobytes(),
           np.asarray(skeleton.rest_rotations, np.float64).tobytes(), tuple(sorted(bone.items())),
           tuple(sorted(axes.primary.items())), tuple(sorted(axes.secondary.items())))
    hit = _REST_CACHE.get(key)
    if hit is None:
        pos, g = _rest_points(skeleton)
        x = bone_axes(g[None, :, :3, :3], pos[None], bone, axes, from_motion=False)
        fwd = body_forward(pos[None], bone)[0]
        for a in (pos, g, fwd, *x.values()):
            a.flags.writeable = False
        if len(_REST_CACHE) >= _REST_CACHE_SIZE:
            _REST_CACHE.pop(next(iter(_REST_CACHE)))
        hit = _REST_CACHE[key] = (x, fwd, pos, g)
    x, fwd, pos, g = hit
    return dict(x), fwd, pos, g


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


def _parent_map(both: set[str]) -> dict[str, str | None]:
    """Each bone's nearest ancestor in the humanoid hierarchy that is mapped on both rigs."""
    out: dict[str, str | None] = {}
    for b in both:
        p = HUMANOID_PARENT.get(b)
        while p is not None and p not in both:
            p = HUMANOID_PARENT.get(p)
        out[b] = p
    return out


def _head_top(skeleton: Skeleton, glob: np.ndarray, head: int) -> np.ndarray | None:
    """``(F, 3)`` the point farthest above the head that the head carries: a child joint or its End Site."""
    offsets = {f"joint {c}": skeleton.offsets[c] for c in skeleton.children(head)}
    if head in skeleton.end_sites:
        offsets["end"] = np.asarray(skeleton.end_sites[head], np.float64)
    if not offsets:
        return None
    off = max(offsets.values(), key=lambda v: float(np.linalg.norm(v)))
    if np.linalg.norm(off) < 1e-9:
        return None
    return np.einsum("fij,j->fi", glob[:, head, :3, :3], off) + glob[:, head, :3, 3]


#: Bones whose hinge (elbow or knee) the clip may show better than the rest pose. Not the forearm: it
#: carries pronation, so its frame turns about the hinge as the hand does.
_HINGE_BONES = ("LeftUpperArm", "RightUpperArm", "LeftUpperLeg", "RightUpperLeg", "LeftLowerLeg", "RightLowerLeg")
#: A clip must bend that joint clearly for about this fraction of its frames (in sine-weighted frames).
_MIN_HINGE_EVIDENCE = 0.05


def _clip_hinges(glob: np.ndarray, bone: dict[str, int], axes) -> dict[str, np.ndarray]:
    """Frames of the hinge bones read from the clip where it bends them clearly (see bone_frames)."""
    pos = glob[..., :3, 3]
    chosen = [b for b in _HINGE_BONES if b in axes.primary and axes.secondary.get(b) == "hinge"
              and hinge_evidence(pos, bone, b) >= _MIN_HINGE_EVIDENCE]
    if not chosen:
        return {}
    sub = type(axes)(primary={b: axes.primary[b] for b in chosen}, secondary={b: "hinge" for b in chosen})
    return bone_axes(glob[..., :3, :3], pos, bone, sub, from_motion=True)


#: Share of the hand's twist about the forearm that the forearm takes (Mecanim's "lower arm twist" default).
_FOREARM_TWIST_SHARE = 0.5


def _share_wrist_twist(t_glob_q: np.ndarray, target: Skeleton, t_bone: dict[str, int], t_g0: np.ndarray,
                       t_pos0: np.ndarray, mapped: set[str]) -> None:
    """Move half of each hand's twist about its forearm into the forearm, in place (``t_glob_q``: world
    quaternions of the target joints).

    A wrist does not twist: pronation turns the radius, and the hand with it. Many rigs keep pronation in
    the hand joint instead (ZEGGS' hands turn 69 and 84 degrees about the forearm, median over the sample
    clip, up to 176), which on an avatar whose forearm skin follows its forearm bone wrings the wrist like
    a sweet wrapper. Turning the forearm about its own axis moves no joint; split in halves, the skin twists
    half as much at the elbow as at the wrist, as a single forearm bone can best show it.
    """
    for side in ("Left", "Right"):
        fore, hand = f"{side}LowerArm", f"{side}Hand"
        if fore not in mapped or hand not in mapped:
            continue
        fj, hj = t_bone[fore], t_bone[hand]
        r0 = t_g0[fj, :3, :3]
        axis = r0.T @ (t_pos0[hj] - t_pos0[fj])  # the forearm's axis in its own local frame
        n = np.linalg.norm(axis)
        if n < 1e-9:
            continue
        axis = axis / n
        rest_rel = matrix_to_quat(r0.T @ t_g0[hj, :3, :3])
        # the hand's turn against the forearm beyond rest, in the forearm's local axes
        turn = quat_multiply(quat_multiply(quat_inverse(t_glob_q[:, fj]), t_glob_q[:, hj]), quat_inverse(rest_rel))
        # continuous over the clip: a hand turned about 180 degrees (ZEGGS reaches 176) must not make the
        # forearm jump half a turn between frames, or between a file and its float32 copy
        twist = np.unwrap(2.0 * np.arctan2(turn[:, :3] @ axis, turn[:, 3]))
        twist -= 2 * np.pi * np.round(np.median(twist) / (2 * np.pi))
        half = 0.5 * _FOREARM_TWIST_SHARE * twist
        spin = np.concatenate([np.sin(half)[:, None] * axis, np.cos(half)[:, None]], axis=1)
        t_glob_q[:, fj] = quat_multiply(t_glob_q[:, fj], spin)


def _same_rig(a: Skeleton, b: Skeleton) -> bool:
    return a is b or (a.names == b.names and a.offsets.shape == b.offsets.shape
                      and np.allclose(a.offsets, b.offsets, atol=1e-9))


def _standing_height(pos: np.ndarray, hips: int) -> tuple[float, float]:
    """Hip height above the lowest joint (median over frames) and the floor height, from ``(F, J, 3)``."""
    lowest = pos[:, :, 1].min(axis=1)
    return float(np.median(pos[:, hips, 1] - lowest)), float(lowest.min())


def retarget(
    source: Motion,
    target: Skeleton,
    name_map: dict[str, str] | None = None,
    target_map: dict[str, str] | None = None,
    target_source: str | None = None,
) -> Motion:
    """``source`` played on the ``target`` skeleton (same fps and frame count).

    ``name_map`` / ``target_map`` are ``{joint: humanoid bone}`` entries for the source / target rig
    that override (or complete) the detected built-in maps. ``target_source`` names the target's file
    (an avatar) in messages. Raises :class:`InputError` naming the file whose rig lacks required bones,
    listing its joints and the bones still missing.

    Every bone mapped on both rigs gets the source's anatomical orientation (see
    :mod:`studyapp.motion.bone_frames`): ``G_t(f) = Y G_s(f) X_s X_t^T`` with ``X_s``, ``X_t`` the bone's
    anatomical frame in each rig's local axes and ``Y`` the turn about +Y between the rigs' facings.
    """
    smap = merge_name_map(source.skeleton, name_map)
    tmap = merge_name_map(target, target_map, what=target_source)
    s_bone = {b: source.skeleton.index(j) for j, b in smap.items()}
    t_bone = {b: target.index(j) for j, b in tmap.items()}
    missing_s = [b for b in REQUIRED_BONES if b not in s_bone]
    missing_t = [b for b in REQUIRED_BONES if b not in t_bone]
    if missing_s:
        raise InputError(source.source or None, "skeleton", missing_bones_message(source.skeleton, smap, "name_map"))
    if missing_t:
        raise InputError(target_source, "skeleton",
                         missing_bones_message(target, tmap, "[avatar.bone_map]", what="avatar"))
    both = {b for b in HUMANOID_BONES if b in s_bone and b in t_bone}
    axes = choose_axes(both, _parent_map(both))

    s_glob = global_transforms(source.skeleton, source.rotations, source.translations)
    s_pos0, s_g0 = _rest_points(source.skeleton)
    # A rig copied onto itself needs no anatomy: its own rest frames on both sides cancel, whatever its pose.
    same = _same_rig(source.skeleton, target)
    standing = same or is_standing(s_pos0, s_bone)
    if standing:
        x_s, s_fwd, _, _ = _rest_frames(source.skeleton, s_bone, axes)
        if not same:
            x_s.update(_clip_hinges(s_glob, s_bone, axes))
    else:  # the zero pose carries no anatomy: read it from the animation
        x_s = bone_axes(s_glob[..., :3, :3], s_glob[..., :3, 3], s_bone, axes, from_motion=True,
                        head_top=_head_top(source.skeleton, s_glob, s_bone["Head"]))
        s_fwd = body_forward(s_glob[..., :3, 3], s_bone).mean(axis=0)
    x_t, t_fwd, t_pos0, t_g0 = _rest_frames(target, t_bone, axes)
    yaw = _yaw_between(s_fwd, t_fwd)
    yaw_m = quat_to_matrix(yaw)

    f = source.n_frames
    t_glob_q = np.empty((f, target.n_joints, 4))
    set_global = np.zeros(target.n_joints, dtype=bool)
    mapped = list(axes.primary)
    if mapped:
        sj = [s_bone[b] for b in mapped]
        tj = [t_bone[b] for b in mapped]
        corr = np.stack([x_s[b] @ x_t[b].T for b in mapped])
        t_glob_q[:, tj] = matrix_to_quat(yaw_m @ s_glob[:, sj, :3, :3] @ corr[None])
        set_global[tj] = True
        if not same:
            _share_wrist_twist(t_glob_q, target, t_bone, t_g0, t_pos0, set(mapped))

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
    h_t = hip_height(target, th)
    if standing:
        h_s = hip_height(source.skeleton, sh)
        # The hips travel relative to where the source stands at rest. Some exporters (BEAT, DiffSHEG's demo
        # conversions) keep the skeleton's rest hips on the floor and put the standing height in the hips'
        # position channels; a displacement from that rest would lift the target by a whole hip height. When
        # the first frame stands about one hip height above the rest hips, that height is part of the rest.
        s_ref = s_pos0[sh].copy()
        lift = float(s_glob[0, sh, 1, 3] - s_ref[1])
        if h_s > 1e-9 and abs(lift - h_s) < 0.2 * h_s:
            s_ref[1] += h_s
    else:  # no standing rest to measure from: the clip's own standing height over its floor
        h_s, floor = _standing_height(s_glob[..., :3, 3], sh)
        s_ref = s_glob[0, sh, :3, 3].copy()
        s_ref[1] = floor + h_s
    if h_s > 1e-9 and h_t > 1e-9:
        scale = h_t / h_s
    elif source.skeleton.unit_scale and target.unit_scale:
        scale = source.skeleton.unit_scale / target.unit_scale
    else:
        scale = 1.0
    disp = quat_rotate(yaw, s_glob[:, sh, :3, 3] - s_ref) * scale
    hips_world = t_pos0[th] + disp
    ph = int(target.parents[th])
    if ph < 0:
        trans[:, th] = hips_world
    else:
        # hips' parent (e.g. an armature node) is never animated: express the point in its rest frame
        pg = t_g0[ph]
        trans[:, th] = (hips_world - pg[:3, 3]) @ np.linalg.inv(pg[:3, :3]).T
    _carry_detached(target, rot, trans, t_bone, _parent_map(set(axes.primary)), t_g0)
    return Motion(target, float(source.fps), rot, trans, source=source.source)


def _is_ancestor(skeleton: Skeleton, a: int, j: int) -> bool:
    p = int(skeleton.parents[j])
    while p >= 0:
        if p == a:
            return True
        p = int(skeleton.parents[p])
    return False


def _carry_detached(target: Skeleton, rot: np.ndarray, trans: np.ndarray, t_bone: dict[str, int],
                    parent_of: dict[str, str | None], t_g0: np.ndarray) -> None:
    """Move each mapped bone that does not hang from its humanoid parent in the target's hierarchy with
    that parent, in place (``trans``).

    IK-rigged characters (RobotExpressive: ``Foot.L`` hangs from the armature root, next to the pole
    targets, not from ``LowerLeg.L``; its thighs hang from ``Body``, beside ``Hips``) leave such a bone where
    the armature puts it: with only rotations copied, the feet stayed on the rest floor spot while the legs
    stepped and bent away from them (shins off by up to 94 degrees).
    The bone's position is put where the parent carries its rest position (its rotation is already set).
    """
    # parents first (humanoid order), so that a detached thigh has moved before the foot below it is placed
    detached = [(t_bone[b], t_bone[p]) for b, p in sorted(parent_of.items(), key=lambda bp: HUMANOID_BONES.index(bp[0]))
                if p is not None and not _is_ancestor(target, t_bone[p], t_bone[b])]
    for j, pj in detached:
        glob = global_transforms(target, rot, trans)
        at_rest = np.linalg.inv(t_g0[pj]) @ t_g0[j, :, 3]  # the bone's rest position in the parent's frame
        want = glob[:, pj] @ at_rest
        hp = int(target.parents[j])
        if hp < 0:
            trans[:, j] = want[:, :3]
        else:
            trans[:, j] = (np.linalg.inv(glob[:, hp]) @ want[..., None])[:, :3, 0]
