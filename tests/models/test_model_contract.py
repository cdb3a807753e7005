"""Models are checked against the contract on load, and every mismatch names file, place and problem."""
from __future__ import annotations

from pathlib import Path

import pytest
from onnx import TensorProto

from studyapp.errors import InputError
from studyapp.models import contract as C
from studyapp.models.runner import StreamingGestureModel
from studyapp.motion.beat import BEAT_UPPER_BODY

from live_model_helpers import good_meta, tiny_model

A = 9  # log_mel:8 + energy
GOOD_IN = {"audio": [1, 4, A], "face": [1, 4, 52], "head": [1, 4, 6], "prev_pose": [1, 47, 6],
           "state_in_h": [1, 1, 16]}
GOOD_OUT = {"rotations": [1, 47, 6], "state_out_h": [1, 1, 16]}


def test_conforming_model_gives_its_spec(tmp_path: Path) -> None:
    path = tiny_model(tmp_path / "ok.onnx", {**GOOD_IN, "audio": ["batch", 4, A]}, GOOD_OUT, good_meta())
    spec = StreamingGestureModel(path).spec
    assert (spec.fps, spec.window, spec.audio_dim, spec.rotation, spec.rotation_width) == (15.0, 4, A, "6d", 6)
    assert spec.audio_features == ("log_mel:8", "energy")
    assert spec.joints == BEAT_UPPER_BODY and spec.n_joints == 47
    assert spec.inputs == ("audio", "face", "head", "prev_pose") and spec.states == {"h": (1, 1, 16)}


def test_declared_joint_subset_and_quaternions(tmp_path: Path) -> None:
    joints = "Spine,Neck,Head,RightArm,LeftArm"
    path = tiny_model(tmp_path / "q.onnx", {"audio": [1, 4, A]}, {"rotations": [1, 5, 4]},
                      good_meta(**{"studyapp.rotation": "quat", "studyapp.joints": joints}))
    spec = StreamingGestureModel(path).spec
    assert spec.joints == tuple(joints.split(",")) and spec.rotation_width == 4 and spec.inputs == ("audio",)


CASES = [
    # (what is wrong, inputs, outputs, metadata, where, problem fragment)
    ("input name", {**GOOD_IN, "mel": [1, 4, A]}, GOOD_OUT, good_meta(), "input 'mel'", "not a contract input"),
    ("no audio", {k: v for k, v in GOOD_IN.items() if k != "audio"}, GOOD_OUT, good_meta(), "input 'audio'", "missing"),
    ("audio width", {**GOOD_IN, "audio": [1, 4, 80]}, GOOD_OUT, good_meta(), "input 'audio'",
     "shape [1, 4, 80] but the contract needs [1, 4, 9]"),
    ("window", {**GOOD_IN, "face": [1, 8, 52]}, GOOD_OUT, good_meta(), "input 'face'", "needs [1, 4, 52]"),
    ("batch 2", {**GOOD_IN, "head": [2, 4, 6]}, GOOD_OUT, good_meta(), "input 'head'", "needs [1, 4, 6]"),
    ("joint count", GOOD_IN, {**GOOD_OUT, "rotations": [1, 40, 6]}, good_meta(), "output 'rotations'",
     "shape [1, 40, 6] but the contract needs [1, 47, 6] (47 joints from the default 47 BEAT upper-body joints"),
    ("prev pose joints", {**GOOD_IN, "prev_pose": [1, 46, 6]}, GOOD_OUT, good_meta(), "input 'prev_pose'", "[1, 47, 6]"),
    ("rotation width", GOOD_IN, {**GOOD_OUT, "rotations": [1, 47, 4]}, good_meta(), "output 'rotations'", "rotation '6d'"),
    ("no rotations", GOOD_IN, {"state_out_h": [1, 1, 16], "pose": [1, 47, 6]}, good_meta(), "output 'rotations'",
     "missing; the model's outputs are state_out_h, pose"),
    ("state pairing", GOOD_IN, {"rotations": [1, 47, 6]}, good_meta(), "output 'state_out_h'", "missing"),
    ("state shape", GOOD_IN, {**GOOD_OUT, "state_out_h": [1, 1, 32]}, good_meta(), "output 'state_out_h'", "[1, 1, 16]"),
    ("dynamic state", {**GOOD_IN, "state_in_h": [1, "n", 16]}, GOOD_OUT, good_meta(), "input 'state_in_h'", "static"),
    ("no metadata", GOOD_IN, GOOD_OUT, None, "metadata 'studyapp.fps'", "missing"),
    ("no window", GOOD_IN, GOOD_OUT, good_meta(**{"studyapp.window": None}), "metadata 'studyapp.window'", "missing"),
    ("no features", GOOD_IN, GOOD_OUT, good_meta(**{"studyapp.audio_features": None}),
     "metadata 'studyapp.audio_features'", "missing"),
    ("no rotation", GOOD_IN, GOOD_OUT, good_meta(**{"studyapp.rotation": None}), "metadata 'studyapp.rotation'", "missing"),
    ("bad fps", GOOD_IN, GOOD_OUT, good_meta(**{"studyapp.fps": "fast"}), "metadata 'studyapp.fps'", "not a number"),
    ("bad feature", GOOD_IN, GOOD_OUT, good_meta(**{"studyapp.audio_features": "mfcc:13"}),
     "metadata 'studyapp.audio_features'", "unknown audio feature 'mfcc:13'"),
    ("bad rotation", GOOD_IN, GOOD_OUT, good_meta(**{"studyapp.rotation": "euler"}), "metadata 'studyapp.rotation'",
     "not one of '6d', 'quat'"),
    ("unknown joint", {"audio": [1, 4, A]}, {"rotations": [1, 2, 6]}, good_meta(**{"studyapp.joints": "Spine,Tail"}),
     "metadata 'studyapp.joints'", "not joints of the BEAT skeleton: Tail"),
    ("joint list vs output", {"audio": [1, 4, A]}, {"rotations": [1, 3, 6]}, good_meta(**{"studyapp.joints": "Spine,Neck"}),
     "output 'rotations'", "2 joints from studyapp.joints"),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_contract_violations_are_clear(tmp_path: Path, case) -> None:
    _, inputs, outputs, meta, where, problem = case
    path = tiny_model(tmp_path / "bad.onnx", inputs, outputs, meta)
    with pytest.raises(InputError) as err:
        StreamingGestureModel(path)
    assert err.value.path == str(path) and err.value.where == where, str(err.value)
    assert problem in err.value.problem, str(err.value)
    assert str(err.value).startswith(f"{path}, {where}: ")


def test_wrong_dtype_and_unreadable_files(tmp_path: Path) -> None:
    path = tiny_model(tmp_path / "f64.onnx", {**GOOD_IN, "audio": [1, 4, A]}, GOOD_OUT, good_meta(),
                      input_type=TensorProto.DOUBLE)
    with pytest.raises(InputError, match=r"input 'audio': type tensor\(double\)"):
        StreamingGestureModel(path)
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a model")
    with pytest.raises(InputError, match="junk.onnx: onnxruntime cannot load the model"):
        StreamingGestureModel(junk)
    with pytest.raises(InputError, match="missing.onnx: model file not found"):
        StreamingGestureModel(tmp_path / "missing.onnx")


def test_metadata_props_round_trip_through_a_model(tmp_path: Path) -> None:
    meta = C.metadata_props(fps=30, window=2, audio_features=["f0"], rotation="quat", joints=["Neck"], description="x")
    path = tiny_model(tmp_path / "m.onnx", {"audio": [1, 2, 1]}, {"rotations": [1, 1, 4]}, meta)
    spec = StreamingGestureModel(path).spec
    assert (spec.fps, spec.window, spec.audio_features, spec.rotation, spec.joints) == (30.0, 2, ("f0",), "quat", ("Neck",))
    assert spec.metadata["studyapp.description"] == "x" and spec.metadata["studyapp.contract"] == C.CONTRACT_VERSION
