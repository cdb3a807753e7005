"""A stored session restored from the database alone (``Session(..., session_id=N)``, what the browser server
does for every request): after every step of a live session, a restored one shows exactly the same state, and a
participant driven only through freshly restored sessions is stored exactly as one driven by a live one."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from fixtures.paradigm_studies import write_paradigm_study
from fixtures.synthetic import write_synthetic_study
from studyapp.study.design import load_design
from studyapp.study.session import RankingError, Session, SessionError, State
from studyapp.study.storage import ResultsDB

PERM = {0: 1, 1: 2, 2: 3}


def _view(s: Session) -> tuple[Any, ...]:
    plan = s.current_trial()
    return (s.state, None if plan is None else plan.trial_index, s.can_play(), s.can_rank(), s.playing, s.plays,
            s.answered, s.block_instructions(), s.resumed, s.resume_point, s.progress_label(), s.finished)


def _restored(s: Session) -> Session:
    return Session(s.design, s.db, s.participant_id, session_id=s.session_id, play_duration_s=lambda plan: 1.25)


def _once_only_study(tmp_path: Path) -> tuple[Any, ResultsDB]:
    path = write_synthetic_study(tmp_path / "s", n_stimuli=3, questionnaire=True, practice=True)
    path.write_text(path.read_text().replace("[playback]\n", "[playback]\nallow_replay = false\n"))
    design = load_design(path, check_files=False)
    assert not design.playback.allow_replay and design.playback.must_watch_fully
    return design, ResultsDB(tmp_path / "r.sqlite", design)


def test_a_restored_session_shows_the_live_sessions_state_after_every_step(tmp_path: Path) -> None:
    design, db = _once_only_study(tmp_path)
    live = Session(design, db, "P01")
    steps = [live.accept_consent, live.finish_instructions, lambda: live.record_env_check({"gl": "x"})]
    for step in steps:
        assert _view(_restored(live)) == _view(live)
        step()
        assert _view(_restored(live)) == _view(live)
    k = 0
    while live.current_trial() is not None:
        live.record_play_started(duration_s=1.25)
        assert _view(_restored(live)) == _view(live)           # a play open
        if k == 0:                                              # the front end lost it: not counted
            live.abandon_play()
            assert _view(_restored(live)) == _view(live) and live.can_play()
            live.record_play_started(duration_s=1.25)
        if k == 2:                                              # stopped: counts, not watched
            live.record_play_finished(False)
            assert _view(_restored(live)) == _view(live) and not live.can_play() and not live.can_rank()
            with pytest.raises(RankingError):
                _restored(live).submit_ranking({c.id: dict(PERM) for c in design.criteria})
            break
        live.record_play_finished(True)
        assert _view(_restored(live)) == _view(live)
        live.submit_ranking({c.id: dict(PERM) for c in design.criteria})
        assert _view(_restored(live)) == _view(live)
        k += 1
    assert k == 2 and live.answered == 2
    db.close()


def test_a_participant_driven_only_through_restored_sessions_is_stored_as_a_live_one(tmp_path: Path) -> None:
    design, db = _once_only_study(tmp_path)
    ranks = {c.id: dict(PERM) for c in design.criteria}

    def run(pid: str, fresh: bool) -> None:
        first = Session(design, db, pid, row=0)
        sid = first.session_id

        def s() -> Session:
            return Session(design, db, pid, session_id=sid, play_duration_s=lambda plan: 1.25) if fresh else first

        s().accept_consent()
        s().finish_instructions()
        s().record_env_check({"gl": "x"})
        while s().current_trial() is not None:
            s().record_play_started(duration_s=1.25)
            s().abandon_play()                      # a reloaded page
            s().record_play_started(duration_s=1.25)
            s().record_play_finished(True)
            with pytest.raises(SessionError):
                s().record_play_started(duration_s=1.25)   # once only
            s().submit_ranking(ranks)
        assert s().state is State.QUESTIONNAIRE
        assert s().submit_questionnaire({"q1": 6, "q2": 5, "comments": ""}) is State.DONE

    run("LIVE", fresh=False)
    run("FRESH", fresh=True)

    def stored(pid: str) -> tuple[Any, ...]:
        keep = ("trial_index", "stimulus", "slot_left", "slot_middle", "slot_right", "plays", "trial_duration_s",
                "attention_passed")
        trials = [tuple(t[k] for k in keep) for t in db.trials(pid)]
        plays = [(p["trial_index"], p["completed"], p["ended"] is not None) for p in db.plays(pid)]
        responses = sorted((r["trial_index"], r["criterion"], r["slot"], r["rank"]) for r in db.responses(pid))
        sessions = [(s["ended"] is not None, sorted(s["machine"])) for s in db.sessions(pid)]
        return trials, plays, responses, sessions, db.participant(pid).status

    assert stored("FRESH") == stored("LIVE")
    assert len(db.trials("FRESH")) == 4 and [t["plays"] for t in db.trials("FRESH")] == [2] * 4
    assert all(t["trial_duration_s"] == 1.25 for t in db.trials("FRESH"))
    shown = [t["shown_at"] for t in db.trials("FRESH")]
    answered = [t["answered_at"] for t in db.trials("FRESH")]
    assert all(s is not None for s in shown) and shown[1:] == answered[:-1]   # shown when the last was answered
    db.close()


def test_dismissed_block_instructions_stay_dismissed_in_a_restored_session(tmp_path: Path) -> None:
    design = load_design(write_paradigm_study(tmp_path / "p"), check_files=False)
    db = ResultsDB(tmp_path / "p.sqlite", design)
    live = Session(design, db, "B01", row=0)
    live.accept_consent()
    live.finish_instructions()
    live.record_env_check()
    assert live.block_instructions() is not None
    assert _restored(live).block_instructions() == live.block_instructions()
    _restored(live).finish_block_instructions()
    again = _restored(live)
    assert again.block_instructions() is None and again.can_play()
    db.close()
