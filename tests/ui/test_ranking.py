"""The ranking logic behind drag, click and keyboard ranking."""
import itertools

import pytest

from studyapp.bots.policies import WEAK_RANKINGS
from studyapp.study.session import RankingError, normalise_ranks
from studyapp.ui.ranking import RankingState, order_and_ties


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


# -- ties (designs with [playback] allow_ties) ------------------------------------------------------------

def _typed(keys, allow_ties=True):
    """A one-question state after typing ``keys`` ("1=23": digits place left/middle/right, "=" ties)."""
    r = RankingState(["a"], allow_ties=allow_ties)
    for k in keys:
        r.key_tie() if k == "=" else r.key_slot(int(k) - 1)
    return r


def test_without_allow_ties_links_cannot_be_tied_and_ranks_stay_a_permutation():
    r = _typed("1=2=3", allow_ties=False)
    r.toggle_tie("a", 0)
    assert r.ties["a"] == [False, False]
    assert r.ranks() == {"a": {0: 1, 1: 2, 2: 3}}
    with pytest.raises(RankingError, match="only once"):
        normalise_ranks({"a": {0: 1, 1: 1, 2: 3}}, ["a"], False)  # what a tie would meet in the session


@pytest.mark.parametrize("keys, ranks", [
    ("1=23", {0: 1, 1: 1, 2: 3}),      # two equal best: competition ranks 1, 1, 3
    ("12=3", {0: 1, 1: 2, 2: 2}),      # two equal worst: 1, 2, 2 (not 1, 3, 3)
    ("1=2=3", {0: 1, 1: 1, 2: 1}),     # all equal
    ("3=21", {0: 3, 1: 1, 2: 1}),
    ("2=13", {0: 1, 1: 1, 2: 3}),      # equal slots keep the rank of the better place, whatever the order
    ("123", {0: 1, 1: 2, 2: 3}),
])
def test_keyboard_ties_give_competition_ranks(keys, ranks):
    assert _typed(keys).ranks() == {"a": ranks}


def test_equals_toggles_the_link_above_the_next_free_place_only():
    r = _typed("=")                      # nothing placed: no figure to tie with
    assert r.ties["a"] == [False, False]
    r = _typed("1==23")                  # a second "=" takes the tie back
    assert r.ties["a"] == [False, False] and r.ranks()["a"] == {0: 1, 1: 2, 2: 3}
    r = _typed("123=")                   # complete: nothing left to tie with the last figure
    assert r.ties["a"] == [False, False]
    r = _typed("1=")                     # the pending tie is visible before the next figure is placed
    assert r.ties["a"] == [True, False] and r.is_tied("a", 0) and r.is_tied("a", 1) and not r.is_tied("a", 2)


def test_tied_but_incomplete_question_is_not_complete_and_has_no_ranks():
    r = RankingState(["a", "b"], allow_ties=True)
    r.toggle_tie("a", 0)
    r.toggle_tie("a", 1)
    r.click("a", 0)
    r.click("a", 1)
    assert not r.is_complete("a") and r.ranks() == {}
    r.click("a", 2)
    assert r.is_complete("a") and not r.all_complete()
    assert r.ranks() == {"a": {0: 1, 1: 1, 2: 1}}
    for s in range(3):
        r.click("b", s)
    assert r.all_complete() and r.ranks()["b"] == {0: 1, 1: 2, 2: 3}


def test_ties_belong_to_places_so_moving_figures_keeps_them_and_clear_resets():
    r = RankingState(["a"], allow_ties=True)
    for s in (0, 1, 2):
        r.click("a", s)
    r.toggle_tie("a", 1)                 # 2nd = 3rd
    r.drop("a", 0, 2)                    # left swaps with right
    assert r.order["a"] == [2, 1, 0] and r.ties["a"] == [False, True]
    assert r.ranks()["a"] == {0: 2, 1: 2, 2: 1}
    assert [r.place_rank("a", p) for p in range(3)] == [1, 2, 2]
    r.clear("a")
    assert r.ties["a"] == [False, False] and r.order["a"] == [None, None, None]


def test_every_panel_state_is_a_ranking_the_session_accepts_and_bots_can_choose():
    # The panel, the bots and the session must share one convention: all 24 (order, links) states of a
    # question give exactly the 13 competition rankings the bots draw from, and the session stores each
    # as the average ranks of the same ordering.
    seen = set()
    for order in itertools.permutations(range(3)):
        for ties in itertools.product((False, True), repeat=2):
            r = RankingState(["a"], allow_ties=True)
            for slot in order:
                r.click("a", slot)
            for link, tied in enumerate(ties):
                if tied:
                    r.toggle_tie("a", link)
            ranks = r.ranks()["a"]
            seen.add(tuple(ranks[s] for s in range(3)))
            averaged = normalise_ranks({"a": ranks}, ["a"], True)["a"]
            assert sorted(averaged) in ([1.0, 2.0, 3.0], [1.5, 1.5, 3.0], [1.0, 2.5, 2.5], [2.0, 2.0, 2.0])
            for i in range(3):
                for j in range(3):  # averaging keeps the participant's order and ties
                    assert (ranks[i] < ranks[j]) == (averaged[i] < averaged[j])
            # and entering these ranks again (what the scripted participant does) gives the same state
            again_order, again_ties = order_and_ties(ranks)
            r2 = RankingState(["a"], allow_ties=True)
            r2.order["a"], r2.ties["a"] = again_order, again_ties
            assert r2.ranks()["a"] == ranks
    assert seen == set(WEAK_RANKINGS) and len(seen) == 13


@pytest.mark.parametrize("ranks", [{0: 1, 1: 1, 2: 2}, {0: 1, 1: 3, 2: 3}, {0: 2, 1: 2, 2: 2}, {0: 1, 1: 2}])
def test_order_and_ties_refuses_what_the_panel_cannot_show(ranks):
    with pytest.raises(ValueError):
        order_and_ties(ranks)
