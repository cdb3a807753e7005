"""The preference and rating answers as the panels hold them (pure logic, no drawing)."""
from __future__ import annotations

import pytest

from studyapp.ui.paradigm import scene_labels, slot_names
from studyapp.ui.preference import PreferenceState
from studyapp.ui.rating import RatingState, anchor_centres, digit_points


def test_preference_keys_pick_options_left_to_right_on_both_scales():
    five = PreferenceState(["a"], levels=5)
    got = []
    for k in range(5):
        five.key_digit(k)
        got.append(five.answers()["a"])
    assert got == [-2, -1, 0, 1, 2]   # key 1 = clearly LEFT (negative) .. key 5 = clearly RIGHT
    three = PreferenceState(["a"], levels=3)
    three.key_digit(4)                 # no 5th option on a 3-level scale: ignored
    assert three.answers() == {}
    three.key_digit(2)
    assert three.answers() == {"a": 1}
    with pytest.raises(ValueError):
        PreferenceState(["a"], levels=4)


def test_preference_arrows_step_from_no_preference_and_stop_at_the_ends():
    p = PreferenceState(["a"], levels=5)
    p.key_step(-1)
    assert p.answers() == {"a": 0}     # the first press lands on "no preference"
    for _ in range(5):
        p.key_step(-1)
    assert p.answers() == {"a": -2}
    p.key_step(1)
    assert p.answers() == {"a": -1}


def test_reasons_only_count_while_some_answer_is_a_preference():
    p = PreferenceState(["a", "b"], levels=5, reasons=("Hands", "Timing"))
    p.choose("a", 0)
    p.choose("b", 0)
    assert not p.reasons_asked() and p.n_rows() == 2 and p.active == 1
    p.toggle_reason("Timing")              # ticked while greyed out: not submitted
    assert p.submitted_reasons() == []
    p.choose("b", 2)                       # a preference: the reasons row appears, the highlight goes there
    assert p.reasons_asked() and p.active == 2
    p.key_digit(0)
    assert p.submitted_reasons() == ["Hands", "Timing"]   # in the block's order
    p.move_active(-1)
    p.key_clear()                          # clearing "b": all answers equal again, the reasons row goes
    assert p.answers() == {"a": 0} and p.active < p.n_rows() and p.submitted_reasons() == []


def test_every_slider_must_move_and_the_missing_ones_are_named():
    r = RatingState(["realism", "diversity"], n_slots=3)
    assert r.missing() == [(c, s) for c in ("realism", "diversity") for s in range(3)]
    r.set("realism", 1, 130.4)             # clamped to the scale
    r.set("diversity", 2, -3)
    assert r.ratings() == {"realism": {1: 100}, "diversity": {2: 0}}
    assert r.missing() == [("realism", 0), ("realism", 2), ("diversity", 0), ("diversity", 1)]
    assert not r.all_moved()
    for c, s in r.missing():
        r.set(c, s, 42)
    assert r.all_moved() and r.ratings()["realism"] == {0: 42, 1: 100, 2: 42}
    r.active = 0
    r.key_clear()                          # Backspace unsets the highlighted slider again
    assert r.missing() == [("realism", 0)]


def test_slider_keys_and_anchor_points():
    assert anchor_centres(4) == [12.5, 37.5, 62.5, 87.5]     # MUSHRA: the centres of equal intervals
    r = RatingState(["q"], n_slots=2)
    r.key_step(-10)                        # an unset slider first goes to the middle, whatever the direction
    assert r.values["q"] == [50, None] and r.active == 0
    r.key_step(-10)
    r.key_step(1)
    assert r.values["q"][0] == 41
    r.move_active(1)
    r.key_point(digit_points(5)[4])        # key 5 of 5 anchors: "Excellent", the centre of 80..100
    assert r.values["q"] == [41, 90]
    assert digit_points(0)[-1] == 90.0     # without anchors, key 9 = 90


def test_figure_names_per_trial_size():
    assert slot_names(None, 3) == ("Left", "Middle", "Right")
    assert slot_names(("A", "B"), 2) == ("A", "B")
    assert slot_names(("A", "B", "C"), 4)[-1] == "D"
    # position words need no labels over the figures; letters do
    assert scene_labels(None, 3) is None and scene_labels(("A", "B", "C"), 3) == ("A", "B", "C")
