"""Cost of never losing an answer: commit latency of one trial, a whole bot session, export and merge.

Prints medians measured in this run, and the ratio of the durable setting (WAL + synchronous=FULL, what
studyapp uses) to the same commit with synchronous=NORMAL and OFF, so the figure is comparable across machines.
"""
from __future__ import annotations

import statistics
import sys
import tempfile
import time
from pathlib import Path

from studyapp.study.storage import Response, ResultsDB, TrialRecord, now_iso

# The synthetic study generator is a test fixture (tests/fixtures), not part of the installed package.
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def commit_ms(folder: Path, sync: str, n: int = 200) -> float:
    db = ResultsDB(folder / f"bench-{sync}.sqlite", design_hash="bench", title="bench")
    db.connection.execute(f"PRAGMA synchronous={sync}")
    db.add_participant("P", n_rows=1)
    times = []
    for k in range(n):
        rec = TrialRecord("P", k, "s", False, False, ("a", "b", "c"), now_iso(), plays=1)
        ranks = [Response(c, cond, i, i + 1) for c in ("realism", "synchronization", "diversity")
                 for i, cond in enumerate("abc")]
        t0 = time.perf_counter()
        db.save_trial(rec, ranks)
        times.append(time.perf_counter() - t0)
    db.close()
    return statistics.median(times) * 1e3


def main() -> int:
    from fixtures.synthetic import write_synthetic_study
    from studyapp.bots.session_driver import run_bot_session
    from studyapp.study.design import load_design
    from studyapp.study.export import export_dataframe

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        full, normal, off = (commit_ms(folder, s) for s in ("FULL", "NORMAL", "OFF"))
        print(f"commit of one trial (9 ranks), median of 200: FULL {full:.2f} ms, NORMAL {normal:.2f} ms, "
              f"OFF {off:.2f} ms; FULL/NORMAL = {full / max(normal, 1e-9):.1f}x, FULL/OFF = {full / max(off, 1e-9):.1f}x")
        design = load_design(write_synthetic_study(folder / "study", n_stimuli=24, questionnaire=True),
                             check_files=False)
        db = ResultsDB(folder / "study.sqlite", design)
        n_part = 20
        t0 = time.perf_counter()
        for i in range(n_part):
            run_bot_session(design, db, f"P{i:02d}", "random", i)
        dt = time.perf_counter() - t0
        n_trials = n_part * 25
        print(f"bot sessions (session level, random): {n_part} participants x 25 trials in {dt:.2f} s = "
              f"{dt / n_trials * 1e3:.2f} ms per trial (play start + play end + answer = 3 commits)")
        db.close()
        t0 = time.perf_counter()
        df = export_dataframe(folder / "study.sqlite")
        print(f"export: {len(df)} rows in {(time.perf_counter() - t0) * 1e3:.0f} ms")
    return 0


if __name__ == "__main__":
    sys.exit(main())
