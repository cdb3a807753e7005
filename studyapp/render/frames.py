"""Frame pacing and audio/video sync bookkeeping for one play of a clip.

The audio clock is the master. Before drawing a frame the app asks :class:`FlipPredictor` when that
frame will appear (the next vsync flip) and draws the media time the audio will have reached by then
(:func:`clock_media_time`). After the flip, :class:`PlayRecorder` compares the time it drew with the
audio clock read at the flip: that difference is the audio/video offset the participant sees.

>>> rec = PlayRecorder(refresh_hz=60.0)
>>> for k, drawn in enumerate([0.0, 1/60, 2/60, 4/60]):      # one frame missed between 2 and 3
...     rec.flip(flip_time=[0, 1, 2, 4][k] / 60, drawn_media_s=drawn, audio_at_flip_s=drawn + 0.002)
>>> rec.frames_shown, rec.dropped_frames, round(rec.worst_av_offset_ms, 1)
(4, 1, 2.0)
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from studyapp.audio.clock import MediaClock


def clock_media_time(clock: MediaClock, now: float, predictor: FlipPredictor | None, duration_s: float) -> float:
    """The clip time a frame drawn at ``now`` shows, for a clip playing on ``clock`` (a media clock).

    Paused: the clock's position (nothing moves). Playing: where the clock will be at the predicted flip
    (:meth:`~studyapp.audio.clock.MediaClock.position_ahead_s`: an audio clock whose sound has not reached
    the speaker yet stays at the start), never past the end. Without a predictor, or on a virtual clock
    (offscreen: no time passes between drawing and the "flip"), the clock's position.

    >>> from studyapp.audio.clock import SilentClock
    >>> fp = FlipPredictor(60.0); fp.flipped(10.0)
    >>> clock = SilentClock(virtual=True); clock.play(None, 0.5, duration_s=2.0)
    >>> clock_media_time(clock, 10.0, fp, 2.0)
    0.5
    >>> class Wall(SilentClock):                                 # a clock that stands at 0.5 s here
    ...     def position_s(self): return 0.5
    >>> wall = Wall(); wall.play(None, duration_s=2.0)
    >>> round(clock_media_time(wall, 10.0, fp, 2.0), 4)         # shown at the next flip, 1/60 s later
    0.5167
    """
    # paused: nothing moves; virtual: no time passes between drawing and the flip; no flip seen yet: no
    # prediction to aim at
    flip = None if clock.paused or predictor is None or getattr(clock, "virtual", False) else predictor.predict(now)
    if flip is None:
        return clock.position_s() if clock.paused else min(clock.position_s(), duration_s)
    return min(clock.position_ahead_s(max(0.0, flip - now)), duration_s)


DRAW_TIME_WINDOW = 30  # recent draw durations the lead is estimated from (half a second at 60 Hz)
DRAW_TIME_QUANTILE = 0.9  # lead = this quantile of them: a frame misses its flip about once in ten spikes


class FlipPredictor:
    """Predicts the flip a frame drawn now will make, from the last flip, the refresh period (measured
    when not known) and how long drawing takes (:meth:`drew`, fed by the frame loop).

    On a fast machine drawing takes a fraction of a period and the frame aims at the next flip. When
    drawing takes longer (a software renderer, a loaded machine) the frame aims at the first flip its
    drawing can make (``now`` plus :attr:`lead_s`), so it is drawn for the audio time at which it will
    really be seen; a frame that still misses that flip is dropped by the loop, never shown late.

    >>> fp = FlipPredictor(50.0); fp.flipped(1.0)
    >>> fp.predict(1.001)                          # nothing known about drawing: the next flip
    1.02
    >>> for d in [0.05] * 10: fp.drew(d)           # drawing takes two and a half periods
    >>> round(fp.predict(1.001), 3)                # the first flip after 1.051
    1.06
    """

    def __init__(self, refresh_hz: float | None = None) -> None:
        self.nominal_hz = refresh_hz
        self.last_flip: float | None = None
        self._intervals: list[float] = []
        self._draws: list[float] = []
        #: The flip the frame being drawn aims at, set when its drawing asked (:meth:`predict`); None when
        #: the frame shows no media time (a static screen), which is then never late.
        self.aimed: float | None = None

    @property
    def lead_s(self) -> float:
        """How long drawing a frame is expected to take (0 until the loop reported a draw)."""
        if not self._draws:
            return 0.0
        return float(np.quantile(self._draws, DRAW_TIME_QUANTILE))

    def drew(self, seconds: float) -> None:
        """Report how long drawing one frame took (from the time it was aimed to the end of drawing)."""
        self._draws.append(max(0.0, float(seconds)))
        del self._draws[:-DRAW_TIME_WINDOW]

    @property
    def period(self) -> float | None:
        if self.nominal_hz:
            return 1.0 / self.nominal_hz
        if len(self._intervals) >= 3:
            return float(np.median(self._intervals[-60:]))
        return None

    def predict(self, now: float) -> float | None:
        period = self.period
        if self.last_flip is None or period is None:
            return None
        nxt = self.last_flip + period
        ready = now + self.lead_s  # when drawing will be done
        if nxt < ready:  # the frame goes out at the first whole period after it is ready
            nxt += np.ceil((ready - nxt) / period) * period
        self.aimed = float(nxt)
        return self.aimed

    def flipped(self, t: float) -> None:
        if self.last_flip is not None:
            self._intervals.append(t - self.last_flip)
            del self._intervals[:-240]
        self.last_flip = t


@dataclass
class PlayRecorder:
    """Frames, drops and A/V offsets of one play (what ``Session.record_play_finished`` stores)."""

    refresh_hz: float | None = None
    flips: list[float] = field(default_factory=list)
    offsets_s: list[float] = field(default_factory=list)
    #: The clip time each shown frame was drawn for (what the participant saw, frame by frame).
    drawn_s: list[float] = field(default_factory=list)

    def flip(self, flip_time: float, drawn_media_s: float, audio_at_flip_s: float) -> None:
        self.flips.append(float(flip_time))
        self.drawn_s.append(float(drawn_media_s))
        self.offsets_s.append(float(drawn_media_s) - float(audio_at_flip_s))

    @property
    def frames_shown(self) -> int:
        return len(self.flips)

    @property
    def measured_refresh_hz(self) -> float | None:
        """Median flip rate (what the display actually did), None with fewer than 3 frames."""
        if len(self.flips) < 3:
            return self.refresh_hz
        d = np.diff(self.flips)
        d = d[d > 0]
        return float(1.0 / np.median(d)) if d.size else self.refresh_hz

    @property
    def dropped_frames(self) -> int:
        """Frame intervals longer than 1.5 refresh periods (each counts once, however long)."""
        if len(self.flips) < 2:
            return 0
        hz = self.refresh_hz or self.measured_refresh_hz
        if not hz:
            return 0
        return int(np.sum(np.diff(self.flips) > 1.5 / hz))

    @property
    def worst_av_offset_ms(self) -> float:
        return float(np.max(np.abs(self.offsets_s)) * 1000.0) if self.offsets_s else 0.0

    def stats(self) -> dict[str, float | int | None]:
        refresh = self.measured_refresh_hz
        return {
            "frames_shown": self.frames_shown,
            "dropped_frames": self.dropped_frames,
            "refresh_hz": None if refresh is None else round(refresh, 2),
            "worst_av_offset_ms": round(self.worst_av_offset_ms, 2),
        }
