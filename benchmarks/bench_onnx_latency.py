"""Per-frame latency of the shipped reference gesture model on this CPU, next to FaceCapGes' published figure.

The reference model is untrained but has FaceCapGes' shape (conv audio encoder, face/head/pose encoders,
LSTM decoder with hidden size 256, 6D output for 47 joints), so its cost per frame is an honest stand-in.
FaceCapGes reports 6.07 ms per frame on an RTX 4090 in PyTorch; here we run onnxruntime on the CPU with
one thread, one frame at a time as a live condition does, over a minute of speech-like audio.

Usage: ``python benchmarks/bench_onnx_latency.py [--frames N]``.
"""
from __future__ import annotations

import argparse
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

PUBLISHED_MS = 6.07  # FaceCapGes, per frame, RTX 4090, PyTorch
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
    parser.add_argument("--frames", type=int, default=900, help="frames to time (900 = 60 s at 15 fps)")
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

    t0 = time.perf_counter()
    compute_features(model.spec.audio_features, audio.mono(), SR, fps)
    feat_ms = (time.perf_counter() - t0) * 1e3 / args.frames
    inputs = stimulus_inputs(model.spec, audio, face)

    model.run_sequence(inputs.features[:50], inputs.face[:50], inputs.head6d[:50])  # warm-up
    model.run_sequence(inputs.features, inputs.face, inputs.head6d)
    step = stats(np.asarray(model.latencies_ms))

    # The bare session.run on the same feeds: what the runner's window and state handling adds.
    feeds = dict(model._feeds)
    raw = []
    for _ in range(args.frames):
        t = time.perf_counter()
        model.session.run(None, feeds)
        raw.append((time.perf_counter() - t) * 1e3)
    bare = stats(np.asarray(raw))

    print(f"reference model: {path.name}, {path.stat().st_size / 1024:.0f} KiB, {model.spec.n_joints} joints, "
          f"{fps:g} fps, window {model.spec.window}, features {','.join(model.spec.audio_features)}")
    print(f"onnxruntime {ort.__version__}, 1 thread, {platform.processor() or platform.machine()}, {args.frames} frames")
    print()
    print(f"{'per frame (ms)':<34}{'median':>9}{'p99':>9}{'max':>9}")
    print(f"{'StreamingGestureModel.step':<34}{step[0]:9.3f}{step[1]:9.3f}{step[2]:9.3f}")
    print(f"{'bare InferenceSession.run':<34}{bare[0]:9.3f}{bare[1]:9.3f}{bare[2]:9.3f}")
    print(f"{'audio features (batch, amortised)':<34}{feat_ms:9.3f}")
    print(f"{'FaceCapGes published (RTX 4090)':<34}{PUBLISHED_MS:9.3f}")
    print()
    print(f"published / this median: {PUBLISHED_MS / step[0]:.1f}x  (this run is {step[0] / PUBLISHED_MS * 100:.1f} % of "
          f"the published per-frame time)")
    print(f"real-time budget at {fps:g} fps: {1000 / fps:.1f} ms; p99 uses {step[1] / (1000 / fps) * 100:.2f} % of it")
    print("note: the reference model is untrained; the comparison is of cost per frame, not of quality, and "
          "across different hardware and frameworks")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
