"""SMPL, SMPL-H and SMPL-X motion files, read as gesture models and data sets write them.

Recognised by their keys and shapes (no design keys needed):

=================================  ==============================================================================
layout                             what identifies it
=================================  ==============================================================================
``.npz`` with ``poses``            ``poses`` ``(F, 72)`` SMPL, ``(F, 156)`` SMPL-H, ``(F, 165)`` SMPL-X axis-angle,
                                   optional ``trans`` ``(F, 3)`` metres, ``betas``, ``expressions`` (FLAME),
                                   ``mocap_frame_rate`` (BEAT2, EMAGE) or ``mocap_framerate`` (AMASS)
``.npz`` AMASS split               ``root_orient`` ``(F, 3)`` + ``pose_body`` ``(F, 63)`` (+ ``pose_hand``
                                   ``(F, 90)`` for SMPL-H, + ``pose_jaw``, ``pose_eye`` for SMPL-X)
``.npy`` TalkSHOW                  ``(F, 265)``: jaw 3, left eye 3, right eye 3, global orient 3, body 63, left
                                   hand 45, right hand 45, FLAME expressions 100 (``scripts/demo.py`` of
                                   yhw-yhw/TalkSHOW); 30 fps unless the condition's ``fps`` says otherwise
=================================  ==============================================================================

Joint order (3 axis-angle numbers each): 0 pelvis, 1-21 body, then SMPL-X: 22 jaw, 23-24 eyes, 25-39 left
hand, 40-54 right hand; SMPL-H: 22-36 left hand, 37-51 right hand; SMPL: 22-23 hands. Each hand is index,
middle, pinky, ring, thumb, three joints each. The rest pose is a T-pose, Y up, facing +Z, the figure's left
along +X, every joint's rest frame aligned with the world, so a joint's axis-angle *is* its local rotation.

Rest joint positions are not public constants. They come from the user's own licensed body model file
(:func:`body_model_rest_joints`: ``J_regressor @ (v_template + shapedirs @ betas)``) or, without one, from
:func:`builtin_rest_joints` (average adult proportions written here).

Coordinates: the up axis is read from the data (where the pelvis carries the body's up over the clip), so
Z-up files (AMASS) and upside-down camera-space ones (TalkSHOW) are stood upright about the X axis; ``trans``
stays in metres and the root keeps its motion; the clip is set on the rest pose's floor (its lowest ankle
over the clip at the height of the rest pose's ankles), since data sets put their floor anywhere.

>>> import numpy as np
>>> poses = np.zeros((2, 165)); poses[:, 16 * 3 + 2] = np.pi / 2    # left shoulder +90 degrees about z
>>> m = smpl_motion(SmplData("smplx", poses.reshape(2, 55, 3), np.zeros((2, 3)), 30.0))
>>> m.skeleton.n_joints, m.fps, m.skeleton.names[16], m.skeleton.unit_scale
(55, 30.0, 'left_shoulder', 1.0)
>>> from studyapp.motion.fk import joint_positions
>>> p = joint_positions(m)[0]
>>> np.round(p[20] - p[16], 2).tolist()       # the left arm points straight up
[0.0, 0.53, 0.0]
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from studyapp.errors import InputError
from studyapp.motion.skeleton import Motion, Skeleton
from studyapp.safe_io import load_npy, load_numpy, npy_header, open_npz, require

__all__ = [
    "FAMILY_JOINTS", "FAMILY_NAMES", "SMPL_BODY_JOINTS", "SMPLX_JOINTS", "SMPLH_JOINTS", "SMPL_JOINTS",
    "TALKSHOW_WIDTH", "SmplData", "joint_names", "parents", "recognise_smpl", "read_smpl", "up_axis",
    "builtin_rest_joints", "body_model_rest_joints", "smpl_skeleton", "smpl_motion", "load_smpl_motion",
    "summarize_smpl",
]

#: The 22 joints SMPL, SMPL-H and SMPL-X share (pelvis and body).
SMPL_BODY_JOINTS: tuple[str, ...] = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
    "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
    "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
)
_BODY_PARENTS = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)
_FINGERS = ("index", "middle", "pinky", "ring", "thumb")
_LEFT_WRIST, _RIGHT_WRIST, _HEAD = 20, 21, 15
_ANKLES = [7, 8]


def _hand(side: str) -> tuple[str, ...]:
    return tuple(f"{side}_{f}{k}" for f in _FINGERS for k in (1, 2, 3))


SMPLX_JOINTS: tuple[str, ...] = (SMPL_BODY_JOINTS + ("jaw", "left_eye_smplhf", "right_eye_smplhf")
                                 + _hand("left") + _hand("right"))
SMPLH_JOINTS: tuple[str, ...] = SMPL_BODY_JOINTS + _hand("left") + _hand("right")
SMPL_JOINTS: tuple[str, ...] = SMPL_BODY_JOINTS + ("left_hand", "right_hand")

#: Family -> joint count (``poses`` has three numbers per joint).
FAMILY_JOINTS: dict[str, int] = {"smpl": 24, "smplh": 52, "smplx": 55}
#: Family -> the name people write.
FAMILY_NAMES: dict[str, str] = {"smpl": "SMPL", "smplh": "SMPL-H", "smplx": "SMPL-X"}
#: Columns of a TalkSHOW ``.npy`` (see the module docstring).
TALKSHOW_WIDTH = 265
#: TalkSHOW writes at 30 fps and stores no rate.
TALKSHOW_FPS = 30.0


def joint_names(family: str) -> tuple[str, ...]:
    """Joint names of a family in ``poses`` order.

    >>> len(joint_names("smplh")), joint_names("smplx")[22], joint_names("smplh")[22]
    (52, 'jaw', 'left_index1')
    """
    return {"smpl": SMPL_JOINTS, "smplh": SMPLH_JOINTS, "smplx": SMPLX_JOINTS}[family]


def parents(family: str) -> np.ndarray:
    """The kinematic tree: each joint's parent index (``-1`` for the pelvis).

    >>> parents("smplx")[[22, 23, 25, 26, 27, 40]].tolist()    # jaw, eye from the head; fingers chain from wrists
    [15, 15, 20, 25, 26, 21]
    """
    out = list(_BODY_PARENTS)
    first = len(out)
    if family == "smpl":
        out += [_LEFT_WRIST, _RIGHT_WRIST]
        return np.array(out)
    if family == "smplx":
        out += [_HEAD, _HEAD, _HEAD]
        first += 3
    for wrist in (_LEFT_WRIST, _RIGHT_WRIST):
        for _ in _FINGERS:
            out += [wrist, len(out), len(out) + 1]
    return np.array(out)


# -- the built-in rest skeleton ------------------------------------------------------------------------------

# Average adult, 1.70 m, floor at y = 0, metres, rounded to the cm. Heights and limb lengths follow the
# segment-length fractions of body height in Winter, "Biomechanics and Motor Control of Human Movement"
# (knee 0.285 H, ankle 0.039 H, shoulder 0.818 H, upper arm 0.186 H, forearm 0.146 H, hand 0.108 H); where the
# joints sit (pelvis above the hip joints, three spine joints, collars inboard of the shoulders, the head joint
# at the skull base) follows the SMPL-X template's layout, except that the trunk joints are set in one vertical
# line: retargeting copies each spine bone's direction, and the template's forward-set head joint would bow an
# avatar's neck at the zero pose. Left side only: the right mirrors x.
_BODY_LEFT: dict[str, tuple[float, float, float]] = {
    "pelvis": (0.0, 0.95, 0.0),
    "left_hip": (0.08, 0.86, 0.0),
    "spine1": (0.0, 1.06, 0.0),
    "left_knee": (0.10, 0.48, 0.0),
    "spine2": (0.0, 1.19, 0.0),
    "left_ankle": (0.09, 0.07, -0.03),
    "spine3": (0.0, 1.25, 0.0),
    "left_foot": (0.11, 0.02, 0.10),
    "neck": (0.0, 1.47, 0.0),
    "left_collar": (0.08, 1.38, 0.0),
    "head": (0.0, 1.55, 0.0),
    "left_shoulder": (0.19, 1.41, -0.01),
    "left_elbow": (0.47, 1.41, -0.01),
    "left_wrist": (0.72, 1.41, -0.01),
}
# From the head joint (SMPL-X only): the jaw hinge below and in front of it, the eyes above and in front.
_HEAD_PARTS = {"jaw": (0.0, -0.03, 0.04), "left_eye_smplhf": (0.03, 0.07, 0.08)}
# Left hand, from the wrist (+x along the hand, palm down): each finger's knuckle, then its two phalanges.
_FINGER_LEFT: dict[str, tuple[tuple[float, float, float], ...]] = {
    "index": ((0.09, -0.01, 0.025), (0.04, 0.0, 0.0), (0.025, 0.0, 0.0)),
    "middle": ((0.095, -0.01, 0.005), (0.04, 0.0, 0.0), (0.027, 0.0, 0.0)),
    "pinky": ((0.08, -0.015, -0.04), (0.025, 0.0, 0.0), (0.02, 0.0, 0.0)),
    "ring": ((0.09, -0.012, -0.02), (0.035, 0.0, 0.0), (0.025, 0.0, 0.0)),
    "thumb": ((0.03, -0.02, 0.03), (0.03, -0.01, 0.025), (0.025, -0.005, 0.02)),
}
_SMPL_HAND = (0.09, -0.01, 0.0)  # SMPL's single hand joint, at the knuckles


def _mirror(name: str, v) -> np.ndarray:
    v = np.array(v, dtype=np.float64)
    if name.startswith("right_"):
        v[0] = -v[0]
    return v


def builtin_rest_joints(family: str) -> np.ndarray:
    """``(J, 3)`` rest joint positions of an average adult (metres, floor at 0, T-pose facing +Z).

    >>> p = builtin_rest_joints("smplx")
    >>> p.shape, float(p[15, 1]), bool(p[16, 0] > 0 > p[17, 0])    # head height; left shoulder along +x
    ((55, 3), 1.55, True)
    """
    names = joint_names(family)
    par = parents(family)
    pos = np.zeros((len(names), 3))
    for j, n in enumerate(names):
        left = n.replace("right_", "left_")
        if left in _BODY_LEFT:
            pos[j] = _mirror(n, _BODY_LEFT[left])
        elif left in _HEAD_PARTS:
            pos[j] = pos[par[j]] + _mirror(n, _HEAD_PARTS[left])
        elif n.endswith("_hand"):
            pos[j] = pos[par[j]] + _mirror(n, _SMPL_HAND)
        else:  # a finger joint: "left_index2" -> finger "index", phalanx 2
            finger, k = left[len("left_"):-1], int(left[-1])
            pos[j] = pos[par[j]] + _mirror(n, _FINGER_LEFT[finger][k - 1])
    return pos


def body_model_rest_joints(model_path: str | Path, betas: np.ndarray | None, family: str) -> np.ndarray:
    """``(J, 3)`` rest joints of a user's body model file shaped by ``betas``:
    ``J_regressor @ (v_template + shapedirs @ betas)``.

    The file is the ``.npz`` the SMPL family's sites hand out (``SMPLX_NEUTRAL.npz``): ``J_regressor``
    ``(J, V)``, ``v_template`` ``(V, 3)``, ``shapedirs`` ``(V, 3, S)`` and optionally ``kintree_table`` ``(2, J)``,
    checked against the family's tree. Betas beyond the model's ``S`` directions are dropped (SMPL-X keeps
    its expression directions after the shape ones, so only the first ``len(betas)`` columns are shape).
    """
    path = str(model_path)
    if not Path(path).is_file():
        raise InputError(path, None, "body model file not found")
    z = load_numpy(path)
    if isinstance(z, np.ndarray):
        raise InputError(path, None, "a body model is an .npz with J_regressor, v_template and shapedirs")
    with z:
        missing = [k for k in ("J_regressor", "v_template", "shapedirs") if k not in z.files]
        if missing:
            raise InputError(path, "keys", f"not a body model: missing {', '.join(missing)} "
                                           f"(the file has {', '.join(z.files) or 'nothing'})")
        reg = np.asarray(require(z["J_regressor"], path, "key J_regressor"), dtype=np.float64)
        vt = np.asarray(require(z["v_template"], path, "key v_template"), dtype=np.float64)
        dirs = np.asarray(require(z["shapedirs"], path, "key shapedirs"), dtype=np.float64)
        tree = (require(z["kintree_table"], path, "key kintree_table", "integer", (2, None))
                if "kintree_table" in z.files else None)
    n_j = FAMILY_JOINTS[family]
    if vt.ndim != 2 or vt.shape[1] != 3:
        raise InputError(path, "key v_template", f"shape {vt.shape}; expected (vertices, 3)")
    if reg.shape != (n_j, vt.shape[0]):
        raise InputError(path, "key J_regressor", f"shape {reg.shape}; a {FAMILY_NAMES[family]} motion needs "
                                                  f"({n_j}, {vt.shape[0]}): is this the {FAMILY_NAMES[family]} model?")
    if dirs.ndim != 3 or dirs.shape[:2] != vt.shape:
        raise InputError(path, "key shapedirs", f"shape {dirs.shape}; expected ({vt.shape[0]}, 3, directions)")
    if tree is not None:
        par = tree[0].astype(np.int64)
        par[par >= n_j] = -1  # the root's parent is stored as 2**32 - 1
        if par.shape != (n_j,) or not np.array_equal(par, parents(family)):
            raise InputError(path, "key kintree_table", f"its joint tree is not {FAMILY_NAMES[family]}'s")
    shaped = vt
    if betas is not None and len(betas):
        n = min(len(betas), dirs.shape[2])
        shaped = vt + dirs[:, :, :n] @ np.asarray(betas[:n], dtype=np.float64)
    return reg @ shaped


# -- reading files ------------------------------------------------------------------------------------------


@dataclass(eq=False)
class SmplData:
    """An SMPL-family motion as its file holds it.

    ``poses`` ``(F, J, 3)`` axis-angle in the family's joint order, ``trans`` ``(F, 3)`` metres, ``fps``,
    ``betas`` (shape), ``expressions`` ``(F, E)`` FLAME coefficients or ``None``, ``layout`` (which of the
    module's layouts), ``notes`` (what was assumed, for ``inspect``).
    """

    family: str
    poses: np.ndarray
    trans: np.ndarray
    fps: float
    betas: np.ndarray | None = None
    expressions: np.ndarray | None = None
    layout: str = "npz poses"
    gender: str | None = None
    source: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def n_frames(self) -> int:
        return int(self.poses.shape[0])

    @property
    def jaw(self) -> np.ndarray | None:
        """``(F, 3)`` jaw axis-angle (SMPL-X only), else ``None``."""
        return self.poses[:, 22] if self.family == "smplx" else None


_WIDTHS = {3 * n: fam for fam, n in FAMILY_JOINTS.items()}
_FPS_KEYS = ("mocap_frame_rate", "mocap_framerate", "fps", "frame_rate")
_AMASS_SPLIT = ("root_orient", "pose_body")


def _npz_arrays(path: Path) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` that is data (pickled objects, which some pipelines add, are skipped, never
    loaded); a file that is not a readable ``.npz`` is an :class:`InputError` saying why."""
    with open_npz(path) as z:  # these files are a few MB at most: read them whole
        return z.arrays(skip_objects=True)


def _npz_shapes(path: Path) -> dict[str, tuple[int, ...]] | None:
    """The shapes of an ``.npz``'s data arrays, from their headers alone; ``None`` for an unreadable file."""
    try:
        with open_npz(path) as z:
            return {k: z.header(k).shape for k in z.files if z.is_plain(k)}
    except InputError:
        return None


def recognise_smpl(path: str | Path) -> str | None:
    """The SMPL family of a motion file (``"smpl"``, ``"smplh"``, ``"smplx"``), or ``None`` when it is not one.

    Only keys and shapes are looked at; a studyapp motion NPZ (``rotations``, ``joints``) is never one.
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext == ".npy":
        try:
            h = npy_header(p)
        except InputError:
            return None
        ok = len(h.shape) == 2 and h.shape[1] == TALKSHOW_WIDTH
        return "smplx" if ok and h.dtype.kind in "iuf" else None
    if ext != ".npz":
        return None
    shapes = _npz_shapes(p)
    if not shapes or "rotations" in shapes:
        return None
    pose = shapes.get("poses")
    if pose is not None and len(pose) == 2 and pose[1] in _WIDTHS:
        return _WIDTHS[pose[1]]
    if all(k in shapes for k in _AMASS_SPLIT) and shapes["pose_body"][-1:] == (63,):
        if "pose_jaw" in shapes or "pose_eye" in shapes:
            return "smplx"
        return "smplh" if "pose_hand" in shapes else "smpl"
    return None


def _scalar_text(z: dict[str, np.ndarray], key: str) -> str | None:
    if key not in z:
        return None
    v = z[key]
    return str(v.item() if v.shape == () else v) if v.dtype.kind in "US" else None


def read_smpl(path: str | Path, fps: float | None = None) -> SmplData:
    """Read a recognised SMPL-family file (:func:`recognise_smpl`); ``fps`` overrides the file's rate."""
    p = Path(path)
    family = recognise_smpl(p)
    if family is None:
        raise InputError(str(p), "keys", "not an SMPL, SMPL-H or SMPL-X motion file (expected `poses` of 72, 156 "
                                         f"or 165 columns, AMASS's root_orient/pose_body, or a {TALKSHOW_WIDTH}-column "
                                         "TalkSHOW .npy)")
    n_j = FAMILY_JOINTS[family]
    notes: list[str] = []
    if p.suffix.lower() == ".npy":
        a = np.asarray(require(load_npy(p), str(p), "array", shape=(None, TALKSHOW_WIDTH)), dtype=np.float64)
        poses = np.concatenate([a[:, 9:12], a[:, 12:75], a[:, 0:3], a[:, 3:9], a[:, 75:165]], axis=1)
        trans = np.zeros((a.shape[0], 3))
        rate = fps if fps is not None else TALKSHOW_FPS
        if fps is None:
            notes.append(f"TalkSHOW .npy stores no frame rate: read at {TALKSHOW_FPS:g} fps (set fps to change)")
        notes.append("TalkSHOW hand poses are relative to SMPL-X's mean hand pose, which only the model file holds: "
                     "fingers play without it")
        data = SmplData(family, poses.reshape(-1, n_j, 3), trans, float(rate), None, a[:, 165:265],
                        "TalkSHOW npy", None, str(p), notes)
        return _checked(data)
    z = _npz_arrays(p)
    for key in ("poses", "root_orient", "pose_body", "pose_jaw", "pose_eye", "pose_hand", "trans", "betas",
                *_FPS_KEYS):
        if key in z:  # a field of text where numbers belong is refused by name, never cast into a traceback
            require(z[key], str(p), f"key {key}")
    if "poses" in z and z["poses"].ndim == 2 and z["poses"].shape[1] == 3 * n_j:
        poses = np.asarray(z["poses"], dtype=np.float64)
        layout = "npz poses"
    else:
        parts = [require(z["root_orient"], str(p), "key root_orient", shape=(None, 3)),
                 require(z["pose_body"], str(p), "key pose_body", shape=(None, 63))]
        if family == "smplx":
            f = z["root_orient"].shape[0]
            parts += [z["pose_jaw"] if "pose_jaw" in z else np.zeros((f, 3)),
                      z["pose_eye"] if "pose_eye" in z else np.zeros((f, 6))]
        if family != "smpl":
            parts.append(z["pose_hand"] if "pose_hand" in z else np.zeros((z["root_orient"].shape[0], 90)))
        else:
            parts.append(np.zeros((z["root_orient"].shape[0], 6)))
        try:
            poses = np.concatenate([np.asarray(x, dtype=np.float64).reshape(len(x), -1) for x in parts], axis=1)
        except ValueError as exc:
            raise InputError(str(p), "keys root_orient/pose_*", f"arrays disagree in frame count ({exc})") from None
        layout = "npz AMASS split"
    f = poses.shape[0]
    trans = np.asarray(z["trans"], dtype=np.float64) if "trans" in z else np.zeros((f, 3))
    if trans.shape != (f, 3):
        raise InputError(str(p), "key trans", f"shape {trans.shape}; expected ({f}, 3) like poses")
    if "trans" not in z:
        notes.append("no `trans`: the root stays in place")
    rate = fps
    if rate is None:
        key = next((k for k in _FPS_KEYS if k in z), None)
        if key is None:
            raise InputError(str(p), "keys", "the file stores no frame rate (mocap_frame_rate or "
                                             "mocap_framerate); set fps on the condition")
        try:
            rate = float(np.asarray(z[key]).reshape(-1)[0])
        except (ValueError, TypeError, IndexError):
            raise InputError(str(p), f"key {key}", f"{z[key]!r} is not a frame rate") from None
    betas = np.asarray(z["betas"], dtype=np.float64).reshape(-1) if "betas" in z else None
    expr = None
    for k in ("expressions", "expression", "expr"):
        if k in z and z[k].ndim == 2 and z[k].shape[0] == f and z[k].dtype.kind in "biuf":
            expr = np.asarray(z[k], dtype=np.float64)
            break
    gender = _scalar_text(z, "gender")
    data = SmplData(family, poses.reshape(f, n_j, 3), trans, float(rate), betas, expr, layout, gender, str(p), notes)
    return _checked(data)


def _checked(data: SmplData) -> SmplData:
    if data.n_frames == 0:
        raise InputError(data.source, "poses", "no frames")
    if not (np.isfinite(data.fps) and data.fps > 0):
        raise InputError(data.source, "frame rate", f"{data.fps} is not a positive frame rate")
    for name, arr in (("poses", data.poses), ("trans", data.trans)):
        if not np.isfinite(arr).all():
            frame = int(np.argwhere(~np.isfinite(arr))[0][0])
            raise InputError(data.source, f"{name}, frame {frame}", "non-finite value")
    return data


# -- the motion ---------------------------------------------------------------------------------------------


def _rotvec_matrices(v: np.ndarray) -> np.ndarray:
    from studyapp.motion.rotations import axis_angle_to_quat, quat_to_matrix

    return quat_to_matrix(axis_angle_to_quat(v))


#: Rotations about +X that stand a file upright, by the world axis its body's up points along.
_STAND_UP = {
    "+Y": np.eye(3),
    "+Z": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),    # -90 degrees about X: z -> y
    "-Z": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),    # +90 degrees about X: -z -> y
    "-Y": np.array([[1.0, 0, 0], [0, -1, 0], [0, 0, -1]]),   # 180 degrees about X (camera space, y down)
}


def up_axis(poses: np.ndarray) -> str:
    """The world axis (``"+Y"``, ``"+Z"``, ``"-Z"``, ``"-Y"``) the body's up points along, over the clip.

    The pelvis's rest frame is the world's, so its rotation applied to +Y is the body's up at each frame.

    >>> up_axis(np.array([[[np.pi / 2, 0.0, 0.0]]])), up_axis(np.zeros((1, 1, 3)))
    ('+Z', '+Y')
    """
    up = _rotvec_matrices(np.asarray(poses, dtype=np.float64)[:, 0])[:, :, 1].mean(axis=0)
    return max(_STAND_UP, key=lambda k: (1 if k[0] == "+" else -1) * up["XYZ".index(k[1])])


def smpl_skeleton(family: str, rest: np.ndarray | None = None) -> Skeleton:
    """The family's skeleton with ``rest`` ``(J, 3)`` joint positions (default :func:`builtin_rest_joints`)."""
    rest = builtin_rest_joints(family) if rest is None else np.asarray(rest, dtype=np.float64)
    par = parents(family)
    offsets = rest - np.where(par[:, None] >= 0, rest[np.maximum(par, 0)], 0.0)
    return Skeleton(joint_names(family), par, offsets, unit_scale=1.0)


def smpl_motion(data: SmplData, rest: np.ndarray | None = None) -> Motion:
    """``data`` as a :class:`Motion` on :func:`smpl_skeleton` (metres, +Y up).

    Each joint's axis-angle is its local rotation (rest frames align with the world); the root is at its rest
    position plus ``trans``, both turned upright (:func:`up_axis`), then lifted or lowered so the clip's
    lowest ankle over all frames is as high as the rest pose's: the files' floors differ, and so do the
    templates' origins (the BEAT2 excerpt's ``trans`` holds about 1.3 m in y, AMASS's some 0.9 m in z).
    Ankles, not toes: a foot pitched down would otherwise sink the whole figure.
    """
    from studyapp.motion.fk import joint_positions, rest_joint_positions
    from studyapp.motion.rotations import axis_angle_to_quat, matrix_to_quat, quat_multiply

    sk = smpl_skeleton(data.family, rest)
    f = data.n_frames
    rot = axis_angle_to_quat(data.poses.reshape(f, -1, 3))
    stand = _STAND_UP[up_axis(data.poses)]
    if stand is not _STAND_UP["+Y"]:
        rot[:, 0] = quat_multiply(np.broadcast_to(matrix_to_quat(stand), (f, 4)), rot[:, 0])
    trans = np.broadcast_to(sk.offsets, (f, sk.n_joints, 3)).copy()
    trans[:, 0] = (sk.offsets[0] + data.trans) @ stand.T
    motion = Motion(sk, float(data.fps), rot, trans, source=data.source)
    rest_floor = float(rest_joint_positions(sk)[_ANKLES, 1].min())
    clip_floor = float(joint_positions(motion)[:, _ANKLES, 1].min())
    trans[:, 0, 1] += rest_floor - clip_floor
    return Motion(sk, float(data.fps), rot, trans, source=data.source)


def load_smpl_motion(path: str | Path, fps: float | None = None, body_model: str | Path | None = None) -> Motion:
    """Read an SMPL-family file as a :class:`Motion`, with rest joints from ``body_model`` when given."""
    data = read_smpl(path, fps=fps)
    rest = None if body_model is None else body_model_rest_joints(body_model, data.betas, data.family)
    return smpl_motion(data, rest)


def summarize_smpl(data: SmplData) -> dict:
    """What ``studyapp inspect`` says about an SMPL-family file beyond the skeleton facts."""
    up = up_axis(data.poses)
    face = []
    if data.family == "smplx":
        face.append("jaw pose (drives jawOpen)")
    if data.expressions is not None:
        face.append(f"{data.expressions.shape[1]} FLAME expression coefficients (used only with a FLAME-to-ARKit "
                    "map, e.g. view --flame-map map.npy)")
    return {
        "family": FAMILY_NAMES[data.family],
        "layout": data.layout,
        "up_axis": up + (" (stood upright)" if up != "+Y" else ""),
        "face_parameters": face or ["none"],
        "betas": 0 if data.betas is None else int(data.betas.size),
        "gender": data.gender,
        "notes": list(data.notes),
    }
