"""A trial as the renderer sees it: up to three animated avatars side by side, one camera, neutral labels.

>>> from studyapp.render.avatar import build_default_avatar
>>> from studyapp.render.pose import prepare_slot
>>> from studyapp.motion.skeleton import Motion
>>> av = build_default_avatar()
>>> slot = prepare_slot(av, Motion.rest(av.skeleton, n_frames=30, fps=30.0), None)
>>> scene = make_scene([slot, slot, slot], av, labels=("A", "B", "C"))
>>> scene.n_slots, scene.duration
(3, 1.0)

A study trial's scene lasts as long as its timeline (:mod:`studyapp.study.timeline`) says, whatever its
motions: :func:`build_trial_scene` passes the trial's ``duration_s``.

>>> make_scene([slot] * 3, av, duration=0.4).duration
0.4
"""
from __future__ import annotations

import weakref
from collections import OrderedDict
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Mapping, Protocol, Sequence, runtime_checkable

import numpy as np

from studyapp.errors import InputError
from studyapp.render.avatar import Avatar, build_default_avatar
from studyapp.render.camera import DEFAULT_FRAMING, Camera, fit_box, follow_offsets, framing_box
from studyapp.render.pose import SlotAnimation, prepare_slot

if TYPE_CHECKING:
    from studyapp.face.animation import FaceAnimation
    from studyapp.motion.skeleton import Motion

#: Most figures one trial shows side by side (a rating trial: up to four).
MAX_SLOTS = 4
#: Aspect ratio (width / height) of one slot in the standard 1280x720 three-slot layout.
THREE_SLOT_ASPECT = (1280 / 3) / 720


@dataclass(eq=False)
class TrialScene:
    """What one trial shows.

    Attributes
    ----------
    slots:
        One :class:`SlotAnimation` per slot, left to right (1 to :data:`MAX_SLOTS` slots).
    avatars:
        The avatar drawn in each slot. Pass the same object for every slot to share GPU buffers.
    labels:
        Neutral slot labels (``("A", "B", "C")``, ``("Left", "Middle", "Right")``) or None. Never model names.
    camera:
        The one camera every slot uses (see :func:`frame_camera`).
    duration:
        Seconds the trial plays (its timeline's length); a slot whose motion ends earlier holds its last frame.
    """

    slots: tuple[SlotAnimation, ...]
    avatars: tuple[Avatar, ...]
    labels: tuple[str, ...] | None
    camera: Camera
    duration: float

    def __post_init__(self) -> None:
        self.slots = tuple(self.slots)
        self.avatars = tuple(self.avatars)
        if not 1 <= len(self.slots) <= MAX_SLOTS:
            raise ValueError(f"a trial shows 1 to {MAX_SLOTS} slots, got {len(self.slots)}")
        if len(self.avatars) != len(self.slots):
            raise ValueError(f"{len(self.avatars)} avatars for {len(self.slots)} slots")
        if self.labels is not None:
            self.labels = tuple(str(x) for x in self.labels)
            if len(self.labels) != len(self.slots):
                raise ValueError(f"{len(self.labels)} labels for {len(self.slots)} slots")
        self.duration = float(self.duration)
        if not (np.isfinite(self.duration) and self.duration > 0):
            raise ValueError(f"a trial lasts a positive number of seconds, got {self.duration}")

    @property
    def n_slots(self) -> int:
        return len(self.slots)


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


def frame_camera(slots: list[SlotAnimation] | tuple[SlotAnimation, ...], avatar: Avatar | Sequence[Avatar],
                 aspect: float, top_reserve: float = 0.0, framing: str = DEFAULT_FRAMING) -> Camera:
    """The shared camera for these slots (already following their hips): see
    :func:`~studyapp.render.camera.framing_box` for what each ``framing`` shows.

    The box is fitted to the skin, not the skeleton: each joint's part of the mesh (head top, fingertips)
    is moved with its skinning matrix over the clip. ``avatar`` is one avatar for every slot or one per slot
    (rigs differ in joints, so each slot's box is found on its own avatar and the camera shows them all).
    """
    avatars = tuple(avatar) if isinstance(avatar, (tuple, list)) else (avatar,) * len(slots)
    boxes = []
    groups: dict[int, list[SlotAnimation]] = {}
    for s, av in zip(slots, avatars):
        groups.setdefault(id(av), []).append(s)
    by_id = {id(av): av for av in avatars}
    for key, group in groups.items():
        boxes.append(_skin_box(group, by_id[key], framing))
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    return fit_box((lo, hi), aspect, top_reserve=top_reserve)


def _skin_box(slots: Sequence[SlotAnimation], avatar: Avatar, framing: str) -> tuple[np.ndarray, np.ndarray]:
    """The framing box of slots that share one avatar."""
    legs, hands, hips = _joint_sets(avatar)
    corners = _skin_corners(avatar)
    head_only = not legs.any() and not hands.any()
    # A box moved by an affine map reaches, on each axis, exactly centre' -+ |A| half-size: two points per
    # joint and frame give framing_box the same per-frame extent as the eight corners, at a quarter of the
    # work (this runs before a participant's first frame; issue 20).
    centre = (corners[:, 0, :3] + corners[:, 7, :3]) / 2  # corner 0 is the box's low end, 7 its high end
    half = (corners[:, 7, :3] - corners[:, 0, :3]) / 2
    pts = []
    for s in slots:
        if s.n_frames:
            idx = np.unique(np.linspace(0, s.n_frames - 1, min(s.n_frames, FRAMING_SAMPLES)).round().astype(int))
            pal = s.palettes[idx, :, :3].astype(np.float64)
            mid = np.einsum("fjab,jb->fja", pal[..., :3], centre) + pal[..., 3]
            reach = np.einsum("fjab,jb->fja", np.abs(pal[..., :3]), half)
            pts.append(np.stack([mid - reach, mid + reach], axis=2))
    if not pts:
        pts = [corners[None, :, :, :3]]
    rest_hips_y = float(np.linalg.inv(avatar.inverse_bind[hips].astype(np.float64))[1, 3])
    return framing_box(framing, np.concatenate(pts), legs, rest_hips_y, avatar.bounds(), head_only=head_only)


def make_scene(slots, avatar: Avatar | tuple[Avatar, ...], labels: tuple[str, ...] | None = None,
               aspect: float | None = None, framing: str = DEFAULT_FRAMING,
               duration: float | None = None) -> TrialScene:
    """A scene from prepared slots; one avatar object for all slots (shared GPU buffers) or one per slot.

    Each slot is shown following its hips (:func:`follow_hips`) and the camera frames what ``framing``
    (``"upper-body"`` or ``"full-body"``) asks for. ``aspect`` is the slot's width / height the camera is
    made for; it refits itself to the aspect it is drawn at. ``duration``: how long the scene plays. A study
    trial passes its timeline's length; without one (a single file in ``view``, the environment check) the
    scene lasts as long as its longest slot.
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
    camera = frame_camera(slots, avatars, aspect, top_reserve=LABEL_SPACE if labels else 0.0, framing=framing)
    if duration is None:
        duration = max(s.duration for s in slots)
    return TrialScene(slots=slots, avatars=avatars, labels=labels, camera=camera, duration=duration)


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
    from studyapp.render.avatar_rig import (BONE_MAP_FIX, bone_map_problems, missing_bones, not_humanoid_message,
                                            not_upright_problem)

    key = tuple(sorted((bone_map or {}).items()))
    try:
        avatar = _load_gltf_cached(str(path.resolve()), path.stat().st_mtime_ns, key)
    except InputError:
        raise
    except (ValueError, ArithmeticError, np.linalg.LinAlgError, KeyError, IndexError) as exc:
        # a damaged file (e.g. a singular inverse bind matrix) must read as a problem with this file, not a crash
        raise InputError(path, "avatar", f"cannot load the avatar ({type(exc).__name__}: {exc}); export it "
                         "again from the modelling tool, or use 'builtin'") from exc
    bad = bone_map_problems(avatar.skeleton.names, bone_map or {}, avatar.joint_aliases)
    if bad:
        joint, problem = bad[0]
        raise InputError(path, f"[avatar.bone_map] {joint}", f"{problem}; {BONE_MAP_FIX}")
    # an animal is refused as one before any bone-map advice (no bone map makes a fox stand)
    upright = not_upright_problem(avatar.skeleton, avatar.bone_map)
    if upright is not None:
        raise InputError(path, None, upright)
    missing = missing_bones(avatar.skeleton, avatar.bone_map)
    if missing:
        raise InputError(path, None, not_humanoid_message(avatar.skeleton, missing))
    return avatar


#: Loaded glTF avatars by (path, mtime, bone map). A few, not one: a study may give each speaker (or slot) its
#: own, and ``validate`` walks every stimulus; an avatar is loaded (and its inverse binds checked) once per file.
_GLTF_CACHE: OrderedDict[tuple, Avatar] = OrderedDict()
_GLTF_CACHE_SIZE = 4


def _load_gltf_cached(path: str, mtime: int, bone_map: tuple = ()) -> Avatar:
    from studyapp.render.gltf import load_gltf

    key = (path, mtime, bone_map)
    if key in _GLTF_CACHE:
        _GLTF_CACHE.move_to_end(key)
    else:
        _GLTF_CACHE[key] = load_gltf(path, bone_map=dict(bone_map) or None)
        while len(_GLTF_CACHE) > _GLTF_CACHE_SIZE:
            _GLTF_CACHE.popitem(last=False)
    return _GLTF_CACHE[key]


class TrialSource(Protocol):
    """What :func:`build_trial_scene` reads from a trial (``studyapp.study.stimuli.TrialMedia`` is one).

    ``motions``, ``name_maps`` and (when a tuple) ``avatar`` are in slot order, left to right; the media
    are already fitted to the trial's timeline, which lasts ``duration_s``.
    """

    # read-only properties, so a dataclass whose fields are narrower (``avatar: str``) still conforms
    @property
    def motions(self) -> Sequence["Motion"]: ...
    @property
    def face(self) -> "FaceAnimation | None": ...
    @property
    def name_maps(self) -> Sequence[Mapping[str, str]]: ...
    @property
    def avatar(self) -> str | Sequence[str]: ...
    @property
    def labels(self) -> tuple[str, ...] | None: ...
    @property
    def duration_s(self) -> float: ...
    @property
    def avatar_bone_map(self) -> Mapping[str, str] | None: ...


@runtime_checkable
class SlotFaces(Protocol):
    """A :class:`TrialSource` whose slots may show their own faces (``TrialMedia``: an SMPL-X file's jaw)."""

    @property
    def slot_faces(self) -> Sequence["FaceAnimation | None"]: ...


class AvatarUploader(Protocol):
    """A renderer that can put an avatar on the GPU ahead of the first frame."""

    def upload_avatar(self, avatar: Avatar) -> object: ...


class SlotError(InputError):
    """One slot's motion cannot be shown on its avatar; ``slot`` is its index (0 = left)."""

    def __init__(self, slot: int, path: str | Path | None, where: str | None, problem: str) -> None:
        self.slot = slot
        super().__init__(path, where, problem)


def slot_avatars(spec: str | Sequence[str] | None, n_slots: int,
                 bone_map: Mapping[str, str] | None = None) -> tuple[Avatar, ...]:
    """One avatar per slot from one spec (all slots) or one spec per slot; the same file gives the same object,
    so slots that share an avatar share its GPU buffers. ``bone_map``: the design's ``[avatar.bone_map]``."""
    specs = [spec] * n_slots if spec is None or isinstance(spec, (str, Path)) else list(spec)
    if len(specs) != n_slots:
        raise ValueError(f"{len(specs)} avatars for {n_slots} slots")
    loaded: dict[str, Avatar] = {}
    out = []
    for sp in specs:
        key = "builtin" if sp is None or str(sp).lower() in ("", "builtin", "default") else str(sp)
        if key not in loaded:
            loaded[key] = load_avatar(None if key == "builtin" else key, bone_map=dict(bone_map or {}) or None)
        out.append(loaded[key])
    return tuple(out)


def build_trial_scene(renderer: AvatarUploader | None, media: TrialSource,
                      labels: tuple[str, ...] | None = None) -> TrialScene:
    """The scene for a study trial: up to :data:`MAX_SLOTS` slots, left to right, lasting the trial's ``duration_s``.

    Each slot is retargeted with its own condition's name map onto its own avatar. A slot that cannot be
    built raises :class:`SlotError` naming the slot and the motion file. When given a renderer (anything
    with ``upload_avatar``), the avatars are uploaded now, so the first frame does not stall; a bare
    context or None is accepted too (``validate`` builds scenes with no GL at all).
    """
    motions = tuple(media.motions)
    avatars = slot_avatars(media.avatar, len(motions), media.avatar_bone_map)
    name_maps = tuple(media.name_maps)
    if len(name_maps) != len(motions):
        raise ValueError(f"{len(name_maps)} name maps for {len(motions)} slots")
    own_faces = tuple(media.slot_faces) if isinstance(media, SlotFaces) else ()
    slots = []
    for i, (motion, avatar, name_map) in enumerate(zip(motions, avatars, name_maps)):
        face = own_faces[i] if i < len(own_faces) and own_faces[i] is not None else media.face
        try:
            slots.append(prepare_slot(avatar, motion, face, name_map=dict(name_map)))
        except InputError as exc:
            raise SlotError(i, motion.source or exc.path, exc.where, exc.problem) from exc
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            # a broken avatar (a singular bind matrix, NaN weights) surfaces here as a numeric error
            raise SlotError(i, motion.source or None, "avatar", f"{type(exc).__name__}: {exc}") from exc
    if labels is None:
        labels = media.labels
    scene = make_scene(slots, avatars, labels=labels, duration=media.duration_s,
                       framing=getattr(media, "framing", None) or DEFAULT_FRAMING)
    if renderer is not None and hasattr(renderer, "upload_avatar"):
        for avatar in {id(a): a for a in avatars}.values():
            renderer.upload_avatar(avatar)
    return scene
