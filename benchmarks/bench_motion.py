"""Motion layer speed and memory: BVH load against ``pandas.read_csv``, forward kinematics at four lengths,
peak memory of loading a 60 s and a 1 h file.

* **BVH load** of a 60 s, 120 fps BEAT file (7,200 frames x 228 channels, 75 joints), in the two layouts real
  writers use: DiffSHEG's ``%e`` with double spaces and a trailing space, and ``%.6f`` (BEAT, most tools).
  Contenders, file on disk to a ``(F, C)`` float64 array: ``read_bvh_channels``; plain ``pandas.read_csv`` of
  the same MOTION block (``skiprows`` past the header, whitespace separated, C engine; pandas imported before
  timing); a line-by-line Python parser. The same number of runs each, interleaved (A B C, then C B A),
  medians with min-max. Each as it runs out of the box -- pandas 3 splits a large file between up to one
  thread per core, ``read_bvh_channels`` parses its pieces on up to one thread per core -- and then both held
  to one thread (``pandas.options.mode.max_threads = 1``; ``bvh_frames.THREADS = 1``). BLAS/OpenMP are
  pinned to one thread throughout.
* **Forward kinematics** ``(F, 75, 4, 4)`` at 1,800 / 3,600 / 7,200 / 14,400 frames, float32 (what the renderer
  uploads) and float64, interleaved, medians with min-max and milliseconds per 1,000 frames (linear in frames
  when that column is flat).
* **Peak memory** (``VmHWM`` of a fresh child process, less its high-water mark after the imports) of reading
  the 60 s file (channels; whole motion) and a 1 h file (432,000 frames, ~1 GB of text; channels as float64 and
  float32), next to the size of the array it produces. ``--no-hour`` skips the hour.

Headline figures go to ``run_all.py --json`` through :func:`figures.record`: ``bvh_load_ratio_vs_pandas``,
``fk_ms`` (float32 at 7,200 frames; baseline = the 50 ms target), ``fk_ms_float64``, ``bvh_peak_mb_60s``,
``bvh_peak_mb_1h``. Usage: ``python benchmarks/bench_motion.py [--runs N] [--no-hour]``.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one thread vs one thread
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from figures import load_average, record  # noqa: E402

from studyapp.motion import _threads  # noqa: E402
from studyapp.motion.beat import beat_skeleton  # noqa: E402
from studyapp.motion import bvh_frames  # noqa: E402
from studyapp.motion.bvh import format_bvh, read_bvh, read_bvh_channels  # noqa: E402
from studyapp.motion.fk import forward_kinematics  # noqa: E402
from studyapp.motion.rotations import euler_to_quat  # noqa: E402
from studyapp.motion.skeleton import Motion  # noqa: E402

_threads.WORKERS = 1  # read_bvh's Euler conversion too: one thread


def naive_parse(path: Path) -> np.ndarray:
    """Line-by-line BVH parse in plain Python: what a straightforward reader does."""
    n_channels = 0
    rows: list[list[float]] = []
    in_motion = False
    with open(path) as fh:
        for line in fh:
            toks = line.split()
            if not toks:
                continue
            if not in_motion:
                if toks[0] == "CHANNELS":
                    n_channels += int(toks[1])
                elif toks[0] == "Frame" and toks[1].startswith("Time"):
                    in_motion = True
                continue
            row = [float(t) for t in toks]
            if len(row) != n_channels:
                raise ValueError("bad line")
            rows.append(row)
    return np.array(rows)


def make_file(folder: Path, frames: int, style: str = "diffsheg", repeat: int = 1) -> tuple[Path, int]:
    """A BEAT-skeleton BVH (``style`` ``"diffsheg"``: ``%e``, double spaces, trailing space; ``"fixed"``:
    ``%.6f``, single spaces) of ``frames * repeat`` frames, and the number of header lines before the data."""
    sk = beat_skeleton()
    rng = np.random.default_rng(0)
    n_ch = sum(len(c) for c in sk.channels)
    data = rng.normal(scale=20.0, size=(frames, n_ch))
    data[:, 1] += 100.0
    text = format_bvh(sk, np.zeros((1, n_ch)), 1 / 120)
    header = text[: text.index("Frames:")] + f"Frames: {frames * repeat}\nFrame Time: 0.008333\n"
    line = "  ".join(["%e"] * n_ch) + " " if style == "diffsheg" else " ".join(["%.6f"] * n_ch)
    body = ("\n".join(line % tuple(r) for r in data.tolist()) + "\n").encode()
    path = folder / f"beat_{frames * repeat}f_{style}.bvh"
    with open(path, "wb") as fh:
        fh.write(header.encode())
        for _ in range(repeat):
            fh.write(body)
    return path, header.count("\n")


def interleaved(contenders: dict[str, callable], runs: int) -> dict[str, dict[str, list[float]]]:
    """Wall and CPU seconds of ``runs`` calls of each contender, the order reversed every other round."""
    out = {k: {"wall": [], "cpu": []} for k in contenders}
    names = list(contenders)
    for r in range(runs):
        for k in names if r % 2 == 0 else reversed(names):
            c0, t0 = time.process_time(), time.perf_counter()
            contenders[k]()
            out[k]["wall"].append(time.perf_counter() - t0)
            out[k]["cpu"].append(time.process_time() - c0)
    return out


def _med(xs: list[float]) -> float:
    return statistics.median(xs)


def _row(name: str, t: dict[str, list[float]]) -> str:
    w, c = t["wall"], t["cpu"]
    return (f"  {name:44s} {_med(w) * 1e3:8.1f} ms ({min(w) * 1e3:.1f}-{max(w) * 1e3:.1f})"
            f"   cpu {_med(c) * 1e3:8.1f} ms ({min(c) * 1e3:.1f}-{max(c) * 1e3:.1f})")


PEAK = r"""
import json, sys
import numpy as np
def hwm():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
what, path, header_lines = sys.argv[1], sys.argv[2], int(sys.argv[3])
if what == "pandas":
    import io, pandas as pd
else:
    from studyapp.motion.bvh import read_bvh, read_bvh_channels
before = hwm()
if what == "channels64":
    out = read_bvh_channels(path).channels
elif what == "channels32":
    out = read_bvh_channels(path, dtype=np.float32).channels
elif what == "motion":
    m = read_bvh(path, fps=120)
    out = np.concatenate([m.rotations.ravel(), m.translations.ravel()])
else:
    out = pd.read_csv(path, skiprows=header_lines, sep=r"\s+", header=None, engine="c", na_filter=False).to_numpy()
print(json.dumps({"before": before, "after": hwm(), "array": out.nbytes}))
"""


def peak(what: str, path: Path, header_lines: int) -> dict:
    """VmHWM (bytes) of a fresh process before and after one load, and the size of what it produced."""
    res = subprocess.run([sys.executable, "-c", PEAK, what, str(path), str(header_lines)], capture_output=True,
                         text=True, check=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


ONE_OURS = "read_bvh_channels, 1 thread"
ONE_PANDAS = "pandas.read_csv, 1 thread"


def _pandas_threads() -> int:
    from pandas.io.parsers.readers import _default_n_workers  # private: only to print the figure

    return _default_n_workers()


def bench_load(folder: Path, runs: int) -> dict:
    import pandas as pd  # imported before any timing: its import is not the parser's cost

    results = {}
    for style in ("diffsheg", "fixed"):
        path, skip = make_file(folder, 7200, style)

        def ours(p=path):
            return read_bvh_channels(p).channels

        def pandas_csv(p=path, s=skip):
            return pd.read_csv(p, skiprows=s, sep=r"\s+", header=None, engine="c", na_filter=False).to_numpy()

        def ours_one_thread(p=path):
            bvh_frames.THREADS = 1
            try:
                return read_bvh_channels(p).channels
            finally:
                bvh_frames.THREADS = None

        def pandas_one_thread(p=path, s=skip):
            with pd.option_context("mode.max_threads", 1):
                return pandas_csv(p, s)

        ref = naive_parse(path)
        assert np.array_equal(ours(), ref) and np.allclose(pandas_csv(), ref, rtol=1e-15, atol=0)
        assert np.array_equal(ours_one_thread(), ref) and np.array_equal(pandas_one_thread(), pandas_csv())
        contenders = {"read_bvh_channels": ours, "pandas.read_csv (same MOTION block)": pandas_csv,
                      ONE_OURS: ours_one_thread, ONE_PANDAS: pandas_one_thread}
        if style == "diffsheg":
            contenders["read_bvh (+ Euler -> quaternions)"] = lambda p=path: read_bvh(p, fps=120)
            contenders["naive line-by-line Python parse"] = lambda p=path: naive_parse(p)
        t = interleaved(contenders, runs)
        results[style] = (path, skip, t)
        mb = path.stat().st_size / 1e6
        print(f"BVH load, 60 s at 120 fps, {style} layout ({mb:.1f} MB), {runs} runs each, interleaved; "
              f"threads as they come (pandas: up to {_pandas_threads()}; ours: {bvh_frames._threads()}), then both "
              "held to 1:")
        for k, v in t.items():
            print(_row(k, v))
        ratio = _med(t["read_bvh_channels"]["wall"]) / _med(t["pandas.read_csv (same MOTION block)"]["wall"])
        ratio_cpu = _med(t["read_bvh_channels"]["cpu"]) / _med(t["pandas.read_csv (same MOTION block)"]["cpu"])
        print(f"  read_bvh_channels / pandas.read_csv: {ratio:.2f}x wall, {ratio_cpu:.2f}x cpu (target <= 1.0)")
        one = _med(t[ONE_OURS]["wall"]) / _med(t[ONE_PANDAS]["wall"])
        print(f"  both held to one thread: {one:.2f}x wall")
    return results


def bench_fk(runs: int) -> dict[tuple[int, str], dict[str, list[float]]]:
    sk = beat_skeleton()
    rng = np.random.default_rng(1)
    motions = {}
    for f in (1800, 3600, 7200, 14400):
        rot = euler_to_quat(rng.normal(scale=20.0, size=(f, sk.n_joints, 3)), "XYZ")
        trans = np.broadcast_to(sk.offsets, (f, sk.n_joints, 3)).copy()
        trans[:, 0] += rng.normal(scale=5.0, size=(f, 3))
        motions[f] = Motion(sk, 120.0, rot, trans)
    contenders = {(f, dt): (lambda m=m, d=dt: forward_kinematics(m, dtype=np.dtype(d)))
                  for f, m in motions.items() for dt in ("float32", "float64")}
    t = interleaved({f"{f} {dt}": fn for (f, dt), fn in contenders.items()}, runs)
    out = {(f, dt): t[f"{f} {dt}"] for f, dt in contenders}
    print(f"\nforward kinematics -> (F, 75, 4, 4), {runs} runs each, interleaved:")
    for dt in ("float32", "float64"):
        for f in motions:
            v = out[f, dt]
            print(_row(f"{f:6d} frames {dt}", v) + f"   {_med(v['wall']) * 1e3 / f * 1000:6.2f} ms / 1,000 frames")
        per = [_med(out[f, dt]["wall"]) / f for f in motions]
        print(f"  {dt}: cost per frame at 14,400 / at 1,800 frames = {per[-1] / per[0]:.2f} (1.00 = linear)")
    return out


def bench_memory(folder: Path, sixty: tuple[Path, int], hour: bool) -> dict:
    path, skip = sixty
    print("\npeak memory (VmHWM of a fresh process, less its mark after the imports):")
    rows = {"60 s channels (float64)": peak("channels64", path, skip),
            "60 s motion (read_bvh: quaternions + translations)": peak("motion", path, skip),
            "60 s pandas.read_csv (for comparison)": peak("pandas", path, skip)}
    if hour:
        big, big_skip = make_file(folder, 7200, "fixed", repeat=60)
        size = big.stat().st_size
        rows[f"1 h channels (float64), {size / 1e9:.2f} GB text"] = peak("channels64", big, big_skip)
        rows[f"1 h channels (float32), {size / 1e9:.2f} GB text"] = peak("channels32", big, big_skip)
        big.unlink()
    for k, v in rows.items():
        print(f"  {k:54s} peak {(v['after'] - v['before']) / 1e6:8.1f} MB over imports (absolute {v['after'] / 1e6:7.1f} MB); "
              f"result array {v['array'] / 1e6:7.1f} MB")
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--no-hour", action="store_true", help="skip the 1 h file (1 GB of text, ~1 min)")
    args = ap.parse_args()
    load_before = load_average()
    print(f"load average at the start: {load_before} on {os.cpu_count()} CPUs")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        loads = bench_load(folder, args.runs)
        fk = bench_fk(args.runs)
        path, skip, _ = loads["diffsheg"]
        mem = bench_memory(folder, (path, skip), not args.no_hour)
    load_after = load_average()
    print(f"load average at the end: {load_after}")
    common = {"runs": args.runs, "loadavg": [load_before, load_after], "cores": os.cpu_count(), "threads": 1}

    _, _, t = loads["diffsheg"]
    ours, pd_t = t["read_bvh_channels"], t["pandas.read_csv (same MOTION block)"]
    _, _, tf = loads["fixed"]
    record("bvh_load_ratio_vs_pandas", value=_med(ours["wall"]) / _med(pd_t["wall"]), baseline=1.0,
           unit="x pandas.read_csv time", read_bvh_channels_ms=_med(ours["wall"]) * 1e3,
           pandas_ms=_med(pd_t["wall"]) * 1e3,
           spread_ms={"read_bvh_channels": [min(ours["wall"]) * 1e3, max(ours["wall"]) * 1e3],
                      "pandas": [min(pd_t["wall"]) * 1e3, max(pd_t["wall"]) * 1e3]},
           cpu_ratio=_med(ours["cpu"]) / _med(pd_t["cpu"]),
           one_thread_ratio=_med(t[ONE_OURS]["wall"]) / _med(t[ONE_PANDAS]["wall"]),
           fixed_layout_ratio=_med(tf["read_bvh_channels"]["wall"]) / _med(tf["pandas.read_csv (same MOTION block)"]["wall"]),
           note="60 s 120 fps BEAT file (DiffSHEG %e layout) to a (7200, 228) float64 array; medians, interleaved; "
                "each with the threads it uses out of the box (pandas 3 splits the file between threads, ours parses "
                "its pieces on as many); one_thread_ratio: both held to one; baseline = the 1.0x target",
           **{**common, "threads": {"pandas": _pandas_threads(), "read_bvh_channels": bvh_frames._threads()}})
    for dt, key in (("float32", "fk_ms"), ("float64", "fk_ms_float64")):
        v = fk[7200, dt]
        per = [_med(fk[f, dt]["wall"]) / f for f in (1800, 3600, 7200, 14400)]
        record(key, value=_med(v["wall"]) * 1e3, baseline=50.0, unit="ms", spread=[min(v["wall"]) * 1e3, max(v["wall"]) * 1e3],
               cpu_ms=_med(v["cpu"]) * 1e3, dtype=dt,
               ms_per_1000_frames={str(f): per[k] * 1e6 for k, f in enumerate((1800, 3600, 7200, 14400))},
               linearity_14400_vs_1800=per[-1] / per[0],
               note=f"forward_kinematics, 7,200 frames x 75 joints -> (F, J, 4, 4) {dt}; baseline = the 50 ms target",
               **common)
    sixty = mem["60 s channels (float64)"]
    record("bvh_peak_mb_60s", value=(sixty["after"] - sixty["before"]) / 1e6, baseline=sixty["array"] / 1e6, unit="MB",
           absolute_mb=sixty["after"] / 1e6,
           motion_peak_mb=(mem["60 s motion (read_bvh: quaternions + translations)"]["after"]
                           - mem["60 s motion (read_bvh: quaternions + translations)"]["before"]) / 1e6,
           pandas_peak_mb=(mem["60 s pandas.read_csv (for comparison)"]["after"]
                           - mem["60 s pandas.read_csv (for comparison)"]["before"]) / 1e6,
           note="VmHWM of a child over its mark after imports, reading a 60 s 120 fps BEAT file's channels; "
                "baseline = the float64 array's size", **common)
    hour = {k: v for k, v in mem.items() if k.startswith("1 h")}
    if hour:
        (k64, h64), (k32, h32) = hour.items()
        record("bvh_peak_mb_1h", value=(h64["after"] - h64["before"]) / 1e6, baseline=h64["array"] / 1e6, unit="MB",
               absolute_mb=h64["after"] / 1e6, float32_peak_mb=(h32["after"] - h32["before"]) / 1e6,
               float32_array_mb=h32["array"] / 1e6, file=k64,
               note="VmHWM of a child over its mark after imports, reading a 1 h 120 fps BEAT file (432,000 frames) "
                    "as float64 channels; baseline = the array's size", **common)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
