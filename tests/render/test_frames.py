"""Frame statistics and flip prediction, checked against values computed by hand."""
import numpy as np
import pytest

from studyapp.render.frames import FlipPredictor, PlayRecorder, media_time_for_flip


def test_dropped_frames_counts_intervals_over_one_and_a_half_periods():
    flips = np.array([0, 1, 2, 3, 5, 6, 9, 10]) / 60.0  # gaps of 2 and 3 periods
    rec = PlayRecorder(refresh_hz=60.0)
    for t in flips:
        rec.flip(t, t, t)
    assert rec.frames_shown == 8
    assert rec.dropped_frames == 2
    assert rec.measured_refresh_hz == pytest.approx(60.0)


def test_worst_offset_is_absolute_and_in_ms():
    rec = PlayRecorder(refresh_hz=60.0)
    rec.flip(0.0, 0.000, 0.010)
    rec.flip(1 / 60, 1 / 60 + 0.004, 1 / 60)
    assert rec.worst_av_offset_ms == pytest.approx(10.0)
    s = rec.stats()
    assert s["frames_shown"] == 2 and s["worst_av_offset_ms"] == pytest.approx(10.0)


def test_measured_refresh_without_nominal_rate():
    rec = PlayRecorder()
    for k in range(10):
        rec.flip(k / 75.0, 0, 0)
    assert rec.measured_refresh_hz == pytest.approx(75.0)
    assert rec.dropped_frames == 0


def test_flip_predictor_next_vsync_and_late_frames():
    p = FlipPredictor(60.0)
    assert p.predict(0.0) is None
    p.flipped(1.0)
    assert p.predict(1.001) == pytest.approx(1.0 + 1 / 60)
    # 2.5 periods after the last flip: the frame can only go out at the 3rd vsync
    assert p.predict(1.0 + 2.5 / 60) == pytest.approx(1.0 + 3 / 60)


def test_flip_predictor_learns_period():
    p = FlipPredictor()
    for k in range(5):
        p.flipped(k * 0.02)
    assert p.period == pytest.approx(0.02)


def test_media_time_leads_by_time_to_flip():
    assert media_time_for_flip(2.0, now=10.0, predicted_flip=10.012) == pytest.approx(2.012)
    assert media_time_for_flip(2.0, now=10.0, predicted_flip=None) == 2.0
