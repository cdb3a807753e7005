"""FaceAnimation: construction rules, interpolation, resampling."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_INDEX, ARKIT_NAMES


def _ramp(n: int = 5, fps: float = 10.0) -> FaceAnimation:
    w = np.zeros((n, 52), np.float32)
    w[:, ARKIT_INDEX["jawopen"]] = np.linspace(0, 1, n)
    w[:, ARKIT_INDEX["eyeblinkleft"]] = [0, 1, 0, 1, 0][:n]
    return FaceAnimation(w, fps, head_rotation=np.stack([np.arange(n)] * 3, 1) * 0.1)


def test_properties_and_clipping() -> None:
    w = np.full((4, 52), 0.5)
    w[0, 0], w[1, 1] = 1.2, -0.3
    face = FaceAnimation(w, 24.0)
    assert face.weights.dtype == np.float32 and face.weights.shape == (4, 52)
    assert face.weights[0, 0] == 1.0 and face.weights[1, 1] == 0.0
    assert face.n_frames == 4 and face.duration == pytest.approx(4 / 24)


@pytest.mark.parametrize("weights, fps, head", [
    (np.zeros((3, 51)), 30.0, None),
    (np.zeros(52), 30.0, None),
    (np.full((2, 52), np.nan), 30.0, None),
    (np.zeros((2, 52)), 0.0, None),
    (np.zeros((2, 52)), float("nan"), None),
    (np.zeros((2, 52)), 30.0, np.zeros((3, 3))),
])
def test_invalid_construction(weights, fps, head) -> None:
    with pytest.raises(ValueError):
        FaceAnimation(weights, fps, head)


def test_sample_matches_numpy_interp_and_clamps() -> None:
    face = _ramp()
    times = np.array([-1.0, 0.0, 0.05, 0.15, 0.39, 0.4, 5.0])
    frame_t = np.arange(5) / 10.0
    got = face.sample(times)
    assert got.shape == (7, 52)
    for name in ("jawopen", "eyeblinkleft"):
        col = face.weights[:, ARKIT_INDEX[name]]
        np.testing.assert_allclose(got[:, ARKIT_INDEX[name]], np.interp(times, frame_t, col), atol=1e-7)
    np.testing.assert_allclose(face.sample_head(np.array([0.05]))[0], [0.05] * 3, atol=1e-7)
    assert face.sample(np.array(0.1)).shape == (1, 52)


def test_resample_keeps_duration_and_values() -> None:
    face = _ramp(5, 10.0)
    up = face.resample(20.0)
    assert up.n_frames == 10 and up.duration == pytest.approx(face.duration)
    np.testing.assert_allclose(up.weights[::2], face.weights, atol=1e-7)
    assert up.weights[1, ARKIT_INDEX["eyeblinkleft"]] == pytest.approx(0.5)
    assert up.head_rotation.shape == (10, 3)
    down = FaceAnimation.neutral(60, 60.0).resample(15.0)
    assert down.n_frames == 15 and down.fps == 15.0


@settings(max_examples=50, deadline=None)
@given(st.integers(2, 40), st.sampled_from([15.0, 24.0, 25.0, 30.0, 60.0]), st.sampled_from([15.0, 30.0, 60.0]))
def test_resample_round_trip_is_linear_interp(n: int, fps: float, new_fps: float) -> None:
    rng = np.random.default_rng(n)
    face = FaceAnimation(rng.random((n, 52)), fps)
    out = face.resample(new_fps)
    assert out.n_frames == round(n * new_fps / fps)
    t = np.arange(out.n_frames) / new_fps
    ref = np.stack([np.interp(t, np.arange(n) / fps, face.weights[:, k]) for k in range(52)], 1)
    np.testing.assert_allclose(out.weights, ref, atol=1e-6)


def test_neutral_and_weight_lookup() -> None:
    face = FaceAnimation.neutral(3, 30.0)
    assert face.weights.sum() == 0 and face.head_rotation is None
    ramp = _ramp()
    np.testing.assert_array_equal(ramp.weight("JawOpen"), ramp.weights[:, 17])
    np.testing.assert_array_equal(ramp.weight("AK_01_EyeBlinkLeft"), ramp.weights[:, 0])
    assert ARKIT_NAMES[17] == "jawOpen"
    with pytest.raises(KeyError):
        ramp.weight("HeadYaw")
