"""Offline render of a real trial to MP4 (what the online mode pre-renders), encoding included.

One trial of the demo design (its participant ``P01``, trial 1: three figures, real BVH motion, face, speech
audio) rendered at 1280x720, 30 fps. Interleaved, round by round (the order alternates), so a loaded machine
slows every variant alike:

* ``single``      :func:`studyapp.render.video.render_video` as shipped (``studyapp render``): one video, frame
                  N+1 drawn while frame N is encoded (encoder thread, reused read-back buffers, x264
                  ``superfast`` crf 20 yuv420p), audio muxed;
* ``serial``      the old path: draw, read back into a new array, flip, encode on the same thread with x264
                  ``veryfast`` crf 20 (the baseline);
* ``render-only`` the same frames drawn and read back, nothing encoded;
* ``encode-only`` the same frames, already in memory, encoded with the shipped settings on one thread;
* ``orders``      what ``studyapp prerender`` does with the trial: its 6 slot orders as 6 videos, each figure drawn
                  once per place and frame (3 drawings per frame for 6 videos), 6 encoder threads, audio muxed;
* ``orders-jobs2`` the same in two worker processes at once (``studyapp prerender --jobs 2``): two trials' 6
                  orders each. The workers are started (and warmed) before the rounds, as they are for all but
                  the first trial of a long pre-render.

The real-time factor is seconds of video written per second of wall time (>= 1.5 is the target). CPU seconds
(all threads; the workers' own) are reported too: unlike wall time they do not grow with other users' load,
and ``cores / CPU per video second`` is what this machine kind does when nobody else uses it. The time to
pre-render a thesis-size study (8 clips x 60 s x 6 slot orders = 2,880 s of video) is extrapolated from the
measured rates. The decoded frames of ``single``, ``serial`` and ``orders`` are compared with the frames drawn
(PSNR): the same pictures through a lossy codec.

Environment: ``BENCH_OFFLINE_SECONDS`` (default 2) seconds of the trial per video, ``BENCH_OFFLINE_ROUNDS``
(default 3) rounds.
"""
from __future__ import annotations

import itertools
import multiprocessing
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
from studyapp.render.video import _shared_context, play_frames, render_order_videos, render_video
from studyapp.render.renderer import Renderer
from studyapp.render.scene import build_trial_scene
from studyapp.resources import demo_design
from studyapp.study.design import load_design
from studyapp.study.schedule import participant_schedule
from studyapp.study.stimuli import load_trial_media

SIZE = (1280, 720)
FPS = 30
SECONDS = float(os.environ.get("BENCH_OFFLINE_SECONDS", "2"))
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


ORDERS = list(itertools.permutations(range(3)))   # the 6 slot orders of a 3-condition trial


def trial(index: int = 1):
    """Design, plan, media and scene of trial ``index`` of the demo design's P01 (built on ``renderer``)."""
    design = load_design(demo_design())
    plan = [p for p in participant_schedule(design, "P01") if p.trial_index == index][0]
    return design, plan, load_trial_media(design, plan)


def orders_render(scene, audio, folder: Path, renderer: Renderer) -> None:
    render_order_videos(scene, ORDERS, audio, [folder / f"order{j}.mp4" for j in range(len(ORDERS))], size=SIZE,
                        fps=FPS, renderer=renderer, duration=SECONDS)


_WORKER: dict = {}


def _worker_init(counter) -> None:
    """A prerender worker process: its own GL context, renderer and scene (trial 1 or 2 of P01), warmed up."""
    with counter.get_lock():
        counter.value += 1
        index = counter.value
    renderer = Renderer(_shared_context())
    _, _, media = trial(index)
    scene = build_trial_scene(renderer, media)
    _WORKER.update(renderer=renderer, scene=scene, media=media, folder=Path(tempfile.mkdtemp(prefix="bench-job-")))
    list(play_frames(scene, FPS, 2, SIZE, renderer, duration=SECONDS))


def _worker_task(_: int) -> float:
    """Render the worker's trial in its 6 orders; returns this process's CPU seconds (all its threads)."""
    c0 = time.process_time()
    orders_render(_WORKER["scene"], _WORKER["media"].audio, _WORKER["folder"], _WORKER["renderer"])
    return time.process_time() - c0


def main() -> None:
    design, plan, media = trial(1)
    renderer = Renderer(_shared_context())
    scene = build_trial_scene(renderer, media)
    n = int(round(SECONDS * FPS))
    print(f"trial: demo design, P01 trial 1 ({scene.n_slots} figures, {scene.duration:.1f} s); rendering "
          f"{SECONDS:g} s = {n} frames per video at {SIZE[0]}x{SIZE[1]} {FPS} fps, {ROUNDS} interleaved rounds; "
          f"{os.cpu_count()} cores ({renderer.ctx.info['GL_RENDERER']}), {load()}")
    print(f"shipped encoder: {SETTINGS.codec} preset={SETTINGS.preset} crf={SETTINGS.crf} {SETTINGS.pix_fmt}; "
          f"serial baseline: preset={SERIAL.preset}; anti-aliasing on this renderer: {renderer.antialiasing} "
          f"(what the participant's window shows here too)")
    tmp = Path(tempfile.mkdtemp(prefix="bench-offline-"))
    frames = [f.copy() for f in play_frames(scene, FPS, n, SIZE, renderer, duration=SECONDS)]  # warm-up too
    # two warm worker processes, each with a trial of its own (trials 1 and 2 of P01)
    spawn = multiprocessing.get_context("spawn")
    pool = spawn.Pool(2, initializer=_worker_init, initargs=(spawn.Value("i", 0),))
    pool.map(time.sleep, [0.1, 0.1], chunksize=1)  # both started and warmed up before the rounds
    video_s = {"single": SECONDS, "serial": SECONDS, "render-only": SECONDS, "encode-only": SECONDS,
               "orders": SECONDS * len(ORDERS), "orders-jobs2": 2 * SECONDS * len(ORDERS)}
    times: dict[str, list[float]] = {k: [] for k in video_s}
    cpu: dict[str, list[float]] = {k: [] for k in video_s}   # CPU seconds of all threads (llvmpipe's, x264's)
    loads: list[float] = []
    job_cpu: list[float] = []

    def jobs2() -> None:
        job_cpu.append(sum(pool.map(_worker_task, [0, 1], chunksize=1)))

    runs = {
        "single": lambda: render_video(scene, media.audio, tmp / "single.mp4", size=SIZE, fps=FPS,
                                       renderer=renderer, duration=SECONDS),
        "serial": lambda: serial_render(scene, tmp / "serial.mp4", n, renderer),
        "render-only": lambda: render_only(scene, n, renderer),
        "encode-only": lambda: encode_only(frames, tmp / "encode_only.mp4"),
        "orders": lambda: orders_render(scene, media.audio, tmp, renderer),
        "orders-jobs2": jobs2,
    }
    for r in range(ROUNDS):
        order = list(runs) if r % 2 == 0 else list(reversed(runs))  # no variant always runs first
        for name in order:
            c0, t0 = time.process_time(), time.perf_counter()
            runs[name]()
            times[name].append(time.perf_counter() - t0)
            cpu[name].append(job_cpu[-1] if name == "orders-jobs2" else time.process_time() - c0)
            loads.append(os.getloadavg()[0])
        print(f"  round {r + 1}: " + ", ".join(f"{k} {times[k][-1]:.1f} s" for k in runs) + f"; {load()}", flush=True)
    pool.close()
    pool.join()

    rtf = {k: [video_s[k] / t for t in v] for k, v in times.items()}
    print("\nreal-time factor (seconds of video written per wall second; >= 1.5 is the target):")
    for k in runs:
        print(f"  {k:13s} {spread(rtf[k])}")
    gain = [o / s for o, s in zip(rtf["orders"], rtf["single"])]
    print(f"  orders vs single, per round: {spread(gain)}")
    cores = os.cpu_count() or 1
    # CPU time does not grow with the load of other users: it says what this machine kind can do when quiet.
    cpu_per_video_s = {k: statistics.median(v) / video_s[k] for k, v in cpu.items()}
    print("\nCPU seconds per second of video, all threads (load-independent): "
          + ", ".join(f"{k} {cpu_per_video_s[k]:.2f}" for k in runs))
    quiet = {k: cores / cpu_per_video_s[k] for k in runs}
    print(f"  on a quiet {cores}-core machine ({cores} cores / CPU per video second): "
          + ", ".join(f"{k} {quiet[k]:.2f}x" for k in ("single", "orders", "orders-jobs2")) + " real time")

    best = max(("orders", "orders-jobs2"), key=lambda k: statistics.median(rtf[k]))
    pre_rtf = statistics.median(rtf[best])
    single_rtf = statistics.median(rtf["single"])
    serial_rtf = statistics.median(rtf["serial"])
    hours = {k: THESIS_VIDEO_S / statistics.median(rtf[k]) / 3600 for k in ("orders", "orders-jobs2", "single", "serial")}
    quiet_hours = THESIS_VIDEO_S / max(quiet["orders"], quiet["orders-jobs2"]) / 3600
    print(f"\npre-render a thesis-size study (8 clips x 60 s x 6 slot orders = {THESIS_VIDEO_S} s of video) at the "
          f"measured rates: {hours['orders']:.2f} h (studyapp prerender), {hours['orders-jobs2']:.2f} h (--jobs 2), "
          f"{hours['single']:.2f} h (one video at a time), {hours['serial']:.2f} h (old serial path); "
          f"{quiet_hours:.2f} h on a quiet machine (CPU bound); load average during the runs: median "
          f"{statistics.median(loads):.2f}, max {max(loads):.2f} on {cores} cores shared with other users")

    drawn, single, ser = frames, decoded(tmp / "single.mp4"), decoded(tmp / "serial.mp4")
    ordered = decoded(tmp / "order0.mp4")  # order (0, 1, 2): the trial itself
    assert len(single) == len(ser) == len(ordered) == len(drawn), (len(single), len(ser), len(ordered), len(drawn))
    p_psnr = [psnr(a, b) for a, b in zip(single, drawn)]
    s_psnr = [psnr(a, b) for a, b in zip(ser, drawn)]
    o_psnr = [psnr(a, b) for a, b in zip(ordered, drawn)]
    mad = [float(np.abs(a.astype(int) - b.astype(int)).mean()) for a, b in zip(single, ser)]
    print(f"\nsame frames? {len(single)} frames each; PSNR vs the drawn frames: single min {min(p_psnr):.1f} dB, "
          f"orders min {min(o_psnr):.1f} dB, serial min {min(s_psnr):.1f} dB; single vs serial mean |diff| max "
          f"{max(mad):.2f} grey levels (crf 20 yuv420p: chroma subsampling alone costs ~1-2 levels at edges)")
    sizes = {k: (tmp / f"{k}.mp4").stat().st_size / 1e6 for k in ("single", "serial")}
    print(f"file size: single {sizes['single']:.2f} MB (with audio), serial {sizes['serial']:.2f} MB")
    assert min(p_psnr) > 35 and min(o_psnr) > 35 and max(mad) < 3, "the renders do not show the same frames"

    common = dict(loadavg_median=statistics.median(loads), loadavg_max=max(loads), cores=cores,
                  seconds_rendered=SECONDS, rounds=ROUNDS, size=f"{SIZE[0]}x{SIZE[1]}", fps=FPS,
                  cpu_s_per_video_s=cpu_per_video_s, quiet_machine_rtf=quiet,
                  encoder=f"{SETTINGS.codec} {SETTINGS.preset} crf {SETTINGS.crf} {SETTINGS.pix_fmt}",
                  machine_shared="2 cores shared with other users' jobs: wall-time figures move with their load")
    record("offline_render_realtime_factor", value=pre_rtf, baseline=single_rtf, unit="x real time",
           note=f"studyapp prerender's path ({best}: 6 slot orders, each figure drawn once per place); baseline: "
                "one video at a time (render_video) in the same run", target=TARGET_RTF,
           min=min(rtf[best]), max=max(rtf[best]), variant=best, serial=serial_rtf,
           orders=statistics.median(rtf["orders"]), orders_jobs2=statistics.median(rtf["orders-jobs2"]),
           render_only=statistics.median(rtf["render-only"]), encode_only=statistics.median(rtf["encode-only"]),
           **common)
    record("prerender_thesis_study_hours", value=THESIS_VIDEO_S / pre_rtf / 3600, baseline=hours["single"], unit="h",
           note="8 clips x 60 s x 6 slot orders at the measured prerender rate; baseline: one video at a time",
           quiet_machine_hours=quiet_hours, serial_hours=hours["serial"], **common)


if __name__ == "__main__":
    main()
