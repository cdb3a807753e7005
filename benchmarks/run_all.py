"""Run every benchmark in this folder, one after the other, and print their figures.

Usage: ``python benchmarks/run_all.py [--json FILE] [name-substring ...]``. Each benchmark is a plain script
that prints its own table with ratios measured in the same run, so a noisy shared machine still gives comparable
numbers. With ``--json FILE`` every headline figure (see :mod:`figures`) is written to FILE with its baseline and
ratio, under ``_meta`` the machine's cores and its load average before and after the run.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description="Run the benchmarks in this folder and print their figures.")
    parser.add_argument("--json", type=Path, help="also write every headline figure to this JSON file")
    parser.add_argument("names", nargs="*", help="run only benchmarks whose file name contains one of these")
    args = parser.parse_args(argv)
    scripts = sorted(p for p in HERE.glob("bench_*.py") if not args.names or any(a in p.name for a in args.names))
    env = dict(os.environ)
    if args.json:
        args.json.write_text("{}\n")
        env["STUDYAPP_BENCH_JSON"] = str(args.json.resolve())
    load_before = os.getloadavg()
    failed = []
    for script in scripts:
        print(f"\n=== {script.name} ===", flush=True)
        t0 = time.perf_counter()
        rc = subprocess.call([sys.executable, str(script)], env=env)
        print(f"--- {script.name}: exit {rc}, {time.perf_counter() - t0:.1f} s", flush=True)
        if rc:
            failed.append(script.name)
    if args.json:
        figures = json.loads(args.json.read_text())
        figures["_meta"] = {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                            "cores": os.cpu_count(), "machine": platform.machine(), "python": platform.python_version(),
                            "loadavg_before": list(load_before), "loadavg_after": list(os.getloadavg()),
                            "benchmarks": [s.name for s in scripts], "failed": failed}
        args.json.write_text(json.dumps(figures, indent=2, sort_keys=True) + "\n")
        print(f"\nfigures written to {args.json}")
    if failed:
        print(f"\nfailed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
