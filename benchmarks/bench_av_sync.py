"""Audio/video sync over one minute: is every frame within one display frame of the sound, without drift?

Plays a synthesized 60 s clip on a real audio output (the null PulseAudio sink started here when no
sound server is running; it is paced in real time like a sound card) and runs a simulated 60 Hz vsync
loop: each frame asks the audio clock where the sound is, draws for the time the sound will have
reached at the next flip (``studyapp.render.frames``), waits for the flip, then reads the audio clock again.
The difference is the audio/video offset a participant would see. Printed per 5 s window: mean and max
offset in ms against the 16.7 ms frame period, and for comparison the offsets without latency
compensation (video following the samples handed to the device) and without the flip lead.
The slope of offset vs time (ms per minute) shows drift between the audio clock and the video.

Usage: ``python benchmarks/bench_av_sync.py [--seconds 60] [--device NAME]``
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

from studyapp.audio.playback import AudioPlayer, Pcm  # noqa: E402
from studyapp.render.frames import FlipPredictor, PlayRecorder, media_time_for_flip  # noqa: E402

REFRESH_HZ = 60.0


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


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--device", default=None)
    args = ap.parse_args(argv)

    pulse_pid = start_null_audio()
    try:
        player = AudioPlayer(args.device)
    except Exception as exc:
        print(f"no audio output ({exc}); install pulseaudio for the null sink. Skipped.")
        return 0
    try:
        flowing = player.wait_until_flowing(6.0)
        print(f"output: {player.device_name} @ {player.rate} Hz, reported latency "
              f"{player.reported_latency_s * 1000:.1f} ms, measured {player.output_latency_s * 1000:.1f} ms"
              f"{'' if flowing else ' (stream still warming up)'}")
        clip = speech_like(args.seconds)
        period = 1.0 / REFRESH_HZ
        predictor = FlipPredictor(REFRESH_HZ)
        rec = PlayRecorder(refresh_hz=REFRESH_HZ)
        rows = []  # (time of flip since start, offset, offset without compensation, offset without lead)
        player.play(clip)
        t_start = time.perf_counter()
        next_flip = t_start + period
        render_cost = 0.004  # what drawing three avatars + UI costs on a fast GPU; busy-waited below
        while not player.finished:
            now = time.perf_counter()
            audible = player.position_s()
            delivered = player.delivered_s  # what the device was handed: no latency compensation
            predicted = predictor.predict(now)
            drawn = min(media_time_for_flip(audible, now, predicted), player.duration_s)
            while time.perf_counter() - now < render_cost:
                pass
            # vsync: the frame appears at the next flip after drawing finished
            while next_flip < time.perf_counter():
                next_flip += period
            time.sleep(max(0.0, next_flip - time.perf_counter() - 0.001))
            while time.perf_counter() < next_flip:
                pass
            flip = time.perf_counter()
            at_flip = player.position_s()
            predictor.flipped(next_flip)
            if audible > 0.0 and at_flip < player.duration_s:  # playing (sound started, not ended)
                rec.flip(flip, drawn, at_flip)
                late = predicted is not None and next_flip > predicted + period / 2  # missed its vsync
                rows.append((flip - t_start, drawn - at_flip, min(delivered, player.duration_s) - at_flip,
                             audible - at_flip, at_flip, late))
            next_flip += period
        wall = time.perf_counter() - t_start
    finally:
        player.close()
        if pulse_pid:
            os.kill(pulse_pid, 15)

    a = np.array(rows, dtype=float)
    t, off, uncomp, nolead = a[:, 0], a[:, 1] * 1000, a[:, 2] * 1000, a[:, 3] * 1000
    late = a[:, 5] > 0
    frame_ms = period * 1000
    print(f"\n{len(a)} frames in {wall:.1f} s; display frame period {frame_ms:.1f} ms; frames that missed "
          f"their vsync (machine busy): {int(late.sum())}")
    print(f"{'window':>10} {'mean|off|':>10} {'max|off|':>9} {'max/frame':>10} {'late':>5} "
          f"{'max|off| on-time':>17} {'no-comp mean':>13} {'no-lead mean':>13}")
    t0 = t[0]
    for w0 in np.arange(0, t[-1] - t0 + 1e-9, 5.0):
        m = (t - t0 >= w0) & (t - t0 < w0 + 5.0)
        if not m.any():
            continue
        o = np.abs(off[m])
        on = np.abs(off[m & ~late])
        print(f"{w0:4.0f}-{w0 + 5:<4.0f}s {o.mean():9.2f}ms {o.max():8.2f}ms {o.max() / frame_ms:9.2f}x "
              f"{int(late[m].sum()):5d} {on.max() if on.size else float('nan'):16.2f}ms "
              f"{np.abs(uncomp[m]).mean():12.1f}ms {np.abs(nolead[m]).mean():12.2f}ms")
    slope = np.polyfit(t, off, 1)[0] * 60.0
    within = np.mean(np.abs(off) <= frame_ms) * 100
    on = np.abs(off[~late])
    print(f"\nall frames: mean |offset| {np.abs(off).mean():.2f} ms, max {np.abs(off).max():.2f} ms "
          f"({np.abs(off).max() / frame_ms:.2f} frame periods); {within:.1f}% within one frame period")
    print(f"frames shown on time: mean |offset| {on.mean():.2f} ms, max {on.max():.2f} ms "
          f"({on.max() / frame_ms:.2f} frame periods)")
    rate = np.polyfit(t, a[:, 4], 1)[0]
    print(f"drift: offset slope {slope:+.3f} ms per minute (0 = no drift); the audio clock ran at "
          f"{rate:.5f} x wall-clock speed (the sink's own pace; the picture follows it, not the wall clock)")
    print(f"without latency compensation the picture would lead the sound by {np.abs(uncomp).mean():.1f} ms "
          f"({np.abs(uncomp).mean() / max(np.abs(off).mean(), 1e-3):.0f}x the compensated offset); without the "
          f"flip lead it would lag by {np.abs(nolead).mean():.1f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
