"""MP4 (H.264 + AAC) and PNG output, checked by decoding the files again."""
from __future__ import annotations

import av
import matplotlib.image as mpimg
import numpy as np
import pytest

from render_helpers import RELAXED, posed
from studyapp.audio.wav import AudioClip
from studyapp.render.pose import prepare_slot
from studyapp.render.scene import make_scene
from studyapp.render.video import render_still, render_video

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def scene(avatar):
    wave = posed(avatar, RELAXED, 12, fps=30.0)
    slot = prepare_slot(avatar, wave, None)
    return make_scene([slot] * 3, avatar, labels=("A", "B", "C"))


def test_video_has_h264_video_and_aac_audio(tmp_path, scene, renderer):
    t = np.arange(16000 // 2) / 16000
    clip = AudioClip(0.3 * np.sin(2 * np.pi * 440 * t).astype(np.float32), 16000)  # 0.5 s, BEAT's 16 kHz mono
    out = render_video(scene, clip, tmp_path / "clip.mp4", size=(192, 108), fps=30, renderer=renderer)
    with av.open(str(out)) as f:
        v = f.streams.video[0]
        a = f.streams.audio[0]
        assert v.codec_context.name == "h264" and v.codec_context.pix_fmt == "yuv420p"
        assert (v.codec_context.width, v.codec_context.height) == (192, 108)
        assert a.codec_context.name == "aac" and a.codec_context.sample_rate == 16000
        frames = [fr.to_ndarray(format="rgb24") for fr in f.decode(video=0)]
    assert len(frames) == 15  # max(motion 0.4 s, audio 0.5 s) at 30 fps
    still = render_still(scene, 0.0, tmp_path / "f0.png", size=(192, 108), renderer=renderer)
    # lossy, but the same picture
    assert np.abs(frames[0].astype(int) - still.astype(int)).mean() < 4
    with av.open(str(out)) as f:
        pcm = np.concatenate([fr.to_ndarray().reshape(-1) for fr in f.decode(audio=0)])
    assert 0.2 < np.abs(pcm).max() < 0.4  # the tone made it into the file


def test_still_png_matches_the_frame(tmp_path, scene, renderer):
    img = render_still(scene, 0.2, tmp_path / "still.png", size=(200, 120), renderer=renderer)
    back = mpimg.imread(tmp_path / "still.png")
    assert back.shape[:2] == (120, 200)
    assert np.array_equal((back[..., :3] * 255).round().astype(np.uint8), img)


def test_video_without_audio(tmp_path, scene, renderer):
    out = render_video(scene, None, tmp_path / "silent.mp4", size=(97, 55), fps=10, renderer=renderer)
    with av.open(str(out)) as f:
        assert len(f.streams.audio) == 0
        v = f.streams.video[0]
        assert (v.codec_context.width, v.codec_context.height) == (96, 54)  # even sizes for yuv420p
        assert sum(1 for _ in f.decode(video=0)) == 4


def test_shortened_video_cuts_the_audio_too(tmp_path, scene, renderer):
    t = np.arange(16000) / 16000
    clip = AudioClip(0.3 * np.sin(2 * np.pi * 440 * t).astype(np.float32), 16000)  # 1 s of sound
    out = render_video(scene, clip, tmp_path / "short.mp4", size=(96, 54), fps=10, renderer=renderer, duration=0.3)
    with av.open(str(out)) as f:
        assert sum(1 for _ in f.decode(video=0)) == 3
    with av.open(str(out)) as f:
        pcm = np.concatenate([fr.to_ndarray().reshape(-1) for fr in f.decode(audio=0)])
    # AAC adds priming and pads to whole 1024-sample frames; the second of sound must not survive
    assert 0.25 * 16000 <= pcm.size <= 0.3 * 16000 + 2 * 1024, pcm.size


def _swinging(avatar, n: int):
    """The left arm swings up a few degrees per frame: every frame differs from its neighbours."""
    from scipy.spatial.transform import Rotation

    m = posed(avatar, RELAXED, n, fps=30.0)
    j = avatar.skeleton.index("LeftUpperArm")
    swing = Rotation.from_euler("z", np.linspace(0, 100, n)[:, None], degrees=True)
    m.rotations[:, j] = (Rotation.from_quat(m.rotations[:, j]) * swing).as_quat()
    return m


def test_pipelined_video_holds_each_frame_of_the_timeline_in_order(tmp_path, avatar, renderer):
    from studyapp.render.video import play_frames

    n = 10
    scene = make_scene([prepare_slot(avatar, _swinging(avatar, n), None)], avatar)
    out = render_video(scene, None, tmp_path / "swing.mp4", size=(160, 96), fps=30, renderer=renderer)
    drawn = [f.astype(int) for f in play_frames(scene, 30, n, (160, 96), renderer)]
    with av.open(str(out)) as f:
        decoded = [fr.to_ndarray(format="rgb24").astype(int) for fr in f.decode(video=0)]
    assert len(decoded) == n
    for k, img in enumerate(decoded):
        err = [np.abs(img - d).mean() for d in drawn]
        # crf 20 yuv420p: a few grey levels on average; the arm moves ~10 degrees between frames, more than that
        assert err[k] < 4, (k, err[k])
        assert int(np.argmin(err)) == k, (k, np.round(err, 2))


def test_encoder_reuses_a_bounded_pool_and_keeps_order_and_orientation(tmp_path):
    from studyapp.render.encode import PipelinedEncoder, open_video_stream

    path = tmp_path / "levels.mp4"
    seen = set()
    with av.open(str(path), "w") as container:
        enc = PipelinedEncoder(container, open_video_stream(container, (64, 64), 10), depth=2)
        for k in range(12):
            buf = enc.acquire()
            seen.add(id(buf))
            buf[:32] = 20 * k          # OpenGL order: these rows are the bottom of the picture
            buf[32:] = 250
            enc.submit(buf)
        enc.close()
    assert seen == {id(b) for b in enc.buffers} and len(seen) == 2
    with av.open(str(path)) as f:
        frames = [fr.to_ndarray(format="rgb24").astype(float) for fr in f.decode(video=0)]
    assert len(frames) == 12
    for k, img in enumerate(frames):
        assert abs(img[40:].mean() - 20 * k) < 3, (k, img[40:].mean())   # bottom rows, right side up
        assert abs(img[:24].mean() - 250) < 3


def test_an_encoder_error_reaches_the_drawing_thread_without_a_hang():
    from studyapp.render.encode import PipelinedEncoder

    class Broken:
        width, height = 32, 32

        def encode(self, frame=None):
            raise ValueError("encoder broke")

    enc = PipelinedEncoder(container=None, stream=Broken(), depth=1)
    enc.submit(enc.acquire())
    with pytest.raises(ValueError, match="encoder broke"):
        try:
            for _ in range(5):
                enc.submit(enc.acquire())
            enc.close()
        finally:
            enc.abort()
    assert not enc._thread.is_alive()


def test_a_drawing_error_stops_the_encoder_thread_and_is_the_error_raised(tmp_path, scene, renderer):
    import threading

    class FailsOnThirdFrame:
        ctx = renderer.ctx

        def __init__(self):
            self.frames = 0

        def draw_trial(self, *args, **kwargs):
            self.frames += 1
            if self.frames == 3:
                raise RuntimeError("draw failed")
            renderer.draw_trial(*args, **kwargs)

    with pytest.raises(RuntimeError, match="draw failed"):
        render_video(scene, None, tmp_path / "broken.mp4", size=(64, 48), fps=30, renderer=FailsOnThirdFrame())
    assert not [t for t in threading.enumerate() if t.name == "studyapp-encoder"]
