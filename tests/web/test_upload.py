"""Bundle participants upload their answers to a real study server process as they are committed
(:mod:`studyapp.study.upload`, :mod:`studyapp.web.uploads`): a participant killed mid-study and resumed, a server
down for part of a session, a tampered upload, and ``merge`` of the zip afterwards.

The participant is ``studyapp run STUDY.zip --no-render --bot careful`` in a process of its own, pacing each clip
for its length (the server checks the watching times, as ``merge`` does); the server is ``fixtures.web_serve``
(the app of ``studyapp serve``) on loopback, its database the one the bundle's key was kept in.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from fixtures.web_serve import ROOT, Server, free_port, read_db
from fixtures.web_study import secret_names, write_web_study
from studyapp.study.bundle import make_bundle, merge_results, open_bundle
from studyapp.study.upload import (HEADER_BUNDLE, HEADER_PARTICIPANT, HEADER_SIGNATURE, UPLOAD_PATH, signature,
                                   snapshot)

ALL_SENT = "All your answers reached the study server."


class Setup:
    def __init__(self, root: Path) -> None:
        self.root = root
        self.design = write_web_study(root / "study")
        self.lab = root / "lab.sqlite"
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.bundle = root / "bundle.zip"
        make_bundle(self.design, self.bundle, participants=4, results=self.lab, upload_url=self.url)
        self.server = Server(self.design, self.lab, self.port, root / "videos")
        self.env = {**os.environ, "PYTHONPATH": str(ROOT), "XDG_CACHE_HOME": str(root / "cache"),
                    "XDG_DATA_HOME": str(root / "data"), "STUDYAPP_RESULTS_DIR": str(root / "outbox")}

    def participant(self, pid: str, pace_s: float = 1.0) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, "-m", "studyapp.cli", "run", str(self.bundle), "--participant", pid,
                                 "--no-render", "--bot", "careful", "--bot-pace", str(pace_s),
                                 "--results", str(self.local(pid))],
                                env=self.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)

    def local(self, pid: str) -> Path:
        return self.root / pid / "remote.sqlite"

    def answers(self, db: Path, pid: str) -> list[tuple]:
        return read_db(db, "SELECT trial_index, answered_at FROM trials WHERE participant = ? ORDER BY trial_index", pid)


def state_of(setup: Setup, pid: str) -> dict:
    """What the participant's local database holds, as the uploads count it."""
    db = setup.local(pid)
    return {"trials": read_db(db, "SELECT COUNT(*) FROM trials")[0][0],
            "status": read_db(db, "SELECT status FROM participants")[0][0],
            "questionnaire": read_db(db, "SELECT COUNT(*) FROM questionnaire")[0][0]}


def wait_for(proc: subprocess.Popen, line: str) -> list[str]:
    """The participant's output up to and including ``line``."""
    seen = []
    for out in proc.stdout:
        seen.append(out.rstrip("\n"))
        if out.strip() == line:
            return seen
    raise AssertionError(f"the participant ended before {line!r}: {seen}")


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    s = Setup(tmp_path_factory.mktemp("upload"))
    yield s
    s.server.stop()


def test_a_participant_killed_mid_study_uploads_exactly_the_answers_after_resuming(setup) -> None:
    setup.server.start()
    first = setup.participant("R01")
    wait_for(first, "saved trial 1")
    os.kill(first.pid, signal.SIGKILL)
    first.wait(10)
    again = setup.participant("R01")
    out, _ = again.communicate(timeout=60)
    assert again.returncode == 0, out
    assert ALL_SENT in out and "Please send this file" not in out
    local = setup.answers(setup.local("R01"), "R01")
    assert len(local) >= 3
    assert setup.answers(setup.lab, "R01") == local            # every answer once, the same times
    status = read_db(setup.local("R01"), "SELECT status FROM participants")
    assert status[0][0] in ("done", "ended_early")
    assert read_db(setup.lab, "SELECT status FROM participants WHERE id = 'R01'") == status
    n = read_db(setup.local("R01"), "SELECT COUNT(*) FROM responses")
    assert read_db(setup.lab, "SELECT COUNT(*) FROM responses WHERE participant = 'R01'") == n
    acked = json.loads(setup.local("R01").with_name("remote.sqlite.uploaded.json").read_text())["R01"]["acknowledged"]
    assert acked == state_of(setup, "R01")
    # the real conditions are in the lab database (the key mapped the blinded tokens back)
    conds = {c for (c,) in read_db(setup.lab, "SELECT DISTINCT condition FROM responses WHERE participant = 'R01'")}
    assert conds == {"FaceCapGes", "DiffSHEG", "CaMN"}
    # the results zip (the fallback) merges as already merged
    zips = sorted((setup.root / "outbox").glob("results-*R01*.zip"))
    [report] = merge_results(setup.lab, zips, design=setup.design)
    assert report.ok and report.already, report.message


def test_answers_given_while_the_server_is_down_are_uploaded_when_it_comes_back(setup) -> None:
    setup.server.stop()
    proc = setup.participant("R03", pace_s=2.0)
    wait_for(proc, "saved trial 0")
    assert read_db(setup.lab, "SELECT COUNT(*) FROM trials WHERE participant = 'R03'") == [(0,)]
    setup.server.start()   # 1.5 s; the participant has at least 2 clips of 2 s to go
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0, out
    assert ALL_SENT in out
    assert setup.answers(setup.lab, "R03") == setup.answers(setup.local("R03"), "R03")
    assert len(setup.answers(setup.lab, "R03")) >= 3
    assert read_db(setup.lab, "SELECT status FROM participants WHERE id = 'R03'") == \
        read_db(setup.local("R03"), "SELECT status FROM participants")


def test_a_session_without_the_server_is_uploaded_by_the_next_run(setup) -> None:
    setup.server.stop()
    proc = setup.participant("R02")
    out, _ = proc.communicate(timeout=60)
    assert proc.returncode == 0, out
    assert "Not all your answers reached the study server" in out and "Please send this file" in out
    setup.server.start()
    again = setup.participant("R02")
    out, _ = again.communicate(timeout=60)
    assert "already finished this study. " + ALL_SENT in out, out
    assert again.returncode == 0
    assert setup.answers(setup.lab, "R02") == setup.answers(setup.local("R02"), "R02")
    assert len(setup.answers(setup.lab, "R02")) >= 3


def _post(setup, pid: str, body: bytes, sign_as: str | None = None, secret: str | None = None) -> tuple[int, dict]:
    opened = open_bundle(setup.bundle, cache=setup.root / "probe-cache")
    sig = signature(secret or opened.upload["secret"], opened.bundle_hash, sign_as or pid, body)
    req = urllib.request.Request(setup.url + UPLOAD_PATH, data=body, method="POST", headers={
        "content-type": "application/json", HEADER_BUNDLE: opened.bundle_hash, HEADER_PARTICIPANT: pid,
        HEADER_SIGNATURE: sig})
    try:
        with urllib.request.urlopen(req, timeout=10) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def _payload_of(setup, pid: str) -> dict:
    import sqlite3

    opened = open_bundle(setup.bundle, cache=setup.root / "probe-cache")
    con = sqlite3.connect(f"file:{setup.local(pid)}?mode=ro", uri=True)
    con.row_factory = sqlite3.Row
    try:
        return snapshot(con, opened.bundle_hash, opened.study, pid)
    finally:
        con.close()


def test_a_tampered_upload_is_refused_with_a_clear_message_and_naming_no_condition(setup) -> None:
    if setup.server.proc is None or setup.server.proc.poll() is not None:
        setup.server.start()
    assert setup.local("R01").exists(), "R01 answered in the first test"
    payload = _payload_of(setup, "R01")
    before = read_db(setup.lab, "SELECT * FROM responses WHERE participant = 'R01' ORDER BY trial_index, criterion, slot")
    # the same upload again: nothing to do
    status, reply = _post(setup, "R01", json.dumps({"payload": payload}).encode())
    assert status == 200 and reply == state_of(setup, "R01")
    # a different answer for a stored trial
    changed = json.loads(json.dumps(payload))
    r0 = [r for r in changed["responses"] if r["trial_index"] == 0]
    r0[0]["rank"], r0[1]["rank"] = r0[1]["rank"], r0[0]["rank"]
    status, reply = _post(setup, "R01", json.dumps({"payload": changed}).encode())
    assert status == 409 and "trial 0 already has a different answer" in reply["error"]
    # R01's answers under another roster id (R04 has answered nothing): the merge checks refuse them
    moved = json.loads(json.dumps(payload).replace('"R01"', '"R04"'))
    status, reply = _post(setup, "R04", json.dumps({"payload": moved}).encode())
    assert status == 422 and "problem" in reply["error"] and "nothing was stored" in reply["error"]
    replies = [reply]
    # a rank no session stores: the checks of merge come first
    bad = json.loads(json.dumps(payload))
    bad["responses"][0]["rank"] = 7.0
    status, reply = _post(setup, "R01", json.dumps({"payload": bad}).encode())
    assert status == 422 and reply["error"].startswith("1 problem in the answers")
    replies.append(reply)
    # a wrong secret, and a participant signed for another id
    status, reply = _post(setup, "R01", json.dumps({"payload": payload}).encode(), secret="0" * 64)
    assert status == 401 and "wrong signature" in reply["error"]
    status, reply2 = _post(setup, "R04", json.dumps({"payload": moved}).encode(), sign_as="R01")
    assert status == 401
    replies += [reply, reply2]
    assert not any(name in json.dumps(r) for r in replies for name in secret_names())
    log = setup.server.log.read_text()
    # the findings are for the experimenter's log
    assert "refused an upload of participant R04" in log and "are not a ranking" in log
    assert read_db(setup.lab, "SELECT * FROM responses WHERE participant = 'R01' ORDER BY trial_index, criterion, slot") == before
    assert read_db(setup.lab, "SELECT COUNT(*) FROM trials WHERE participant = 'R04'") == [(0,)]


def test_the_bundle_carries_the_server_address_and_a_secret_the_key_keeps(setup) -> None:
    import zipfile

    from studyapp.errors import InputError
    from studyapp.study.storage import ResultsDB
    from studyapp.study.upload import check_upload_url

    manifest = json.loads(zipfile.ZipFile(setup.bundle).read("manifest.json"))
    assert manifest["upload"]["url"] == setup.url and len(manifest["upload"]["secret"]) == 64
    with ResultsDB(setup.lab, create=False) as db:
        assert db.bundle_key(manifest["design_hash"])["upload_secret"] == manifest["upload"]["secret"]
    for bad in ("http://study.example.org", "ftp://127.0.0.1/", "https://", "study.example.org"):
        with pytest.raises(InputError, match="is not a study server address"):
            check_upload_url(bad)
