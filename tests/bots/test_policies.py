"""Scripted participants' choices, with and without ties, and what reaches the results database."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from studyapp.bots.policies import WEAK_RANKINGS, _ranks_from_scores, choose_ranking, trial_rng
from studyapp.bots.session_driver import run_bot_session
from studyapp.study.design import load_design
from studyapp.study.schedule import TrialPlan
from studyapp.study.session import normalise_ranks
from studyapp.study.storage import ResultsDB
from fixtures.synthetic import write_synthetic_study

PLAN = TrialPlan(0, "s1", ("b", "c", "a"), False, False, 0)
CRITS = ["realism", "synchronization"]


def _as_tuple(ranks: dict) -> tuple:
    return tuple(ranks[s] for s in range(3))


def test_random_without_ties_still_draws_one_permutation_per_criterion() -> None:
    # Resumed and uninterrupted runs must answer alike, so the draw itself must not change for designs
    # without ties.
    for seed in range(20):
        got = choose_ranking("random", PLAN, None, CRITS, np.random.default_rng(seed))
        rng = np.random.default_rng(seed)
        assert got == {c: {i: int(r) for i, r in enumerate(rng.permutation(3) + 1)} for c in CRITS}


def test_random_with_ties_draws_every_competition_ranking() -> None:
    seen = set()
    for seed in range(400):
        got = choose_ranking("random", PLAN, None, CRITS, np.random.default_rng(seed), allow_ties=True)
        seen.update(_as_tuple(r) for r in got.values())
    assert seen == set(WEAK_RANKINGS) and len(seen) == 13
    # and the session accepts each, as average ranks
    for ranks in WEAK_RANKINGS:
        normalise_ranks({"c": dict(enumerate(ranks))}, ["c"], True)


def test_ordered_never_ties() -> None:
    got = choose_ranking("ordered", PLAN, None, CRITS, np.random.default_rng(0),
                         condition_order=["a", "b", "c"], allow_ties=True)
    assert got == {c: {0: 2, 1: 3, 2: 1} for c in CRITS}


@pytest.mark.parametrize("scores, gap, ranks", [
    ([1.0, 0.95, 0.0], 0.1, (1, 1, 3)),    # the two best cannot be told apart
    ([0.0, 1.0, 0.05], 0.1, (2, 1, 2)),    # the two worst: competition ranks, 2 and 2
    ([0.5, 0.55, 0.45], 0.1, (1, 1, 1)),   # neighbours chain into one tie
    ([1.0, 0.95, 0.0], None, (1, 2, 3)),   # ties not allowed
    ([1.0, 0.5, 0.0], 0.1, (1, 2, 3)),
])
def test_careful_ties_only_what_it_cannot_tell_apart(scores, gap, ranks) -> None:
    assert _as_tuple(_ranks_from_scores(scores, gap)) == ranks


def _study(folder: Path, allow_ties: bool):
    path = write_synthetic_study(folder, n_stimuli=3, practice=False, allow_ties=allow_ties)
    # An id that no participant text can contain: the design's blinding check refuses texts naming a
    # condition, and "static" is an ordinary word.
    path.write_text(path.read_text().replace('id = "static"', 'id = "pose0"'))
    design = load_design(path)
    return design, ResultsDB(folder / "r.sqlite", design)


def _stored(db, pid: str) -> dict:
    out: dict = {}
    for r in db.responses(pid):
        out.setdefault(r["trial_index"], {}).setdefault(r["criterion"], {})[r["slot"]] = r["rank"]
    return out


def test_careful_bot_ties_on_real_media_only_when_allowed(tmp_path: Path) -> None:
    from studyapp.study.stimuli import load_trial_media

    design, db = _study(tmp_path, True)
    db.close()
    plan = TrialPlan(0, "s1", ("synced", "lagged", "pose0"), False, False, 0)
    media = load_trial_media(design, plan)
    tied = strict = 0
    for seed in range(60):
        with_ties = choose_ranking("careful", plan, media, design.criteria, np.random.default_rng(seed),
                                   allow_ties=True)
        without = choose_ranking("careful", plan, media, design.criteria, np.random.default_rng(seed))
        for c in with_ties:
            assert _as_tuple(with_ties[c]) in WEAK_RANKINGS
            assert sorted(without[c].values()) == [1, 2, 3]
            if len(set(with_ties[c].values())) < 3:
                tied += 1
            else:
                strict += 1
    assert tied > 0 and strict > 0


def test_bot_session_stores_tied_ranks_when_the_design_allows_them(tmp_path: Path) -> None:
    design, db = _study(tmp_path / "ties", True)
    session = run_bot_session(design, db, "P1", "random", 4)
    stored = _stored(db, "P1")
    expected = {}
    for plan in session.plans:
        chosen = choose_ranking("random", plan, None, design.criteria, trial_rng(4, "P1", plan.trial_index),
                                allow_ties=True)
        expected[plan.trial_index] = {c: dict(enumerate(v))
                                      for c, v in normalise_ranks(chosen, [c.id for c in design.criteria],
                                                                  True).items()}
    assert stored == expected
    ranks = [tuple(v[s] for s in range(3)) for trial in stored.values() for v in trial.values()]
    assert any(len(set(r)) < 3 for r in ranks), ranks   # seed 4 gives ties: the path is exercised
    db.close()

    design, db = _study(tmp_path / "strict", False)
    run_bot_session(design, db, "P1", "random", 4)
    assert all(sorted(v.values()) == [1.0, 2.0, 3.0] for trial in _stored(db, "P1").values() for v in trial.values())
    db.close()


def test_pilot_without_rendering_builds_each_participants_scene(tmp_path: Path, monkeypatch) -> None:
    """A `run --no-render` pilot walks the participant's path: the same scene builder, the same duration stored,
    and a scene that cannot be built stops the pilot as it would stop the participant's window."""
    import studyapp.render.scene as scene_mod

    design, db = _study(tmp_path, allow_ties=False)
    built = []
    real = scene_mod.build_trial_scene

    def spy(renderer, media, labels=None):
        scene = real(renderer, media, labels)
        built.append((media.plan.trial_index, scene.duration))
        return scene

    monkeypatch.setattr(scene_mod, "build_trial_scene", spy)
    run_bot_session(design, db, "P1", "random", seed=1)
    stored = {t["trial_index"]: t["trial_duration_s"] for t in db.trials("P1")}
    assert sorted(built) == sorted(stored.items()) and len(built) == len(stored) > 0

    def broken(renderer, media, labels=None):
        raise scene_mod.SlotError(1, "m.bvh", "skeleton", "cannot retarget")

    monkeypatch.setattr(scene_mod, "build_trial_scene", broken)
    with pytest.raises(scene_mod.SlotError):
        run_bot_session(design, db, "P2", "random", seed=1)
    assert db.trials("P2") == []
