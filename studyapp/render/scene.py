"""A trial as the renderer sees it: up to three animated avatars side by side, one camera, neutral labels.

>>> from studyapp.render.avatar import build_default_avatar
>>> from studyapp.render.pose import prepare_slot
>>> from studyapp.motion.skeleton import Motion
>>> av = build_default_avatar()
>>> slot = prepare_slot(av, Motion.rest(av.skeleton, n_frames=30, fps=30.0), None)
>>> scene = make_scene([slot, slot, slot], av, labels=("A", "B", "C"))
>>> scene.n_slots, scene.duration
(3, 1.0)
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from studyapp.errors import InputError
from studyapp.render.avatar import Avatar, build_default_avatar
from studyapp.render.camera import DEFAULT_FRAMING, Camera, fit_box, follow_offsets, framing_box
from studyapp.render.pose import SlotAnimation, prepare_slot

#: Aspect ratio (width / height) of one slot in the standard 1280x720 three-slot layout.
THREE_SLOT_ASPECT = (1280 / 3) / 720


@dataclass(eq=False)
class TrialScene:
    """What one trial shows.

    Attributes
    ----------
    slots:
        One :class:`SlotAnimation` per slot, left to right (1 to 3 slots).
    avatars:
        The avatar drawn in each slot. Pass the same object for every slot to share GPU buffers.
    labels:
        Neutral slot labels (``("A", "B", "C")``, ``("Left", "Middle", "Right")``) or None. Never model names.
    camera:
        The one camera every slot uses (see :func:`frame_camera`).
    """

    slots: tuple[SlotAnimation, ...]
    avatars: tuple[Avatar, ...]
    labels: tuple[str, ...] | None
    camera: Camera

    def __post_init__(self) -> None:
        self.slots = tuple(self.slots)
        self.avatars = tuple(self.avatars)
        if not 1 <= len(self.slots) <= 3:
            raise ValueError(f"a trial shows 1 to 3 slots, got {len(self.slots)}")
        if len(self.avatars) != len(self.slots):
            raise ValueError(f"{len(self.avatars)} avatars for {len(self.slots)} slots")
        if self.labels is not None:
            self.labels = tuple(str(x) for x in self.labels)
            if len(self.labels) != len(self.slots):
                raise ValueError(f"{len(self.labels)} labels for {len(self.slots)} slots")

    @property
    def n_slots(self) -> int:
        return len(self.slots)

    @property
    def duration(self) -> float:
        """Seconds until the longest slot's motion ends."""
        return max(s.duration for s in self.slots)


#: Fraction of the frame height kept free above the heads when slot labels are shown.
LABEL_SPACE = 0.09
#: Frames of a clip looked at for framing, at most (evenly spread): plenty for the hands' range.
FRAMING_SAMPLES = 600
_LEG_WORDS = ("leg", "foot", "toe", "knee", "ankle", "thigh", "shin", "calf")


def _joint_sets(avatar: Avatar) -> tuple[np.ndarray, np.ndarray, int]:
    """``(legs, hands, hips)``: masks of leg/foot and hand/finger joints (by name) and the hips' index."""
    sk = avatar.skeleton
    low = [n.lower() for n in sk.names]
    legs = np.array([any(k in n for k in _LEG_WORDS) for n in low], bool)
    hands = np.array(["hand" in n for n in low], bool)
    for j in range(sk.n_joints):  # fingers hang below the hand, whatever their names
        if sk.parents[j] >= 0 and hands[sk.parents[j]]:
            hands[j] = True
    hips = next((j for j, n in enumerate(low) if "hips" in n or "pelvis" in n), int(np.flatnonzero(sk.parents < 0)[0]))
    return legs, hands, hips


def _skin_corners(avatar: Avatar) -> np.ndarray:
    """``(J, 8, 4)`` bind-pose corners (homogeneous) of the box around the vertices each joint carries most;
    a joint that carries none is a point at its bind position. Moved by a skinning matrix they bound that
    part of the skin in any pose."""
    rest = np.linalg.inv(avatar.inverse_bind.astype(np.float64))[:, :3, 3]
    n = avatar.skeleton.n_joints
    lo, hi = rest.copy(), rest.copy()
    if avatar.n_vertices:
        owner = avatar.joints[np.arange(avatar.n_vertices), avatar.weights.argmax(1)].astype(np.int64)
        v = avatar.vertices.astype(np.float64)
        for j in np.unique(owner):
            sel = v[owner == j]
            lo[j], hi[j] = sel.min(axis=0), sel.max(axis=0)
    corners = np.ones((n, 8, 4))
    for k in range(8):
        corners[:, k, :3] = np.where([(k >> 2) & 1, (k >> 1) & 1, k & 1], hi, lo)
    return corners


def follow_hips(slot: SlotAnimation, hips: int, rest_hips: np.ndarray) -> SlotAnimation:
    """``slot`` as seen by a camera that follows its hips across the floor (smoothed, see
    :func:`~studyapp.render.camera.follow_offsets`): the horizontal travel is taken out of its palettes and
    joint positions. The slot itself when it does not travel (within a millimetre) or already follows."""
    if slot.n_frames == 0 or slot in _FOLLOWING:
        return slot
    off = follow_offsets(slot.joint_positions[:, hips, [0, 2]], slot.fps, np.asarray(rest_hips)[[0, 2]])
    if np.abs(off).max() < 1e-3:
        return slot
    shift = np.zeros((slot.n_frames, 3), np.float32)
    shift[:, [0, 2]] = off
    palettes = slot.palettes.copy()
    palettes[:, :, :3, 3] -= shift[:, None]
    out = replace(slot, palettes=palettes, joint_positions=slot.joint_positions - shift[:, None])
    _FOLLOWING.add(out)  # a scene remade from this one's slots (a resized window) does not follow twice
    return out


_FOLLOWING: "weakref.WeakSet[SlotAnimation]" = weakref.WeakSet()


def frame_camera(slots: list[SlotAnimation] | tuple[SlotAnimation, ...], avatar: Avatar, aspect: float,
                 top_reserve: float = 0.0, framing: str = DEFAULT_FRAMING) -> Camera:
    """The shared camera for these slots (already following their hips): see
    :func:`~studyapp.render.camera.framing_box` for what each ``framing`` shows.

    The box is fitted to the skin, not the skeleton: each joint's part of the mesh (head top, fingertips)
    is moved with its skinning matrix over the clip.
    """
    legs, hands, hips = _joint_sets(avatar)
    corners = _skin_corners(avatar)
    head_only = not legs.any() and not hands.any()
    pts = []
    for s in slots:
        if s.n_frames:
            idx = np.unique(np.linspace(0, s.n_frames - 1, min(s.n_frames, FRAMING_SAMPLES)).round().astype(int))
            pal = s.palettes[idx].astype(np.float64)
            pts.append(np.einsum("fjab,jkb->fjka", pal[:, :, :3], corners))
    if not pts:
        pts = [corners[None, :, :, :3]]
    rest_hips_y = float(np.linalg.inv(avatar.inverse_bind[hips].astype(np.float64))[1, 3])
    box = framing_box(framing, np.concatenate(pts), legs, rest_hips_y, avatar.bounds(), head_only=head_only)
    return fit_box(box, aspect, top_reserve=top_reserve)


def make_scene(slots, avatar: Avatar | tuple[Avatar, ...], labels: tuple[str, ...] | None = None,
               aspect: float | None = None, framing: str = DEFAULT_FRAMING) -> TrialScene:
    """A scene from prepared slots; one avatar object for all slots (shared GPU buffers) or one per slot.

    Each slot is shown following its hips (:func:`follow_hips`) and the camera frames what ``framing``
    (``"upper-body"`` or ``"full-body"``) asks for. ``aspect`` is the slot's width / height the camera is
    made for; it refits itself to the aspect it is drawn at.
    """
    slots = tuple(slots)
    avatars = tuple(avatar) if isinstance(avatar, (tuple, list)) else (avatar,) * len(slots)
    if aspect is None:
        aspect = THREE_SLOT_ASPECT if len(slots) == 3 else (1280 / len(slots)) / 720
    followed = {}
    for s, av in zip(slots, avatars):
        if id(s) not in followed:  # the same slot object in several places stays one object
            _, _, hips = _joint_sets(av)
            rest_hips = np.linalg.inv(av.inverse_bind[hips].astype(np.float64))[:3, 3]
            followed[id(s)] = follow_hips(s, hips, rest_hips)
    slots = tuple(followed[id(s)] for s in slots)
    camera = frame_camera(slots, avatars[0], aspect, top_reserve=LABEL_SPACE if labels else 0.0, framing=framing)
    return TrialScene(slots=slots, avatars=avatars, labels=labels, camera=camera)


def load_avatar(spec: str | Path | None, bone_map: dict[str, str] | None = None) -> Avatar:
    """``None``/``"builtin"`` -> the built-in avatar; otherwise a glTF/GLB/VRM file, which must be humanoid.

    ``bone_map`` is the design's ``[avatar.bone_map]`` (``{joint name: humanoid bone}``). A file whose
    joints (recognised names plus ``bone_map``) lack a required humanoid bone is refused with a message
    that names the file, the bones missing and its joints.
    """
    if spec is None or str(spec).lower() in ("", "builtin", "default"):
        return build_default_avatar()
    path = Path(spec)
    if not path.is_file():
        raise InputError(path, None, "avatar file not found (use 'builtin' for the built-in avatar)")
    from studyapp.render.avatar_rig import BONE_MAP_FIX, bone_map_problems, missing_bones, not_humanoid_message

    key = tuple(sorted((bone_map or {}).items()))
    avatar = _load_gltf_cached(str(path.resolve()), path.stat().st_mtime_ns, key)
    bad = bone_map_problems(avatar.skeleton.names, bone_map or {}, avatar.joint_aliases)
    if bad:
        joint, problem = bad[0]
        raise InputError(path, f"[avatar.bone_map] {joint}", f"{problem}; {BONE_MAP_FIX}")
    missing = missing_bones(avatar.skeleton, avatar.bone_map)
    if missing:
        raise InputError(path, None, not_humanoid_message(avatar.skeleton, missing))
    return avatar


_GLTF_CACHE: dict[tuple, Avatar] = {}


def _load_gltf_cached(path: str, mtime: int, bone_map: tuple = ()) -> Avatar:
    from studyapp.render.gltf import load_gltf

    key = (path, mtime, bone_map)
    if key not in _GLTF_CACHE:
        _GLTF_CACHE.clear()  # one custom avatar per study; do not hold old ones
        _GLTF_CACHE[key] = load_gltf(path, bone_map=dict(bone_map) or None)
    return _GLTF_CACHE[key]


def build_trial_scene(ctx_or_renderer: Any, media: Any, labels: tuple[str, ...] | None = None) -> TrialScene:
    """The scene for a study trial (``studyapp.study.stimuli.TrialMedia``): three slots, left to right.

    ``media`` needs ``motions`` (3 Motions in slot order), ``face`` (FaceAnimation or None), ``avatar`` (or
    ``avatar_spec``: ``"builtin"`` or a glTF path) and ``labels``. When given a
    :class:`~studyapp.render.renderer.Renderer` the avatar is uploaded now, so the first frame does not
    stall; a bare context (or None) is accepted for symmetry with the UI code.
    """
    spec = getattr(media, "avatar", None)
    if spec is None:
        spec = getattr(media, "avatar_spec", None)
    avatar = load_avatar(spec, bone_map=getattr(media, "avatar_bone_map", None))
    face = getattr(media, "face", None)
    name_map = getattr(media, "name_map", None)
    slots = [prepare_slot(avatar, m, face, name_map=name_map) for m in media.motions]
    if labels is None:
        labels = getattr(media, "labels", None)
    scene = make_scene(slots, avatar, labels=labels, framing=getattr(media, "framing", None) or DEFAULT_FRAMING)
    if hasattr(ctx_or_renderer, "upload_avatar"):
        ctx_or_renderer.upload_avatar(avatar)
    return scene
