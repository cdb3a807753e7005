"""The browser flow of the other response paradigms, on the shipped example designs: a block's instructions
page before its first trial, pairwise and mismatch preferences (with reasons), ratings on sliders; every answer
through the session's own method (``submit_preference``, ``submit_ratings``), refused when it breaks their
rules, stored as judgements; nothing served names a condition."""
from __future__ import annotations

import json
import warnings

import pytest

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from starlette.testclient import TestClient

from fixtures.web_study import Browser, ClipVideos, Clock, Study
from studyapp.resources import designs_dir
from studyapp.study.design import load_design
from studyapp.study.design.blinding import conditions_named_in


@pytest.fixture(params=["pairwise_example.toml", "mismatch_example.toml", "rating_example.toml"])
def example(request, tmp_path) -> Study:
    path = designs_dir() / request.param
    design = load_design(path, check_files=False)
    return Study(path, design, tmp_path / "results.sqlite", ClipVideos(tmp_path / "videos"), Clock())


def _answer(b: Browser, study: Study) -> dict:
    """A valid answer of the current trial's paradigm, built from what the page shows."""
    st = b.state
    crits = [c["id"] for c in st["criteria"]]
    if st["paradigm"] == "rating":
        return {"ratings": {c: {str(s): 20 * (s + 1) for s in range(len(st["labels"]))} for c in crits}}
    assert [o["value"] for o in st["options"]] in ([-2, -1, 0, 1, 2], [-1, 0, 1])
    return {"levels": {c: st["options"][-1]["value"] for c in crits}, "reasons": st["reasons"][:1]}


def _bad_answers(st: dict) -> list[tuple[dict, int]]:
    crits = [c["id"] for c in st["criteria"]]
    if st["paradigm"] == "rating":
        k = len(st["labels"])
        return [({"ratings": {c: {str(s): 50 for s in range(k - 1)} for c in crits}}, 422),    # a slider not moved
                ({"ratings": {c: {str(s): 101 for s in range(k)} for c in crits}}, 422),
                ({"ratings": {c: {str(s): "50" for s in range(k)} for c in crits}}, 400),
                ({"ranks": {c: {"0": 1, "1": 2, "2": 3} for c in crits}}, 400)]
    return [({"levels": {c: 3 for c in crits}}, 422),
            ({"levels": {c: 0 for c in crits}, "reasons": ["Hands"]}, 422),       # reasons without a preference
            ({"levels": {c: 1.5 for c in crits}}, 400),
            ({"levels": {c: 1 for c in crits}, "reasons": ["not a reason"]}, 422),
            ({"levels": {crits[0]: True}}, 400)]


def test_a_participant_answers_every_paradigm_block_in_the_browser(example, browser_for) -> None:
    study = example
    with TestClient(study.app()) as client:
        b = browser_for(client, study)
        b.open("PROLIFIC_PID=para1")
        b.consent()
        how = b.state["how"]
        for blk in study.design.trial_blocks:   # the instructions say how to answer each paradigm
            key = {"rank": "instructions.how", "rating": "instructions.how_rating"}.get(blk.paradigm, "instructions.how_pref")
            assert study.design.texts[key].split("{")[0][:40] in how
        assert b.state["how_title"] == "How to answer"     # not "How to rank": these designs do not rank
        b.act("continue")
        b.act("sound", {})
        blocks_seen, paradigms, tried_bad = 0, set(), False
        while b.state["screen"] in ("trial", "block"):
            if b.state["screen"] == "block":
                blocks_seen += 1
                b.act("answer", _answer_placeholder(), expect=400)   # no answer before the block's page is read
                b.act("block")
                continue
            paradigms.add(b.state["paradigm"])
            if b.state["paradigm"] == "rating":    # the number keys jump where the desktop's do
                from studyapp.ui.rating import digit_points
                points = digit_points(len(b.state["anchors"]))
                assert b.state["points"] == pytest.approx(points, abs=0.01)
                assert f"number keys 1-{len(points)} jump" in how
            b.watch()
            if not tried_bad:
                for bad, code in _bad_answers(b.state):
                    b.act("answer", bad, expect=code)
                tried_bad = True
            b.act("answer", _answer(b, study))
        for url, headers, body in b.seen:
            text = " ".join([url, json.dumps(headers), body.decode("latin-1")])
            assert conditions_named_in(study.design, text) == [], url
    expected = {blk.paradigm for blk in study.design.trial_blocks}
    assert paradigms == expected and blocks_seen == sum(1 for blk in study.design.trial_blocks if blk.instructions)
    db = study.db()
    trials = db.trials("para1")
    judgements = db.judgements("para1")
    db.close()
    assert len(trials) == len([t for t in trials if t["paradigm"] in expected]) > 0
    per_trial = {}
    for j in judgements:
        per_trial.setdefault(j["trial_index"], []).append(j)
    assert set(per_trial) == {t["trial_index"] for t in trials}
    for t in trials:
        rows = per_trial[t["trial_index"]]
        if t["paradigm"] == "rating":
            assert sorted({r["value"] for r in rows}) == [20.0 * (k + 1) for k in range(len({r["slot"] for r in rows}))]
        else:   # the right figure clearly (or simply) preferred: +p for slot 1, -p for slot 0
            assert {(r["slot"], r["value"]) for r in rows} <= {(1, 2.0), (0, -2.0), (1, 1.0), (0, -1.0)}


def _answer_placeholder() -> dict:
    return {"levels": {}, "ratings": {}, "ranks": {}}
