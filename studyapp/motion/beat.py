"""The BEAT dataset's 75-joint skeleton, built in code, and its 47-joint upper-body subset.

BEAT (Liu et al. 2022) motion capture and the models trained on it (CaMN, DiffSHEG, FaceCapGes) share
one hierarchy: root ``Hips`` with six channels, every other joint ``Xrotation Yrotation Zrotation``,
centimetres, about 180 cm tall, facing +Z with the character's right hand towards -X. The offsets
below are those of the released data (as found in DiffSHEG's BVH output); note two quirks of the
real rig kept on purpose: the pinky chain hangs under ``*HandRing`` and the thumb under ``*HandIndex``,
and ``HeadEnd`` / ``*Middle4`` etc. are real joints with channels *and* an End Site.

>>> sk = beat_skeleton()
>>> sk.n_joints, sk.names[0], len(BEAT_UPPER_BODY), sk.unit_scale
(75, 'Hips', 47, 0.01)
"""
from __future__ import annotations

import numpy as np

from studyapp.motion.rotations import quat_normalize
from studyapp.motion.skeleton import Motion, Skeleton

__all__ = [
    "BEAT_JOINTS",
    "BEAT_UPPER_BODY",
    "BEAT_FPS",
    "BEAT_MODEL_FPS",
    "beat_skeleton",
    "beat_upper_body_indices",
    "beat_motion_from_upper_body",
]

#: Native capture rate of BEAT motion and the rate the gesture models are trained/emit at.
BEAT_FPS = 120.0
BEAT_MODEL_FPS = 15.0

# (name, parent, offset in cm), depth-first as in the released BVH files.
_HIERARCHY: tuple[tuple[str, str | None, tuple[float, float, float]], ...] = (
('Hips', None, (0.0, 0.0, 0.0)),
    ('Spine', 'Hips', (0.0, 8.340413, -2.71395)),
    ('Spine1', 'Spine', (0.0, 11.909995, -2.100054)),
    ('Spine2', 'Spine1', (0.0, 12.047703, -1.054038)),
    ('Spine3', 'Spine2', (0.0, 12.093727, 0.0)),
    ('Neck', 'Spine3', (0.0, 15.54908, 1.554907)),
    ('Neck1', 'Neck', (0.0, 4.68734, 0.410089)),
    ('Head', 'Neck1', (0.0, 4.633774, 0.817058)),
    ('HeadEnd', 'Head', (0.0, 9.727722, 0.0)),
    ('RightShoulder', 'Spine3', (0.0, 11.106487, 6.072617)),
    ('RightArm', 'RightShoulder', (-19.427898, 8e-06, 0.0)),
    ('RightForeArm', 'RightArm', (-29.35075, 8e-06, 0.0)),
    ('RightHand', 'RightForeArm', (-27.018089, 8e-06, 0.0)),
    ('RightHandMiddle1', 'RightHand', (-9.244034, 4e-06, 0.0)),
    ('RightHandMiddle2', 'RightHandMiddle1', (-4.870026, 0.0, 0.0)),
    ('RightHandMiddle3', 'RightHandMiddle2', (-3.169075, 0.0, 0.0)),
    ('RightHandMiddle4', 'RightHandMiddle3', (-1.888374, 0.0, 0.0)),
    ('RightHandRing', 'RightHand', (-0.25, -0.25, -0.956503)),
    ('RightHandRing1', 'RightHandRing', (-8.140221, 4e-06, -0.734604)),
    ('RightHandRing2', 'RightHandRing1', (-4.501564, 0.0, -0.406238)),
    ('RightHandRing3', 'RightHandRing2', (-3.06884, 0.0, -0.276944)),
    ('RightHandRing4', 'RightHandRing3', (-1.869919, 0.0, -0.168749)),
    ('RightHandPinky', 'RightHandRing', (-0.163017, -0.25, -0.975101)),
    ('RightHandPinky1', 'RightHandPinky', (-6.681488, 4e-06, -1.494111)),
    ('RightHandPinky2', 'RightHandPinky1', (-3.580948, 0.0, -0.800769)),
    ('RightHandPinky3', 'RightHandPinky2', (-2.276527, 0.0, -0.509077)),
    ('RightHandPinky4', 'RightHandPinky3', (-1.690346, 0.0, -0.377994)),
    ('RightHandIndex', 'RightHand', (-0.25, -0.25, 0.956503)),
    ('RightHandIndex1', 'RightHandIndex', (-8.934097, 4e-06, 0.806247)),
    ('RightHandIndex2', 'RightHandIndex1', (-4.694687, 0.0, 0.423666)),
    ('RightHandIndex3', 'RightHandIndex2', (-2.811722, 0.0, 0.253741)),
    ('RightHandIndex4', 'RightHandIndex3', (-1.709946, 0.0, 0.154312)),
    ('RightHandThumb1', 'RightHandIndex', (-0.163017, -0.75, 0.975101)),
    ('RightHandThumb2', 'RightHandThumb1', (-5.411659, 0.835533, 2.244703)),
    ('RightHandThumb3', 'RightHandThumb2', (-3.567184, 0.550758, 1.479634)),
    ('RightHandThumb4', 'RightHandThumb3', (-2.150558, 0.332031, 0.892029)),
    ('LeftShoulder', 'Spine3', (0.0, 11.106487, 6.072617)),
    ('LeftArm', 'LeftShoulder', (19.427898, 8e-06, 0.0)),
    ('LeftForeArm', 'LeftArm', (29.35075, 8e-06, 0.0)),
    ('LeftHand', 'LeftForeArm', (27.018089, 8e-06, 0.0)),
    ('LeftHandMiddle1', 'LeftHand', (9.402672, 4e-06, 0.0)),
    ('LeftHandMiddle2', 'LeftHandMiddle1', (4.950096, 0.0, 0.0)),
    ('LeftHandMiddle3', 'LeftHandMiddle2', (3.211952, 0.0, 0.0)),
    ('LeftHandMiddle4', 'LeftHandMiddle3', (1.927605, 0.0, 0.0)),
    ('LeftHandRing', 'LeftHand', (0.25, -0.25, -0.90616)),
    ('LeftHandRing1', 'LeftHandRing', (8.286079, 4e-06, -0.747767)),
    ('LeftHandRing2', 'LeftHandRing1', (4.585472, 0.0, -0.41381)),
    ('LeftHandRing3', 'LeftHandRing2', (3.12442, 0.0, -0.281959)),
    ('LeftHandRing4', 'LeftHandRing3', (1.908768, 0.0, -0.172254)),
    ('LeftHandPinky', 'LeftHandRing', (0.167542, -0.25, -0.924962)),
    ('LeftHandPinky1', 'LeftHandPinky', (6.823502, 4e-06, -1.525868)),
    ('LeftHandPinky2', 'LeftHandPinky1', (3.64283, 0.0, -0.814608)),
    ('LeftHandPinky3', 'LeftHandPinky2', (2.333107, 0.0, -0.521728)),
    ('LeftHandPinky4', 'LeftHandPinky3', (1.725464, 0.0, -0.385847)),
    ('LeftHandIndex', 'LeftHand', (0.25, -0.25, 0.90616)),
    ('LeftHandIndex1', 'LeftHandIndex', (9.088005, 4e-06, 0.820136)),
    ('LeftHandIndex2', 'LeftHandIndex1', (4.77655, 0.0, 0.431054)),
    ('LeftHandIndex3', 'LeftHandIndex2', (2.865135, 0.0, 0.258561)),
    ('LeftHandIndex4', 'LeftHandIndex3', (1.745476, 0.0, 0.157519)),
    ('LeftHandThumb1', 'LeftHandIndex', (0.167542, -0.75, 0.924962)),
    ('LeftHandThumb2', 'LeftHandThumb1', (5.551453, 0.857117, 2.302688)),
    ('LeftHandThumb3', 'LeftHandThumb2', (3.625626, 0.55978, 1.503871)),
    ('LeftHandThumb4', 'LeftHandThumb3', (2.195244, 0.338936, 0.910563)),
    ('RightUpLeg', 'Hips', (-8.786538, 0.0, 0.0)),
    ('RightLeg', 'RightUpLeg', (0.0, -42.17041, 0.0)),
    ('RightFoot', 'RightLeg', (0.0, -45.94915, 0.0)),
    ('RightForeFoot', 'RightFoot', (0.0, -4.685799, 0.0)),
    ('RightToeBase', 'RightForeFoot', (0.0, 0.0, 18.351074)),
    ('RightToeBaseEnd', 'RightToeBase', (0.0, 0.0, 6.416922)),
    ('LeftUpLeg', 'Hips', (8.786538, 0.0, 0.0)),
    ('LeftLeg', 'LeftUpLeg', (0.0, -42.17041, 0.0)),
    ('LeftFoot', 'LeftLeg', (0.0, -45.94915, 0.0)),
    ('LeftForeFoot', 'LeftFoot', (0.0, -4.685799, 0.0)),
    ('LeftToeBase', 'LeftForeFoot', (0.0, 0.0, 18.351074)),
    ('LeftToeBaseEnd', 'LeftToeBase', (0.0, 0.0, 7.522032)),
)

_END_SITES: dict[str, tuple[float, float, float]] = {
    'HeadEnd': (0.0, 9.727722, 0.0),
    'RightHandMiddle4': (-1.888367, 0.0, 0.0),
    'RightHandRing4': (-1.869919, 0.0, -0.168749),
    'RightHandPinky4': (-1.690346, 0.0, -0.377994),
    'RightHandIndex4': (-1.709946, 0.0, 0.154312),
    'RightHandThumb4': (-2.150558, 0.332035, 0.89203),
    'LeftHandMiddle4': (1.927605, 0.0, 0.0),
    'LeftHandRing4': (1.908768, 0.0, -0.172255),
    'LeftHandPinky4': (1.725464, 0.0, -0.385848),
    'LeftHandIndex4': (1.745476, 0.0, 0.157518),
    'LeftHandThumb4': (2.195244, 0.338936, 0.910564),
    'RightToeBaseEnd': (0.0, 0.0, 6.416927),
    'LeftToeBaseEnd': (0.0, 0.0, 7.522036),
}

#: The 75 joint names in file order.
BEAT_JOINTS: tuple[str, ...] = tuple(name for name, _, _ in _HIERARCHY)


def _side(side: str) -> tuple[str, ...]:
    fingers = (
        "Middle1", "Middle2", "Middle3",
        "Ring", "Ring1", "Ring2", "Ring3",
        "Pinky", "Pinky1", "Pinky2", "Pinky3",
        "Index", "Index1", "Index2", "Index3",
        "Thumb1", "Thumb2", "Thumb3",
    )
    return (f"{side}Shoulder", f"{side}Arm", f"{side}ForeArm", f"{side}Hand") + tuple(
        f"{side}Hand{f}" for f in fingers
    )


#: The 47 joints that BEAT-trained gesture models drive, in the column order of their output
#: (BEAT's ``spine_neck_141`` list, 47 x 3 = 141 values per frame): ``Spine``, ``Neck``, ``Neck1``,
#: then for the right side and then the left side: shoulder, arm, forearm, hand and 18 finger joints
#: (Middle1-3, Ring + Ring1-3, Pinky + Pinky1-3, Index + Index1-3, Thumb1-3). ``Spine1..Spine3``,
#: ``Head`` and the finger tips (``*4``) are not driven by the models and stay at rest, like the legs.
BEAT_UPPER_BODY: tuple[str, ...] = ("Spine", "Neck", "Neck1") + _side("Right") + _side("Left")


def beat_skeleton() -> Skeleton:
    """A fresh BEAT 75-joint skeleton (centimetres, ``unit_scale`` 0.01, BVH channel layout of BEAT)."""
    index = {name: i for i, name in enumerate(BEAT_JOINTS)}
    parents = np.array([-1 if p is None else index[p] for _, p, _ in _HIERARCHY])
    offsets = np.array([o for _, _, o in _HIERARCHY], dtype=np.float64)
    channels = tuple(
        ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation") if p is None
        else ("Xrotation", "Yrotation", "Zrotation")
        for _, p, _ in _HIERARCHY
    )
    end_sites = {index[n]: np.array(o, dtype=np.float64) for n, o in _END_SITES.items()}
    return Skeleton(BEAT_JOINTS, parents, offsets, channels, end_sites, unit_scale=0.01)


def beat_upper_body_indices() -> np.ndarray:
    """Indices into :data:`BEAT_JOINTS` of the 47 :data:`BEAT_UPPER_BODY` joints, in model column order."""
    index = {name: i for i, name in enumerate(BEAT_JOINTS)}
    return np.array([index[n] for n in BEAT_UPPER_BODY])


def beat_motion_from_upper_body(
    rotations_47: np.ndarray,
    fps: float = BEAT_MODEL_FPS,
    root: np.ndarray | tuple[float, float, float] | None = None,
    skeleton: Skeleton | None = None,
) -> Motion:
    """A full 75-joint BEAT motion from model output on the 47 upper-body joints.

    ``rotations_47`` is ``(F, 47, 4)`` local quaternions (xyzw) in :data:`BEAT_UPPER_BODY` order; every
    other joint holds its rest rotation. ``root`` is the hips position, either one ``(3,)`` point held
    for every frame or an ``(F, 3)`` trajectory (default: the rest offset, i.e. the origin).

    >>> m = beat_motion_from_upper_body(np.tile([0.0, 0.0, 0.0, 1.0], (10, 47, 1)))
    >>> m.rotations.shape, m.fps
    ((10, 75, 4), 15.0)
    """
    sk = beat_skeleton() if skeleton is None else skeleton
    rot47 = np.asarray(rotations_47, dtype=np.float64)
    if rot47.ndim != 3 or rot47.shape[1:] != (47, 4):
        raise ValueError(f"upper-body rotations must be (frames, 47, 4) quaternions, got {rot47.shape}")
    f = rot47.shape[0]
    motion = Motion.rest(sk, n_frames=f, fps=fps)
    motion.source = "BEAT upper body"
    idx = np.array([sk.index(n) for n in BEAT_UPPER_BODY])
    motion.rotations[:, idx] = quat_normalize(rot47)
    if root is not None:
        r = np.asarray(root, dtype=np.float64)
        if r.shape not in ((3,), (f, 3)):
            raise ValueError(f"root must be (3,) or ({f}, 3), got {r.shape}")
        motion.translations[:, 0] = r
    return motion
