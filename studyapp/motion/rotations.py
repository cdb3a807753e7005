"""Rotation representations and conversions, batched over any leading dimensions.

Every function takes ``(..., k)`` arrays and returns float64 arrays with the same leading shape.
Conventions (see :mod:`studyapp.motion.skeleton`):

* Quaternions are unit, scalar-last ``(x, y, z, w)``.
* Euler ``order`` strings are upper-case axes such as ``"ZXY"`` and mean *intrinsic* rotations, the
  way a BVH channel list reads: ``"ZXY"`` gives ``R = R_Z @ R_X @ R_Y`` and ``angles[..., 0]`` is the
  Z angle. Angles are in degrees unless ``degrees=False``.
* Matrices rotate column vectors: ``v_parent = R @ v_local``.
* 6D comes in two layouts of the same six matrix entries (``Rij`` = row ``i``, column ``j``); the
  numbers alone cannot tell them apart (read the wrong way, every joint plays its inverse rotation):

  - ``"sixd"``: Zhou et al. 2019 ("On the Continuity of Rotation Representations in Neural
    Networks"), the first two **columns**, ``[col0, col1]`` = ``[R00, R10, R20, R01, R11, R21]``
    (``np.concatenate([R[..., :, 0], R[..., :, 1]], -1)``).
  - ``"sixd_rows"``: the first two **rows**, ``[row0, row1]`` = ``[R00, R01, R02, R10, R11, R12]``,
    i.e. ``R[..., :2, :].reshape(..., 6)``. This is what PyTorch3D's ``matrix_to_rotation_6d``
    writes (``matrix[..., :2, :].clone().reshape(batch_dim + (6,))``, "by dropping the last row") and
    its ``rotation_6d_to_matrix`` reads (Gram-Schmidt rows stacked with ``dim=-2``), so most PyTorch
    gesture code (EMAGE and other BEAT-derived pipelines that copy PyTorch3D's conversions) stores it.

>>> import numpy as np
>>> q = euler_to_quat(np.array([90.0, 0.0, 0.0]), "ZXY")
>>> np.round(quat_to_matrix(q) @ np.array([1.0, 0.0, 0.0]), 6)
array([0., 1., 0.])
"""
from __future__ import annotations


import numpy as np

__all__ = [
    "REPRESENTATIONS",
    "ORDERS",
    "euler_to_quat",
    "quat_to_euler",
    "quat_to_matrix",
    "matrix_to_quat",
    "axis_angle_to_quat",
    "quat_to_axis_angle",
    "sixd_to_matrix",
    "matrix_to_sixd",
    "quat_to_sixd",
    "sixd_to_quat",
    "sixd_rows_to_matrix",
    "matrix_to_sixd_rows",
    "quat_to_sixd_rows",
    "sixd_rows_to_quat",
    "quat_multiply",
    "quat_inverse",
    "quat_slerp",
    "quat_normalize",
    "quat_identity",
    "quat_rotate",
    "quat_between",
    "to_quat",
    "from_quat",
    "representation_width",
]

#: The 12 intrinsic Euler orders (6 Tait-Bryan, 6 proper Euler).
ORDERS: tuple[str, ...] = (
    "XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX",
    "XYX", "XZX", "YXY", "YZY", "ZXZ", "ZYZ",
)

#: Names accepted by :func:`to_quat` / :func:`from_quat`, with the per-joint width of each.
REPRESENTATIONS: dict[str, int] = {
    "euler": 3,
    "axis_angle": 3,
    "quat": 4,
    "quat_wxyz": 4,
    "sixd": 6,
    "sixd_rows": 6,
    "matrix": 9,
}


def _check_order(order: str) -> str:
    o = str(order).upper()
    if len(o) != 3 or any(c not in "XYZ" for c in o) or o[0] == o[1] or o[1] == o[2]:
        raise ValueError(f"invalid Euler order {order!r}; expected three axes like 'ZXY'")
    return o


def _flat(a: np.ndarray, width: tuple[int, ...]) -> tuple[np.ndarray, tuple[int, ...]]:
    a = np.asarray(a, dtype=np.float64)
    k = len(width)
    if a.shape[a.ndim - k:] != width:
        raise ValueError(f"expected trailing shape {width}, got {a.shape}")
    lead = a.shape[: a.ndim - k]
    return a.reshape((-1,) + width), lead


def quat_identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    """Identity quaternions of the given leading shape."""
    q = np.zeros(tuple(shape) + (4,))
    q[..., 3] = 1.0
    return q


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions; raises ``ValueError`` on zero-length or non-finite input."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if not np.all(np.isfinite(n)) or np.any(n < 1e-12):
        raise ValueError("quaternions must be finite and non-zero")
    return q / n


def _axis_quat(axis: str, half: np.ndarray) -> np.ndarray:
    q = np.zeros(half.shape + (4,))
    q[..., "XYZ".index(axis)] = np.sin(half)
    q[..., 3] = np.cos(half)
    return q


def euler_to_quat(angles: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Intrinsic Euler angles ``(..., 3)`` (in ``order``'s axis order) to quaternions ``(..., 4)``.

    Computed as the product of the three axis rotations (pure numpy; BVH loading converts every
    joint of every frame through here).

    >>> np.round(euler_to_quat([0.0, 0.0, 180.0], "XYZ"), 6)
    array([0., 0., 1., 0.])
    """
    o = _check_order(order)
    a = np.asarray(angles, dtype=np.float64)
    if a.shape[-1:] != (3,):
        raise ValueError(f"expected trailing shape (3,), got {a.shape}")
    if o[0] == o[2]:
        half = a * (np.pi / 360.0) if degrees else a * 0.5
        q = quat_multiply(_axis_quat(o[0], half[..., 0]), _axis_quat(o[1], half[..., 1]))
        q = quat_multiply(q, _axis_quat(o[2], half[..., 2]))
        # scipy's convention (w >= 0) keeps results comparable with Rotation.as_quat
        return np.where(q[..., 3:4] < 0, -q, q)
    # closed form of q_i(a) * q_j(b) * q_k(c); s flips the cross terms for odd permutations.
    # Worked component-first ((3, ...) and (4, ...) contiguous rows): the same arithmetic as on
    # strided (..., 3) columns, bit for bit, but each vector operation runs on contiguous memory.
    i, j, k = ("XYZ".index(c) for c in o)
    s = 1.0 if (i, j, k) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
    half = np.empty((3,) + a.shape[:-1])
    np.multiply(np.moveaxis(a, -1, 0), (np.pi / 360.0) if degrees else 0.5, out=half)
    ca, cb, cc = np.cos(half)
    sa, sb, sc = np.sin(half)
    del half
    cacb, sasb, sacb, casb = ca * cb, sa * sb, sa * cb, ca * sb
    comp = np.empty((4,) + a.shape[:-1])
    comp[i] = sacb * cc + s * casb * sc
    comp[j] = casb * cc - s * sacb * sc
    comp[k] = cacb * sc + s * sasb * cc
    comp[3] = cacb * cc - s * sasb * sc
    # scipy's convention (w >= 0) keeps results comparable with Rotation.as_quat (negating is exact)
    comp *= np.where(comp[3] < 0, -1.0, 1.0)
    return np.ascontiguousarray(np.moveaxis(comp, 0, -1))


def quat_to_euler(q: np.ndarray, order: str, degrees: bool = True) -> np.ndarray:
    """Quaternions ``(..., 4)`` to intrinsic Euler angles ``(..., 3)`` in ``order``'s axis order.

    Closed form from the rotation matrix. Tait-Bryan orders (three different axes, all BVH orders)
    give a middle angle in ``[-90, 90]`` degrees, proper Euler orders (``"ZXZ"``) one in ``[0, 180]``.
    At gimbal lock the decomposition is not unique: the third angle is set to zero and the first
    absorbs the rest, so the angles still reproduce the rotation (to about 1e-8).
    """
    o = _check_order(order)
    q = np.asarray(q, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(f"expected trailing shape (4,), got {q.shape}")
    i, j = "XYZ".index(o[0]), "XYZ".index(o[1])
    k = 3 - i - j
    s = 1.0 if (i, j, k) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
    m = quat_to_matrix(q)
    if o[0] != o[2]:
        sin_b_abs = np.hypot(m[..., i, i], m[..., i, j])  # |cos b| for Tait-Bryan
        b = np.arctan2(s * m[..., i, k], sin_b_abs)
        free_a = np.arctan2(-s * m[..., j, k], m[..., k, k])
        free_c = np.arctan2(-s * m[..., i, j], m[..., i, i])
    else:
        sin_b_abs = np.hypot(m[..., i, j], m[..., i, k])
        b = np.arctan2(sin_b_abs, m[..., i, i])
        free_a = np.arctan2(m[..., j, i], -s * m[..., k, i])
        free_c = np.arctan2(m[..., i, j], s * m[..., i, k])
    # below ~sqrt(machine eps) the two free angles are ill-conditioned: treat as locked
    locked = sin_b_abs < 1e-8
    a = np.where(locked, np.arctan2(s * m[..., k, j], m[..., j, j]), free_a)
    c = np.where(locked, 0.0, free_c)
    out = np.stack([a, b, c], axis=-1)
    return np.degrees(out) if degrees else out


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` to rotation matrices ``(..., 3, 3)``.

    Pure numpy (no per-call object construction): forward kinematics calls it on every joint of
    every frame. Input is normalised first so slightly denormalised data stays a rotation.
    """
    q = np.asarray(q, dtype=np.float64)
    n2 = np.einsum("...i,...i->...", q, q)
    s = np.where(n2 > 0, 2.0 / np.where(n2 > 0, n2, 1.0), 0.0)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xs, ys, zs = x * s, y * s, z * s
    wx, wy, wz = w * xs, w * ys, w * zs
    xx, xy, xz = x * xs, x * ys, x * zs
    yy, yz, zz = y * ys, y * zs, z * zs
    m = np.empty(q.shape[:-1] + (3, 3))
    m[..., 0, 0] = 1.0 - (yy + zz)
    m[..., 0, 1] = xy - wz
    m[..., 0, 2] = xz + wy
    m[..., 1, 0] = xy + wz
    m[..., 1, 1] = 1.0 - (xx + zz)
    m[..., 1, 2] = yz - wx
    m[..., 2, 0] = xz - wy
    m[..., 2, 1] = yz + wx
    m[..., 2, 2] = 1.0 - (xx + yy)
    return m


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` to unit quaternions ``(..., 4)`` (w >= 0).

    Slightly non-orthogonal input is projected to the nearest rotation (scipy's method).
    """
    flat, lead = _flat(m, (3, 3))
    if flat.shape[0] == 0:
        return np.zeros(lead + (4,))
    # scipy's Rotation.from_matrix, in numpy (scipy.spatial costs ~0.8 s to import before a participant's first
    # frame, issue 20, and a participant's install has no scipy): proper rotations (all retargeting and reader
    # output) directly; others are projected to the nearest rotation (polar decomposition) first
    gram = np.einsum("nji,njk->nik", flat, flat) - np.eye(3)
    if np.all(np.isfinite(flat)) and np.abs(gram).max() < 1e-9 and np.linalg.det(flat).min() > 0:
        return _markley_quat(flat).reshape(lead + (4,))
    det = np.linalg.det(flat)
    if np.any(det <= 0):
        i = int(np.nonzero(det <= 0)[0][0])
        raise ValueError(f"Non-positive determinant (left-handed or null coordinate frame) in rotation matrix {i}: "
                         f"{flat[i]}.")
    gram = flat @ np.swapaxes(flat, 1, 2)
    skew = ~np.all(np.isclose(gram, np.eye(3), atol=1e-12), axis=(1, 2))
    flat = flat.copy()
    if skew.any():
        u, _, vt = np.linalg.svd(flat[skew], full_matrices=False)
        flat[skew] = u @ vt
    return _markley_quat(flat).reshape(lead + (4,))


def _markley_quat(m: np.ndarray) -> np.ndarray:
    """``(N, 3, 3)`` rotation matrices to canonical ``(N, 4)`` xyzw quaternions (w >= 0; when w == 0 the first
    non-zero of x, y, z positive) by Markley's method, as scipy computes them: built from the largest of the
    diagonal and the trace, so no component is found by dividing by a small number."""
    trace = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    choice = np.argmax(np.stack([m[:, 0, 0], m[:, 1, 1], m[:, 2, 2], trace], axis=1), axis=1)
    q = np.empty((len(m), 4))
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        s = choice == i
        q[s, i] = 1.0 - trace[s] + 2.0 * m[s, i, i]
        q[s, j] = m[s, j, i] + m[s, i, j]
        q[s, k] = m[s, k, i] + m[s, i, k]
        q[s, 3] = m[s, k, j] - m[s, j, k]
    s = choice == 3
    q[s, 0] = m[s, 2, 1] - m[s, 1, 2]
    q[s, 1] = m[s, 0, 2] - m[s, 2, 0]
    q[s, 2] = m[s, 1, 0] - m[s, 0, 1]
    q[s, 3] = 1.0 + trace[s]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    # canonical sign: the first non-zero of w, x, y, z positive
    lead = np.take_along_axis(q[:, [3, 0, 1, 2]], np.argmax(q[:, [3, 0, 1, 2]] != 0, axis=1)[:, None], 1)[:, 0]
    q[lead < 0] *= -1.0
    return q


def axis_angle_to_quat(v: np.ndarray) -> np.ndarray:
    """Rotation vectors ``(..., 3)`` (axis times angle in radians) to quaternions ``(..., 4)``."""
    flat, lead = _flat(v, (3,))
    if flat.shape[0] == 0:
        return np.zeros(lead + (4,))
    # scipy's Rotation.from_rotvec, in numpy (a participant's install has no scipy): sin(a/2)/a by its Taylor
    # series near zero, where the division would lose digits
    angle = np.linalg.norm(flat, axis=1)
    small = angle <= 1e-3
    a2 = angle * angle
    safe = np.where(small, 1.0, angle)
    scale = np.where(small, 0.5 - a2 / 48.0 + a2 * a2 / 3840.0, np.sin(0.5 * safe) / safe)
    q = np.concatenate([scale[:, None] * flat, np.cos(0.5 * angle)[:, None]], axis=1)
    return q.reshape(lead + (4,))


def quat_to_axis_angle(q: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` to rotation vectors ``(..., 3)`` with angle in ``[0, pi]`` radians."""
    flat, lead = _flat(q, (4,))
    if flat.shape[0] == 0:
        return np.zeros(lead + (3,))
    # scipy's Rotation.as_rotvec, in numpy: the angle from atan2 (accurate at every angle), w >= 0 first
    q = flat / np.linalg.norm(flat, axis=1, keepdims=True)
    q = np.where(q[:, 3:] < 0, -q, q)
    angle = 2.0 * np.arctan2(np.linalg.norm(q[:, :3], axis=1), q[:, 3])
    small = angle <= 1e-3
    a2 = angle * angle
    scale = np.where(small, 2.0 + a2 / 12.0 + 7.0 * a2 * a2 / 2880.0,
                     angle / np.sin(0.5 * np.where(small, 1.0, angle)))
    return (scale[:, None] * q[:, :3]).reshape(lead + (3,))


def _gram_schmidt(d6: np.ndarray, vectors: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthonormal ``b1, b2, b3`` from the two 3-vectors of ``(..., 6)`` (Zhou et al., section B)."""
    d6 = np.asarray(d6, dtype=np.float64)
    if d6.shape[-1:] != (6,):
        raise ValueError(f"expected trailing shape (6,), got {d6.shape}")
    a1, a2 = d6[..., 0:3], d6[..., 3:6]
    n1 = np.linalg.norm(a1, axis=-1, keepdims=True)
    if np.any(n1 < 1e-12):
        raise ValueError(f"6D rotation has a zero first {vectors[:-1]}")
    b1 = a1 / n1
    b2 = a2 - np.sum(b1 * a2, axis=-1, keepdims=True) * b1
    n2 = np.linalg.norm(b2, axis=-1, keepdims=True)
    if np.any(n2 < 1e-12):
        raise ValueError(f"6D rotation has parallel {vectors}")
    b2 = b2 / n2
    return b1, b2, np.cross(b1, b2)


def sixd_to_matrix(d6: np.ndarray) -> np.ndarray:
    """Zhou 6D ``(..., 6)`` = ``[R00, R10, R20, R01, R11, R21]`` (first two **columns**) to matrices
    ``(..., 3, 3)``; Gram-Schmidt makes the columns orthonormal and the third is their cross product.

    >>> sixd_to_matrix(np.array([2.0, 0, 0, 0.5, 3.0, 0])).round(6).tolist()
    [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    >>> z90 = [[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90 degrees about Z
    >>> np.array_equal(sixd_to_matrix(np.array([0.0, 1, 0, -1, 0, 0])), z90)
    True
    """
    return np.stack(_gram_schmidt(d6, "columns"), axis=-1)


def matrix_to_sixd(m: np.ndarray) -> np.ndarray:
    """Matrices ``(..., 3, 3)`` to Zhou 6D ``(..., 6)``: the first two **columns**,
    ``[R00, R10, R20, R01, R11, R21]``.

    >>> matrix_to_sixd(np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])).tolist()  # 90 degrees about Z
    [0.0, 1.0, 0.0, -1.0, 0.0, 0.0]
    """
    m = np.asarray(m, dtype=np.float64)
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"expected trailing shape (3, 3), got {m.shape}")
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def sixd_rows_to_matrix(d6: np.ndarray) -> np.ndarray:
    """Row-layout 6D ``(..., 6)`` = ``[R00, R01, R02, R10, R11, R12]`` (first two **rows**, PyTorch3D's
    ``rotation_6d_to_matrix``) to matrices ``(..., 3, 3)``; Gram-Schmidt on the rows, the third row is
    their cross product.

    >>> z90 = [[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90 degrees about Z
    >>> np.array_equal(sixd_rows_to_matrix(np.array([0.0, -1, 0, 1, 0, 0])), z90)
    True
    """
    return np.stack(_gram_schmidt(d6, "rows"), axis=-2)


def matrix_to_sixd_rows(m: np.ndarray) -> np.ndarray:
    """Matrices ``(..., 3, 3)`` to row-layout 6D ``(..., 6)``: the first two **rows** flattened,
    ``[R00, R01, R02, R10, R11, R12]`` (= ``m[..., :2, :].reshape(..., 6)``, PyTorch3D's
    ``matrix_to_rotation_6d``).

    >>> matrix_to_sixd_rows(np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])).tolist()  # 90 degrees about Z
    [0.0, -1.0, 0.0, 1.0, 0.0, 0.0]
    """
    m = np.asarray(m, dtype=np.float64)
    if m.shape[-2:] != (3, 3):
        raise ValueError(f"expected trailing shape (3, 3), got {m.shape}")
    # copy: for a single contiguous matrix the reshape would be a view into the caller's array
    return m[..., :2, :].reshape(m.shape[:-2] + (6,)).copy()


def quat_to_sixd(q: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` to Zhou (column) 6D ``(..., 6)``."""
    return matrix_to_sixd(quat_to_matrix(q))


def sixd_to_quat(d6: np.ndarray) -> np.ndarray:
    """Zhou (column) 6D ``(..., 6)`` to quaternions ``(..., 4)``."""
    return matrix_to_quat(sixd_to_matrix(d6))


def quat_to_sixd_rows(q: np.ndarray) -> np.ndarray:
    """Quaternions ``(..., 4)`` to row-layout (PyTorch3D) 6D ``(..., 6)``."""
    return matrix_to_sixd_rows(quat_to_matrix(q))


def sixd_rows_to_quat(d6: np.ndarray) -> np.ndarray:
    """Row-layout (PyTorch3D) 6D ``(..., 6)`` to quaternions ``(..., 4)``."""
    return matrix_to_quat(sixd_rows_to_matrix(d6))


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first, then ``a``), broadcasting leading dims.

    >>> z90 = euler_to_quat([90.0, 0, 0], "ZYX")
    >>> np.allclose(quat_multiply(z90, z90), euler_to_quat([180.0, 0, 0], "ZYX"))
    True
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    ax, ay, az, aw = a[..., 0], a[..., 1], a[..., 2], a[..., 3]
    bx, by, bz, bw = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quat_inverse(q: np.ndarray) -> np.ndarray:
    """Inverse of (unit) quaternions: the conjugate divided by the squared norm."""
    q = np.asarray(q, dtype=np.float64)
    conj = q * np.array([-1.0, -1.0, -1.0, 1.0])
    return conj / np.sum(q * q, axis=-1, keepdims=True)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``(..., 3)`` by quaternions ``(..., 4)`` (broadcasting)."""
    q = np.asarray(q, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    u, w = q[..., :3], q[..., 3:4]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def quat_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest-arc rotation taking direction ``a`` to direction ``b`` (``(..., 3)`` each).

    Zero-length inputs give the identity; opposite directions pick an arbitrary perpendicular axis.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    a, b = np.broadcast_arrays(a, b)
    na = np.linalg.norm(a, axis=-1, keepdims=True)
    nb = np.linalg.norm(b, axis=-1, keepdims=True)
    ok = (na[..., 0] > 1e-12) & (nb[..., 0] > 1e-12)
    au = a / np.where(na > 1e-12, na, 1.0)
    bu = b / np.where(nb > 1e-12, nb, 1.0)
    d = np.sum(au * bu, axis=-1)
    axis = np.cross(au, bu)
    q = np.concatenate([axis, (1.0 + d)[..., None]], axis=-1)
    opposite = ok & (d < -1.0 + 1e-9)
    if np.any(opposite):
        # any axis perpendicular to a: cross with the coordinate axis least aligned with it
        helper = np.where(np.abs(au[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
        perp = np.cross(au, helper)
        perp /= np.linalg.norm(perp, axis=-1, keepdims=True)
        q = np.where(opposite[..., None], np.concatenate([perp, np.zeros(perp.shape[:-1] + (1,))], axis=-1), q)
    q = np.where(ok[..., None], q, [0.0, 0.0, 0.0, 1.0])
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_slerp(q0: np.ndarray, q1: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical linear interpolation along the shorter arc, broadcasting ``q0``, ``q1`` and ``t``.

    ``t`` broadcasts against the leading dims (``q0[..., 0]``); ``t=0`` gives ``q0``, ``t=1`` gives
    ``q1`` (up to sign).
    """
    q0 = quat_normalize(q0)
    q1 = quat_normalize(q1)
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    near = sin_t < 1e-6
    safe = np.where(near, 1.0, sin_t)
    w0 = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / safe)
    w1 = np.where(near, t, np.sin(t * theta) / safe)
    out = w0 * q0 + w1 * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def representation_width(representation: str) -> int:
    """Numbers per joint for a representation name (``"sixd"`` -> 6)."""
    try:
        return REPRESENTATIONS[representation]
    except KeyError:
        raise ValueError(
            f"unknown rotation representation {representation!r}; expected one of {sorted(REPRESENTATIONS)}"
        ) from None


def to_quat(data: np.ndarray, representation: str, order: str | None = None, degrees: bool = True) -> np.ndarray:
    """Convert ``(..., k)`` rotations of a named representation to quaternions ``(..., 4)``.

    ``representation`` is one of ``"euler"`` (needs ``order``; degrees unless ``degrees=False``),
    ``"axis_angle"`` (radians), ``"quat"`` (xyzw), ``"quat_wxyz"``, ``"sixd"`` (Zhou: first two
    columns, ``[R00, R10, R20, R01, R11, R21]``), ``"sixd_rows"`` (PyTorch3D: first two rows,
    ``[R00, R01, R02, R10, R11, R12]``) or ``"matrix"`` (``(..., 3, 3)`` or flattened row-major
    ``(..., 9)``).

    >>> to_quat(np.array([1.0, 0, 0, 0]), "quat_wxyz").tolist()
    [0.0, 0.0, 0.0, 1.0]
    """
    width = representation_width(representation)
    data = np.asarray(data, dtype=np.float64)
    if representation == "matrix":
        if data.shape[-2:] == (3, 3):
            return matrix_to_quat(data)
        if data.shape[-1:] == (9,):
            return matrix_to_quat(data.reshape(data.shape[:-1] + (3, 3)))
        raise ValueError(f"matrix rotations must be (..., 3, 3) or (..., 9), got {data.shape}")
    if data.shape[-1:] != (width,):
        raise ValueError(f"{representation} rotations need {width} numbers per joint, got shape {data.shape}")
    if representation == "euler":
        if order is None:
            raise ValueError("Euler rotations need an order such as 'XYZ'")
        return euler_to_quat(data, order, degrees=degrees)
    if representation == "axis_angle":
        return axis_angle_to_quat(data)
    if representation == "quat":
        return quat_normalize(data)
    if representation == "quat_wxyz":
        return quat_normalize(data[..., [1, 2, 3, 0]])
    if representation == "sixd_rows":
        return sixd_rows_to_quat(data)
    return sixd_to_quat(data)


def from_quat(q: np.ndarray, representation: str, order: str | None = None, degrees: bool = True) -> np.ndarray:
    """Inverse of :func:`to_quat`: quaternions ``(..., 4)`` to a named representation."""
    representation_width(representation)
    q = np.asarray(q, dtype=np.float64)
    if representation == "euler":
        if order is None:
            raise ValueError("Euler rotations need an order such as 'XYZ'")
        return quat_to_euler(q, order, degrees=degrees)
    if representation == "axis_angle":
        return quat_to_axis_angle(q)
    if representation == "quat":
        return quat_normalize(q)
    if representation == "quat_wxyz":
        return quat_normalize(q)[..., [3, 0, 1, 2]]
    if representation == "sixd":
        return quat_to_sixd(q)
    if representation == "sixd_rows":
        return quat_to_sixd_rows(q)
    return quat_to_matrix(q)
