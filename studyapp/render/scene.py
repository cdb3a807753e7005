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

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from studyapp.errors import InputError
from studyapp.render.avatar import Avatar, build_default_avatar
from studyapp.render.camera import Camera, fit_camera
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
        The one camera every slot uses (see :func:`studyapp.render.camera.fit_camera`).
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
               aspect: float | None = None) -> TrialScene:
    """A scene from prepared slots; one avatar object for all slots (shared GPU buffers) or one per slot."""
    slots = tuple(slots)
    avatars = tuple(avatar) if isinstance(avatar, (tuple, list)) else (avatar,) * len(slots)
    if aspect is None:
        aspect = THREE_SLOT_ASPECT if len(slots) == 3 else (1280 / len(slots)) / 720
    camera = frame_camera(slots, avatars[0], aspect, top_reserve=LABEL_SPACE if labels else 0.0)
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
    scene = make_scene(slots, avatar, labels=labels)
    if hasattr(ctx_or_renderer, "upload_avatar"):
        ctx_or_renderer.upload_avatar(avatar)
    return scene
