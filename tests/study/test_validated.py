"""A session start reuses a passed ``validate`` of exactly the same files (studyapp.study.design.validated),
and checks in full otherwise: a broken motion file of the third trial is refused before the first trial, with
the line ``validate`` prints, by a real ``studyapp run`` process, and answers already stored stay."""
from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from fixtures.synthetic import write_synthetic_study

CLI = [sys.executable, "-m", "studyapp.cli"]


def _run(cache: Path, *args: object) -> subprocess.CompletedProcess:
    env = {**os.environ, "STUDYAPP_CACHE_DIR": str(cache)}
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=180, env=env)


def _third_trial_motion(design_path: Path) -> Path:
    from studyapp.study.design import FROZEN_PREFIX, load_design, motion_path
    from studyapp.study.schedule import participant_schedule

    design = load_design(design_path, check_files=False)
    plan = [p for p in participant_schedule(design, "P2", row=0) if not p.is_practice][2]
    stim = design.stimulus(plan.stimulus_id)
    cond = next(design.condition(c.removeprefix(FROZEN_PREFIX)) for c in plan.slots
                if design.condition(c.removeprefix(FROZEN_PREFIX)).motion is not None)
    return motion_path(design, cond, stim, 1)


def test_load_reuses_a_recorded_check_and_any_changed_file_undoes_it(tmp_path: Path, monkeypatch) -> None:
    import studyapp.study.stimuli as stimuli
    from studyapp.study.design import load_design, validate_design

    monkeypatch.setenv("STUDYAPP_CACHE_DIR", str(tmp_path / "cache"))
    design = write_synthetic_study(tmp_path / "study", n_stimuli=3)
    calls = []
    real = stimuli.check_stimulus_files
    monkeypatch.setattr(stimuli, "check_stimulus_files", lambda d: calls.append(d) or real(d))

    load_design(design, reuse_check=True)             # nothing recorded: the full check runs
    assert len(calls) == 1
    load_design(design, reuse_check=True)             # recorded by the check above
    assert len(calls) == 1
    assert validate_design(design) == [] and len(calls) == 2   # `validate` always checks in full
    load_design(design)                               # so does a plain load
    assert len(calls) == 3
    assert len(list((tmp_path / "cache" / "validated").iterdir())) == 1

    motion = _third_trial_motion(design)
    motion.write_bytes(motion.read_bytes() + b" ")    # same content but one byte: a new hash, a new check
    load_design(design, reuse_check=True)
    assert len(calls) == 4


def test_broken_third_trial_motion_is_refused_before_the_session_with_validates_line(tmp_path: Path) -> None:
    cache = tmp_path / "cache"
    design = write_synthetic_study(tmp_path / "study", n_stimuli=3)
    ok = _run(cache, "validate", design)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert len(list((cache / "validated").iterdir())) == 1
    db = tmp_path / "kept.sqlite"
    first = _run(cache, "run", design, "--results", db, "--participant", "P1", "--no-render", "--bot", "random")
    assert first.returncode == 0, first.stderr
    stored = sqlite3.connect(db).execute("SELECT count(*) FROM responses").fetchone()[0]
    assert stored > 0

    motion = _third_trial_motion(design)
    text = motion.read_text()
    motion.write_text(text[:text.index("MOTION")])    # the header only: no MOTION block
    bad = _run(cache, "validate", design)
    assert bad.returncode == 1
    line = next(ln for ln in bad.stdout.splitlines() if str(motion.name) in ln)

    fresh = tmp_path / "fresh.sqlite"
    refused = _run(cache, "run", design, "--results", fresh, "--participant", "P2", "--no-render", "--bot", "random")
    assert refused.returncode != 0
    assert line in refused.stderr + refused.stdout
    assert "Traceback" not in refused.stderr and "saved trial" not in refused.stdout
    assert not fresh.exists() or fresh.stat().st_size == 0

    # the database that holds P1's answers refuses the changed design, and keeps every answer
    again = _run(cache, "run", design, "--results", db, "--participant", "P2", "--no-render", "--bot", "random")
    assert again.returncode != 0 and "Traceback" not in again.stderr
    assert sqlite3.connect(db).execute("SELECT count(*) FROM responses").fetchone()[0] == stored


if __name__ == "__main__":
    sys.exit(pytest.main([__file__, "-q"]))
