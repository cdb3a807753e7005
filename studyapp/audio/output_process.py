"""The audio output stream in a process of its own, with its clock in shared memory.

Why: PortAudio calls the stream callback on its own thread, but a Python callback needs the interpreter
lock, and the render thread holds that lock for the whole of a long GL call (moderngl does not release
it; on llvmpipe one frame under load is hundreds of milliseconds). The device then ran dry and the
audio clock, anchored by the callbacks, fell behind the sound: 1 % of frames within one frame of the
audio at a load of twice the core count. In a child process (``spawn``: no GL state, no threads
inherited) the callback never waits for the parent.

Protocol: the parent (:class:`~studyapp.audio.playback.AudioPlayer`) sends commands on a pipe --
``("load", samples)`` (float32 ``(N, channels)``), ``("start", first_sample, gen)``, ``("halt", gen)``,
``("close",)`` -- and reads the clock from :class:`SharedClock`, which the callback writes: the run
(``gen``) and first clip sample of the last buffer that carried clip samples, its length, and the
``time.monotonic()`` at which it reaches the DAC (the callback's ``outputBufferDacTime`` moved onto the
monotonic clock both processes share), plus counters. The child resolves the device itself
(:func:`~studyapp.audio.playback.resolve_device`: the parent never loads PortAudio, 0.3 s of a participant's
start) and, after opening the stream, answers ``("ok", reported_latency_s, device, rate, channels)`` (``device``
an :class:`~studyapp.audio.playback.OutputDevice`) or ``("error", message)``, a message for the participant.

The child imports only this module, :mod:`studyapp.audio.playback` (numpy, no scipy until a clip needs
resampling, which only the parent does) and ``sounddevice``: it starts while the parent loads the study
(``studyapp run``), so anything else it imported would slow the participant's start on a 2-core machine.
"""
from __future__ import annotations

import threading
import time
from multiprocessing import shared_memory
from typing import Any

import numpy as np

# slots of the shared float64 array
SEQ, GEN, FIRST, DAC, FRAMES, READ, CALLBACKS, FRAMES_TOTAL, UNDERFLOWS, LATENCY, ALIVE = range(11)
N_SLOTS = 16


class SharedClock:
    """A few float64 numbers in shared memory, written by one process and read by another.

    Writes happen inside :meth:`write` (a sequence lock: the sequence number is odd while writing), so a
    reader never sees half of an update (:meth:`snapshot` retries)."""

    def __init__(self, name: str | None = None) -> None:
        self.shm = shared_memory.SharedMemory(name=name, create=name is None, size=8 * N_SLOTS)
        self.owner = name is None
        self.a = np.ndarray((N_SLOTS,), np.float64, buffer=self.shm.buf)
        if self.owner:
            self.a[:] = 0.0
            self.a[GEN] = -1.0

    @property
    def name(self) -> str:
        return self.shm.name

    def write(self, **values: float) -> None:
        a = self.a
        a[SEQ] += 1.0
        for key, v in values.items():
            a[_SLOT[key]] = v
        a[SEQ] += 1.0

    def snapshot(self) -> np.ndarray:
        for _ in range(1000):
            s0 = self.a[SEQ]
            out = self.a.copy()
            if s0 % 2 == 0 and self.a[SEQ] == s0:
                return out
        return self.a.copy()

    def close(self) -> None:
        self.a = None  # type: ignore[assignment]
        self.shm.close()
        if self.owner:
            self.shm.unlink()


_SLOT = {"gen": GEN, "first": FIRST, "dac": DAC, "frames": FRAMES, "read": READ, "callbacks": CALLBACKS,
         "frames_total": FRAMES_TOTAL, "underflows": UNDERFLOWS, "latency": LATENCY, "alive": ALIVE}


def run_output(conn: Any, shm_name: str, device: int | str | None, samplerate: float | None, channels: int,
               latency: Any) -> None:
    """Child process body: find the device, open the stream, answer, then serve commands until ``close`` or EOF."""
    from studyapp.audio.playback import AudioDeviceError, resolve_device  # playback imports this module

    clock = SharedClock(shm_name)
    try:
        info = resolve_device(device)
    except AudioDeviceError as exc:
        _answer(conn, ("error", str(exc)))
        clock.close()
        return
    rate = int(samplerate or info.default_samplerate or 48000)
    channels = max(1, min(int(channels), info.max_output_channels))
    lock = threading.Lock()
    state: dict[str, Any] = {"buf": np.zeros((0, channels), np.float32), "read": 0, "running": False, "gen": -1,
                             "callbacks": 0, "frames_total": 0, "underflows": 0}
    latencies: list[float] = []

    def callback(outdata: np.ndarray, frames: int, time_info: Any, status: Any) -> None:
        mono = time.monotonic()
        with lock:
            state["callbacks"] += 1
            state["frames_total"] += frames
            if status and status.output_underflow:
                state["underflows"] += 1
            running, gen, start, buf = state["running"], state["gen"], state["read"], state["buf"]
            n = 0
            if running:
                n = max(0, min(frames, len(buf) - start))
                outdata[:n] = buf[start:start + n]
                state["read"] = start + n
        outdata[n:] = 0.0
        dac = float(time_info.outputBufferDacTime)
        now = float(time_info.currentTime)
        if dac <= 0.0 or now <= 0.0:  # some host APIs leave them unset: the reported latency instead
            ahead = float(stream.latency)
        else:
            ahead = dac - now
            if len(latencies) < 4096:
                latencies.append(ahead)
        values = {"callbacks": state["callbacks"], "frames_total": state["frames_total"],
                  "underflows": state["underflows"], "read": state["read"]}
        if latencies and state["callbacks"] % 16 == 1:
            values["latency"] = float(np.median(latencies))
        if running and n > 0:  # anchor the clock only on buffers that carry clip samples
            values.update(gen=gen, first=start, dac=mono + ahead, frames=n)
        clock.write(**values)

    try:
        import sounddevice as sd

        stream = sd.OutputStream(samplerate=rate, channels=channels, dtype="float32", device=info.index,
                                 latency=latency, callback=callback)
        stream.start()
    except Exception as exc:  # reported to the parent, which raises AudioDeviceError
        _answer(conn, ("error", f"could not open audio output {info.name!r}: {exc}"))
        clock.close()
        return
    try:
        if not _answer(conn, ("ok", float(stream.latency), info, rate, channels)):
            return  # the parent is gone already (it ended before the stream was open)
        while True:
            try:
                msg = conn.recv()
            except (EOFError, OSError):  # the parent is gone
                break
            cmd = msg[0]
            if cmd == "load":
                with lock:
                    state["buf"] = msg[1]
            elif cmd == "start":
                with lock:
                    state["read"], state["gen"], state["running"] = int(msg[1]), int(msg[2]), True
            elif cmd == "halt":
                with lock:
                    state["running"], state["gen"] = False, int(msg[1])
            elif cmd == "close":
                break
    finally:
        stream.stop()
        stream.close()
        clock.write(alive=0.0)
        clock.close()


def _answer(conn: Any, msg: tuple) -> bool:
    """Send ``msg`` to the parent; False when the parent is gone (a start that ended early)."""
    try:
        conn.send(msg)
        return True
    except (OSError, ValueError):
        return False
