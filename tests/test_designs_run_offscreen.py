"""Every shipped design that validates also runs: a scripted participant goes through the real app offscreen
to the end (a real ``studyapp run`` process), and every trial records the duration its timeline gives. A design
without a live model runs on a participant's install (no extras: pandas, scipy, matplotlib, onnxruntime, av
refused)."""
from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from fixtures.participant_install import participant_env
from studyapp.resources import designs_dir

DESIGNS = sorted(designs_dir().glob("*.toml"))


def test_there_are_designs_to_check() -> None:
    assert {p.name for p in DESIGNS} >= {"demo.toml", "example_beat.toml", "live_model_example.toml"}


@pytest.mark.parametrize("design", DESIGNS, ids=[p.stem for p in DESIGNS])
def test_a_design_that_validates_runs_offscreen(design: Path, tmp_path: Path) -> None:
    from studyapp.study.design import load_design, validate_design
    from studyapp.study.stimuli import load_audio

    if validate_design(design):
        pytest.skip(f"{design.name} does not validate")  # nothing to promise for it
    db = tmp_path / "r.sqlite"
    # a live model needs the "models" extra; everything else must run on what `pip install studyapp` brings
    live = any(c.model for c in load_design(design).conditions)
    env = os.environ if live else participant_env(tmp_path / "site")
    ran = subprocess.run([sys.executable, "-m", "studyapp.cli", "run", str(design), "--participant", "P01",
                          "--offscreen", "--bot", "careful", "--results", str(db)],
                         capture_output=True, text=True, timeout=600, env={**env, "MPLBACKEND": "Agg"})
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "completed the study" in ran.stdout
    d = load_design(design)
    expected = {s.id: s.duration_s if s.duration_s is not None else load_audio(s.audio).duration for s in d.stimuli}
    with sqlite3.connect(db) as con:
        rows = con.execute("SELECT stimulus, trial_duration_s FROM trials WHERE participant = 'P01'").fetchall()
        status = con.execute("SELECT status FROM participants WHERE id = 'P01'").fetchone()[0]
    assert status == "done" and rows
    for stim, seconds in rows:
        assert seconds == pytest.approx(expected[stim], abs=1e-6), stim
