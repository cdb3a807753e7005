"""Audio/video sync while rendering real frames, under load: is every frame shown within one display frame
of the sound, with late frames dropped (and counted) rather than shown late, and without drift?

Plays a synthesized clip on a real audio output (the null PulseAudio sink started here when no sound
server is running; it is paced in real time like a sound card) and runs the participant's frame loop
(:class:`studyapp.render.loop.FrameLoop` with its pacer) on a simulated 60 Hz display: each frame the
renderer draws three built-in avatars at 1280x720 offscreen for the audio time of the flip it aims at
(``studyapp.render.frames``), presenting waits for the next vsync, and the offset is against the audio
clock at that vsync instant (read after it, less the time since: a thread on a loaded machine returns
from the wait late, while a display flips on time). The audio stream runs in its own process
(``studyapp.audio.output_process``). ``--load N`` busy processes (default: twice the core count) run meanwhile, as on a loaded laptop.

Printed per 5 s window: mean and max offset against the 16.7 ms frame period, frames shown and dropped;
then the share of shown frames within one frame period, the worst offset, and the slope of offset vs
time (drift). Recorded for ``run_all.py --json``: ``av_sync_max_offset_frames_under_render``.

Usage: ``python benchmarks/bench_av_sync.py [--seconds 20] [--load N] [--device NAME]``
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from figures import load_average, record  # noqa: E402
from bench_render import gesture_motion, talking_face  # noqa: E402
from studyapp.audio.playback import AudioPlayer, Pcm  # noqa: E402
from studyapp.render.avatar import build_default_avatar  # noqa: E402
from studyapp.render.context import create_offscreen_context  # noqa: E402
from studyapp.render.frames import FlipPredictor  # noqa: E402
from studyapp.render.loop import FrameLoop, OffscreenFrames, ScenePlayer, WallTimer  # noqa: E402
from studyapp.render.pose import prepare_slot  # noqa: E402
from studyapp.render.renderer import Renderer  # noqa: E402
from studyapp.render.scene import make_scene  # noqa: E402

REFRESH_HZ = 60.0
SIZE = (1280, 720)


def start_null_audio() -> int | None:
    if os.environ.get("PULSE_SERVER") or shutil.which("pulseaudio") is None:
        return None
    script = ROOT / ".ci" / "start-null-audio.sh"
    out = subprocess.run(["bash", str(script)], capture_output=True, text=True, timeout=30).stdout
    env = {k: v.strip("'\"") for k, v in (t.split("=", 1) for t in out.replace("export ", "").split() if "=" in t)}
    pid = int(env.pop("AUDIO_NULL_PID"))
    os.environ.update(env)
    return pid


def speech_like(seconds: float, rate: int = 16000, seed: int = 0) -> Pcm:
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    env = np.clip(np.sin(2 * np.pi * 4.0 * t), 0, None) ** 2 * (np.sin(2 * np.pi * 0.5 * t) > -0.3)
    x = 0.3 * env * (rng.standard_normal(t.size) * 0.3 + np.sin(2 * np.pi * 160 * t))
    return Pcm(x.astype(np.float32)[:, None], rate, "synthetic speech")


class VsyncFrames(OffscreenFrames):
    """An offscreen target whose ``present`` waits for the next flip of a simulated 60 Hz display."""

    def __init__(self, ctx, size, period: float) -> None:
        super().__init__(ctx, size)
        self.period = period
        self.t0 = time.perf_counter()
        self.last_flip = self.t0

    def present(self) -> None:
        now = time.perf_counter()
        flip = self.t0 + (np.floor((now - self.t0) / self.period) + 1) * self.period
        time.sleep(max(0.0, flip - time.perf_counter() - 0.001))
        while time.perf_counter() < flip:
            pass
        self.last_flip = flip


class VsyncTimer(WallTimer):
    """Real time, with each flip at the simulated display's vsync instant (as a display flips in hardware),
    not when the loaded thread got back from waiting for it."""

    def __init__(self, target: VsyncFrames) -> None:
        self.target = target

    def flip_time(self) -> float:
        return self.target.last_flip


def busy_processes(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--load", type=int, default=2 * (os.cpu_count() or 1),
                    help="busy processes to run meanwhile (default: twice the core count)")
    ap.add_argument("--device", default=None)
    ap.add_argument("--latency", type=float, default=0.1,
                    help="audio output latency in seconds (the participant app's default is 0.1)")
    args = ap.parse_args(argv)

    ctx = create_offscreen_context()
    avatar = build_default_avatar()
    face = talking_face(args.seconds + 1)
    slots = [prepare_slot(avatar, gesture_motion(avatar, args.seconds + 1, phase=k), face) for k in range(3)]
    scene = make_scene(slots, avatar, labels=("A", "B", "C"))
    renderer = Renderer(ctx)
    period = 1.0 / REFRESH_HZ
    target = VsyncFrames(ctx, SIZE, period)

    pulse_pid = start_null_audio()
    try:
        player = AudioPlayer(args.device, latency=args.latency)
    except Exception as exc:
        print(f"no audio output ({exc}); install pulseaudio for the null sink. Skipped.")
        return 0
    busy: list[subprocess.Popen] = []
    try:
        flowing = player.wait_until_flowing(6.0)
        underflows0 = player.underflows
        print(f"output: {player.device_name} @ {player.rate} Hz, measured latency {player.output_latency_s * 1000:.1f} ms"
              f"{'' if flowing else ' (stream still warming up)'}; GL: {ctx.info['GL_RENDERER']}, "
              f"anti-aliasing {renderer.antialiasing}, {SIZE[0]}x{SIZE[1]}, 3 avatars")
        clip = speech_like(args.seconds)
        predictor = FlipPredictor(REFRESH_HZ)
        scene_player = ScenePlayer(renderer, scene, player, audio=clip, duration_s=args.seconds, predictor=predictor,
                                   flip_clock=time.perf_counter)
        loop = FrameLoop(target, VsyncTimer(target), scene_player.draw, scene_player.after_flip, pacer=predictor,
                         running=lambda: not player.finished)
        for k in range(3):  # warm up (shaders, uploads) and let the predictor learn the flips
            scene_player.draw(target.fbo, SIZE, time.perf_counter())
            target.present()
            predictor.flipped(time.perf_counter())
        busy = busy_processes(args.load)
        time.sleep(1.0)  # let the load settle
        load_before = load_average()
        scene_player.start(0.0)
        t_start = time.perf_counter()
        loop.run()
        wall = time.perf_counter() - t_start
        underflows = player.underflows - underflows0
        load_after = load_average()
    finally:
        for p in busy:
            p.kill()
            p.wait()
        player.close()
        if pulse_pid:
            os.kill(pulse_pid, 15)

    rec = scene_player.recorder
    flips = np.array(rec.flips) - t_start
    off = np.array(rec.offsets_s) * 1000
    frame_ms = period * 1000
    if off.size < 3:
        print("too few frames shown to measure")
        return 1
    drawn = loop.frames
    print(f"\n{args.load} busy processes on {os.cpu_count()} cores (load average {load_before:.1f} -> {load_after:.1f})")
    print(f"{drawn} frames drawn in {wall:.1f} s ({drawn / wall:.1f} fps), {rec.frames_shown} shown, "
          f"{loop.dropped_late} dropped because they finished after their flip; display period {frame_ms:.1f} ms")
    print(f"{'window':>10} {'shown':>6} {'mean|off|':>10} {'max|off|':>9} {'max/frame':>10}")
    for w0 in np.arange(0, flips[-1] + 1e-9, 5.0):
        m = (flips >= w0) & (flips < w0 + 5.0)
        if not m.any():
            continue
        o = np.abs(off[m])
        print(f"{w0:4.0f}-{w0 + 5:<4.0f}s {int(m.sum()):6d} {o.mean():9.2f}ms {o.max():8.2f}ms {o.max() / frame_ms:9.2f}x")
    within = float(np.mean(np.abs(off) <= frame_ms) * 100)
    worst = float(np.abs(off).max() / frame_ms)
    slope = float(np.polyfit(flips, off, 1)[0] * 60.0)
    print(f"\nshown frames within one frame period of the sound: {within:.1f}% (goal >= 99%); worst offset "
          f"{worst:.2f} frame periods; mean |offset| {np.abs(off).mean():.2f} ms")
    print(f"audio device underflows during the play: {underflows}")
    print(f"drift: offset slope {slope:+.3f} ms per minute (0 = no drift)")
    record("av_sync_max_offset_frames_under_render", round(worst, 3), 1.0, "display frame periods",
           within_one_frame_pct=round(within, 2), goal_within_pct=99.0, frames_drawn=drawn,
           frames_shown=rec.frames_shown, dropped_late=loop.dropped_late, fps=round(drawn / wall, 2),
           drift_ms_per_min=round(slope, 3), underflows=underflows, busy_processes=args.load, audio_latency_s=args.latency,
           load_average=[load_before, load_after], cpu_count=os.cpu_count(), gl_renderer=ctx.info["GL_RENDERER"])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
