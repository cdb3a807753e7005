"""Duration agreement of a stimulus's media files."""
from __future__ import annotations

import pytest

from studyapp.durations import check_durations, duration_mismatches
from studyapp.errors import InputError


def test_within_tolerance_is_fine() -> None:
    items = {"audio": (10.0, "a.wav"), "face": (10.033, "f.csv"), "motion:m1": (9.9, "m1.bvh")}
    assert duration_mismatches(items) == []
    check_durations(items)
    assert duration_mismatches({}) == [] and duration_mismatches({"audio": (3.0, "a.wav")}) == []


def test_mismatch_names_every_file_and_duration() -> None:
    items = {"audio": (10.0, "clips/a.wav"), "face": (10.0, "clips/a.csv"), "motion:m2": (7.5, "m2/a.bvh")}
    problems = duration_mismatches(items)
    assert len(problems) == 1
    for label, (dur, path) in items.items():
        assert f"{label} {dur:.3f} s ({path})" in problems[0]
    assert "differ by 2.500 s" in problems[0]
    with pytest.raises(InputError) as exc:
        check_durations(items)
    assert exc.value.path == "clips/a.wav" and "m2/a.bvh" in str(exc.value) and "7.500 s" in str(exc.value)


def test_tolerance_boundary() -> None:
    items = {"audio": (10.0, "a"), "face": (10.25, "f")}
    assert duration_mismatches(items, tolerance_s=0.3) == []
    assert len(duration_mismatches(items, tolerance_s=0.2)) == 1


def test_invalid_durations_are_reported_not_compared() -> None:
    items = {"audio": (10.0, "a.wav"), "face": (float("nan"), "f.csv"), "motion:m": (-1.0, "m.bvh")}
    problems = duration_mismatches(items)
    assert len(problems) == 2
    assert "face (f.csv)" in problems[0] and "motion:m (m.bvh)" in problems[1]
    with pytest.raises(InputError):
        check_durations(items)
