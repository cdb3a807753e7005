"""Motion layer speed: BVH load and forward kinematics on a 60 s, 120 fps BEAT-like file.

Generates 7,200 frames x 228 channels (BEAT's 75 joints) in a temporary folder, written the way
DiffSHEG writes them (``%e`` numbers, double spaces, trailing space), then times

* ``read_bvh_channels`` (vectorized parse, raw channels) and ``read_bvh`` (plus Euler -> quaternions),
* a plain-Python line-by-line parser of the same file (written below, as a baseline),
* ``forward_kinematics`` (F, J, 4, 4) and ``joint_positions`` (F, J, 3),
* ``write_bvh``.

Each figure is the best of a few repeats; ratios are measured in the same run, so they stay
meaningful on a busy shared machine. Usage: ``python benchmarks/bench_motion.py [--frames N]``.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from studyapp.motion.beat import beat_skeleton
from studyapp.motion.bvh import format_bvh, read_bvh, read_bvh_channels, write_bvh
from studyapp.motion.fk import forward_kinematics, joint_positions


def naive_parse(path: Path) -> tuple[list[str], np.ndarray]:
    """Line-by-line BVH parse in plain Python: what a straightforward reader does."""
    names: list[str] = []
    n_channels = 0
    rows: list[list[float]] = []
    in_motion = False
    with open(path) as fh:
        for line in fh:
            toks = line.split()
            if not toks:
                continue
            if not in_motion:
                if toks[0] in ("ROOT", "JOINT"):
                    names.append(toks[1])
                elif toks[0] == "CHANNELS":
                    n_channels += int(toks[1])
                elif toks[0] == "Frame" and toks[1].startswith("Time"):
                    in_motion = True
                continue
            row = [float(t) for t in toks]
            if len(row) != n_channels:
                raise ValueError("bad line")
            rows.append(row)
    return names, np.array(rows)


def best_of(fn, repeats: int) -> tuple[tuple[float, float], object]:
    """Best wall-clock and best CPU time (seconds) of ``repeats`` calls, and the last result.

    CPU time is reported too because on a shared, oversubscribed machine wall time mostly measures
    the other jobs; CPU time is what this process spent.
    """
    best_wall, best_cpu, result = float("inf"), float("inf"), None
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        result = fn()
        best_wall = min(best_wall, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return (best_wall, best_cpu), result


def make_file(folder: Path, frames: int, style: str = "diffsheg") -> Path:
    """A BEAT-skeleton BVH: ``style`` ``"diffsheg"`` (``%e``, double spaces, trailing space, as that
    model writes) or ``"fixed"`` (``%.6f`` single spaces, as BEAT's own files and most tools)."""
    sk = beat_skeleton()
    rng = np.random.default_rng(0)
    n_ch = sum(len(c) for c in sk.channels)
    data = rng.normal(scale=20.0, size=(frames, n_ch))
    data[:, 1] += 100.0
    text = format_bvh(sk, np.zeros((1, n_ch)), 1 / 120)
    header = text[: text.index("Frames:")]
    line = "  ".join(["%e"] * n_ch) + " " if style == "diffsheg" else " ".join(["%.6f"] * n_ch)
    body = "\n".join(line % tuple(r) for r in data.tolist())
    path = folder / f"beat_60s_120fps_{style}.bvh"
    path.write_text(f"{header}Frames: {frames}\nFrame Time: 0.008333\n{body}\n")
    return path


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=7200)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    load_start = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = make_file(folder, args.frames)
        size_mb = path.stat().st_size / 1e6
        fixed = make_file(folder, args.frames, "fixed")
        fixed_mb = fixed.stat().st_size / 1e6
        t_fixed, _ = best_of(lambda: read_bvh_channels(fixed), args.repeats)
        t_raw, data = best_of(lambda: read_bvh_channels(path), args.repeats)
        t_read, motion = best_of(lambda: read_bvh(path, fps=120), args.repeats)
        t_naive, (names, naive) = best_of(lambda: naive_parse(path), max(1, args.repeats - 1))
        assert np.allclose(naive, data.channels) and len(names) == 75
        t_fk, _ = best_of(lambda: forward_kinematics(motion), args.repeats)
        t_pos, _ = best_of(lambda: joint_positions(motion), args.repeats)
        t_write, _ = best_of(lambda: write_bvh(motion, folder / "out.bvh", order="ZXY"), 1)

    f, j = motion.n_frames, motion.skeleton.n_joints
    print(f"file: {f} frames x {data.channels.shape[1]} channels ({j} joints), {size_mb:.1f} MB as DiffSHEG "
          f"writes it (%e), {fixed_mb:.1f} MB with %.6f")
    if hasattr(os, "getloadavg"):
        print(f"load average at the start: {load_start:.1f}, at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs "
              "(the parser uses 2 threads: wall < cpu when a second core was free)")
    print(f"{'step':<42} {'wall ms':>9} {'cpu ms':>9}")
    rows = [
        ("read_bvh_channels (vectorized parse)", t_raw),
        ("read_bvh_channels, %.6f file", t_fixed),
        ("read_bvh (parse + Euler -> quaternions)", t_read),
        ("naive line-by-line Python parse", t_naive),
        ("forward_kinematics -> (F, J, 4, 4)", t_fk),
        ("joint_positions -> (F, J, 3)", t_pos),
        ("write_bvh (new rotation order)", t_write),
    ]
    for name, (wall, cpu) in rows:
        print(f"{name:<42} {wall * 1e3:9.1f} {cpu * 1e3:9.1f}")
    print(f"speed-up of read_bvh_channels over the naive parser: {t_naive[0] / t_raw[0]:.1f}x wall, {t_naive[1] / t_raw[1]:.1f}x cpu")
    print(f"speed-up of read_bvh over the naive parser:          {t_naive[0] / t_read[0]:.1f}x wall, {t_naive[1] / t_read[1]:.1f}x cpu")
    print(f"FK throughput: {f * j / t_fk[0] / 1e6:.1f} M joint transforms/s (wall)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
