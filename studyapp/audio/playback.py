"""Audio output whose stream clock is the master clock of a trial.

:class:`AudioPlayer` keeps one callback-driven ``sounddevice.OutputStream`` open for its whole life
(silence between clips), because opening a stream costs time and PulseAudio delivers few callbacks for
the first second after a stream starts. Its :meth:`AudioPlayer.position_s` is the clip time that is
*audible right now*: the samples handed to the device so far, divided by the rate, minus the output
latency. Each callback tells us which clip sample starts its buffer and the stream time at which that
buffer reaches the DAC (``outputBufferDacTime``); between callbacks the position is interpolated with
the stream's own clock (``Stream.time``), so it moves smoothly instead of in block-sized steps and
never drifts from the audio hardware.

When no device is present, :func:`open_clock` returns a :class:`~studyapp.audio.clock.SilentClock`
and a message saying so, so a study can still run (silently) and the experimenter can pick a device
with ``--audio-device``.

Example (needs an output device, e.g. the null PulseAudio sink of ``.ci/start-null-audio.sh``)::

    player = AudioPlayer()             # default device; AudioPlayer("NullSink") or AudioPlayer(3)
    player.play(clip)                  # clip: studyapp.audio.wav.AudioClip (samples (N, C), sample_rate)
    t = player.position_s()            # draw the frame for this time
"""
from __future__ import annotations

import logging
import math
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np

from studyapp.audio.clock import SilentClock
from studyapp.errors import StudyappError

log = logging.getLogger(__name__)


class AudioDeviceError(StudyappError):
    """No usable audio output device (or the one asked for does not exist)."""


@dataclass(frozen=True)
class OutputDevice:
    """One audio output as PortAudio reports it."""

    index: int
    name: str
    hostapi: str
    max_output_channels: int
    default_samplerate: float
    default_low_latency_s: float
    default_high_latency_s: float
    is_default: bool


@dataclass(frozen=True)
class Pcm:
    """Minimal audio clip (same fields as ``studyapp.audio.wav.AudioClip``), e.g. for the test tone."""

    samples: np.ndarray  # (N, C) float32
    sample_rate: int
    source: str = ""

    @property
    def duration(self) -> float:
        return len(self.samples) / float(self.sample_rate)


def sound_check_tone(freq_hz: float = 440.0, duration_s: float = 0.6, sample_rate: int = 48000,
              level: float = 0.3) -> Pcm:
    """A sine beep with 20 ms fades (no clicks), for the sound check.

    >>> tone = sound_check_tone(1000.0, 0.5, 8000)
    >>> tone.samples.shape, round(float(abs(tone.samples).max()), 2)
    ((4000, 1), 0.3)
    """
    n = int(round(duration_s * sample_rate))
    t = np.arange(n) / sample_rate
    env = np.clip(np.minimum(t, duration_s - t) / 0.02, 0.0, 1.0)
    wave = (level * env * np.sin(2 * np.pi * freq_hz * t)).astype(np.float32)
    return Pcm(wave[:, None], int(sample_rate), source=f"test tone {freq_hz:g} Hz")


def list_output_devices() -> list[OutputDevice]:
    """Every device with output channels (empty when PortAudio sees none or is missing)."""
    try:
        import sounddevice as sd
    except OSError as exc:  # libportaudio missing: treat as "no device", the caller says so
        log.debug("sounddevice unavailable: %s", exc)
        return []
    try:
        devices = sd.query_devices()
        hostapis = sd.query_hostapis()
        default_out = sd.default.device[1]
    except Exception as exc:  # PortAudio errors on broken setups; no device is the honest answer
        log.debug("query_devices failed: %s", exc)
        return []
    if default_out is None or default_out < 0:
        try:
            default_out = sd.query_devices(kind="output")["index"]
        except Exception:
            default_out = -1
    out = []
    for d in devices:
        if d["max_output_channels"] <= 0:
            continue
        out.append(OutputDevice(
            index=int(d["index"]), name=str(d["name"]), hostapi=str(hostapis[d["hostapi"]]["name"]),
            max_output_channels=int(d["max_output_channels"]),
            default_samplerate=float(d["default_samplerate"]),
            default_low_latency_s=float(d["default_low_output_latency"]),
            default_high_latency_s=float(d["default_high_output_latency"]),
            is_default=int(d["index"]) == int(default_out),
        ))
    return out


def resolve_device(device: int | str | None, devices: list[OutputDevice] | None = None) -> OutputDevice:
    """The output device given by index, by (case-insensitive, partial) name, or the default (None).

    Raises :class:`AudioDeviceError` that lists the available outputs when there is no match.
    """
    devices = list_output_devices() if devices is None else devices
    if not devices:
        raise AudioDeviceError(
            "no audio output device found: the study would play without sound. Connect headphones or "
            "speakers (or start a sound server) and check with `studyapp doctor`."
        )
    listing = "; ".join(f"{d.index}: {d.name}" for d in devices)
    if device is None:
        for d in devices:
            if d.is_default:
                return d
        return devices[0]
    if isinstance(device, int) or (isinstance(device, str) and device.strip().isdigit()):
        idx = int(device)
        for d in devices:
            if d.index == idx:
                return d
        raise AudioDeviceError(f"no audio output device with index {idx}; outputs are: {listing}")
    want = str(device).strip().lower()
    exact = [d for d in devices if d.name.lower() == want]
    partial = [d for d in devices if want in d.name.lower()]
    hits = exact or partial
    if len(hits) == 1 or exact:
        return hits[0]
    if not hits:
        raise AudioDeviceError(f"no audio output device named like {device!r}; outputs are: {listing}")
    raise AudioDeviceError(f"audio device name {device!r} is ambiguous ({', '.join(d.name for d in hits)}); "
                           f"give its index instead. Outputs are: {listing}")


def _to_stream_format(clip: Any, rate: int, channels: int) -> np.ndarray:
    """Clip samples as contiguous float32 ``(N, channels)`` at ``rate`` (resampled, channels mapped)."""
    samples = np.asarray(clip.samples, dtype=np.float32)
    if samples.ndim == 1:
        samples = samples[:, None]
    src_rate = int(clip.sample_rate)
    if src_rate != rate:
        from scipy.signal import resample_poly

        g = math.gcd(src_rate, rate)
        samples = resample_poly(samples, rate // g, src_rate // g, axis=0).astype(np.float32)
    if samples.shape[1] == channels:
        out = samples
    elif samples.shape[1] == 1:
        out = np.repeat(samples, channels, axis=1)
    elif samples.shape[1] > channels:
        out = samples[:, :channels] if channels > 1 else samples.mean(axis=1, keepdims=True)
    else:  # fewer channels than the device: repeat the last one
        out = np.concatenate([samples] + [samples[:, -1:]] * (channels - samples.shape[1]), axis=1)
    return np.ascontiguousarray(np.clip(out, -1.0, 1.0), dtype=np.float32)


class AudioPlayer:
    """Plays clips on one output device; its stream clock is the trial's master clock.

    Parameters
    ----------
    device:
        Index, (part of a) name, or None for the system default (see :func:`list_output_devices`).
    samplerate:
        Stream rate; default: the device's default rate (clips are resampled to it once per play).
    channels:
        Output channels (clips are up/down-mixed), at most the device's.
    latency:
        PortAudio latency hint (``"low"``, ``"high"`` or seconds). Low latency keeps the sound-to-picture
        delay short; the measured latency is compensated either way.
    """

    def __init__(self, device: int | str | None = None, *, samplerate: float | None = None,
                 channels: int = 2, latency: str | float = 0.1) -> None:
        import sounddevice as sd

        info = resolve_device(device)
        self.device = info
        self.device_name = info.name
        self.rate = int(samplerate or info.default_samplerate or 48000)
        self.channels = max(1, min(int(channels), info.max_output_channels))
        self._lock = threading.Lock()
        self._buf = np.zeros((0, self.channels), np.float32)
        self._read = 0            # next clip sample to hand to the device
        self._running = False     # delivering clip samples (not paused, not stopped)
        self._active = False      # a clip is loaded and was started
        self._gen = 0             # bumps on play/resume so stale timing from older buffers is ignored
        self._start_s = 0.0       # position shown until the first buffer of this run reaches the callback
        self._paused_at: float | None = None
        self._last: tuple[int, int, float, int] | None = None  # (gen, first sample, dac time, frames)
        self._latencies: list[float] = []
        self._converted: tuple | None = None  # (key, clip, stream-format samples) of the last clip played
        self.callbacks = 0
        self.frames_total = 0     # frames the device asked for since the stream started (pacing check)
        self.underflows = 0
        try:
            self._stream = sd.OutputStream(
                samplerate=self.rate, channels=self.channels, dtype="float32", device=info.index,
                latency=latency, callback=self._callback,
            )
            self._stream.start()
        except Exception as exc:
            raise AudioDeviceError(f"could not open audio output {info.name!r}: {exc}") from exc

    # -- audio thread ----------------------------------------------------------------------------
    def _callback(self, outdata: np.ndarray, frames: int, time_info: Any, status: Any) -> None:
        self.callbacks += 1
        self.frames_total += frames
        if status and status.output_underflow:
            self.underflows += 1
        with self._lock:
            running, gen, start = self._running, self._gen, self._read
            n = 0
            if running:
                n = max(0, min(frames, len(self._buf) - start))
                outdata[:n] = self._buf[start:start + n]
                self._read = start + n
        outdata[n:] = 0.0
        dac = float(time_info.outputBufferDacTime)
        now = float(time_info.currentTime)
        if dac <= 0.0:  # some host APIs leave it unset; fall back to the reported latency
            dac = now + float(self._stream.latency)
        elif now > 0.0 and len(self._latencies) < 4096:
            self._latencies.append(dac - now)
        if running and n > 0:  # anchor the clock only on buffers that carry clip samples
            self._last = (gen, start, dac, n)

    # -- clock -----------------------------------------------------------------------------------
    def position_s(self) -> float:
        """Clip time (seconds) audible now: delivered samples / rate minus the output latency."""
        if not self._active:
            return self._start_s
        if self._paused_at is not None:
            return self._paused_at
        last = self._last
        if last is None or last[0] != self._gen:
            return self._start_s  # the device has not asked for this run's first buffer yet
        _, first, dac, frames = last
        pos = first / self.rate + (float(self._stream.time) - dac)
        # Never ahead of what was delivered, never before where this run started.
        pos = min(pos, (first + frames) / self.rate)
        return float(min(max(pos, self._start_s), self.duration_s))

    @property
    def delivered_s(self) -> float:
        """Clip time handed to the device so far (ahead of what is audible by the output latency)."""
        return self._read / float(self.rate)

    @property
    def started(self) -> bool:
        """The device has taken this run's first samples: the clock moves with the sound from now on
        (before that, frames show the start and there is nothing to be in sync with yet)."""
        last = self._last
        return self._active and last is not None and last[0] == self._gen

    @property
    def output_latency_s(self) -> float:
        """Measured delay from callback to DAC (median), or PortAudio's reported latency before any."""
        if self._latencies:
            return float(np.median(self._latencies))
        return float(self._stream.latency)

    @property
    def reported_latency_s(self) -> float:
        return float(self._stream.latency)

    # -- transport -------------------------------------------------------------------------------
    def play(self, clip: Any, start_s: float = 0.0, *, duration_s: float | None = None) -> None:
        """Play ``clip`` (``samples`` (N[, C]) + ``sample_rate``) from ``start_s`` seconds."""
        key = (id(clip), duration_s)
        if self._converted is not None and self._converted[0] == key and self._converted[1] is clip:
            buf = self._converted[2]  # a replay: no second resampling of the same clip
        else:
            buf = self._prepare(clip, duration_s)
            self._converted = (key, clip, buf)
        with self._lock:
            self._buf = buf
            self._start_pos(start_s)

    def _prepare(self, clip: Any, duration_s: float | None) -> np.ndarray:
        buf = _to_stream_format(clip, self.rate, self.channels)
        if duration_s is not None:  # align the audio to the trial length (silence pads, extra is cut)
            n = int(round(duration_s * self.rate))
            buf = buf[:n] if len(buf) >= n else np.concatenate([buf, np.zeros((n - len(buf), self.channels), np.float32)])
        return buf

    def _start_pos(self, start_s: float) -> None:
        # caller holds the lock
        start = min(max(0.0, float(start_s)), self.duration_s)
        self._read = int(round(start * self.rate))
        self._start_s = self._read / self.rate
        self._paused_at = None
        self._gen += 1
        self._active = True
        self._running = True

    def pause(self) -> None:
        """Freeze the clock at the audible position (the last ~latency of sound still plays out)."""
        if self._active and self._paused_at is None:
            pos = self.position_s()
            with self._lock:
                self._running = False
                self._paused_at = pos

    def resume(self) -> None:
        """Continue from where the picture stopped (re-plays the few ms heard after pausing)."""
        if self._active and self._paused_at is not None:
            with self._lock:
                self._start_pos(self._paused_at)

    def stop(self) -> None:
        with self._lock:
            self._running = False
            self._active = False
            self._paused_at = None
            self._start_s = 0.0
            self._gen += 1

    def replay(self) -> None:
        with self._lock:
            self._start_pos(0.0)

    @property
    def duration_s(self) -> float:
        return len(self._buf) / float(self.rate)

    @property
    def playing(self) -> bool:
        return self._active and self._paused_at is None and not self.finished

    @property
    def paused(self) -> bool:
        return self._active and self._paused_at is not None

    @property
    def finished(self) -> bool:
        return self._active and self._paused_at is None and self.position_s() >= self.duration_s

    def wait_until_flowing(self, timeout_s: float = 4.0, window_s: float = 0.2) -> bool:
        """Block until the device consumes samples at (about) its rate.

        A fresh PulseAudio stream pre-fills a buffer and then asks for little for up to ~1.5 s; a
        clip started then would begin late (correctly followed by the picture, but needlessly).
        """
        import time

        t_end = time.monotonic() + timeout_s
        while time.monotonic() < t_end:
            f0 = self.frames_total
            time.sleep(window_s)
            if self.frames_total - f0 >= 0.7 * window_s * self.rate:
                return True
        return False

    def close(self) -> None:
        stream = getattr(self, "_stream", None)
        if stream is not None:
            try:
                stream.stop()
                stream.close()
            finally:
                self._stream = None

    def __enter__(self) -> "AudioPlayer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_clock(device: int | str | None = None, *, required: bool = False) -> tuple[Any, str]:
    """The master clock for a session and a one-line description for the experimenter.

    With an output device: an :class:`AudioPlayer`. Without one (and ``required`` False): a
    :class:`SilentClock` and a message that says the study will be silent and how to pick a device.
    A device that was asked for by name/index but does not exist is always an error.
    """
    try:
        player = AudioPlayer(device)
    except AudioDeviceError as exc:
        if required or device is not None:
            raise
        return SilentClock(reason="no audio output device"), (
            f"WARNING: {exc} Choose an output with --audio-device (see `studyapp doctor`)."
        )
    return player, f"audio output: {player.device_name} (its latency is measured and compensated)"
