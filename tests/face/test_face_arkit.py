"""ARKit names: Apple's order, the index, and the name matcher against names seen in real files."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from studyapp.face.arkit import ARKIT_INDEX, ARKIT_NAMES, match_arkit_name

# The shared real-world samples sit beside the checkout (../shared/samples).
SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"  # copies of ../shared/samples (see its README)


def test_52_unique_names_in_apple_order() -> None:
    assert len(ARKIT_NAMES) == 52 == len(set(ARKIT_NAMES))
    # Apple groups the list: left eye (7), right eye (7), mouth and jaw (27), brows/cheeks/nose (10), tongue.
    assert ARKIT_NAMES[:7] == ("eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft",
                               "eyeLookUpLeft", "eyeSquintLeft", "eyeWideLeft")
    assert ARKIT_NAMES[14:18] == ("jawForward", "jawLeft", "jawRight", "jawOpen")
    assert ARKIT_NAMES[21:23] == ("mouthLeft", "mouthRight")
    assert ARKIT_NAMES[41] == "browDownLeft" and ARKIT_NAMES[46] == "cheekPuff"
    assert ARKIT_NAMES[-1] == "tongueOut"
    assert all(ARKIT_INDEX[n.lower()] == i for i, n in enumerate(ARKIT_NAMES))


def test_live_link_and_beat_names_all_match() -> None:
    header = next(csv.reader(open(SAMPLES / "livelinkface_S07-001_excerpt.csv")))
    shapes = header[2:54]
    assert [match_arkit_name(h) for h in shapes] == [
        next(n for n in ARKIT_NAMES if n.lower() == h.lower()) for h in shapes
    ]
    assert sorted(match_arkit_name(h) for h in shapes) == sorted(ARKIT_NAMES)
    for other in header[:2] + header[54:]:  # Timecode, BlendShapeCount, head and eye angles
        assert match_arkit_name(other) is None, other
    beat = json.loads((SAMPLES / "beat_face51_diffsheg_gt_excerpt.json").read_text())["names"]
    assert {match_arkit_name(n) for n in beat} == set(ARKIT_NAMES) - {"tongueOut"}


@pytest.mark.parametrize("raw, expected", [
    ("AK_01_EyeBlinkLeft", "eyeBlinkLeft"),
    ("AK_52_TongueOut", "tongueOut"),
    ("blendShape1.jawOpen", "jawOpen"),
    ("blendShape12.mouthSmile_L", "mouthSmileLeft"),
    ("ARKit_browInnerUp", "browInnerUp"),
    ("bs_cheekPuff", "cheekPuff"),
    ("BS_NoseSneerRight", "noseSneerRight"),
    ("JawOpen", "jawOpen"),
    ("jawopen", "jawOpen"),
    ("JAW_OPEN", "jawOpen"),
    ("face:mouth_roll_lower", "mouthRollLower"),
    ("Body|blendShape1.eyeWide_R", "eyeWideRight"),
    ("jawOpen.001", "jawOpen"),
    ("mouthLeft", "mouthLeft"),       # a real name ending in "Left" must not be mistaken for a side suffix
    ("eyeLookIn_L", "eyeLookInLeft"),
    # ARKit's own raw values use _L/_R side suffixes
    ("eyeBlink_L", "eyeBlinkLeft"), ("mouthUpperUp_R", "mouthUpperUpRight"), ("browDown_L", "browDownLeft"),
    ("noseSneer_L", "noseSneerLeft"), ("cheekSquint_R", "cheekSquintRight"), ("eyeLookUp_R", "eyeLookUpRight"),
])
def test_decorated_names(raw: str, expected: str) -> None:
    assert match_arkit_name(raw) == expected


@pytest.mark.parametrize("raw", ["", "Timecode", "HeadYaw", "LeftEyePitch", "jaw", "open", "mouth",
                                 "CTRL_expressions_jawOpen", "eyeBlink", "123", "blendShape1.", "tongueIn"])
def test_non_names(raw: str) -> None:
    assert match_arkit_name(raw) is None


_PREFIXES = st.sampled_from(["", "AK_07_", "ARKit_", "arkit", "bs_", "BS", "blendShape1.", "Head|blendShape3.",
                             "face:", "12_"])
_SUFFIXES = st.sampled_from(["", ".001", "_bs", "1"])


def _case(name: str, style: str) -> str:
    if style == "lower":
        return name.lower()
    if style == "upper":
        return name.upper()
    if style == "pascal":
        return name[0].upper() + name[1:]
    if style == "snake":
        return "".join("_" + c.lower() if c.isupper() else c for c in name)
    return name


@settings(max_examples=300, deadline=None)
@given(st.sampled_from(ARKIT_NAMES), _PREFIXES, _SUFFIXES,
       st.sampled_from(["asis", "lower", "upper", "pascal", "snake"]))
def test_decorations_always_recover_the_name(name: str, prefix: str, suffix: str, style: str) -> None:
    assert match_arkit_name(prefix + _case(name, style) + suffix) == name


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=30))
def test_matcher_is_total_and_idempotent(raw: str) -> None:
    got = match_arkit_name(raw)
    assert got is None or got in ARKIT_NAMES
    if got is not None:
        assert match_arkit_name(got) == got


def _words(name: str) -> list[str]:
    import re

    return re.findall(r"[a-z]+|[A-Z][a-z]*", name)


def test_character_creator_numbered_names_map_to_every_arkit_shape():
    # CC4 spells each shape as A<nn>_Word_Word_Side, e.g. A38_Mouth_Smile_Left; built here from the ARKit names
    for i, name in enumerate(ARKIT_NAMES, start=1):
        cc4 = f"A{i:02d}_" + "_".join(w.capitalize() for w in _words(name))
        assert match_arkit_name(cc4) == name, cc4
        assert match_arkit_name(f"CC_Base_Body.{cc4}") == name


@pytest.mark.parametrize("raw,want", [
    ("blendShape1.jawOpen", "jawOpen"), ("ARKit_mouthSmileLeft", "mouthSmileLeft"), ("JAWOPEN", "jawOpen"),
    ("eye_blink_left", "eyeBlinkLeft"), ("mouthSmile_R", "mouthSmileRight"),
    # not ARKit, or either side: left alone rather than guessed
    ("Face.M_F00_000_00_Fcl_EYE_Close", None), ("Face.M_F00_000_00_Fcl_MTH_A", None), ("Eye_Blink", None),
    ("Mouth_Smile", None), ("vrc.v_aa", None),
])
def test_prefixed_and_cased_names(raw, want):
    assert match_arkit_name(raw) == want
