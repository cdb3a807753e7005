"""The 52 ARKit blendshapes and a forgiving matcher for the names rigs and exporters give them.

Three orderings of the same 52 (or 51) shapes exist in the wild: Apple's (``ARFaceAnchor.BlendShapeLocation``
as Apple documents it, grouped eyes / mouth and jaw / brows, cheeks and nose / tongue), Live Link Face's CSV
columns (jaw and mouth left/right swapped) and BEAT's alphabetical 51 without ``tongueOut``. studyapp stores
weights in Apple's order and maps every source by name, never by position.

>>> len(ARKIT_NAMES), ARKIT_NAMES[0], ARKIT_NAMES[-1]
(52, 'eyeBlinkLeft', 'tongueOut')
>>> match_arkit_name("AK_17_JawOpen"), match_arkit_name("blendShape1.mouthSmile_L")
('jawOpen', 'mouthSmileLeft')
>>> match_arkit_name("HeadYaw") is None
True
"""
from __future__ import annotations

import re

#: The 52 ARKit blendshape names in the order Apple documents ``ARFaceAnchor.BlendShapeLocation``.
ARKIT_NAMES: tuple[str, ...] = (
    # Left eye
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft",
    "eyeSquintLeft", "eyeWideLeft",
    # Right eye
    "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight",
    "eyeSquintRight", "eyeWideRight",
    # Mouth and jaw
    "jawForward", "jawLeft", "jawRight", "jawOpen",
    "mouthClose", "mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight",
    "mouthSmileLeft", "mouthSmileRight", "mouthFrownLeft", "mouthFrownRight",
    "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft", "mouthStretchRight",
    "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight",
    "mouthUpperUpLeft", "mouthUpperUpRight",
    # Eyebrows, cheeks and nose
    "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight",
    "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft", "noseSneerRight",
    # Tongue
    "tongueOut",
)

#: Lower-case name -> index in :data:`ARKIT_NAMES`.
ARKIT_INDEX: dict[str, int] = {name.lower(): i for i, name in enumerate(ARKIT_NAMES)}

N_ARKIT = len(ARKIT_NAMES)

# Decorations seen in rigs and exports, tried on the lower-cased, separator-free key:
# "ak17jawopen" (AK_17_JawOpen), "arkitjawopen", "bsjawopen", "blendshapejawopen", "17jawopen",
# "a25jawopen" (Character Creator 4's A01..A52 ARKit set). MetaHuman's CTRL_expressions_* curves are
# controls with their own semantics, not ARKit shapes, and stay unmatched.
_PREFIX = re.compile(r"^(?:(?:ak|arkit|bs|blendshapes?|shapes?|morph|target|face|facial)\d*|a\d\d|\d+)")
_SUFFIX = re.compile(r"(?:(?:bs|blendshapes?|shape|morph|target)\d*|\d+)$")
_SEPARATORS = re.compile(r"[\s_\-]+")
_NAMESPACE = re.compile(r"[.|:/\\]")


def _candidates(key: str):
    """Yield the key with decorations peeled off one layer at a time (prefixes, then suffixes)."""
    seen = set()
    stack = [key]
    while stack:
        k = stack.pop()
        if not k or k in seen:
            continue
        seen.add(k)
        yield k
        for pattern in (_PREFIX, _SUFFIX):
            stripped = pattern.sub("", k, count=1)
            if stripped != k:
                stack.append(stripped)


def match_arkit_name(name: str) -> str | None:
    """The canonical ARKit name a rig or export means by ``name``, or ``None`` if it is not one.

    Matching is case-insensitive and tolerant of the decorations pipelines add: Maya node paths
    (``blendShape1.jawOpen``), namespaces (``face:jawOpen``), numbered prefixes (``AK_01_EyeBlinkLeft``),
    ``ARKit_`` / ``bs_`` prefixes, Blender duplicate suffixes (``jawOpen.001``), Live Link PascalCase,
    ``_L`` / ``_R`` side suffixes and Character Creator 4's numbered set (``A01_Brow_Inner_Up``). Names that
    could mean either side (``Eye_Blink``) or are not ARKit (VRoid's ``Fcl_EYE_Close``) give ``None``.

    >>> match_arkit_name("EyeBlinkLeft"), match_arkit_name("ARKit_tongue_out"), match_arkit_name("jaw")
    ('eyeBlinkLeft', 'tongueOut', None)
    >>> match_arkit_name("A38_Mouth_Smile_Left"), match_arkit_name("Eye_Blink"), match_arkit_name("Fcl_EYE_Close")
    ('mouthSmileLeft', None, None)
    """
    if not isinstance(name, str):
        return None
    parts = [p for p in _NAMESPACE.split(name.strip()) if p.strip() and not p.strip().isdigit()]
    if not parts:
        return None
    key = _SEPARATORS.sub("", parts[-1]).lower()
    for cand in _candidates(key):
        idx = ARKIT_INDEX.get(cand)
        if idx is None and cand[-1:] in ("l", "r"):
            # Side suffix shorthand: "mouthsmilel" -> "mouthsmileleft"; only accepted when it names a shape.
            idx = ARKIT_INDEX.get(cand[:-1] + ("left" if cand[-1] == "l" else "right"))
        if idx is not None:
            return ARKIT_NAMES[idx]
    return None
