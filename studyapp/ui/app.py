"""The participant application: the session's screens drawn with Dear ImGui over the 3D view.

:class:`StudyApp` is the whole UI for one GL context and is driven one frame at a time by the frame
loop (:class:`studyapp.render.loop.FrameLoop`), so the same code runs in a GLFW window (:func:`run_window`,
:class:`WindowRunner`, on the audio or wall clock) and offscreen for the scripted participant
(:mod:`studyapp.bots.ui_driver`, on a virtual clock). Each frame:

1. queued input (:mod:`studyapp.ui.input`) goes to ImGui;
2. the screen for the session's state builds the UI and, on a trial, asks for the 3D view at the media
   time that the audio clock will have reached when the frame is shown;
3. the renderer draws the three avatars into their part of the framebuffer, the UI is drawn on top;
4. after the flip, :meth:`StudyApp.after_flip` records the audio/video offset and does slow work that
   was requested (loading a trial, the environment check) so a "Loading..." frame is shown first.
"""
from __future__ import annotations

import logging
import os
import wave
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

from studyapp.errors import StudyappError
from studyapp.render.frames import FlipPredictor
from studyapp.ui.input import InputQueue
from studyapp.ui.layer import ImGuiLayer
from studyapp.ui.trial import TrialView
from studyapp.ui.widgets import Painter

if TYPE_CHECKING:
    import moderngl
    import numpy as np

    from studyapp.audio.clock import MediaClock
    from studyapp.audio.playback import PendingClock
    from studyapp.render.loop import FrameTimer
    from studyapp.render.renderer import Renderer
    from studyapp.render.scene import TrialScene
    from studyapp.study.design import Design, Stimulus
    from studyapp.study.storage import ResultsDB
    from studyapp.ui.seams import ParticipantSession

log = logging.getLogger(__name__)

BACKGROUND = (0.11, 0.12, 0.14)
DEFAULT_SLOT_NAMES = ("Left", "Middle", "Right")


class StudyApp:
    """All screens of one participant session, for one GL context (what the screens use of it:
    :class:`~studyapp.ui.seams.ScreenApp`).

    Parameters
    ----------
    design, session:
        The loaded design and the running :class:`~studyapp.study.session.Session`.
    ctx:
        The moderngl context (window or offscreen).
    clock:
        The master clock: an :class:`~studyapp.audio.playback.AudioPlayer` or a
        :class:`~studyapp.audio.clock.SilentClock`; or a :class:`~studyapp.audio.playback.PendingClock`,
        an output still opening in its own process: the app takes its clock after the first frame that
        finds it open (and prints its message for the experimenter), or waits for it when something needs
        the clock before (a clip played, the environment check). The screens up to the first trial frame
        need no sound, so they do not wait for it; a device asked for that cannot be opened ends the
        session from :meth:`after_flip` with its error.
    refresh_hz:
        Display refresh rate when known (frame drop detection, flip prediction).
    display:
        ``(name, size, refresh, content scale)`` for the environment check (None: measured there).
    bench_frames:
        Frames of the render benchmark in the environment check.
    """

    def __init__(self, design: Design, session: ParticipantSession, ctx: moderngl.Context,
                 clock: MediaClock | PendingClock, *,
                 queue: InputQueue | None = None,
                 refresh_hz: float | None = None, display: tuple | None = None, bench_frames: int = 20,
                 db_path: Path | str | None = None) -> None:
        from studyapp.audio.playback import PendingClock

        self.design = design
        self.session = session
        self.ctx = ctx
        self._pending_audio = clock if isinstance(clock, PendingClock) else None
        self._clock = None if self._pending_audio is not None else clock
        self.refresh_hz = refresh_hz
        self.display = display
        self.bench_frames = bench_frames
        self.db_path = db_path if db_path is not None else getattr(getattr(session, "db", None), "path", None)
        from studyapp.study.design.fonts import design_fallback_font

        # a system font for the characters of the design's texts the UI's font lacks (e.g. Chinese)
        self.layer = ImGuiLayer(ctx, extra_font=design_fallback_font(design)[0])
        self.ui = Painter()
        self.ui.layer = self.layer
        self.input = queue if queue is not None else InputQueue()
        self.input.on_focus = self._on_focus
        self.predictor = FlipPredictor(refresh_hz)
        self.slot_names = tuple(design.slot_labels) if design.slot_labels else DEFAULT_SLOT_NAMES
        self._renderer = None
        self._scene_cache = None
        self._view: TrialView | None = None
        self._scene_req: tuple | None = None
        self._pending: list[str] = []
        self._last_now: float | None = None
        self.fb_size = (1280, 720)
        self.scale = 1.0
        self.now = 0.0
        self.frame_index = 0
        # screen state that outlives a frame
        self.env_report = None
        self.test_sound_played = False
        self.answers: dict[str, Any] = {}
        self.question_active = 0
        self.question_moved = False   # the keyboard picked another questionnaire item: scroll it into view
        self.focus_text = False
        self.typing = False
        self.declining = False        # the welcome page asks "end without taking part?" before it does
        self.quit = False
        self.fullscreen_toggle = False
        self.error: str | None = None
        self.page_pad_x: float | None = None   # set by each page for its bottom row
        #: one line on the final screen: whether a bundle run's answers reached the study server (None: no uploads)
        self.upload_status: Callable[[], str] | None = None

    @property
    def results_file(self) -> Path | None:
        """The results file a remote (bundle) run wrote at the end (set by the session), else None."""
        return self.session.results_file

    # -- resources ---------------------------------------------------------------------------------
    @property
    def clock(self) -> MediaClock:
        """The master clock (waits for an output still opening: see the class text)."""
        if self._clock is None:
            self._take_audio()
        return self._clock

    @clock.setter
    def clock(self, clock: MediaClock) -> None:
        self._clock, self._pending_audio = clock, None

    def _take_audio(self) -> None:
        clock, message = self._pending_audio.result()
        self._clock, self._pending_audio = clock, None
        print(message, flush=True)

    @property
    def renderer(self) -> Renderer:
        if self._renderer is None:
            from studyapp.render.renderer import Renderer

            self._renderer = Renderer(self.ctx)
        return self._renderer

    def trial_view(self) -> TrialView | None:
        plan = self.session.current_trial()
        if plan is None:
            self._view = None
            return None
        if self._view is None or self._view.plan.trial_index != plan.trial_index:
            self._view = TrialView(self, plan)
        return self._view

    # -- requests from screens ------------------------------------------------------------------
    def request_scene(self, scene: TrialScene, t: float, rect: tuple[float, float, float, float]) -> None:
        self._scene_req = (scene, t, rect)

    def request_trial_load(self) -> None:
        if "trial" not in self._pending:
            self._pending.append("trial")

    def request_env_check(self) -> None:
        if "env" not in self._pending:
            self._pending.append("env")

    def key_pressed(self, key: Any) -> bool:
        """A key went down this frame (no repeats), unless the participant is typing into a text box."""
        from imgui_bundle import imgui

        if imgui.get_io().want_text_input:
            return False
        names = {"enter": ("enter", "keypad_enter"), "space": ("space",), "up": ("up_arrow",),
                 "down": ("down_arrow",), "backspace": ("backspace",), "delete": ("delete",), "f11": ("f11",)}
        keys = [getattr(imgui.Key, n) for n in names[key]] if isinstance(key, str) else [key]
        return any(imgui.is_key_pressed(k, False) for k in keys)

    def typed_text(self) -> str:
        """The characters typed this frame, in the order typed; empty while a text box takes the typing.

        For symbols such as ``=``: which physical key types them depends on the keyboard layout (Shift+0 on
        a German one), so they are read from the typed text, not from key codes.
        """
        from imgui_bundle import imgui

        io = imgui.get_io()
        if io.want_text_input:
            return ""
        typed = io.input_queue_characters
        return "".join(chr(typed[i]) for i in range(typed.size()))

    def estimated_minutes(self) -> int:
        total = 0.0
        by_id = {s.id: s for s in self.design.stimuli}
        for plan in self.session.plans:
            stim = by_id.get(plan.stimulus_id)
            total += _clip_seconds(stim) + 40.0  # watching once + ranking three questions
        return max(2, int(round(total / 60.0)))

    def play_test_sound(self) -> None:
        from studyapp.audio.playback import sound_check_tone

        rate = getattr(self.clock, "rate", 48000)
        self.clock.play(sound_check_tone(sample_rate=rate))
        self.test_sound_played = True

    def env_info(self) -> dict[str, Any]:
        """What the environment check found, as stored with the session."""
        if self.env_report is None:
            return {}
        d = self.env_report.as_dict()
        keep = ("gl_renderer", "gl_version", "display", "display_size", "refresh_hz", "content_scale",
                "audio_device", "audio_latency_ms", "render_fps", "ok", "verdict")
        return {k: d[k] for k in keep if d.get(k) is not None}

    def screen_key(self) -> str:
        """A name for what is on screen (screenshots, tests): ``welcome``, ``trials:ranking``, ...

        Trials: ``loading``, ``ready``, ``playing``, ``paused``, ``ended``, then ``ranking`` / ``ranked`` (a
        ranking trial) or ``answering`` / ``answered`` (the other paradigms) while the answers are open, and
        ``block`` while a block's instructions page is shown before its first trial.
        """
        from studyapp.ui.screens.block_intro import pending

        state = self.session.state.value
        plan = self.session.current_trial()
        if plan is not None and pending(self):
            return f"{state}:block"
        view = self._view
        if plan is None or view is None or view.plan.trial_index != plan.trial_index:
            view = None
        if plan is not None and view is None:
            return f"{state}:loading"
        if view is None:
            if state == "env_check" and self.env_report is None:
                return "env_check:measuring"
            return state
        if not view.loaded:
            return f"{state}:loading"
        if view.ranking_open() and not view.in_play:
            if view.paradigm == "rank":
                return f"{state}:{'ranked' if view.answers_complete() else 'ranking'}"
            return f"{state}:{'answered' if view.answers_complete() else 'answering'}"
        return f"{state}:{view.state}"

    def _on_focus(self, focused: bool) -> None:
        view = self._view
        if not focused and view is not None and bool(self.design.playback.pause_on_focus_loss):
            view.pause()

    # -- the frame ---------------------------------------------------------------------------------
    def frame(self, fbo: moderngl.Framebuffer, fb_size: tuple[int, int], now: float, content_scale: float = 1.0) -> None:
        """Build and draw one frame into ``fbo`` (``fb_size`` pixels) for time ``now`` (seconds)."""
        from imgui_bundle import imgui

        from studyapp.study.session import State
        from studyapp.ui.screens import env_check, final, instructions, questionnaire, trial, welcome

        dt = 1.0 / 60.0 if self._last_now is None else max(1e-4, now - self._last_now)
        self._last_now = now
        self.now = now
        self.fb_size = (int(fb_size[0]), int(fb_size[1]))
        self.input.apply(imgui.get_io())
        self.layer.new_frame(self.fb_size, dt, content_scale)
        self.scale = self.layer.scale
        self.ui.begin_frame()
        self._scene_req = None
        screens = {
            State.WELCOME: welcome.draw, State.INSTRUCTIONS: instructions.draw, State.ENV_CHECK: env_check.draw,
            State.PRACTICE: trial.draw, State.TRIALS: trial.draw, State.QUESTIONNAIRE: questionnaire.draw,
            State.DONE: final.draw, State.ENDED_EARLY: final.draw, State.DECLINED: final.draw,
        }
        try:
            screens[self.session.state](self)
        except StudyappError as exc:  # a refused action (e.g. a ranking the session rejects): say so
            self.error = str(exc)
            log.warning("%s", exc)
        if self.key_pressed("f11"):
            self.fullscreen_toggle = True
        if self.error:
            self._draw_error()
        fbo.use()
        self.ctx.viewport = (0, 0, *self.fb_size)
        req = self._scene_req
        if req is None or req[2][2] < 1 or req[2][3] < 1:
            fbo.clear(*BACKGROUND, 1.0, depth=1.0)
            self.layer.render(self.fb_size)
        else:  # the scene cache fills the whole frame: the scene, BACKGROUND around it (one copy, no clear)
            scene, t, (x, y, w, h) = req
            viewport = (int(x), int(self.fb_size[1] - y - h), int(w), int(h))  # GL: origin bottom-left
            if self._scene_cache is None:
                from studyapp.ui.scene_cache import SceneCache

                self._scene_cache = SceneCache(self.ctx)
            # the UI goes over the scene where the cache says (into a new picture before its copy)
            self._scene_cache.draw(self.renderer, scene, t, fbo, viewport, self.fb_size, BACKGROUND,
                                   overlay=lambda: self.layer.render(self.fb_size))
            fbo.use()
            self.ctx.viewport = (0, 0, *self.fb_size)
        self.frame_index += 1

    def _draw_error(self) -> None:
        from imgui_bundle import imgui

        s = self.scale
        imgui.set_next_window_pos((self.fb_size[0] / 2, 20 * s), 0, imgui.ImVec2(0.5, 0.0))
        imgui.begin("##error", None, imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_decoration)
        self.ui.text(self.error, color=(1.0, 0.55, 0.5, 1.0))
        if self.ui.button("OK", key="error_ok"):
            self.error = None
        imgui.end()

    def after_flip(self, flip_time: float) -> None:
        """Call right after the frame was presented (swap) with the time it happened."""
        self.predictor.flipped(flip_time)
        if self._pending_audio is not None and self._pending_audio.done():
            self._take_audio()
        if self._view is not None:
            self._view.after_flip(flip_time)
        while self._pending:
            job = self._pending.pop(0)
            if job == "trial" and self._view is not None and not self._view.loaded:
                self._view.load()
            elif job == "env" and self.env_report is None:
                from studyapp.ui.envcheck import gather

                self.env_report = gather(self.ctx, clock=self.clock, bench_frames=self.bench_frames,
                                         display=self.display)

    def shutdown(self) -> None:
        view = self._view
        if view is not None and view.in_play:
            view.stop()
        if self._scene_cache is not None:
            self._scene_cache.release()
        self.layer.shutdown()


def _clip_seconds(stim: Stimulus | None) -> float:
    """About how long a clip plays, for "about N minutes": the trial timeline's rule on the audio's length."""
    from studyapp.study.timeline import trial_duration

    if stim is None:
        return 30.0
    try:
        with wave.open(str(stim.audio), "rb") as w:
            audio_s = w.getnframes() / float(w.getframerate())
    except Exception:  # non-PCM WAV variants: an estimate is enough for "about N minutes"
        audio_s = 30.0
    return trial_duration(stim.duration_s, audio_s)


# -- the window -----------------------------------------------------------------------------------------

class WindowRunner:
    """The participant window: a GLFW :class:`~studyapp.render.context.Window` driving a StudyApp through
    the frame loop (:class:`~studyapp.render.loop.FrameLoop`).

    :meth:`step` runs one frame (tests interleave it with xdotool events); :meth:`run` loops until the
    participant finishes or closes the window. ``timer``: the loop's frame timer, real time by default
    (a :class:`~studyapp.render.loop.VirtualTimer` makes the window play frame for frame what the
    offscreen path plays, for comparing the two). ``clock``: the master clock, or a
    :class:`~studyapp.audio.playback.PendingClock` still opening (see :class:`StudyApp`).
    """

    def __init__(self, design: Design, session: ParticipantSession, clock: MediaClock | PendingClock, *,
                 fullscreen: bool = False, size: tuple[int, int] = (1280, 720), vsync: bool = True,
                 timer: FrameTimer | None = None, maximized: bool = False,
                 upload_status: Callable[[], str] | None = None) -> None:
        import glfw

        from studyapp.render.context import Window
        from studyapp.render.loop import FrameLoop, WallTimer, WindowTarget

        self.window = Window(size, fullscreen=fullscreen, vsync=vsync, maximized=maximized)
        self.queue = InputQueue()
        self.queue.attach_glfw(self.window)
        monitor = glfw.get_window_monitor(self.window.handle) or glfw.get_primary_monitor()
        mode = glfw.get_video_mode(monitor) if monitor else None
        refresh = float(mode.refresh_rate) if mode and mode.refresh_rate else None
        display = ("window", (mode.size.width, mode.size.height) if mode else None, refresh,
                   self.window.content_scale[0])
        self.app = StudyApp(design, session, self.window.ctx, clock, queue=self.queue, refresh_hz=refresh,
                            display=display)
        self.app.upload_status = upload_status
        self.loop = FrameLoop(WindowTarget(self.window), timer if timer is not None else WallTimer(),
                              self._draw, self._after_flip, running=lambda: not self.app.quit,
                              pacer=self.app.predictor)

    @property
    def capture(self) -> bool:
        """Read each frame back into :attr:`last_rgb` (tests)."""
        return self.loop.capture

    @capture.setter
    def capture(self, on: bool) -> None:
        self.loop.capture = bool(on)

    @property
    def last_rgb(self) -> np.ndarray | None:
        return self.loop.last_rgb

    def _draw(self, fbo: moderngl.Framebuffer, size: tuple[int, int], now: float) -> None:
        self.app.frame(fbo, size, now, self.window.content_scale[0])

    def _after_flip(self, flip_time: float) -> None:
        self.app.after_flip(flip_time)
        if self.app.fullscreen_toggle:
            self.app.fullscreen_toggle = False
            self.window.set_fullscreen(not self.window.is_fullscreen)

    def step(self) -> bool:
        """One frame; False once the window should close (participant done or window closed)."""
        return self.loop.step()

    def run(self) -> None:
        self.loop.run()

    def close(self) -> None:
        self.app.shutdown()
        self.window.close()


def run_window(design: Design, db: ResultsDB, participant_id: str, fullscreen: bool = False,
               audio_device: int | str | None = None, *, size: tuple[int, int] = (1280, 720),
               plans: Sequence[Any] | None = None, n_rows: int | None = None,
               upload_status: Callable[[], str] | None = None, audio: PendingClock | None = None) -> int:
    """Run the participant's session in a window. Returns 0 when the study was completed (or ended
    early by the attention rule), 1 when the window was closed before the end (run again to resume).

    ``audio_device``: output index or name (default: ``$STUDYAPP_AUDIO_DEVICE``, else the system
    default); without any output the study runs silently and says so (console and environment check).
    ``plans`` and ``n_rows``: a schedule given instead of the design's (a bundle's participant).
    ``upload_status``: the final screen's line about the answers' uploads (:mod:`studyapp.study.upload`).
    ``audio``: the output, opening since the caller started it (``studyapp run`` does, before it loads the
    design), used instead of opening one here (``audio_device`` is then ignored); the caller closes it too.
    """
    from studyapp.audio.playback import PendingClock
    from studyapp.study.session import Session

    if audio is None:
        if audio_device is None:  # lets the experimenter pick the output for any front end that calls us
            audio_device = os.environ.get("STUDYAPP_AUDIO_DEVICE") or None
        audio = PendingClock(audio_device)  # opens while the session is prepared
    try:
        session = Session(design, db, participant_id, plans=plans, n_rows=n_rows)
    except BaseException:
        audio.close()
        raise
    runner = None
    try:
        # maximized: the figures get the whole screen; F11 switches to full screen and back. The window, its
        # GL context, the UI and the first frames come while the audio output still opens (see StudyApp).
        runner = WindowRunner(design, session, audio, fullscreen=fullscreen, size=size, maximized=True,
                              upload_status=upload_status)
        runner.run()
    finally:
        if runner is not None:
            runner.close()
        audio.close()  # the output, opened or not (the runner's clock when it is an AudioPlayer)
        session.close()
    if session.finished:
        return 0
    print(f"The window was closed before the end; run the same command again to continue "
          f"(participant {session.participant_id}).", flush=True)
    return 1
