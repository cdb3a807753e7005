"""``studyapp view`` (look at one motion file) and ``studyapp render`` (a participant's trial to PNG/MP4)."""
from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from studyapp.errors import InputError, StudyappError

log = logging.getLogger(__name__)


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 1280x720, got {text!r}") from None
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"size too small: {text!r}")
    return w, h


def register(subparsers: argparse._SubParsersAction) -> None:
    v = subparsers.add_parser(
        "view", help="play one motion file on the avatar in a window (or render a frame offscreen)",
        description="Play a motion (BVH or array) on the avatar. Keys: space = pause, R = restart, Esc = close.",
    )
    v.add_argument("motion", help="motion file (BVH, NPZ, ...)")
    v.add_argument("--face", help="ARKit blendshape file (Live Link CSV, BEAT JSON, ...)")
    v.add_argument("--audio", help="WAV file to play along")
    v.add_argument("--avatar", help="glTF/GLB/VRM avatar (default: the built-in one)")
    v.add_argument("--fps", type=float, help="true frame rate of the motion when its header is wrong")
    v.add_argument("--offscreen", action="store_true", help="render one frame headless instead of opening a window")
    v.add_argument("--out", help="PNG to write with --offscreen")
    v.add_argument("--time", type=float, default=0.0, help="time in seconds of the offscreen frame")
    v.add_argument("--size", type=_size, default=(960, 720), help="window / image size, e.g. 960x720")
    v.add_argument("--fullscreen", action="store_true", help="open fullscreen")
    v.set_defaults(func=cmd_view)

    r = subparsers.add_parser(
        "render", help="render a participant's trial exactly as they see it (PNG frame or MP4 clip)",
        description="Render one trial of a participant's sequence offscreen, with the clips in the slots and "
        "order that participant sees: a still frame at --time as a PNG, or the whole trial with its audio as "
        "an MP4.",
    )
    r.add_argument("design", help="study design (TOML)")
    r.add_argument("--participant", required=True, help="participant id")
    r.add_argument("--trial", type=int, required=True, help="0-based trial index in that participant's sequence")
    r.add_argument("--time", type=float, help="time in seconds of the still frame (required for a PNG)")
    r.add_argument("--out", required=True, help="FRAME.png (with --time) or CLIP.mp4")
    r.add_argument("--size", type=_size, default=(1280, 720), help="image size, e.g. 1280x720")
    r.add_argument("--fps", type=int, default=30, help="video frame rate")
    r.set_defaults(func=cmd_render)


def _single_scene(args: argparse.Namespace, aspect: float):
    from studyapp.motion.io import load_motion
    from studyapp.render.pose import prepare_slot
    from studyapp.render.scene import load_avatar, make_scene

    motion = load_motion(args.motion, fps=args.fps)
    face = None
    if args.face:
        from studyapp.face.io import load_face

        face = load_face(args.face)
    avatar = load_avatar(args.avatar)
    slot = prepare_slot(avatar, motion, face)
    return make_scene([slot], avatar, labels=None, aspect=aspect)


def cmd_view(args: argparse.Namespace) -> int:
    audio = None
    if args.audio:
        from studyapp.audio.wav import load_wav

        audio = load_wav(args.audio)
    w, h = args.size
    if args.offscreen:
        if not args.out:
            raise StudyappError("--offscreen needs --out FRAME.png")
        from studyapp.render.video import render_still

        scene = _single_scene(args, w / h)
        render_still(scene, args.time, args.out, size=(w, h))
        print(f"wrote {args.out}")
        return 0
    return _view_window(args, audio)


def _view_window(args: argparse.Namespace, audio) -> int:
    import glfw

    from studyapp.render.context import Window
    from studyapp.render.renderer import Renderer

    win = Window(args.size, fullscreen=args.fullscreen)
    try:
        fw, fh = win.framebuffer_size
        scene = _single_scene(args, fw / max(fh, 1))
        renderer = Renderer(win.ctx)
        clock = _Clock(audio, scene.duration)
        state = {"aspect": fw / max(fh, 1)}

        def on_key(key: int, _sc: int, action: int, _mods: int) -> None:
            if action != glfw.PRESS:
                return
            if key == glfw.KEY_ESCAPE:
                win.request_close()
            elif key == glfw.KEY_SPACE:
                clock.toggle()
            elif key == glfw.KEY_R:
                clock.restart()

        win.on_key(on_key)
        while not win.should_close:
            win.poll_events()
            fw, fh = win.framebuffer_size
            if fw == 0 or fh == 0:  # minimised
                time.sleep(0.05)
                continue
            if abs(fw / fh - state["aspect"]) > 1e-3:
                from studyapp.render.scene import make_scene

                scene = make_scene(scene.slots, scene.avatars, None, aspect=fw / fh, duration=scene.duration)
                state["aspect"] = fw / fh
            win.use()
            renderer.draw_trial(scene, clock.time(), win.fbo, (0, 0, fw, fh))
            win.swap_buffers()
        clock.close()
        renderer.release()
    finally:
        win.close()
    return 0


class _Clock:
    """Looping playback time: the audio device's clock when there is one, else the wall clock."""

    def __init__(self, audio, duration: float) -> None:
        self.audio = audio
        self.duration = max(duration, (len(audio.samples) / audio.sample_rate) if audio is not None else 0.0, 1e-3)
        self.player = None
        if audio is not None:
            try:
                from studyapp.audio.playback import AudioPlayer

                self.player = AudioPlayer()
            except Exception as exc:  # no sound card: play silently
                log.warning("no audio output (%s); playing silently", exc)
        self._t0 = time.perf_counter()
        self._paused_at: float | None = None
        self._start_audio()

    def _start_audio(self) -> None:
        if self.player is not None:
            self.player.play(self.audio)

    def time(self) -> float:
        if self._paused_at is not None:
            return self._paused_at
        t = time.perf_counter() - self._t0
        if t >= self.duration:  # loop
            self.restart()
            t = 0.0
        return t

    def toggle(self) -> None:
        if self._paused_at is None:
            self._paused_at = time.perf_counter() - self._t0
            if self.player is not None:
                self.player.pause()
        else:
            self._t0 = time.perf_counter() - self._paused_at
            self._paused_at = None
            if self.player is not None:
                self.player.resume()

    def restart(self) -> None:
        self._t0 = time.perf_counter()
        if self._paused_at is not None:
            self._paused_at = 0.0
        self._start_audio()

    def close(self) -> None:
        if self.player is not None:
            self.player.close()


def cmd_render(args: argparse.Namespace) -> int:
    from studyapp.study.design import load_design
    from studyapp.study.schedule import participant_schedule
    from studyapp.study.stimuli import load_trial_media
    from studyapp.render.scene import build_trial_scene
    from studyapp.render.video import render_still, render_video

    design = load_design(args.design)
    plans = participant_schedule(design, args.participant)
    match = [p for p in plans if p.trial_index == args.trial]
    if not match:
        raise InputError(args.design, f"--trial {args.trial}",
                         f"participant {args.participant!r} has trials 0..{len(plans) - 1}")
    media = load_trial_media(design, match[0])
    scene = build_trial_scene(None, media)
    out = Path(args.out)
    if out.suffix.lower() == ".png":
        if args.time is None:
            raise StudyappError("a PNG needs --time SECONDS (or write an .mp4 for the whole trial)")
        if not 0.0 <= args.time <= scene.duration:
            raise StudyappError(f"--time {args.time:g} is outside the trial, which lasts {scene.duration:.2f} s")
        render_still(scene, args.time, out, size=args.size)
    elif out.suffix.lower() in (".mp4", ".m4v", ".mov"):
        duration = getattr(media, "duration_s", None)
        render_video(scene, media.audio, out, size=args.size, fps=args.fps, duration=duration)
    else:
        raise InputError(out, None, "output must end in .png or .mp4")
    print(f"wrote {out}")
    return 0
