"""The ranking logic behind drag, click and keyboard ranking."""
import itertools

import pytest

from studyapp.ui.ranking import RankingState


def test_click_in_order_gives_that_order_and_ranks():
    r = RankingState(["realism"])
    for slot in (1, 2, 0):
        r.click("realism", slot)
    assert r.order["realism"] == [1, 2, 0]
    assert r.ranks() == {"realism": {0: 3, 1: 1, 2: 2}}


def test_click_on_placed_chip_takes_it_out_and_next_click_fills_the_gap():
    r = RankingState(["realism"])
    for slot in (0, 1, 2):
        r.click("realism", slot)
    r.click("realism", 1)
    assert r.order["realism"] == [0, None, 2]
    assert not r.is_complete("realism") and r.ranks() == {}
    r.click("realism", 1)
    assert r.order["realism"] == [0, 1, 2]


def test_drop_on_occupied_place_swaps():
    r = RankingState(["c"])
    r.drop("c", 0, 0)
    r.drop("c", 1, 1)
    r.drop("c", 2, 2)
    r.drop("c", 2, 0)  # 2 goes to the top, 0 moves to where 2 was
    assert r.order["c"] == [2, 1, 0]
    r.drop("c", 1, 1)  # dropping where it already is changes nothing
    assert r.order["c"] == [2, 1, 0]


def test_drop_of_unplaced_chip_on_occupied_place_pushes_the_other_out():
    r = RankingState(["c"])
    r.drop("c", 0, 0)
    r.drop("c", 1, 0)
    assert r.order["c"] == [1, None, None]
    assert r.unplaced("c") == [0, 2]


@pytest.mark.parametrize("order", list(itertools.permutations(range(3))))
def test_every_permutation_reachable_by_keyboard_and_ranks_are_inverse(order):
    r = RankingState(["a", "b"])
    for slot in order:
        r.key_slot(slot)
    assert r.order["a"] == list(order)
    assert r.active == 1  # the keyboard moved on to the unfinished question
    ranks = r.ranks()["a"]
    assert sorted(ranks.values()) == [1, 2, 3]
    assert [min(ranks, key=ranks.get)] == [order[0]] and ranks[order[2]] == 3


def test_keyboard_repeat_of_a_placed_slot_is_ignored_and_clear_resets():
    r = RankingState(["a"])
    r.key_slot(0)
    r.key_slot(0)
    assert r.order["a"] == [0, None, None]
    r.clear("a")
    assert r.order["a"] == [None, None, None]


def test_all_complete_needs_every_criterion():
    r = RankingState(["a", "b"])
    for s in range(3):
        r.click("a", s)
    assert not r.all_complete()
    for s in range(3):
        r.click("b", s)
    assert r.all_complete()
