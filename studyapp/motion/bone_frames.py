"""Anatomical frames of humanoid bones: what "the same pose" means on two rigs, twist included.

Copying a bone's world rotation from one rig to another is only right when both rigs agree on what the
bone's zero rotation looks like. Rigs do not: BEAT and Mixamo files stand in a T-pose at zero, while the
zero pose of Bandai-Namco and LAFAN1 files is a heap of bones along +X (every joint's local axes at
identity), and their animation carries the difference, twist about each bone included. A correction
that only lines up bone directions leaves that twist in: the chest and head of a Bandai-Namco clip then
face 90 degrees away from the legs while every joint position looks right.

So each mapped bone gets an *anatomical frame* on each rig, built from two directions that mean the same
thing on every human body, and expressed in the bone's own local axes (where it is constant):

=========================  ======================================  ==========================================
bones                      primary axis                            secondary axis (sets the twist)
=========================  ======================================  ==========================================
Hips, Spine .. Neck, Head  up the spine (to the next spine bone;   the body's left: hips -> upper legs;
                           Head: on from the neck)                 chest and above -> upper arms; Spine: both
Shoulder                   to the upper arm                        the body's forward
Upper/lower arm and leg    along the limb                          the elbow / knee hinge axis
Hand                       to the middle finger, else on from the  the finger spread (index - little), else the
                           forearm                                 elbow hinge
Foot, Toes                 to the toes, else on from the shin      the body's left
fingers                    along the finger                        the hand's finger spread, else forward
=========================  ======================================  ==========================================

*Where* the two directions are read depends on the rig's rest pose:

- a rest pose that stands (spine up, as in T- and A-poses and every avatar) is read directly, the hinge of
  a straight limb taken as the anatomical one (elbows bend forward, knees backward) and that of a limb the
  rest pose bends clearly (an avatar modelled with bent elbows and knees) where it bends; where the clip
  bends an upper arm's elbow or a knee clearly, the hinge it shows is used instead (a rig's rest arm can
  be turned 30 degrees about itself, as CMU's is, and the avatar's elbow would then fold askew);
- a rest pose that does not stand, or whose spine stands while its limbs are folded anywhere (not a T- or
  A-pose, :func:`is_standing`), carries no anatomy, so the directions are read from the animation
  itself: at every frame the world-space directions (the body's left at that frame, the elbow's actual
  hinge when bent, ...) are brought into the bone's local axes and averaged over the clip, weighted by
  how well each frame defines them (a straight elbow defines no hinge).

A frame is a rotation matrix whose columns are the primary axis, the secondary axis made orthogonal to
it, and their cross product.

>>> import numpy as np
>>> f = frame_from_axes(np.array([[0.0, 2.0, 0.0]]), np.array([[1.0, 1.0, 0.0]]))
>>> np.round(f[0], 6).tolist()
[[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BoneAxes", "frame_from_axes", "is_standing", "bone_axes", "body_forward", "hinge_evidence"]

_TRUNK = ("Hips", "Spine", "Chest", "UpperChest", "Neck", "Head")
_SIDES = ("Left", "Right")
_FINGERS = ("Thumb", "Index", "Middle", "Ring", "Little")
#: A straight limb (bent less than this) says nothing about its hinge.
_MIN_BEND_SIN = np.sin(np.radians(12.0))


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def frame_from_axes(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` rotations with columns: ``primary``, ``secondary`` made orthogonal to it, their cross.

    A secondary axis parallel to the primary one is replaced by whichever coordinate axis is least
    aligned with the primary, so the result is always a rotation.
    """
    p = _unit(np.asarray(primary, np.float64))
    s = np.asarray(secondary, np.float64)
    s = s - np.sum(s * p, -1, keepdims=True) * p
    bad = np.linalg.norm(s, axis=-1) < 1e-6
    if np.any(bad):
        helper = np.eye(3)[np.argmin(np.abs(p), axis=-1)]
        alt = helper - np.sum(helper * p, -1, keepdims=True) * p
        s = np.where(bad[..., None], alt, s)
    s = _unit(s)
    return np.stack([p, s, np.cross(p, s)], axis=-1)


#: A T/A-pose rest limb is straight to within this (CesiumMan's A-pose elbows bend 29 degrees).
_MAX_REST_BEND_DEG = 40.0


def is_standing(positions: np.ndarray, bone: dict[str, int]) -> bool:
    """Whether a rest pose (``(J, 3)`` world positions) is a standing T- or A-pose whose anatomy can be read.

    Hips to head within 45 degrees of +Y, and every mapped arm and leg as a T/A-pose holds it: elbows and
    knees bent less than 40 degrees, thighs pointing down (within 45 degrees), upper arms out to the side or
    down (less than 45 degrees forward or back, not raised above 45 degrees). A zero pose whose spine
    happens to point up while its limbs are folded anywhere (each joint's local axes turned at will, as in
    Bandai-Namco, LAFAN1 and some Truebones files) carries no more anatomy than a heap of bones does: read
    as standing, its folded elbows gave the avatar's forearms a twist of 70 to 145 degrees.
    """
    up = positions[bone["Head"]] - positions[bone["Hips"]]
    n = np.linalg.norm(up)
    if not (n > 1e-9 and up[1] / n > np.cos(np.radians(45.0))):
        return False
    up = up / n
    left = positions[bone["LeftUpperLeg"]] - positions[bone["RightUpperLeg"]] if {"LeftUpperLeg", "RightUpperLeg"} <= set(bone) else None
    forward = _unit(np.cross(left, up)) if left is not None and np.linalg.norm(np.cross(left, up)) > 1e-9 else None
    max_sin = np.sin(np.radians(45.0))
    for s in _SIDES:
        for top, mid, end, leg in (("UpperArm", "LowerArm", "Hand", False), ("UpperLeg", "LowerLeg", "Foot", True)):
            names = (f"{s}{top}", f"{s}{mid}", f"{s}{end}")
            if not all(x in bone for x in names):
                continue
            a = positions[bone[names[1]]] - positions[bone[names[0]]]
            b = positions[bone[names[2]]] - positions[bone[names[1]]]
            if np.linalg.norm(a) < 1e-9 or np.linalg.norm(b) < 1e-9:
                continue
            a, b = _unit(a), _unit(b)
            if np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))) > _MAX_REST_BEND_DEG:
                return False
            if leg and a @ up > -np.cos(np.radians(45.0)):
                return False
            if not leg and (a @ up > max_sin or (forward is not None and abs(a @ forward) > max_sin)):
                return False
    return True


@dataclass(frozen=True)
class BoneAxes:
    """Per bone, which primary and secondary axis rule applies (the same on both rigs)."""

    primary: dict[str, tuple[str, str]]    # bone -> ("child", other bone) | ("on", parent bone)
    secondary: dict[str, str]              # bone -> "left", "left_legs", "left_arms", "forward", "hinge", "spread"


def _first(candidates: tuple[str, ...], have: set[str]) -> str | None:
    return next((c for c in candidates if c in have), None)


def choose_axes(both: set[str], parent_of: dict[str, str | None]) -> BoneAxes:
    """The axis rules for the bones mapped on both rigs (``parent_of``: nearest mapped humanoid ancestor)."""
    primary: dict[str, tuple[str, str]] = {}
    secondary: dict[str, str] = {}
    spine_chain = [b for b in _TRUNK if b in both]
    for i, b in enumerate(spine_chain):
        if i + 1 < len(spine_chain):
            primary[b] = ("child", spine_chain[i + 1])
        elif parent_of.get(b):
            primary[b] = ("on", parent_of[b])  # Head: on from the neck
        secondary[b] = "left_legs" if b == "Hips" else "left_arms" if b != "Spine" else "left"
    fingers_ok = {s: all(f"{s}{f}Proximal" in both for f in ("Index", "Middle")) and
                  _first((f"{s}LittleProximal", f"{s}RingProximal"), both) is not None for s in _SIDES}
    for s in _SIDES:
        chains = (("Shoulder", "UpperArm"), ("UpperArm", "LowerArm"), ("LowerArm", "Hand"),
                  ("UpperLeg", "LowerLeg"), ("LowerLeg", "Foot"), ("Foot", "Toes"))
        for a, c in chains:
            if f"{s}{a}" in both and f"{s}{c}" in both:
                primary[f"{s}{a}"] = ("child", f"{s}{c}")
        for a in ("Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes"):
            b = f"{s}{a}"
            if b in both and b not in primary and parent_of.get(b):
                primary[b] = ("on", parent_of[b])
        secondary.update({f"{s}Shoulder": "forward", f"{s}UpperArm": "hinge", f"{s}LowerArm": "hinge",
                          f"{s}UpperLeg": "hinge", f"{s}LowerLeg": "hinge", f"{s}Foot": "left_legs",
                          f"{s}Toes": "left_legs"})
        if fingers_ok[s]:
            primary[f"{s}Hand"] = ("child", f"{s}MiddleProximal")
            secondary[f"{s}Hand"] = "spread"
        else:
            secondary[f"{s}Hand"] = "hinge"
        for f in _FINGERS:
            chain = [f"{s}{f}{ph}" for ph in ("Proximal", "Intermediate", "Distal")]
            chain = [c for c in chain if c in both]
            for i, b in enumerate(chain):
                primary[b] = ("child", chain[i + 1]) if i + 1 < len(chain) else ("on", parent_of.get(b) or f"{s}Hand")
                secondary[b] = "spread" if fingers_ok[s] else "forward"
    primary = {b: p for b, p in primary.items() if b in both and p[1] in both}
    return BoneAxes(primary=primary, secondary={b: v for b, v in secondary.items() if b in primary})


def _left_vectors(pos: np.ndarray, bone: dict[str, int]) -> dict[str, np.ndarray]:
    """``(F, 3)`` directions of the body's left, from the legs and from the arms (each falls back on the other)."""
    def across(part: str) -> np.ndarray | None:
        if f"Left{part}" in bone and f"Right{part}" in bone:
            return _unit(pos[:, bone[f"Left{part}"]] - pos[:, bone[f"Right{part}"]])
        return None

    legs = across("UpperLeg")
    arms = across("UpperArm")
    if legs is None:
        legs = arms
    if arms is None:
        arms = legs
    if legs is None:
        legs = arms = np.broadcast_to([1.0, 0.0, 0.0], pos[:, 0].shape)
    return {"left_legs": legs, "left_arms": arms, "left": _unit(legs + arms)}


def body_forward(pos: np.ndarray, bone: dict[str, int]) -> np.ndarray:
    """``(F, 3)`` the body's forward at each frame: the body's left crossed with hips-to-head (up)."""
    left = _left_vectors(pos, bone)["left"]
    up = _unit(pos[:, bone["Head"]] - pos[:, bone["Hips"]])
    return _unit(np.cross(left, up))


def _parent_in(b: str, axes: BoneAxes) -> str | None:
    rule, other = axes.primary[b]
    return other if rule == "on" else next((p for p, (r, c) in axes.primary.items() if r == "child" and c == b), None)


def _hinge(pos: np.ndarray, bone: dict[str, int], b: str) -> tuple[np.ndarray, np.ndarray] | None:
    """World hinge axis ``(F, 3)`` of the elbow or knee a bone belongs to, and its weight ``(F,)``."""
    side = "Left" if b.startswith("Left") else "Right"
    chain = ((f"{side}UpperArm", f"{side}LowerArm", f"{side}Hand") if ("Arm" in b or "Hand" in b)
             else (f"{side}UpperLeg", f"{side}LowerLeg", f"{side}Foot"))
    if not all(c in bone for c in chain):
        return None
    upper = _unit(pos[:, bone[chain[1]]] - pos[:, bone[chain[0]]])
    lower = _unit(pos[:, bone[chain[2]]] - pos[:, bone[chain[1]]])
    c = np.cross(upper, lower)
    s = np.linalg.norm(c, axis=-1)
    return _unit(c), np.clip(s - _MIN_BEND_SIN, 0.0, None)


def hinge_evidence(positions: np.ndarray, bone: dict[str, int], b: str) -> float:
    """How well a clip (``(F, J, 3)`` positions) shows the hinge of the elbow or knee of bone ``b``: the
    fraction of frames' worth of clear bending (0 when the limb never bends past 12 degrees)."""
    got = _hinge(positions, bone, b)
    return 0.0 if got is None else float(got[1].sum() / max(len(positions), 1))


def _rest_hinge(pos: np.ndarray, bone: dict[str, int], b: str, forward: np.ndarray) -> np.ndarray:
    """The hinge a standing rest pose implies: elbows bend forward, knees backward; a limb the rest pose
    itself bends clearly (RobotExpressive's elbows 31-57 degrees, its knees 41) the way it can bend hinges
    where it bends, as its mesh was modelled."""
    side = "Left" if b.startswith("Left") else "Right"
    arm = "Arm" in b or "Hand" in b
    top, mid, end = ((f"{side}UpperArm", f"{side}LowerArm", f"{side}Hand") if arm
                     else (f"{side}UpperLeg", f"{side}LowerLeg", f"{side}Foot"))
    upper = _unit(pos[:, bone[mid]] - pos[:, bone[top]]) if top in bone and mid in bone else forward
    assumed = _unit(np.cross(upper, forward if arm else -forward))
    got = _hinge(pos, bone, b)
    if got is None:
        return assumed
    seen, weight = got
    use = (weight > 0)[:, None] & (np.sum(seen * assumed, -1, keepdims=True) > 0)
    return np.where(use, seen, assumed)


def bone_axes(rotations: np.ndarray, positions: np.ndarray, bone: dict[str, int], axes: BoneAxes,
              from_motion: bool, head_top: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Each bone's anatomical frame in its own local axes: ``{bone: (3, 3)}``.

    ``rotations`` ``(F, J, 3, 3)`` and ``positions`` ``(F, J, 3)`` are world transforms: one frame of a
    standing rest pose (``from_motion=False``), or every frame of an animation whose rig does not stand
    at rest (``from_motion=True``: world directions averaged in local axes, see the module text).
    ``head_top`` ``(F, 3)``, a point the head carries above it (a ``HeadEnd`` joint, a BVH End Site),
    gives the head's own up axis where the rest pose cannot: averaging the neck's direction instead
    would take the clip's mean nod for upright.
    """
    left = _left_vectors(positions, bone)
    forward = body_forward(positions, bone)
    out: dict[str, np.ndarray] = {}
    world_primary: dict[str, np.ndarray] = {}
    scale = float(np.ptp(positions[0], axis=0).max()) or 1.0
    for b, (rule, other) in axes.primary.items():  # parents before children (humanoid order)
        j = bone[b]
        prim = positions[:, bone[other]] - positions[:, j] if rule == "child" else positions[:, j] - positions[:, bone[other]]
        if np.linalg.norm(prim, axis=-1).mean() < 1e-6 * scale:
            # a zero-length bone (CMU's LowerBack sits on the hips, a thumb on its wrist): use the spine's
            # overall direction, or carry on the parent bone's
            if b in _TRUNK:
                prim = positions[:, bone["Head"]] - positions[:, bone["Hips"]]
            else:
                prim = world_primary.get(_parent_in(b, axes), prim)
        if b == "Head" and from_motion and head_top is not None:
            prim = head_top - positions[:, j]
        world_primary[b] = prim
        kind = axes.secondary[b]
        weight = np.ones(len(positions))
        if kind in left:
            sec = left[kind]
        elif kind == "forward":
            sec = forward
        elif kind == "spread":
            side = "Left" if b.startswith("Left") else "Right"
            little = f"{side}LittleProximal" if f"{side}LittleProximal" in bone else f"{side}RingProximal"
            sec = positions[:, bone[f"{side}IndexProximal"]] - positions[:, bone[little]]
        else:  # hinge
            if from_motion:
                got = _hinge(positions, bone, b)
                sec, weight = got if got is not None else (forward, weight)
                if weight.sum() < 1e-3:  # the limb never bends in this clip
                    sec, weight = _rest_hinge(positions, bone, b, forward), np.ones(len(positions))
            else:
                sec = _rest_hinge(positions, bone, b, forward)
        rot_t = np.swapaxes(rotations[:, j], -1, -2)  # world -> the bone's local axes
        p_local = np.einsum("fij,fj->fi", rot_t, _unit(prim))
        s_local = np.einsum("fij,fj->fi", rot_t, _unit(sec))
        p_mean = p_local.mean(axis=0)
        s_mean = (s_local * weight[:, None]).sum(axis=0)
        out[b] = frame_from_axes(p_mean, s_mean)
    return out
