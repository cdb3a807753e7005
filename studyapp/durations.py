"""Check that the media of one stimulus (audio, face, each model's motion) last equally long.

A clip whose motion is a second shorter than its audio makes the avatars freeze while the voice goes on,
which participants rate as unnatural for reasons that have nothing to do with the model. Validators find
such clips before a study starts; the message lists every file with its duration so the experimenter can
see which one is off.

>>> duration_mismatches({"audio": (10.0, "a.wav"), "face": (10.1, "a.csv")})
[]
>>> duration_mismatches({"audio": (10.0, "a.wav"), "motion:m1": (8.0, "m1.bvh")})[0]
'durations differ by 2.000 s (tolerance 0.200 s): audio 10.000 s (a.wav), motion:m1 8.000 s (m1.bvh)'
"""
from __future__ import annotations

import math

from studyapp.errors import InputError


def duration_mismatches(items: dict[str, tuple[float, str]], tolerance_s: float = 0.2) -> list[str]:
    """Problems with the durations of ``items`` (label -> (seconds, file path)); empty when they agree.

    Reports one message when the longest and shortest differ by more than ``tolerance_s``, naming every
    file and its duration, plus one message per non-finite or negative duration.
    """
    problems: list[str] = []
    good: dict[str, tuple[float, str]] = {}
    for label, (dur, path) in items.items():
        if not isinstance(dur, (int, float)) or not math.isfinite(dur) or dur < 0:
            problems.append(f"{label} ({path}): duration {dur!r} is not a valid length in seconds")
        else:
            good[label] = (float(dur), str(path))
    if len(good) >= 2:
        durs = [d for d, _ in good.values()]
        spread = max(durs) - min(durs)
        if spread > tolerance_s:
            listing = ", ".join(f"{label} {d:.3f} s ({path})" for label, (d, path) in good.items())
            problems.append(f"durations differ by {spread:.3f} s (tolerance {tolerance_s:.3f} s): {listing}")
    return problems


def check_durations(items: dict[str, tuple[float, str]], tolerance_s: float = 0.2) -> None:
    """Raise :class:`InputError` naming every file and its duration if ``items`` disagree in length.

    >>> check_durations({"audio": (10.0, "a.wav"), "face": (9.0, "a.csv")})
    Traceback (most recent call last):
    ...
    studyapp.errors.InputError: a.wav, durations: durations differ by 1.000 s (tolerance 0.200 s): audio 10.000 s (a.wav), face 9.000 s (a.csv)
    """
    problems = duration_mismatches(items, tolerance_s)
    if problems:
        first = next(iter(items.values()))[1] if items else None
        raise InputError(first, "durations", "; ".join(problems))


__all__ = ["check_durations", "duration_mismatches"]
