"""Pipelined H.264 encoding of frames read back from OpenGL: frame N+1 is drawn while frame N is encoded.

:class:`PipelinedEncoder` owns a fixed pool of ``depth`` read-back buffers (``(H, W, 4) uint8`` RGBA, OpenGL
row order: bottom row first; RGBA because Mesa reads it back with a plain copy, about 3x faster than packing
RGB) and one encoder thread. The drawing thread takes a free buffer with
:meth:`~PipelinedEncoder.acquire`, reads the frame into it (no allocation per frame) and hands it over with
:meth:`~PipelinedEncoder.submit`; the encoder thread turns it right side up into its one reused RGBA frame,
encodes it (PyAV converts to yuv420p and runs x264 with the GIL released) and muxes the packets, then gives
the buffer back. When the encoder is ``depth`` frames behind, :meth:`acquire` waits: memory stays bounded.

Frames are encoded in submission order with ``pts`` = frame index in a ``1/fps`` time base, so the file
holds exactly the frames drawn, in order. An error in the encoder thread is raised in the drawing thread
at its next :meth:`acquire` or at :meth:`close` (the thread keeps returning buffers, so nothing hangs).

:data:`SETTINGS` is the one place that says how studyapp encodes video.

>>> import av, tempfile, os, numpy as np
>>> path = os.path.join(tempfile.mkdtemp(), "grey.mp4")
>>> with av.open(path, "w") as container:
...     enc = PipelinedEncoder(container, open_video_stream(container, (64, 48), 10), depth=2)
...     for k in range(5):
...         buf = enc.acquire(); buf[:] = 100; enc.submit(buf)
...     enc.close()
>>> with av.open(path) as f: [fr.pts for fr in f.decode(video=0)] == [k * f.streams.video[0].time_base.denominator // 10 for k in range(5)]
True
"""
from __future__ import annotations

import queue
import threading
from dataclasses import dataclass
from fractions import Fraction
from typing import Any

import numpy as np


@dataclass(frozen=True)
class EncoderSettings:
    """How a video stream is encoded.

    ``preset="superfast"``: at 720p it encodes about 1.5-2x as fast as ``veryfast`` for the flat-shaded
    figures on a gradient studyapp draws, at a visually equal picture (``crf`` keeps the quality constant;
    the file is somewhat larger). ``yuv420p`` because every player and browser decodes it.
    """

    codec: str = "libx264"
    crf: int = 20
    preset: str = "superfast"
    pix_fmt: str = "yuv420p"


SETTINGS = EncoderSettings()


def open_video_stream(container: Any, size: tuple[int, int], fps: int, settings: EncoderSettings = SETTINGS) -> Any:
    """Add the H.264 stream of ``settings`` (``size`` must be even for yuv420p) to an open PyAV container."""
    stream = container.add_stream(settings.codec, rate=Fraction(int(fps), 1))
    stream.width, stream.height = int(size[0]), int(size[1])
    stream.pix_fmt = settings.pix_fmt
    stream.codec_context.time_base = Fraction(1, int(fps))
    stream.options = {"crf": str(settings.crf), "preset": settings.preset}
    return stream


_STOP = None


class PipelinedEncoder:
    """Encode frames on a thread of its own from a bounded pool of reused read-back buffers (see module)."""

    def __init__(self, container: Any, stream: Any, depth: int = 3) -> None:
        import av

        if depth < 1:
            raise ValueError(f"depth must be at least 1, got {depth}")
        self.container = container
        self.stream = stream
        self.size = (int(stream.width), int(stream.height))
        w, h = self.size
        self.buffers = [np.empty((h, w, 4), np.uint8) for _ in range(depth)]
        self._free: queue.Queue[np.ndarray] = queue.Queue()
        for buf in self.buffers:
            self._free.put(buf)
        self._work: queue.Queue[np.ndarray | None] = queue.Queue()
        # The one RGBA frame the encoder thread fills: PyAV converts it to a new yuv420p frame inside
        # encode(), so it is free again as soon as encode() returns.
        self._frame = av.VideoFrame(w, h, "rgba")
        plane = self._frame.planes[0]
        self._rgba = np.frombuffer(plane, np.uint8).reshape(h, plane.line_size)[:, : w * 4].reshape(h, w, 4)
        self._error: BaseException | None = None
        self.frames = 0
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="studyapp-encoder", daemon=True)
        self._thread.start()

    def acquire(self) -> np.ndarray:
        """A free ``(H, W, 4)`` RGBA buffer to read the next frame into, bottom row first (waits while full)."""
        buf = self._free.get()
        if self._error is not None:
            self._free.put(buf)
            self._raise()
        return buf

    def submit(self, buf: np.ndarray) -> None:
        """Hand over a buffer from :meth:`acquire`, now holding the next frame."""
        self._work.put(buf)

    def close(self) -> None:
        """Encode what is queued, flush the encoder into the container and stop the thread."""
        if self._closed:
            return
        self._closed = True
        self._work.put(_STOP)
        self._thread.join()
        if self._error is None:
            try:
                for packet in self.stream.encode():
                    self.container.mux(packet)
            except BaseException as exc:  # noqa: BLE001 - re-raised below, as an encoder thread error would be
                self._error = exc
        self._raise()

    def abort(self) -> None:
        """Stop without flushing (the drawing side failed; its error is the one to report)."""
        if not self._closed:
            self._closed = True
            self._work.put(_STOP)
            self._thread.join()

    def _raise(self) -> None:
        if self._error is not None:
            raise self._error

    def _run(self) -> None:
        while True:
            buf = self._work.get()
            if buf is _STOP:
                return
            try:
                if self._error is None:
                    np.copyto(self._rgba, buf[::-1])  # OpenGL's rows run bottom to top
                    self._frame.pts = self.frames
                    for packet in self.stream.encode(self._frame):
                        self.container.mux(packet)
                    self.frames += 1
            except BaseException as exc:  # noqa: BLE001 - handed to the drawing thread, which raises it
                self._error = exc
            finally:
                self._free.put(buf)
