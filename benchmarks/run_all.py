"""Run every benchmark in this folder, one after the other, and print their figures.

Usage: ``python benchmarks/run_all.py [--json FILE] [name-substring ...]``. Each benchmark is a plain script
that prints its own table with ratios measured in the same run, so a noisy shared machine still gives
comparable numbers. With ``--json FILE`` the headline figures the benchmarks record (:mod:`_figures`) are
written to FILE as one object, ``{key: {"value", "baseline", "unit", ...}}``; each figure carries the load
average it was measured under.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from _figures import ENV  # noqa: E402


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, default=None, help="write the recorded figures to this file")
    ap.add_argument("names", nargs="*", help="run only benchmarks whose file name contains one of these")
    args = ap.parse_args(argv)
    scripts = sorted(p for p in HERE.glob("bench_*.py") if not args.names or any(a in p.name for a in args.names))
    failed = []
    figures: dict[str, dict] = {}
    load_start = round(os.getloadavg()[0], 2)
    with tempfile.TemporaryDirectory() as tmp:
        for script in scripts:
            print(f"\n=== {script.name} ===", flush=True)
            sink = Path(tmp) / f"{script.stem}.jsonl"
            env = {**os.environ, ENV: str(sink)}
            t0 = time.perf_counter()
            rc = subprocess.call([sys.executable, str(script)], env=env)
            print(f"--- {script.name}: exit {rc}, {time.perf_counter() - t0:.1f} s", flush=True)
            if rc:
                failed.append(script.name)
            if sink.exists():
                for line in sink.read_text(encoding="utf-8").splitlines():
                    row = json.loads(line)
                    key = row.pop("key")
                    figures[key] = {**row, "benchmark": script.name}
    if args.json is not None:
        args.json.write_text(json.dumps(figures, indent=2) + "\n", encoding="utf-8")
        print(f"\nfigures written to {args.json}: {', '.join(sorted(figures)) or 'none'} (load average "
              f"{load_start} at the start, {os.getloadavg()[0]:.2f} at the end, {os.cpu_count()} cores)")
    if failed:
        print(f"\nfailed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
