"""Live conditions: stimulus inputs, BEAT motion, and the on-disk cache that spares a session the wait."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from studyapp.audio.wav import AudioClip
from studyapp.face.animation import FaceAnimation
from studyapp.models import live
from studyapp.models.runner import StreamingGestureModel
from studyapp.motion import rotations as R
from studyapp.motion.beat import BEAT_UPPER_BODY, beat_skeleton
from studyapp.motion.skeleton import Motion

from live_model_helpers import SR, good_meta, speech_like, tiny_model


@pytest.fixture
def cache(tmp_path: Path, monkeypatch) -> Path:
    monkeypatch.setenv("STUDYAPP_CACHE_DIR", str(tmp_path / "cache"))
    return tmp_path / "cache" / "models"


def clip(seconds: float = 3.0, seed: int = 0) -> AudioClip:
    return AudioClip(speech_like(seconds, seed=seed), SR, "speech")


def face_for(seconds: float, seed: int = 0, head: bool = True) -> FaceAnimation:
    rng = np.random.default_rng(seed)
    n = int(seconds * 30)
    return FaceAnimation(rng.uniform(0, 1, (n, 52)).astype(np.float32), 30.0,
                         head_rotation=rng.normal(0, 0.2, (n, 3)) if head else None)


def test_cache_dir_follows_env_and_xdg(monkeypatch, tmp_path: Path) -> None:
    monkeypatch.setenv("STUDYAPP_CACHE_DIR", str(tmp_path / "a"))
    assert live.cache_dir() == tmp_path / "a" / "models"
    monkeypatch.delenv("STUDYAPP_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert live.cache_dir() == tmp_path / "xdg" / "studyapp" / "models"


def test_motion_for_stimulus_runs_once_then_reads_the_cache(ref_model: Path, cache: Path) -> None:
    audio, face = clip(), face_for(3.0)
    runs = live.RUN_COUNT
    first = live.motion_for_stimulus(ref_model, audio, face)
    assert live.RUN_COUNT == runs + 1
    entries = list(cache.glob("*.npz"))
    assert len(entries) == 1
    mtime = entries[0].stat().st_mtime_ns
    second = live.motion_for_stimulus(ref_model, AudioClip(audio.samples.copy(), SR, "elsewhere.wav"), face)
    assert live.RUN_COUNT == runs + 1 and entries[0].stat().st_mtime_ns == mtime
    assert np.array_equal(first.rotations, second.rotations)
    # Any change to the inputs or the model is a different entry.
    live.motion_for_stimulus(ref_model, audio, face_for(3.0, seed=1))
    live.motion_for_stimulus(ref_model, audio, face, head=np.zeros((90, 3)))
    assert live.RUN_COUNT == runs + 3 and len(list(cache.glob("*.npz"))) == 3


def test_damaged_cache_entry_is_regenerated(ref_model: Path, cache: Path) -> None:
    audio = clip(1.0)
    good = live.motion_for_stimulus(ref_model, audio)
    (entry,) = cache.glob("*.npz")
    entry.write_bytes(b"truncated")
    runs = live.RUN_COUNT
    again = live.motion_for_stimulus(ref_model, audio)
    assert live.RUN_COUNT == runs + 1 and np.array_equal(good.rotations, again.rotations)


def test_generated_motion_is_the_streamed_output_on_the_beat_skeleton(ref_model: Path, cache: Path) -> None:
    audio, face = clip(2.5), face_for(2.5)
    motion = live.motion_for_stimulus(ref_model, audio, face)
    assert motion.fps == 15.0 and motion.n_frames == math.ceil(2.5 * 15)
    assert motion.skeleton.names == beat_skeleton().names
    model = StreamingGestureModel(ref_model)
    inputs = live.stimulus_inputs(model.spec, audio, face)
    expected = R.sixd_to_quat(model.run_sequence(inputs.features, inputs.face, inputs.head6d))
    idx = [motion.skeleton.index(n) for n in BEAT_UPPER_BODY]
    got = motion.rotations[:, idx]
    assert np.allclose(np.abs(np.sum(got * expected, axis=-1)), 1.0, atol=1e-6)  # same rotations (q ~ -q)
    legs = motion.skeleton.index("RightUpLeg")
    assert np.allclose(motion.rotations[:, legs], [0, 0, 0, 1])


def test_template_motion_sets_skeleton_and_hips(ref_model: Path, cache: Path) -> None:
    template = Motion.rest(beat_skeleton(), 2, 15.0)
    template.translations[:, 0] = [5.0, 95.0, -3.0]
    motion = live.motion_for_stimulus(ref_model, clip(1.0), template=template)
    assert np.allclose(motion.translations[:, 0], [5.0, 95.0, -3.0])


def test_stimulus_inputs_are_causal_in_audio_time(ref_model: Path) -> None:
    spec = StreamingGestureModel(ref_model).spec
    audio = speech_like(3.0)
    base = live.stimulus_inputs(spec, AudioClip(audio, SR))
    t = 20
    changed = audio.copy()
    # Frame t's windows reach 1/fps seconds past its time (the centred log-mel window); start just after.
    start = math.ceil((t + 1) / spec.fps * SR) + 1
    changed[start:] = speech_like(3.0, seed=5)[start:] * 3
    other = live.stimulus_inputs(spec, AudioClip(changed, SR))
    assert np.array_equal(base.features[: t + 1], other.features[: t + 1])
    assert not np.array_equal(base.features[t + 1:], other.features[t + 1:])


def test_head_rotation_from_face_file_or_explicit_array(ref_model: Path) -> None:
    spec = StreamingGestureModel(ref_model).spec
    audio = AudioClip(speech_like(1.0), SR)
    face = face_for(1.0)
    from_face = live.stimulus_inputs(spec, audio, face)
    explicit = live.stimulus_inputs(spec, audio, face_for(1.0, head=False), head=face.head_rotation)
    assert from_face.head6d.shape == (15, 6)
    np.testing.assert_allclose(from_face.head6d, explicit.head6d, atol=1e-5)
    assert live.stimulus_inputs(spec, audio, face_for(1.0, head=False)).head6d is None
    # Yaw turns about +Y: the rotated x axis (first 6D column) swings towards -Z.
    yaw = live.head_to_sixd(np.array([[np.pi / 2, 0.0, 0.0]]))
    np.testing.assert_allclose(yaw[0], [0, 0, -1, 0, 1, 0], atol=1e-12)


def test_quaternion_model_on_a_joint_subset(tmp_path: Path, cache: Path) -> None:
    meta = good_meta(**{"studyapp.rotation": "quat", "studyapp.joints": "Neck,Head,RightArm"})
    path = tiny_model(tmp_path / "q.onnx", {"audio": [1, 4, 9]}, {"rotations": [1, 3, 4]}, meta, value=0.5)
    motion = live.motion_for_stimulus(path, clip(1.0))
    sk = motion.skeleton
    for name in ("Neck", "Head", "RightArm"):  # Head is outside the 47 and still set
        assert np.allclose(motion.rotations[:, sk.index(name)], 0.5)
    assert np.allclose(motion.rotations[:, sk.index("LeftArm")], [0, 0, 0, 1])
