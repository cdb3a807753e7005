"""Can this PC run the study? One function for ``studyapp doctor`` and the in-app environment check.

:func:`gather` measures (GL renderer and version, display size and refresh, audio outputs and the
output latency, a short render benchmark of the three built-in avatars) and :func:`evaluate` turns the
facts into pass / warn / fail checks with a plain-language verdict. Both the doctor and the participant
window call :func:`gather`, so the experimenter's pre-flight check and the in-app check agree.

>>> r = EnvReport(gl_renderer="llvmpipe", gl_version_code=450, refresh_hz=60.0, audio_device="NullSink",
...               audio_latency_ms=40.0, render_fps=45.0)
>>> [c.status for c in evaluate(r)], verdict(evaluate(r))[0]
(['pass', 'pass', 'pass', 'pass'], True)

Participants see the same checks in plain words (:func:`plain`, :func:`plain_verdict`): no renderer
names, frame rates or API versions; those stay in the experimenter's ``doctor`` output and in what the
session records (``env_check`` in the results database).

>>> [plain(c) for c in evaluate(r)][0], plain_verdict(evaluate(r))
(('Graphics', 'The figures can be shown.'), 'Everything is ready.')
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from studyapp.study.design.texts import EN as EN_TEXTS

if TYPE_CHECKING:
    import moderngl

    from studyapp.audio.clock import MediaClock
    from studyapp.render.scene import TrialScene

#: Below this many frames per second the clips stutter visibly (the study shows 15-30 fps motion).
MIN_RENDER_FPS = 24.0
#: The picture follows the audio clock, so latency only delays the start; beyond this the sound check
#: becomes confusing and the output is probably a Bluetooth headset.
MAX_AUDIO_LATENCY_MS = 250.0
MIN_REFRESH_HZ = 50.0


@dataclass
class Check:
    name: str
    status: str  # "pass" | "warn" | "fail"
    detail: str


@dataclass
class EnvReport:
    """What :func:`gather` found (None where it could not be measured)."""

    gl_renderer: str | None = None
    gl_vendor: str | None = None
    gl_version: str | None = None
    gl_version_code: int | None = None
    display: str | None = None          # None: no display
    display_size: tuple[int, int] | None = None
    refresh_hz: float | None = None
    content_scale: float | None = None
    audio_devices: list[str] = field(default_factory=list)
    audio_device: str | None = None     # the output the study will use; None: none
    audio_latency_ms: float | None = None
    audio_error: str | None = None
    render_fps: float | None = None
    render_frames: int = 0
    render_size: tuple[int, int] | None = None
    render_error: str | None = None

    def as_dict(self) -> dict[str, Any]:
        d = asdict(self)
        checks = evaluate(self)
        ok, summary = verdict(checks)
        d["checks"] = [asdict(c) for c in checks]
        d["ok"] = ok
        d["verdict"] = summary
        return d


def evaluate(r: EnvReport) -> list[Check]:
    """Pass/warn/fail checks for a report (pure; no measuring)."""
    checks = []
    if r.gl_version_code is None:
        checks.append(Check("OpenGL", "fail", r.render_error or "no OpenGL context could be created"))
    elif r.gl_version_code < 330:
        checks.append(Check("OpenGL", "fail", f"OpenGL {r.gl_version_code / 100:.1f} < 3.3 ({r.gl_renderer}); "
                                               "update the graphics driver"))
    else:
        checks.append(Check("OpenGL", "pass", f"{r.gl_renderer} (OpenGL {r.gl_version_code / 100:.1f})"))
    if not r.refresh_hz:  # None or 0: GLFW reports 0 Hz when the display does not say (Xvfb, VMs)
        checks.append(Check("Display", "warn", "no display found: only offscreen runs are possible"
                            if r.display is None else "refresh rate unknown"))
    elif r.refresh_hz < MIN_REFRESH_HZ:
        checks.append(Check("Display", "warn", f"{r.refresh_hz:.0f} Hz refresh; motion may look choppy"))
    else:
        size = f"{r.display_size[0]}x{r.display_size[1]}, " if r.display_size else ""
        checks.append(Check("Display", "pass", f"{size}{r.refresh_hz:.0f} Hz"))
    if not r.audio_device:
        checks.append(Check("Audio", "fail", r.audio_error or "no audio output device: the clips would be silent"))
    elif r.audio_latency_ms is not None and r.audio_latency_ms > MAX_AUDIO_LATENCY_MS:
        checks.append(Check("Audio", "warn", f"{r.audio_device}: {r.audio_latency_ms:.0f} ms output latency "
                                             "(compensated; wired headphones are better)"))
    else:
        lat = "" if r.audio_latency_ms is None else f", {r.audio_latency_ms:.0f} ms latency (compensated)"
        checks.append(Check("Audio", "pass", f"{r.audio_device}{lat}"))
    if r.render_fps is None:
        checks.append(Check("Rendering", "fail" if r.render_error else "warn",
                            r.render_error or "render speed not measured"))
    elif r.render_fps < MIN_RENDER_FPS:
        checks.append(Check("Rendering", "fail", f"{r.render_fps:.1f} fps for three avatars; need at least "
                                                 f"{MIN_RENDER_FPS:.0f}"))
    else:
        target = r.refresh_hz or 60.0
        status = "pass" if r.render_fps >= min(target, 60.0) * 0.5 else "warn"
        checks.append(Check("Rendering", status, f"{r.render_fps:.0f} fps for three avatars"))
    return checks


def verdict(checks: list[Check]) -> tuple[bool, str]:
    """(can run, one sentence)."""
    fails = [c for c in checks if c.status == "fail"]
    warns = [c for c in checks if c.status == "warn"]
    if fails:
        return False, "This computer cannot run the study yet: " + "; ".join(f"{c.name}: {c.detail}" for c in fails)
    if warns:
        return True, "This computer can run the study (check: " + "; ".join(c.name for c in warns) + ")."
    return True, "This computer can run the study."


#: The participant texts (:mod:`studyapp.study.design.texts`) naming each check; its sentence is
#: ``<key>.<status>``, or the nearest one a check of that kind can have.
PLAIN = {"OpenGL": "env.graphics", "Display": "env.screen", "Audio": "env.sound", "Rendering": "env.animation"}
_NEAREST = {"pass": ("pass",), "warn": ("warn", "pass"), "fail": ("fail", "warn")}


def plain(check: Check, texts: Mapping[str, str] = EN_TEXTS) -> tuple[str, str]:
    """(name, sentence) of ``check`` for a participant, from ``texts`` (a design's): no technical details
    (they stay in the record)."""
    base = PLAIN.get(check.name, "env.screen")
    sentence = next(texts[k] for k in (f"{base}.{s}" for s in _NEAREST[check.status]) if k in texts)
    return texts[base], sentence


def plain_verdict(checks: list[Check], texts: Mapping[str, str] = EN_TEXTS) -> str:
    """The verdict for a participant, in one plain sentence."""
    worst = "fail" if any(c.status == "fail" for c in checks) else (
        "warn" if any(c.status == "warn" for c in checks) else "pass")
    return texts[f"env.verdict.{worst}"]


# -- measuring ---------------------------------------------------------------------------------------

def display_facts() -> tuple[str | None, tuple[int, int] | None, float | None, float | None]:
    """(display name, primary monitor size, refresh Hz, content scale) or Nones without a display."""
    import os
    import sys

    name = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    if not name and sys.platform not in ("win32", "darwin"):
        return None, None, None, None
    try:
        import glfw

        if not glfw.init():
            return name, None, None, None
        mon = glfw.get_primary_monitor()
        if not mon:
            return name, None, None, None
        mode = glfw.get_video_mode(mon)
        sx, _ = glfw.get_monitor_content_scale(mon)
        refresh = float(mode.refresh_rate) or None  # 0: the display does not report it
        return (name or "desktop"), (mode.size.width, mode.size.height), refresh, float(sx)
    except Exception:
        return name, None, None, None


def audio_facts(report: EnvReport, device: int | str | None = None, clock: MediaClock | None = None,
                measure_s: float = 2.5) -> None:
    """Fill the audio fields: devices, the chosen output and its measured latency.

    With ``clock`` (the app's open :class:`AudioPlayer`) its measurements are used; otherwise a player
    is opened for up to ``measure_s`` seconds (PulseAudio needs about a second to settle).
    """
    from studyapp.audio.playback import AudioDeviceError, AudioPlayer, list_output_devices

    devices = list_output_devices()
    report.audio_devices = [f"{d.index}: {d.name}{' (default)' if d.is_default else ''}" for d in devices]
    if clock is not None and isinstance(clock, AudioPlayer):
        report.audio_device = clock.device_name
        report.audio_latency_ms = round(clock.output_latency_s * 1000.0, 1)
        return
    if clock is not None:  # a SilentClock: the app already knows there is no usable output
        report.audio_error = f"no sound: {getattr(clock, 'reason', clock.device_name)}"
        return
    try:
        player = AudioPlayer(device)
    except AudioDeviceError as exc:
        report.audio_error = str(exc)
        return
    try:
        player.wait_until_flowing(measure_s)
        report.audio_device = player.device_name
        report.audio_latency_ms = round(player.output_latency_s * 1000.0, 1)
    finally:
        player.close()


def gl_facts(report: EnvReport, ctx: moderngl.Context) -> None:
    info = ctx.info
    report.gl_renderer = str(info.get("GL_RENDERER"))
    report.gl_vendor = str(info.get("GL_VENDOR"))
    report.gl_version = str(info.get("GL_VERSION"))
    report.gl_version_code = int(ctx.version_code)


def benchmark_scene(n_frames: int = 60, fps: float = 30.0) -> TrialScene:
    """Three built-in avatars waving their arms (different phases), independent of any design."""
    from studyapp.motion.rotations import axis_angle_to_quat, quat_multiply
    from studyapp.motion.skeleton import Motion
    from studyapp.render.avatar import build_default_avatar
    from studyapp.render.pose import prepare_slot
    from studyapp.render.scene import make_scene

    avatar = build_default_avatar()
    sk = avatar.skeleton
    t = np.arange(n_frames) / fps
    slots = []
    for k in range(3):
        motion = Motion.rest(sk, n_frames, fps)
        for name, sign in (("LeftUpperArm", 1.0), ("RightUpperArm", -1.0), ("LeftLowerArm", 1.0),
                           ("RightLowerArm", -1.0)):
            if name in sk.names:
                j = sk.index(name)
                angle = sign * (0.5 + 0.4 * np.sin(2 * np.pi * (0.8 + 0.3 * k) * t + k))
                swing = axis_angle_to_quat(np.outer(angle, [0.0, 0.0, 1.0]))
                motion.rotations[:, j] = quat_multiply(swing, sk.rest_rotations[j])
        slots.append(prepare_slot(avatar, motion, None))
    return make_scene(slots, avatar, labels=("A", "B", "C"))


def render_benchmark(ctx: moderngl.Context, n_frames: int = 30, size: tuple[int, int] = (1280, 720)) -> float:
    """Frames per second drawing three animated built-in avatars at ``size``, with a full read-back."""
    from studyapp.render.context import OffscreenTarget
    from studyapp.render.renderer import Renderer

    scene = benchmark_scene()
    renderer = Renderer(ctx)
    target = OffscreenTarget(ctx, size)
    try:
        times = []
        for k in range(n_frames + 2):
            t0 = time.perf_counter()
            target.clear((0.1, 0.1, 0.1))
            renderer.draw_trial(scene, (k / 30.0) % max(scene.duration, 1e-3), target.fbo, (0, 0, *size))
            target.read_rgb()
            times.append(time.perf_counter() - t0)
        steady = times[2:]  # the first frames compile shaders and upload buffers
        return float(len(steady) / sum(steady))
    finally:
        target.release()
        renderer.release()


def gather(ctx: moderngl.Context | None = None, *, audio_device: int | str | None = None,
           clock: MediaClock | None = None,
           bench_frames: int = 30, bench_size: tuple[int, int] = (1280, 720),
           display: tuple | None = None) -> EnvReport:
    """Measure everything the study needs. ``ctx``: an existing GL context (else an offscreen one).

    ``display`` overrides :func:`display_facts` (the app passes what its window reports).
    """
    report = EnvReport()
    report.display, report.display_size, report.refresh_hz, report.content_scale = (
        display if display is not None else display_facts())
    if ctx is None:
        try:
            from studyapp.render.context import create_offscreen_context

            ctx = create_offscreen_context()
        except Exception as exc:
            report.render_error = str(exc)
    if ctx is not None:
        gl_facts(report, ctx)
        if bench_frames > 0:
            try:
                report.render_fps = round(render_benchmark(ctx, bench_frames, bench_size), 1)
                report.render_frames = bench_frames
                report.render_size = tuple(bench_size)
            except Exception as exc:  # a broken driver shows up here; say so rather than crash
                first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
                report.render_error = f"render benchmark failed: {type(exc).__name__}: {first[:200]}"
    audio_facts(report, audio_device, clock)
    return report
