"""``studyapp run | export | bundle | merge`` as real processes, the way experimenters and participants use them."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from fixtures.synthetic import write_synthetic_study

CLI = [sys.executable, "-m", "studyapp.cli"]


def _run(*args: str, env: dict | None = None, cwd: Path | None = None) -> subprocess.CompletedProcess:
    """A real ``studyapp`` process."""
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=180,
                          env={**os.environ, **(env or {})}, cwd=cwd)


@pytest.fixture()
def cli(capsys):
    """The same command line in this process (the dispatcher's ``main``), for the many short calls."""
    from studyapp.cli import main

    def call(*args: str) -> subprocess.CompletedProcess:
        capsys.readouterr()
        rc = main([str(a) for a in args])
        out, err = capsys.readouterr()
        return subprocess.CompletedProcess(args, rc, out, err)

    return call


def test_run_resume_refuse_rerun_and_export(tmp_path: Path, cli) -> None:
    design = write_synthetic_study(tmp_path / "study", n_stimuli=3, questionnaire=True)
    default_db = design.with_name("tiny.results.sqlite")

    first = _run("run", design, "--participant", "P1", "--no-render", "--bot", "random", "--seed", "4",
                 "--group", "device=desktop")
    assert first.returncode == 0, first.stderr
    assert f"Results database: {default_db}" in first.stdout and default_db.is_file()
    assert [ln for ln in first.stdout.splitlines() if ln.startswith("saved trial")] == \
        [f"saved trial {k}" for k in range(4)]

    again = cli("run", design, "--participant", "P1", "--no-render", "--bot", "random")
    assert again.returncode == 2 and "already completed" in again.stderr

    rerun = cli("run", design, "--participant", "P1", "--no-render", "--bot", "ordered", "--allow-rerun")
    assert rerun.returncode == 0 and "recorded as P1-rerun2" in rerun.stdout, rerun.stderr

    no_bot = cli("run", design, "--participant", "P2", "--no-render")
    assert no_bot.returncode == 2 and "--bot" in no_bot.stderr

    out = tmp_path / "out" / "results.csv"
    qout = tmp_path / "out" / "q.csv"
    exported = cli("export", default_db, "--csv", out, "--questionnaire-csv", qout)
    assert exported.returncode == 0, exported.stderr
    df = pd.read_csv(out)
    assert len(df) == 2 * 4 * 9 and set(df["participant"]) == {"P1", "P1-rerun2"}
    assert set(df["device"].dropna()) == {"desktop"} and set(df["speaker"]) == {"spk1", "spk2"}
    assert len(pd.read_csv(qout)) == 2 * 3

    # a changed stimulus changes the design hash: the old database is refused, naming the file
    audio = design.parent / "audio" / "s1.wav"
    data = bytearray(audio.read_bytes())
    mid = len(data) // 2
    data[mid:mid + 100] = bytes(b ^ 0x55 for b in data[mid:mid + 100])
    audio.write_bytes(bytes(data))
    changed = cli("run", design, "--participant", "P3", "--no-render", "--bot", "random")
    assert changed.returncode == 2 and "another design" in changed.stderr and str(default_db) in changed.stderr

    # a damaged database is refused by export too
    broken = tmp_path / "broken.sqlite"
    shutil.copy(default_db, broken)
    with open(broken, "r+b") as fh:
        fh.seek(0)
        fh.write(b"garbage garbage!")
    bad = cli("export", broken, "--csv", tmp_path / "x.csv")
    assert bad.returncode == 2 and str(broken) in bad.stderr and "not an SQLite database" in bad.stderr


def test_bundle_remote_run_and_merge(tmp_path: Path, cli) -> None:
    design = write_synthetic_study(tmp_path / "study", n_stimuli=2, practice=False)
    lab_db = tmp_path / "lab.sqlite"
    bundled = cli("bundle", design, "-o", tmp_path / "send" / "study.zip", "--participants", "2", "--results", lab_db)
    assert bundled.returncode == 0, bundled.stderr
    assert "R01 (row 0)" in bundled.stdout
    # the key stays in the lab database: nothing but the zip is written where the bundle goes
    assert sorted(p.name for p in (tmp_path / "send").iterdir()) == ["study.zip"]
    assert "not written next to the zip" in bundled.stdout

    # the participant's PC: own home, cache and data folders; runs from an unrelated folder
    home = tmp_path / "participant"
    home.mkdir()
    env = {"HOME": str(home), "XDG_CACHE_HOME": str(home / ".cache"), "XDG_DATA_HOME": str(home / ".local/share"),
           "STUDYAPP_RESULTS_DIR": str(home / "studyapp-results")}
    # watching each 1-second clip as long as it lasts: merge refuses answers given sooner
    remote = _run("run", tmp_path / "send" / "study.zip", "--participant", "R01", "--no-render", "--bot", "careful",
                  "--bot-pace", "1.0", env=env, cwd=home)
    assert remote.returncode == 0, remote.stderr
    [results_zip] = (home / "studyapp-results").glob("results-Tiny-synthetic-study-tiny-R01-*.zip")
    assert f"Your results file: {results_zip}" in remote.stdout and results_zip.is_file()
    assert str(home / ".local/share/studyapp/studies") in remote.stdout
    assert any((home / ".cache" / "studyapp" / "bundles").iterdir())

    merged = cli("merge", lab_db, results_zip, "--design", design)
    assert merged.returncode == 0 and "imported" in merged.stdout, merged.stdout + merged.stderr
    twice = cli("merge", lab_db, results_zip, "--design", design)
    assert twice.returncode == 0 and "already merged" in twice.stdout and "REFUSED" not in twice.stdout
    out = tmp_path / "lab.csv"
    assert cli("export", lab_db, "--csv", out).returncode == 0
    df = pd.read_csv(out)
    assert set(df["condition"]) == {"synced", "lagged", "static"} and set(df["participant"]) == {"R01"}
    # the careful viewer perceives the synced motion as best synchronized (on average: it has perception noise)
    sync = df[(df["criterion"] == "synchronization") & ~df["is_practice"].astype(bool)]
    assert sync.groupby("condition")["rank"].mean().idxmin() == "synced"


@pytest.mark.parametrize("command", ["render", "bundle", "merge", "export", "run", "validate", "schedule",
                                     "inspect", "convert", "view", "generate", "doctor", "demo"])
def test_every_command_help_has_a_description(command: str, capsys) -> None:
    """`studyapp CMD --help` shows a paragraph saying what the command does between usage and arguments."""
    from studyapp.cli import main

    with pytest.raises(SystemExit) as done:
        main([command, "--help"])
    assert done.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: studyapp {command}")
    paragraphs = out.split("\n\n")
    assert len(paragraphs) > 2 and not paragraphs[1].startswith(("positional arguments", "options")), out
    assert len(paragraphs[1].split()) >= 8, paragraphs[1]


def test_attention_checks_are_summed_up_for_the_experimenter_only(tmp_path: Path, cli) -> None:
    design = write_synthetic_study(tmp_path / "study", n_stimuli=2, practice=False, attention_check=True)
    lab = cli("run", design, "--participant", "P1", "--no-render", "--bot", "ordered")
    assert lab.returncode == 0, lab.stderr
    # the ordered bot ranks by design order, whatever the frozen figure does: its check passes or fails,
    # and the line must say which, agreeing with the stored trial
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB

    db = ResultsDB(design.with_name("tiny.results.sqlite"), load_design(design))
    [passed] = [t["attention_passed"] for t in db.trials("P1") if t["is_attention_check"]]
    db.close()
    assert f"Attention checks passed: {int(bool(passed))} of 1." in lab.stdout, lab.stdout
    cli("bundle", design, "-o", tmp_path / "send" / "study.zip", "--participants", "1",
        "--results", tmp_path / "lab.sqlite")
    env = {"HOME": str(tmp_path / "home"), "XDG_CACHE_HOME": str(tmp_path / "home" / ".cache"),
           "XDG_DATA_HOME": str(tmp_path / "home" / "data"), "STUDYAPP_RESULTS_DIR": str(tmp_path / "home" / "out")}
    remote = _run("run", tmp_path / "send" / "study.zip", "--participant", "R01", "--no-render", "--bot", "ordered",
                  env=env)
    assert remote.returncode == 0, remote.stderr
    assert "checks passed" not in remote.stdout, remote.stdout
