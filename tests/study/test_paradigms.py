"""Response paradigms (issue 18): [[blocks]] in a design, their balanced schedules, what each trial plays, the
session's answers per paradigm, and schema 6 with its upgrade from 5.

Balance is counted here with plain loops over the trials of ``n_rows`` participants, not with the schedule's
own formulas, so a wrong rotation shows as a wrong count.
"""
from __future__ import annotations

import json
import shutil
import sqlite3
import warnings
from collections import Counter
from itertools import combinations
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from studyapp.resources import demo_design, designs_dir
from studyapp.study import row_checksums
from studyapp.study.design import Block, DesignWarning, load_design, validate_design
from studyapp.study.schedule import n_rows, participant_schedule
from studyapp.study.session import RankingError, Session, SessionError, State
from studyapp.study.storage import SCHEMA_VERSION, ResultsDB

EXAMPLES = {p: designs_dir() / f"{p}_example.toml" for p in ("pairwise", "mismatch", "rating")}
DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.fixture(scope="module")
def examples() -> dict:
    return {p: load_design(path, check_files=False) for p, path in EXAMPLES.items()}


def _plans(design) -> list[list]:
    return [participant_schedule(design, f"P{r:02d}", r) for r in range(n_rows(design))]


# ---------------------------------------------------------------------------------------------------------
# Design


ONE_CRITERION = '[[criteria]]\nid = "realism"\nquestion = "Which looks most natural?"\n'


def _design_text(blocks: str, extra: str = ONE_CRITERION) -> str:
    demo = demo_design().parent
    stimuli = "".join(f'[[stimuli]]\nid = "clip0{i}"\naudio = "{demo}/demo/audio/clip0{i}.wav"\n'
                      f'tags = {{ speaker = "spk{(i + 1) // 2}" }}\n' for i in range(1, 5))
    conds = "".join(f'[[conditions]]\nid = "{c}"\nmotion = "{demo}/demo/motion/{c}/{{stimulus}}.bvh"\n'
                    for c in ("synced", "lagged", "static"))
    return f'title = "t"\n{extra}{conds}{stimuli}{blocks}'


def test_block_problems_are_one_line_each_at_their_line(tmp_path: Path) -> None:
    text = _design_text('''[[blocks]]
id = "a"
paradigm = "pairwise"
conditions = ["synced"]
reference = "static"

[[blocks]]
id = "b"
paradigm = "ranking"

[[blocks]]
id = "c"
paradigm = "rating"
conditions = ["synced", "lagged", "static", "nope"]
reference = "synced"
anchors = ["only one"]

[[blocks]]
id = "d"
paradigm = "mismatch"
match_tag = "site"
levels = 4
''')
    path = tmp_path / "d.toml"
    path.write_text(text)
    lines = text.splitlines()
    problems = validate_design(path, check_files=False)
    got = {(p.key, p.line) for p in problems}

    def line(needle: str, after: int = 0) -> int:
        return next(i + 1 for i, ln in enumerate(lines) if i >= after and ln.startswith(needle))

    b0 = line("[[blocks]]")
    assert ("blocks[0].reference", line("reference", b0)) in got            # pairwise has no reference
    assert ("blocks[0].conditions", line("conditions", b0)) in got          # pairwise needs 2
    assert ("blocks[1].paradigm", line('paradigm = "ranking"')) in got
    c = line('id = "c"')
    assert ("blocks[2].conditions[3]", line("conditions", c)) in got        # unknown condition
    assert ("blocks[2].anchors", line("anchors", c)) in got
    d = line('id = "d"')
    assert ("blocks[3].levels", line("levels", d)) in got
    assert sum(p.key == "blocks[3].match_tag" for p in problems) == 4       # no clip has a "site" tag
    assert all(str(p).count("\n") == 0 for p in problems)
    # the rating block: synced is both a condition and the reference, so 3 known figures: no count problem
    assert not any(p.key == "blocks[2].conditions" for p in problems)


def test_a_lone_clip_of_its_speaker_cannot_be_mismatched(tmp_path: Path) -> None:
    path = tmp_path / "d.toml"
    path.write_text(_design_text('[[blocks]]\nid = "m"\nparadigm = "mismatch"\nstimuli = ["clip01", "clip02", '
                                 '"clip03"]\n'))
    problems = validate_design(path, check_files=False)
    assert [p.key for p in problems] == ["blocks[0].stimuli"]
    assert "'clip03'" in problems[0].message and "speaker" in problems[0].message


def test_attention_checks_need_a_rank_block(tmp_path: Path) -> None:
    path = tmp_path / "d.toml"
    path.write_text(_design_text('[[blocks]]\nid = "p"\nparadigm = "pairwise"\n[[attention_checks]]\n'
                                 'stimulus = "clip01"\n'))
    assert [p.key for p in validate_design(path, check_files=False)] == ["attention_checks"]


def test_attention_checks_are_scored_on_a_criterion_of_the_first_rank_block(tmp_path: Path) -> None:
    path = tmp_path / "d.toml"
    criteria = ONE_CRITERION + ONE_CRITERION.replace("realism", "sync")
    text = _design_text('[[blocks]]\nid = "r"\nparadigm = "rank"\ncriteria = ["sync"]\n[[attention_checks]]\n'
                        'stimulus = "clip01"\n', criteria)
    path.write_text(text)
    problems = validate_design(path, check_files=False)
    assert [p.key for p in problems] == ["attention_checks[0].criterion"] and "'r'" in problems[0].message
    path.write_text(text + 'criterion = "sync"\n')
    assert validate_design(path, check_files=False) == []


def test_a_block_asking_motion_and_speech_together_is_noted_not_refused(tmp_path: Path) -> None:
    path = tmp_path / "d.toml"
    path.write_text(_design_text('[[blocks]]\nid = "p"\nparadigm = "pairwise"\n', ""))  # the default three criteria
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert validate_design(path, check_files=False) == []
    notes = [str(w.message) for w in caught if issubclass(w.category, DesignWarning)]
    assert len(notes) == 1 and "Nagy et al. 2025" in notes[0] and f"{path}:" in notes[0]
    for example in EXAMPLES.values():  # each example asks one aspect per block
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            load_design(example, check_files=False)
        assert not [w for w in caught if issubclass(w.category, DesignWarning)], example.name


def test_a_design_without_blocks_is_one_rank_block_named_main() -> None:
    d = load_design(demo_design(), check_files=False)
    assert d.blocks == []
    assert d.trial_blocks == [Block("main", "rank", tuple(d.criterion_ids), tuple(d.condition_ids),
                                    tuple(d.rotation_stimuli))]
    plans = participant_schedule(d, "P01", 0)
    assert {(p.block, p.paradigm, p.motion_stimuli, len(p.slots)) for p in plans} == {("main", "rank", (), 3)}


@pytest.mark.parametrize("paradigm", list(EXAMPLES))
def test_the_examples_validate_with_their_files(paradigm: str) -> None:
    problems = validate_design(EXAMPLES[paradigm])
    assert problems == [], "\n".join(map(str, problems))


# ---------------------------------------------------------------------------------------------------------
# Schedule: balance counted over n_rows participants


def test_pairwise_pairs_and_sides_are_balanced(examples) -> None:
    d = examples["pairwise"]
    block = d.trial_blocks[0]
    assert n_rows(d) == 12  # lcm(4 Williams rows, 2 x 3 pairs)
    pairs, sides, per_stim = Counter(), Counter(), Counter()
    for plans in _plans(d):
        rated = [p for p in plans if not p.is_practice]
        assert sorted(p.stimulus_id for p in rated) == sorted(block.stimuli)  # each clip once
        for p in rated:
            assert p.paradigm == "pairwise" and len(p.slots) == 2 and p.slots[0] != p.slots[1]
            pairs[frozenset(p.slots)] += 1
            per_stim[p.stimulus_id, frozenset(p.slots)] += 1
            sides[p.slots[0], "left"] += 1
            sides[p.slots[1], "right"] += 1
    all_pairs = {frozenset(x) for x in combinations(block.conditions, 2)}
    assert set(pairs) == all_pairs and len(set(pairs.values())) == 1
    assert len(per_stim) == 4 * 3 and len(set(per_stim.values())) == 1
    assert len(set(sides.values())) == 1 and len(sides) == 6


def test_mismatch_sides_and_sources_are_balanced(examples) -> None:
    d = examples["mismatch"]
    speaker = {s.id: s.tags["speaker"] for s in d.stimuli}
    side, source = Counter(), Counter()
    for plans in _plans(d):
        for p in plans:
            assert p.paradigm == "mismatch" and p.slots[0] == p.slots[1]
            assert sorted(p.motion_stimuli).count(p.stimulus_id) == 1
            other = next(m for m in p.motion_stimuli if m != p.stimulus_id)
            assert speaker[other] == speaker[p.stimulus_id]
            if p.is_practice:
                continue
            matched_left = p.motion_stimuli[0] == p.stimulus_id
            assert p.matched_slot == (0 if matched_left else 1)
            side[p.slots[0], p.stimulus_id, matched_left] += 1
            source[p.stimulus_id, other, matched_left] += 1
    assert len(side) == 3 * 4 * 2 and len(set(side.values())) == 1
    assert len(set(source.values())) == 1


def test_mismatch_sources_rotate_over_every_same_tag_clip() -> None:
    """Three clips of one speaker: each clip's mismatched motion comes from each of the two others equally."""
    d = load_design(EXAMPLES["mismatch"], check_files=False)
    for s in d.stimuli:
        s.tags["speaker"] = "one"
    d.blocks = [Block("m", "mismatch", d.criterion_ids, ("synced",), ("clip01", "clip02", "clip03"))]
    d.practice = []
    rows = n_rows(d)
    assert rows % (2 * 2) == 0
    source = Counter()
    for r in range(rows):
        for p in participant_schedule(d, "P", r):
            other = next(m for m in p.motion_stimuli if m != p.stimulus_id)
            source[p.stimulus_id, other, p.motion_stimuli[0] == p.stimulus_id] += 1
    assert len(source) == 3 * 2 * 2 and len(set(source.values())) == 1


def test_rating_slot_order_is_balanced_with_the_reference_in_every_trial(examples) -> None:
    d = examples["rating"]
    for block in d.trial_blocks:
        assert set(block.figures) == {"synced", "lagged", "static"}
    seat = Counter()
    for plans in _plans(d):
        assert [p.block for p in plans if not p.is_practice] == ["realism"] * 4 + ["speech"] * 3
        for p in plans:
            assert p.paradigm == "rating" and "synced" in p.slots and len(set(p.slots)) == 3
            if not p.is_practice:
                for i, c in enumerate(p.slots):
                    seat[p.block, p.stimulus_id, c, i] += 1
    assert len(seat) == (4 + 3) * 3 * 3 and len(set(seat.values())) == 1


# ---------------------------------------------------------------------------------------------------------
# What a mismatch trial plays


def test_a_mismatch_trial_plays_its_audio_and_face_with_the_other_clips_motion(examples) -> None:
    from studyapp.study.stimuli import load_audio, load_condition_motion, load_trial_media

    d = load_design(EXAMPLES["mismatch"])
    plan = next(p for p in participant_schedule(d, "P01", 0) if not p.is_practice)
    media = load_trial_media(d, plan)
    assert len(media.motions) == 2 and media.labels == ("A", "B") and media.criteria == ("appropriateness",)
    stim = d.stimulus(plan.stimulus_id)
    assert np.array_equal(media.audio.samples, load_audio(stim.audio).samples[:len(media.audio.samples)])
    cond = d.condition(plan.slots[0])
    for slot in (0, 1):
        own = load_condition_motion(d, cond, d.stimulus(plan.motion_stimulus(slot)))
        n = media.motions[slot].n_frames
        assert np.array_equal(media.motions[slot].rotations, own.rotations[:n])
    assert not np.array_equal(media.motions[0].rotations, media.motions[1].rotations)


def test_validate_refuses_a_mismatched_motion_shorter_than_its_trial(tmp_path: Path) -> None:
    """clip02 plays 6.5 s of its own (fine), but its 6.7 s motion is mismatched into clip01's 10 s trial."""
    demo = demo_design().parent
    shutil.copytree(demo / "demo", tmp_path / "demo")
    bvh = tmp_path / "demo/motion/synced/clip02.bvh"
    head, _, data = bvh.read_text().partition("MOTION\n")
    rows = data.splitlines()
    bvh.write_text(head + "MOTION\nFrames: 200\n" + rows[1] + "\n" + "\n".join(rows[2:202]) + "\n")
    text = (_design_text('[[blocks]]\nid = "m"\nparadigm = "mismatch"\nconditions = ["synced"]\n'
                         'stimuli = ["clip01", "clip02"]\n')
            .replace(str(demo) + "/", "").replace('id = "clip02"\n', 'id = "clip02"\nduration_s = 6.5\n'))
    path = tmp_path / "d.toml"
    path.write_text(text)
    problems = validate_design(path)
    assert [p.key for p in problems] == ["conditions[0].motion_end"], "\n".join(map(str, problems))
    assert "clip02 (6.67 s) under clip01 (10.00 s)" in problems[0].message
    path.write_text(text.replace('id = "synced"\n', 'id = "synced"\nmotion_end = "hold"\n'))
    assert validate_design(path) == []


# ---------------------------------------------------------------------------------------------------------
# Session: every trial of each example answered through the Session methods


def _start(s: Session) -> None:
    s.accept_consent()
    s.finish_instructions()
    s.record_env_check({})


def _answer(s: Session, plan, rng: np.random.Generator) -> None:
    block = s.design.block(plan.block)
    if plan.paradigm in ("pairwise", "mismatch"):
        scale = (-2, -1, 0, 1, 2) if block.levels == 5 else (-1, 0, 1)
        levels = {c: int(rng.choice(scale)) for c in block.criteria}
        reasons = list(block.reasons[:1]) if any(levels.values()) else []
        s.submit_preference(levels, reasons)
    elif plan.paradigm == "rating":
        s.submit_ratings({c: {i: float(rng.integers(0, 101)) for i in range(len(plan.slots))}
                          for c in block.criteria})
    else:
        s.submit_ranking({c: {0: 1, 1: 2, 2: 3} for c in block.criteria})


def _run(design, db, pid: str, seed: int, stop_after: int | None = None) -> tuple[Session, list[str]]:
    s = Session(design, db, pid)
    _start(s)
    rng = np.random.default_rng(seed)
    intros = []
    answered = 0
    while s.current_trial() is not None and (stop_after is None or answered < stop_after):
        text = s.block_instructions()
        if text is not None:
            intros.append(s.current_trial().block)
            s.finish_block_instructions()
        s.record_play_started()
        s.record_play_finished(True)
        _answer(s, s.current_trial(), rng)
        answered += 1
    return s, intros


@pytest.mark.parametrize("paradigm", list(EXAMPLES))
def test_every_trial_of_each_example_is_answered_and_stored(paradigm: str, examples, tmp_path: Path) -> None:
    d = examples[paradigm]
    with ResultsDB(tmp_path / "r.sqlite", d) as db:
        for k in range(3):
            s, intros = _run(d, db, f"P{k}", k)
            assert s.state is State.DONE
            assert intros == [b.id for b in d.trial_blocks]  # each block's page once, before its first trial
            plans = s.plans
            trials = db.trials(f"P{k}")
            assert [(t["block"], t["paradigm"]) for t in trials] == [(p.block, p.paradigm) for p in plans]
            slots = db.trial_slots(f"P{k}")
            assert [(r["trial_index"], r["slot"], r["condition"], r["motion_stimulus"]) for r in slots] == [
                (p.trial_index, i, c, p.motion_stimulus(i)) for p in plans for i, c in enumerate(p.slots)]
            judged = db.judgements(f"P{k}")
            assert db.responses(f"P{k}") == []
            n_crit = {b.id: len(b.criteria) for b in d.trial_blocks}
            assert len(judged) == sum(n_crit[p.block] * len(p.slots) for p in plans)
            by_trial: dict = {}
            for j in judged:
                by_trial.setdefault((j["trial_index"], j["criterion"]), []).append(j)
            for (t, _), rows in by_trial.items():
                plan = plans[t]
                assert [r["condition"] for r in rows] == list(plan.slots)
                if paradigm == "rating":
                    assert all(0 <= r["value"] <= 100 for r in rows)
                else:
                    assert rows[0]["value"] == -rows[1]["value"] and rows[0]["value"] in (-2, -1, 0, 1, 2)
                    assert rows[0]["reasons"] == rows[1]["reasons"]
                    chosen = json.loads(rows[0]["reasons"])
                    assert chosen == ([] if rows[0]["value"] == 0 or paradigm == "mismatch" else ["Hand and arm movement"])
        assert row_checksums.verify(db.connection) == []


def test_preference_is_stored_for_each_slot_left_negative(examples, tmp_path: Path) -> None:
    d = examples["pairwise"]
    with ResultsDB(tmp_path / "r.sqlite", d) as db:
        s = Session(d, db, "P1")
        _start(s)
        s.finish_block_instructions()
        s.record_play_started()
        s.record_play_finished(True)
        plan = s.current_trial()
        s.submit_preference({"human_likeness": -2}, ["Smoothness", "Hand and arm movement"])  # left clearly
        rows = db.judgements("P1")
    assert [(r["slot"], r["condition"], r["value"]) for r in rows] == [(0, plan.slots[0], 2.0), (1, plan.slots[1], -2.0)]
    assert json.loads(rows[0]["reasons"]) == ["Hand and arm movement", "Smoothness"]  # the block's order


def test_wrong_answers_are_refused_with_a_message_and_nothing_stored(examples, tmp_path: Path) -> None:
    d = examples["pairwise"]
    with ResultsDB(tmp_path / "r.sqlite", d) as db:
        s = Session(d, db, "P1")
        _start(s)
        with pytest.raises(SessionError, match="instructions come first"):
            s.record_play_started()
        s.finish_block_instructions()
        with pytest.raises(RankingError, match="watch the clip"):
            s.submit_preference({"human_likeness": 1})
        s.record_play_started()
        s.record_play_finished(True)
        for levels, reasons, message in [
            ({}, [], "choose an answer for 'human_likeness'"),
            ({"human_likeness": 3}, [], "choose one of -2, -1, 0, 1, 2"),
            ({"human_likeness": 1.5}, [], "choose one of"),
            ({"human_likeness": True}, [], "choose one of"),
            ({"human_likeness": 1, "x": 1}, [], "unknown question"),
            ({"human_likeness": 1}, ["Looks"], "unknown reason"),
            ({"human_likeness": 0}, ["Smoothness"], "only when you prefer"),
        ]:
            with pytest.raises(RankingError, match=message):
                s.submit_preference(levels, reasons)
        with pytest.raises(SessionError, match="submit_preference"):
            s.submit_ratings({"human_likeness": {0: 1, 1: 2}})
        with pytest.raises(SessionError, match="submit_preference"):
            s.submit_ranking({"human_likeness": {0: 1, 1: 2, 2: 3}})
        assert db.trials("P1") == [] and db.judgements("P1") == []
    d = examples["rating"]
    with ResultsDB(tmp_path / "q.sqlite", d) as db:
        s = Session(d, db, "P1")
        _start(s)
        s.finish_block_instructions()
        s.record_play_started()
        s.record_play_finished(True)
        for ratings, message in [
            ({"realism": {0: 50, 1: 50}}, r"move every slider for 'realism' \(1 not yet moved\)"),
            ({"realism": {0: 50, 1: 50, 2: 101}}, "from 0 to 100"),
            ({"realism": {0: 50, 1: 50, 2: float("nan")}}, "from 0 to 100"),
            ({"realism": {0: 50, 1: 50, 3: 5}}, "no slot 3"),
        ]:
            with pytest.raises(RankingError, match=message):
                s.submit_ratings(ratings)
        assert db.trials("P1") == []
        s.submit_ratings({"realism": {0: 0, 1: 100, "2": 37.5}})
        assert [r["value"] for r in db.judgements("P1")] == [0.0, 100.0, 37.5]


def test_resume_continues_at_the_first_unanswered_trial_and_shows_block_pages_once(examples, tmp_path: Path) -> None:
    d = examples["rating"]
    first_block = sum(1 for p in participant_schedule(d, "P1", 0) if p.block == "realism")
    with ResultsDB(tmp_path / "r.sqlite", d) as db:
        _, intros = _run(d, db, "P1", 0, stop_after=2)               # practice + first rated, inside "realism"
        assert intros == ["realism"]
        s, intros = _run(d, db, "P1", 0, stop_after=first_block - 2)  # the rest of "realism": no page again
        assert intros == [] and s.current_trial().block == "speech"
        s.close()
        s, intros = _run(d, db, "P1", 0)                              # resumes at the first trial of "speech"
        assert intros == ["speech"] and s.state is State.DONE
        assert [t["trial_index"] for t in db.trials("P1")] == list(range(len(s.plans)))


# ---------------------------------------------------------------------------------------------------------
# Storage: schema 6 and the upgrade of a schema 5 database


def _table(con: sqlite3.Connection, table: str) -> list[tuple]:
    return sorted(tuple(r) for r in con.execute(f"SELECT * FROM {table}"))


def test_a_schema_5_database_made_by_the_old_code_is_upgraded_in_place(tmp_path: Path) -> None:
    """tests/data/results_schema5.sqlite was written by studyapp before schema 6 (two bot participants of a
    generated study): upgraded in place, every row it held is unchanged, every checksum verifies."""
    from results_analysis import integrity

    path = tmp_path / "r.sqlite"
    shutil.copy(DATA / "results_schema5.sqlite", path)
    with sqlite3.connect(path) as con:
        assert con.execute("SELECT version FROM schema_version").fetchone()[0] == 5
        before = {t: _table(con, t) for t in ("trials", "responses", "participants", "plays", "questionnaire")}
        assert not con.execute("SELECT 1 FROM sqlite_master WHERE name = 'judgements'").fetchone()
    con.close()
    with ResultsDB(path, create=False) as db:
        con = db.connection
        assert con.execute("SELECT version FROM schema_version").fetchone()[0] == SCHEMA_VERSION == 7
        assert row_checksums.verify(con) == []
        after = _table(con, "trials")
        assert [r[:-2] for r in after] == before["trials"] and {r[-2:] for r in after} == {(None, None)}
        for t in ("responses", "participants", "plays", "questionnaire"):
            assert _table(con, t) == before[t]
        assert db.trial_slots() == [] and db.judgements() == []
    with sqlite3.connect(path) as con:
        assert integrity.damaged_rows(con) == []
    con.close()


# ---------------------------------------------------------------------------------------------------------
# Merge: returned preference and rating answers are re-checked


def _quick_copy(paradigm: str, folder: Path) -> Path:
    """The example next to a link to the demo's files, without must_watch_fully (answers come at once)."""
    folder.mkdir()
    (folder / "demo").symlink_to(designs_dir() / "demo", target_is_directory=True)
    text = EXAMPLES[paradigm].read_text().replace("must_watch_fully = true", "must_watch_fully = false")
    path = folder / EXAMPLES[paradigm].name
    path.write_text(text)
    return path


def _edited_zip(src: Path, out: Path, edit) -> Path:
    import hashlib
    import zipfile

    with zipfile.ZipFile(src) as zf:
        payload = json.loads(zf.read("results.json"))
        manifest = json.loads(zf.read("manifest.json"))
    edit(payload)
    body = json.dumps(payload, indent=1, sort_keys=True).encode()
    manifest["files"]["results.json"] = hashlib.sha256(body).hexdigest()
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr("results.json", body)
        zf.writestr("manifest.json", json.dumps(manifest))
    return out


def _first(payload: dict, table: str, **match) -> dict:
    return next(r for r in payload[table] if all(r.get(k) == v for k, v in match.items()))


def _pairwise_not_opposite(p: dict) -> None:
    t = next(t["trial_index"] for t in p["trials"] if not t["is_practice"])
    _first(p, "judgements", trial_index=t, slot=0)["value"] = 1.0
    _first(p, "judgements", trial_index=t, slot=1)["value"] = 1.0


def _pairwise_level_off_scale(p: dict) -> None:
    for r in p["judgements"]:
        if r["trial_index"] == 1:
            r["value"] = 3.0 if r["slot"] == 1 else -3.0


def _pairwise_invented_reason(p: dict) -> None:
    for r in p["judgements"]:
        if r["trial_index"] == 1:
            r["value"] = 1.0 if r["slot"] == 1 else -1.0
            r["reasons"] = json.dumps(["Colour"])


def _pairwise_ranked(p: dict) -> None:
    p["responses"].append({"participant": p["participant"], "trial_index": 1, "criterion": "human_likeness",
                           "condition": p["trial_slots"][2]["condition"], "slot": 0, "rank": 1.0,
                           "design_hash": p["design_hash"], "app_version": "x"})


def _mismatch_other_motion(p: dict) -> None:
    row = _first(p, "trial_slots", trial_index=1, slot=0)
    row["motion_stimulus"] = "clip04" if row["motion_stimulus"] != "clip04" else "clip03"


def _rating_slider_missing(p: dict) -> None:
    p["judgements"].remove(_first(p, "judgements", trial_index=1, slot=2))


def _rating_over_100(p: dict) -> None:
    _first(p, "judgements", trial_index=1, slot=0)["value"] = 140.0


EDITS = [
    ("pairwise", _pairwise_not_opposite, "are not a preference: the two slots get -p and p"),
    ("pairwise", _pairwise_level_off_scale, "p one of [-2, -1, 0, 1, 2]"),
    ("pairwise", _pairwise_invented_reason, "reasons ['Colour'] are not some of the block's reasons"),
    ("pairwise", _pairwise_ranked, "trial 1: ranks on a pairwise trial"),
    ("mismatch", _mismatch_other_motion, "trial 1: its slots (condition, motion of which clip, sample)"),
    ("rating", _rating_slider_missing, "needs one answer for each of the 3 slots"),
    ("rating", _rating_over_100, "are not all in 0..100"),
]


@pytest.mark.parametrize("paradigm", list(EXAMPLES))
def test_returned_answers_of_each_paradigm_merge_and_edits_are_refused(paradigm: str, tmp_path: Path) -> None:
    from studyapp.study.bundle import merge_results, write_results_file

    design_path = _quick_copy(paradigm, tmp_path / "study")
    d = load_design(design_path, check_files=False)
    with ResultsDB(tmp_path / "remote.sqlite", d) as db:
        _run(d, db, "P1", 3)
        results = write_results_file(db, "P1", tmp_path / "out")
        stored = (db.trial_slots("P1"), db.judgements("P1"))
    for k, (_, edit, message) in enumerate(e for e in EDITS if e[0] == paradigm):
        lab = design_path.with_name(f"lab{k}.sqlite")
        ResultsDB(lab, d).close()
        [report] = merge_results(lab, [_edited_zip(results, tmp_path / f"edit{k}.zip", edit)], design=design_path)
        assert not report.ok and any(message in p for p in report.problems), (report.message, report.problems)
        with ResultsDB(lab, create=False) as db:
            assert db.trials() == [] and db.judgements() == []
    lab = design_path.with_name("lab.sqlite")
    ResultsDB(lab, d).close()
    [report] = merge_results(lab, [results], design=design_path)
    assert report.ok, report.problems
    with ResultsDB(lab, create=False) as db:
        assert [{k: v for k, v in r.items() if k != "app_version"} for r in db.trial_slots("P1")] == [
            {k: v for k, v in r.items() if k != "app_version"} for r in stored[0]]
        assert [(r["trial_index"], r["slot"], r["value"], r["reasons"]) for r in db.judgements("P1")] == [
            (r["trial_index"], r["slot"], r["value"], r["reasons"]) for r in stored[1]]
    [again] = merge_results(lab, [results], design=design_path)
    assert again.ok and again.already


# ---------------------------------------------------------------------------------------------------------
# Bundles: the paradigms shipped blinded, run remotely, merged back


@pytest.mark.parametrize("paradigm", ["mismatch", "rating"])  # pairwise ships as rating does (2 tokens shown)
def test_a_bundle_ships_each_paradigm_blinded_and_its_answers_merge_back(paradigm: str, tmp_path: Path) -> None:
    import zipfile

    from studyapp.study.bundle import make_bundle, merge_results, open_bundle, remote_plan, write_results_file

    design_path = _quick_copy(paradigm, tmp_path / "study")
    lab = design_path.with_name("lab.sqlite")
    bundle = tmp_path / "send" / "study.zip"
    make_bundle(design_path, bundle, participants=1, results=lab, salt="s" * 32)  # checks both designs' files
    d = load_design(design_path, check_files=False)
    with zipfile.ZipFile(bundle) as zf:
        shipped = zf.read("study.toml").decode()
        names = [n for n in zf.namelist() if n.startswith("media/")]
    import re

    for secret in (*d.condition_ids, *(s.id for s in d.stimuli)):
        assert not re.search(rf"\b{secret}\b", shipped), secret
    assert not re.search(r"^\s*(reference|match_tag = \"speaker\"|speaker)\s*=", shipped, re.M)
    assert len(names) == len(set(names))
    opened = open_bundle(bundle, tmp_path / "cache")
    carried = remote_plan(opened, "R01")
    remote = load_design(opened.design_path, check_files=False)
    expected = participant_schedule(d, "R01", carried.row)
    assert [(p.block, p.paradigm, len(p.slots)) for p in carried.plans] == [
        (p.block, p.paradigm, len(p.slots)) for p in expected]
    with ResultsDB(tmp_path / "remote.sqlite", remote) as db:
        s = Session(remote, db, "R01", row=carried.row, plans=carried.plans, n_rows=carried.n_rows)
        _start(s)
        rng = np.random.default_rng(1)
        while s.current_trial() is not None:
            if s.block_instructions() is not None:
                s.finish_block_instructions()
            s.record_play_started()
            s.record_play_finished(True)
            _answer(s, s.current_trial(), rng)
        results = write_results_file(db, "R01", tmp_path / "out", opened)
        answers = [(r["trial_index"], r["slot"], r["value"]) for r in db.judgements("R01")]
    [report] = merge_results(lab, [results], design=design_path)
    assert report.ok, report.problems
    with ResultsDB(lab, create=False) as db:
        slots = db.trial_slots("R01")
        assert [(r["trial_index"], r["slot"], r["condition"], r["motion_stimulus"], r["sample"]) for r in slots] == [
            (p.trial_index, i, c, p.motion_stimulus(i), p.samples[i]) for p in expected for i, c in enumerate(p.slots)]
        assert [(r["trial_index"], r["slot"], r["value"]) for r in db.judgements("R01")] == answers
        assert {r["condition"] for r in db.judgements("R01")} <= set(d.condition_ids)


# ---------------------------------------------------------------------------------------------------------
# Export: the tidy table's paradigm columns


def test_the_export_has_each_answer_once_in_its_paradigm_columns(examples, tmp_path: Path) -> None:
    from results_analysis.loader import load_results
    from studyapp.study.export import export_dataframe

    d = load_design(EXAMPLES["mismatch"], check_files=False)
    r = load_design(EXAMPLES["rating"], check_files=False)
    r.blocks = [*r.blocks, Block("pw", "pairwise", ("realism",), ("lagged", "static"), ("clip02", "clip03"),
                                 reasons=("Hands",))]
    r.blocks = [Block("rk", "rank", ("realism",), ("synced", "lagged", "static"), ("clip01", "clip04")), *r.blocks]
    for design, name in ((d, "m"), (r, "r")):
        with ResultsDB(tmp_path / f"{name}.sqlite", design) as db:
            _run(design, db, "P1", 5)
            judged = {(j["trial_index"], j["criterion"], j["slot"]): j for j in db.judgements("P1")}
            ranked = {(x["trial_index"], x["criterion"], x["slot"]): x for x in db.responses("P1")}
            plans = {p.trial_index: p for p in participant_schedule(design, "P1", db.participant("P1").latin_row)}
            df = export_dataframe(db)
        assert len(df) == len(judged) + len(ranked)
        for row in df.itertuples():
            plan = plans[row.trial_index]
            assert (row.block, row.paradigm, row.motion_stimulus) == (
                plan.block, plan.paradigm, plan.motion_stimulus(row.slot))
            key = (row.trial_index, row.criterion, row.slot)
            if plan.paradigm == "rank":
                assert row.rank == ranked[key]["rank"] and np.isnan(row.rating) and np.isnan(row.preference)
                continue
            j = judged[key]
            assert np.isnan(row.rank) and row.condition == j["condition"]
            if plan.paradigm == "rating":
                assert row.rating == j["value"] and np.isnan(row.preference) and row.reasons == ""
            else:
                assert row.preference == j["value"] and np.isnan(row.rating)
                assert row.reasons == ("" if j["reasons"] == "[]" else j["reasons"])
            if plan.paradigm == "mismatch":
                assert row.matched == int(plan.motion_stimuli[row.slot] == plan.stimulus_id)
            else:
                assert row.matched is pd.NA
        csv = tmp_path / f"{name}.csv"
        df.to_csv(csv, index=False)
        for source in (csv, tmp_path / f"{name}.sqlite"):
            loaded = load_results(source)
            assert list(loaded["paradigm"]) == list(df["paradigm"])
            assert np.allclose(loaded["preference"], df["preference"], equal_nan=True)
            assert np.allclose(loaded["rating"], df["rating"], equal_nan=True)
    old = tmp_path / "old.csv"  # an export before schema 6: a rank study
    old.write_text("participant,trial_index,stimulus,criterion,condition,rank\nP1,0,c1,realism,A,1\n"
                   "P1,0,c1,realism,B,2\n")
    loaded = load_results(old)
    assert list(loaded["paradigm"]) == ["rank", "rank"] and list(loaded["block"]) == ["main", "main"]
    assert list(loaded["motion_stimulus"]) == ["c1", "c1"]


def test_a_scene_holds_up_to_four_figures() -> None:
    from studyapp.motion.skeleton import Motion
    from studyapp.render.avatar import build_default_avatar
    from studyapp.render.pose import prepare_slot
    from studyapp.render.scene import MAX_SLOTS, make_scene

    av = build_default_avatar()
    slot = prepare_slot(av, Motion.rest(av.skeleton, n_frames=3, fps=30.0), None)
    assert MAX_SLOTS == 4 and make_scene([slot] * 4, av, labels=("A", "B", "C", "D")).n_slots == 4
    with pytest.raises(ValueError, match="1 to 4 slots"):
        make_scene([slot] * 5, av)


def test_row_checksums_cover_judgements_and_trial_slots(examples, tmp_path: Path) -> None:
    from studyapp.errors import InputError

    d = examples["pairwise"]
    path = tmp_path / "r.sqlite"
    with ResultsDB(path, d) as db:
        _run(d, db, "P1", 2, stop_after=2)
    for table, column in (("judgements", "value"), ("trial_slots", "motion_stimulus")):
        copy = tmp_path / f"{table}.sqlite"
        shutil.copy(path, copy)
        with sqlite3.connect(copy) as con:
            con.execute(f"UPDATE {table} SET {column} = {column} || 'x' WHERE rowid = 1" if column != "value" else
                        f"UPDATE {table} SET value = -value + 0.5 WHERE rowid = 1")
        con.close()
        with pytest.raises(InputError, match=f"table {table}, row .*does not match its checksum"):
            ResultsDB(copy, create=False)
