"""Offline render of a real trial to MP4 (what the online mode pre-renders), encoding included.

One trial of the demo design (its participant ``P01``, trial 1: three figures, real BVH motion, face, speech
audio) rendered at 1280x720, 30 fps, through :func:`studyapp.render.video.render_video`. Interleaved, round by
round, in one process so a loaded machine slows every variant alike:

* ``pipelined``   render_video as shipped: frame N+1 drawn while frame N is encoded (encoder thread, reused
                  read-back buffers, x264 ``superfast`` crf 20 yuv420p), audio muxed;
* ``serial``      the previous path: draw, read back into a new array, flip, encode on the same thread with
                  x264 ``veryfast`` crf 20 (the baseline the speed-up is measured against);
* ``render-only`` the same frames drawn and read back, nothing encoded (the floor the encoder hides behind);
* ``encode-only`` the same frames, already in memory, encoded with the shipped settings on one thread.

The real-time factor is seconds of video per second of wall time (>= 1.5 is the target). The time to
pre-render a thesis-size study (8 clips x 60 s x 6 slot orders = 2,880 s of video) is extrapolated from it.
The decoded frames of the ``pipelined`` and ``serial`` files are compared with the frames drawn (PSNR) and with
each other: the same timeline, different presets of a lossy codec.

Environment: ``BENCH_OFFLINE_SECONDS`` (default 3) seconds of the trial per render, ``BENCH_OFFLINE_ROUNDS``
(default 3) rounds.
"""
from __future__ import annotations

import os
import statistics
import tempfile
import time
from fractions import Fraction
from pathlib import Path

import av
import numpy as np

from figures import record
from studyapp.render.encode import SETTINGS, EncoderSettings, open_video_stream
from studyapp.render.video import _shared_context, play_frames, render_video
from studyapp.render.renderer import Renderer
from studyapp.render.scene import build_trial_scene
from studyapp.resources import demo_design
from studyapp.study.design import load_design
from studyapp.study.schedule import participant_schedule
from studyapp.study.stimuli import load_trial_media

SIZE = (1280, 720)
FPS = 30
SECONDS = float(os.environ.get("BENCH_OFFLINE_SECONDS", "3"))
ROUNDS = int(os.environ.get("BENCH_OFFLINE_ROUNDS", "3"))
THESIS_VIDEO_S = 8 * 60 * 6          # 8 clips x 60 s x 6 slot orders
TARGET_RTF = 1.5
SERIAL = EncoderSettings(preset="veryfast")   # what render_video used before the pipelined encoder


def load(label: str = "") -> str:
    one, five, _ = os.getloadavg()
    return f"load {one:.2f}/{five:.2f}{label}"


def serial_render(scene, out: Path, n: int, renderer: Renderer) -> None:
    """The previous render_video loop, video only (audio muxing is the same in both and cheap)."""
    with av.open(str(out), mode="w") as container:
        stream = container.add_stream(SERIAL.codec, rate=Fraction(FPS, 1))
        stream.width, stream.height = SIZE
        stream.pix_fmt = SERIAL.pix_fmt
        stream.options = {"crf": str(SERIAL.crf), "preset": SERIAL.preset}
        for img in play_frames(scene, FPS, n, SIZE, renderer, duration=SECONDS):
            for packet in stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def render_only(scene, n: int, renderer: Renderer) -> None:
    for _ in play_frames(scene, FPS, n, SIZE, renderer, duration=SECONDS):
        pass


def encode_only(frames: list[np.ndarray], out: Path) -> None:
    with av.open(str(out), mode="w") as container:
        stream = open_video_stream(container, SIZE, FPS, SETTINGS)
        for k, img in enumerate(frames):
            frame = av.VideoFrame.from_ndarray(img, format="rgb24")
            frame.pts = k
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def decoded(path: Path) -> list[np.ndarray]:
    with av.open(str(path)) as f:
        return [fr.to_ndarray(format="rgb24") for fr in f.decode(video=0)]


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0 ** 2 / mse)


def spread(values: list[float]) -> str:
    return f"median {statistics.median(values):6.3f}  (min {min(values):.3f}, max {max(values):.3f}, n={len(values)})"


def main() -> None:
    design = load_design(demo_design())
    plan = [p for p in participant_schedule(design, "P01") if p.trial_index == 1][0]
    media = load_trial_media(design, plan)
    renderer = Renderer(_shared_context())
    scene = build_trial_scene(renderer, media)
    n = int(round(SECONDS * FPS))
    print(f"trial: demo design, P01 trial 1 ({scene.n_slots} figures, {scene.duration:.1f} s); rendering "
          f"{SECONDS:g} s = {n} frames at {SIZE[0]}x{SIZE[1]} {FPS} fps, {ROUNDS} interleaved rounds; "
          f"{os.cpu_count()} cores, {load()}")
    print(f"shipped encoder: {SETTINGS.codec} preset={SETTINGS.preset} crf={SETTINGS.crf} {SETTINGS.pix_fmt}; "
          f"serial baseline: preset={SERIAL.preset}")
    tmp = Path(tempfile.mkdtemp(prefix="bench-offline-"))
    frames = [f.copy() for f in play_frames(scene, FPS, n, SIZE, renderer, duration=SECONDS)]  # warm-up too
    times: dict[str, list[float]] = {"pipelined": [], "serial": [], "render-only": [], "encode-only": []}
    cpu: dict[str, list[float]] = {k: [] for k in times}   # CPU seconds of all threads (llvmpipe's, x264's)
    loads: list[float] = []
    runs = {
        "pipelined": lambda: render_video(scene, media.audio, tmp / "pipelined.mp4", size=SIZE, fps=FPS,
                                          renderer=renderer, duration=SECONDS),
        "serial": lambda: serial_render(scene, tmp / "serial.mp4", n, renderer),
        "render-only": lambda: render_only(scene, n, renderer),
        "encode-only": lambda: encode_only(frames, tmp / "encode_only.mp4"),
    }
    for r in range(ROUNDS):
        order = list(runs) if r % 2 == 0 else list(reversed(runs))  # no variant always runs first
        for name in order:
            c0, t0 = time.process_time(), time.perf_counter()
            runs[name]()
            times[name].append(time.perf_counter() - t0)
            cpu[name].append(time.process_time() - c0)
            loads.append(os.getloadavg()[0])
        print(f"  round {r + 1}: " + ", ".join(f"{k} {times[k][-1]:.2f} s" for k in runs) + f"; {load()}")

    rtf = {k: [SECONDS / t for t in v] for k, v in times.items()}
    print("\nreal-time factor (seconds of video per wall second; >= 1.5 is the target):")
    for k in runs:
        print(f"  {k:12s} {spread(rtf[k])}")
    speedup = [s / p for p, s in zip(times["pipelined"], times["serial"])]
    print(f"  pipelined vs serial, per round: {spread(speedup)}")
    hidden = statistics.median(times["render-only"]) / statistics.median(times["pipelined"])
    print(f"  pipelined wall time / render-only: {1 / hidden:.2f}x (1.00 = the encode is fully hidden)")

    # CPU time does not grow with the load of other users: it says what this machine kind can do when quiet.
    cpu_ms = {k: statistics.median(v) / n * 1e3 for k, v in cpu.items()}
    cores = os.cpu_count() or 1
    print("\nCPU milliseconds per frame, all threads (load-independent): "
          + ", ".join(f"{k} {cpu_ms[k]:.1f}" for k in runs))
    idle_rtf = cores / (cpu_ms["pipelined"] / 1e3 * FPS)
    print(f"  upper bound on a quiet {cores}-core machine ({cores} cores / CPU per frame): "
          f"{idle_rtf:.2f}x real time pipelined, {cores / (cpu_ms['render-only'] / 1e3 * FPS):.2f}x drawing alone")

    pipe_rtf = statistics.median(rtf["pipelined"])
    serial_rtf = statistics.median(rtf["serial"])
    hours, serial_hours = THESIS_VIDEO_S / pipe_rtf / 3600, THESIS_VIDEO_S / serial_rtf / 3600
    print(f"\npre-render a thesis-size study (8 clips x 60 s x 6 slot orders = {THESIS_VIDEO_S} s of video) "
          f"at the measured rate: {hours:.2f} h (serial path: {serial_hours:.2f} h); "
          f"load average during the runs: median {statistics.median(loads):.2f}, max {max(loads):.2f}")

    drawn, pipe, ser = frames, decoded(tmp / "pipelined.mp4"), decoded(tmp / "serial.mp4")
    assert len(pipe) == len(ser) == len(drawn), (len(pipe), len(ser), len(drawn))
    p_psnr = [psnr(a, b) for a, b in zip(pipe, drawn)]
    s_psnr = [psnr(a, b) for a, b in zip(ser, drawn)]
    mad = [float(np.abs(a.astype(int) - b.astype(int)).mean()) for a, b in zip(pipe, ser)]
    print(f"\nsame frames? {len(pipe)} frames each; PSNR vs the drawn frames: pipelined min {min(p_psnr):.1f} dB, "
          f"serial min {min(s_psnr):.1f} dB; pipelined vs serial mean |diff| max {max(mad):.2f} grey levels "
          f"(crf 20 yuv420p: chroma subsampling alone costs ~1-2 levels at the figures' edges)")
    sizes = {k: (tmp / f"{k}.mp4").stat().st_size / 1e6 for k in ("pipelined", "serial")}
    print(f"file size: pipelined {sizes['pipelined']:.2f} MB (with audio), serial {sizes['serial']:.2f} MB")
    assert min(p_psnr) > 35 and max(mad) < 3, "the pipelined render does not show the same frames"

    common = dict(loadavg_median=statistics.median(loads), loadavg_max=max(loads), cores=os.cpu_count(),
                  seconds_rendered=SECONDS, rounds=ROUNDS, size=f"{SIZE[0]}x{SIZE[1]}", fps=FPS,
                  cpu_ms_per_frame=cpu_ms, quiet_machine_upper_bound_rtf=idle_rtf,
                  encoder=f"{SETTINGS.codec} {SETTINGS.preset} crf {SETTINGS.crf} {SETTINGS.pix_fmt}")
    record("offline_render_realtime_factor", value=pipe_rtf, baseline=serial_rtf, unit="x real time",
           note="baseline: the previous serial render+encode (veryfast) in the same run", target=TARGET_RTF,
           min=min(rtf["pipelined"]), max=max(rtf["pipelined"]),
           render_only=statistics.median(rtf["render-only"]), encode_only=statistics.median(rtf["encode-only"]),
           **common)
    record("prerender_thesis_study_hours", value=hours, baseline=serial_hours, unit="h",
           note="8 clips x 60 s x 6 slot orders at the measured real-time factor; baseline: serial path", **common)


if __name__ == "__main__":
    main()
