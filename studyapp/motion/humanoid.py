"""The humanoid bone set (Unity Mecanim names) and built-in name maps from common rigs to it.

Retargeting by name (as Unity's Mecanim did for the published study) maps each rig's joints onto
one shared set of humanoid bones. Maps here are ``{rig joint name: humanoid bone}``; joints a rig has
but the humanoid set lacks (BEAT's ``Spine2``, ``Neck1``, finger metacarpals, end joints) are left
out and their rotations get composed into the next mapped bone by :mod:`studyapp.motion.retarget`.

A map may name one bone for several joints of a chain (BEAT ``Neck`` and ``Neck1``); the joint
deepest in the hierarchy gets the bone. Built-in maps: ``"beat"`` (BEAT 75 joints; ZEGGS uses the same
names), ``"mixamo"`` (``mixamorig:`` prefix, any number after it), ``"cmu"`` (CMU converted from ASF, and
the Xia/PFNN rig), ``"daz"`` (CMU as Daz/MotionBuilder export it: ``lShldr``, ``lThigh``), ``"lafan1"``,
``"bandai"`` (``UpperArm_L``), ``"smpl"`` (SMPL, SMPL-H and SMPL-X joint names), ``"vrm0"``
(``J_Bip_C_Hips`` node names of VRoid/VRM 0.x models), ``"vrm1"`` (VRM 1.0 humanoid names such as
``hips``, ``upperChest``, ``leftUpperArm``; the thumb is Metacarpal/Proximal/Distal there) and
``"unity"`` (the humanoid names themselves). Names match case-insensitively.

>>> BUILTIN_MAPS["mixamo"]["mixamorig:LeftForeArm"]
'LeftLowerArm'
>>> len(REQUIRED_BONES), "Hips" in HUMANOID_BONES
(15, True)
"""
from __future__ import annotations

__all__ = [
    "HUMANOID_BONES",
    "HUMANOID_PARENT",
    "REQUIRED_BONES",
    "FINGERS",
    "BUILTIN_MAPS",
    "BEAT_MAP",
    "MIXAMO_MAP",
    "VRM0_MAP",
    "VRM1_MAP",
    "UNITY_MAP",
    "BANDAI_MAP",
    "CMU_MAP",
    "DAZ_MAP",
    "LAFAN1_MAP",
    "SMPL_MAP",
]

FINGERS: tuple[str, ...] = ("Thumb", "Index", "Middle", "Ring", "Little")
_PHALANGES = ("Proximal", "Intermediate", "Distal")
_SIDES = ("Left", "Right")


def _build_parents() -> dict[str, str | None]:
    parent: dict[str, str | None] = {
        "Hips": None,
        "Spine": "Hips",
        "Chest": "Spine",
        "UpperChest": "Chest",
        "Neck": "UpperChest",
        "Head": "Neck",
        "Jaw": "Head",
        "LeftEye": "Head",
        "RightEye": "Head",
    }
    for s in _SIDES:
        parent.update({
            f"{s}Shoulder": "UpperChest",
            f"{s}UpperArm": f"{s}Shoulder",
            f"{s}LowerArm": f"{s}UpperArm",
            f"{s}Hand": f"{s}LowerArm",
        })
        for f in FINGERS:
            prev = f"{s}Hand"
            for ph in _PHALANGES:
                parent[f"{s}{f}{ph}"] = prev
                prev = f"{s}{f}{ph}"
    for s in _SIDES:
        parent.update({
            f"{s}UpperLeg": "Hips",
            f"{s}LowerLeg": f"{s}UpperLeg",
            f"{s}Foot": f"{s}LowerLeg",
            f"{s}Toes": f"{s}Foot",
        })
    return parent


#: Humanoid bone -> its parent bone in the full humanoid hierarchy (``None`` for Hips). Optional
#: bones (Chest, UpperChest, Neck, shoulders, toes, fingers, eyes, jaw) may be absent from a rig;
#: then a bone's effective parent is its nearest present ancestor.
HUMANOID_PARENT: dict[str, str | None] = _build_parents()

#: All humanoid bone names, parents before children.
HUMANOID_BONES: tuple[str, ...] = tuple(HUMANOID_PARENT)

#: The bones every rig must map (Unity's required humanoid bones).
REQUIRED_BONES: tuple[str, ...] = (
    "Hips", "Spine", "Head",
    "LeftUpperArm", "LeftLowerArm", "LeftHand",
    "RightUpperArm", "RightLowerArm", "RightHand",
    "LeftUpperLeg", "LeftLowerLeg", "LeftFoot",
    "RightUpperLeg", "RightLowerLeg", "RightFoot",
)


def _mixamo_style_limbs() -> dict[str, str]:
    """Limb and finger names BEAT shares with Mixamo (``LeftForeArm``, ``LeftHandPinky1``, ...)."""
    finger = {"Thumb": "Thumb", "Index": "Index", "Middle": "Middle", "Ring": "Ring", "Little": "Pinky"}
    m: dict[str, str] = {}
    for s in _SIDES:
        m.update({
            f"{s}Shoulder": f"{s}Shoulder",
            f"{s}Arm": f"{s}UpperArm",
            f"{s}ForeArm": f"{s}LowerArm",
            f"{s}Hand": f"{s}Hand",
            f"{s}UpLeg": f"{s}UpperLeg",
            f"{s}Leg": f"{s}LowerLeg",
            f"{s}Foot": f"{s}Foot",
            f"{s}ToeBase": f"{s}Toes",
        })
        for f, src in finger.items():
            for k, ph in enumerate(_PHALANGES, start=1):
                m[f"{s}Hand{src}{k}"] = f"{s}{f}{ph}"
    return m


def _beat_map() -> dict[str, str]:
    m = {
        "Hips": "Hips",
        "Spine": "Spine",
        "Spine1": "Chest",
        # Spine2 has no humanoid counterpart: its rotation is composed into UpperChest
        "Spine3": "UpperChest",
        # Neck and Neck1 both name the humanoid Neck: where a rig has both, the upper one (Neck1)
        # takes the bone and the lower one's rotation is composed into it
        "Neck": "Neck",
        "Neck1": "Neck",
        "Head": "Head",
    }
    m.update(_mixamo_style_limbs())
    return m


def _mixamo_map() -> dict[str, str]:
    m = {
        "Hips": "Hips", "Spine": "Spine", "Spine1": "Chest", "Spine2": "UpperChest",
        "Neck": "Neck", "Head": "Head",
    }
    m.update(_mixamo_style_limbs())
    return {f"mixamorig:{k}": v for k, v in m.items()}


def _vrm0_map() -> dict[str, str]:
    m = {
        "J_Bip_C_Hips": "Hips", "J_Bip_C_Spine": "Spine", "J_Bip_C_Chest": "Chest",
        "J_Bip_C_UpperChest": "UpperChest", "J_Bip_C_Neck": "Neck", "J_Bip_C_Head": "Head",
        "J_Adj_L_FaceEye": "LeftEye", "J_Adj_R_FaceEye": "RightEye",
    }
    for s, c in (("Left", "L"), ("Right", "R")):
        m.update({
            f"J_Bip_{c}_Shoulder": f"{s}Shoulder",
            f"J_Bip_{c}_UpperArm": f"{s}UpperArm",
            f"J_Bip_{c}_LowerArm": f"{s}LowerArm",
            f"J_Bip_{c}_Hand": f"{s}Hand",
            f"J_Bip_{c}_UpperLeg": f"{s}UpperLeg",
            f"J_Bip_{c}_LowerLeg": f"{s}LowerLeg",
            f"J_Bip_{c}_Foot": f"{s}Foot",
            f"J_Bip_{c}_ToeBase": f"{s}Toes",
        })
        for f in FINGERS:
            for k, ph in enumerate(_PHALANGES, start=1):
                m[f"J_Bip_{c}_{f}{k}"] = f"{s}{f}{ph}"
    return m


def _camel(bone: str) -> str:
    return bone[0].lower() + bone[1:]


def _vrm1_map() -> dict[str, str]:
    m = {}
    for bone in HUMANOID_BONES:
        if "Thumb" in bone:
            continue
        m[_camel(bone)] = bone
    for s in _SIDES:
        # VRM 1.0 names the thumb from the wrist: Metacarpal, Proximal, Distal
        for vrm, ph in zip(("Metacarpal", "Proximal", "Distal"), _PHALANGES):
            m[f"{_camel(s)}Thumb{vrm}"] = f"{s}Thumb{ph}"
    return m


def _bandai_map() -> dict[str, str]:
    """Bandai-Namco Research Motiondataset: ``UpperArm_L``, ``Hand_L``, ..., under a ``joint_Root``."""
    m = {"Hips": "Hips", "Spine": "Spine", "Chest": "Chest", "Neck": "Neck", "Head": "Head"}
    for s, c in (("Left", "L"), ("Right", "R")):
        for part in ("Shoulder", "UpperArm", "LowerArm", "Hand", "UpperLeg", "LowerLeg", "Foot", "Toes"):
            m[f"{part}_{c}"] = f"{s}{part}"
    return m


def _cmu_map() -> dict[str, str]:
    """CMU mocap as converted from ASF (and the Xia/PFNN rig built on it): ``LowerBack``, ``LHipJoint``, ..."""
    m = {"Hips": "Hips", "LowerBack": "Spine", "Spine": "Chest", "Spine1": "UpperChest",
         "Neck": "Neck", "Neck1": "Neck", "Head": "Head"}
    m.update(_mixamo_style_limbs())
    for s, c in (("Left", "L"), ("Right", "R")):
        m[f"{c}Thumb"] = f"{s}ThumbProximal"
    return m


def _daz_map() -> dict[str, str]:
    """CMU as exported by Daz / MotionBuilder: ``hip``, ``abdomen``, ``chest``, ``lShldr``, ``lThigh``, ..."""
    m = {"hip": "Hips", "abdomen": "Spine", "abdomen2": "Chest", "chest": "UpperChest", "neck": "Neck",
         "neck1": "Neck", "head": "Head", "pelvis": "Hips"}
    fingers = {"Thumb": "Thumb", "Index": "Index", "Mid": "Middle", "Ring": "Ring", "Pinky": "Little"}
    for s, c in (("Left", "l"), ("Right", "r")):
        m.update({f"{c}Collar": f"{s}Shoulder", f"{c}Shldr": f"{s}UpperArm", f"{c}ShldrBend": f"{s}UpperArm",
                  f"{c}ForeArm": f"{s}LowerArm", f"{c}ForearmBend": f"{s}LowerArm", f"{c}Hand": f"{s}Hand",
                  f"{c}Thigh": f"{s}UpperLeg", f"{c}ThighBend": f"{s}UpperLeg", f"{c}Shin": f"{s}LowerLeg",
                  f"{c}Foot": f"{s}Foot", f"{c}Toe": f"{s}Toes"})
        for src, f in fingers.items():
            for k, ph in enumerate(_PHALANGES, start=1):
                m[f"{c}{src}{k}"] = f"{s}{f}{ph}"
    return m


def _lafan1_map() -> dict[str, str]:
    """Ubisoft LAFAN1: Mixamo-like limbs without prefix, ``Spine``..``Spine2``, ``LeftToe``."""
    m = {"Hips": "Hips", "Spine": "Spine", "Spine1": "Chest", "Spine2": "UpperChest", "Neck": "Neck",
         "Head": "Head"}
    m.update(_mixamo_style_limbs())
    for s in _SIDES:
        m[f"{s}Toe"] = f"{s}Toes"
    return m


def _smpl_map() -> dict[str, str]:
    """SMPL / SMPL-H / SMPL-X joint names (``pelvis``, ``left_hip``, ``left_index1``, ...)."""
    m = {"pelvis": "Hips", "spine1": "Spine", "spine2": "Chest", "spine3": "UpperChest", "neck": "Neck",
         "head": "Head", "jaw": "Jaw"}
    fingers = {"thumb": "Thumb", "index": "Index", "middle": "Middle", "ring": "Ring", "pinky": "Little"}
    for s, c in (("Left", "left"), ("Right", "right")):
        m.update({f"{c}_collar": f"{s}Shoulder", f"{c}_shoulder": f"{s}UpperArm", f"{c}_elbow": f"{s}LowerArm",
                  f"{c}_wrist": f"{s}Hand", f"{c}_hip": f"{s}UpperLeg", f"{c}_knee": f"{s}LowerLeg",
                  f"{c}_ankle": f"{s}Foot", f"{c}_foot": f"{s}Toes", f"{c}_eye": f"{s}Eye",
                  f"{c}_eye_smplhf": f"{s}Eye"})
        for src, f in fingers.items():
            for k, ph in enumerate(_PHALANGES, start=1):
                m[f"{c}_{src}{k}"] = f"{s}{f}{ph}"
    return m


BEAT_MAP: dict[str, str] = _beat_map()
BANDAI_MAP: dict[str, str] = _bandai_map()
CMU_MAP: dict[str, str] = _cmu_map()
DAZ_MAP: dict[str, str] = _daz_map()
LAFAN1_MAP: dict[str, str] = _lafan1_map()
SMPL_MAP: dict[str, str] = _smpl_map()
MIXAMO_MAP: dict[str, str] = _mixamo_map()
VRM0_MAP: dict[str, str] = _vrm0_map()
VRM1_MAP: dict[str, str] = _vrm1_map()
UNITY_MAP: dict[str, str] = {b: b for b in HUMANOID_BONES}

#: Name -> built-in map, in the order :func:`~studyapp.motion.retarget.detect_name_map` prefers on ties.
BUILTIN_MAPS: dict[str, dict[str, str]] = {
    "unity": UNITY_MAP,
    "beat": BEAT_MAP,
    "mixamo": MIXAMO_MAP,
    "vrm0": VRM0_MAP,
    "vrm1": VRM1_MAP,
    "cmu": CMU_MAP,
    "lafan1": LAFAN1_MAP,
    "bandai": BANDAI_MAP,
    "daz": DAZ_MAP,
    "smpl": SMPL_MAP,
}
