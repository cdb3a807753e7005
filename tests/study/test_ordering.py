"""Williams squares and slot permutations: the balance properties the study's analysis relies on."""
from __future__ import annotations

from collections import Counter
from itertools import permutations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from studyapp.study.ordering import (ALL_PERMS, EVEN_PERMS, ODD_PERMS, n_latin_rows, participant_seed,
                                     slot_permutations, williams_square)


def test_williams_4_matches_the_published_square() -> None:
    # Williams (1949) / Bradley (1958) design for four treatments (A=0, B=1, C=2, D=3): ABDC, BCAD, CDBA, DACB.
    assert williams_square(4).tolist() == [[0, 1, 3, 2], [1, 2, 0, 3], [2, 3, 1, 0], [3, 0, 2, 1]]


def test_williams_3_is_all_six_orders() -> None:
    sq = williams_square(3)
    assert sq.shape == (6, 3)
    assert {tuple(r) for r in sq.tolist()} == set(permutations(range(3)))


@pytest.mark.parametrize("n", range(2, 17))
def test_williams_properties(n: int) -> None:
    sq = williams_square(n)
    rows = n if n % 2 == 0 else 2 * n
    assert sq.shape == (rows, n) == (n_latin_rows(n), n)
    assert sq[0].tolist()[:3] == [0, 1, n - 1][:min(3, n)]
    for r in sq:
        assert sorted(r.tolist()) == list(range(n))
    # Every block of n rows: each treatment once per position.
    for block in range(rows // n):
        part = sq[block * n:(block + 1) * n]
        for pos in range(n):
            assert sorted(part[:, pos].tolist()) == list(range(n)), (n, block, pos)
    # Every ordered pair of distinct treatments is adjacent equally often (1x even, 2x odd).
    pairs = Counter((int(a), int(b)) for r in sq for a, b in zip(r[:-1], r[1:]))
    assert len(pairs) == n * (n - 1)
    assert set(pairs.values()) == {1 if n % 2 == 0 else 2}


def test_williams_rejects_nonsense() -> None:
    with pytest.raises(ValueError):
        williams_square(0)
    assert williams_square(1).tolist() == [[0]]


def test_perm_sets_are_latin_squares() -> None:
    for square in (EVEN_PERMS, ODD_PERMS):
        arr = np.array(square)
        for s in range(3):
            assert sorted(arr[:, s].tolist()) == [0, 1, 2]
    assert set(EVEN_PERMS) | set(ODD_PERMS) == set(ALL_PERMS) and len(ALL_PERMS) == 6


def _slot_counts(perms: list[tuple[int, int, int]]) -> np.ndarray:
    counts = np.zeros((3, 3), int)  # condition x slot
    for p in perms:
        for slot, cond in enumerate(p):
            counts[cond, slot] += 1
    return counts


@pytest.mark.parametrize("k", range(12))
def test_balanced_slots_within_participant_every_prefix(k: int) -> None:
    perms = slot_permutations(40, 0, k, "balanced")
    for t in range(1, len(perms) + 1):
        c = _slot_counts(perms[:t])
        assert c.max() - c.min() <= 1, (k, t, c)
        assert c.sum() == 3 * t


def test_balanced_slots_eight_trials_counts_differ_by_at_most_one() -> None:
    for k in range(6):
        c = _slot_counts(slot_permutations(8, 123, k, "balanced"))
        assert set(np.unique(c)) <= {2, 3}, c


@pytest.mark.parametrize("n_trials", [1, 2, 3, 4, 5, 7, 8, 12, 13])
def test_six_consecutive_participants_see_all_permutations_at_every_trial(n_trials: int) -> None:
    for start in range(6):
        seqs = [slot_permutations(n_trials, 0, k, "balanced") for k in range(start, start + 6)]
        for t in range(n_trials):
            assert {s[t] for s in seqs} == set(ALL_PERMS), (start, t)


@given(n_trials=st.integers(1, 30), n_participants=st.integers(1, 5).map(lambda m: 6 * m))
@settings(max_examples=40, deadline=None)
def test_balanced_slots_across_participants(n_trials: int, n_participants: int) -> None:
    total = sum((_slot_counts(slot_permutations(n_trials, 0, k, "balanced")) for k in range(n_participants)),
                np.zeros((3, 3), int))
    assert (total == total[0, 0]).all() and total[0, 0] == n_trials * n_participants // 3
    perm_use = Counter(p for k in range(n_participants) for p in slot_permutations(n_trials, 0, k, "balanced"))
    assert set(perm_use) <= set(ALL_PERMS)
    if n_trials % 6 == 0:
        assert set(perm_use.values()) == {n_trials * n_participants // 6}


def test_random_slots_reproducible_and_seed_dependent() -> None:
    a = slot_permutations(50, 11, 0, "random")
    assert a == slot_permutations(50, 11, 3, "random")  # the index plays no role in random mode
    assert a != slot_permutations(50, 12, 0, "random")
    assert set(a) <= set(ALL_PERMS) and len(set(a)) == 6


def test_unknown_mode_and_negative_count() -> None:
    with pytest.raises(ValueError):
        slot_permutations(3, 0, 0, "latin")
    with pytest.raises(ValueError):
        slot_permutations(-1, 0, 0, "balanced")


def test_participant_seed_is_stable_across_processes() -> None:
    import subprocess
    import sys

    code = "from studyapp.study.ordering import participant_seed as p; print(p(5, 'P07', 'slots'))"
    outs = {subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                           env={"PYTHONHASHSEED": str(h), "PATH": ""}).stdout.strip() for h in (1, 2)}
    assert outs == {str(participant_seed(5, "P07", "slots"))}
    assert participant_seed(5, "P07") != participant_seed(5, "P08") != participant_seed(6, "P08")
