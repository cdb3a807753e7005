"""Offline output: MP4 videos (H.264 + AAC via PyAV) and PNG stills of a trial, rendered headless.

>>> import tempfile, pathlib
>>> from studyapp.render.avatar import build_default_avatar
>>> from studyapp.render.pose import prepare_slot
>>> from studyapp.render.scene import make_scene
>>> from studyapp.motion.skeleton import Motion
>>> av = build_default_avatar()
>>> scene = make_scene([prepare_slot(av, Motion.rest(av.skeleton, 3, 30.0), None)] * 3, av)
>>> out = pathlib.Path(tempfile.mkdtemp()) / "still.png"
>>> render_still(scene, 0.0, out, size=(192, 108)).shape
(108, 192, 3)
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from studyapp.audio.clock import SilentClock
from studyapp.render.context import create_offscreen_context, make_current
from studyapp.render.encode import SETTINGS, EncoderSettings, PipelinedEncoder, open_video_stream
from studyapp.render.loop import FrameLoop, OffscreenFrames, ScenePlayer, VirtualTimer
from studyapp.render.renderer import Renderer

_CONTEXT = None


def _shared_context():
    """One headless context per process: creating EGL contexts repeatedly is slow and leaks on some drivers."""
    global _CONTEXT
    if _CONTEXT is None:
        _CONTEXT = create_offscreen_context()
    # Another context (a window, a test's own) may have become current since: objects made now must land
    # in this one, or Mesa fails to create them ("cannot create program").
    make_current(_CONTEXT)
    return _CONTEXT


def _even(size: tuple[int, int]) -> tuple[int, int]:
    # yuv420p needs even dimensions
    return int(size[0]) // 2 * 2, int(size[1]) // 2 * 2


def render_frames(scene, times, size: tuple[int, int] = (1280, 720), renderer: Renderer | None = None):
    """Yield ``(H, W, 3) uint8`` frames of ``scene`` at the given times (headless).

    Each frame goes through the frame loop (:mod:`studyapp.render.loop`) with a virtual clock set to
    that time, exactly as :func:`render_video` and ``studyapp view --offscreen`` draw theirs.
    """
    ctx = renderer.ctx if renderer is not None else _shared_context()
    renderer = renderer or Renderer(ctx)
    target = OffscreenFrames(ctx, size)
    player = ScenePlayer(renderer, scene, SilentClock(virtual=True, reason="offscreen render"))
    loop = FrameLoop(target, VirtualTimer(30.0), player.draw, player.after_flip, capture=True)
    try:
        for t in times:
            player.start(float(t))
            loop.step()
            yield loop.last_rgb
    finally:
        target.release()


def play_frames(scene, fps: float, n_frames: int, size: tuple[int, int] = (1280, 720),
                renderer: Renderer | None = None, duration: float | None = None):
    """Yield the ``n_frames`` frames of one play of ``scene`` from its start, on a virtual clock that the
    frame loop moves by exactly ``1 / fps`` per frame (frame ``k`` shows time ``k / fps``)."""
    ctx = renderer.ctx if renderer is not None else _shared_context()
    renderer = renderer or Renderer(ctx)
    target = OffscreenFrames(ctx, size)
    loop = _play_loop(renderer, scene, target, fps, duration, capture=True)
    try:
        for _ in range(int(n_frames)):
            loop.step()
            yield loop.last_rgb
    finally:
        target.release()


def _play_loop(renderer: Renderer, scene, target, fps: float, duration: float | None, *,
               capture: bool = False) -> FrameLoop:
    """The frame loop of one play of ``scene`` from its start into ``target``, on a virtual clock that moves
    exactly ``1 / fps`` per frame (what :func:`play_frames` and :func:`render_video` both step)."""
    clock = SilentClock(virtual=True, reason="offscreen render")
    player = ScenePlayer(renderer, scene, clock, duration_s=duration)
    loop = FrameLoop(target, VirtualTimer(fps, clocks=[clock]), player.draw, player.after_flip, capture=capture)
    player.start(0.0)
    return loop


def render_still(scene, t: float, out_png: str | Path, size: tuple[int, int] = (1280, 720),
                 renderer: Renderer | None = None) -> np.ndarray:
    """Render one frame at ``t`` seconds to a PNG; returns the image ``(H, W, 3) uint8``."""
    import matplotlib.image as mpimg

    img = next(render_frames(scene, [t], size, renderer))
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    mpimg.imsave(out_png, img)
    return img


def render_video(scene, audio, out_path: str | Path, size: tuple[int, int] = (1280, 720), fps: int = 30,
                 renderer: Renderer | None = None, duration: float | None = None,
                 settings: EncoderSettings = SETTINGS) -> Path:
    """Write an MP4 (H.264 yuv420p, plus AAC audio when ``audio`` is an AudioClip) of the whole trial.

    The video lasts ``duration`` seconds (default: the longer of the motion and the audio); the audio is
    muxed from the start of the clip and cut at ``duration``, so picture and sound line up as they do in the
    study and a shortened video does not go on talking over a frozen last frame.

    The frames are those of :func:`play_frames` (the same frame loop, virtual clock and player); each is
    read back into a reused buffer and encoded on a thread of its own while the next one is drawn
    (:mod:`studyapp.render.encode`, whose ``SETTINGS`` say codec, crf, preset and pixel format).
    """
    import av

    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    size = _even(size)
    if duration is None:
        duration = scene.duration
        if audio is not None:
            duration = max(duration, len(audio.samples) / float(audio.sample_rate))
    n_frames = max(1, int(round(duration * fps)))
    with av.open(str(out_path), mode="w") as container:
        vstream = open_video_stream(container, size, fps, settings)
        astream = None
        if audio is not None:
            samples = np.asarray(audio.samples, np.float32)
            if samples.ndim == 1:
                samples = samples[:, None]
            layout = "mono" if samples.shape[1] == 1 else "stereo"
            samples = samples[: int(round(duration * float(audio.sample_rate))), :2]
            astream = container.add_stream("aac", rate=int(audio.sample_rate))
            astream.layout = layout
        ctx = renderer.ctx if renderer is not None else _shared_context()
        renderer = renderer or Renderer(ctx)
        encoder = PipelinedEncoder(container, vstream)
        target = None
        try:
            target = _EncoderTarget(ctx, size, encoder)
            _play_loop(renderer, scene, target, fps, duration).run(n_frames)
        except BaseException:
            encoder.abort()  # the drawing side's error is the one to report
            raise
        finally:
            if target is not None:
                target.release()
        encoder.close()
        if astream is not None:
            _write_audio(container, astream, samples, int(audio.sample_rate))
    return out_path


class _EncoderTarget(OffscreenFrames):
    """An offscreen frame target whose "present" hands the frame to the encoder: it is read straight into
    a free buffer of the encoder's pool (OpenGL row order; the encoder thread turns it upright)."""

    def __init__(self, ctx, size: tuple[int, int], encoder: PipelinedEncoder) -> None:
        super().__init__(ctx, size)
        self.encoder = encoder

    def present(self) -> None:
        buf = self.encoder.acquire()
        self.target.resolve()  # OffscreenFrames is single-sampled: its fbo is the resolved image
        self.target.fbo.read_into(buf, components=4, alignment=1)
        self.encoder.submit(buf)


def _write_audio(container, stream, samples: np.ndarray, rate: int) -> None:
    import av

    chunk = 1024
    layout = "mono" if samples.shape[1] == 1 else "stereo"
    pts = 0
    for start in range(0, len(samples), chunk):
        block = np.ascontiguousarray(samples[start:start + chunk].T, np.float32)  # planar: (channels, n)
        frame = av.AudioFrame.from_ndarray(block, format="fltp", layout=layout)
        frame.sample_rate = rate
        frame.pts = pts
        pts += block.shape[1]
        for packet in stream.encode(frame):
            container.mux(packet)
    for packet in stream.encode():
        container.mux(packet)
