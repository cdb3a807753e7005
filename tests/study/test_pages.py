"""Participant pages the design edits (issue 18, item 5), at the session level: consent and declining it,
the completion text, questionnaire items of every kind, and where a resumed participant continues."""
from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from fixtures.synthetic import write_synthetic_study
from studyapp.bots.session_driver import run_bot_session
from studyapp.study.design import DesignError, load_design
from studyapp.study.export import export_dataframe, questionnaire_dataframe
from studyapp.study.session import ParticipantFinishedError, RankingError, Session, State
from studyapp.study.storage import ResultsDB
from fixtures.questionnaire_kinds import CHOICE_AND_NUMBER_ITEMS

TOP = '''
consent = """
We study gestures. It takes about {minutes} minutes.
Your answers are anonymous."""
completion = "Thanks! This study compared gesture models. Write to study@example.org with questions."
'''
PAGES = CHOICE_AND_NUMBER_ITEMS


def _design(tmp_path: Path, extra: str = PAGES, top: str = TOP):
    """The tiny study with ``top`` (top-level keys) before its first table and ``extra`` at the end."""
    path = write_synthetic_study(tmp_path / "s", n_stimuli=2, seconds=1.0, practice=False, questionnaire=True)
    path.write_text(top + "\n" + path.read_text() + extra)
    return load_design(path)


def test_design_reads_the_pages_and_the_new_item_kinds(tmp_path):
    d = _design(tmp_path)
    assert d.consent.startswith("We study gestures. It takes about {minutes} minutes.")
    assert d.completion.startswith("Thanks!")
    kinds = {q.id: q for q in d.questionnaire}
    assert kinds["device"].options == ("Headphones", "Speakers", "Laptop") and not kinds["device"].multiple
    assert kinds["hobbies"].multiple
    assert (kinds["age"].min, kinds["age"].max, kinds["age"].integer) == (18.0, 99.0, True)


@pytest.mark.parametrize("item,key,words", [
    ('kind = "choice"\noptions = ["Only one"]', "questionnaire[3].options", "at least two"),
    ('kind = "choice"\noptions = ["A", "A"]', "questionnaire[3].options", "twice"),
    ('kind = "number"\nmin = 1', "questionnaire[3].max", "needs a range"),
    ('kind = "number"\nmin = 5\nmax = 1', "questionnaire[3].max", "larger than min"),
    ('kind = "likert"\noptions = ["A", "B"]', "questionnaire[3].options", "only choice items"),
    ('kind = "text"\nmin = 1', "questionnaire[3].min", "only number items"),
    ('kind = "slider"', "questionnaire[3].kind", "unknown item kind"),
])
def test_each_questionnaire_problem_is_one_message(tmp_path, item, key, words):
    with pytest.raises(DesignError) as err:
        _design(tmp_path, f'\n[[questionnaire]]\nid = "x"\ntext = "X?"\n{item}\n')
    probs = [p for p in err.value.problems if p.key.startswith("questionnaire[3]")]
    assert len(probs) == 1, probs
    assert probs[0].key == key and words in probs[0].message, probs[0]


def test_a_consent_text_naming_a_condition_is_refused(tmp_path):
    with pytest.raises(DesignError) as err:
        _design(tmp_path, top='consent = "You will compare synced motion with others."\n')
    assert any(p.key == "consent" and "unblinds" in p.message for p in err.value.problems)


def test_declining_consent_ends_the_session_and_is_recorded(tmp_path):
    d = _design(tmp_path)
    db = ResultsDB(tmp_path / "r.sqlite", d)
    try:
        run_bot_session(d, db, "P1", "ordered", seed=1)
        s = run_bot_session(d, db, "P2", "ordered", seed=1, consent=False)
        assert s.state is State.DECLINED and s.finished and "not to take part" in s.end_message
        assert db.participant("P2").status == "ended_early"
        assert db.trials("P2") == [] and db.questionnaire("P2") == [] and db.plays("P2") == []
        with pytest.raises(ParticipantFinishedError):
            Session(d, db, "P2")
        # the export and the questionnaire export keep working, with P1's answers only
        assert set(export_dataframe(db)["participant"]) == {"P1"}
        assert set(questionnaire_dataframe(db)["participant"]) == {"P1"}
    finally:
        db.close()
    con = sqlite3.connect(tmp_path / "r.sqlite")
    machine = [json.loads(m) for (m,) in con.execute("SELECT machine FROM sessions WHERE participant = 'P2'")]
    con.close()
    assert machine[0]["consent"] == "declined" and machine[0]["consent_declined_at"]


def test_completion_text_is_the_end_message(tmp_path):
    d = _design(tmp_path)
    db = ResultsDB(tmp_path / "r.sqlite", d)
    try:
        s = run_bot_session(d, db, "P1", "random", seed=3)
        assert s.state is State.DONE and s.end_message == d.completion
    finally:
        db.close()


def test_every_item_kind_is_checked_and_stored(tmp_path):
    from results_analysis.loader import normalize_questionnaire

    d = _design(tmp_path)
    db = ResultsDB(tmp_path / "r.sqlite", d)
    try:
        s = Session(d, db, "P1")
        s.accept_consent(); s.finish_instructions(); s.record_env_check({})
        while (plan := s.current_trial()) is not None:
            s.record_play_started(); s.record_play_finished(True)
            s.submit_ranking({c.id: {0: 1, 1: 2, 2: 3} for c in d.criteria})
        good = {"q1": 5, "q2": 2, "comments": "", "device": "Speakers", "hobbies": ["Sign language", "Dance"],
                "age": "34"}
        for bad, words in (({"device": "Radio"}, "choose one option"), ({"hobbies": []}, "at least one"),
                           ({"age": "17"}, "from 18 to 99"), ({"age": "30.5"}, "whole number"),
                           ({"age": ""}, "whole number"), ({"q1": 8}, "from 1 to 7")):
            with pytest.raises(RankingError, match=words):
                s.submit_questionnaire({**good, **bad})
        s.submit_questionnaire(good)
        rows = {r["item"]: (r["kind"], r["value"]) for r in db.questionnaire("P1")}
    finally:
        db.close()
    assert rows["device"] == ("choice", "Speakers")
    assert rows["hobbies"] == ("choice", '["Dance", "Sign language"]')  # in the design's order
    assert rows["age"] == ("number", "34") and rows["q1"] == ("likert", "5")
    qdf = questionnaire_dataframe(tmp_path / "r.sqlite")
    assert float(qdf.set_index("item").loc["age", "value"]) == 34.0
    assert qdf.set_index("item").loc["device", "text"] == "Speakers"
    # the analysis treats only the rated items as numbers
    import pandas as pd
    raw = pd.DataFrame([{"participant": "P1", "item": k, "kind": v[0], "value": v[1], "_where": k}
                        for k, v in rows.items()])
    assert set(normalize_questionnaire(raw, "x")["item"]) == {"q1", "q2"}


def test_bots_answer_every_kind_in_range(tmp_path):
    d = _design(tmp_path)
    db = ResultsDB(tmp_path / "r.sqlite", d)
    try:
        for k in range(4):
            run_bot_session(d, db, f"P{k}", "random", seed=k)
        rows = db.questionnaire()
    finally:
        db.close()
    ages = [int(r["value"]) for r in rows if r["item"] == "age"]
    assert len(ages) == 4 and all(18 <= a <= 99 for a in ages)
    assert all(r["value"] in ("Headphones", "Speakers", "Laptop") for r in rows if r["item"] == "device")
    assert all(json.loads(r["value"]) for r in rows if r["item"] == "hobbies")


def test_resume_says_where_and_whether_a_half_answer_was_dropped(tmp_path):
    d = _design(tmp_path)
    db = ResultsDB(tmp_path / "r.sqlite", d)
    try:
        s = Session(d, db, "P1")
        assert s.resume_point is None
        s.accept_consent(); s.finish_instructions(); s.record_env_check({})
        s.record_play_started(); s.record_play_finished(True)
        s.submit_ranking({c.id: {0: 1, 1: 2, 2: 3} for c in d.criteria})
        s.close()
        s2 = Session(d, db, "P1")
        rp = s2.resume_point
        assert (rp.k, rp.n, rp.practice, rp.dropped) == (2, 2, False, False)
        s2.accept_consent(); s2.finish_instructions(); s2.record_env_check({})
        s2.record_play_started(); s2.record_play_finished(True)   # watched clip 2, closed before answering
        s2.close()
        rp = Session(d, db, "P1").resume_point
        assert (rp.k, rp.n, rp.dropped) == (2, 2, True)
    finally:
        db.close()


def test_merge_checks_choice_and_number_answers(tmp_path):
    """A returned results file whose choice or number answers were edited is flagged, one finding each."""
    from studyapp.study.returned import check_questionnaire

    d = _design(tmp_path)
    good = [{"item": "device", "value": "Speakers"}, {"item": "hobbies", "value": '["Dance"]'},
            {"item": "age", "value": "34"}]
    assert check_questionnaire(good, d, "active") == []
    bad = [{"item": "device", "value": "Radio"}, {"item": "hobbies", "value": "Dance"},
           {"item": "age", "value": "150"}]
    found = check_questionnaire(bad, d, "active")
    assert sorted(f.where for f in found) == ["questionnaire age", "questionnaire device", "questionnaire hobbies"]
