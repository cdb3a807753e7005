"""Per-frame cost of a live model condition on this CPU: audio features plus the shipped reference model's
step, against the bare onnxruntime call of the same model on the same machine, interleaved.

The reference model is untrained but has FaceCapGes' shape (conv audio encoder, face/head/pose encoders,
LSTM decoder with hidden size 256, 6D output for 47 joints), so its cost per frame stands in for a model of
that size; it says nothing about a trained model's quality. onnxruntime runs on the CPU with one thread, one
frame at a time as a live condition does, over speech-like audio. Each round times, back to back, the audio
features of the whole clip (amortised per frame: a live condition pays them too), the runner's steps and the
bare ``InferenceSession.run`` on the same feeds; the table gives medians over rounds with min-max. No figure
from other hardware is compared: FaceCapGes' published 6.07 ms per frame (RTX 4090, PyTorch, trained
model) is printed only as a labelled reference, never divided by.

Usage: ``python benchmarks/bench_onnx_latency.py [--frames N] [--rounds R]``.
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np
import onnxruntime as ort

from studyapp.audio.features import compute_features
from studyapp.audio.wav import AudioClip
from studyapp.face.animation import FaceAnimation
from studyapp.models.live import stimulus_inputs
from studyapp.models.reference import shipped_reference_model
from studyapp.models.runner import StreamingGestureModel

PUBLISHED_MS = 6.07  # FaceCapGes, per frame, RTX 4090, PyTorch: other hardware, framework and weights
SR = 16000


def speech_like(seconds: float) -> np.ndarray:
    t = np.arange(int(seconds * SR)) / SR
    phase = 2 * np.pi * np.cumsum(140 + 30 * np.sin(2 * np.pi * 0.4 * t)) / SR
    voice = 0.3 * np.sin(phase) + 0.15 * np.sin(2 * phase) + 0.08 * np.sin(3 * phase)
    return (voice * (0.5 + 0.5 * np.sin(2 * np.pi * 3.0 * t))).astype(np.float32)


def stats(ms: np.ndarray) -> tuple[float, float, float]:
    return float(np.median(ms)), float(np.percentile(ms, 99)), float(ms.max())


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=450, help="frames per round (450 = 30 s at 15 fps)")
    parser.add_argument("--rounds", type=int, default=5, help="interleaved rounds (default 5)")
    args = parser.parse_args(argv)

    path = shipped_reference_model()
    model = StreamingGestureModel(path, threads=1)
    fps = model.spec.fps
    seconds = args.frames / fps
    audio = AudioClip(speech_like(seconds), SR)
    rng = np.random.default_rng(0)
    n_face = int(seconds * 30)
    face = FaceAnimation(rng.uniform(0, 1, (n_face, 52)).astype(np.float32), 30.0,
                         head_rotation=rng.normal(0, 0.1, (n_face, 3)))
    inputs = stimulus_inputs(model.spec, audio, face)
    model.run_sequence(inputs.features[:50], inputs.face[:50], inputs.head6d[:50])  # warm-up
    feeds = dict(model._feeds)

    feat, step, bare, p99 = [], [], [], []
    for _ in range(args.rounds):
        t0 = time.perf_counter()
        compute_features(model.spec.audio_features, audio.mono(), SR, fps)
        feat.append((time.perf_counter() - t0) * 1e3 / args.frames)
        model.run_sequence(inputs.features, inputs.face, inputs.head6d)
        lat = np.asarray(model.latencies_ms[-args.frames:])
        step.append(float(np.median(lat)))
        p99.append(float(np.percentile(lat, 99)))
        raw = []
        for _ in range(args.frames):  # the bare session.run on the same feeds: the same-machine baseline
            t = time.perf_counter()
            model.session.run(None, feeds)
            raw.append((time.perf_counter() - t) * 1e3)
        bare.append(float(np.median(raw)))
    total = [f + s_ for f, s_ in zip(feat, step)]

    def row(name: str, xs: list[float]) -> str:
        return f"{name:<40}{np.median(xs):9.3f}{min(xs):9.3f}{max(xs):9.3f}"

    print(f"reference model (untrained): {path.name}, {path.stat().st_size / 1024:.0f} KiB, {model.spec.n_joints} "
          f"joints, {fps:g} fps, window {model.spec.window}, features {','.join(model.spec.audio_features)}")
    print(f"onnxruntime {ort.__version__}, 1 thread, {platform.processor() or platform.machine()}, {args.frames} "
          f"frames x {args.rounds} interleaved rounds; load average {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)")
    print()
    print(f"{'per frame (ms), median of round medians':<40}{'median':>9}{'min':>9}{'max':>9}")
    print(row("audio features (amortised)", feat))
    print(row("StreamingGestureModel.step", step))
    print(row("features + step (what a live frame costs)", total))
    print(row("baseline: bare InferenceSession.run", bare))
    print(row("step p99", p99))
    print()
    ratio = float(np.median(total)) / float(np.median(bare))
    print(f"features + step / bare run: {ratio:.2f}x (same machine, same model, interleaved)")
    print(f"real-time budget at {fps:g} fps: {1000 / fps:.1f} ms; features + step use "
          f"{np.median(total) / (1000 / fps) * 100:.1f} % of it, step p99 {np.median(p99) / (1000 / fps) * 100:.1f} %")
    print(f"for reference only, not comparable: FaceCapGes publishes {PUBLISHED_MS} ms per frame for its trained "
          "model in PyTorch on an RTX 4090 (other hardware, framework and weights)")
    return 0

if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
