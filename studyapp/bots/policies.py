"""How a scripted participant answers: the ranking policies and their per-trial random generator.

The drivers (:mod:`studyapp.bots.session_driver`, :mod:`studyapp.bots.ui_driver`) take every answer from
here, so a pilot without rendering and one through the real UI answer a trial alike. Policies:

* ``random``: a uniformly random ranking per criterion. The generator is seeded per trial from
  ``(seed, participant, trial index)``, so a session killed and resumed answers every trial exactly as an
  uninterrupted one would (the kill tests rely on this).
* ``ordered``: ranks conditions in the order the design lists them, on every criterion (the condition listed
  first gets rank 1). A frozen attention-check slot ranks after every real condition.
* ``careful``: ranks by :func:`studyapp.bots.careful.careful_scores` (higher score = better rank), i.e. what a
  careful viewer would perceive in the actual motion and audio; criteria without a score fall back to random.

The other paradigms (see :mod:`studyapp.ui.paradigm`), each policy in its own spirit:

* :func:`choose_preference` (``pairwise``, ``mismatch``): a level per criterion, negative = left preferred.
  ``random``: a uniform option, and each of the block's reasons with probability 1/2; ``ordered``: the figure
  whose condition the design lists first, clearly (a mismatch trial shows one condition twice: the slot
  playing its own speech's motion, clearly), and the first reason; ``careful``: the difference of the two
  figures' perceived 0..100 ratings (:func:`studyapp.bots.careful.careful_ratings`; in a mismatch trial
  :func:`~studyapp.bots.careful.alignment_ratings`, how well each motion fits the trial's speech), each
  with perception noise of :data:`RATING_NOISE_SD`: under :data:`PREFER_EQUAL` apart is "no preference",
  under :data:`PREFER_CLEARLY` "slightly", else "clearly" (3 levels: under :data:`PREFER_EQUAL` equal, else
  the better one); it ticks one reason drawn at random (it cannot read free-text reasons).
* :func:`choose_ratings` (``rating``): ``random`` a uniform whole number 0..100 per slider; ``ordered`` 90 for
  the condition listed first down to 10 for the last; ``careful`` its perceived 0..100 rating, rounded.

With ``allow_ties`` (the design's ``[playback] allow_ties``) ``random`` draws uniformly from all 13 ways to
rank three slots with ties, and ``careful`` calls two slots equal when it perceives them closer than
:data:`CAREFUL_TIE_GAP`. Ties are given as competition ranks (1, 1, 3 / 1, 2, 2 / 1, 1, 1), the convention
of :func:`studyapp.study.session.normalise_ranks`. ``ordered`` never ties: its point is a known strict order.

Example
-------
>>> import numpy as np
>>> from studyapp.study.schedule import TrialPlan
>>> plan = TrialPlan(0, "s1", ("b", "c", "a"), False, False, 0)
>>> choose_ranking("ordered", plan, None, ["realism"], np.random.default_rng(0), condition_order=["a", "b", "c"])
{'realism': {0: 2, 1: 3, 2: 1}}
"""
from __future__ import annotations

import math
import zlib
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

from studyapp.errors import StudyappError

if TYPE_CHECKING:
    from studyapp.study.schedule import TrialPlan
    from studyapp.study.stimuli import TrialMedia

POLICIES = ("random", "ordered", "careful")


def _criterion_ids(criteria: Sequence[Any]) -> list[str]:
    return [c if isinstance(c, str) else c.id for c in criteria]


def _ranks_from_scores(scores: Sequence[float], tie_gap: float | None = None) -> dict[int, int]:
    # Higher score -> better (lower) rank; equal scores keep slot order so the result is deterministic.
    # With tie_gap, neighbours in that order closer than the gap are equal (competition ranks: the tied
    # slots share the better rank), which is what a viewer who cannot tell them apart would answer.
    order = sorted(range(3), key=lambda i: (-float(scores[i]), i))
    ranks = {order[0]: 1}
    for k in range(1, 3):
        tied = tie_gap is not None and float(scores[order[k - 1]]) - float(scores[order[k]]) < tie_gap
        ranks[order[k]] = ranks[order[k - 1]] if tied else k + 1
    return {slot: ranks[slot] for slot in range(3)}


#: Every ranking of three slots with ties allowed, as competition ranks (slot 0, 1, 2): 6 strict orders,
#: 3 with two equal best, 3 with two equal worst, and all three equal.
WEAK_RANKINGS: tuple[tuple[int, int, int], ...] = (
    (1, 2, 3), (1, 3, 2), (2, 1, 3), (2, 3, 1), (3, 1, 2), (3, 2, 1),
    (1, 1, 3), (1, 3, 1), (3, 1, 1),
    (1, 2, 2), (2, 1, 2), (2, 2, 1),
    (1, 1, 1),
)


def _random_ranks(rng: np.random.Generator, allow_ties: bool) -> dict[int, int]:
    if allow_ties:
        return dict(enumerate(WEAK_RANKINGS[int(rng.integers(len(WEAK_RANKINGS)))]))
    return {i: int(r) for i, r in enumerate(rng.permutation(3) + 1)}


#: Perception noise of the careful bot, in units of the trial's score range (Thurstone case V). Real viewers
#: disagree where motions are close and agree where one is clearly worse; a noiseless bot would make every
#: simulated participant identical and the statistics degenerate (W = 1, zero-width intervals).
CAREFUL_NOISE_SD = 0.3

#: With ties allowed, the careful bot calls two slots equal when their perceived scores differ by less than
#: this (same units as the noise): about a third of the perception noise, so ties are common between close
#: motions and rare where one is clearly worse.
CAREFUL_TIE_GAP = 0.1


def _perceived(scores: Sequence[float], rng: np.random.Generator) -> np.ndarray:
    v = np.asarray(scores, dtype=np.float64)
    spread = float(v.max() - v.min())
    normed = (v - v.min()) / spread if spread > 0 else np.zeros_like(v)
    return normed + rng.normal(0.0, CAREFUL_NOISE_SD, size=v.shape)


def choose_ranking(
    policy: str,
    plan: TrialPlan,
    media: TrialMedia | None,
    criteria: Sequence[Any],
    rng: np.random.Generator,
    *,
    condition_order: Sequence[str] | None = None,
    allow_ties: bool = False,
) -> dict[str, dict[int, int]]:
    """A complete ranking ``{criterion: {slot: rank}}`` for one trial under ``policy``.

    ``media`` (a :class:`~studyapp.study.stimuli.TrialMedia`) is needed by ``careful`` only;
    ``condition_order`` (the design's condition ids) by ``ordered`` only. ``allow_ties`` lets ``random``
    and ``careful`` give tied (competition) ranks.
    """
    crits = _criterion_ids(criteria)
    if policy == "random":
        return {c: _random_ranks(rng, allow_ties) for c in crits}
    if policy == "ordered":
        if condition_order is None:
            raise ValueError("the ordered bot needs condition_order (the design's condition ids)")
        position = {cid: i for i, cid in enumerate(condition_order)}
        keys = [position.get(cid, len(position)) for cid in plan.slots]  # frozen:... and unknown rank last
        return {c: _ranks_from_scores([-k for k in keys]) for c in crits}
    if policy == "careful":
        if media is None:
            raise ValueError("the careful bot needs the trial's media (load_trial_media)")
        from studyapp.bots.careful import careful_scores  # signal processing, only for this policy

        scores = careful_scores(media)
        out = {}
        for c in crits:
            if c in scores:
                out[c] = _ranks_from_scores(_perceived(scores[c], rng), CAREFUL_TIE_GAP if allow_ties else None)
            else:
                out[c] = _random_ranks(rng, allow_ties)
        return out
    raise StudyappError(f"unknown bot policy {policy!r}; choose one of {', '.join(POLICIES)}")


def trial_rng(seed: int, participant_id: str, trial_index: int) -> np.random.Generator:
    """The generator a bot uses for one trial: independent of how many trials ran in this process."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, zlib.crc32(participant_id.encode()), int(trial_index)])


def questionnaire_answers(items: Sequence[Any], rng: np.random.Generator) -> dict[str, Any]:
    """Bot answers, one per item kind: a random point on a Likert item, a random option (one to all of them
    when several may be chosen), a random number in range (whole when the item asks so; as typed text),
    a fixed note on text items."""
    out: dict[str, Any] = {}
    for q in items:
        if q.kind == "likert":
            out[q.id] = int(rng.integers(1, int(q.points) + 1))
        elif q.kind == "choice" and q.multiple:
            k = int(rng.integers(1, len(q.options) + 1))
            picked = set(rng.choice(len(q.options), size=k, replace=False).tolist())
            out[q.id] = [o for i, o in enumerate(q.options) if i in picked]
        elif q.kind == "choice":
            out[q.id] = q.options[int(rng.integers(0, len(q.options)))]
        elif q.kind == "number":
            x = float(rng.uniform(q.min, q.max))
            out[q.id] = str(int(round(min(max(x, math.ceil(q.min)), math.floor(q.max))))) if q.integer else repr(min(max(round(x, 1), q.min), q.max))
        else:
            out[q.id] = "(scripted participant)"
    return out


#: Perception noise (points on the 0..100 scale, per figure) of the careful bot's ratings and preferences.
RATING_NOISE_SD = 8.0
#: Perceived rating differences (points) under which the careful bot has no preference, and from which it
#: prefers clearly rather than slightly.
PREFER_EQUAL, PREFER_CLEARLY = 5.0, 15.0


def _condition_keys(plan: TrialPlan, condition_order: Sequence[str] | None) -> list[int]:
    if condition_order is None:
        raise ValueError("the ordered bot needs condition_order (the design's condition ids)")
    position = {cid: i for i, cid in enumerate(condition_order)}
    return [position.get(cid, len(position)) for cid in plan.slots]


def _matched_slots(plan: TrialPlan) -> list[bool]:
    """Per slot: does it play the trial's own stimulus's motion (always, outside mismatch trials)?"""
    motion = tuple(getattr(plan, "motion_stimuli", ()) or ())
    if not motion:
        return [True] * len(plan.slots)
    return [m == plan.stimulus_id for m in motion]


def _level(diff: float, levels: int) -> int:
    """A perceived difference (right minus left, points) as a level: negative = left preferred."""
    size = abs(diff)
    if size < PREFER_EQUAL:
        return 0
    step = 1 if levels == 3 or size < PREFER_CLEARLY else 2
    return step if diff > 0 else -step


def choose_preference(
    policy: str,
    plan: TrialPlan,
    media: TrialMedia | None,
    criteria: Sequence[Any],
    rng: np.random.Generator,
    *,
    levels: int = 5,
    reasons: Sequence[str] = (),
    condition_order: Sequence[str] | None = None,
) -> tuple[dict[str, int], list[str]]:
    """``({criterion: level}, reasons)`` for a two-figure trial (``pairwise`` or ``mismatch``) under ``policy``:
    what ``Session.submit_preference`` takes (levels -2..2, or -1..1 for 3 levels; negative = left).

    >>> from studyapp.study.schedule import TrialPlan
    >>> plan = TrialPlan(0, "s1", ("b", "a"), False, False, 0, paradigm="pairwise")
    >>> choose_preference("ordered", plan, None, ["realism"], np.random.default_rng(0), reasons=["Hands"],
    ...                   condition_order=["a", "b"])
    ({'realism': 2}, ['Hands'])
    """
    crits = _criterion_ids(criteria)
    top = 2 if levels == 5 else 1
    if policy == "random":
        out = {c: int(rng.integers(-top, top + 1)) for c in crits}
        picked = [r for r in reasons if rng.random() < 0.5]
    elif policy == "ordered":
        if getattr(plan, "paradigm", "") == "mismatch":
            matched = _matched_slots(plan)
            side = 0 if matched[0] == matched[1] else (-top if matched[0] else top)
        else:
            keys = _condition_keys(plan, condition_order)
            side = 0 if keys[0] == keys[1] else (-top if keys[0] < keys[1] else top)
        out = {c: side for c in crits}
        picked = list(reasons[:1])
    elif policy == "careful":
        if media is None:
            raise ValueError("the careful bot needs the trial's media (load_trial_media)")
        from studyapp.bots.careful import alignment_ratings, careful_ratings

        if getattr(plan, "paradigm", "") == "mismatch":
            fit = alignment_ratings(media)
            ratings = {c: fit for c in crits}
        else:
            ratings = careful_ratings(media)
        out = {}
        for c in crits:
            if c in ratings:
                left, right = np.asarray(ratings[c][:2], dtype=np.float64) + rng.normal(0.0, RATING_NOISE_SD, 2)
                out[c] = _level(float(right - left), levels)
            else:
                out[c] = int(rng.integers(-top, top + 1))
        picked = [reasons[int(rng.integers(len(reasons)))]] if reasons else []
    else:
        raise StudyappError(f"unknown bot policy {policy!r}; choose one of {', '.join(POLICIES)}")
    return out, (picked if any(v != 0 for v in out.values()) else [])


def choose_ratings(
    policy: str,
    plan: TrialPlan,
    media: TrialMedia | None,
    criteria: Sequence[Any],
    rng: np.random.Generator,
    *,
    condition_order: Sequence[str] | None = None,
) -> dict[str, dict[int, int]]:
    """``{criterion: {slot: 0..100}}`` for every slider of a ``rating`` trial under ``policy``.

    >>> from studyapp.study.schedule import TrialPlan
    >>> plan = TrialPlan(0, "s1", ("c", "a", "b"), False, False, 0, paradigm="rating")
    >>> choose_ratings("ordered", plan, None, ["realism"], np.random.default_rng(0), condition_order=["a", "b", "c"])
    {'realism': {0: 10, 1: 90, 2: 50}}
    """
    crits = _criterion_ids(criteria)
    n = len(plan.slots)
    if policy == "random":
        return {c: {s: int(rng.integers(0, 101)) for s in range(n)} for c in crits}
    if policy == "ordered":
        keys = _condition_keys(plan, condition_order)
        worst = max(1, len(condition_order or ()) - 1)
        return {c: {s: int(round(90 - 80 * min(k, worst) / worst)) for s, k in enumerate(keys)} for c in crits}
    if policy == "careful":
        if media is None:
            raise ValueError("the careful bot needs the trial's media (load_trial_media)")
        from studyapp.bots.careful import careful_ratings

        ratings = careful_ratings(media)
        out = {}
        for c in crits:
            base = np.asarray(ratings[c], dtype=np.float64) if c in ratings else rng.uniform(0, 100, n)
            seen = np.clip(base + rng.normal(0.0, RATING_NOISE_SD, n), 0.0, 100.0)
            out[c] = {s: int(round(float(v))) for s, v in enumerate(seen)}
        return out
    raise StudyappError(f"unknown bot policy {policy!r}; choose one of {', '.join(POLICIES)}")
