"""Issue 7's end-to-end check: a design with a live ONNX condition runs as a study and exports.

The scripted participant goes through the real UI offscreen (so the live model's motion is generated,
retargeted and drawn) and the export holds ranks for the live condition like for any other.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd

from studyapp.resources import designs_dir


def _cli(*args: object, env: dict[str, str], cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "studyapp.cli", *map(str, args)], env=env, cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def test_live_model_condition_runs_in_a_bot_session_and_exports(tmp_path: Path) -> None:
    env = {**os.environ, "STUDYAPP_CACHE_DIR": str(tmp_path / "cache")}
    design = designs_dir() / "live_model_example.toml"
    db = tmp_path / "live.sqlite"
    run = _cli("run", design, "--participant", "L01", "--results", db, "--offscreen", "--bot", "careful",
               env=env, cwd=tmp_path)
    assert run.returncode == 0, run.stdout + run.stderr
    # the live model ran causally over every clip and its motion was cached for the next session
    cached = list((tmp_path / "cache").rglob("*.npz"))
    assert cached, "the live model's output was not cached"

    csv = tmp_path / "live.csv"
    exported = _cli("export", db, "--csv", csv, env=env, cwd=tmp_path)
    assert exported.returncode == 0, exported.stderr
    df = pd.read_csv(csv)
    rated = df[~df["is_practice"].astype(bool) & ~df["is_attention_check"].astype(bool)]
    assert set(rated["condition"]) == {"synced", "reference", "static"}
    per_trial = rated.groupby(["trial_index", "criterion"])["rank"].apply(sorted)
    assert all(r == [1, 2, 3] for r in per_trial), per_trial
    live = rated[rated["condition"] == "reference"]
    assert len(live) == rated["trial_index"].nunique() * rated["criterion"].nunique()
    assert (df["design_hash"].nunique() == 1) and df["app_version"].notna().all()
