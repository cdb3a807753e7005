"""``studyapp view`` (look at one motion file) and ``studyapp render`` (a participant's trial to PNG/MP4)."""
from __future__ import annotations

import argparse
import logging
import os
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from studyapp.errors import InputError, StudyappError

if TYPE_CHECKING:
    from studyapp.study.design import Design

log = logging.getLogger(__name__)


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"size must look like 1280x720, got {text!r}") from None
    if w < 16 or h < 16:
        raise argparse.ArgumentTypeError(f"size too small: {text!r}")
    return w, h


def _names(text: str) -> tuple[str, ...]:
    names = tuple(n for n in text.replace(",", " ").split() if n)
    if not names:
        raise argparse.ArgumentTypeError("--joints needs joint names, e.g. Spine,Spine1,Neck")
    return names


def _bone_map(text: str) -> dict[str, str]:
    from studyapp.render.avatar_rig import parse_bone_map

    try:
        return parse_bone_map(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def register(subparsers: argparse._SubParsersAction) -> None:
    v = subparsers.add_parser(
        "view", help="play one motion file on the avatar in a window (or render a frame offscreen)",
        description="Play a motion (BVH or NPZ/NPY array) on the avatar, looping, on the same media clock as "
        "a study (the sound card's when --audio plays). The condition options mean what the same keys mean "
        "in a design's [[conditions]]. Keys: space = pause, R = restart, Esc = close.",
    )
    v.add_argument("motion", help="motion file (BVH, NPZ, NPY)")
    v.add_argument("--face", help="ARKit blendshape file (Live Link CSV, BEAT JSON, ...); default for an SMPL-X "
                   "motion: its jaw drives jawOpen")
    v.add_argument("--flame-map", help="(E, 52) .npy mapping an SMPL-X file's FLAME expressions to ARKit shapes")
    v.add_argument("--audio", help="WAV file to play along (it sets how long one loop lasts)")
    v.add_argument("--avatar", help="glTF/GLB/VRM avatar (default: the built-in one)")
    v.add_argument("--framing", choices=("upper-body", "full-body"), default="upper-body",
                   help="what the camera shows, as a design's [display] framing (default: upper-body)")
    c = v.add_argument_group("condition options (as in a design's [[conditions]])")
    c.add_argument("--fps", type=float, help="true frame rate of the motion (arrays have none; BVH headers can lie)")
    c.add_argument("--name-map", action="append", metavar="JOINT=BONE|FILE.toml",
                   help="source joint -> humanoid bone; repeat it, or give a TOML file "
                   "(what `studyapp inspect FILE --name-map-template` writes)")
    c.add_argument("--template", help="BVH whose skeleton an NPZ/NPY array drives")
    c.add_argument("--representation", help="rotations of an NPZ/NPY array: euler, axis_angle, quat, quat_wxyz, "
                   "sixd (Zhou's columns), sixd_rows (PyTorch3D's rows), matrix")
    c.add_argument("--rotation-order", help="Euler order of an euler array, e.g. XYZ")
    c.add_argument("--joints", type=_names, help="template joints the array's columns drive, in order "
                   "(comma-separated)")
    deg = c.add_mutually_exclusive_group()
    deg.add_argument("--degrees", dest="degrees", action="store_true", default=None,
                     help="Euler arrays are in degrees (the default)")
    deg.add_argument("--radians", dest="degrees", action="store_false", help="Euler arrays are in radians")
    c.add_argument("--body-model", help="your SMPL/SMPL-H/SMPL-X model .npz: the rest skeleton of an SMPL-family file")
    v.add_argument("--avatar-bone-map", type=_bone_map, metavar="JOINT=BONE,...",
                   help="the avatar's [avatar.bone_map], e.g. UpperArm.L=LeftUpperArm,LowerArm.L=LeftLowerArm")
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
    r.add_argument("--results", type=Path, help="results database holding the participant's Latin-square row "
                   "(default: <design>.results.sqlite next to the design)")
    r.add_argument("--row", type=int, help="Latin-square row of a participant not (yet) in the results database "
                   "(default: the row derived from the id, as without a database)")
    r.set_defaults(func=cmd_render)


def _single_scene(args: argparse.Namespace, aspect: float):
    """The scene ``view`` plays: the motion read with the condition options, as a design reads it."""
    from studyapp.render.pose import prepare_slot
    from studyapp.render.scene import load_avatar, make_scene
    from studyapp.study.preview import load_preview_motion, parse_name_map, preview_condition

    cond = preview_condition(args.motion, fps=args.fps, name_map=parse_name_map(args.name_map),
                             template=args.template, representation=args.representation,
                             rotation_order=args.rotation_order, joints=args.joints, degrees=args.degrees,
                             body_model=args.body_model)
    motion = load_preview_motion(args.motion, cond)
    face = None
    if args.face:
        from studyapp.face.io import load_face

        face = load_face(args.face)
    else:
        from studyapp.cli.motion import smplx_face_of

        with warnings.catch_warnings(record=True) as caught:  # one "warning:" line, as convert prints them
            warnings.simplefilter("always", UserWarning)
            face = smplx_face_of(args.motion, fps=args.fps, flame_map=args.flame_map)
        for w in caught:
            print(f"warning: {w.message}", file=sys.stderr)
    avatar = load_avatar(args.avatar, bone_map=args.avatar_bone_map)
    slot = prepare_slot(avatar, motion, face, name_map=cond.name_map or None)
    return make_scene([slot], avatar, labels=None, aspect=aspect, framing=args.framing)


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
        render_still(scene, args.time, args.out, size=(w, h))  # the frame loop, on a virtual clock
        print(f"wrote {args.out}")
        return 0
    return _view_window(args, audio)


def _view_window(args: argparse.Namespace, audio) -> int:
    import glfw

    from studyapp.render.context import Window
    from studyapp.render.frames import FlipPredictor
    from studyapp.render.loop import FrameLoop, ScenePlayer, WallTimer, WindowTarget
    from studyapp.render.renderer import Renderer
    from studyapp.render.scene import make_scene

    win = Window(args.size, fullscreen=args.fullscreen)
    clock = _open_clock(audio)
    renderer = None
    try:
        fw, fh = win.framebuffer_size
        scene = _single_scene(args, fw / max(fh, 1))
        renderer = Renderer(win.ctx)
        # One loop lasts the audio when there is some (as a stimulus without duration_s), else the motion.
        duration = audio.duration if audio is not None else None
        player = ScenePlayer(renderer, scene, clock, audio=audio, duration_s=duration, loop=True,
                             predictor=FlipPredictor(_refresh_hz(win)))

        def on_key(key: int, _sc: int, action: int, _mods: int) -> None:
            if action != glfw.PRESS:
                return
            if key == glfw.KEY_ESCAPE:
                win.request_close()
            elif key == glfw.KEY_SPACE:
                player.toggle_pause()
            elif key == glfw.KEY_R:
                player.start(0.0)

        aspect_now = [fw / max(fh, 1)]

        def draw(fbo, size, now) -> None:
            aspect = size[0] / size[1]
            if abs(aspect - aspect_now[0]) > 1e-3:  # the window was resized: frame the figure anew
                player.scene = make_scene(player.scene.slots, player.scene.avatars, None, aspect=aspect,
                                          duration=player.scene.duration, framing=args.framing)
                aspect_now[0] = aspect
            player.draw(fbo, size, now)

        win.on_key(on_key)
        player.start(0.0)
        FrameLoop(WindowTarget(win), WallTimer(), draw, player.after_flip, pacer=player.predictor).run()
    finally:
        clock.close()
        if renderer is not None:
            renderer.release()
        win.close()
    return 0


def _open_clock(audio):
    """The media clock of ``view``: the sound card's when there is audio to play, else the wall clock."""
    from studyapp.audio.clock import SilentClock

    if audio is None:
        return SilentClock(reason="no --audio")
    from studyapp.audio.playback import open_clock

    # the output a study session would use (run_window reads the same variable)
    clock, message = open_clock(os.environ.get("STUDYAPP_AUDIO_DEVICE") or None)
    log.info("%s", message)
    if isinstance(clock, SilentClock):
        print(message, flush=True)
    return clock


def _refresh_hz(win) -> float | None:
    import glfw

    monitor = glfw.get_window_monitor(win.handle) or glfw.get_primary_monitor()
    mode = glfw.get_video_mode(monitor) if monitor else None
    return float(mode.refresh_rate) if mode and mode.refresh_rate else None


def _participant_row(args: argparse.Namespace, design: "Design") -> int | None:
    """The row the participant follows: the one the results database gave them (rows are assigned in order of
    arrival, so the id alone does not tell it), else ``--row``, else None (the row derived from the id)."""
    from studyapp.cli.session import default_results_path
    from studyapp.study.storage import ResultsDB

    results = args.results or default_results_path(Path(args.design))
    record = None
    if results.is_file() and results.stat().st_size > 0:
        db = ResultsDB(results, create=False)
        try:
            record = db.participant(args.participant)
        finally:
            db.close()
    if record is not None:
        if args.row is not None and args.row != record.latin_row:
            raise InputError(results, f"participant {args.participant}", f"follows row {record.latin_row}, not "
                             f"--row {args.row}; drop --row")
        return int(record.latin_row)
    if args.results is not None and args.row is None:
        raise InputError(results, None, f"no participant {args.participant!r} in this results database")
    return args.row


def cmd_render(args: argparse.Namespace) -> int:
    from studyapp.study.design import load_design
    from studyapp.study.schedule import participant_schedule
    from studyapp.study.stimuli import load_trial_media
    from studyapp.render.scene import build_trial_scene
    from studyapp.render.video import render_still, render_video

    design = load_design(args.design)
    plans = participant_schedule(design, args.participant, row=_participant_row(args, design))
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
        from studyapp.cli.extras import require

        require("render", "av")
        duration = getattr(media, "duration_s", None)
        render_video(scene, media.audio, out, size=args.size, fps=args.fps, duration=duration)
    else:
        raise InputError(out, None, "output must end in .png or .mp4")
    print(f"wrote {out}")
    return 0
