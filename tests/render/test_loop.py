"""The one frame loop: virtual clocks step by 1/fps, ``view``'s player loops and pauses on its media
clock, and video frames are the stills at the same times."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from studyapp.audio.clock import SilentClock
from studyapp.render.loop import FrameLoop, NullTarget, ScenePlayer, VirtualTimer


class _Recorder:
    """Stands in for the Renderer: notes the media time of every drawn frame."""

    def __init__(self):
        self.times: list[float] = []

    def draw_trial(self, scene, t, fbo, viewport):
        self.times.append(t)


class _Scene:
    duration = 1.0


def test_view_player_loops_with_its_clock_and_pauses():
    clock = SilentClock(virtual=True)
    drawn = _Recorder()
    player = ScenePlayer(drawn, _Scene(), clock, loop=True)
    loop = FrameLoop(NullTarget(), VirtualTimer(4.0, clocks=[clock]), player.draw, player.after_flip)
    player.start(0.0)
    assert loop.run(10) == 10
    # a 1 s clip at 4 frames per second: 0, 1/4, 2/4, 3/4, and at its end (1 s) the start again
    assert drawn.times == pytest.approx([0.0, 0.25, 0.5, 0.75] * 2 + [0.0, 0.25])
    assert player.plays == 3
    assert player.recorder.drawn_s == pytest.approx([0.0, 0.25])  # the frames of the play now running
    player.toggle_pause()                     # Space: the picture holds while frames go on
    loop.run(3)
    assert drawn.times[-3:] == pytest.approx([0.5, 0.5, 0.5])
    assert player.recorder.drawn_s == pytest.approx([0.0, 0.25])  # paused frames are not A/V samples
    player.toggle_pause()
    loop.run(2)
    assert drawn.times[-2:] == pytest.approx([0.5, 0.75])
    player.start(0.0)                         # R: from the start
    loop.run(1)
    assert drawn.times[-1] == 0.0


def test_player_duration_comes_from_the_scene_unless_given():
    clock = SilentClock(virtual=True)
    assert ScenePlayer(_Recorder(), _Scene(), clock).duration_s == 1.0
    player = ScenePlayer(_Recorder(), _Scene(), clock, duration_s=2.5)
    player.start()
    assert clock.duration_s == 2.5


def test_loop_stops_when_told():
    frames = []
    loop = FrameLoop(NullTarget(), VirtualTimer(10.0), lambda fbo, size, now: frames.append(now),
                     running=lambda: len(frames) < 3)
    assert loop.run() == 3 and frames == pytest.approx([0.0, 0.1, 0.2])


@pytest.mark.gl
def test_video_frames_are_the_stills_at_k_over_fps(renderer, avatar):
    """``play_frames`` (what ``render`` writes to MP4) steps a virtual clock 1/fps per frame: frame k is
    pixel for pixel the still rendered at k / fps, and frames at different times differ."""
    from render_helpers import posed
    from studyapp.render.pose import prepare_slot
    from studyapp.render.scene import make_scene
    from studyapp.render.video import play_frames, render_frames

    m = posed(avatar, {"LeftUpperArm": (0, 0, -70)}, n_frames=10, fps=10.0)
    j = avatar.skeleton.index("LeftUpperArm")
    for f in range(10):  # the left arm swings up over the clip
        lift = Rotation.from_rotvec([0, 0, np.radians(8 * f)])
        m.rotations[f, j] = (Rotation.from_quat(m.rotations[f, j]) * lift).as_quat()
    scene = make_scene([prepare_slot(avatar, m, None)], avatar)
    video = list(play_frames(scene, 5.0, 5, size=(96, 128), renderer=renderer))
    stills = list(render_frames(scene, [k / 5.0 for k in range(5)], size=(96, 128), renderer=renderer))
    assert len(video) == 5
    for k in range(5):
        assert np.array_equal(video[k], stills[k]), k
    assert np.abs(video[0].astype(int) - video[4].astype(int)).sum(-1).max() > 100
