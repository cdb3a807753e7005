"""The session state machine, driven exactly as the UI drives it, on a tiny generated study."""
from __future__ import annotations

from pathlib import Path

import pytest

from studyapp.errors import InputError
from studyapp.bots.session_driver import run_bot_session
from studyapp.study.design import load_design
from studyapp.study.schedule import participant_schedule
from studyapp.study.session import (
    ENDED_EARLY_MESSAGE, ParticipantFinishedError, RankingError, Session, SessionError, State,
)
from studyapp.study.storage import ResultsDB
from fixtures.synthetic import write_synthetic_study

PERM = {0: 1, 1: 2, 2: 3}


def _design(folder: Path, **kw):
    return load_design(write_synthetic_study(folder, **kw), check_files=False)


def _start(s: Session) -> None:
    s.accept_consent()
    s.finish_instructions()
    s.record_env_check({"gl_renderer": "test", "refresh_hz": 60})


def _watch(s: Session, frames: int = 30, dropped: int = 0) -> None:
    s.record_play_started()
    s.record_play_finished(True, {"frames_shown": frames, "dropped_frames": dropped, "refresh_hz": 60.0,
                                  "worst_av_offset_ms": -12.5})


def _rank_all(design, order=PERM) -> dict:
    return {c.id: dict(order) for c in design.criteria}


@pytest.fixture()
def study(tmp_path: Path):
    design = _design(tmp_path, n_stimuli=4, questionnaire=True)
    db = ResultsDB(tmp_path / "r.sqlite", design)
    yield design, db
    db.close()


def test_full_session_in_order_with_progress_and_stats(study) -> None:
    design, db = study
    s = Session(design, db, "P01")
    assert s.state is State.WELCOME and s.current_trial() is None
    with pytest.raises(SessionError):
        s.finish_instructions()
    _start(s)
    assert s.state is State.PRACTICE and s.progress_label() == "Practice clip 1 of 1"
    expected = participant_schedule(design, "P01", s.row)
    seen = []
    while (plan := s.current_trial()) is not None:
        seen.append(plan)
        if not plan.is_practice:
            assert s.state is State.TRIALS
            assert s.progress_label() == f"Clip {len(seen) - 1} of 4"
        _watch(s)
        _watch(s, frames=10, dropped=2)  # a replay
        s.submit_ranking(_rank_all(design))
    assert seen == expected
    assert s.state is State.QUESTIONNAIRE
    s.submit_questionnaire({"q1": 5, "q2": 7, "comments": "fine"})
    assert s.state is State.DONE and s.finished
    assert db.participant("P01").status == "done"
    trials = db.trials("P01")
    assert [t["trial_index"] for t in trials] == [p.trial_index for p in expected]
    t = trials[1]
    assert (t["plays"], t["frames_shown"], t["dropped_frames"], t["refresh_hz"], t["worst_av_offset_ms"]) == (2, 40, 2, 60.0, 12.5)
    assert t["response_time_s"] >= 0 and t["shown_at"] <= t["answered_at"]
    # ranks follow the slots: slot i of the plan shows condition plan.slots[i] and got rank i+1
    for r in db.responses("P01"):
        plan = expected[r["trial_index"]]
        assert r["condition"] == plan.slots[r["slot"]] and r["rank"] == r["slot"] + 1
    sessions = db.sessions("P01")
    assert sessions[0]["machine"]["gl_renderer"] == "test" and sessions[0]["ended"]
    assert {q["item"]: q["value"] for q in db.questionnaire("P01")} == {"q1": "5", "q2": "7", "comments": "fine"}


def test_must_watch_fully_before_ranking(study) -> None:
    design, db = study
    s = Session(design, db, "P01")
    _start(s)
    assert not s.can_rank()
    with pytest.raises(RankingError, match="watch the clip"):
        s.submit_ranking(_rank_all(design))
    s.record_play_started()
    assert not s.can_rank()
    s.record_play_finished(False)  # stopped half-way
    assert not s.can_rank()
    _watch(s)
    assert s.can_rank()
    assert db.answered_trials("P01") == set()


@pytest.mark.parametrize("bad, message", [
    ({"realism": {0: 1, 1: 2}}, "rank all three"),
    ({"realism": {0: 1, 1: 1, 2: 3}}, "only once"),
    ({"realism": {0: 1, 1: 2, 2: 4}}, "from 1"),
    ({"realism": {0: 1, 1: 2, 2: 3}, "beauty": {0: 1, 1: 2, 2: 3}}, "unknown"),
])
def test_invalid_rankings_are_refused_and_nothing_is_stored(study, bad, message) -> None:
    design, db = study
    s = Session(design, db, "P01")
    _start(s)
    _watch(s)
    ranks = _rank_all(design)
    ranks.update(bad)
    with pytest.raises(RankingError, match=message):
        s.submit_ranking(ranks)
    assert db.answered_trials("P01") == set() and db.responses() == []


def test_ties_become_average_ranks_when_allowed(tmp_path: Path) -> None:
    design = _design(tmp_path, n_stimuli=2, practice=False, allow_ties=True)
    db = ResultsDB(tmp_path / "r.sqlite", design)
    s = Session(design, db, "P01")
    _start(s)
    _watch(s)
    s.submit_ranking({c.id: {0: 1, 1: 1, 2: 3} for c in design.criteria})
    ranks = [r["rank"] for r in db.responses("P01") if r["criterion"] == "realism"]
    assert ranks == [1.5, 1.5, 3.0]
    db.close()


def test_resume_continues_at_first_unanswered_trial_with_same_schedule(study) -> None:
    design, db = study
    s = Session(design, db, "P07")
    _start(s)
    first_row = s.row
    done = []
    for _ in range(3):
        done.append(s.current_trial())
        _watch(s)
        s.submit_ranking(_rank_all(design))
    nxt = s.current_trial()
    del s  # the process dies: no close, no goodbye
    again = Session(design, db, "P07")
    assert again.resumed and again.row == first_row
    _start(again)
    assert again.current_trial() == nxt
    assert again.plans[:3] == done
    with pytest.raises(InputError, match="already follows"):
        Session(design, db, "P07", row=(first_row + 1) % 12)


def test_finished_participant_needs_explicit_rerun(study) -> None:
    design, db = study
    run_bot_session(design, db, "P01", "ordered", 1)
    with pytest.raises(ParticipantFinishedError, match="already completed"):
        Session(design, db, "P01")
    rerun = Session(design, db, "P01", allow_rerun=True)
    assert rerun.participant_id == "P01-rerun2"
    assert db.participant("P01-rerun2").groups["rerun_of"] == "P01"
    assert db.participant("P01-rerun2").latin_row == db.participant("P01").latin_row
    assert len(db.trials("P01")) == 5  # the first run's answers are untouched


def test_attention_failures_end_the_session_politely(tmp_path: Path) -> None:
    design = _design(tmp_path, n_stimuli=4, attention_check=True, max_attention_failures=0)
    db = ResultsDB(tmp_path / "r.sqlite", design)
    # ordered ranks 'static' (listed last) last on realism: the known-worst check passes
    good = run_bot_session(design, db, "good", "ordered", 1)
    assert good.state is State.DONE
    att = [t for t in db.trials("good") if t["is_attention_check"]]
    assert [t["attention_passed"] for t in att] == [1]
    # a participant who ranks static first fails it and the session ends right after that trial
    s = Session(design, db, "bad")
    _start(s)
    while (plan := s.current_trial()) is not None:
        _watch(s)
        static = list(plan.slots).index("static")
        others = [i for i in range(3) if i != static]
        ranks = {static: 1, others[0]: 2, others[1]: 3}
        s.submit_ranking({c.id: ranks for c in design.criteria})
        if plan.is_attention_check:
            break
    assert s.state is State.ENDED_EARLY and s.end_message == ENDED_EARLY_MESSAGE
    assert db.participant("bad").status == "ended_early"
    assert len(db.trials("bad")) == next(i for i, p in enumerate(s.plans) if p.is_attention_check) + 1
    db.close()


def test_questionnaire_validation(study) -> None:
    design, db = study
    s = run_bot_session(design, db, "P02", "random", 3)
    assert s.state is State.DONE
    s2 = Session(design, db, "P03")
    _start(s2)
    while s2.current_trial() is not None:
        _watch(s2)
        s2.submit_ranking(_rank_all(design))
    with pytest.raises(RankingError):
        s2.submit_questionnaire({"q1": 9, "q2": 1})
    with pytest.raises(RankingError):
        s2.submit_questionnaire({"q1": 2})
    assert s2.state is State.QUESTIONNAIRE and db.questionnaire("P03") == []
    s2.submit_questionnaire({"q1": 2, "q2": 3})
    assert {q["item"]: q["kind"] for q in db.questionnaire("P03")} == {"q1": "likert", "q2": "likert", "comments": "text"}


def test_resume_refuses_a_schedule_that_no_longer_matches(study) -> None:
    design, db = study
    s = Session(design, db, "P09")
    _start(s)
    _watch(s)
    s.submit_ranking(_rank_all(design))
    plans = list(s.plans)
    swapped = [plans[0].__class__(p.trial_index, p.stimulus_id, tuple(reversed(p.slots)), p.is_practice,
                                  p.is_attention_check, p.row) for p in plans]
    with pytest.raises(InputError, match="does not match"):
        Session(design, db, "P09", plans=swapped)
    assert Session(design, db, "P09", plans=plans).answered == 1
