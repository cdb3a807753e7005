"""Motion stored as numpy arrays (model outputs) and studyapp's own NPZ motion format.

Gesture models write per-frame joint rotations as arrays: CaMN Euler angles, DiffSHEG axis-angle,
FaceCapGes 6D, often flattened to ``(F, J*k)`` and without any skeleton. 6D comes in two layouts that
the numbers cannot tell apart: ``"sixd"`` (Zhou et al.: first two columns, ``[R00, R10, R20, R01, R11,
R21]``) and ``"sixd_rows"`` (PyTorch3D's ``matrix_to_rotation_6d``, used by EMAGE and other
BEAT-derived code: first two rows, ``[R00, R01, R02, R10, R11, R12]``); the wrong one plays every joint
rotation inverted. :func:`load_rotation_array`
puts such an array onto a template skeleton; :func:`save_motion_npz` / :func:`load_motion_npz` keep a
whole motion (skeleton included) in one NPZ.

>>> import numpy as np, tempfile, os
>>> from studyapp.motion.beat import beat_skeleton
>>> path = os.path.join(tempfile.mkdtemp(), "out.npy")
>>> np.save(path, np.zeros((30, 47 * 3)))            # DiffSHEG-like: 47 joints, axis-angle
>>> m = load_rotation_array(path, beat_skeleton(), "axis_angle", fps=15)
>>> m.rotations.shape, m.fps
((30, 75, 4), 15.0)
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from studyapp.errors import InputError
from studyapp.safe_io import Npz, load_numpy, npy_header, numpy_kind, open_npz, require
from studyapp.motion.fk import joint_positions
from studyapp.motion.rotations import REPRESENTATIONS, representation_width, to_quat
from studyapp.motion.skeleton import Motion, Skeleton

__all__ = [
    "load_rotation_array", "save_motion_npz", "load_motion_npz", "read_array", "is_motion_npz", "check_numpy_file",
    "fitting_representations",
]

# keys tried, in order, when an NPZ holds several arrays and no key is given
_ROTATION_KEYS = ("rotations", "rotation", "poses", "pose", "motion", "body_pose", "data", "arr_0")
_ROOT_KEYS = ("root", "root_translation", "trans", "translation", "transl")


def _template_motion(template: Motion | Skeleton | str | Path) -> Motion:
    if isinstance(template, Motion):
        return template
    if isinstance(template, Skeleton):
        return Motion.rest(template)
    name = str(template)
    if name.lower() == "beat":
        from studyapp.motion.beat import beat_skeleton

        return Motion.rest(beat_skeleton())
    from studyapp.motion.io import load_motion

    return load_motion(name)


def check_numpy_file(path: str | Path) -> None:
    """Raise :class:`InputError` unless ``path`` is a readable ``.npy`` (header checked against the file's
    size) or ``.npz`` (zip directory within :data:`~studyapp.safe_io.NPZ_ZIP`).

    Checked before the data is read: ``np.load`` takes any other file for a pickle and then complains about
    pickles, a message that hides the real problem (a text file or a BVH saved as ``.npy``).
    """
    if numpy_kind(path) == "npy":
        npy_header(path)
    else:
        open_npz(path).close()


def read_array(path: str | Path, key: str | None = None) -> tuple[np.ndarray, str]:
    """The rotation array of an ``.npy`` / ``.npz`` file and the place it came from (for messages)."""
    path = str(path)
    loaded = load_numpy(path)
    if isinstance(loaded, np.ndarray):
        if key is not None:
            raise InputError(path, f"key {key}", "an .npy file holds a single array; drop the key")
        return loaded, "array"
    with loaded:
        keys = loaded.keys()
        if key is None:
            if len(keys) == 1:
                key = keys[0]
            else:
                key = next((k for k in _ROTATION_KEYS if k in keys), None)
                if key is None:
                    raise InputError(path, "keys", f"several arrays ({', '.join(keys)}); say which holds the rotations")
        if key not in keys:
            raise InputError(path, f"key {key}", f"no such array; the file has: {', '.join(keys) or 'nothing'}")
        return loaded[key], f"key {key}"


def _open_npz(path: str) -> Npz:
    """An ``.npz`` (an ``.npy`` or any other file is refused by name)."""
    loaded = load_numpy(path)
    if isinstance(loaded, np.ndarray):
        raise InputError(path, None, "an .npy file holds a single array; a motion NPZ holds several")
    return loaded


def fitting_representations(shape: tuple[int, ...]) -> list[str]:
    """Representations whose per-joint width fits an array of ``shape`` the way
    :func:`load_rotation_array` reads it (``(F, J, k)``, flattened ``(F, J*k)`` or ``(F, J, 3, 3)``).

    Only the shape is checked: a fit is a possibility, not a guess at what the array holds.

    >>> fitting_representations((30, 47 * 6))
    ['euler', 'axis_angle', 'sixd', 'sixd_rows']
    >>> fitting_representations((1, 30, 47, 4))
    ['quat', 'quat_wxyz']
    """
    shape = tuple(int(n) for n in shape)
    while len(shape) > 2 and shape[0] == 1 and not (len(shape) == 4 and shape[2:] == (3, 3)):
        shape = shape[1:]
    if len(shape) == 4:
        return ["matrix"] if shape[2:] == (3, 3) else []
    if len(shape) == 3:
        return [r for r, k in REPRESENTATIONS.items() if shape[2] == k]
    if len(shape) == 2 and shape[1] > 0:
        return [r for r, k in REPRESENTATIONS.items() if shape[1] % k == 0]
    return []


def _default_joints(skeleton: Skeleton, n: int | None) -> tuple[str, ...]:
    from studyapp.motion.beat import BEAT_UPPER_BODY

    beat_like = set(BEAT_UPPER_BODY) <= set(skeleton.names)
    if beat_like and n == len(BEAT_UPPER_BODY) and n != skeleton.n_joints:
        return BEAT_UPPER_BODY
    return skeleton.names


def load_rotation_array(
    path: str | Path,
    template: Motion | Skeleton | str,
    representation: str,
    fps: float,
    joints: list[str] | None = None,
    order: str | None = None,
    key: str | None = None,
    root_key: str | None = None,
    degrees: bool = True,
) -> Motion:
    """Put an array of per-frame joint rotations onto ``template``'s skeleton.

    Parameters
    ----------
    path:
        ``.npy`` or ``.npz`` with ``(F, J, k)`` or flattened ``(F, J*k)`` values (leading singleton
        batch dimensions are dropped); ``k`` is 3 for ``"euler"`` / ``"axis_angle"``, 4 for
        ``"quat"`` / ``"quat_wxyz"``, 6 for ``"sixd"`` / ``"sixd_rows"``, 9 (or ``3x3``) for ``"matrix"``.
    template:
        A :class:`Motion` (its first frame poses the joints the array does not drive), a
        :class:`Skeleton` (rest pose), a motion file path, or ``"beat"``.
    representation:
        See :func:`studyapp.motion.rotations.to_quat`. For 6D, ``"sixd"`` reads each joint's six
        numbers as Zhou's first two matrix columns ``[R00, R10, R20, R01, R11, R21]``, ``"sixd_rows"``
        as the first two rows ``[R00, R01, R02, R10, R11, R12]`` (PyTorch3D ``matrix_to_rotation_6d``).
    fps:
        Frame rate of the array (arrays carry none).
    joints:
        Template joint names the array's joints map to, in column order. Default: all template
        joints, or :data:`~studyapp.motion.beat.BEAT_UPPER_BODY` when the array has 47 joints and the
        template is BEAT-like.
    order:
        Euler order (``"XYZ"``) for ``"euler"``; default: each joint's order in the template's BVH layout.
    key, root_key:
        NPZ array names for the rotations and an optional ``(F, 3)`` root translation.
    degrees:
        Euler angles in degrees (default) or radians.
    """
    path = str(path)
    width = representation_width(representation)
    base = _template_motion(template)
    sk = base.skeleton
    data, where = read_array(path, key)
    data = np.asarray(data)
    if not np.issubdtype(data.dtype, np.number):
        raise InputError(path, where, f"array has dtype {data.dtype}; expected numbers")
    data = data.astype(np.float64)
    while data.ndim > 2 and data.shape[0] == 1 and not (representation == "matrix" and data.ndim == 4):
        data = data[0]
    if data.ndim < 2:
        raise InputError(path, where, f"array has shape {data.shape}; expected (frames, joints, {width}) or (frames, joints*{width})")
    n_frames = data.shape[0]
    if representation == "matrix" and data.ndim == 4:
        if data.shape[2:] != (3, 3):
            raise InputError(path, where, f"matrix array has shape {data.shape}; expected (frames, joints, 3, 3)")
        data = data.reshape(n_frames, data.shape[1], 9)
    if data.ndim == 3:
        if data.shape[2] != width:
            raise InputError(
                path, where,
                f"array has shape {data.shape}: {data.shape[2]} numbers per joint, but {representation} needs {width}",
            )
        n_j = data.shape[1]
    elif data.ndim == 2:
        if data.shape[1] % width:
            raise InputError(
                path, where,
                f"array has {data.shape[1]} columns, not a multiple of {width} ({representation} numbers per joint)",
            )
        n_j = data.shape[1] // width
        data = data.reshape(n_frames, n_j, width)
    else:
        raise InputError(path, where, f"array has shape {data.shape}; expected (frames, joints, {width}) or (frames, joints*{width})")
    if n_frames == 0:
        raise InputError(path, where, "array has no frames")
    if not np.isfinite(data).all():
        bad = np.argwhere(~np.isfinite(data))[0]
        raise InputError(path, where, f"non-finite value at frame {bad[0]}, joint {bad[1]}")

    names = tuple(joints) if joints is not None else _default_joints(sk, n_j)
    if len(names) != n_j:
        raise InputError(
            path, where,
            f"array has {n_j} joints ({n_j * width} values per frame) but "
            f"{len(names)} joint names are mapped ({'given' if joints is not None else 'template'}); "
            f"pass the joint list the columns follow",
        )
    missing = [n for n in names if n not in sk.names]
    if missing:
        raise InputError(path, "joints", f"joints not in the template skeleton: {', '.join(missing)}")
    idx = np.array([sk.index(n) for n in names])

    try:
        if representation == "euler":
            if order is not None:
                quats = to_quat(data, "euler", order=order, degrees=degrees)
            else:
                quats = np.empty((n_frames, n_j, 4))
                for c, j in enumerate(idx):
                    o = sk.rotation_order(int(j))
                    if o is None or len(o) != 3:
                        raise InputError(path, "order", f"joint {sk.names[j]!r} has no 3-axis rotation order in the template; pass order")
                    quats[:, c] = to_quat(data[:, c], "euler", order=o, degrees=degrees)
        else:
            quats = to_quat(data, representation)
    except ValueError as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(path, where, f"cannot read as {representation}: {exc}") from None

    first = 0 if base.n_frames else None
    rot = np.broadcast_to(base.rotations[first] if first is not None else sk.rest_rotations, (n_frames, sk.n_joints, 4)).copy()
    trans = np.broadcast_to(base.translations[first] if first is not None else sk.offsets, (n_frames, sk.n_joints, 3)).copy()
    rot[:, idx] = quats
    if root_key is None:
        _warn_unused_root(path, n_frames)
    else:
        root, rwhere = read_array(path, root_key)
        root = require(root, path, rwhere)
        root = np.asarray(root, dtype=np.float64).reshape(-1, 3) if root.size == n_frames * 3 else None
        if root is None:
            raise InputError(path, f"key {root_key}", f"root translation must be ({n_frames}, 3)")
        roots = np.flatnonzero(sk.parents < 0)
        trans[:, roots[0]] = root
    return Motion(sk, float(fps), rot, trans, source=path)


def _warn_unused_root(path: str, n_frames: int) -> None:
    """Warn when an NPZ holds what looks like a root translation that nobody asked for.

    It is not applied on a guess: model outputs store it in metres, centimetres or normalised units,
    and a wrong unit would throw the figure across the scene; the root stays where the template has it.
    """
    if not path.lower().endswith(".npz"):
        return
    try:
        with open_npz(path) as z:
            found = [k for k in _ROOT_KEYS if k in z.files and int(np.prod(z.header(k).shape)) == n_frames * 3]
    except InputError:
        return
    if found:
        warnings.warn(
            f"{path}: array {found[0]!r} looks like a ({n_frames}, 3) root translation but is not used; the root "
            f"keeps the template's position (pass root_key={found[0]!r} / --root-key {found[0]} to apply it)",
            stacklevel=3,
        )


def save_motion_npz(motion: Motion, path: str | Path) -> None:
    """Write ``motion`` to an NPZ that other tools can read without studyapp.

    Arrays: ``rotations`` ``(F, J, 4)`` local quaternions in ``quaternion_order`` ``'xyzw'``,
    ``translations`` ``(F, J, 3)`` local, ``positions`` ``(F, J, 3)`` world joint positions, ``joints``
    (names), ``parents``, ``offsets``, ``rest_rotations``, ``fps``, ``unit_scale`` (NaN if unknown),
    ``channels`` (the BVH channel layout, one space-separated string per joint) and the BVH end sites
    as ``end_site_joints`` / ``end_site_offsets``.
    """
    sk = motion.skeleton
    np.savez_compressed(
        str(path),
        rotations=motion.rotations,
        translations=motion.translations,
        positions=joint_positions(motion),
        joints=np.array(sk.names, dtype=str),
        parents=sk.parents,
        offsets=sk.offsets,
        rest_rotations=sk.rest_rotations,
        fps=np.float64(motion.fps),
        unit_scale=np.float64(np.nan if sk.unit_scale is None else sk.unit_scale),
        channels=np.array([" ".join(c) for c in sk.channels], dtype=str),
        end_site_joints=np.array(sorted(sk.end_sites), dtype=np.int64),
        end_site_offsets=np.array([sk.end_sites[k] for k in sorted(sk.end_sites)], dtype=np.float64).reshape(-1, 3),
        quaternion_order=np.array("xyzw"),
    )


def is_motion_npz(path: str | Path) -> bool:
    """Whether ``path`` is an NPZ written by :func:`save_motion_npz` (has skeleton and rotations)."""
    try:
        with open_npz(path) as z:
            return {"rotations", "joints", "parents", "offsets"} <= set(z.keys())
    except InputError:
        return False


def load_motion_npz(path: str | Path, fps: float | None = None) -> Motion:
    """Read an NPZ written by :func:`save_motion_npz` back into a :class:`Motion`.

    Every field's kind and shape is checked (:func:`~studyapp.safe_io.require`): a file edited or written by
    another tool with, say, ``joints`` as numbers is refused by the field's name.
    """
    path = str(path)
    z = _open_npz(path)
    with z:
        keys = set(z.keys())
        need = {"rotations", "joints", "parents", "offsets"}
        if not need <= keys:
            raise InputError(path, "keys", f"not a studyapp motion NPZ: missing {', '.join(sorted(need - keys))}")

        def field(key: str, kind: str = "number", shape: tuple[int | None, ...] | None = None) -> np.ndarray:
            return require(z[key], path, f"key {key}", kind, shape)

        rot = np.asarray(field("rotations", shape=(None, None, 4)), dtype=np.float64)
        n_j = rot.shape[1]
        order = str(field("quaternion_order", "text", ())) if "quaternion_order" in keys else "xyzw"
        if order == "wxyz":
            rot = rot[..., [1, 2, 3, 0]]
        elif order != "xyzw":
            raise InputError(path, "key quaternion_order", f"unknown quaternion order {order!r}; expected 'xyzw' or 'wxyz'")
        names = tuple(str(n) for n in field("joints", "text", (n_j,)))
        chans = tuple(tuple(str(c).split()) for c in field("channels", "text", (n_j,))) if "channels" in keys else ()
        unit = float(field("unit_scale", shape=())) if "unit_scale" in keys else float("nan")
        ends = {}
        if "end_site_joints" in keys and "end_site_offsets" in keys:
            joints = field("end_site_joints", "integer", (None,))
            offsets = field("end_site_offsets", shape=(len(joints), 3))
            ends = {int(j): np.asarray(o, dtype=np.float64) for j, o in zip(joints, offsets)}
        parents, offsets = field("parents", "integer", (n_j,)), field("offsets", shape=(n_j, 3))
        rest = field("rest_rotations", shape=(n_j, 4)) if "rest_rotations" in keys else None
        try:
            sk = Skeleton(names, parents, offsets, chans, ends, None if np.isnan(unit) else unit, rest)
        except (ValueError, IndexError) as exc:
            raise InputError(path, "key joints", f"invalid skeleton: {exc}") from None
        trans = (np.asarray(field("translations", shape=rot.shape[:2] + (3,)), dtype=np.float64)
                 if "translations" in keys else np.broadcast_to(sk.offsets, rot.shape[:2] + (3,)).copy())
        if fps is None:
            if "fps" not in keys:
                raise InputError(path, "key fps", "the file stores no frame rate; pass fps")
            fps = float(field("fps", shape=()))
    try:
        return Motion(sk, fps, rot, trans, source=path)
    except ValueError as exc:
        raise InputError(path, "key rotations", str(exc)) from None
