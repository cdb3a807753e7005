"""The participant frame against a bare draw: three built-in avatars at 1280x720, read back every frame.

Four pipelines run interleaved in one process (rounds of a few frames each, the order rotated every
round), so a busy shared machine slows all of them alike:

* **participant frame**: what the participant window draws on every trial frame, in ``StudyApp.frame``'s
  order -- the ImGui UI built (panel, buttons, progress bar), the renderer's picture (skinning, morphs,
  lighting -- per vertex on a software rasteriser, see ``Renderer`` --, the anti-aliasing chosen for this
  GL, labels) through the scene cache into the window's framebuffer (the renderer's canvas, scene and the
  app's background around it, the UI drawn over it, in one framebuffer copy), read back;
* **renderer only**: ``draw_trial`` straight into the target, read back;
* **bare draw**: the same triangles in the same three viewports with a trivial shader, read back;
* **bare draw, flushed**: the same, flushed after each slot like the renderer on a software rasteriser
  (there a flush lets the raster threads fill one slot while the next one's vertices are shaded): how much
  of the ratio that scheduling buys, printed and recorded next to the ratio, which is against the plain
  bare draw.

Printed: median frame time with its spread (25th-75th percentile) per pipeline, the ratio participant /
bare as the median of per-round ratios with their spread, and the calling thread's CPU per frame split
into time inside GL calls (moderngl and ImGui's GL backend: Mesa's vertex work runs there on llvmpipe)
and the rest ("Python CPU"), measured on separate profiled frames so profiling never slows the timed ones.

Recorded for ``run_all.py --json``: ``render_frame_ratio_vs_bare``.
Usage: ``python benchmarks/bench_render.py [--rounds 12] [--frames 3] [--size 1280x720]``
"""
from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
from scipy.spatial.transform import Rotation

from figures import load_average, record
from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_NAMES
from studyapp.motion.skeleton import Motion
from studyapp.render.avatar import build_default_avatar
from studyapp.render.context import OffscreenTarget, create_offscreen_context
from studyapp.render.pose import prepare_slot
from studyapp.render.renderer import Renderer
from studyapp.render.scene import make_scene
from studyapp.resources import read_shader
from studyapp.ui.app import BACKGROUND as APP_BACKGROUND

GOAL = 1.3  # issue 20: the participant frame within 1.3x a bare draw of the same geometry


def gesture_motion(avatar, seconds: float, fps: float = 15.0, phase: float = 0.0) -> Motion:
    """Arms and head moving like a speaker (smooth sines), at BEAT's 15 fps."""
    n = int(seconds * fps)
    t = np.arange(n) / fps + phase
    m = Motion.rest(avatar.skeleton, n, fps)
    sk = avatar.skeleton

    def rot(name, rotvec):
        j = sk.index(name)
        m.rotations[:, j] = (Rotation.from_quat(m.rotations[:, j]) * Rotation.from_rotvec(rotvec)).as_quat()

    rot("LeftUpperArm", np.c_[0.3 * np.sin(1.3 * t), 0.4 * np.sin(0.7 * t), -1.1 + 0.3 * np.sin(2.1 * t)])
    rot("RightUpperArm", np.c_[0.3 * np.sin(1.1 * t), -0.4 * np.sin(0.9 * t), 1.1 - 0.3 * np.sin(1.7 * t)])
    rot("LeftLowerArm", np.c_[np.zeros(n), -0.8 - 0.5 * np.sin(2.3 * t), np.zeros(n)])
    rot("RightLowerArm", np.c_[np.zeros(n), 0.8 + 0.5 * np.sin(1.9 * t), np.zeros(n)])
    rot("Head", np.c_[0.1 * np.sin(1.5 * t), 0.15 * np.sin(0.8 * t), np.zeros(n)])
    return m


def talking_face(seconds: float, fps: float = 30.0) -> FaceAnimation:
    n = int(seconds * fps)
    t = np.arange(n) / fps
    w = np.zeros((n, 52), np.float32)
    w[:, ARKIT_NAMES.index("jawOpen")] = 0.4 * (1 + np.sin(9 * t)) / 2
    for name in ("mouthSmileLeft", "mouthSmileRight", "browInnerUp", "mouthFunnel", "cheekSquintLeft"):
        w[:, ARKIT_NAMES.index(name)] = 0.3 * (1 + np.sin(2 * t + len(name))) / 2
    blink = (np.mod(t, 3.0) < 0.15).astype(np.float32)
    w[:, ARKIT_NAMES.index("eyeBlinkLeft")] = blink
    w[:, ARKIT_NAMES.index("eyeBlinkRight")] = blink
    return FaceAnimation(w, fps)


class Overlay:
    """The participant UI over a trial frame: the bottom panel with its status text, buttons and progress
    bar, drawn with the app's own ImGui layer (fonts, theme, GL backend)."""

    def __init__(self, ctx) -> None:
        from studyapp.ui.layer import ImGuiLayer

        self.layer = ImGuiLayer(ctx)

    def build(self, size: tuple[int, int], t: float) -> None:
        """The frame's UI, as a screen builds it before the scene is drawn; :meth:`render` draws it."""
        from imgui_bundle import imgui

        w, h = size
        self.layer.new_frame(size, 1 / 60)
        s = self.layer.scale
        imgui.set_next_window_pos((0, h - 90 * s))
        imgui.set_next_window_size((w, 90 * s))
        imgui.begin("##panel", None, imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.no_move)
        imgui.text("Trial 3 of 12")
        imgui.same_line(0, 24 * s)
        for label in ("Pause", "Replay", "Stop"):
            imgui.button(label, imgui.ImVec2(110 * s, 44 * s))
            imgui.same_line()
        imgui.progress_bar((t % 10) / 10, imgui.ImVec2(200 * s, 24 * s), f"0:{int(t % 10):02d} / 0:10")
        imgui.end()

    def render(self, size: tuple[int, int]) -> None:
        """Draw the built UI into the bound framebuffer."""
        self.layer.render(size)


class GlClock:
    """Calling-thread CPU spent inside GL calls (moderngl's C objects, ImGui's OpenGL3 backend), via
    ``sys.setprofile``: on llvmpipe these calls do Mesa's vertex work on this thread, which is not Python."""

    def __init__(self) -> None:
        self.gl = 0.0
        self._t0: float | None = None
        self._depth = 0

    @staticmethod
    def _is_gl(fn) -> bool:
        owner = getattr(fn, "__self__", None)
        mod = getattr(type(owner), "__module__", "") or ""
        name = getattr(fn, "__name__", "")
        return mod.startswith(("moderngl", "mgl", "_moderngl")) or name.startswith("opengl3_render")

    def __call__(self, frame, event, arg) -> None:
        if event == "c_call" and self._is_gl(arg):
            if self._depth == 0:
                self._t0 = time.thread_time()
            self._depth += 1
        elif event in ("c_return", "c_exception") and self._is_gl(arg) and self._depth:
            self._depth -= 1
            if self._depth == 0:
                self.gl += time.thread_time() - self._t0


def cpu_split(step, frames: int) -> tuple[float, float]:
    """(Python ms, GL-call ms) of calling-thread CPU per frame of ``step``."""
    clock = GlClock()
    c0 = time.thread_time()
    sys.setprofile(clock)
    try:
        for k in range(frames):
            step(k / 30.0)
    finally:
        sys.setprofile(None)
    total = time.thread_time() - c0
    return 1000 * (total - clock.gl) / frames, 1000 * clock.gl / frames


def spread(x) -> str:
    q1, q2, q3 = np.percentile(x, [25, 50, 75])
    return f"{q2:7.1f} [{q1:.1f}-{q3:.1f}]"


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=12)
    ap.add_argument("--frames", type=int, default=3, help="frames per pipeline per round")
    ap.add_argument("--size", default="1280x720")
    args = ap.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))

    ctx = create_offscreen_context()
    t0 = time.perf_counter()
    avatar = build_default_avatar()
    build_s = time.perf_counter() - t0
    face = talking_face(10)
    slots = [prepare_slot(avatar, gesture_motion(avatar, 10, phase=k), face) for k in range(3)]
    scene = make_scene(slots, avatar, labels=("A", "B", "C"))
    renderer = Renderer(ctx)
    target = OffscreenTarget(ctx, size)
    overlay = Overlay(ctx)
    from studyapp.ui.scene_cache import SceneCache

    cache = SceneCache(ctx)
    bare_prog = ctx.program(vertex_shader=read_shader("bare.vert"), fragment_shader=read_shader("bare.frag"))
    bare = Renderer(ctx, samples=0)
    fbo = target.fbo

    def participant(t: float) -> None:  # studyapp.ui.app.StudyApp.frame on a trial
        overlay.build(size, t)
        fbo.use()
        ctx.viewport = (0, 0, *size)
        # fills the frame (no clear), the UI over it
        cache.draw(renderer, scene, t, fbo, (0, 0, *size), size, APP_BACKGROUND, overlay=lambda: overlay.render(size))
        fbo.use()
        target.read_rgb()

    def renderer_only(t: float) -> None:
        renderer.draw_trial(scene, t, fbo)
        target.read_rgb()

    def bare_draw(t: float) -> None:
        bare.draw_bare(avatar, scene, fbo, bare_prog)
        target.read_rgb()

    def bare_flushed(t: float) -> None:
        bare.draw_bare(avatar, scene, fbo, bare_prog, flush_slots=True)
        target.read_rgb()

    pipelines = {"participant frame": participant, "renderer only": renderer_only, "bare draw": bare_draw,
                 "bare draw, flushed": bare_flushed}
    for step in pipelines.values():  # warm up: shader compiles, uploads, fonts
        step(0.0)
        step(0.1)
    times: dict[str, list[float]] = {k: [] for k in pipelines}
    ratios = []
    ratios_flushed = []
    names = list(pipelines)
    frame = 0
    loads = [load_average()]
    for r in range(args.rounds):
        order = names[r % len(names):] + names[:r % len(names)]
        round_ms = {}
        for name in order:
            ms = []
            for _ in range(args.frames):
                t = (frame % 300) / 30.0  # a new pose every frame (the scene cache never short-cuts)
                frame += 1
                c = time.perf_counter()
                pipelines[name](t)
                ms.append(1000 * (time.perf_counter() - c))
            times[name] += ms
            round_ms[name] = float(np.median(ms))
        ratios.append(round_ms["participant frame"] / round_ms["bare draw"])
        ratios_flushed.append(round_ms["participant frame"] / round_ms["bare draw, flushed"])
        loads.append(load_average())
    cpu = {name: cpu_split(step, max(2, args.frames)) for name, step in pipelines.items()}

    print(f"GL: {ctx.info['GL_RENDERER']}  size {size[0]}x{size[1]}, 3 avatars, read-back every frame; "
          f"anti-aliasing {renderer.antialiasing}, lighting per {renderer.lighting}")
    print(f"avatar: {avatar.n_triangles} triangles drawn per figure "
          f"(built-in: {avatar.n_triangles}); build {build_s * 1000:.0f} ms")
    print(f"{args.rounds} rounds x {args.frames} frames per pipeline, interleaved; load average "
          f"{min(loads):.1f}-{max(loads):.1f} on {os.cpu_count()} cores")
    print(f"{'':20s}{'frame ms: median [p25-p75]':>30s}{'fps':>7s}{'Python CPU ms':>15s}{'GL-call CPU ms':>16s}")
    for name in names:
        med = float(np.median(times[name]))
        print(f"{name:20s}{spread(times[name]):>30s}{1000 / med:7.1f}{cpu[name][0]:15.2f}{cpu[name][1]:16.2f}")
    q1, q2, q3 = np.percentile(ratios, [25, 50, 75])
    print(f"participant frame / bare draw: {q2:.2f}x [{q1:.2f}-{q3:.2f}] (median of per-round ratios; goal <= {GOAL}x)")
    r1, r2, r3 = np.percentile(np.array(times["renderer only"]) / np.median(times["bare draw"]), [25, 50, 75])
    print(f"renderer only / bare draw: {r2:.2f}x")
    f1, f2, f3 = np.percentile(ratios_flushed, [25, 50, 75])
    print(f"participant frame / bare draw flushed per slot: {f2:.2f}x [{f1:.2f}-{f3:.2f}]")
    record("render_frame_ratio_vs_bare", round(float(q2), 3), 1.0, "x bare-draw frame time",
           spread=[round(float(q1), 3), round(float(q3), 3)], goal=GOAL,
           participant_ms=round(float(np.median(times["participant frame"])), 2),
           bare_ms=round(float(np.median(times["bare draw"])), 2),
           ratio_vs_bare_flushed=[round(float(f1), 3), round(float(f2), 3), round(float(f3), 3)],
           renderer_flushes_slots=renderer.flush_slots,
           size=f"{size[0]}x{size[1]}", gl_renderer=ctx.info["GL_RENDERER"], antialiasing=renderer.antialiasing,
           lighting=renderer.lighting, load_average=[min(loads), max(loads)], cpu_count=os.cpu_count())
    overlay.layer.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
