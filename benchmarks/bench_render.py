"""Renderer throughput: three built-in avatars at 1280x720, offscreen with a full read-back per frame.

Prints, measured in the same run so a busy machine still gives a fair ratio:
* fps of the real renderer (skinning + morphs + lighting + MSAA resolve + read-back),
* Python CPU milliseconds per frame spent issuing it (palette blend/upload, uniforms, draw calls), as the
  calling thread's CPU time around ``draw_trial`` (llvmpipe's raster threads are not counted),
* the same without anti-aliasing,
* fps of a bare moderngl draw of the same triangles (positions only, trivial shader, no anti-aliasing,
  same read-back) and the ratios to it.
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np
from scipy.spatial.transform import Rotation

from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_NAMES
from studyapp.motion.skeleton import Motion
from studyapp.render.avatar import build_default_avatar
from studyapp.render.context import OffscreenTarget, create_offscreen_context
from studyapp.render.pose import prepare_slot
from studyapp.render.renderer import Renderer
from studyapp.render.scene import make_scene
from studyapp.resources import read_shader

SIZE = (1280, 720)
SECONDS = 4.0


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


def measure(draw, target: OffscreenTarget, seconds: float) -> tuple[float, float]:
    """(fps with read-back, CPU ms per frame spent in ``draw``)."""
    draw(0.0)
    target.read_rgb()  # warm up (shader compile, uploads)
    frames = 0
    cpu = 0.0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        c0 = time.thread_time()
        draw(frames / 60.0)
        cpu += time.thread_time() - c0
        target.read_rgb()
        frames += 1
    wall = time.perf_counter() - t0
    return frames / wall, 1000.0 * cpu / frames


def main() -> int:
    ctx = create_offscreen_context()
    print(f"GL: {ctx.info['GL_RENDERER']}  size {SIZE[0]}x{SIZE[1]}, 3 avatars, read-back every frame")
    t0 = time.perf_counter()
    avatar = build_default_avatar()
    build_s = time.perf_counter() - t0
    face = talking_face(10)
    t0 = time.perf_counter()
    slots = [prepare_slot(avatar, gesture_motion(avatar, 10, phase=k), face) for k in range(3)]
    prep_ms = (time.perf_counter() - t0) * 1000 / 3
    scene = make_scene(slots, avatar, labels=("A", "B", "C"))
    renderer = Renderer(ctx, samples=4)
    print(f"anti-aliasing: {renderer.antialiasing}" + (" (MSAA replaced on this software rasteriser)" if renderer.fxaa else ""))
    target = OffscreenTarget(ctx, SIZE)
    fps, cpu_ms = measure(lambda t: renderer.draw_trial(scene, t, target.fbo), target, SECONDS)
    plain = Renderer(ctx, samples=0)  # no anti-aliasing at all
    noaa_fps, noaa_cpu = measure(lambda t: plain.draw_trial(scene, t, target.fbo), target, SECONDS)
    bare_prog = ctx.program(vertex_shader=read_shader("bare.vert"), fragment_shader=read_shader("bare.frag"))
    bare_fps, bare_cpu = measure(lambda t: plain.draw_bare(avatar, scene, target.fbo, bare_prog), target, SECONDS)
    print(f"avatar: {avatar.n_vertices} vertices, {avatar.n_triangles} triangles, {avatar.skeleton.n_joints} joints, "
          f"52 morphs; build {build_s * 1000:.0f} ms (cached after)")
    print(f"prepare_slot (10 s clip, retarget-free, 60 fps palettes): {prep_ms:.0f} ms per slot")
    print(f"{'':24s}{'fps':>8s}{'CPU ms/frame':>15s}")
    print(f"{'renderer (full, ' + renderer.antialiasing + ')':24s}{fps:8.1f}{cpu_ms:15.2f}")
    print(f"{'renderer, no AA':24s}{noaa_fps:8.1f}{noaa_cpu:15.2f}")
    print(f"{'bare moderngl draw':24s}{bare_fps:8.1f}{bare_cpu:15.2f}")
    print(f"ratio full / bare fps: {fps / bare_fps:.2f}, no-AA / bare: {noaa_fps / bare_fps:.2f}   (load average now: {os.getloadavg()[0]:.1f} "
          f"on {os.cpu_count()} cores; absolute fps drop when others use the CPU)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
