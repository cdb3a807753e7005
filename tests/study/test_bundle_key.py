"""The bundle's key: kept in the lab database only, exported on request, and never orphaned by a kill.

The kill tests run ``make_bundle`` in a real subprocess that SIGKILLs itself at chosen moments (inside the
zip writing, before and after the key is recorded, before and after the zip is linked into place), and
at timed moments of a real ``studyapp bundle`` command; after every kill the output folder holds nothing
but a finished zip or nothing at all, and the database's keys match the zip that exists.
"""
from __future__ import annotations

import json
import os
import signal
import stat
import subprocess
import sys
import textwrap
import time
import zipfile
from pathlib import Path

import pytest

from studyapp.errors import InputError
from studyapp.study.bundle import export_key, make_bundle, settle_pending_keys
from studyapp.study.design import load_design
from studyapp.study.storage import ResultsDB
from fixtures.synthetic import write_synthetic_study

CLI = [sys.executable, "-m", "studyapp.cli"]


def _keys(results: Path, design_path: Path) -> dict[str, dict]:
    db = ResultsDB(results, load_design(design_path, check_files=False))
    try:
        return db.bundle_keys()
    finally:
        db.close()


def test_key_is_kept_in_the_database_and_exported_only_on_request(tmp_path: Path) -> None:
    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=3)
    results = tmp_path / "lab.sqlite"
    send = tmp_path / "send"
    info = make_bundle(design_path, send / "study.zip", participants=2, results=results)
    assert sorted(p.name for p in send.iterdir()) == ["study.zip"]  # nothing beside the zip
    assert info.key_path is None
    stored = _keys(results, design_path)
    assert list(stored) == [info.bundle_hash] and "pending" not in stored[info.bundle_hash]
    assert stored[info.bundle_hash]["roster"] == info.roster == {"R01": 0, "R02": 1}

    # on request: from `bundle --export-key`, or later from the database by the zip or a hash prefix
    again = make_bundle(design_path, send / "study2.zip", participants=1, results=results,
                        export_key=tmp_path / "private" / "k.json")
    assert again.key_path == tmp_path / "private" / "k.json"
    assert json.loads(again.key_path.read_text())["bundle_hash"] == again.bundle_hash
    assert stat.S_IMODE(again.key_path.stat().st_mode) == 0o600
    by_zip = export_key(results, send / "study.zip", tmp_path / "private" / "first.json")
    assert json.loads(by_zip.read_text()) == stored[info.bundle_hash]
    by_hash = export_key(results, again.bundle_hash[:10], tmp_path / "private" / "second.json")
    assert json.loads(by_hash.read_text())["roster"] == again.roster
    with pytest.raises(InputError, match="no bundle key matches 'ffff'.*keys kept here"):
        export_key(results, "ffff", tmp_path / "private" / "none.json")
    assert sorted(p.name for p in send.iterdir()) == ["study.zip", "study2.zip"]


def test_key_command_and_merge_with_the_exported_key(tmp_path: Path) -> None:
    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=2, practice=False)
    with design_path.open("a") as fh:  # the seed matters only to random draws
        fh.write('\n[slots]\nassignment = "random"\n')
    results = tmp_path / "lab.sqlite"
    out = subprocess.run([*CLI, "bundle", str(design_path), "-o", str(tmp_path / "s.zip"), "--participants", "1",
                          "--results", str(results)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "kept in" in out.stdout and "not written next to the zip" in out.stdout
    assert "the design's seed is small" in out.stdout  # the synthetic study's seed is 7
    assert not list(tmp_path.glob("*.json"))
    key = subprocess.run([*CLI, "key", str(results), str(tmp_path / "s.zip"), "-o", str(tmp_path / "k.json")],
                         capture_output=True, text=True, timeout=300)
    assert key.returncode == 0, key.stderr
    assert json.loads((tmp_path / "k.json").read_text())["roster"] == {"R01": 0}
    bad = subprocess.run([*CLI, "key", str(results), "0000", "-o", str(tmp_path / "x.json")],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "no bundle key matches" in bad.stderr and "Traceback" not in bad.stderr


def test_bundle_says_when_the_seed_is_small_enough_to_guess(tmp_path: Path) -> None:
    """Only random ordering or slots draw from the seed; balanced ones are arithmetic of the row, which the
    bundle ships (the README says what that allows), so a small seed is noted only with random draws."""
    def study(name: str, seed: int, random_slots: bool) -> Path:
        path = write_synthetic_study(tmp_path / name, n_stimuli=2, practice=False, seed=seed)
        if random_slots:
            with path.open("a") as fh:
                fh.write('\n[slots]\nassignment = "random"\n')
        return path

    def small(path: Path) -> bool:
        return make_bundle(path, path.with_suffix(".zip"), participants=1,
                           results=path.with_suffix(".sqlite")).small_seed

    assert small(study("small", 2026, random_slots=True))
    assert not small(study("large", 2 ** 61 + 12345, random_slots=True))
    assert not small(study("balanced", 2026, random_slots=False))


def test_balanced_slots_follow_from_the_shipped_row_alone(tmp_path: Path) -> None:
    """The limit the README states: with balanced ordering and slots, the design position in each slot of a
    remote participant's trials is public arithmetic of the row in schedule.json, whatever the seed."""
    import zipfile

    from studyapp.study.design import load_design
    from studyapp.study.schedule import participant_schedule

    path = write_synthetic_study(tmp_path / "s", n_stimuli=3, practice=False, seed=2 ** 61 + 5)
    info = make_bundle(path, tmp_path / "s.zip", participants=2, results=tmp_path / "s.sqlite")
    with zipfile.ZipFile(info.path) as z:
        shipped = json.loads(next(z.read(n) for n in z.namelist() if n.endswith("schedule.json")))
    design = load_design(path)
    other = load_design(write_synthetic_study(tmp_path / "t", n_stimuli=3, practice=False, seed=3))
    for pid, entry in shipped.items() if "R01" in shipped else shipped["participants"].items():
        row = entry["row"]
        real = [p.slots for p in participant_schedule(design, pid, row)]
        assert [p.slots for p in participant_schedule(other, pid, row)] == real  # the seed plays no part


def test_merge_on_another_machine_with_the_exported_key(tmp_path: Path) -> None:
    from fixtures.bundles import remote_run
    from studyapp.study.bundle import merge_results
    from studyapp.study.export import export_dataframe

    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=2, seconds=0.3, practice=False)
    info = make_bundle(design_path, tmp_path / "s.zip", participants=1, results=tmp_path / "lab.sqlite",
                       export_key=tmp_path / "private" / "k.json")
    (tmp_path / "pc").mkdir()
    returned = remote_run(info.path, tmp_path / "pc", "R01", pace_s=0.3)
    elsewhere = tmp_path / "elsewhere" / "lab.sqlite"
    elsewhere.parent.mkdir()
    ResultsDB(elsewhere, load_design(design_path)).close()  # a database that never saw the bundle
    refused = merge_results(elsewhere, [returned], design=design_path)
    assert not refused[0].ok and "--key" in refused[0].message
    merged = merge_results(elsewhere, [returned], design=design_path, key_file=tmp_path / "private" / "k.json")
    assert merged[0].ok, merged[0].problems
    assert set(export_dataframe(elsewhere)["condition"]) == {"synced", "lagged", "static"}


# ------------------------------------------------------------------------------------------ kills
_KILLER = textwrap.dedent("""
    import os, signal, sys, zipfile
    from studyapp.study import bundle
    from studyapp.study.storage import ResultsDB

    point, design, out, results = sys.argv[1:5]
    calls = {"writestr": 0, "add_key": 0}

    def die():
        os.kill(os.getpid(), signal.SIGKILL)

    real_writestr = zipfile.ZipFile.writestr
    def writestr(self, *a, **k):
        calls["writestr"] += 1
        if point == "mid-zip" and calls["writestr"] == 3:
            die()
        return real_writestr(self, *a, **k)
    zipfile.ZipFile.writestr = writestr

    real_add = ResultsDB.add_bundle_key
    def add_key(self, h, key):
        calls["add_key"] += 1
        if point == "before-pending" and calls["add_key"] == 1:
            die()
        real_add(self, h, key)
        if point == "after-pending" and calls["add_key"] == 1:
            die()
        if point == "after-complete" and calls["add_key"] == 2:
            die()
    ResultsDB.add_bundle_key = add_key

    real_link = os.link
    def link(src, dst, *a, **k):
        if point == "before-link":
            die()
        real_link(src, dst, *a, **k)
        if point == "after-link":
            die()
    os.link = link
    real_replace = os.replace
    def replace(src, dst, *a, **k):  # the named fallback where anonymous files are not available
        if point == "before-link" and str(dst).endswith(".zip"):
            die()
        real_replace(src, dst, *a, **k)
        if point == "after-link" and str(dst).endswith(".zip"):
            die()
    os.replace = replace

    bundle.make_bundle(design, out, participants=2, results=results, salt="kill-salt")
    print("finished")
""")

POINTS = ["mid-zip", "before-pending", "after-pending", "before-link", "after-link", "after-complete", "none"]


def _check_after_kill(send: Path, results: Path, design_path: Path) -> dict[str, str]:
    """The folder holds finished zips only; the database keeps exactly their keys. Returns zip name -> hash."""
    left = sorted(p.name for p in send.iterdir()) if send.exists() else []
    assert all(n.endswith(".zip") and not n.startswith(".") for n in left), left  # no .part, temp or key file
    hashes = {}
    for name in left:
        with zipfile.ZipFile(send / name) as zf:
            assert zf.testzip() is None
            hashes[name] = json.loads(zf.read("manifest.json"))["design_hash"]
    if results.exists():
        db = ResultsDB(results, load_design(design_path, check_files=False))
        try:
            settle_pending_keys(db)
            keys = db.bundle_keys()
        finally:
            db.close()
    else:
        keys = {}
    # a zip never lacks its key, and a key is never left for a zip that does not exist
    assert set(keys) == set(hashes.values()), (left, sorted(keys))
    assert all("pending" not in k for k in keys.values())
    return hashes


@pytest.mark.skipif(os.name != "posix", reason="SIGKILL is POSIX")
@pytest.mark.parametrize("point", POINTS)
def test_bundle_killed_at_each_step_leaves_the_zip_with_its_key_or_nothing(point: str, tmp_path: Path) -> None:
    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=3)
    send, results = tmp_path / "send", tmp_path / "lab.sqlite"
    send.mkdir()
    proc = subprocess.run([sys.executable, "-c", _KILLER, point, str(design_path), str(send / "study.zip"),
                           str(results)], capture_output=True, text=True, timeout=300)
    if point == "none":
        assert proc.returncode == 0 and "finished" in proc.stdout, proc.stderr
    else:
        assert proc.returncode == -signal.SIGKILL, (proc.returncode, proc.stderr)
    made = _check_after_kill(send, results, design_path)
    assert bool(made) == (point in ("after-link", "after-complete", "none")), point
    # bundling again works, and a bundle that never existed handed out no ids: R01, R02 again
    info = make_bundle(design_path, send / "again.zip", participants=2, results=results, salt="kill-salt")
    assert _check_after_kill(send, results, design_path) == {**made, "again.zip": info.bundle_hash}
    expected = ["R03", "R04"] if made else ["R01", "R02"]
    assert list(info.roster) == expected, point


@pytest.mark.skipif(os.name != "posix", reason="SIGKILL is POSIX")
def test_bundle_command_killed_at_timed_moments(tmp_path: Path) -> None:
    """A real `studyapp bundle` killed after growing delays: every outcome is the zip with its key, or nothing."""
    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=6)
    cmd = [*CLI, "bundle", str(design_path), "--participants", "1"]
    t0 = time.monotonic()
    full = subprocess.run([*cmd, "-o", str(tmp_path / "full" / "study.zip"), "--results", str(tmp_path / "f.sqlite")],
                          capture_output=True, text=True, timeout=300)
    assert full.returncode == 0, full.stderr
    total = time.monotonic() - t0
    outcomes = set()
    for k, frac in enumerate((0.4, 0.7, 0.9, 1.0)):
        send, results = tmp_path / f"send{k}", tmp_path / f"lab{k}.sqlite"
        proc = subprocess.Popen([*cmd, "-o", str(send / "study.zip"), "--results", str(results)],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(total * frac)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
        outcomes.add(bool(_check_after_kill(send, results, design_path)))
    assert outcomes  # the checks above are what matters; which moments landed where varies with the machine
