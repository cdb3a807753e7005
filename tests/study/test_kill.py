"""Kill tests with real processes: ``studyapp run --no-render --bot random`` SIGKILLed again and again.

Every restart must resume where the last commit left off; in the end the database must hold exactly the
answers of an uninterrupted run with the same seed -- none lost, none duplicated, identical ranks -- and
every trial a killed process reported as saved must be in the database.
"""
from __future__ import annotations

import os
import queue
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from fixtures.synthetic import write_synthetic_study

pytestmark = pytest.mark.skipif(os.name != "posix", reason="SIGKILL is POSIX")

CLI = [sys.executable, "-m", "studyapp.cli"]
N_KILLS = 25
N_STIMULI = 48
SEED = 11


def _cmd(design: Path, db: Path, pace: float) -> list[str]:
    return [*CLI, "run", str(design), "--participant", "K1", "--results", str(db), "--no-render", "--bot", "random",
            "--seed", str(SEED), "--bot-pace", str(pace)]


def _reader(stream, out: queue.Queue) -> None:
    for line in iter(stream.readline, ""):
        out.put((time.monotonic(), line.rstrip("\n")))
    out.put((time.monotonic(), None))


def _answers(db: Path) -> tuple[list[tuple], list[tuple], list[tuple]]:
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        trials = con.execute("SELECT trial_index, stimulus, slot_left, slot_middle, slot_right FROM trials "
                             "WHERE participant = 'K1' ORDER BY trial_index").fetchall()
        ranks = con.execute("SELECT trial_index, criterion, slot, condition, rank FROM responses "
                            "WHERE participant = 'K1' ORDER BY trial_index, criterion, slot").fetchall()
        quest = con.execute("SELECT item, value FROM questionnaire WHERE participant = 'K1' ORDER BY item").fetchall()
    finally:
        con.close()
    return trials, ranks, quest


def _status(db: Path) -> str | None:
    if not db.exists() or not db.stat().st_size:
        return None
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        row = con.execute("SELECT status FROM participants WHERE id = 'K1'").fetchone()
    except sqlite3.OperationalError:  # killed before the schema was committed
        row = None
    finally:
        con.close()
    return None if row is None else row[0]


def _kill_until_done(design: Path, db: Path, env: dict, rng: np.random.Generator, startup: float, gap: float,
                     max_kills: int) -> tuple[int, int, int]:
    """SIGKILL runs on ``db`` until ``max_kills`` kills or the study is complete; returns (kills, kills after
    new answers, runs), checking after each kill that every reported answer is on disk."""
    pace = 0.01
    reported: set[int] = set()
    kills = 0
    answering_kills = 0  # kills of a run that had committed answers and was not done
    n_before = 0
    runs = 0
    while kills < max_kills:
        runs += 1
        assert runs < max(3 * max_kills, 10), "the bot finished too often before a kill could land"
        proc = subprocess.Popen(_cmd(design, db, pace), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                env=env)
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=_reader, args=(proc.stdout, lines), daemon=True).start()
        # Kill during start-up (opening or creating the database, registering the participant), or at a
        # random moment after the first answer of this run was committed, while trials are being answered.
        mode = rng.choice(["startup", "opened", "answering", "answering"])
        if mode == "startup":
            time.sleep(rng.uniform(0.0, startup))
        else:
            wanted = "Results database" if mode == "opened" else "saved trial"
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                try:
                    _, line = lines.get(timeout=deadline - time.monotonic())
                except queue.Empty:
                    break
                if line is not None and line.startswith("saved trial"):
                    reported.add(int(line.split()[-1]))
                if line is None or line.startswith(wanted):
                    break
            time.sleep(rng.uniform(0.0, gap if mode == "opened" else 0.08))
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            kills += 1
        proc.wait(timeout=30)
        err = proc.stderr.read()
        proc.stdout.close()
        proc.stderr.close()
        # collect what the process said it saved before it died
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:
            try:
                _, line = lines.get(timeout=1)
            except queue.Empty:
                break
            if line is None:
                break
            if line.startswith("saved trial"):
                reported.add(int(line.split()[-1]))
        if proc.returncode == 0:
            break  # finished before the kill: the study is complete
        assert proc.returncode == -signal.SIGKILL, err
        if _status(db) == "done":
            break  # killed while exiting after the last commit
        if db.exists():
            trials, ranks, _ = _answers(db) if _status(db) else ([], [], [])
            in_db = {t[0] for t in trials}
            assert reported <= in_db, f"reported saved but missing: {sorted(reported - in_db)}"
            # answered trials are always a prefix of the schedule, each with all 9 ranks
            assert sorted(in_db) == list(range(len(in_db)))
            assert len(ranks) == 9 * len(in_db)
            answering_kills += n_before < len(in_db) < N_STIMULI + 1
            n_before = len(in_db)
    return kills, answering_kills, runs


def _finish_and_compare(design: Path, db: Path, env: dict, reference: tuple, answering_kills: int) -> None:
    """Run ``db`` to the end uninterrupted; its answers must equal the reference run's exactly."""
    done = subprocess.run(_cmd(design, db, 0.0), capture_output=True, text=True, env=env, timeout=120)
    if done.returncode != 0:  # already complete: a finished participant is refused, clearly
        assert "already completed" in done.stderr, done.stderr
    trials, ranks, quest = _answers(db)
    ref_trials, ref_ranks, ref_quest = reference
    assert trials == ref_trials
    assert ranks == ref_ranks
    assert quest == ref_quest
    con = sqlite3.connect(db)
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    assert con.execute("SELECT status FROM participants WHERE id = 'K1'").fetchone()[0] == "done"
    n_sessions = con.execute("SELECT COUNT(*) FROM sessions").fetchone()[0]
    con.close()
    assert n_sessions >= answering_kills + 1  # each of those runs was a session of its own


@pytest.mark.timeout(180)
def test_sigkill_at_random_points_loses_and_duplicates_nothing(tmp_path: Path) -> None:
    design = write_synthetic_study(tmp_path / "study", n_stimuli=N_STIMULI, seconds=0.5, questionnaire=True)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}

    # The uninterrupted reference run, same participant id and seed, its own database.
    # Its output timing tells how long start-up takes (until the database is open, until the first answer).
    ref_db = tmp_path / "reference.sqlite"
    t0 = time.monotonic()
    ref = subprocess.Popen(_cmd(design, ref_db, 0.01), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           env=env)
    stamps = {}
    for line in ref.stdout:
        for key in ("Results database", "saved trial"):
            if line.startswith(key):
                stamps.setdefault(key, time.monotonic() - t0)
    assert ref.wait(timeout=120) == 0, ref.stderr.read()
    ref.stdout.close()
    ref.stderr.close()
    gap = stamps["saved trial"] - stamps["Results database"]  # database open -> first answer committed
    # Start-up of a later run (the design is fully validated only before the first session): probe it with
    # the finished reference participant, which is refused right after the database is opened.
    t0 = time.monotonic()
    probe = subprocess.run(_cmd(design, ref_db, 0.0), capture_output=True, text=True, env=env, timeout=120)
    startup = time.monotonic() - t0
    assert probe.returncode == 2 and "already completed" in probe.stderr
    ref_trials, ref_ranks, ref_quest = _answers(ref_db)
    assert len(ref_trials) == N_STIMULI + 1 and len(ref_ranks) == (N_STIMULI + 1) * 3 * 3 and len(ref_quest) == 3

    rng = np.random.default_rng(2024)
    kills = answering_kills = runs = rounds = 0
    # On a loaded machine the bot can outrun the kills and finish the study early: then that database is
    # checked and a fresh one is killed, so the test always gets its N_KILLS kills.
    while kills < N_KILLS:
        rounds += 1
        assert rounds <= 4, f"the bot finished the study {rounds - 1} times with only {kills} kills"
        db = tmp_path / f"killed-{rounds}.sqlite"
        k, a, r = _kill_until_done(design, db, env, rng, startup, gap, N_KILLS - kills)
        kills, answering_kills, runs = kills + k, answering_kills + a, runs + r
        _finish_and_compare(design, db, env, (ref_trials, ref_ranks, ref_quest), a)
    assert kills >= N_KILLS and answering_kills >= 8, (kills, answering_kills)
    print(f"{kills} kills ({answering_kills} after new answers) over {runs} runs; start-up {startup:.2f} s, "
          f"first answer {gap:.2f} s after the database is open")
