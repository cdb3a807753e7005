"""Planning before recruiting: the power of a design's headline test, simulated on the design's own schedule.

For ``N`` participants arriving in order (participant ``k`` on design row ``k mod n_rows``, as a results
database assigns them), each participant's rated trials are the ``rank`` trials of
:func:`studyapp.study.schedule.participant_schedule` (practice and attention checks are never analysed; the
other response paradigms are not simulated, and a design without a rank block is refused).
Each rated trial's ranking of the conditions in its three slots is drawn from a Plackett-Luce model with the
given strengths, one per design condition (the best place goes to condition ``i`` with probability
``s_i / sum s``, then the next among the rest; drawn with the Gumbel-max trick), independently of the slot,
trial and participant. A condition in no rank block is left out of the test, and its strength is not used.

The test is the analysis's headline (:mod:`results_analysis.analysis`, ``block='participant'``): each
participant's mean within-trial rank per condition, re-ranked within the participant, then Friedman's
chi-squared with tie correction (:func:`results_analysis.friedman.friedman_ranks`). Power is the share of
simulated studies with ``p < alpha``; its Monte-Carlo standard error is ``sqrt(p (1 - p) / n_sim)``.

The ``N`` needed for a target power (80 %) is searched over ``N = 2, 4, 8, ...`` up to ``max_n``, then by
bisection between the last ``N`` below the target and the first at or above it. Every ``N`` is simulated
with its own generator seeded from ``(seed, N)``, so a result is reproducible and does not depend on which
other ``N`` were tried.

Also reported: the balance the schedule achieves for ``N`` (clip x position and condition x slot counts,
:func:`studyapp.study.schedule.balance_counts`) and the session length: every trial's playing time from the
design's durations (:func:`studyapp.study.timeline.trial_duration`: ``duration_s`` or the audio's length,
practice and attention checks included), plus an assumed answering time per trial.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from results_analysis.friedman import friedman_ranks
from results_analysis.ranks import within_block_ranks
from studyapp.errors import InputError
from studyapp.study.design import Design
from studyapp.study.schedule import balance_counts, full_schedule, n_rows, participant_ids, participant_schedule
from studyapp.study.stimuli import load_audio
from studyapp.study.timeline import trial_duration

#: Default assumed time (s) a participant takes to answer one trial, on top of watching it once.
ANSWER_S = 15.0
_BATCH = 200  # simulated studies per vectorised batch (bounds memory for large N)


@dataclass
class PlanResult:
    """What ``studyapp plan`` reports (see the module notes)."""

    n_participants: int
    strengths: dict[str, float]
    alpha: float
    n_sim: int
    power: float
    target: float
    n_for_target: int | None  # None: not reached up to max_n
    max_n: int
    curve: dict[int, float]  # every N simulated, its power
    n_rows: int
    rated_trials: int  # per participant
    balance: dict[str, pd.DataFrame]
    trial_seconds: float  # playing time of one participant's trials
    answer_s: float
    n_trials: int  # all trials per participant (practice and checks included)
    seed: int
    notes: list[str] = field(default_factory=list)

    @property
    def power_se(self) -> float:
        return math.sqrt(self.power * (1 - self.power) / self.n_sim)

    @property
    def session_seconds(self) -> float:
        return self.trial_seconds + self.answer_s * self.n_trials


def parse_strengths(text: str, design: Design) -> dict[str, float]:
    """``"3,1.5,1"`` -> strength per condition, in design order; one clear error otherwise."""
    ids = design.condition_ids
    parts = [p.strip() for p in str(text).split(",")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise InputError(None, "--strengths", f"{text!r}: expected {len(ids)} numbers separated by commas, one per "
                         f"condition in design order ({', '.join(ids)})") from None
    if len(values) != len(ids):
        raise InputError(None, "--strengths", f"{len(values)} values for {len(ids)} conditions ({', '.join(ids)}); "
                         "give one per condition, in design order")
    if not all(math.isfinite(v) and v > 0 for v in values):
        raise InputError(None, "--strengths", f"{text!r}: Plackett-Luce strengths must be positive numbers")
    return dict(zip(ids, values))


def rated_conditions(design: Design, n_participants: int) -> np.ndarray:
    """``(N, m, 3)`` condition indices (design order) in the slots of each participant's rated trials, rows
    assigned in order of arrival; ``-1`` pads participants with fewer rated trials than the most."""
    ids = design.condition_ids
    rows = n_rows(design)
    per: list[list[list[int]]] = []
    for k, pid in enumerate(participant_ids(n_participants)):
        plans = participant_schedule(design, pid, k % rows)
        per.append([[ids.index(c) for c in p.slots] for p in plans
                    if not (p.is_practice or p.is_attention_check) and p.paradigm == "rank"])
    m = max(len(t) for t in per)
    out = np.full((n_participants, m, 3), -1, np.int64)
    for i, t in enumerate(per):
        if t:
            out[i, :len(t)] = t
    return out


def simulate_p_values(slots: np.ndarray, strengths: Sequence[float], n_sim: int,
                      rng: np.random.Generator) -> np.ndarray:
    """Headline p-values of ``n_sim`` simulated studies on the trials ``slots`` (from :func:`rated_conditions`)."""
    log_s = np.log(np.asarray(strengths, dtype=np.float64))
    k = len(log_s)
    # the test compares the conditions the rank trials show: a block design's other conditions have no rank
    # (left in, each would sit at mean rank 0, "best" for every participant, and make any design look powerful)
    ranked = np.unique(slots[slots >= 0])
    valid = slots[..., 0] >= 0  # (N, m)
    idx = np.where(slots >= 0, slots, 0)
    out = np.empty(n_sim)
    for start in range(0, n_sim, _BATCH):
        b = min(_BATCH, n_sim - start)
        keys = log_s[idx][None] + rng.gumbel(size=(b,) + idx.shape)       # (b, N, m, 3) in slot order
        place = np.argsort(np.argsort(-keys, axis=-1), axis=-1) + 1.0      # rank 1 = best, per slot
        per_cond = np.zeros((b,) + idx.shape[:2] + (k,))
        np.put_along_axis(per_cond, np.broadcast_to(idx, place.shape), place, axis=-1)
        seen = np.zeros(idx.shape[:2] + (k,))
        np.put_along_axis(seen, idx, 1.0, axis=-1)
        seen *= valid[..., None]
        per_cond *= valid[None, ..., None]
        # each participant's mean within-trial rank per condition (every trial shows every condition here)
        means = per_cond.sum(axis=2) / np.maximum(seen.sum(axis=1), 1)[None]
        for i in range(b):
            out[start + i] = friedman_ranks(within_block_ranks(means[i][:, ranked])).p
    return out


def power_at(design: Design, n_participants: int, strengths: Sequence[float], *, n_sim: int = 1000,
             alpha: float = 0.05, seed: int = 0) -> float:
    """Share of ``n_sim`` simulated studies of ``n_participants`` whose headline test has ``p < alpha``."""
    if n_participants < 2:
        raise InputError(None, "--participants", f"{n_participants}: the Friedman test needs at least 2 participants")
    rng = np.random.default_rng([int(seed), int(n_participants)])
    p = simulate_p_values(rated_conditions(design, n_participants), strengths, n_sim, rng)
    return float(np.mean(p < alpha))


def n_for_power(design: Design, strengths: Sequence[float], *, target: float = 0.8, max_n: int = 500,
                n_sim: int = 1000, alpha: float = 0.05, seed: int = 0,
                curve: dict[int, float] | None = None) -> int | None:
    """Smallest ``N`` (2..``max_n``) whose simulated power reaches ``target`` (see the module notes)."""
    curve = {} if curve is None else curve

    def power(n: int) -> float:
        if n not in curve:
            curve[n] = power_at(design, n, strengths, n_sim=n_sim, alpha=alpha, seed=seed)
        return curve[n]

    lo, hi = 1, 2
    while power(hi) < target:
        if hi >= max_n:
            return None
        lo, hi = hi, min(2 * hi, max_n)
    while hi - lo > 1:  # power(lo) < target <= power(hi) (lo = 1: no test possible)
        mid = (lo + hi) // 2
        if power(mid) >= target:
            hi = mid
        else:
            lo = mid
    return hi


def session_seconds(design: Design, participant_id: str = "P01", row: int = 0) -> tuple[float, int]:
    """Playing time (s) of one participant's trials, and the number of trials (practice and checks included)."""
    lengths: dict[str, float] = {}
    total = 0.0
    plans = participant_schedule(design, participant_id, row)
    for p in plans:
        if p.stimulus_id not in lengths:
            stim = design.stimulus(p.stimulus_id)
            audio_s = load_audio(stim.audio).duration if stim.duration_s is None else 0.0
            lengths[p.stimulus_id] = trial_duration(stim.duration_s, audio_s)
        total += lengths[p.stimulus_id]
    return total, len(plans)


def plan_study(design: Design, n_participants: int, strengths: dict[str, float], *, n_sim: int = 1000,
               alpha: float = 0.05, target: float = 0.8, max_n: int = 500, answer_s: float = ANSWER_S,
               seed: int = 0) -> PlanResult:
    """Everything ``studyapp plan`` reports for ``n_participants`` (see the module notes)."""
    if not 0 < alpha < 1:
        raise InputError(None, "--alpha", f"{alpha} is not between 0 and 1")
    if not 0 < target < 1:
        raise InputError(None, "--target", f"{target} is not between 0 and 1")
    if n_sim < 10:
        raise InputError(None, "--simulations", f"{n_sim}: need at least 10 simulated studies")
    if not any(b.paradigm == "rank" for b in design.trial_blocks):
        raise InputError(design.path, "blocks", "studyapp plan simulates rank trials (Plackett-Luce rankings); this "
                         "design has no rank block")
    s = [strengths[c] for c in design.condition_ids]
    curve: dict[int, float] = {}
    power = power_at(design, n_participants, s, n_sim=n_sim, alpha=alpha, seed=seed)
    curve[n_participants] = power
    needed = n_for_power(design, s, target=target, max_n=max(max_n, 2), n_sim=n_sim, alpha=alpha, seed=seed,
                         curve=curve)
    sched = full_schedule(design, n_participants)
    seconds, n_trials = session_seconds(design)
    rated = rated_conditions(design, 1).shape[1]
    notes = []
    rows = n_rows(design)
    if n_participants % rows:
        notes.append(f"{n_participants} participants is not a multiple of the design's {rows} rows: clip order and "
                     "slots are not fully balanced (see the counts)")
    ranked = {c for b in design.trial_blocks if b.paradigm == "rank" for c in b.conditions}
    unranked = [c for c in design.condition_ids if c not in ranked]
    if unranked:
        whose = "its strength is" if len(unranked) == 1 else "their strengths are"
        notes.append(f"{', '.join(unranked)} in no rank block: {whose} not used (other paradigms are not simulated)")
    if len({strengths[c] for c in ranked}) == 1:
        notes.append("all strengths are equal: the 'power' is the test's false-positive rate (about alpha)")
    return PlanResult(n_participants=n_participants, strengths=dict(strengths), alpha=alpha, n_sim=n_sim,
                      power=power, target=target, n_for_target=needed, max_n=max_n, curve=dict(sorted(curve.items())),
                      n_rows=rows, rated_trials=rated, balance=balance_counts(sched), trial_seconds=seconds,
                      answer_s=answer_s, n_trials=n_trials, seed=seed, notes=notes)


__all__ = ["ANSWER_S", "PlanResult", "n_for_power", "parse_strengths", "plan_study", "power_at", "rated_conditions",
           "session_seconds", "simulate_p_values"]
