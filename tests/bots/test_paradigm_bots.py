"""Every bot answers every paradigm, and the careful one answers from what it perceives.

The answers are read back from the results database as stored (``judgements``: one row per slot, the
preference FOR that slot, or its 0..100 rating), so these tests check what a study records.
"""
from __future__ import annotations

import sqlite3

import numpy as np
import pytest
from scipy.stats import binomtest

from fixtures.paradigm_studies import paradigm_study  # noqa: F401
from studyapp.bots.policies import POLICIES, choose_preference, choose_ratings, trial_rng
from studyapp.study.schedule import TrialPlan


def stored_judgements(db, pid: str) -> dict[int, dict]:
    """``{trial: {criterion: {slot: value}}, ...}`` and each trial's reasons, from the database file."""
    out: dict[int, dict] = {}
    with sqlite3.connect(db.path) as con:
        rows = con.execute("SELECT trial_index, criterion, slot, value, reasons FROM judgements "
                           "WHERE participant = ?", (pid,)).fetchall()
    for trial, crit, slot, value, reasons in rows:
        t = out.setdefault(trial, {"values": {}, "reasons": reasons})
        t["values"].setdefault(crit, {})[int(slot)] = float(value)
    return out


def expected_answers(design, plan, pid: str, policy: str, seed: int):
    """What the policy answers on ``plan``, computed without any driver."""
    from studyapp.study.stimuli import load_trial_media
    from studyapp.ui.paradigm import PREFERENCE, block_view

    block = block_view(design, plan)
    media = load_trial_media(design, plan) if policy == "careful" else None
    rng = trial_rng(seed, pid, plan.trial_index)
    order = [c.id for c in design.conditions]
    if block.paradigm in PREFERENCE:
        levels, reasons = choose_preference(policy, plan, media, block.criteria, rng, levels=block.levels,
                                            reasons=block.reasons, condition_order=order)
        # stored per slot: slot 0 (left) gets -level, slot 1 (right) +level
        return {c: {0: float(-v), 1: float(v)} for c, v in levels.items()}, reasons
    return {c: {s: float(v) for s, v in d.items()}
            for c, d in choose_ratings(policy, plan, media, block.criteria, rng, condition_order=order).items()}, []


@pytest.mark.parametrize("policy", POLICIES)
def test_session_bot_answers_each_paradigm_as_its_policy_says(paradigm_study, policy):
    import json

    from studyapp.bots.session_driver import run_bot_session

    design, db = paradigm_study
    session = run_bot_session(design, db, "B1", policy, seed=4)
    assert session.finished
    got = stored_judgements(db, "B1")
    plans = session.plans
    assert sorted(got) == [p.trial_index for p in plans] and {p.paradigm for p in plans} == {
        "pairwise", "mismatch", "rating"}
    for plan in plans:
        values, reasons = expected_answers(design, plan, "B1", policy, 4)
        assert got[plan.trial_index]["values"] == values, (plan, got[plan.trial_index])
        stored = got[plan.trial_index]["reasons"]
        assert (json.loads(stored) if stored else []) == list(reasons)


def _demo_mismatch_plans(design, condition: str) -> list[TrialPlan]:
    """Every matched/mismatched pair of the demo: each clip's own motion against its same-speaker partner's,
    the matched one on the left and on the right."""
    by_speaker: dict[str, list[str]] = {}
    for s in design.stimuli:
        by_speaker.setdefault(s.tags["speaker"], []).append(s.id)
    plans = []
    for clips in by_speaker.values():
        for sid in clips:
            for other in clips:
                if other == sid:
                    continue
                for motions in ((sid, other), (other, sid)):
                    plans.append(TrialPlan(len(plans), sid, (condition, condition), False, False, 0, (1, 1),
                                           "fit", "mismatch", motions))
    return plans


def test_careful_bot_prefers_the_motion_made_for_the_speech_in_demo_mismatch_trials():
    """The demo's ``synced`` motion is built on its own clip's syllables: shown with that speech next to the
    same condition's motion for the other clip of the speaker, the careful bot prefers it far more often than
    chance (0.5), on whichever side it is."""
    from studyapp.resources import demo_design
    from studyapp.study.design import load_design
    from studyapp.study.stimuli import load_trial_media

    design = load_design(demo_design())
    plans = _demo_mismatch_plans(design, "synced")
    assert len(plans) == 8
    wins = ties = n = 0
    for plan in plans:
        media = load_trial_media(design, plan)
        matched = plan.motion_stimuli.index(plan.stimulus_id)
        for seed in range(25):
            levels, _ = choose_preference("careful", plan, media, ["synchronization"],
                                          np.random.default_rng(seed), levels=5)
            v = levels["synchronization"] * (1 if matched == 1 else -1)   # > 0: the matched one preferred
            wins += v > 0
            ties += v == 0
            n += 1
    rate = (wins + 0.5 * ties) / n
    assert rate > 0.8, (wins, ties, n)
    assert binomtest(wins, n - ties, 0.5, alternative="greater").pvalue < 1e-6


def test_careful_ratings_follow_the_demo_conditions():
    """On a demo trial, the careful bot rates the speech-synced figure above the near-static one on
    synchronization and diversity, every time, and its ratings are whole numbers in 0..100."""
    from studyapp.resources import demo_design
    from studyapp.study.design import load_design
    from studyapp.study.stimuli import load_trial_media

    design = load_design(demo_design())
    plan = TrialPlan(0, "clip02", ("static", "lagged", "synced"), False, False, 0, (1, 1, 1), "main", "rating")
    media = load_trial_media(design, plan)
    for seed in range(10):
        r = choose_ratings("careful", plan, media, ["synchronization", "diversity"], np.random.default_rng(seed))
        for c in ("synchronization", "diversity"):
            assert r[c][2] > r[c][0], (seed, r)
            assert all(isinstance(v, int) and 0 <= v <= 100 for v in r[c].values())
