"""Shared pieces of the study-server tests: a tiny browser study, an app on it with a test clock, a scripted
browser participant that keeps every response it received (for the blinding scans)."""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import pytest

from fixtures.web_study import ClipVideos, write_web_study
from studyapp.study.design import load_design
from studyapp.study.schedule import participant_schedule
from studyapp.study.storage import ResultsDB
from studyapp.web.app import build_app
from studyapp.web.flow import Flow
from studyapp.web.tokens import Tokens

SECRET = b"s" * 32


class Clock:
    """A settable clock for the server (seconds since the epoch)."""

    def __init__(self) -> None:
        import time

        self.now = time.time()

    def __call__(self) -> float:
        return self.now


@dataclass
class Study:
    path: Path
    design: Any
    db_path: Path
    videos: ClipVideos
    clock: Clock
    flows: list[Flow] = field(default_factory=list)

    def app(self, password: str | None = None, limits: dict | None = None) -> Any:
        def open_flow() -> Flow:
            flow = Flow(self.design, ResultsDB(self.db_path, self.design), Tokens(SECRET), self.videos, clock=self.clock)
            self.flows.append(flow)
            return flow

        return build_app(open_flow, password=password, limits=limits)

    def db(self) -> ResultsDB:
        return ResultsDB(self.db_path, self.design)


@pytest.fixture(scope="session")
def web_study_files(tmp_path_factory) -> tuple[Path, Any]:
    path = write_web_study(tmp_path_factory.mktemp("webstudy") / "study")
    return path, load_design(path)


@pytest.fixture
def study(web_study_files, tmp_path) -> Study:
    path, design = web_study_files
    return Study(path, design, tmp_path / "results.sqlite", ClipVideos(path.parent / "videos"), Clock())


def state_of(html: str) -> dict[str, Any]:
    m = re.search(r'<script id="state" type="application/json">(.*?)</script>', html, re.S)
    assert m, html[:300]
    return json.loads(m.group(1))


class Browser:
    """A scripted participant over a TestClient: every response is kept in ``seen`` (url, headers, body)."""

    def __init__(self, client: Any, study: Study) -> None:
        self.client = client
        self.study = study
        self.seen: list[tuple[str, dict[str, str], bytes]] = []
        self.state: dict[str, Any] = {}
        self.base = ""
        self.csrf = ""

    def _keep(self, r: Any) -> Any:
        self.seen.append((str(r.url), dict(r.headers), r.content))
        return r

    def get(self, url: str, **kw: Any) -> Any:
        return self._keep(self.client.get(url, **kw))

    def open(self, query: str = "") -> dict[str, Any]:
        r = self.get("/" + (f"?{query}" if query else ""))
        assert r.status_code == 200, r.text[:300]
        return self._set(state_of(r.text))

    def consent(self, agree: bool = True) -> Any:
        s = self.state
        r = self._keep(self.client.post("/start", json={"nonce": s["nonce"], "csrf": s["entry_csrf"], "consent": agree,
                                                        "params": s["params"]}))
        assert r.status_code == 200, r.text
        self.base = r.json()["go"]
        return self.reload()

    def reload(self) -> dict[str, Any]:
        r = self.get(self.base)
        assert r.status_code == 200, r.text[:300]
        return self._set(state_of(r.text))

    def act(self, action: str, body: dict | None = None, expect: int = 200) -> Any:
        r = self._keep(self.client.post(self.base + action, json=body or {}, headers={"X-CSRF-Token": self.csrf}))
        assert r.status_code == expect, r.text
        if r.status_code == 200:
            self._set(r.json())
        return r

    def _set(self, state: dict[str, Any]) -> dict[str, Any]:
        self.state = state
        self.csrf = state.get("csrf", self.csrf)
        return state

    def watch(self) -> None:
        """Fetch the trial's video, play it and report its end after its length passed on the server clock."""
        video = self.get(self.state["video"])
        assert video.status_code == 200 and video.headers["content-type"] == "video/mp4"
        self.act("play")
        self.study.clock.now += 1.0
        self.act("ended")
        assert self.state["can_rank"]

    def plan(self) -> Any:
        """The current trial's plan, as the experimenter knows it (from the schedule, never from the page)."""
        db = self.study.db()
        try:
            pid = next(p.id for p in db.participants() if self.base.endswith(f"/s/{self.study.flows[-1].tokens.session(p.id)}/"))
            rec = db.participant(pid)
            answered = db.answered_trials(pid)
        finally:
            db.close()
        plans = participant_schedule(self.study.design, pid, rec.latin_row)
        return next(p for p in plans if p.trial_index not in answered)

    def answer_well(self) -> Any:
        """Rank so that attention checks pass: the check's known-worst condition last on every question."""
        plan = self.plan()
        worst = self.study.design.attention_checks[0].expected["condition"]
        order = sorted(range(3), key=lambda s: plan.slots[s] == worst)   # worst slot ranked 3
        ranks = {c.id: {str(s): order.index(s) + 1 for s in range(3)} for c in self.study.design.criteria}
        return self.act("answer", {"ranks": ranks})

    def answer_badly(self) -> Any:
        plan = self.plan()
        worst = self.study.design.attention_checks[0].expected["condition"]
        order = sorted(range(3), key=lambda s: plan.slots[s] != worst)   # worst slot ranked 1
        ranks = {c.id: {str(s): order.index(s) + 1 for s in range(3)} for c in self.study.design.criteria}
        return self.act("answer", {"ranks": ranks})

    def questionnaire(self) -> Any:
        return self.act("questionnaire", {"answers": {"q1": 6, "q2": 5, "comments": "fine", "device": "Laptop",
                                                      "langs": ["German", "English"], "age": "34"}})


@pytest.fixture
def browser_for() -> Callable[[Any, Study], Browser]:
    return Browser
