"""Re-express a motion so that its zero pose *is* its rest pose, under humanoid bone names.

A BVH's rest pose is all channels at zero. A glTF avatar's skeleton rests with non-identity local
rotations (an A-pose, a -Z facing armature turned at load), so its motion written as is would show a
heap of bones at zero in Blender. :func:`zero_at_rest` moves every joint's rest rotation into the
offsets and the animation: the new skeleton's offsets are the rest pose's world-space bone vectors,
every joint's zero rotation is its rest orientation, and every world position of every frame stays
the same. :func:`humanoid_names` renames joints to the humanoid bones they are mapped to.

>>> import numpy as np
>>> from studyapp.motion.skeleton import Motion, Skeleton
>>> from studyapp.motion.rotations import euler_to_quat
>>> rest = np.array([euler_to_quat([0, 0, 90.0], "XYZ"), [0, 0, 0, 1.0]])
>>> sk = Skeleton(("a", "b"), np.array([-1, 0]), np.array([[0, 0, 0], [1.0, 0, 0]]), rest_rotations=rest)
>>> out = zero_at_rest(Motion.rest(sk, 1, 30.0))
>>> np.round(out.skeleton.offsets[1], 6).tolist(), np.round(out.rotations[0, 0], 6).tolist()
([0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0])
"""
from __future__ import annotations

import numpy as np

from studyapp.motion.fk import global_transforms, rest_global_transforms
from studyapp.motion.rotations import matrix_to_quat, quat_inverse, quat_multiply
from studyapp.motion.skeleton import Motion, Skeleton

__all__ = ["zero_at_rest", "humanoid_names"]


def zero_at_rest(motion: Motion) -> Motion:
    """The same animation (world positions equal frame by frame) on a skeleton whose zero pose is the rest pose."""
    sk = motion.skeleton
    rest = rest_global_transforms(sk)
    glob = global_transforms(sk, motion.rotations, motion.translations)
    rest_q = matrix_to_quat(rest[:, :3, :3])
    # world rotation relative to rest: the new joint frames coincide with the world axes at rest
    rel = quat_multiply(matrix_to_quat(glob[..., :3, :3]), quat_inverse(rest_q)[None])
    offsets = np.zeros_like(sk.offsets)
    trans = np.empty_like(motion.translations)
    rot = np.empty_like(rel)
    for j in range(sk.n_joints):
        p = int(sk.parents[j])
        if p < 0:
            offsets[j] = rest[j, :3, 3]
            trans[:, j] = glob[:, j, :3, 3]
            rot[:, j] = rel[:, j]
        else:
            offsets[j] = rest[j, :3, 3] - rest[p, :3, 3]
            trans[:, j] = offsets[j]
            rot[:, j] = quat_multiply(quat_inverse(rel[:, p]), rel[:, j])
    ends = {j: rest[j, :3, :3] @ np.asarray(v, np.float64) for j, v in sk.end_sites.items()}
    flat = Skeleton(sk.names, sk.parents, offsets, sk.channels, end_sites=ends, unit_scale=sk.unit_scale)
    return Motion(flat, motion.fps, rot / np.linalg.norm(rot, axis=-1, keepdims=True), trans, source=motion.source)


def humanoid_names(motion: Motion, mapping: dict[str, str]) -> Motion:
    """The motion with each mapped joint named as its humanoid bone (``{joint: bone}``); others keep their
    names, made unique where one collides with a bone name."""
    sk = motion.skeleton
    bones = set(mapping.values())
    names = []
    for n in sk.names:
        new = mapping.get(n, n)
        if n not in mapping and new in bones:
            new = f"{n}_unmapped"
        names.append(new)
    renamed = Skeleton(tuple(names), sk.parents, sk.offsets, sk.channels, end_sites=dict(sk.end_sites),
                       unit_scale=sk.unit_scale, rest_rotations=sk.rest_rotations)
    return Motion(renamed, motion.fps, motion.rotations, motion.translations, source=motion.source)
