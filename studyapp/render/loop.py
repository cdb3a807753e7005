"""The one frame loop: every picture studyapp shows or writes is made here, one frame at a time.

For each frame :class:`FrameLoop` asks its timer for the time of the frame, has the drawing function
draw into the target (a window's back buffer or an offscreen framebuffer), reads the frame back when
asked, presents it (a buffer swap; nothing offscreen) and reports the flip. What is drawn comes from a
media clock (:mod:`studyapp.audio.clock`): the audio clock when sound plays, a wall clock without a
sound device, a virtual clock offscreen that the :class:`VirtualTimer` moves by exactly 1/fps per frame
(no real time passes while drawing, so a 10 s clip renders in as many frames as it has, however slow).

The participant window (:class:`studyapp.ui.app.WindowRunner`), the offscreen scripted participant
(:mod:`studyapp.bots.ui_driver`), ``studyapp view`` and video/still export (:mod:`studyapp.render.video`) all
run through it. :class:`ScenePlayer` is the drawing function of the last two: one scene played on a
media clock with the same A/V bookkeeping as a trial (:mod:`studyapp.render.frames`).

>>> from studyapp.audio.clock import SilentClock
>>> clock = SilentClock(virtual=True)
>>> shown = []
>>> loop = FrameLoop(NullTarget(), VirtualTimer(4.0, clocks=[clock]),
...                  draw=lambda fbo, size, now: shown.append((now, clock.position_s())))
>>> clock.play(None, duration_s=1.0)
>>> loop.run(3)
3
>>> shown                                  # frame time and media time move 1/fps per frame
[(0.0, 0.0), (0.25, 0.25), (0.5, 0.5)]
"""
from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from studyapp.audio.clock import MediaClock, SilentClock
from studyapp.render.frames import FlipPredictor, PlayRecorder, clock_media_time

if TYPE_CHECKING:
    import moderngl

    from studyapp.render.context import Window
    from studyapp.render.renderer import Renderer
    from studyapp.render.scene import TrialScene


# -- targets: where a frame goes -------------------------------------------------------------------------

class FrameTarget(Protocol):
    """Something frames are drawn into and presented on."""

    @property
    def fbo(self) -> Any: ...
    @property
    def size(self) -> tuple[int, int]: ...
    def begin(self) -> bool: ...        # before a frame: handle events; False when the target closes
    def use(self) -> None: ...
    def read_rgb(self) -> np.ndarray: ...
    def present(self) -> None: ...


class WindowTarget:
    """A :class:`~studyapp.render.context.Window`: events are polled before each frame, presenting swaps."""

    def __init__(self, window: Window) -> None:
        self.window = window

    @property
    def fbo(self) -> Any:
        return self.window.fbo  # replaced on resize

    @property
    def size(self) -> tuple[int, int]:
        return self.window.framebuffer_size

    def begin(self) -> bool:
        self.window.poll_events()
        return not self.window.should_close

    def use(self) -> None:
        self.window.use()

    def read_rgb(self) -> np.ndarray:
        return self.window.read_rgb()

    def present(self) -> None:
        self.window.swap_buffers()


class OffscreenFrames:
    """An offscreen framebuffer (:class:`~studyapp.render.context.OffscreenTarget`) of a fixed size."""

    def __init__(self, ctx: moderngl.Context, size: tuple[int, int]) -> None:
        from studyapp.render.context import OffscreenTarget

        self.target = OffscreenTarget(ctx, size)
        self.size = self.target.size

    @property
    def fbo(self) -> Any:
        return self.target.fbo

    def begin(self) -> bool:
        return True

    def use(self) -> None:
        self.target.fbo.use()

    def read_rgb(self) -> np.ndarray:
        return self.target.read_rgb()

    def present(self) -> None:
        pass  # nothing to show: the frame is read back or drawn on by the caller

    def release(self) -> None:
        self.target.release()


class NullTarget:
    """No pixels at all (doctests, timing logic): drawing functions receive ``fbo=None``."""

    fbo = None
    size = (1, 1)

    def begin(self) -> bool:
        return True

    def use(self) -> None:
        pass

    def read_rgb(self) -> np.ndarray:
        return np.zeros((1, 1, 3), np.uint8)

    def present(self) -> None:
        pass


# -- timers: when a frame happens -------------------------------------------------------------------------

class FrameTimer(Protocol):
    """When frames happen and are flipped (:class:`WallTimer`, :class:`VirtualTimer`)."""

    virtual: bool   # True: time moves only frame by frame (nothing passes while drawing)

    def now(self) -> float: ...         # the time of the frame about to be drawn
    def flip_time(self) -> float: ...   # when the frame just presented was flipped
    def tick(self) -> None: ...         # after a frame
    def idle(self) -> None: ...         # instead of a frame (a minimised window)
    def wait_until(self, t: float) -> None: ...  # hold a finished frame back until ``t`` (``now()``'s time base)


class WallTimer:
    """Real time (``time.perf_counter``): frames happen when they happen, flips are stamped after the swap."""

    virtual = False

    def now(self) -> float:
        return time.perf_counter()

    def flip_time(self) -> float:
        return time.perf_counter()

    def tick(self) -> None:
        pass

    def idle(self) -> None:
        time.sleep(0.05)  # a minimised window: nothing to draw, do not spin

    def wait_until(self, t: float) -> None:
        time.sleep(max(0.0, t - time.perf_counter()))


class VirtualTimer:
    """Frame ``k`` happens at ``k / fps`` and is flipped at that same instant; after each frame the
    attached virtual media clocks (:class:`~studyapp.audio.clock.SilentClock` ``virtual=True``) move on by
    exactly one frame, so frame ``k`` of a clip started at frame 0 shows media time ``k / fps``."""

    virtual = True

    def __init__(self, fps: float, clocks: Iterable[SilentClock] = ()) -> None:
        if not fps > 0:
            raise ValueError(f"fps must be positive, got {fps}")
        self.fps = float(fps)
        self.clocks = list(clocks)
        self.frame = 0

    def now(self) -> float:
        return self.frame / self.fps

    def flip_time(self) -> float:
        return self.now()

    def tick(self) -> None:
        self.frame += 1
        for clock in self.clocks:
            clock.advance(1.0 / self.fps)

    def idle(self) -> None:
        self.tick()

    def wait_until(self, t: float) -> None:
        pass  # no real time passes


# -- the loop ------------------------------------------------------------------------------------------------

DrawFn = Callable[[Any, tuple[int, int], float], None]
#: A frame finished early is held until this many periods before its flip, then swapped: any time in the
#: last period before a flip lands on it, and waking up early leaves room for a sleep that overshoots
#: (tens of milliseconds with twice as many busy processes as cores).
HOLD_PERIODS = 0.75


class FrameLoop:
    """Draws frames into ``target`` at the times ``timer`` gives.

    Parameters
    ----------
    target:
        Where frames go (:class:`WindowTarget`, :class:`OffscreenFrames`).
    timer:
        :class:`WallTimer` (windows) or :class:`VirtualTimer` (offscreen).
    draw:
        ``draw(fbo, (w, h), now)``: draws the whole frame for time ``now``.
    after_flip:
        ``after_flip(flip_time)``: called once the frame is presented (A/V bookkeeping, slow work).
    running:
        Checked before each frame; the loop stops when it returns False (a participant finished).
    capture:
        Read every frame back into :attr:`last_rgb` (before presenting, while the back buffer holds it).
    pacer:
        The :class:`~studyapp.render.frames.FlipPredictor` the drawing function aims its media time with
        (real-time timers only). The loop tells it how long each frame took to draw, so frames aim at
        the first flip they can make; a frame that aimed at a flip and was still drawing when that flip
        passed is dropped (not presented, no ``after_flip``) and counted in :attr:`dropped_late`. Frames
        are never shown late: each one is drawn for the audio time of its own flip, so a slow frame costs
        a skipped picture, not a picture that lags the sound (drop, never drift). Nor early: a frame done
        well before its flip is held back until :data:`HOLD_PERIODS` before it (a vsync'd swap would
        otherwise show it at the next flip, ahead of the sound); a hold that overshoots the flip (the
        sleep of a loaded machine) drops the frame too.
    """

    def __init__(self, target: FrameTarget, timer: FrameTimer, draw: DrawFn,
                 after_flip: Callable[[float], None] | None = None, *,
                 running: Callable[[], bool] | None = None, capture: bool = False,
                 pacer: FlipPredictor | None = None) -> None:
        self.target = target
        self.timer = timer
        self.draw = draw
        self.after_flip = after_flip
        self.running = running
        self.capture = capture
        self.pacer = None if timer.virtual else pacer  # virtual time does not pass while drawing
        self.last_rgb: np.ndarray | None = None
        self.frames = 0
        #: Frames drawn but not shown because they finished after the flip they were drawn for.
        self.dropped_late = 0

    def step(self) -> bool:
        """One frame; False (nothing drawn) once the target closed or ``running`` says stop."""
        if not self.target.begin():
            return False
        if self.running is not None and not self.running():
            return False
        size = self.target.size
        if size[0] <= 0 or size[1] <= 0:  # minimised
            self.timer.idle()
            return True
        now = self.timer.now()
        pacer = self.pacer
        if pacer is not None:
            pacer.aimed = None
        self.target.use()
        self.draw(self.target.fbo, size, now)
        if pacer is not None:
            done = self.timer.now()
            pacer.drew(done - now)
            if pacer.aimed is not None and done > pacer.aimed:  # its flip has passed: drop, do not show late
                self.dropped_late += 1
                self.frames += 1
                return True
            period = pacer.period
            hold = pacer.aimed - HOLD_PERIODS * period if pacer.aimed is not None and period else None
            if hold is not None and done < hold:
                self.timer.wait_until(hold)  # the swap then lands on the aimed flip
                if self.timer.now() > pacer.aimed:  # the wait overshot the flip (a loaded machine): late
                    self.dropped_late += 1
                    self.frames += 1
                    return True
        if self.capture:
            self.last_rgb = self.target.read_rgb()
        self.target.present()
        flip = self.timer.flip_time()
        if self.after_flip is not None:
            self.after_flip(flip)
        self.timer.tick()
        self.frames += 1
        return True

    def run(self, max_frames: int | None = None) -> int:
        """Step until the target closes (or ``max_frames`` frames); returns the frames drawn."""
        start = self.frames
        while max_frames is None or self.frames - start < max_frames:
            if not self.step():
                break
        return self.frames - start


# -- one scene on a media clock -------------------------------------------------------------------------------

class ScenePlayer:
    """Plays a :class:`~studyapp.render.scene.TrialScene` on a media clock (``view``, stills, videos).

    Parameters
    ----------
    renderer:
        The :class:`~studyapp.render.renderer.Renderer` that draws the scene.
    scene:
        What to show; its ``duration`` is how long one play lasts unless ``duration_s`` says otherwise.
    clock:
        The media clock (audio player, wall or virtual :class:`~studyapp.audio.clock.SilentClock`).
    audio:
        The clip the clock plays (None: silence).
    duration_s:
        Length of one play (default: the scene's duration).
    loop:
        Start again from the beginning (with the sound) at the end (``view``).
    predictor:
        Flip prediction of a real display (windows); None offscreen.
    flip_clock:
        The clock flip times are given on (``time.perf_counter`` for :class:`WallTimer`), when a flip can
        be reported before the thread gets to read the audio: the audio position recorded for a frame
        is then the one at its flip (the position read, less the time since the flip), not the one at
        whenever the thread ran again. None: the position read right after the flip.
    """

    def __init__(self, renderer: Renderer, scene: TrialScene, clock: MediaClock, *, audio: Any = None,
                 duration_s: float | None = None, loop: bool = False,
                 predictor: FlipPredictor | None = None, flip_clock: Callable[[], float] | None = None) -> None:
        self.renderer = renderer
        self.scene = scene
        self.clock = clock
        self.audio = audio
        self.duration_s = float(scene.duration if duration_s is None else duration_s)
        self.loop = loop
        self.predictor = predictor
        self.flip_clock = flip_clock
        self.recorder = PlayRecorder(refresh_hz=predictor.nominal_hz if predictor is not None else None)
        self.plays = 0
        self._drawn: float | None = None

    def start(self, at_s: float = 0.0) -> None:
        """Play from ``at_s`` seconds (a new play: the frame record starts afresh)."""
        self.clock.play(self.audio, at_s, duration_s=max(self.duration_s, float(at_s)))
        self.recorder = PlayRecorder(refresh_hz=self.recorder.refresh_hz)
        self.plays += 1

    def toggle_pause(self) -> None:
        if self.clock.paused:
            self.clock.resume()
        else:
            self.clock.pause()

    def media_time(self, now: float) -> float:
        """The clip time the frame drawn at ``now`` shows (see :func:`~studyapp.render.frames.clock_media_time`)."""
        if self.loop and self.clock.finished:
            self.start(0.0)
        return clock_media_time(self.clock, now, self.predictor, self.clock.duration_s)

    def draw(self, fbo: Any, size: tuple[int, int], now: float) -> None:
        t = self.media_time(now)
        self.renderer.draw_trial(self.scene, t, fbo, (0, 0, int(size[0]), int(size[1])))
        self._drawn = t

    def after_flip(self, flip_time: float) -> None:
        if self.predictor is not None:
            self.predictor.flipped(flip_time)
        # Only frames shown while the clip runs count (before a device starts, picture and sound both wait).
        if self._drawn is not None and self.clock.started and not self.clock.paused:
            audio = self.clock.position_s()
            if self.flip_clock is not None:
                audio = max(0.0, audio - max(0.0, self.flip_clock() - flip_time))
            self.recorder.flip(flip_time, self._drawn, audio)
        self._drawn = None
