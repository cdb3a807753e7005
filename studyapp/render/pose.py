"""Turn a motion (any skeleton) and a face animation into per-frame GPU inputs for one avatar slot.

Everything heavy happens once, when a trial loads: retargeting, resampling to the playback rate, forward
kinematics and the skinning palettes (float32, what the GPU takes; see :data:`PALETTE_FLOAT32_TOLERANCE`).
Per displayed frame :meth:`SlotAnimation.frame_at` only blends two neighbouring precomputed frames.

Interpolation: the source motion (often 15 fps) is resampled at load to ``playback_fps`` (60 by default)
with quaternion slerp of the local rotations and linear interpolation of translations, then
:meth:`SlotAnimation.frame_at` blends the two nearest resampled palettes linearly (the rotation between
two 1/60 s frames is tiny, so a linear blend of matrices is indistinguishable from slerp).

>>> from studyapp.render.avatar import build_default_avatar
>>> from studyapp.motion.skeleton import Motion
>>> av = build_default_avatar()
>>> slot = prepare_slot(av, Motion.rest(av.skeleton, n_frames=15, fps=15.0), None)
>>> palette, weights = slot.frame_at(0.5)
>>> palette.shape, weights.shape, round(float(abs(palette[0] - np.eye(4)).max()), 6)
((52, 4, 4), (52,), 0.0)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_NAMES
from studyapp.motion.fk import global_transforms, rest_joint_positions
from studyapp.motion.rotations import euler_to_quat, quat_multiply, quat_slerp
from studyapp.motion.skeleton import Motion, Skeleton
from studyapp.render.avatar import Avatar

DEFAULT_PLAYBACK_FPS = 60.0


@dataclass(eq=False)
class SlotAnimation:
    """One slot's animation, ready for the GPU.

    Attributes
    ----------
    fps:
        Rate of the precomputed frames (the playback rate, not the source's).
    palettes:
        ``(F, J, 4, 4) float32`` skinning matrices (joint world transform x inverse bind).
    face_weights:
        ``(F, M) float32`` morph weights at the same rate, in the avatar's ``morph_names`` order.
    head_rotation:
        ``(F, 3)`` yaw/pitch/roll (radians) that was added to the Head bone, or None.
    duration:
        Seconds of motion (``t`` beyond it holds the last frame).
    joint_positions:
        ``(F, J, 3)`` world joint positions (for framing the camera and the contact shadow).
    """

    fps: float
    palettes: np.ndarray
    face_weights: np.ndarray
    head_rotation: np.ndarray | None
    duration: float
    joint_positions: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(self.palettes.shape[0])

    def _index(self, t: float) -> tuple[int, int, float]:
        pos = min(max(float(t), 0.0) * self.fps, self.n_frames - 1)
        i0 = int(np.floor(pos))
        i1 = min(i0 + 1, self.n_frames - 1)
        return i0, i1, pos - i0

    def frame_at(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Palette ``(J, 4, 4) float32`` and morph weights ``(M,) float32`` at ``t`` seconds (linear blend)."""
        i0, i1, a = self._index(t)
        if a == 0.0 or i0 == i1:
            return self.palettes[i0], self.face_weights[i0]
        pal = self.palettes[i0] * np.float32(1 - a) + self.palettes[i1] * np.float32(a)
        w = self.face_weights[i0] * np.float32(1 - a) + self.face_weights[i1] * np.float32(a)
        return pal, w

    def joints_at(self, t: float) -> np.ndarray:
        """World joint positions ``(J, 3)`` at ``t`` seconds."""
        i0, i1, a = self._index(t)
        return self.joint_positions[i0] * (1 - a) + self.joint_positions[i1] * a


#: Largest difference of a palette entry computed in float32 (this module) from one computed in float64, for
#: motions in metres (what :func:`to_avatar_skeleton` gives): measured at most 5.3e-7 for rotation entries
#: and 1.1e-6 m for translations on the built-in avatar and the sample glTF/VRM characters playing the demo's
#: and real BEAT, ZEGGS, CMU and Mixamo motion (tests/render/test_palettes_float32.py), with a tenfold margin
#: here. A hundredth of a millimetre is under a thousandth of a pixel for a figure 600 pixels tall: rendered
#: frames differ by one colour level on about a hundred of 921,600 pixels.
PALETTE_FLOAT32_TOLERANCE = 1e-5


def _world_and_palettes(avatar: Avatar, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """World transforms and skinning matrices ``(F, J, 4, 4)``, both float32.

    Float32 throughout, what the GPU takes: forward kinematics in float32 and the inverse bind matrices
    (stored float32) folded in float32, instead of float64 products rounded at the end, which cost twice
    the memory traffic and a full-size conversion pass for no visible difference
    (:data:`PALETTE_FLOAT32_TOLERANCE`).
    """
    world = global_transforms(avatar.skeleton, motion.rotations, motion.translations, dtype=np.float32)
    return world, np.matmul(world, np.asarray(avatar.inverse_bind, np.float32))


def skinning_palettes(avatar: Avatar, motion: Motion) -> np.ndarray:
    """``(F, J, 4, 4) float32`` skinning matrices of a motion on the avatar's own skeleton.

    Computed once per trial: batched forward kinematics (``studyapp.motion.fk``) times the inverse bind
    matrices, in float32 (within :data:`PALETTE_FLOAT32_TOLERANCE` of float64). The rest pose gives
    identity matrices.
    """
    if motion.skeleton.n_joints != avatar.skeleton.n_joints:
        raise ValueError(f"motion has {motion.skeleton.n_joints} joints, avatar skeleton {avatar.skeleton.n_joints}; "
                         "retarget first (prepare_slot does)")
    return _world_and_palettes(avatar, motion)[1]


def resample_motion(motion: Motion, fps: float) -> Motion:
    """The motion at ``fps`` (slerp of local rotations, linear translations), same duration (last frame held)."""
    n_out = max(1, int(round(motion.duration * fps)))
    pos = np.clip(np.arange(n_out) * motion.fps / fps, 0, motion.n_frames - 1)
    i0 = np.floor(pos).astype(np.int64)
    i1 = np.minimum(i0 + 1, motion.n_frames - 1)
    a = pos - i0
    rot = quat_slerp(motion.rotations[i0], motion.rotations[i1], np.broadcast_to(a[:, None], (n_out, motion.skeleton.n_joints)))
    tr = motion.translations[i0] * (1 - a)[:, None, None] + motion.translations[i1] * a[:, None, None]
    return Motion(motion.skeleton, fps, rot, tr, source=motion.source)


def _same_skeleton(a: Skeleton, b: Skeleton) -> bool:
    return a is b or (a.names == b.names and np.allclose(a.offsets, b.offsets, atol=1e-6))


def to_avatar_skeleton(avatar: Avatar, motion: Motion, name_map: dict[str, str] | None = None) -> Motion:
    """The motion on the avatar's skeleton, in metres, standing where the avatar stands.

    Uses ``studyapp.motion.retarget.retarget`` (humanoid bone names; it scales the hips' travel by the ratio
    of hip heights, which converts centimetres to metres) unless the motion already is on the avatar's
    skeleton. The first frame is centred horizontally on the avatar's rest hips, and the clip stands on the
    avatar's floor: its lowest joint, in the frames where it is lowest (5th percentile), is as high as the
    avatar's lowest joint at rest. Rigs disagree on where their feet are relative to their hips (CMU's stood
    15 cm above the floor), and a floating or sunken figure looks wrong for reasons no model caused.
    """
    target = avatar.skeleton
    if _same_skeleton(motion.skeleton, target):
        return motion
    from studyapp.motion.retarget import retarget

    out = retarget(motion, target, name_map=name_map, target_map=avatar.bone_map or None)
    # Presentation, not retargeting: every slot starts centred on its own floor spot whatever the source's
    # position on the capture stage was, so no avatar stands off-centre in its third of the screen.
    trans = out.translations.copy()
    roots = np.flatnonzero(target.parents < 0)
    for r in roots:
        trans[:, r, [0, 2]] -= trans[0, r, [0, 2]] - target.offsets[r, [0, 2]]
    # float32: a hundredth of a millimetre does not move a figure on its floor
    lowest = global_transforms(target, out.rotations, trans, dtype=np.float32)[:, :, 1, 3].min(axis=1)
    rest_lowest = float(rest_joint_positions(target)[:, 1].min())
    trans[:, roots, 1] -= float(np.percentile(lowest, 5.0)) - rest_lowest
    return Motion(target, out.fps, out.rotations, trans, source=out.source or motion.source)


def _apply_head_rotation(motion: Motion, head_index: int, ypr: np.ndarray) -> Motion:
    q = euler_to_quat(np.asarray(ypr, np.float64)[:, [1, 0, 2]], "XYZ", degrees=False)
    rot = motion.rotations.copy()
    rot[:, head_index] = quat_multiply(rot[:, head_index], q)
    return Motion(motion.skeleton, motion.fps, rot, motion.translations, source=motion.source)


def _face_matrix(avatar: Avatar, face: FaceAnimation | None, times: np.ndarray) -> np.ndarray:
    """Face weights sampled at ``times`` and reordered to the avatar's morph order."""
    m = len(avatar.morph_names)
    out = np.zeros((len(times), m), np.float32)
    if face is None:
        return out
    sampled = face.sample(times)
    col = {name: i for i, name in enumerate(ARKIT_NAMES)}
    for j, name in enumerate(avatar.morph_names):
        if name in col:
            out[:, j] = sampled[:, col[name]]
    return out


def prepare_slot(avatar: Avatar, motion: Motion, face: FaceAnimation | None, name_map: dict[str, str] | None = None,
                 playback_fps: float = DEFAULT_PLAYBACK_FPS) -> SlotAnimation:
    """Everything one slot needs for playback, computed once.

    Retargets ``motion`` onto the avatar (see :func:`to_avatar_skeleton`), resamples it to
    ``playback_fps``, adds the face's head rotation (yaw about +Y, pitch about +X, roll about +Z of the
    Head bone, applied after the body's own head rotation) when present, computes the skinning palettes
    and samples the face weights at the same rate.
    """
    body = to_avatar_skeleton(avatar, motion, name_map)
    body = resample_motion(body, playback_fps)
    times = np.arange(body.n_frames) / playback_fps
    head_ypr = None
    if face is not None and face.head_rotation is not None and "Head" in avatar.skeleton.names:
        src = np.asarray(face.head_rotation, np.float64)
        src_t = np.arange(len(src)) / face.fps
        head_ypr = np.stack([np.interp(times, src_t, src[:, k]) for k in range(3)], -1)
        body = _apply_head_rotation(body, avatar.skeleton.index("Head"), head_ypr)
    world, palettes = _world_and_palettes(avatar, body)
    return SlotAnimation(
        fps=float(playback_fps),
        palettes=palettes,
        face_weights=_face_matrix(avatar, face, times),
        head_rotation=head_ypr,
        duration=float(motion.duration),
        joint_positions=np.ascontiguousarray(world[:, :, :3, 3]),
    )
