"""The browser participant's flow through the study server (Starlette's TestClient, a test clock): the same
Session and results database as the desktop, every answer committed before the next trial is sent, Prolific's
parameters recorded, reloads and restarts resume, finished participants refused, attention checks end the
session, abandoned participants free their row, and nothing a participant receives names a condition."""
from __future__ import annotations

import json
import warnings

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from starlette.testclient import TestClient

from fixtures.web_study import COMPLETION_CODE, ClipVideos, Clock, Study, secret_names
from studyapp.study.design import load_design
from studyapp.study.design.blinding import conditions_named_in
from studyapp.study.schedule import n_rows

PROLIFIC = "PROLIFIC_PID=5f0c0ffee0ddba11&STUDY_ID=study77&SESSION_ID=sess99"


def _to_first_trial(b, query: str = PROLIFIC) -> None:
    assert b.open(query)["screen"] == "welcome"
    assert b.consent()["screen"] == "instructions"
    b.act("continue")
    assert b.state["screen"] == "soundcheck"
    b.act("sound", {"user_agent": "Mozilla/5.0 test", "screen_w": 1920, "screen_h": 1080})
    assert b.state["screen"] == "trial"


def test_a_prolific_participant_completes_the_study(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        _to_first_trial(b)
        answered = 0
        while b.state["screen"] == "trial":
            b.watch()
            b.answer_well()
            answered += 1
            # the reply that shows the next page came after the answer was committed: a second connection sees it
            db = study.db()
            assert len(db.answered_trials("5f0c0ffee0ddba11")) == answered
            db.close()
        assert b.state["screen"] == "questionnaire"
        assert {i["kind"] for i in b.state["items"]} == {"likert", "choice", "number", "text"}
        b.questionnaire()
        assert b.state["screen"] == "done"
        assert COMPLETION_CODE in b.state["code"]
        assert b.state["redirect"] == f"https://app.prolific.com/submissions/complete?cc={COMPLETION_CODE}"
    db = study.db()
    rec = db.participant("5f0c0ffee0ddba11")
    assert rec.status == "done"
    assert answered == len(db.trials("5f0c0ffee0ddba11")) == 4   # practice, 2 clips, the attention check
    assert len(db.responses("5f0c0ffee0ddba11")) == 4 * 3 * len(study.design.criteria)
    # the design's criteria are recorded with the answers: the analysis names them by their labels
    assert [(c["id"], c["label"], c["question"]) for c in db.criteria()] == [
        (c.id, c.label, c.question) for c in study.design.criteria]
    machine = db.sessions("5f0c0ffee0ddba11")[0]["machine"]
    assert machine["frontend"] == "browser" and machine["prolific_study_id"] == "study77"
    assert machine["prolific_session_id"] == "sess99" and machine["prolific_prolific_pid"] == "5f0c0ffee0ddba11"
    assert machine["user_agent"] == "Mozilla/5.0 test" and machine["screen"] == "1920x1080"
    q = {r["item"]: r["value"] for r in db.questionnaire("5f0c0ffee0ddba11")}
    assert q == {"q1": "6", "q2": "5", "comments": "fine", "device": "Laptop", "langs": '["English", "German"]',
                 "age": "34"}
    assert all(t["plays"] == 1 and t["trial_duration_s"] == pytest.approx(1.0, abs=0.05)
               for t in db.trials("5f0c0ffee0ddba11"))
    db.close()


def test_nothing_a_participant_receives_names_a_condition(study, browser_for) -> None:
    names = secret_names()
    media: dict[str, set[str]] = {}
    with TestClient(study.app()) as client:
        for k in range(3):
            b = browser_for(client, study)
            _to_first_trial(b, f"PROLIFIC_PID=pp{k}&STUDY_ID=s&SESSION_ID=x{k}")
            while b.state["screen"] == "trial":
                media.setdefault(b.state["video"], set()).add(str(k))
                b.watch()
                b.answer_well()
            b.questionnaire()
            for asset in ("/a/app.js", "/a/app.css", "/a/tone.wav", "/a/dashboard.js"):
                b.get(asset)
            assert len(b.seen) > 20
            for url, headers, body in b.seen:
                text = " ".join([url, json.dumps(headers), body.decode("latin-1")])
                found = conditions_named_in(study.design, text)
                assert found == [], f"{url} names {found}"
                for name in names:   # and not even inside another word
                    assert name.lower() not in text.lower(), (url, name)
    # every video address belongs to one participant and one trial: nothing groups trials across participants
    assert all(len(who) == 1 for who in media.values()) and len(media) == 3 * 4


def test_the_clip_must_be_watched_to_its_end_before_ranking(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        _to_first_trial(b)
        ranks = {c.id: {"0": 1, "1": 2, "2": 3} for c in study.design.criteria}
        r = b.act("answer", {"ranks": ranks}, expect=422)
        assert "watch the clip to the end" in r.json()["error"]
        b.act("play")
        study.clock.now += 0.2          # the page says "ended" long before the clip could have played
        b.act("ended")
        assert not b.state["can_rank"]
        b.act("answer", {"ranks": ranks}, expect=422)
        b.act("play")
        study.clock.now += 0.9
        b.act("ended")
        assert b.state["can_rank"] and b.state["can_play"]     # replay allowed by the design
        b.act("answer", {"ranks": ranks})
        assert b.state["progress"] == "Clip 1 of 3"
    db = study.db()
    plays = db.plays("5f0c0ffee0ddba11")
    assert [p["completed"] for p in plays] == [0, 1] and db.trials("5f0c0ffee0ddba11")[0]["plays"] == 2
    db.close()


def test_a_reload_mid_trial_and_a_server_restart_resume_at_the_first_unanswered_trial(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        _to_first_trial(b)
        for _ in range(2):
            b.watch()
            b.answer_well()
        b.act("play")                      # the page is reloaded while the clip plays
        page = b.reload()
        assert page["screen"] == "trial" and page["progress"] == "Clip 2 of 3" and not page["can_rank"]
        assert page["can_play"]            # the reloaded page may play the clip again
        b.act("play")                      # the play left open by the reload is closed as not completed
        study.clock.now += 1.0
        b.act("ended")
        assert b.state["can_rank"]
        base = b.base
    # the server stops (its process ends) and starts again on the same database and secret: nothing of the
    # session was in its memory, so the participant continues where they were, the clip watched
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        b.base = base
        page = b.reload()
        assert page["screen"] == "trial" and page["progress"] == "Clip 2 of 3" and page["can_rank"]
        b.answer_well()
        assert b.state["progress"] == "Clip 3 of 3"
    db = study.db()
    assert sorted(db.answered_trials("5f0c0ffee0ddba11")) == [0, 1, 2]
    assert [p["completed"] for p in db.plays("5f0c0ffee0ddba11") if p["trial_index"] == 2] == [0, 1]
    assert len(db.sessions("5f0c0ffee0ddba11")) == 1 and db.trials("5f0c0ffee0ddba11")[2]["plays"] == 2
    db.close()


def test_a_request_reads_the_participant_s_record_once(study, browser_for, monkeypatch) -> None:
    """A page, a video and every action read the participant's record once, under the participant's lock:
    the session restored for the request gets that record rather than reading it again."""
    from studyapp.study.storage import ResultsDB

    reads: list[str] = []
    read = ResultsDB.participant

    def counted(self, participant_id):
        reads.append(participant_id)
        return read(self, participant_id)

    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        _to_first_trial(b)
        monkeypatch.setattr(ResultsDB, "participant", counted)
        for request in (b.reload, lambda: b.get(b.state["video"]), lambda: b.act("play"),
                        lambda: (setattr(study.clock, "now", study.clock.now + 1.0), b.act("ended"))):
            reads.clear()
            request()
            assert reads == ["5f0c0ffee0ddba11"], request
        assert b.state["can_rank"]
        monkeypatch.setattr(ResultsDB, "participant", read)
        b.answer_well()               # the answer went to the session restored with the record it was given
        assert b.state["progress"] == "Clip 1 of 3"
    db = study.db()
    assert len(db.answered_trials("5f0c0ffee0ddba11")) == 1
    db.close()


def test_a_finished_participant_cannot_start_again(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        _to_first_trial(b)
        while b.state["screen"] == "trial":
            b.watch()
            b.answer_well()
        b.questionnaire()
        assert b.reload()["screen"] == "done"          # reloading the last page still shows the code
        again = client.get(f"/?{PROLIFIC}")
        assert again.status_code == 403 and "cannot be taken again" in again.text
        start = client.post("/start", json={"nonce": b.state.get("nonce", "n"), "csrf": "x", "consent": True,
                                            "params": {"PROLIFIC_PID": "5f0c0ffee0ddba11"}})
        assert start.status_code == 400                # no valid entry token: refused before anything else
        fresh = browser_for(client, study)
        fresh.open("PROLIFIC_PID=someoneelse")
        s = fresh.state
        r = client.post("/start", json={"nonce": s["nonce"], "csrf": s["entry_csrf"], "consent": True,
                                        "params": {"PROLIFIC_PID": "5f0c0ffee0ddba11"}})
        assert r.status_code == 403 and "cannot be taken again" in r.json()["refused"]
    db = study.db()
    assert [p.id for p in db.participants()] == ["5f0c0ffee0ddba11"]
    db.close()


def test_the_same_prolific_id_coming_back_unfinished_continues(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        _to_first_trial(b)
        b.watch()
        b.answer_well()
        r = client.get(f"/?{PROLIFIC}", follow_redirects=False)
        assert r.status_code == 303 and r.headers["location"] == b.base


def test_a_failed_attention_check_ends_the_session(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        _to_first_trial(b)
        while b.state["screen"] == "trial":
            b.watch()
            if b.plan().is_attention_check:
                b.answer_badly()
                break
            b.answer_well()
        assert b.state["screen"] == "ended" and "check questions" in b.state["text"]
        assert b.reload()["screen"] == "ended"
        b.act("play")                                  # nothing more can be done
        assert b.state["screen"] == "ended"
    db = study.db()
    assert db.participant("5f0c0ffee0ddba11").status == "ended_early"
    assert db.attention_failures("5f0c0ffee0ddba11") == 1
    db.close()


def test_declining_records_it_and_takes_no_row(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        b.open("PROLIFIC_PID=decliner")
        assert b.consent(agree=False)["screen"] == "declined"
        c = browser_for(client, study)
        c.open("PROLIFIC_PID=second")
        c.consent()
    db = study.db()
    assert db.participant("decliner").status == "ended_early" and db.trials("decliner") == []
    assert db.participant("decliner").latin_row == db.participant("second").latin_row == 0
    db.close()


def test_an_abandoned_participant_frees_their_row(study, browser_for) -> None:
    rows = n_rows(study.design)
    with TestClient(study.app()) as client:
        first = browser_for(client, study)
        _to_first_trial(first, "PROLIFIC_PID=leaver")
        first.watch()
        first.answer_well()
        lab = study.db()                               # a lab station on the same database: its participant
        lab.add_participant("LAB01", rows)             # is never taken as abandoned
        lab.start_session("LAB01", {"app_version": "x"})
        lab.close()
        study.clock.now += 119 * 60                    # within the design's 120 minutes: still holds row 0
        second = browser_for(client, study)
        _to_first_trial(second, "PROLIFIC_PID=second")
        study.clock.now += 2 * 60 + 1                  # the leaver's last activity is now over 120 minutes ago
        third = browser_for(client, study)
        _to_first_trial(third, "PROLIFIC_PID=third")
        back = client.get("/?PROLIFIC_PID=leaver")
        assert back.status_code == 403 and "left unfinished for too long" in back.text
        assert first.reload()["screen"] == "ended" and "too long" in first.state["text"]
    db = study.db()
    rec = {p.id: p for p in db.participants()}
    assert rec["leaver"].status == "ended_early" and len(db.trials("leaver")) == 1     # the answer is kept
    assert rec["LAB01"].status == "active" and rec["second"].status == "active"
    assert (rec["leaver"].latin_row, rec["LAB01"].latin_row, rec["second"].latin_row) == (0, 1, 2)
    assert rec["third"].latin_row == 0                  # the abandoned row, given out again
    machine = db.sessions("leaver")[-1]["machine"]
    assert "abandoned_at" in machine and machine["abandon_after_min"] == 120.0
    assert db.row_counts(rows)[:3] == [1, 1, 1]
    db.close()


def test_invalid_answers_are_refused_and_nothing_is_stored(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        _to_first_trial(b)
        b.watch()
        crit = [c.id for c in study.design.criteria]
        for bad, code in (({"ranks": []}, 400), ({"ranks": {crit[0]: [1, 2, 3]}}, 400),
                          ({"ranks": {c: {"0": 1, "1": 1, "2": 3} for c in crit}}, 422),   # ties not allowed
                          ({"ranks": {c: {"0": 1, "1": 2, "2": 4} for c in crit}}, 422),
                          ({"ranks": {c: {"0": 1, "1": 2} for c in crit}}, 422),
                          ({"ranks": {**{c: {"0": 1, "1": 2, "2": 3} for c in crit}, "x": {"0": 1}}}, 422),
                          ({"ranks": {c: {"0": 1, "1": 2, "2": 3} for c in crit[:-1]}}, 422)):
            b.act("answer", bad, expect=code)
        r = client.post(b.base + "answer", content=b'{"ranks": NaN}',
                        headers={"X-CSRF-Token": b.csrf, "content-type": "application/json"})
        assert r.status_code == 400
        r = client.post(b.base + "answer", content=b"x" * 70_000,
                        headers={"X-CSRF-Token": b.csrf, "content-type": "application/json"})
        assert r.status_code == 400
        b.act("nonsense", {}, expect=400)
        b.act("questionnaire", {"answers": {}}, expect=400)   # not in that state: refused, nothing stored
    db = study.db()
    assert db.trials("5f0c0ffee0ddba11") == [] and db.questionnaire("5f0c0ffee0ddba11") == []
    db.close()


def test_questionnaire_answers_are_checked_per_kind(study, browser_for) -> None:
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        _to_first_trial(b)
        while b.state["screen"] == "trial":
            b.watch()
            b.answer_well()
        good = {"q1": 6, "q2": 5, "comments": "", "device": "Laptop", "langs": ["German"], "age": "34"}
        for change in ({"age": "17"}, {"age": "3.5"}, {"q1": 8}, {"device": "Phone"}, {"langs": []},
                       {"q2": None}, {"comments": "x" * 6000}):
            r = b.act("questionnaire", {"answers": {**good, **change}}, expect=422)
            assert r.json()["error"].startswith("Your answer could not be saved")
        b.act("questionnaire", {"answers": {**good, "age": {"x": 1}}}, expect=400)
        b.act("questionnaire", {"answers": good})
        assert b.state["screen"] == "done"


def test_a_reload_mid_clip_keeps_a_play_once_clip_playable(web_study_files, tmp_path, browser_for) -> None:
    """With ``allow_replay = false`` the clip plays once; a page reloaded mid-clip lost that play, and the
    clip may be played again (as after a restart on the desktop), once."""
    path, _ = web_study_files
    once = path.with_name("once.toml")
    once.write_text(path.read_text().replace("[playback]\n", "[playback]\nallow_replay = false\n"))
    design = load_design(once)
    assert not design.playback.allow_replay
    study = Study(once, design, tmp_path / "results.sqlite", ClipVideos(path.parent / "videos"), Clock())
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        _to_first_trial(b)
        b.act("play")
        page = b.reload()
        assert page["can_play"] and not page["can_rank"]
        b.watch()
        assert not b.state["can_play"]     # watched once: no replay in this design
        b.act("play", expect=400)
        b.answer_well()
    db = study.db()
    assert [(p["trial_index"], p["completed"]) for p in db.plays("5f0c0ffee0ddba11")] == [(0, 0), (0, 1)]
    db.close()


def test_the_demo_is_served(tmp_path, browser_for) -> None:
    """The shipped demo design through the server (stand-in videos): every page, the frozen attention check
    passed, its questionnaire, done."""
    from studyapp.resources import demo_design

    design = load_design(demo_design(), check_files=False)
    study = Study(demo_design(), design, tmp_path / "demo.sqlite", ClipVideos(tmp_path / "videos"), Clock())
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        _to_first_trial(b, "PROLIFIC_PID=demo1")
        assert "Practice clip 1 of 1" == b.state["progress"] and b.state["labels"] == ["A", "B", "C"]
        # the number keys name figures, not ranks: the page says which key is which figure, as the desktop does
        assert b.state["texts"]["start_hint"].endswith("or press 1 = A, 2 = B, 3 = C.")
        assert any(b"1 = A, 2 = B, 3 = C puts that figure in the next free box" in body for _, _, body in b.seen)
        assert any(b'"how_title": "How to rank"' in body for _, _, body in b.seen)
        while b.state["screen"] == "trial":
            b.watch()
            b.answer_well()
        assert b.state["screen"] == "questionnaire"
        b.act("questionnaire", {"answers": {q["id"]: 5 for q in b.state["items"]}})
        assert b.state["screen"] == "done"
        # the demo's [online] table: Prolific's completion code and redirect, as a real study has them
        assert "DEMO1234" in b.state["code"]
        assert b.state["redirect"] == "https://app.prolific.com/submissions/complete?cc=DEMO1234"
        for url, headers, body in b.seen:
            assert conditions_named_in(design, " ".join([url, json.dumps(headers), body.decode("latin-1")])) == []
    db = study.db()
    assert db.participant("demo1").status == "done"
    assert [t["attention_passed"] for t in db.trials("demo1") if t["is_attention_check"]] == [1]
    db.close()
