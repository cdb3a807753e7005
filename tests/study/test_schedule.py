"""Participant schedules: balance over participants, reproducibility, practice and attention-check rules."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from studyapp.study.design import AttentionCheck, Condition, Design, Stimulus, DEFAULT_CRITERIA
from studyapp.study.ordering import williams_square
from studyapp.study.schedule import (SCHEDULE_COLUMNS, attention_positions, balance_counts, full_schedule, n_rows,
                                     participant_schedule)


def make_design(n_stimuli: int = 8, *, ordering: str = "balanced-latin-square", slots: str = "balanced",
                practice: list[str] | None = None, checks: list[AttentionCheck] | None = None,
                extra: list[str] = (), seed: int = 3) -> Design:
    """An in-memory design (no files needed: schedules never open stimuli)."""
    stims = [Stimulus(f"c{i + 1}", Path(f"/x/c{i + 1}.wav")) for i in range(n_stimuli)]
    stims += [Stimulus(sid, Path(f"/x/{sid}.wav"), in_rotation=False) for sid in extra]
    conds = [Condition("m1", motion="a/{stimulus}.bvh"), Condition("m2", motion="b/{stimulus}.bvh"),
             Condition("m3", motion="c/{stimulus}.bvh")]
    return Design(path=Path("/x/d.toml"), title="t", instructions="", conditions=conds, stimuli=stims,
                  criteria=list(DEFAULT_CRITERIA), ordering=ordering, slot_assignment=slots,
                  practice=practice or [], attention_checks=checks or [], seed=seed)


def rated(df: pd.DataFrame) -> pd.DataFrame:
    return df[~df.is_practice & ~df.is_attention_check]


@pytest.mark.parametrize("n_stimuli", [2, 3, 4, 5, 8])
def test_full_balance_after_n_rows_participants(n_stimuli: int) -> None:
    d = make_design(n_stimuli)
    rows = n_rows(d)
    assert rows == int(np.lcm(n_stimuli if n_stimuli % 2 == 0 else 2 * n_stimuli, 6))
    df = full_schedule(d, rows)
    assert list(df.columns) == SCHEDULE_COLUMNS and len(df) == rows * n_stimuli
    counts = balance_counts(df)
    pos = counts["position_x_stimulus"]
    assert pos.shape == (n_stimuli, n_stimuli) and (pos.to_numpy() == rows // n_stimuli).all()
    slots = counts["slot_x_condition"]
    assert list(slots.columns) == ["left", "middle", "right"] and sorted(slots.index) == ["m1", "m2", "m3"]
    assert (slots.to_numpy() == rows * n_stimuli // 3).all()


def test_clip_order_follows_williams_rows() -> None:
    d = make_design(4)
    sq = williams_square(4)
    for row in range(n_rows(d)):
        order = [p.stimulus_id for p in participant_schedule(d, "anyone", row)]
        assert order == [f"c{i + 1}" for i in sq[row % 4]]


@pytest.mark.parametrize("n_stimuli", [1, 2, 4, 7, 8, 11])
def test_slots_balanced_within_each_participant(n_stimuli: int) -> None:
    d = make_design(n_stimuli)
    for row in range(12):
        plans = participant_schedule(d, f"P{row}", row)
        counts = np.zeros((3, 3), int)
        for p in plans:
            for s, cid in enumerate(p.slots):
                counts[int(cid[1]) - 1, s] += 1
        assert counts.max() - counts.min() <= 1, (n_stimuli, row, counts)


@pytest.mark.parametrize("n_participants", [6, 12, 18, 30])
def test_slot_totals_equal_for_multiples_of_six(n_participants: int) -> None:
    for n_stimuli in (3, 4, 8):
        slots = balance_counts(full_schedule(make_design(n_stimuli), n_participants))["slot_x_condition"]
        assert len(set(slots.to_numpy().ravel())) == 1, (n_stimuli, n_participants, slots)


def test_same_inputs_give_identical_frames_and_ids_matter() -> None:
    d = make_design(8, slots="random", ordering="random")
    a, b = full_schedule(d, 10), full_schedule(make_design(8, slots="random", ordering="random"), 10)
    pd.testing.assert_frame_equal(a, b)
    p1 = participant_schedule(d, "alice", 0)
    assert p1 == participant_schedule(d, "alice", 0)
    p2 = participant_schedule(d, "bob", 0)
    assert [p.slots for p in p1] != [p.slots for p in p2]
    assert [p.stimulus_id for p in p1] != [p.stimulus_id for p in p2]
    # And another design seed changes them.
    assert [p.slots for p in participant_schedule(make_design(8, slots="random", seed=4), "alice", 0)] != \
        [p.slots for p in p1]


def test_balanced_neighbours_get_different_slot_permutations() -> None:
    d = make_design(8)
    seqs = [tuple(p.slots for p in participant_schedule(d, f"P{k}", k)) for k in range(6)]
    assert len(set(seqs)) == 6
    for t in range(8):
        assert len({s[t] for s in seqs}) == 6  # all 6 permutations at every trial position


def test_schedule_is_identical_in_another_process(tmp_path: Path) -> None:
    here = Path(__file__).resolve()
    code = (f"import sys; sys.path.insert(0, {str(here.parent)!r}); from test_schedule import make_design; "
            "from studyapp.study.schedule import full_schedule; "
            "full_schedule(make_design(8, slots='random', ordering='random'), 5).to_csv(sys.argv[1], index=False)")
    out = tmp_path / "plan.csv"
    subprocess.run([sys.executable, "-c", code, str(out)], check=True, env={"PYTHONHASHSEED": "12345", "PATH": ""})
    mine = full_schedule(make_design(8, slots="random", ordering="random"), 5)
    pd.testing.assert_frame_equal(pd.read_csv(out), mine, check_dtype=False)


def test_row_none_is_derived_from_the_participant_id() -> None:
    d = make_design(4)
    a = participant_schedule(d, "P42")
    assert a == participant_schedule(d, "P42") and 0 <= a[0].row < n_rows(d)
    rows = {participant_schedule(d, f"Q{i}")[0].row for i in range(60)}
    assert len(rows) > 6  # ids spread over the rows
    with pytest.raises(ValueError):
        participant_schedule(d, "P1", -1)


def test_fixed_and_random_ordering() -> None:
    fixed = make_design(5, ordering="fixed")
    for row in range(6):
        assert [p.stimulus_id for p in participant_schedule(fixed, "x", row)] == ["c1", "c2", "c3", "c4", "c5"]
    assert n_rows(fixed) == 6 and n_rows(make_design(5, ordering="fixed", slots="random")) == 1
    rnd = make_design(8, ordering="random")
    orders = {tuple(p.stimulus_id for p in participant_schedule(rnd, f"P{i}", 0)) for i in range(20)}
    assert len(orders) == 20
    for o in orders:
        assert sorted(o) == sorted(f"c{i + 1}" for i in range(8))


def test_practice_first_and_attention_checks_at_documented_positions() -> None:
    checks = [AttentionCheck("att", "frozen", {"criterion": "realism", "rank": 3}),
              AttentionCheck("c2", "known-worst", {"criterion": "diversity", "rank": 3, "condition": "m3"})]
    d = make_design(8, practice=["prac", "c1"], checks=checks, extra=["prac", "att"])
    assert attention_positions(8, 2) == [2, 5]
    for row in range(12):
        plans = participant_schedule(d, "P", row)
        assert [p.trial_index for p in plans] == list(range(12))
        assert [p.stimulus_id for p in plans[:2]] == ["prac", "c1"] and all(p.is_practice for p in plans[:2])
        kinds = ["P" if p.is_practice else "A" if p.is_attention_check else "R" for p in plans]
        att1, att2 = [p for p in plans if p.is_attention_check]
        # Nominal places: after rated trials 2 and 5; the c2 check moves off a neighbouring rated c2.
        assert "".join(kinds[:7]) == "PP" + "RR" + "A" + "RR" and kinds.count("A") == 2
        assert plans[plans.index(att2) - 1].stimulus_id != "c2"
        nxt = plans.index(att2) + 1
        assert nxt == len(plans) or plans[nxt].stimulus_id != "c2"
        rated_before = sum(1 for p in plans[:plans.index(att2)] if kinds[p.trial_index] == "R")
        assert abs(rated_before - 5) <= 2
        assert att1.stimulus_id == "att" and att2.stimulus_id == "c2"
        frozen = [s for s in att1.slots if s.startswith("frozen:")]
        assert len(frozen) == 1 and att1.slots.index(frozen[0]) == row % 3
        assert sorted(s.removeprefix("frozen:") for s in att1.slots) == ["m1", "m2", "m3"]
        assert sorted(att2.slots) == ["m1", "m2", "m3"]
        assert checks[0].passed(att1.slots, {"realism": [3 if s.startswith("frozen:") else 1.5 for s in att1.slots]})
        # Rated trials cover each rotation stimulus exactly once; practice and checks are extra.
        assert sorted(p.stimulus_id for p in plans if kinds[p.trial_index] == "R") == sorted(f"c{i + 1}" for i in range(8))


def test_attention_check_rule_with_ties() -> None:
    c = AttentionCheck("s", "frozen", {"criterion": "realism", "rank": 3})
    slots = ("a", "frozen:b", "c")
    assert c.passed(slots, {"realism": (1, 3, 2)})
    assert not c.passed(slots, {"realism": (3, 1, 2)})
    assert c.passed(slots, {"realism": (1, 2.5, 2.5)})      # averaged tie covering rank 3
    assert c.passed(slots, {"realism": (1, 2, 2)})          # min-rank tie covering rank 3
    assert c.passed(slots, {"realism": (2, 2, 1)})          # tie over positions 2..3 covers 3
    assert not c.passed(slots, {"realism": (1, 1, 3)})      # tie over positions 1..2 does not
    k = AttentionCheck("s", "known-worst", {"criterion": "diversity", "rank": 3, "condition": "c"})
    assert k.passed(slots, {"diversity": (1, 2, 3)}) and not k.passed(slots, {"diversity": (3, 2, 1)})
