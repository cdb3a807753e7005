"""Audio output whose stream clock is the master clock of a trial.

:class:`AudioPlayer` keeps one callback-driven ``sounddevice.OutputStream`` open for its whole life
(silence between clips), because opening a stream costs time and PulseAudio delivers few callbacks for
the first second after a stream starts. The stream and its callback live in a process of their own
(:mod:`studyapp.audio.output_process`), so the callback never waits for this interpreter's lock, which
the render thread holds through long GL calls on a software renderer. Its
:meth:`AudioPlayer.position_s` is the clip time that is *audible right now*: the samples handed to the
device so far, divided by the rate, minus the output latency. Each callback publishes which clip
sample starts its buffer and when that buffer reaches the DAC (``outputBufferDacTime``, moved onto
``time.monotonic``, which both processes share); between callbacks the position is interpolated with
that clock, so it moves smoothly instead of in block-sized steps and never drifts from the audio
hardware.

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
from studyapp.audio.output_process import (
    CALLBACKS, DAC, FIRST, FRAMES, FRAMES_TOTAL, GEN, LATENCY, READ, UNDERFLOWS, SharedClock, run_output,
)
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
        from studyapp.audio.dsp import resample_poly  # scipy's, in numpy: a participant's install has no scipy

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

    wait:
        True: return once the stream is open (or raise :class:`AudioDeviceError`). False: return as soon as
        the output process is started, so the caller loads its study meanwhile; :meth:`ready` then waits
        for it (and raises). ``device``, ``device_name``, ``rate`` and ``channels`` are known from then.

    The stream lives in a child process started with ``multiprocessing``'s ``spawn`` (opening takes
    about half a second more, which ``wait=False`` overlaps with the caller's work); as with any spawned
    process, a script that makes a player must keep its top-level code under ``if __name__ == "__main__":``
    (the ``studyapp`` command does).
    """

    def __init__(self, device: int | str | None = None, *, samplerate: float | None = None,
                 channels: int = 2, latency: str | float = 0.1, wait: bool = True) -> None:
        import multiprocessing as mp

        self._proc = None
        self._opened = False
        self.device: OutputDevice | None = None
        self.device_name = "default output" if device is None else str(device)  # until the child says
        self.rate = int(samplerate or 48000)
        self.channels = max(1, int(channels))
        self._lock = threading.Lock()  # commands to the output process go out in the order they were made
        self._buf = np.zeros((0, self.channels), np.float32)
        self._read = 0            # first clip sample of the current run
        self._active = False      # a clip is loaded and was started
        self._gen = 0             # bumps on play/resume/stop so stale timing from older buffers is ignored
        self._start_s = 0.0       # position shown until the first buffer of this run reaches the callback
        self._paused_at: float | None = None
        self._converted: tuple | None = None  # (key, clip, stream-format samples) of the last clip played
        self._loaded: np.ndarray | None = None  # the samples the output process holds
        # The stream runs in a process of its own (studyapp.audio.output_process): its callback must
        # not wait for this interpreter's lock, which the render thread holds during long GL calls.
        self._clock = SharedClock()
        spawn = mp.get_context("spawn")
        self._conn, child = spawn.Pipe()
        # the child finds the device itself (studyapp.audio.output_process): no PortAudio in this process
        proc = spawn.Process(target=run_output, name="studyapp-audio", daemon=True,
                             args=(child, self._clock.name, device, samplerate, int(channels), latency))
        proc.start()
        self._proc = proc
        child.close()
        self._reported_latency = 0.0
        if wait:
            self.ready()

    def ready(self) -> "AudioPlayer":
        """Wait until the output process has opened the stream; raises :class:`AudioDeviceError` (and ends
        that process) when it could not."""
        if self._opened:
            return self
        if self._proc is None:
            raise AudioDeviceError("the audio output was closed before it was opened")
        try:
            ready = self._conn.recv() if self._conn.poll(30.0) else ("error", "the audio output did not open within 30 s")
        except EOFError:
            ready = ("error", f"the audio process ended (exit code {self._proc.exitcode})")
        if ready[0] != "ok":
            self._shutdown()
            raise AudioDeviceError(ready[1])
        _, latency, self.device, self.rate, self.channels = ready
        self.device_name = self.device.name
        self._buf = np.zeros((0, self.channels), np.float32)
        self._reported_latency = float(latency)
        self._opened = True
        return self

    def _send(self, *msg: Any) -> None:
        self._conn.send(msg)

    @property
    def callbacks(self) -> int:
        return int(self._clock.snapshot()[CALLBACKS])

    @property
    def frames_total(self) -> int:
        """Frames the device asked for since the stream started (pacing check)."""
        return int(self._clock.snapshot()[FRAMES_TOTAL])

    @property
    def underflows(self) -> int:
        return int(self._clock.snapshot()[UNDERFLOWS])

    def _anchor(self) -> tuple[int, int, float, int] | None:
        """(gen, first sample, monotonic DAC time, frames) of the last buffer that carried clip samples."""
        a = self._clock.snapshot()
        if a[GEN] < 0:
            return None
        return int(a[GEN]), int(a[FIRST]), float(a[DAC]), int(a[FRAMES])

    # -- clock -----------------------------------------------------------------------------------
    def position_s(self) -> float:
        """Clip time (seconds) audible now: delivered samples / rate minus the output latency."""
        return self._position(0.0, delivered_only=True)

    def position_ahead_s(self, ahead_s: float) -> float:
        """Clip time (seconds) audible ``ahead_s`` seconds from now, if the sound keeps flowing. Before the
        first samples reach the speaker (an output latency after the device took them) the sound is at the
        start, so a frame aimed at a flip in that time shows the start: extrapolating the standing clock
        by the time to the flip put the first frames of every play up to a drawing time (~50-80 ms on a
        loaded software renderer) ahead of the sound."""
        return self._position(max(0.0, float(ahead_s)), delivered_only=False)

    def _position(self, ahead_s: float, *, delivered_only: bool) -> float:
        import time

        if not self._active:
            return self._start_s
        if self._paused_at is not None:
            return self._paused_at
        last = self._anchor()
        if last is None or last[0] != self._gen:
            return self._start_s  # the device has not asked for this run's first buffer yet
        _, first, dac, frames = last
        pos = first / self.rate + (time.monotonic() + ahead_s - dac)
        if delivered_only:  # now: never ahead of what was delivered (later, more will have been)
            pos = min(pos, (first + frames) / self.rate)
        # Never before where this run started.
        return float(min(max(pos, self._start_s), self.duration_s))

    @property
    def delivered_s(self) -> float:
        """Clip time handed to the device so far (ahead of what is audible by the output latency)."""
        if not self._active:
            return self._start_s
        last = self._anchor()
        if self._paused_at is not None or last is None or last[0] != self._gen:
            return self._read / float(self.rate)
        return self._clock.snapshot()[READ] / float(self.rate)

    @property
    def started(self) -> bool:
        """The device has taken this run's first samples: the clock moves with the sound from now on
        (before that, frames show the start and there is nothing to be in sync with yet)."""
        last = self._anchor()
        return self._active and last is not None and last[0] == self._gen

    @property
    def output_latency_s(self) -> float:
        """Measured delay from callback to DAC (median), or PortAudio's reported latency before any."""
        measured = float(self._clock.snapshot()[LATENCY])
        return measured if measured > 0 else self._reported_latency

    @property
    def reported_latency_s(self) -> float:
        return self._reported_latency

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
            if self._loaded is not buf:
                self._send("load", buf)
                self._loaded = buf
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
        self._send("start", self._read, self._gen)

    def pause(self) -> None:
        """Freeze the clock at the audible position (the last ~latency of sound still plays out)."""
        if self._active and self._paused_at is None:
            pos = self.position_s()
            with self._lock:
                self._gen += 1
                self._send("halt", self._gen)
                self._paused_at = pos

    def resume(self) -> None:
        """Continue from where the picture stopped (re-plays the few ms heard after pausing)."""
        if self._active and self._paused_at is not None:
            with self._lock:
                self._start_pos(self._paused_at)

    def stop(self) -> None:
        with self._lock:
            self._active = False
            self._paused_at = None
            self._start_s = 0.0
            self._gen += 1
            self._send("halt", self._gen)

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
        """End the output process (also one still opening: a start that ended early leaves no process)."""
        if getattr(self, "_proc", None) is None:
            return
        try:
            self._send("close")
        except (OSError, ValueError):  # the process is gone already
            pass
        self._shutdown()

    def _shutdown(self) -> None:
        self._proc.join(5.0)
        if self._proc.is_alive():
            self._proc.terminate()
            self._proc.join(2.0)
        self._conn.close()
        self._clock.close()
        self._proc = None

    def __enter__(self) -> "AudioPlayer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class PendingClock:
    """A session's master clock whose audio output opens in its own process while the caller loads the study.

    ``studyapp run`` starts one before it reads the design, so the ~0.7 s the output process takes to start
    and open its stream overlaps with loading the design, the trial media and the scene. :meth:`result`
    waits for it and gives what :func:`open_clock` gives; :meth:`close` ends the output process whether or
    not it was opened or used (call it on every way out: an early exit leaves no process behind).
    """

    def __init__(self, device: int | str | None = None, *, required: bool = False) -> None:
        self.device = device
        self.required = required
        self.player = AudioPlayer(device, wait=False)
        self._result: tuple[Any, str] | None = None
        self._error: AudioDeviceError | None = None

    def done(self) -> bool:
        """The output process has answered (or ended): :meth:`result` returns at once."""
        p = self.player
        return self._result is not None or self._error is not None or p._opened or p._proc is None or p._conn.poll(0)

    def result(self) -> tuple[Any, str]:
        """``(clock, message)``: the opened :class:`AudioPlayer`, or a :class:`SilentClock` (see :func:`open_clock`).
        Raises :class:`AudioDeviceError` for a device asked for that cannot be opened (the same error each call)."""
        if self._error is not None:
            raise self._error
        if self._result is None:
            try:
                self.player.ready()
            except AudioDeviceError as exc:
                if self.required or self.device is not None:
                    self._error = exc
                    raise
                self._result = (SilentClock(reason="no audio output device"),
                                f"WARNING: {exc} Choose an output with --audio-device (see `studyapp doctor`).")
            else:
                self._result = (self.player, f"audio output: {self.player.device_name} "
                                             "(its latency is measured and compensated)")
        return self._result

    def close(self) -> None:
        self.player.close()


def open_clock(device: int | str | None = None, *, required: bool = False) -> tuple[Any, str]:
    """The master clock for a session and a one-line description for the experimenter.

    With an output device: an :class:`AudioPlayer`. Without one (and ``required`` False): a
    :class:`SilentClock` and a message that says the study will be silent and how to pick a device.
    A device that was asked for by name/index but does not exist is always an error.
    """
    return PendingClock(device, required=required).result()
