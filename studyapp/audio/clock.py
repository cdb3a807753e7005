"""Media clocks: the time base every displayed frame is drawn for.

Two implementations share one interface (:class:`MediaClock`):

* :class:`studyapp.audio.playback.AudioPlayer` -- the audio output stream is the master clock, so the
  picture follows what the participant hears (video frames can be repeated or skipped, audio cannot).
* :class:`SilentClock` -- no sound: time comes from ``time.monotonic`` (a machine without an audio
  device) or is advanced explicitly (``virtual=True``, the offscreen bot, where a 10 s clip may be
  "played" in a handful of rendered frames).

Example:

>>> clock = SilentClock(virtual=True)
>>> clock.play(None, duration_s=2.0)
>>> clock.advance(0.5); round(clock.position_s(), 3)
0.5
>>> clock.pause(); clock.advance(1.0); round(clock.position_s(), 3)
0.5
>>> clock.resume(); clock.advance(5.0); clock.finished, clock.position_s()
(True, 2.0)
"""
from __future__ import annotations

import time
from typing import Any, Protocol


class MediaClock(Protocol):
    """What the UI needs from a clock; both clocks here and the audio player implement it."""

    #: Human-readable output name ("no audio device", "NullSink", ...), shown in the environment check.
    device_name: str

    def play(self, clip: Any, start_s: float = 0.0, *, duration_s: float | None = None) -> None: ...
    def pause(self) -> None: ...
    def resume(self) -> None: ...
    def stop(self) -> None: ...
    def replay(self) -> None: ...
    def position_s(self) -> float: ...
    def position_ahead_s(self, ahead_s: float) -> float: ...
    @property
    def duration_s(self) -> float: ...
    @property
    def started(self) -> bool: ...
    @property
    def playing(self) -> bool: ...
    @property
    def paused(self) -> bool: ...
    @property
    def finished(self) -> bool: ...
    @property
    def output_latency_s(self) -> float: ...
    def close(self) -> None: ...


def clip_duration(clip: Any) -> float:
    """Duration in seconds of an audio clip (anything with ``samples`` (N[, C]) and ``sample_rate``)."""
    if clip is None:
        return 0.0
    if hasattr(clip, "duration"):
        return float(clip.duration)
    return len(clip.samples) / float(clip.sample_rate)


class SilentClock:
    """A media clock without sound.

    Parameters
    ----------
    virtual:
        When True time only moves through :meth:`advance` (deterministic, for bots and tests);
        otherwise it follows ``time.monotonic``.
    reason:
        Why there is no sound (shown to the experimenter), e.g. ``"no audio output device"``.
    """

    def __init__(self, *, virtual: bool = False, reason: str = "no audio output device") -> None:
        self.virtual = virtual
        self.reason = reason
        self.device_name = f"none ({reason})"
        self._virtual_now = 0.0
        self._duration = 0.0
        self._start_s = 0.0
        self._anchor: float | None = None  # clock time at which position == _start_s while running
        self._paused_at: float | None = None
        self._active = False

    # -- time base -------------------------------------------------------------------------------
    def _now(self) -> float:
        return self._virtual_now if self.virtual else time.monotonic()

    def advance(self, dt: float) -> None:
        """Move virtual time forward by ``dt`` seconds (only for ``virtual=True``)."""
        if not self.virtual:
            raise RuntimeError("advance() is only meaningful for a virtual SilentClock")
        self._virtual_now += max(0.0, float(dt))

    # -- transport -------------------------------------------------------------------------------
    def play(self, clip: Any, start_s: float = 0.0, *, duration_s: float | None = None) -> None:
        """Start (or restart) playback of ``clip`` (only its duration matters) at ``start_s``."""
        self._duration = float(duration_s) if duration_s is not None else clip_duration(clip)
        self._start_s = min(max(0.0, float(start_s)), self._duration)
        self._anchor = self._now()
        self._paused_at = None
        self._active = True

    def pause(self) -> None:
        if self._active and self._paused_at is None:
            self._paused_at = self.position_s()

    def resume(self) -> None:
        if self._active and self._paused_at is not None:
            self._start_s, self._anchor, self._paused_at = self._paused_at, self._now(), None

    def stop(self) -> None:
        self._active = False
        self._paused_at = None
        self._start_s = 0.0

    def replay(self) -> None:
        self.play(None, 0.0, duration_s=self._duration)

    def position_s(self) -> float:
        if not self._active:
            return self._start_s
        if self._paused_at is not None:
            return self._paused_at
        return min(self._duration, self._start_s + (self._now() - float(self._anchor)))

    def position_ahead_s(self, ahead_s: float) -> float:
        """Clip time ``ahead_s`` seconds from now: time runs from :meth:`play` on, so while playing it is the
        position now plus ``ahead_s`` (not held at the end: the caller bounds it by the clip)."""
        pos = self.position_s()
        return pos + max(0.0, float(ahead_s)) if self._active and self._paused_at is None else pos

    # -- state -----------------------------------------------------------------------------------
    @property
    def duration_s(self) -> float:
        return self._duration

    @property
    def playing(self) -> bool:
        return self._active and self._paused_at is None and not self.finished

    @property
    def started(self) -> bool:
        """Time runs from the moment of :meth:`play` (there is no device to wait for)."""
        return self._active

    @property
    def paused(self) -> bool:
        return self._active and self._paused_at is not None

    @property
    def finished(self) -> bool:
        return self._active and self.position_s() >= self._duration

    @property
    def output_latency_s(self) -> float:
        return 0.0

    def close(self) -> None:
        self.stop()
