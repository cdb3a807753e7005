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

from collections.abc import Mapping, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from studyapp.audio.clock import SilentClock
from studyapp.render.context import create_offscreen_context, make_current
from studyapp.render.encode import SETTINGS, EncoderSettings, PipelinedEncoder, open_video_stream
from studyapp.render.loop import FrameLoop, OffscreenFrames, ScenePlayer, VirtualTimer
from studyapp.render.renderer import Renderer, slot_viewports

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
    from PIL import Image

    img = next(render_frames(scene, [t], size, renderer))
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.ascontiguousarray(img)).save(out_png, format="png")
    return img


def render_video(scene, audio, out_path: str | Path, size: tuple[int, int] = (1280, 720), fps: int = 30,
                 renderer: Renderer | None = None, duration: float | None = None,
                 settings: EncoderSettings = SETTINGS, metadata: Mapping[str, str] | None = None) -> Path:
    """Write an MP4 (H.264 yuv420p, plus AAC audio when ``audio`` is an AudioClip) of the whole trial.

    The video lasts ``duration`` seconds (default: the longer of the motion and the audio); the audio is
    muxed from the start of the clip and cut at ``duration``, so picture and sound line up as they do in the
    study and a shortened video does not go on talking over a frozen last frame.

    The frames are those of :func:`play_frames` (the same frame loop, virtual clock and player); each is
    read back into a reused buffer and encoded on a thread of its own while the next one is drawn
    (:mod:`studyapp.render.encode`, whose ``SETTINGS`` say codec, crf, preset and pixel format). The index
    is written at the front (``faststart``: a browser starts playing before the whole file arrived) and the
    file carries no metadata beyond ``metadata`` (each value an empty string by default: see
    :func:`_open_container`).
    """
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    size = _even(size)
    duration = _duration(scene, audio, duration)
    n_frames = max(1, int(round(duration * fps)))
    samples = _audio_samples(audio, duration)
    with _open_container(out_path, metadata) as container:
        vstream = open_video_stream(container, size, fps, settings)
        astream = _open_audio_stream(container, samples, audio)
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


def _duration(scene, audio, duration: float | None) -> float:
    """The video's length: ``duration``, or the longer of the scene and the audio."""
    if duration is None:
        duration = scene.duration
        if audio is not None:
            duration = max(duration, len(audio.samples) / float(audio.sample_rate))
    return float(duration)


def _audio_samples(audio, duration: float) -> np.ndarray | None:
    """``(n, channels<=2) float32`` samples of ``audio`` cut at ``duration`` (None without audio)."""
    if audio is None:
        return None
    samples = np.asarray(audio.samples, np.float32)
    if samples.ndim == 1:
        samples = samples[:, None]
    return samples[: int(round(duration * float(audio.sample_rate))), :2]


def _open_container(path: Path, metadata: Mapping[str, str] | None = None):
    """An MP4 container for writing: index at the front (``+faststart``) and no tag that FFmpeg would add
    on its own (``+bitexact``: no encoder version string); ``metadata`` are the only file-level tags."""
    import av

    container = av.open(str(path), mode="w", format="mp4",
                        options={"movflags": "+faststart", "fflags": "+bitexact"})
    for k, v in (metadata or {}).items():
        container.metadata[k] = v
    return container


def _open_audio_stream(container, samples: np.ndarray | None, audio):
    if samples is None:
        return None
    astream = container.add_stream("aac", rate=int(audio.sample_rate))
    astream.layout = "mono" if samples.shape[1] == 1 else "stereo"
    return astream


def permuted_scene(scene, order: Sequence[int]):
    """``scene`` with its figures rearranged: slot ``p`` shows ``scene``'s figure ``order[p]``.

    Camera, labels and duration stay: the camera is fitted to the set of figures (not their order) and a
    label belongs to its place, so this is the scene :func:`~studyapp.render.scene.build_trial_scene` makes
    for the same trial with its conditions in that order (a test compares the pixels)."""
    order = tuple(int(k) for k in order)
    if sorted(order) != list(range(scene.n_slots)):
        raise ValueError(f"order {order} is not a permutation of the scene's {scene.n_slots} slots")
    return replace(scene, slots=tuple(scene.slots[k] for k in order),
                   avatars=tuple(scene.avatars[k] for k in order))


class OrderFrames:
    """Frames of one scene in several slot orders, drawing each figure in each place once.

    A slot's pixels depend only on the figure it shows, its place (position, width, label) and the shared
    camera, never on its neighbours (each slot has its own viewport, backdrop, floor and shadow). The
    ``n`` cyclic rotations of the scene put every figure in every place once, so any order of the ``n``
    figures is made by copying each slot's columns from the rotation that shows that figure there:
    ``n`` drawings per frame for up to ``n!`` orders (3 for the 6 orders of a 3-condition trial). With
    no more orders than slots, each order is simply drawn.

    :meth:`draw` draws time ``t``; :meth:`compose` then writes order ``j``'s frame (``(H, W, 4)`` RGBA, OpenGL
    row order) into a caller's buffer.
    """

    def __init__(self, renderer: Renderer, scene, orders: Sequence[Sequence[int]], target) -> None:
        self.renderer = renderer  # ``target`` only gives the size: the pictures are read from the renderer
        self.orders = [tuple(int(k) for k in o) for o in orders]
        n = scene.n_slots
        for o in self.orders:
            if sorted(o) != list(range(n)):
                raise ValueError(f"order {o} is not a permutation of the scene's {n} slots")
        self.target = target
        w, h = target.size
        self.columns = [(x, x + vw) for x, _, vw, _ in slot_viewports((0, 0, w, h), n)]
        self.rotated = len(self.orders) > n
        if self.rotated:  # rotation r shows figure (p + r) % n in place p
            self.drawn = [permuted_scene(scene, [(p + r) % n for p in range(n)]) for r in range(n)]
        else:
            self.drawn = [permuted_scene(scene, o) for o in self.orders]
        self.buffers = [np.empty((h, w, 4), np.uint8) for _ in self.drawn]

    def draw(self, t: float) -> None:
        for scene, buf in zip(self.drawn, self.buffers):
            # the renderer's finished picture, read where it lies (what draw_trial would copy into a target)
            tex = self.renderer.render_texture(scene, t, self.target.size)
            tex.read_into(buf, alignment=1)

    def compose(self, j: int, out: np.ndarray) -> None:
        if not self.rotated:
            np.copyto(out, self.buffers[j])
            return
        n = len(self.columns)
        order = self.orders[j]
        if all(order[p] == (order[0] + p) % n for p in range(n)):
            np.copyto(out, self.buffers[order[0]])  # a rotation itself: one contiguous copy
            return
        for p, (x0, x1) in enumerate(self.columns):
            np.copyto(out[:, x0:x1], self.buffers[(order[p] - p) % n][:, x0:x1])


def order_frames(scene, orders: Sequence[Sequence[int]], fps: float, n_frames: int,
                 size: tuple[int, int] = (1280, 720), renderer: Renderer | None = None,
                 duration: float | None = None):
    """Yield, for each of ``n_frames`` frames of one play (frame ``k`` at ``k / fps``), the list of the
    ``(H, W, 3)`` frames of every order (see :class:`OrderFrames`): what :func:`render_order_videos` encodes."""
    ctx = renderer.ctx if renderer is not None else _shared_context()
    renderer = renderer or Renderer(ctx)
    target = OffscreenFrames(ctx, size)
    frames = OrderFrames(renderer, scene, orders, target)
    player = _OrdersPlayer(renderer, scene, frames, duration)
    loop = FrameLoop(target, VirtualTimer(fps, clocks=[player.clock]), player.draw, player.after_flip)
    player.start(0.0)
    out = np.empty((target.size[1], target.size[0], 4), np.uint8)
    try:
        for _ in range(int(n_frames)):
            loop.step()
            rgb = []
            for j in range(len(frames.orders)):
                frames.compose(j, out)
                rgb.append(out[::-1, :, :3].copy())
            yield rgb
    finally:
        target.release()


class _OrdersPlayer(ScenePlayer):
    """The :class:`ScenePlayer` of one play (same clock, same media time per frame) whose drawing is every
    order's frame at that media time (:class:`OrderFrames`)."""

    def __init__(self, renderer: Renderer, scene, frames: OrderFrames, duration: float | None) -> None:
        super().__init__(renderer, scene, SilentClock(virtual=True, reason="offscreen render"), duration_s=duration)
        self.frames = frames

    def draw(self, fbo, size: tuple[int, int], now: float) -> None:
        t = self.media_time(now)
        self.frames.draw(t)
        self._drawn = t


def render_order_videos(scene, orders: Sequence[Sequence[int]], audio, out_paths: Sequence[str | Path],
                        size: tuple[int, int] = (1280, 720), fps: int = 30, renderer: Renderer | None = None,
                        duration: float | None = None, settings: EncoderSettings = SETTINGS,
                        metadata: Mapping[str, str] | None = None) -> list[Path]:
    """One MP4 per slot order of ``scene`` (``out_paths[j]`` shows ``permuted_scene(scene, orders[j])``),
    each exactly what :func:`render_video` writes for that scene, drawn by :class:`OrderFrames` (each figure
    once per place and frame) and encoded by one :class:`~studyapp.render.encode.PipelinedEncoder` per
    video, all running while the next frame is drawn."""
    if len(out_paths) != len(orders):
        raise ValueError(f"{len(out_paths)} output paths for {len(orders)} orders")
    size = _even(size)
    duration = _duration(scene, audio, duration)
    n_frames = max(1, int(round(duration * fps)))
    samples = _audio_samples(audio, duration)
    outs = [Path(p) for p in out_paths]
    containers, encoders, astreams = [], [], []
    ctx = renderer.ctx if renderer is not None else _shared_context()
    renderer = renderer or Renderer(ctx)
    target = None
    try:
        for out in outs:
            out.parent.mkdir(parents=True, exist_ok=True)
            container = _open_container(out, metadata)
            containers.append(container)
            vstream = open_video_stream(container, size, fps, settings)
            astreams.append(_open_audio_stream(container, samples, audio))
            encoders.append(PipelinedEncoder(container, vstream))
        target = _OrdersTarget(ctx, size, encoders)
        frames = OrderFrames(renderer, scene, orders, target)
        target.frames = frames
        player = _OrdersPlayer(renderer, scene, frames, duration)
        loop = FrameLoop(target, VirtualTimer(fps, clocks=[player.clock]), player.draw, player.after_flip)
        player.start(0.0)
        loop.run(n_frames)
        for container, encoder, astream in zip(containers, encoders, astreams):
            encoder.close()
            if astream is not None:
                _write_audio(container, astream, samples, int(audio.sample_rate))
    except BaseException:
        for encoder in encoders:
            encoder.abort()  # the drawing side's error is the one to report
        raise
    finally:
        if target is not None:
            target.release()
        for container in containers:
            container.close()
    return outs


class _OrdersTarget(OffscreenFrames):
    """Presents a frame by composing every order's picture straight into a free buffer of its encoder."""

    def __init__(self, ctx, size: tuple[int, int], encoders: list[PipelinedEncoder]) -> None:
        super().__init__(ctx, size)
        self.encoders = encoders
        self.frames: OrderFrames | None = None

    def present(self) -> None:
        for j, encoder in enumerate(self.encoders):
            buf = encoder.acquire()
            self.frames.compose(j, buf)
            encoder.submit(buf)


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
