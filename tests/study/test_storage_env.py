"""The results database's surroundings, with real processes and real file systems: a full disk, a read-only
folder or file, a lock held by another program and two participants creating a new database at once are each
one clear line (never "damaged, start a new one", never a traceback), and nothing already saved is lost.

The full-disk and read-only-folder cases mount a small tmpfs (root only; skipped elsewhere); the read-only
file case runs the session as user ``nobody`` when the tests run as root (root ignores file permissions).
"""
from __future__ import annotations

import os
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from studyapp.study.storage import ResultsDB
from fixtures.synthetic import write_synthetic_study

pytestmark = pytest.mark.skipif(os.name != "posix", reason="POSIX file systems and processes")

CLI = [sys.executable, "-m", "studyapp.cli"]
N_STIMULI = 6


def _env() -> dict:
    return {**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": os.pathsep.join(sys.path)}


def _run_cmd(design: Path, db: Path, pid: str = "P1", pace: float = 0.0) -> list[str]:
    return [*CLI, "run", str(design), "--participant", pid, "--results", str(db), "--no-render", "--bot", "random",
            "--seed", "3", "--bot-pace", str(pace)]


def _one_line_error(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if ln.startswith("error: ")]
    assert "Traceback" not in stderr and len(lines) == 1, stderr
    assert "damaged" not in lines[0] and "start a new one" not in lines[0], lines[0]
    return lines[0]


def _answers(db: Path, pid: str = "P1") -> list[tuple]:
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        return con.execute("SELECT trial_index, criterion, slot FROM responses WHERE participant = ? "
                           "ORDER BY trial_index, criterion, slot", (pid,)).fetchall()
    finally:
        con.close()


@pytest.fixture
def tmpfs():
    """A fresh 1 MiB tmpfs (a disk that can really fill up), unmounted afterwards."""
    mnt = Path(tempfile.mkdtemp(prefix="studyapp-tmpfs-"))
    if subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m,mode=0777", "tmpfs", str(mnt)],
                      capture_output=True).returncode != 0:
        mnt.rmdir()
        pytest.skip("mounting a tmpfs needs root")
    yield mnt
    subprocess.run(["umount", "-l", str(mnt)], check=False)
    mnt.rmdir()


def _fill(folder: Path, leave: int = 0) -> Path:
    """Fill the file system of ``folder`` up to about ``leave`` free bytes with one file; returns it."""
    filler = folder / "filler.bin"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    try:
        while True:
            st = os.statvfs(folder)
            room = st.f_bavail * st.f_frsize - leave
            if room <= 0:
                break
            os.write(fd, b"\0" * min(room, 1 << 16))
    except OSError:
        pass
    finally:
        os.close(fd)
    return filler


@pytest.fixture(scope="module")
def design(tmp_path_factory) -> Path:
    return write_synthetic_study(tmp_path_factory.mktemp("envstudy"), n_stimuli=N_STIMULI, seconds=0.5)


def test_a_full_disk_while_the_database_is_created_says_so(design: Path, tmpfs: Path) -> None:
    filler = _fill(tmpfs, leave=12 * 1024)  # room for the file's first pages, not for the whole schema
    db = tmpfs / "r.sqlite"
    run = subprocess.run(_run_cmd(design, db), capture_output=True, text=True, env=_env(), timeout=120)
    assert run.returncode == 2
    assert "disk is full" in _one_line_error(run.stderr) and "Free some disk space" in run.stderr
    filler.unlink()  # space again: the same file becomes the study's database
    run = subprocess.run(_run_cmd(design, db), capture_output=True, text=True, env=_env(), timeout=120)
    assert run.returncode == 0, run.stderr
    assert len(_answers(db)) == (N_STIMULI + 1) * 3 * 3


def test_a_full_disk_mid_session_says_so_and_loses_nothing(design: Path, tmpfs: Path) -> None:
    db = tmpfs / "r.sqlite"
    proc = subprocess.Popen(_run_cmd(design, db, pace=0.3), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=_env())
    saved = 0
    for line in proc.stdout:
        if line.startswith("saved trial"):
            saved += 1
            if saved == 2:
                break
    filler = _fill(tmpfs)  # the disk fills up between two answers
    out, err = proc.communicate(timeout=120)
    saved += out.count("saved trial")
    assert proc.returncode == 2, err
    line = _one_line_error(err)
    assert "disk is full" in line and "was not saved" in line and "resumes" in line
    assert len(_answers(db)) == saved * 3 * 3  # every answer it reported, none half-written
    filler.unlink()
    run = subprocess.run(_run_cmd(design, db), capture_output=True, text=True, env=_env(), timeout=120)
    assert run.returncode == 0, run.stderr
    assert len(_answers(db)) == (N_STIMULI + 1) * 3 * 3 == len(set(_answers(db)))


def test_a_read_only_folder_says_so(design: Path, tmpfs: Path) -> None:
    db = tmpfs / "r.sqlite"
    run = subprocess.run(_run_cmd(design, db), capture_output=True, text=True, env=_env(), timeout=120)
    assert run.returncode == 0, run.stderr
    subprocess.run(["mount", "-o", "remount,ro", str(tmpfs)], check=True)
    for cmd in (_run_cmd(design, db, pid="P2"), _run_cmd(design, tmpfs / "new.sqlite", pid="P2"),
                [*CLI, "export", str(db), "--csv", str(Path(tempfile.mkdtemp()) / "o.csv")]):
        run = subprocess.run(cmd, capture_output=True, text=True, env=_env(), timeout=120)
        assert run.returncode == 2, run.stderr
        line = _one_line_error(run.stderr)
        assert ("cannot write" in line or "read-only" in line.lower()) and "writable" in line, line


def test_a_read_only_file_says_so(design: Path, tmp_path: Path) -> None:
    db = tmp_path / "r.sqlite"
    run = subprocess.run(_run_cmd(design, db), capture_output=True, text=True, env=_env(), timeout=120)
    assert run.returncode == 0, run.stderr
    # a read-only bind mount of the one file (root ignores permission bits, not a read-only mount)
    if subprocess.run(["mount", "--bind", str(db), str(db)], capture_output=True).returncode != 0:
        pytest.skip("bind-mounting a file needs root")
    try:
        subprocess.run(["mount", "-o", "remount,ro,bind", str(db)], check=True)
        run = subprocess.run(_run_cmd(design, db, pid="P2"), capture_output=True, text=True, env=_env(), timeout=120)
        line = _one_line_error(run.stderr)
        assert run.returncode == 2 and "read-only" in line and "writable" in line, line
        # reading it still works: the export needs no write
        run = subprocess.run([*CLI, "export", str(db), "--csv", str(tmp_path / "o.csv")], capture_output=True,
                             text=True, env=_env(), timeout=120)
        assert run.returncode == 0, run.stderr
    finally:
        subprocess.run(["umount", str(db)], check=False)
    assert len(_answers(db)) == (N_STIMULI + 1) * 3 * 3


def test_a_lock_held_too_long_mid_session_says_so(tmp_path: Path, monkeypatch) -> None:
    """Another process holds the write lock after the session has started: the wait ends in one line, the
    answer can be given again once the lock is gone, and nothing is lost."""
    from studyapp.errors import InputError
    from studyapp.study.storage import Response, TrialRecord, now_iso

    def trial(k: int) -> TrialRecord:
        return TrialRecord(participant="P1", trial_index=k, stimulus=f"s{k}", is_practice=False,
                           is_attention_check=False, slots=("a", "b", "c"), answered_at=now_iso())

    ranks = [Response("realism", c, i, i + 1) for i, c in enumerate("abc")]
    monkeypatch.setattr(ResultsDB, "LOCK_TIMEOUT_S", 0.5)
    db = ResultsDB(tmp_path / "r.sqlite", design_hash="h", title="T")
    db.add_participant("P1", n_rows=1)
    db.save_trial(trial(0), ranks)
    holder = subprocess.Popen([sys.executable, "-c", "import sqlite3, sys, time\n"
                               "con = sqlite3.connect(sys.argv[1], isolation_level=None)\n"
                               "con.execute('BEGIN IMMEDIATE'); print('locked', flush=True); time.sleep(60)",
                               str(db.path)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(InputError) as err:
            db.save_trial(trial(1), ranks)
    finally:
        holder.kill()
        holder.wait()
        holder.stdout.close()
    line = str(err.value)
    assert "in use by another program" in line and "was not saved" in line and "damaged" not in line, line
    db.save_trial(trial(1), ranks)  # the lock is gone: the same answer goes in
    assert db.answered_trials("P1") == {0, 1} and len(db.responses()) == 6
    db.close()
    ResultsDB(tmp_path / "r.sqlite", create=False).close()  # every row still matches its checksum


def test_two_participants_starting_at_once_on_a_new_database(design: Path, tmp_path: Path) -> None:
    """Two real processes create the same new database at the same moment, again and again (a new database
    each round): both sessions run and both are stored, never "damaged"."""
    rounds = int(os.environ.get("STUDYAPP_START_RACES", "20"))
    # Each process runs every round itself (paying for its imports once); a round starts when both have
    # said they are ready, so the two open the new file within a millisecond or so of each other.
    code = ("import sys, time\n"
            "from pathlib import Path\n"
            "from studyapp.study.design import load_design\n"
            "from studyapp.study.storage import ResultsDB\n"
            "from studyapp.bots.session_driver import run_bot_session\n"
            "design, folder, me, other = load_design(sys.argv[1]), Path(sys.argv[2]), sys.argv[3], sys.argv[4]\n"
            "for k in range(int(sys.argv[5])):\n"
            "    (folder / f'ready-{k}-{me}').touch()\n"
            "    give_up = time.time() + 60\n"
            "    while not (folder / f'ready-{k}-{other}').exists():\n"
            "        if time.time() > give_up: sys.exit(f'round {k}: the other process stopped')\n"
            "    with ResultsDB(folder / f'r{k}.sqlite', design) as db:\n"
            "        run_bot_session(design, db, me, 'random', k)\n")
    procs = [subprocess.Popen([sys.executable, "-c", code, str(design), str(tmp_path), me, other, str(rounds)],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
             for me, other in (("A", "B"), ("B", "A"))]
    results = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [err[-600:] for _, err in results]
    for k in range(rounds):
        with ResultsDB(tmp_path / f"r{k}.sqlite", create=False) as rdb:
            assert {p.id: p.status for p in rdb.participants()} == {"A": "done", "B": "done"}, k
            assert len(rdb.responses()) == 2 * (N_STIMULI + 1) * 3 * 3


def test_two_processes_upgrading_an_old_database_at_once(tmp_path: Path) -> None:
    """Two stations open a schema 3 database at the same moment: one upgrades it, the other uses the result."""
    base = tmp_path / "base.sqlite"
    with ResultsDB(base, design_hash="h", title="T") as db:
        db.add_participant("P1", n_rows=2)
    with sqlite3.connect(base) as con:  # what studyapp wrote before labels (4) and row checksums (5)
        con.execute("DROP TABLE row_checksums")
        con.execute("ALTER TABLE conditions DROP COLUMN label")
        con.execute("DROP TABLE criteria")  # added by 7
        for table in ("trial_slots", "judgements"):  # added by 6
            con.execute(f"DROP TABLE {table}")
        for column in ("block", "paradigm"):  # added by 6
            con.execute(f"ALTER TABLE trials DROP COLUMN {column}")
        con.execute("UPDATE schema_version SET version = 3")
    con.close()
    code = ("import sys, time\n"
            "from studyapp.study.storage import ResultsDB\n"
            "t = float(sys.argv[2])\n"
            "while time.time() < t: pass\n"
            "with ResultsDB(sys.argv[1], design_hash='h') as db: db.add_participant(sys.argv[3], n_rows=2)\n")
    for k in range(int(os.environ.get("STUDYAPP_START_RACES", "8"))):
        db = tmp_path / f"r{k}.sqlite"
        db.write_bytes(base.read_bytes())
        start = time.time() + 1.0
        procs = [subprocess.Popen([sys.executable, "-c", code, str(db), str(start), pid], stderr=subprocess.PIPE,
                                  text=True, env=_env()) for pid in ("A", "B")]
        results = [(p.wait(timeout=120), p.stderr.read()) for p in procs]
        for p in procs:
            p.stderr.close()
        assert [rc for rc, _ in results] == [0, 0], (k, [e[-300:] for _, e in results])
        with ResultsDB(db, create=False) as rdb:
            assert sorted(p.id for p in rdb.participants()) == ["A", "B", "P1"]
