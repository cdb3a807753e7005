"""Frame statistics and flip prediction, checked against values computed by hand."""
import numpy as np
import pytest

import time

from studyapp.audio.clock import SilentClock
from studyapp.audio.playback import AudioPlayer
from studyapp.render.frames import FlipPredictor, PlayRecorder, clock_media_time


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


class _Lead:
    """A flip predictor whose frames appear ``lead`` seconds after they are drawn."""

    def __init__(self, lead: float) -> None:
        self.lead = lead

    def predict(self, now: float) -> float:
        return now + self.lead


def test_media_time_leads_by_time_to_flip():
    class Wall(SilentClock):
        def position_s(self):
            return 2.0

    wall = Wall()
    wall.play(None, duration_s=5.0)
    assert clock_media_time(wall, 10.0, _Lead(0.012), 5.0) == pytest.approx(2.012)
    assert clock_media_time(wall, 10.0, None, 5.0) == 2.0
    assert FlipPredictor(60.0).predict(10.0) is None  # no flip seen yet: nothing to aim at
    assert clock_media_time(wall, 10.0, FlipPredictor(60.0), 5.0) == 2.0
    assert clock_media_time(wall, 10.0, _Lead(4.0), 5.0) == 5.0  # never past the end
    wall.pause()
    assert clock_media_time(wall, 10.0, _Lead(0.012), 5.0) == 2.0


def _player_with_last_buffer(first: int, dac_in_s: float, rate: int = 48000) -> AudioPlayer:
    """An audio player (no output process) whose device took the buffer starting at sample ``first``; its
    sound reaches the speaker ``dac_in_s`` seconds from now (negative: already audible)."""
    p = AudioPlayer.__new__(AudioPlayer)
    p._active, p._paused_at, p._gen, p._start_s, p.rate = True, None, 7, 0.0, rate
    p._buf = np.zeros((5 * rate, 1), np.float32)
    dac = time.monotonic() + dac_in_s
    p._anchor = lambda: (7, first, dac, 1024)
    return p


def test_first_frames_of_a_play_wait_with_the_sound_for_the_speaker():
    """Just after a play starts, the device has taken the first samples but they reach the speaker only an
    output latency later: the clock stands at the start until then. A frame whose flip comes before the
    sound starts must show the start, not the start plus its drawing time (that put the first frames of
    every trial 50-80 ms ahead of the sound on a loaded software renderer)."""
    p = _player_with_last_buffer(first=0, dac_in_s=0.1)
    assert p.position_s() == 0.0
    assert clock_media_time(p, time.perf_counter(), _Lead(0.06), p.duration_s) == 0.0
    assert p.position_ahead_s(0.15) == pytest.approx(0.05, abs=0.01)
    # Flowing: where the sound will be at the flip, past what was delivered so far.
    p = _player_with_last_buffer(first=48000, dac_in_s=0.0)
    assert p.position_s() == pytest.approx(1.0, abs=0.01)
    assert clock_media_time(p, time.perf_counter(), _Lead(0.05), p.duration_s) == pytest.approx(1.05, abs=0.01)
    assert p.position_s() <= (48000 + 1024) / 48000  # now: never ahead of what was delivered
