"""The streaming runner: causal, stateful, and equal to the same network run over a whole sequence."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import onnxruntime as ort
import pytest

from studyapp.errors import InputError
from studyapp.models.reference import ReferenceConfig, reference_sequence_model
from studyapp.models.runner import IDENTITY_6D, StreamingGestureModel

N = 40


def random_inputs(spec, n: int = N, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    feats = np.concatenate([rng.normal(-5, 3, (n, spec.audio_dim - 2)), rng.uniform(0, 0.1, (n, 1)),
                            rng.uniform(0, 300, (n, 1))], axis=1).astype(np.float32)
    face = rng.uniform(0, 1, (n, 52)).astype(np.float32)
    q = rng.normal(size=(n, 3))
    head = np.concatenate([np.cos(q[:, :1]), np.sin(q[:, :1]), np.zeros((n, 1)),
                           -np.sin(q[:, :1]), np.cos(q[:, :1]), np.zeros((n, 1))], axis=1).astype(np.float32)
    return feats, face, head


def windows(x: np.ndarray, w: int, fill: np.ndarray) -> np.ndarray:
    """(F, D) -> (F, w, D): row t holds frames t-w+1 .. t, ``fill`` before the start (independent of the runner)."""
    padded = np.concatenate([np.tile(fill, (w - 1, 1)), x], axis=0)
    return np.stack([padded[t:t + w] for t in range(x.shape[0])]).astype(np.float32)


def whole_sequence(cfg: ReferenceConfig, feats, face, head) -> np.ndarray:
    sess = ort.InferenceSession(reference_sequence_model(cfg).SerializeToString(), providers=["CPUExecutionProvider"])
    w = cfg.window
    return sess.run(None, {"audio": windows(feats, w, np.zeros(feats.shape[1])), "face": windows(face, w, np.zeros(52)),
                           "head": windows(head, w, IDENTITY_6D)})[0]


@pytest.mark.parametrize("previous_pose", [False, True], ids=["lstm-over-sequence", "scan-with-pose-feedback"])
def test_frame_by_frame_equals_whole_sequence(previous_pose: bool, ref_model: Path, ref_model_no_prev: Path) -> None:
    model = StreamingGestureModel(ref_model if previous_pose else ref_model_no_prev)
    assert model.spec.takes("prev_pose") == previous_pose
    feats, face, head = random_inputs(model.spec)
    streamed = model.run_sequence(feats, face, head)
    batch = whole_sequence(ReferenceConfig(previous_pose=previous_pose), feats, face, head)
    assert batch.shape == streamed.shape == (N, 47, 6)
    np.testing.assert_allclose(streamed, batch, atol=2e-5, rtol=1e-4)
    # The comparison has teeth: without carrying the LSTM state, frames after the first differ.
    model.reset()
    stateless = []
    for i in range(N):
        model.reset()
        stateless.append(model.step(feats[i], face[i], head[i]))
    assert np.abs(np.array(stateless)[5:] - batch[5:]).max() > 1e-3


@pytest.mark.parametrize("which", ["audio", "face", "head"])
def test_changing_inputs_after_frame_t_never_changes_output_up_to_t(which: str, ref_model: Path) -> None:
    model = StreamingGestureModel(ref_model)
    feats, face, head = random_inputs(model.spec)
    before = model.run_sequence(feats, face, head)
    t = 17
    arrays = {"audio": feats.copy(), "face": face.copy(), "head": head.copy()}
    arrays[which][t + 1:] = random_inputs(model.spec, seed=1)[["audio", "face", "head"].index(which)][t + 1:]
    after = model.run_sequence(arrays["audio"], arrays["face"], arrays["head"])
    assert np.array_equal(before[: t + 1], after[: t + 1])
    assert np.abs(before[t + 1:] - after[t + 1:]).max() > 1e-4  # the change does reach later frames


def test_reset_restarts_and_state_carries(ref_model: Path) -> None:
    model = StreamingGestureModel(ref_model)
    feats, face, head = random_inputs(model.spec, n=10)
    first = model.run_sequence(feats, face, head)
    continued = model.run_sequence(feats, face, head, reset=False)
    again = model.run_sequence(feats, face, head)
    assert np.array_equal(first, again)
    assert np.abs(continued - first).max() > 1e-4


def test_latency_is_recorded_per_step(ref_model: Path) -> None:
    model = StreamingGestureModel(ref_model)
    feats, face, head = random_inputs(model.spec, n=12)
    model.run_sequence(feats, face, head)
    lat = model.latency_summary()
    assert lat["frames"] == 12 and len(model.latencies_ms) == 12
    assert 0 < lat["median_ms"] <= lat["p99_ms"] <= lat["max_ms"]
    model.reset()
    assert model.latency_summary()["frames"] == 0


def test_missing_face_and_head_hold_neutral_values(ref_model: Path) -> None:
    model = StreamingGestureModel(ref_model)
    feats, _, _ = random_inputs(model.spec, n=8)
    neutral = model.run_sequence(feats, np.zeros((8, 52), np.float32), np.tile(IDENTITY_6D, (8, 1)))
    assert np.array_equal(model.run_sequence(feats), neutral)


def test_wrongly_shaped_frames_are_refused(ref_model: Path) -> None:
    model = StreamingGestureModel(ref_model)
    with pytest.raises(InputError, match=r"input 'audio': frame has 65 values, the model takes 66"):
        model.step(np.zeros(65, np.float32))
    with pytest.raises(InputError, match=r"face: shape \(3, 51\), expected \(3, 52\)"):
        model.run_sequence(np.zeros((3, 66), np.float32), np.zeros((3, 51), np.float32))
