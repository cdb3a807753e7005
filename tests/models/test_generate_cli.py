"""``studyapp generate``: BVH that loads back with the right frame count, a latency report, clear errors."""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import pytest

from studyapp.audio.wav import AudioClip, save_wav
from studyapp.errors import InputError
from studyapp.face.animation import FaceAnimation
from studyapp.face.io import save_face_csv
from studyapp.cli import models as cli
from studyapp.models.live import stimulus_inputs
from studyapp.models.runner import StreamingGestureModel
from studyapp.motion import rotations as R
from studyapp.motion.beat import BEAT_UPPER_BODY
from studyapp.motion.bvh import read_bvh

from live_model_helpers import SR, speech_like


def run(argv: list[str]) -> int:
    """Parse and dispatch like ``studyapp.cli.main`` does, with only this area's sub-commands."""
    parser = argparse.ArgumentParser(prog="studyapp")
    cli.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return args.func(args)


@pytest.fixture
def stimulus(tmp_path: Path) -> tuple[Path, Path, FaceAnimation, AudioClip]:
    audio = AudioClip(speech_like(2.3), SR)
    save_wav(audio, tmp_path / "a.wav")
    rng = np.random.default_rng(0)
    face = FaceAnimation(rng.uniform(0, 1, (69, 52)).astype(np.float32), 30.0, head_rotation=rng.normal(0, 0.1, (69, 3)))
    save_face_csv(face, tmp_path / "f.csv")
    return tmp_path / "a.wav", tmp_path / "f.csv", face, audio


def test_generate_writes_bvh_and_latency_report(ref_model: Path, stimulus, tmp_path: Path) -> None:
    wav, face_csv, _, _ = stimulus
    out, report = tmp_path / "out" / "m.bvh", tmp_path / "out" / "r.json"
    assert run(["generate", "--model", str(ref_model), "--audio", str(wav), "--face", str(face_csv),
                "--out", str(out), "--report", str(report)]) == 0
    motion = read_bvh(out, fps=15.0)
    n = math.ceil(2.3 * 15)
    assert motion.n_frames == n and motion.skeleton.n_joints == 75
    rep = json.loads(report.read_text())
    assert rep["frames"] == n and rep["fps"] == 15.0 and rep["joints"] == 47
    lat = rep["latency_ms"]
    assert 0 < lat["median"] <= lat["p99"] <= lat["max"]
    # What the file holds is the model's streamed output (through Euler BVH, so to ~1e-4).
    from studyapp.audio.wav import load_wav
    from studyapp.face.io import load_face

    model = StreamingGestureModel(ref_model)
    inputs = stimulus_inputs(model.spec, load_wav(wav), load_face(face_csv))
    want = R.sixd_to_quat(model.run_sequence(inputs.features, inputs.face, inputs.head6d))
    got = motion.rotations[:, [motion.skeleton.index(j) for j in BEAT_UPPER_BODY]]
    assert np.abs(np.sum(got * want, axis=-1)).min() > 1 - 1e-6


def test_head_file_and_fps_override(ref_model: Path, stimulus, tmp_path: Path) -> None:
    wav, face_csv, face, _ = stimulus
    head = tmp_path / "head.csv"
    head.write_text("yaw,pitch,roll\n" + "\n".join(",".join(f"{v:.6f}" for v in r) for r in face.head_rotation) + "\n")
    out = tmp_path / "m.bvh"
    assert run(["generate", "--model", str(ref_model), "--audio", str(wav), "--head", str(head),
                "--out", str(out), "--fps", "30"]) == 0
    assert read_bvh(out, fps=30.0).n_frames == math.ceil(2.3 * 30)
    assert np.allclose(cli.load_head(head), face.head_rotation, atol=1e-6)
    shuffled = tmp_path / "livelink_like.csv"
    shuffled.write_text("Timecode,HeadRoll,HeadYaw,HeadPitch\n00:00:00:00.0,0.3,0.1,0.2\n")
    assert cli.load_head(shuffled).tolist() == [[0.1, 0.2, 0.3]]
    bare = tmp_path / "bare.csv"
    bare.write_text("0.1,0.2,0.3\n0.4,0.5,0.6\n")
    assert cli.load_head(bare).shape == (2, 3)


def test_bad_inputs_name_the_file(ref_model: Path, stimulus, tmp_path: Path) -> None:
    wav, face_csv, _, _ = stimulus
    bad = tmp_path / "bad.csv"
    bad.write_text("yaw,pitch,roll\n0,0,0\n0,zero,0\n")
    with pytest.raises(InputError, match=r"bad.csv, line 3: expected three numbers \(yaw, pitch, roll\)"):
        run(["generate", "--model", str(ref_model), "--audio", str(wav), "--head", str(bad), "--out", str(tmp_path / "x.bvh")])
    with pytest.raises(InputError, match=r"nope.onnx: model file not found"):
        run(["generate", "--model", str(tmp_path / "nope.onnx"), "--audio", str(wav), "--out", str(tmp_path / "x.bvh")])
    assert not (tmp_path / "x.bvh").exists()
