"""Benchmark: the full analysis (tests, bootstraps, Bradley-Terry, breakdown, all figures and the report)
of 1,000 participants x 8 stimuli x 3 criteria x 3 conditions (72,000 rated answers).

Prints seconds per phase and each phase's share of the total, measured in the same run.
Usage: ``python benchmarks/bench_analysis.py [n_participants]``.
"""
from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

from results_analysis.analysis import run_analysis
from results_analysis.loader import load_results
from results_analysis.report import write_figures, write_outputs
from results_analysis.simulate import simulate_results


def main(argv: list[str]) -> int:
    n = int(argv[0]) if argv else 1000
    times: dict[str, float] = {}
    t = time.perf_counter()
    df = simulate_results(n, 8, seed=1, fail_attention=["P0007"])
    times["simulate"] = time.perf_counter() - t
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        t = time.perf_counter()
        df.to_csv(out / "results.csv", index=False)
        loaded = load_results(out / "results.csv")
        times["csv write + load"] = time.perf_counter() - t
        t = time.perf_counter()
        a = run_analysis(loaded, groups=["speaker"], exclude_failed_attention=True, conover=True,
                         n_boot=2000, seed=0)
        times["statistics (2000 bootstraps)"] = time.perf_counter() - t
        t = time.perf_counter()
        write_figures(a, out / "figures")
        times["figures (4 x png+svg)"] = time.perf_counter() - t
        t = time.perf_counter()
        write_outputs(a, out / "full", title="Benchmark")
        times["all outputs incl. figures"] = time.perf_counter() - t
    rated = int((~df.is_practice & ~df.is_attention_check).sum())
    analysis_total = times["csv write + load"] + times["statistics (2000 bootstraps)"] + times["all outputs incl. figures"]
    print(f"{n} participants x 8 stimuli x 3 criteria x 3 conditions: {rated} rated answers, "
          f"{a.criteria['realism'].friedman.n_blocks} blocks per criterion")
    for name, sec in times.items():
        print(f"  {name:32s} {sec:7.2f} s  ({sec / analysis_total:5.1%} of analysis)")
    print(f"  {'load + analyse + write everything':32s} {analysis_total:7.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
