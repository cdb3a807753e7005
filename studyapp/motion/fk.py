"""Forward kinematics: local joint rotations/translations to world transforms, all frames at once.

Joints are depth-first (``parents[j] < j``), so parents are always computed before their children:
all joints of one tree depth are done together for a block of frames at once, never a Python loop over
frames or joints (:func:`_world_blocks` says how, and why that layout). ``dtype=np.float32`` is the fast
path, what the renderer uses: about half the time of float64, measured by ``benchmarks/bench_motion.py``
(key ``fk_ms``: 7,200 frames of BEAT's 75 joints).

>>> import numpy as np
>>> from studyapp.motion.skeleton import Skeleton, Motion
>>> sk = Skeleton(("root", "tip"), np.array([-1, 0]), np.array([[0, 0, 0], [0, 2.0, 0]]))
>>> joint_positions(Motion.rest(sk))[0].tolist()
[[0.0, 0.0, 0.0], [0.0, 2.0, 0.0]]
>>> figure_height(sk)
2.0
"""
from __future__ import annotations

import threading
from collections.abc import Iterator
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from studyapp.motion.cores import usable_cores
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


#: How far float32 forward kinematics may put a joint from the float64 result, as a fraction of the figure's
#: height (measured on BEAT's 75 joints, 15 levels deep: under 5e-7, i.e. a thousandth of a millimetre on a
#: 1.8 m figure; a GPU vertex is float32 anyway). Rotation matrix entries agree within the same figure.
FLOAT32_TOLERANCE = 1e-5
# Frames are processed in blocks of this many: a block's work arrays (under 1 MB in float32) stay in the
# 2 MB L2 cache between the ~80 numpy calls per block instead of streaming 7,200-frame rows through memory
# each time, and the blocks are long enough for those calls' fixed cost (~1-4 us each) to stay small.
# On BEAT's 75 joints, float32, bench_motion.py's data, interleaved: 192 frames measured best, 128 and
# 256 within a few per cent, 512 ~25 % slower.
_FRAME_BLOCK = 192
#: Long motions are split into this many frame ranges, worked on side by side (numpy releases the
#: interpreter lock in its loops): one per core, at most 4 (past that, memory bandwidth, not arithmetic,
#: bounds it). Set it to 1 to keep forward kinematics on the calling thread.
THREADS = usable_cores(4)
# A part shorter than this is not worth a thread (a start and join cost ~0.1 ms; a block ~1 ms).
_PARALLEL_MIN_FRAMES = 4 * _FRAME_BLOCK


class _Plan(NamedTuple):
    """How one hierarchy is walked: joints regrouped by depth so that each depth is one contiguous run."""

    #: Joint indices in level order (depth 0 first; within a depth, by the parent's place in the level above).
    order: np.ndarray
    #: Place of each joint in ``order`` (the inverse permutation).
    place: np.ndarray
    #: Per depth: ``(lo, hi, parents)``: the depth's joints are ``order[lo:hi]``; ``parents`` gives their
    #: parents as places in the previous depth's run: a slice when they are consecutive (chains: fingers,
    #: spine) or a single joint repeated (a slice of length 1, broadcast), else an index array; None for roots.
    levels: tuple[tuple[int, int, slice | np.ndarray | None], ...]


@lru_cache(maxsize=64)
def _plan_cached(parents_bytes: bytes) -> _Plan:
    parents = np.frombuffer(parents_bytes, dtype=np.int64)
    depth = np.zeros(len(parents), dtype=np.int64)
    for k, p in enumerate(parents):
        if p >= 0:
            depth[k] = depth[p] + 1
    order: list[int] = []
    within = np.zeros(len(parents), dtype=np.int64)  # a joint's place inside its depth's run
    levels = []
    for d in range(int(depth.max(initial=0)) + 1):
        idx = np.flatnonzero(depth == d)
        par: slice | np.ndarray | None = None
        if d:
            # Sorting by the parent's place keeps each chain in one lane from depth to depth, so a chain's
            # parents are a plain view of the level above instead of a gather.
            idx = idx[np.argsort(within[parents[idx]], kind="stable")]
            pl = within[parents[idx]]
            if np.array_equal(pl, np.arange(pl[0], pl[0] + len(pl))):
                par = slice(int(pl[0]), int(pl[0]) + len(pl))
            elif (pl == pl[0]).all():
                par = slice(int(pl[0]), int(pl[0]) + 1)
            else:
                par = pl
        within[idx] = np.arange(len(idx))
        levels.append((len(order), len(order) + len(idx), par))
        order.extend(idx.tolist())
    order_a = np.array(order, dtype=np.int64)
    return _Plan(order_a, np.argsort(order_a), tuple(levels))


def _plan(parents: np.ndarray) -> _Plan:
    """The walk of a hierarchy (cached per hierarchy: the viewer runs forward kinematics every frame on the
    same skeleton)."""
    return _plan_cached(np.ascontiguousarray(parents, dtype=np.int64).tobytes())


def _local_matrices(q: np.ndarray, out: np.ndarray) -> None:
    """Rotation matrices of unit quaternions ``q`` ``(4, ...)`` (x, y, z, w first) written column-major into
    ``out`` ``(4 or more, 3, ...)``: ``out[c, r]`` is entry (r, c).

    Motion rotations are unit by contract, so no normalisation pass here (this is the hot loop).
    """
    x, y, z, w = q
    x2, y2, z2 = x + x, y + y, z + z
    xx, yy, zz = x * x2, y * y2, z * z2
    np.subtract(1.0, yy + zz, out=out[0, 0])
    np.subtract(1.0, xx + zz, out=out[1, 1])
    np.subtract(1.0, xx + yy, out=out[2, 2])
    del xx, yy, zz
    xy, wz = x * y2, w * z2
    np.subtract(xy, wz, out=out[1, 0])
    np.add(xy, wz, out=out[0, 1])
    xz, wy = x * z2, w * y2
    np.add(xz, wy, out=out[2, 0])
    np.subtract(xz, wy, out=out[0, 2])
    yz, wx = y * z2, w * x2
    np.subtract(yz, wx, out=out[2, 1])
    np.add(yz, wx, out=out[1, 2])


def _check(skeleton: Skeleton, rotations: np.ndarray, translations: np.ndarray) -> None:
    j = skeleton.n_joints
    if rotations.ndim != 3 or rotations.shape[1:] != (j, 4):
        raise ValueError(f"rotations must be (frames, {j}, 4), got {rotations.shape}")
    if translations.shape != rotations.shape[:2] + (3,):
        raise ValueError(f"translations must be (frames, {j}, 3), got {translations.shape}")


def _world_blocks(plan: _Plan, rotations: np.ndarray, translations: np.ndarray,
                  dtype: np.dtype) -> Iterator[tuple[int, int, list[np.ndarray]]]:
    """World ``[R | t]`` of every joint, one block of frames at a time: yields ``(a, b, worlds)`` for frames
    ``a:b``, where ``worlds[d]`` is a ``(3, 4, m, b - a)`` array (row, column, joint, frame) of depth ``d``'s
    joints in :attr:`_Plan.order`. The arrays are reused by the next block.

    Layout, the reasons for it, and what each step costs (profiled on BEAT's 75 joints; copies, not
    arithmetic, dominate):

    * component-first, frame-last: every numpy call runs over long contiguous rows of frames, all joints
      of one depth at once (15 levels for BEAT), never a Python loop over frames or joints;
    * joints in level order, so a level's local transforms and results are contiguous runs: no gather of
      the locals and no scatter of the results; parents are a view of the level above except where a
      joint has several children (BEAT: 5 of 15 levels gather);
    * local transforms column-major (``local[c, r]``) and each level's result in its own contiguous array:
      ``einsum`` composes ``[R | t]`` of a level in one call (``R = Rp R_l``, ``t = Rp t_l``, then
      ``+ tp``), about 1.5x faster in these layouts than with a row-major local, 2x than into a strided output;
    * input blocks are cast to ``dtype`` while still contiguous (a vector cast), then transposed: a
      strided casting copy measured 1.5x slower.
    """
    f, j = rotations.shape[:2]
    block = min(_FRAME_BLOCK, max(f, 1))
    rb = np.empty((block, j, 4), dtype)
    tb = np.empty((block, j, 3), dtype)
    q_joint = np.empty((4, j, block), dtype)
    t_joint = np.empty((3, j, block), dtype)
    q_level = np.empty((4, j, block), dtype)
    local = np.empty((4, 3, j, block), dtype)
    worlds = [np.empty((3, 4, hi - lo, block), dtype) for lo, hi, _ in plan.levels]
    gathered = [np.empty((3, 4, hi - lo, block), dtype) if isinstance(par, np.ndarray) else None
                for lo, hi, par in plan.levels]
    for a in range(0, f, block):
        b = min(a + block, f)
        n = b - a
        np.copyto(rb[:n], rotations[a:b])
        np.copyto(tb[:n], translations[a:b])
        np.copyto(q_joint[..., :n], rb[:n].transpose(2, 1, 0))
        np.copyto(t_joint[..., :n], tb[:n].transpose(2, 1, 0))
        # mode="clip": numpy buffers take() into ``out`` in the default mode; indices are valid by construction
        np.take(q_joint[..., :n], plan.order, axis=1, out=q_level[..., :n], mode="clip")
        np.take(t_joint[..., :n], plan.order, axis=1, out=local[3, ..., :n], mode="clip")
        _local_matrices(q_level[..., :n], local[..., :n])
        out: list[np.ndarray] = []
        for d, (lo, hi, par) in enumerate(plan.levels):
            w = worlds[d][..., :n]
            loc = local[:, :, lo:hi, :n]
            if par is None:
                np.copyto(w, loc.transpose(1, 0, 2, 3))
            else:
                if isinstance(par, slice):
                    pw = out[-1][:, :, par]
                else:
                    pw = gathered[d][..., :n]
                    np.take(out[-1], par, axis=2, out=pw, mode="clip")
                np.einsum("ikmf,jkmf->ijmf", pw[:, :3], loc, out=w)
                w[:, 3] += pw[:, 3]
            out.append(w)
        yield a, b, out


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
    _check(skeleton, rotations, translations)
    f, j = rotations.shape[:2]
    out = np.empty((f, j, 4, 4), dtype=dtype)
    if f == 0 or j == 0:
        return out
    plan = _plan(skeleton.parents)
    parts = _split(f)
    if len(parts) == 1:
        _fill(plan, rotations, translations, out)
        return out
    # numpy's loops release the interpreter lock, so the parts run on separate cores; the first part runs
    # on this thread. Errors (only MemoryError is possible here) are raised here, after every part ended.
    errors: list[BaseException] = []

    def run(a: int, b: int) -> None:
        try:
            _fill(plan, rotations[a:b], translations[a:b], out[a:b])
        except BaseException as e:  # noqa: BLE001 -- handed to the caller's thread below
            errors.append(e)

    threads = [threading.Thread(target=run, args=ab, name="studyapp-fk", daemon=True) for ab in parts[1:]]
    for t in threads:
        t.start()
    run(*parts[0])
    for t in threads:
        t.join()
    if errors:
        raise errors[0]
    return out


def _split(f: int) -> list[tuple[int, int]]:
    """Frame ranges worked on side by side: one per core (at most :data:`THREADS`), each at least
    :data:`_PARALLEL_MIN_FRAMES` long, split on block boundaries so each part's blocks are full-sized."""
    n = max(1, min(THREADS, f // _PARALLEL_MIN_FRAMES))
    if n == 1:
        return [(0, f)]
    per = -(-f // n // _FRAME_BLOCK) * _FRAME_BLOCK
    return [(a, min(a + per, f)) for a in range(0, f, per)]


def _fill(plan: _Plan, rotations: np.ndarray, translations: np.ndarray, out: np.ndarray) -> None:
    """Write the world transforms of ``rotations``/``translations`` (one range of frames) into ``out``
    ``(n, J, 4, 4)``, block by block."""
    f, j = rotations.shape[:2]
    dtype = out.dtype
    block = min(_FRAME_BLOCK, f)
    # Each block goes (3, 4, m, n) per level -> (J, n, 16) in level order (a 2-D transpose per level; the
    # last row [0 0 0 1] is written once) -> (J, n, 16) in joint order (a take of whole rows) -> (n, J, 16)
    # in the output (a copy of whole 4x4 matrices, as 64- or 128-byte items). That is cheaper than one
    # strided 4-D copy, or than writing each joint's matrices into the output directly (measured).
    staged = np.empty((j, block, 16), dtype=dtype)
    staged[..., 12:] = np.array([0, 0, 0, 1], dtype=dtype)
    ordered = np.empty((j, block, 16), dtype=dtype)
    matrix = np.dtype((np.void, 16 * dtype.itemsize))
    out_m = out.reshape(f, j, 16).view(matrix)[..., 0]
    ordered_m = ordered.view(matrix)[..., 0]
    for a, b, worlds in _world_blocks(plan, rotations, translations, dtype):
        n = b - a
        for (lo, hi, _), w in zip(plan.levels, worlds):
            np.copyto(staged[lo:hi, :n, :12], w.reshape(12, hi - lo, n).transpose(1, 2, 0))
        np.take(staged[:, :n], plan.place, axis=0, out=ordered[:, :n], mode="clip")
        np.copyto(out_m[a:b], ordered_m[:, :n].T)


def forward_kinematics(motion: Motion, dtype: type = np.float64) -> np.ndarray:
    """World 4x4 transforms ``(F, J, 4, 4)`` of every joint in every frame of ``motion`` (see
    :func:`global_transforms` for ``dtype``)."""
    return global_transforms(motion.skeleton, motion.rotations, motion.translations, dtype)


def joint_positions(motion: Motion) -> np.ndarray:
    """World joint positions ``(F, J, 3)`` (cheaper than :func:`forward_kinematics` when only positions matter)."""
    rotations, translations = np.asarray(motion.rotations), np.asarray(motion.translations)
    _check(motion.skeleton, rotations, translations)
    out = np.empty(rotations.shape[:2] + (3,))
    if out.size == 0:
        return out
    plan = _plan(motion.skeleton.parents)
    for a, b, worlds in _world_blocks(plan, rotations, translations, np.dtype(np.float64)):
        for (lo, hi, _), w in zip(plan.levels, worlds):
            out[a:b, plan.order[lo:hi]] = w[:, 3].transpose(2, 1, 0)
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
