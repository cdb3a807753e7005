"""Several server processes on one PostgreSQL database: two real ``studyapp serve`` processes (two ports, one
database, one secret) and a participant whose consecutive requests alternate between them. Every rule holds
(watch once before answering, a too-short play does not count, no going back, a reload and a SIGKILLed and
restarted server resume where the participant was) and every answer is stored exactly once; ``--workers``
runs on PostgreSQL and is refused, in one line, on SQLite. A participant begun at a lab station, whose latest
session is not a browser one, still gets the browser's own session with "welcome back" first."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path
from typing import Any

import httpx
import pytest

from fixtures.synthetic import write_synthetic_study
from fixtures.web_serve import free_port
from studyapp.study.storage import open_results

ROOT = Path(__file__).resolve().parents[2]
CODE = "MULTI123"
#: The stand-in clip length is 1 s and the server allows 0.5 s of slack: a play reported after this long counts.
WATCHED_S = 0.7


def _state(text: str) -> dict[str, Any]:
    return json.loads(re.search(r'type="application/json">(.*?)</script>', text, re.S).group(1))


class Serve:
    """``studyapp serve`` in a process of its own."""

    def __init__(self, design: Path, db: str, *extra: str) -> None:
        self.port = free_port()
        self.args = [sys.executable, "-m", "studyapp.cli", "serve", str(design), "--db", db, "--port", str(self.port),
                     "--size", "64x48", "--fps", "5", *extra]
        self.log = design.with_name(f"serve-{self.port}.log")
        self.proc: subprocess.Popen | None = None

    def start(self) -> "Serve":
        with open(self.log, "ab") as log:
            self.proc = subprocess.Popen(self.args, env={**os.environ, "PYTHONPATH": str(ROOT)}, stdout=log,
                                         stderr=subprocess.STDOUT)
        give_up = time.monotonic() + 120
        while True:
            assert self.proc.poll() is None, self.log.read_text()[-3000:]
            try:
                httpx.get(f"http://127.0.0.1:{self.port}/a/app.css", timeout=1)
                return self
            except httpx.TransportError:
                assert time.monotonic() < give_up, "the server did not start"
                time.sleep(0.2)

    def kill(self) -> None:
        assert self.proc is not None
        os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.wait(10)

    def stop(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)


class Alternating:
    """One participant whose every request goes to the other server than the one before."""

    def __init__(self, ports: list[int]) -> None:
        self.clients = [httpx.Client(base_url=f"http://127.0.0.1:{p}", timeout=30) for p in ports]
        self.turn = 0
        self.base = ""
        self.csrf = ""
        self.state: dict[str, Any] = {}
        self.served: list[int] = []

    def _next(self) -> httpx.Client:
        self.served.append(self.turn)
        client = self.clients[self.turn]
        self.turn = 1 - self.turn
        return client

    def get(self, url: str) -> httpx.Response:
        return self._next().get(url)

    def page(self) -> dict[str, Any]:
        r = self.get(self.base)
        assert r.status_code == 200, r.text[:300]
        self.state = _state(r.text)
        self.csrf = self.state.get("csrf", self.csrf)
        return self.state

    def act(self, action: str, body: dict | None = None, expect: int = 200) -> httpx.Response:
        r = self._next().post(self.base + action, json=body or {}, headers={"X-CSRF-Token": self.csrf})
        assert r.status_code == expect, (action, r.status_code, r.text[:300])
        if r.status_code == 200:
            self.state = r.json()
            self.csrf = self.state.get("csrf", self.csrf)
        return r

    def close(self) -> None:
        for c in self.clients:
            c.close()


@pytest.fixture(scope="module")
def multi_study(tmp_path_factory) -> Path:
    path = write_synthetic_study(tmp_path_factory.mktemp("multi") / "study", n_stimuli=3, seconds=1.0,
                                 practice=False, questionnaire=True, name="multi")
    path.write_text(path.read_text() + f'\n[online]\ncompletion_code = "{CODE}"\n')
    return path


def _ranks(criteria: list[dict[str, Any]]) -> dict[str, dict[str, int]]:
    return {c["id"]: {"0": 1, "1": 2, "2": 3} for c in criteria}


def test_a_participant_alternating_between_two_server_processes_keeps_every_rule(multi_study, postgres_server) -> None:
    url = postgres_server.new_database(f"multi_{uuid.uuid4().hex[:12]}")
    a = Serve(multi_study, url).start()             # renders the videos; the second finds them there
    b = Serve(multi_study, url).start()
    p = Alternating([a.port, b.port])
    try:
        r = p.get("/?PROLIFIC_PID=alt01&STUDY_ID=s1&SESSION_ID=x1")                        # A
        entry = _state(r.text)
        go = p._next().post("/start", json={"nonce": entry["nonce"], "csrf": entry["entry_csrf"], "consent": True,
                                            "params": entry["params"]})                      # B
        assert go.status_code == 200, go.text
        p.base = go.json()["go"]
        assert p.page()["screen"] == "instructions"                                           # A
        p.act("continue")                                                                     # B
        assert p.state["screen"] == "soundcheck"
        p.act("sound", {"user_agent": "test", "screen_w": 800, "screen_h": 600})              # A
        assert p.state["screen"] == "trial" and p.state["progress"] == "Clip 1 of 3"

        answered_pages: list[dict[str, Any]] = []
        for k in (1, 2, 3):
            trial = p.state
            ranks = _ranks(trial["criteria"])
            # must watch once: no answer before a play, nor after a play reported too soon
            p.act("answer", {"ranks": ranks}, expect=422)
            video = p.get(trial["video"])
            assert video.status_code == 200 and video.content[4:8] == b"ftyp"
            p.act("play")
            ticket = p.state.get("play")
            p.act("ended", {"play": ticket})                     # at once: on the other process, too soon
            assert not p.state["can_rank"]
            p.act("answer", {"ranks": ranks}, expect=422)
            p.act("play")
            early = p.state.get("play")
            time.sleep(WATCHED_S)
            p.act("ended", {"play": ticket}, expect=400)          # the earlier play's ticket is not this play's
            p.act("ended", {"play": early})
            assert p.state["can_rank"] and p.state["progress"] == f"Clip {k} of 3"
            if k == 2:
                # a reload, then the server that served the last request is killed and started again:
                # the participant continues where they were on either process, the clip still watched
                assert p.page()["can_rank"]
                victim = [a, b][1 - p.turn]
                victim.kill()
                victim.start()
                p.close()      # no kept-alive connection to the killed process
                p.clients = [httpx.Client(base_url=f"http://127.0.0.1:{s.port}", timeout=30) for s in (a, b)]
                for _ in range(2):
                    page = p.page()
                    assert page["screen"] == "trial" and page["progress"] == "Clip 2 of 3" and page["can_rank"]
            p.act("answer", {"ranks": ranks})
            answered_pages.append(trial)
            # no going back: the answered clip's video is gone, and its answer cannot be given again
            assert p.get(trial["video"]).status_code == 404
            if k < 3:
                assert p.state["progress"] == f"Clip {k + 1} of 3"
                p.act("answer", {"ranks": ranks}, expect=422)     # lands on the next clip, not yet watched
        assert p.state["screen"] == "questionnaire"
        p.act("questionnaire", {"answers": {"q1": 6, "q2": 5, "comments": "two servers"}})
        assert p.state["screen"] == "done" and CODE in p.state["code"]
        assert p.page()["screen"] == "done"
        refused = p.get("/?PROLIFIC_PID=alt01")
        assert refused.status_code == 403
        assert p.served.count(0) > 10 and p.served.count(1) > 10
    finally:
        p.close()
        a.stop()
        b.stop()

    db = open_results(url)
    try:
        assert db.participant("alt01").status == "done"
        assert [t["trial_index"] for t in db.trials("alt01")] == [0, 1, 2]
        n_crit = len(answered_pages[0]["criteria"])
        rows = db.responses("alt01")
        assert len(rows) == 3 * 3 * n_crit
        assert len({(r["trial_index"], r["criterion"], r["slot"]) for r in rows}) == len(rows)
        plays = db.plays("alt01")
        # per clip: one play reported too soon, one watched; every play closed, none lost or doubled
        assert [(p_["trial_index"], p_["completed"]) for p_ in plays] == [(t, c) for t in (0, 1, 2) for c in (0, 1)]
        assert all(p_["ended"] is not None for p_ in plays)
        assert [t["plays"] for t in db.trials("alt01")] == [2, 2, 2]
        sessions = db.sessions("alt01")
        assert len(sessions) == 1 and sessions[0]["ended"] is not None
        assert sessions[0]["machine"]["prolific_study_id"] == "s1"
        assert {q["item"] for q in db.questionnaire("alt01")} == {"q1", "q2", "comments"}
    finally:
        db.close()


def test_workers_need_postgresql_and_serve_a_participant_on_it(multi_study, postgres_server, tmp_path) -> None:
    sqlite = subprocess.run([sys.executable, "-m", "studyapp.cli", "serve", str(multi_study), "--workers", "2",
                             "--db", str(tmp_path / "r.sqlite")], env={**os.environ, "PYTHONPATH": str(ROOT)},
                            capture_output=True, text=True, timeout=120)
    assert sqlite.returncode != 0 and "Traceback" not in sqlite.stderr
    lines = [ln for ln in sqlite.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "--workers" in lines[0] and "PostgreSQL" in lines[0], sqlite.stderr
    assert not (tmp_path / "r.sqlite").exists()

    url = postgres_server.new_database(f"workers_{uuid.uuid4().hex[:12]}")
    server = Serve(multi_study, url, "--workers", "2").start()
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{server.port}", timeout=30) as c:
            entry = _state(c.get("/?PROLIFIC_PID=w01").text)
            go = c.post("/start", json={"nonce": entry["nonce"], "csrf": entry["entry_csrf"], "consent": True,
                                        "params": entry["params"]}).json()["go"]
            csrf = _state(c.get(go).text)["csrf"]
            c.post(go + "continue", json={}, headers={"X-CSRF-Token": csrf})
            trial = c.post(go + "sound", json={}, headers={"X-CSRF-Token": csrf}).json()
            assert trial["screen"] == "trial" and c.get(trial["video"]).status_code == 200
        children = subprocess.run(["pgrep", "-P", str(server.proc.pid)], capture_output=True, text=True).stdout.split()
        assert len(children) >= 2, server.log.read_text()[-2000:]     # uvicorn's two worker processes
    finally:
        server.stop()
    db = open_results(url)
    try:
        assert [s["machine"]["frontend"] for s in db.sessions("w01")] == ["browser"]
    finally:
        db.close()


def test_a_participant_begun_at_a_lab_station_gets_welcome_back_in_the_browser(study, browser_for) -> None:
    """The latest session is not an open browser one: the browser starts its own, "welcome back" first, and a
    clip played but left unanswered at the station must be watched again."""
    import warnings

    from studyapp.study.session import Session

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from starlette.testclient import TestClient

    db = study.db()
    lab = Session(study.design, db, "LAB7")
    lab.accept_consent()
    lab.finish_instructions()
    lab.record_env_check({"gl_renderer": "station"})
    lab.record_play_started()
    lab.record_play_finished(True)
    lab.submit_ranking({c.id: {0: 1, 1: 2, 2: 3} for c in study.design.criteria})   # the practice clip
    lab.record_play_started()
    lab.record_play_finished(True)                                                    # clip 1 watched, not answered
    lab.close()
    db.close()
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        r = b.get("/?PROLIFIC_PID=LAB7")
        assert r.status_code == 200 and "/s/" in str(r.url)
        b.base = str(r.url)[len(str(client.base_url)):]
        page = b.reload()
        assert page["screen"] == "back" and "clip 1 of 3" in page["lines"][0] and "not saved" in page["lines"][1]
        b.act("continue")
        assert b.state["screen"] == "trial" and b.state["progress"] == "Clip 1 of 3" and not b.state["can_rank"]
        b.watch()
        b.answer_well()
        assert b.reload()["progress"] == "Clip 2 of 3"
    db = study.db()
    sessions = db.sessions("LAB7")
    assert len(sessions) == 2 and sessions[1]["machine"]["frontend"] == "browser" and sessions[1]["machine"]["resumed_at"]
    assert sorted(db.answered_trials("LAB7")) == [0, 1]
    db.close()
