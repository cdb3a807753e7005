"""Benchmark: the statistics of a large study, cold, against a same-machine baseline, interleaved.

A study of N participants (default 10,000) x 8 stimuli x 3 criteria x 3 conditions is simulated once and
written as the CSV export. Each run then starts a fresh Python process, as an experimenter's
``studyapp-analyze`` does, so imports, reading the CSV and the first (cold) analysis all count:

* ours: import results_analysis, ``load_results``, ``run_analysis`` (Friedman, Nemenyi, Wilcoxon, Conover,
  2,000 participant bootstraps for the mean-rank, Bradley-Terry and effect-size intervals, breakdown by
  speaker, agreement), then ``write_outputs`` (tables, the four figures as PNG and SVG, the report);
* baseline: pingouin's ``friedman`` and scikit-posthocs' ``posthoc_nemenyi_friedman`` per criterion when both
  are installed, else scipy's ``friedmanchisquare`` per criterion (said so in the output): pandas reading
  the same CSV, the participant x condition mean ranks, the omnibus test (and post-hoc) per criterion.

The two alternate (ours first in odd rounds, the baseline first in even ones) over the same number of runs;
the table gives medians with min-max. Time is wall clock from just before the process is started to the
end of its statistics (``analysis_10k_s``), so interpreter start and imports are in it; the
process's user + system CPU time up to that point (``analysis_10k_cpu_s``, all threads: the analysis draws its
largest resample matrices in a background thread) is given beside it, as machine load inflates it less than
wall time; peak memory is the process's peak resident set size at that point (``analysis_10k_peak_mb``). Figures are recorded with
:func:`figures.record` for ``run_all.py --json``; the load average is printed and recorded with them.

The package's bytecode is compiled first (``compileall``), as ``pip install`` does and as bench_startup does:
with ``PYTHONDONTWRITEBYTECODE`` set and no ``__pycache__`` in a checkout, every run would otherwise compile
results_analysis's modules again (0.1-0.2 s of CPU here), a cost an experimenter's installed copy pays never
and a checkout only on its first run.

Usage: ``python benchmarks/bench_analysis.py [n_participants] [runs]`` (defaults 10000 and 3).
"""
from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def _cpu_s() -> float:
    """User + system CPU seconds of this process so far (all its threads): what the machine's load does not
    inflate the way it inflates wall-clock time."""
    import resource
    u = resource.getrusage(resource.RUSAGE_SELF)
    return u.ru_utime + u.ru_stime


def _peak_mb() -> float:
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def _child_ours(csv: Path, out: Path) -> dict:
    t = time.perf_counter()
    from results_analysis.analysis import run_analysis
    from results_analysis.loader import load_results
    from results_analysis.report import write_outputs
    phases = {"import": time.perf_counter() - t}
    t = time.perf_counter()
    df = load_results(csv)
    phases["load csv"] = time.perf_counter() - t
    t = time.perf_counter()
    a = run_analysis(df, groups=["speaker"], exclude_failed_attention=True, conover=True, n_boot=2000, seed=0)
    phases["statistics"] = time.perf_counter() - t
    done, peak, cpu = time.time(), _peak_mb(), _cpu_s()
    t = time.perf_counter()
    write_outputs(a, out, title="Benchmark")
    phases["tables, figures, report"] = time.perf_counter() - t
    return {"stats_done": done, "peak_mb": peak, "cpu_s": cpu, "phases": phases, "peak_mb_all": _peak_mb()}


def _have_pingouin() -> bool:
    import importlib.util
    return all(importlib.util.find_spec(m) is not None for m in ("pingouin", "scikit_posthocs"))


def _child_baseline(csv: Path) -> dict:
    t = time.perf_counter()
    import pandas as pd
    use_pg = _have_pingouin()
    if use_pg:
        import pingouin as pg
        import scikit_posthocs as sp
    else:
        from scipy.stats import friedmanchisquare
    phases = {"import": time.perf_counter() - t}
    t = time.perf_counter()
    df = pd.read_csv(csv)
    phases["load csv"] = time.perf_counter() - t
    t = time.perf_counter()
    df = df[~df["is_practice"].astype(bool) & ~df["is_attention_check"].astype(bool)]
    df = df[~df["participant"].isin(df.loc[~df["attention_passed"].astype(bool), "participant"])]
    for crit, g in df.groupby("criterion"):
        wide = g.pivot_table(index="participant", columns="condition", values="rank", aggfunc="mean")
        if use_pg:
            long = wide.reset_index().melt(id_vars="participant", var_name="condition", value_name="rank")
            pg.friedman(long, dv="rank", within="condition", subject="participant")
            sp.posthoc_nemenyi_friedman(wide.to_numpy())
        else:
            friedmanchisquare(*[wide[c].to_numpy() for c in wide.columns])
    phases["statistics"] = time.perf_counter() - t
    return {"stats_done": time.time(), "peak_mb": _peak_mb(), "cpu_s": _cpu_s(), "phases": phases}


def _run(kind: str, csv: Path, out: Path) -> dict:
    start = time.time()
    proc = subprocess.run([sys.executable, __file__, "--child", kind, str(csv), str(out)], capture_output=True,
                          text=True, env=dict(os.environ, MPLBACKEND="Agg"))
    if proc.returncode:
        raise SystemExit(f"{kind} run failed:\n{proc.stderr[-2000:]}")
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    res["cold_s"] = res["stats_done"] - start
    return res


def _spread(xs: list[float], unit: str) -> str:
    return f"{statistics.median(xs):7.2f} {unit} (min {min(xs):.2f}, max {max(xs):.2f})"


def _byte_compile() -> None:
    """Compile the package's bytecode as an installed copy has it (see the module text)."""
    import compileall

    import results_analysis
    compileall.compile_dir(str(Path(results_analysis.__file__).parent), quiet=2)


def main(argv: list[str]) -> int:
    if argv and argv[0] == "--child":
        kind, csv, out = argv[1], Path(argv[2]), Path(argv[3])
        print(json.dumps(_child_ours(csv, out) if kind == "ours" else _child_baseline(csv)))
        return 0
    from figures import record
    from results_analysis.simulate import simulate_results
    _byte_compile()
    n = int(argv[0]) if argv else 10_000
    runs = int(argv[1]) if len(argv) > 1 else 3
    baseline_name = ("pingouin.friedman + scikit_posthocs.posthoc_nemenyi_friedman" if _have_pingouin() else
                     "scipy.stats.friedmanchisquare (pingouin / scikit-posthocs not installed)")
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "results.csv"
        df = simulate_results(n, 8, seed=1, fail_attention=["P0007"])
        df.to_csv(csv, index=False)
        rated = int((~df.is_practice & ~df.is_attention_check).sum())
        del df
        ours, base = [], []
        for r in range(runs):
            order = ("ours", "baseline") if r % 2 == 0 else ("baseline", "ours")
            for kind in order:
                res = _run(kind, csv, Path(tmp) / f"out{r}")
                (ours if kind == "ours" else base).append(res)
    load_after = os.getloadavg()
    load = f"load average {load_before[0]:.2f} before, {load_after[0]:.2f} after, {os.cpu_count()} cores"
    print(f"{n} participants x 8 stimuli x 3 criteria x 3 conditions ({rated} rated answers), {runs} cold runs "
          f"each, interleaved; {load}")
    print(f"baseline: {baseline_name}")
    for name, rows in (("ours", ours), ("baseline", base)):
        print(f"  {name}:")
        for phase in rows[0]["phases"]:
            print(f"    {phase:26s} {_spread([r['phases'][phase] for r in rows], 's')}")
        print(f"    {'start to statistics done':26s} {_spread([r['cold_s'] for r in rows], 's')}")
        print(f"    {'CPU (user+sys) to then':26s} {_spread([r['cpu_s'] for r in rows], 's')}")
        print(f"    {'peak RSS at that point':26s} {_spread([r['peak_mb'] for r in rows], 'MB')}")
        if "peak_mb_all" in rows[0]:
            print(f"    {'peak RSS incl. outputs':26s} {_spread([r['peak_mb_all'] for r in rows], 'MB')}")
    cold, cold_base = statistics.median(r["cold_s"] for r in ours), statistics.median(r["cold_s"] for r in base)
    print(f"  ratio ours / baseline (start to statistics done): {cold / cold_base:.2f}x; target: ours <= 5 s")
    common = {"n_participants": n, "runs": runs, "baseline_is": baseline_name, "loadavg": [load_before[0],
              load_after[0]], "cores": os.cpu_count()}
    record("analysis_10k_s", value=cold, baseline=cold_base, unit="s",
           spread=[min(r["cold_s"] for r in ours), max(r["cold_s"] for r in ours)],
           note="cold process: start, imports, CSV load and every statistic; median", **common)
    record("analysis_10k_cpu_s", value=statistics.median(r["cpu_s"] for r in ours),
           baseline=statistics.median(r["cpu_s"] for r in base), unit="s",
           spread=[min(r["cpu_s"] for r in ours), max(r["cpu_s"] for r in ours)],
           note="user + system CPU time of the cold process (all threads) up to the end of its statistics; "
                "less inflated by machine load than wall time; median", **common)
    record("analysis_10k_peak_mb", value=statistics.median(r["peak_mb"] for r in ours),
           baseline=statistics.median(r["peak_mb"] for r in base), unit="MB",
           peak_incl_outputs_mb=statistics.median(r["peak_mb_all"] for r in ours),
           note="peak resident set size of the process when its statistics are done; median", **common)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
