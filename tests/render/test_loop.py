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


class _FakeTime:
    """Real time, simulated: drawing and waiting for vsync move it on; nothing else does."""

    def __init__(self):
        self.t = 0.0


class _SoundClock(SilentClock):
    """An audio clock on the fake time: the sound is at ``t - started`` (it never waits for the picture)."""

    def __init__(self, time_):
        super().__init__()
        self.time = time_

    def position_s(self):
        return min(self.time.t, self.duration_s)


class _FakeWallTimer:
    virtual = False

    def __init__(self, time_):
        self.time = time_

    def now(self):
        return self.time.t

    def flip_time(self):
        return self.time.t

    def tick(self):
        pass

    def idle(self):
        pass

    def wait_until(self, t):
        self.time.t = max(self.time.t, t)


class _VsyncTarget(NullTarget):
    """Presenting waits for the next vsync of a 60 Hz display (a whole multiple of the period)."""

    def __init__(self, time_, period):
        self.time = time_
        self.period = period
        self.presented = 0

    def present(self):
        self.time.t = (np.floor(self.time.t / self.period + 1e-9) + 1) * self.period
        self.presented += 1


class _SlowRenderer:
    """A renderer whose frames take ``costs[k]`` seconds of (fake) time to draw."""

    def __init__(self, time_, costs):
        self.time = time_
        self.costs = list(costs)
        self.times: list[float] = []

    def draw_trial(self, scene, t, fbo, viewport):
        self.times.append(t)
        self.time.t += self.costs[(len(self.times) - 1) % len(self.costs)]


class _LongScene:
    duration = 100.0


def _paced_play(costs, frames, pacer):
    from studyapp.render.frames import FlipPredictor

    period = 1 / 60
    time_ = _FakeTime()
    clock = _SoundClock(time_)
    renderer = _SlowRenderer(time_, costs)
    predictor = FlipPredictor(60.0)
    predictor.flipped(0.0)  # the display was running before the clip started (the UI draws every frame)
    player = ScenePlayer(renderer, _LongScene(), clock, predictor=predictor)
    target = _VsyncTarget(time_, period)
    loop = FrameLoop(target, _FakeWallTimer(time_), player.draw, player.after_flip,
                     pacer=predictor if pacer else None)
    player.start(0.0)
    loop.run(frames)
    return loop, player, target, period


def test_slow_frames_are_dropped_and_counted_never_shown_late():
    """Drawing takes 1.3 periods with a 4-period spike every 10th frame (a loaded software renderer): the
    loop aims each frame at the first flip it can make, drops the frames that miss it, and every frame
    shown is within one period of the sound; the offset does not grow over the play (no drift)."""
    p = 1 / 60
    costs = [1.3 * p] * 9 + [4.0 * p]
    loop, player, target, period = _paced_play(costs, 400, pacer=True)
    off = np.abs(np.array(player.recorder.offsets_s))
    assert target.presented == loop.frames - loop.dropped_late == len(off)
    assert loop.dropped_late >= 40 - 5  # (about) every spike is dropped ...
    assert loop.dropped_late <= 400 * 0.15  # ... and little else once the lead is learnt
    assert np.all(off <= period + 1e-9)
    # no drift: the offsets of the last hundred frames shown are no larger than those of the first
    assert off[-100:].mean() <= off[:100].mean() + 1e-9
    # the pictures shown are drawn for the sound's time at their own flips, not a running count of frames
    shown = np.array(player.recorder.drawn_s)
    flips = np.array(player.recorder.flips)
    assert np.allclose(shown, flips, atol=period + 1e-9)


def test_without_pacing_slow_frames_show_the_sound_late():
    """The same slow renderer without the pacer (the loop before drop-not-drift): frames drawn for the next
    flip appear at a later one: every spike is shown three or more periods behind the sound."""
    p = 1 / 60
    loop, player, target, period = _paced_play([1.3 * p] * 9 + [4.0 * p], 400, pacer=False)
    off = np.abs(np.array(player.recorder.offsets_s))
    assert loop.dropped_late == 0
    assert np.mean(off <= period + 1e-9) < 0.99  # the spikes are shown, late
    assert off.max() >= 3 * period - 1e-9


def test_quick_frames_wait_for_the_flip_they_were_drawn_for():
    """Mostly quick frames with a long one every sixth (the lead covers the long ones, so quick frames aim
    several flips ahead): a quick frame is held back until its flip, not shown early at the next vsync."""
    p = 1 / 60
    loop, player, target, period = _paced_play([0.3 * p] * 5 + [3.5 * p], 300, pacer=True)
    off = np.abs(np.array(player.recorder.offsets_s))
    assert len(off) > 200
    assert np.mean(off <= period + 1e-9) >= 0.99
    assert np.all(off[30:] <= period + 1e-9)  # once the lead is learnt


def test_static_frames_are_never_dropped():
    """A frame that shows no media time (a paused clip, a questionnaire page) never misses anything."""
    from studyapp.render.frames import FlipPredictor

    time_ = _FakeTime()
    target = _VsyncTarget(time_, 1 / 60)

    def draw(fbo, size, now):
        time_.t += 0.1  # very slow, but asks the predictor for no flip

    predictor = FlipPredictor(60.0)
    predictor.flipped(0.0)
    loop = FrameLoop(target, _FakeWallTimer(time_), draw, pacer=predictor)
    loop.run(5)
    assert loop.dropped_late == 0 and target.presented == 5


def test_audio_is_taken_at_the_flip_when_the_thread_reads_it_late():
    """With ``flip_clock`` the offset of a frame is against the audio at its flip: a thread that gets
    back 30 ms after the flip (a loaded machine) reads the clock 30 ms on, and that is taken off."""
    time_ = _FakeTime()
    clock = _SoundClock(time_)
    late = 0.030
    player = ScenePlayer(_Recorder(), _LongScene(), clock, flip_clock=lambda: time_.t)
    plain = ScenePlayer(_Recorder(), _LongScene(), clock)
    player.start(0.0)
    time_.t = 1.0
    for p in (player, plain):
        p.draw(None, (4, 4), time_.t)  # drawn for the clock's 1.0 s, shown at the flip at 1.0 s
    time_.t = 1.0 + late  # the thread runs again only now
    player.after_flip(1.0)
    plain.after_flip(1.0)
    assert player.recorder.offsets_s == [pytest.approx(0.0)]
    assert plain.recorder.offsets_s == [pytest.approx(-late)]


def test_a_hold_that_overshoots_the_flip_drops_the_frame():
    """A quick frame is held until shortly before its flip; when that sleep overshoots the flip (a loaded
    machine), the frame would appear a period late: it is dropped and counted, never shown."""
    from studyapp.render.frames import FlipPredictor

    time_ = _FakeTime()

    class Oversleeping(_FakeWallTimer):
        def wait_until(self, t):
            self.time.t = t + 0.9 / 60  # wakes up most of a period late

    predictor = FlipPredictor(60.0)
    predictor.flipped(0.0)
    player = ScenePlayer(_SlowRenderer(time_, [0.1 / 60]), _LongScene(), _SoundClock(time_), predictor=predictor)
    target = _VsyncTarget(time_, 1 / 60)
    loop = FrameLoop(target, Oversleeping(time_), player.draw, player.after_flip, pacer=predictor)
    player.start(0.0)
    loop.run(20)
    assert loop.dropped_late >= 5
    assert target.presented + loop.dropped_late == 20
    assert np.all(np.abs(player.recorder.offsets_s) <= 1 / 60 + 1e-9)  # what was shown was on time
