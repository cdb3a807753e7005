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

from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Mapping, Protocol, Sequence

import numpy as np

from studyapp.errors import InputError
from studyapp.render.avatar import Avatar, build_default_avatar
from studyapp.render.camera import Camera, fit_camera
from studyapp.render.pose import SlotAnimation, prepare_slot

if TYPE_CHECKING:
    from studyapp.face.animation import FaceAnimation
    from studyapp.motion.skeleton import Motion

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
        The one camera every slot uses (see :func:`studyapp.render.camera.fit_camera`).
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
        if not 1 <= len(self.slots) <= 3:
            raise ValueError(f"a trial shows 1 to 3 slots, got {len(self.slots)}")
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


def frame_camera(slots: list[SlotAnimation] | tuple[SlotAnimation, ...], avatar: Avatar, aspect: float,
                 top_reserve: float = 0.0) -> Camera:
    """The shared camera for these slots: fitted to every joint of every slot over the whole clip.

    Joint positions are padded with the avatar's reach beyond its joints (head top, fingertips) so the
    fitted box holds the surface, not just the skeleton.
    """
    # legs are left out: the framing is the upper body (head, arms, hands) down to the hips
    sk = avatar.skeleton
    upper = [j for j, n in enumerate(sk.names) if not any(k in n for k in ("Leg", "Foot", "Toes", "Knee", "Ankle"))]
    pts = np.concatenate([s.joint_positions[:, upper].reshape(-1, 3) for s in slots])
    lo, hi = avatar.bounds()
    rest_top = float(hi[1])
    jp_rest_top = float(np.max(slots[0].joint_positions[0, :, 1])) if slots[0].n_frames else rest_top
    pad_top = max(0.0, rest_top - jp_rest_top)
    # the head top and the fingertips stick out beyond the joints
    extra = pts.copy()
    extra[:, 1] += pad_top
    return fit_camera(np.concatenate([pts, extra]), aspect, top_reserve=top_reserve)


def make_scene(slots, avatar: Avatar | tuple[Avatar, ...], labels: tuple[str, ...] | None = None,
               aspect: float | None = None, duration: float | None = None) -> TrialScene:
    """A scene from prepared slots; one avatar object for all slots (shared GPU buffers) or one per slot.

    ``duration``: how long the scene plays. A study trial passes its timeline's length; without one (a
    single file in ``view``, the environment check) the scene lasts as long as its longest slot.
    """
    slots = tuple(slots)
    avatars = tuple(avatar) if isinstance(avatar, (tuple, list)) else (avatar,) * len(slots)
    if aspect is None:
        aspect = THREE_SLOT_ASPECT if len(slots) == 3 else (1280 / len(slots)) / 720
    camera = frame_camera(slots, avatars[0], aspect, top_reserve=LABEL_SPACE if labels else 0.0)
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
    from studyapp.render.avatar_rig import BONE_MAP_FIX, bone_map_problems, missing_bones, not_humanoid_message

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
    """The scene for a study trial: up to three slots, left to right, lasting the trial's ``duration_s``.

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
    slots = []
    for i, (motion, avatar, name_map) in enumerate(zip(motions, avatars, name_maps)):
        try:
            slots.append(prepare_slot(avatar, motion, media.face, name_map=dict(name_map)))
        except InputError as exc:
            raise SlotError(i, motion.source or exc.path, exc.where, exc.problem) from exc
        except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
            # a broken avatar (a singular bind matrix, NaN weights) surfaces here as a numeric error
            raise SlotError(i, motion.source or None, "avatar", f"{type(exc).__name__}: {exc}") from exc
    if labels is None:
        labels = media.labels
    scene = make_scene(slots, avatars, labels=labels, duration=media.duration_s)
    if renderer is not None and hasattr(renderer, "upload_avatar"):
        for avatar in {id(a): a for a in avatars}.values():
            renderer.upload_avatar(avatar)
    return scene
