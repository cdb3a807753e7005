"""``studyapp generate``: run a live ONNX gesture model over one clip outside a study.

It streams the model frame by frame (as a live condition does), writes the motion as a BEAT BVH and,
with ``--report``, a JSON file with the frame count and per-frame latency (median, p99, max in ms).
"""
from __future__ import annotations

import argparse
import json
import logging
import platform
from pathlib import Path

import numpy as np

from studyapp.errors import InputError

log = logging.getLogger(__name__)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "generate", help="run an ONNX gesture model over a clip and write BVH",
        description="Run a studyapp ONNX gesture model (see studyapp/models/CONTRACT.md) causally, one frame at a "
                    "time, over a speech clip and its facial animation; write the motion as BVH on the BEAT skeleton.",
    )
    p.add_argument("--model", required=True, type=Path, help="the .onnx model")
    p.add_argument("--audio", required=True, type=Path, help="speech WAV")
    p.add_argument("--face", type=Path, help="ARKit facial animation (Live Link Face CSV, BEAT JSON, CSV, NPZ)")
    p.add_argument("--head", type=Path,
                   help="head yaw/pitch/roll in radians at the face's frame rate: .npy (F, 3) or CSV with yaw, pitch, "
                        "roll columns (default: the face file's own head rotation, if any)")
    p.add_argument("--out", required=True, type=Path, help="output .bvh")
    p.add_argument("--report", type=Path, help="write frames generated and per-frame latency as JSON here")
    p.add_argument("--fps", type=float, help="frame rate to run the model at (default: the model's studyapp.fps)")
    p.add_argument("--threads", type=int, default=1, help="onnxruntime threads (default 1)")
    p.set_defaults(func=run_generate)


def load_head(path: Path) -> np.ndarray:
    """``(F, 3)`` yaw/pitch/roll radians from ``.npy``, or from CSV: either a header naming ``yaw``, ``pitch``,
    ``roll`` columns (any case, optional ``head`` prefix as in Live Link Face; other columns ignored) or
    exactly three numeric columns in that order."""
    if not path.is_file():
        raise InputError(path, None, "file not found")
    if path.suffix.lower() == ".npy":
        from studyapp.safe_io import load_npy

        head = load_npy(path)
    else:
        lines = [(i, ln) for i, ln in enumerate(path.read_text(encoding="utf-8-sig").splitlines(), 1) if ln.strip()]
        cells = [[c.strip() for c in ln.split(",")] for _, ln in lines]
        cols, header_less = [0, 1, 2], True
        if cells and not _numeric_row(cells[0]):
            header_less = False
            names = [c.lower().removeprefix("head").lstrip("_") for c in cells[0]]
            try:
                cols = [names.index(n) for n in ("yaw", "pitch", "roll")]
            except ValueError:
                raise InputError(path, "line 1", f"header {lines[0][1]!r} has no yaw, pitch and roll columns") from None
            lines, cells = lines[1:], cells[1:]
        rows = []
        for (i, line), row in zip(lines, cells):
            picked = [row[c] for c in cols if c < len(row)]
            if len(picked) != 3 or not _numeric_row(picked) or (header_less and len(row) != 3):
                raise InputError(path, f"line {i}", f"expected three numbers (yaw, pitch, roll), got {line!r}")
            rows.append([float(v) for v in picked])
        head = np.array(rows, dtype=np.float64) if rows else np.zeros((0, 3))
    if head.ndim != 2 or head.shape[1] != 3 or head.shape[0] == 0:
        raise InputError(path, None, f"shape {head.shape}, expected (frames, 3) yaw/pitch/roll in radians")
    if not np.isfinite(head).all():
        raise InputError(path, None, "contains NaN or infinite values")
    return head


def _numeric_row(cells: list[str]) -> bool:
    try:
        [float(c) for c in cells]
    except ValueError:
        return False
    return True


def run_generate(args: argparse.Namespace) -> int:
    from studyapp.audio.wav import load_wav
    from studyapp.face.io import load_face
    from studyapp.models.live import generate, stimulus_inputs, to_beat_motion
    from studyapp.models.runner import StreamingGestureModel
    from studyapp.motion.bvh import write_bvh

    model = StreamingGestureModel(args.model, threads=args.threads)
    spec = model.spec
    fps = float(args.fps or spec.fps)
    if args.fps and abs(fps - spec.fps) > 1e-6:
        log.warning("running %s at %g fps; it declares %g fps", args.model.name, fps, spec.fps)
    audio = load_wav(args.audio)
    face = load_face(args.face) if args.face else None
    head = load_head(args.head) if args.head else None
    inputs = stimulus_inputs(spec, audio, face, head, fps)
    output = generate(model, inputs)
    motion = to_beat_motion(output, spec, fps, source=f"{args.model} on {args.audio}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    write_bvh(motion, args.out)
    lat = model.latency_summary()
    print(f"wrote {args.out}: {motion.n_frames} frames at {fps:g} fps; per-frame latency median {lat['median_ms']:.3f} ms, "
          f"p99 {lat['p99_ms']:.3f} ms, max {lat['max_ms']:.3f} ms")
    if args.report:
        import onnxruntime

        report = {
            "model": str(args.model), "audio": str(args.audio), "face": str(args.face) if args.face else None,
            "out": str(args.out), "fps": fps, "frames": int(output.shape[0]), "joints": len(spec.joints),
            "rotation": spec.rotation, "latency_ms": {k[:-3]: v for k, v in lat.items() if k.endswith("_ms")},
            "threads": args.threads, "onnxruntime": onnxruntime.__version__, "cpu": platform.processor() or platform.machine(),
        }
        args.report.parent.mkdir(parents=True, exist_ok=True)
        args.report.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    return 0
