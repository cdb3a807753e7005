"""Forward kinematics: local joint rotations/translations to world transforms, all frames at once.

Joints are depth-first (``parents[j] < j``), so parents are always computed before their children:
all joints of one tree depth are done together for every frame at once, never a Python loop over
frames.

>>> import numpy as np
>>> from studyapp.motion.skeleton import Skeleton, Motion
>>> sk = Skeleton(("root", "tip"), np.array([-1, 0]), np.array([[0, 0, 0], [0, 2.0, 0]]))
>>> joint_positions(Motion.rest(sk))[0].tolist()
[[0.0, 0.0, 0.0], [0.0, 2.0, 0.0]]
>>> figure_height(sk)
2.0
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from studyapp.motion.skeleton import Motion, Skeleton

__all__ = [
    "global_transforms",
    "forward_kinematics",
    "joint_positions",
    "rest_global_transforms",
    "rest_joint_positions",
    "end_site_positions",
    "figure_height",
    "guess_unit_scale",
]


_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])
#: How far float32 forward kinematics may put a joint from the float64 result, as a fraction of the figure's
#: height (measured on BEAT's 75 joints, 15 levels deep: under 5e-7, i.e. a thousandth of a millimetre on a
#: 1.8 m figure; a GPU vertex is float32 anyway). Rotation matrix entries agree within the same figure.
FLOAT32_TOLERANCE = 1e-5
# Frames are processed in blocks of this many: each block's work arrays (about 1 MB) stay in cache
# between the ~40 vector operations per block instead of streaming 7,200-frame rows through memory
# each time. 256 balances that against the per-block Python overhead (~90 numpy calls a block): on
# BEAT's 75 joints it measured 58 ms against 66 ms for 128 and 85 ms for 512 (bench_motion.py, float64;
# float32 measured the same from 256 to 1,024).
_FRAME_BLOCK = 256


@lru_cache(maxsize=64)
def _levels_cached(parents_bytes: bytes) -> tuple[np.ndarray, ...]:
    parents = np.frombuffer(parents_bytes, dtype=np.int64)
    depth = np.zeros(len(parents), dtype=np.int64)
    for k, p in enumerate(parents):
        if p >= 0:
            depth[k] = depth[p] + 1
    return tuple(np.flatnonzero(depth == d) for d in range(int(depth.max(initial=0)) + 1))


def _depth_levels(parents: np.ndarray) -> tuple[np.ndarray, ...]:
    """Joint indices grouped by depth below the root(s), shallowest first (cached per hierarchy:
    the viewer runs forward kinematics every frame on the same skeleton)."""
    return _levels_cached(np.ascontiguousarray(parents, dtype=np.int64).tobytes())


def _matrix_components(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions ``(4, ...)`` (component-first) as ``(3, 3, ...)``.

    Motion rotations are unit by contract, so no normalisation pass here (this is the hot loop).
    """
    x, y, z, w = q
    m = np.empty((3, 3) + q.shape[1:], dtype=q.dtype)
    x2, y2, z2 = x + x, y + y, z + z
    xx, yy, zz = x * x2, y * y2, z * z2
    np.subtract(1.0, yy + zz, out=m[0, 0])
    np.subtract(1.0, xx + zz, out=m[1, 1])
    np.subtract(1.0, xx + yy, out=m[2, 2])
    del xx, yy, zz
    xy, wz = x * y2, w * z2
    np.subtract(xy, wz, out=m[0, 1])
    np.add(xy, wz, out=m[1, 0])
    xz, wy = x * z2, w * y2
    np.add(xz, wy, out=m[0, 2])
    np.subtract(xz, wy, out=m[2, 0])
    yz, wx = y * z2, w * x2
    np.subtract(yz, wx, out=m[1, 2])
    np.add(yz, wx, out=m[2, 1])
    return m


def _global_rt(parents: np.ndarray, rotations: np.ndarray, translations: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World rotations ``(3, 3, J, F)`` and positions ``(3, J, F)`` from local ``(F, J, 4)`` / ``(F, J, 3)``
    (views of :func:`_global_rows`' one array)."""
    g = _global_rows(parents, rotations, translations)
    return g[:, :3], g[:, 3]


def _global_rows(parents: np.ndarray, rotations: np.ndarray, translations: np.ndarray,
                 g: np.ndarray | None = None, dtype: type = np.float64) -> np.ndarray:
    """World ``[R | t]`` rows ``(3, 4, J, F)`` from local ``(F, J, 4)`` / ``(F, J, 3)``.

    Component-first, frame-last layout with all joints of one depth handled together: numpy's
    ``matmul`` on stacks of 3x3 matrices is slow (one tiny product at a time), while an ``einsum``
    over long contiguous frame rows is two vector operations per tree level (15 levels for BEAT).
    Rotation and translation share one array so the (F, J, 4, 4) output is one strided copy.
    ``g``, when given, is a ``(4 or more, 4, J, F)`` array whose first three rows are filled in; the
    arithmetic is done in ``g``'s type (else ``dtype``).
    """
    dtype = g.dtype if g is not None else dtype
    local_r = _matrix_components(np.ascontiguousarray(rotations.transpose(2, 1, 0), dtype=dtype))
    local_t = np.ascontiguousarray(translations.transpose(2, 1, 0), dtype=dtype)
    if g is None:
        g = np.empty((3, 4) + local_r.shape[2:], dtype=dtype)
    g_r, g_t = g[:3, :3], g[:3, 3]
    for level in _depth_levels(parents):
        par = parents[level]
        if par[0] < 0:  # roots are depth 0 and only roots are
            g_r[:, :, level] = local_r[:, :, level]
            g_t[:, level] = local_t[:, level]
            continue
        pr = g_r[:, :, par]
        g_r[:, :, level] = np.einsum("iknf,kjnf->ijnf", pr, local_r[:, :, level])
        g_t[:, level] = np.einsum("iknf,knf->inf", pr, local_t[:, level]) + g_t[:, par]
    return g[:3]


def global_transforms(skeleton: Skeleton, rotations: np.ndarray, translations: np.ndarray,
                      dtype: type = np.float64) -> np.ndarray:
    """World 4x4 transforms ``(F, J, 4, 4)`` from local quaternions ``(F, J, 4)`` and translations ``(F, J, 3)``.

    Each joint's transform maps points from that joint's frame to world space; its last column is the
    joint's world position. ``dtype=np.float32`` computes and returns float32 (half the memory traffic, what
    the GPU takes): positions then agree with float64 within :data:`FLOAT32_TOLERANCE` of the figure's size.
    """
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise ValueError(f"dtype must be float32 or float64, got {dtype}")
    rotations = np.asarray(rotations)
    translations = np.asarray(translations)
    j = skeleton.n_joints
    if rotations.ndim != 3 or rotations.shape[1:] != (j, 4):
        raise ValueError(f"rotations must be (frames, {j}, 4), got {rotations.shape}")
    if translations.shape != rotations.shape[:2] + (3,):
        raise ValueError(f"translations must be (frames, {j}, 3), got {translations.shape}")
    f = rotations.shape[0]
    out = np.empty((f, j, 4, 4), dtype=dtype)
    block = min(_FRAME_BLOCK, max(f, 1))
    g = np.empty((4, 4, j, block), dtype=dtype)
    g[3] = _LAST_ROW[:, None, None]
    # The (16, J, n) -> (n, J, 16) reorder goes through a (J, n, 16) buffer: a plain 2-D transpose
    # and then a copy of whole 128-byte matrices, about twice as fast as one 4-D strided copy.
    staging = np.empty((j, block, 16), dtype=dtype)
    for a in range(0, f, block):
        b = min(a + block, f)
        n = b - a
        gb = g[..., :n]
        _global_rows(skeleton.parents, rotations[a:b], translations[a:b], gb)
        st = staging[:, :n]
        np.copyto(st, gb.reshape(16, j, n).transpose(1, 2, 0))
        out[a:b] = st.reshape(j, n, 4, 4).transpose(1, 0, 2, 3)
    return out


def forward_kinematics(motion: Motion, dtype: type = np.float64) -> np.ndarray:
    """World 4x4 transforms ``(F, J, 4, 4)`` of every joint in every frame of ``motion`` (see
    :func:`global_transforms` for ``dtype``)."""
    return global_transforms(motion.skeleton, motion.rotations, motion.translations, dtype)


def joint_positions(motion: Motion) -> np.ndarray:
    """World joint positions ``(F, J, 3)`` (cheaper than :func:`forward_kinematics` when only positions matter)."""
    rotations, translations = motion.rotations, motion.translations
    f = rotations.shape[0]
    out = np.empty((f, motion.skeleton.n_joints, 3))
    for a in range(0, f, _FRAME_BLOCK):
        b = min(a + _FRAME_BLOCK, f)
        _, g_t = _global_rt(motion.skeleton.parents, rotations[a:b], translations[a:b])
        out[a:b] = g_t.transpose(2, 1, 0)
    return out


def rest_global_transforms(skeleton: Skeleton) -> np.ndarray:
    """World 4x4 transforms ``(J, 4, 4)`` of the rest pose (offsets and ``rest_rotations``)."""
    return global_transforms(skeleton, skeleton.rest_rotations[None], skeleton.offsets[None])[0]


def rest_joint_positions(skeleton: Skeleton) -> np.ndarray:
    """World joint positions ``(J, 3)`` in the rest pose."""
    return rest_global_transforms(skeleton)[:, :3, 3]


def end_site_positions(skeleton: Skeleton, transforms: np.ndarray) -> np.ndarray:
    """World positions ``(..., E, 3)`` of the BVH end sites given joint transforms ``(..., J, 4, 4)``."""
    if not skeleton.end_sites:
        return np.zeros(transforms.shape[:-3] + (0, 3))
    idx = np.array(sorted(skeleton.end_sites))
    offs = np.stack([skeleton.end_sites[i] for i in idx])
    t = transforms[..., idx, :, :]
    return np.einsum("...eij,ej->...ei", t[..., :3, :3], offs) + t[..., :3, 3]


def figure_height(obj: Motion | Skeleton) -> float:
    """Vertical extent (max - min of world Y over joints and end sites) in the file's units.

    For a :class:`Skeleton` the rest pose is measured; for a :class:`Motion` its first frame, since
    models may start in any pose (a standing figure measures the same either way).
    """
    if isinstance(obj, Motion):
        if obj.n_frames == 0:
            return figure_height(obj.skeleton)
        tr = global_transforms(obj.skeleton, obj.rotations[:1], obj.translations[:1])[0]
        skeleton = obj.skeleton
    else:
        skeleton = obj
        tr = rest_global_transforms(skeleton)
    pts = np.concatenate([tr[:, :3, 3], end_site_positions(skeleton, tr)], axis=0)
    if len(pts) == 0:
        return 0.0
    return float(pts[:, 1].max() - pts[:, 1].min())


def guess_unit_scale(height: float) -> float | None:
    """Metres per file unit guessed from a standing figure's height.

    Adults are 1.5-2.0 m tall, children and crouched or cropped rigs less, so: a height of 100-250
    means centimetres (0.01), 1.0-2.5 means metres (1.0), 1000-2500 means millimetres (0.001);
    anything else (e.g. the pybvh sample's ~63 units) is ``None``: unknown, set it by hand.

    >>> guess_unit_scale(179.0), guess_unit_scale(1.7), guess_unit_scale(63.0)
    (0.01, 1.0, None)
    """
    if 100.0 <= height <= 250.0:
        return 0.01
    if 1.0 <= height <= 2.5:
        return 1.0
    if 1000.0 <= height <= 2500.0:
        return 0.001
    return None
