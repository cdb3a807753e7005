"""A participant's trials: which clip, which condition in which slot, practice and attention checks.

The schedule is a pure function of (design, participant id, design row): the same inputs give the same
trials on any machine, so a session can be resumed or audited from the design file alone.

Design rows. A participant's *row* (assigned by the results database, in order of arrival) picks both the
clip order and the slot rotation: Latin-square row ``row mod L`` (``L`` rows of the Williams square, 1 for
random or fixed order) and slot rotation ``row mod 6`` (balanced assignment). :func:`n_rows` is
``lcm(L, 6)`` for balanced slots and ``L`` for random ones, so every block of ``n_rows`` consecutive
participants is fully balanced in both respects.

Trial sequence, in this order (``trial_index`` counts from 0 over all of them):

1. practice trials, in the order of ``practice`` (marked ``is_practice``);
2. the rotation stimuli in the row's order, with the attention checks inserted: with ``m`` rated trials
   and ``c`` checks, check ``i`` (0-based, design order) comes right after rated trial
   ``k = max(1, (i + 1) * m // (c + 1))`` -- spread evenly, never before the first rated trial. When the
   rated trial just before or just after that place shows the check's own clip, the check moves to the
   nearest place (``k + 1``, ``k - 1``, ``k + 2``, ...) where neither neighbour does, so a participant
   never sees the same clip twice in a row (it stays at ``k`` if there is no such place).

A ``frozen`` attention check replaces the condition in slot ``(row + i) mod 3`` by
``"frozen:<that condition's id>"`` (see :class:`studyapp.study.design.AttentionCheck`).

>>> from studyapp.resources import demo_design
>>> from studyapp.study.design import load_design
>>> d = load_design(demo_design())
>>> plan = participant_schedule(d, "P01", row=0)
>>> plan[0].is_practice, sorted(plan[1].slots)
(True, ['lagged', 'static', 'synced'])
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import pandas as pd

from studyapp.study.design import FROZEN_PREFIX, Design
from studyapp.study.ordering import latin_row, n_latin_rows, participant_seed, slot_permutations

SLOT_NAMES = ("left", "middle", "right")
SCHEDULE_COLUMNS = ["participant", "row", "trial_index", "stimulus", "is_practice", "is_attention_check",
                    "slot_left", "slot_middle", "slot_right"]


@dataclass(frozen=True)
class TrialPlan:
    """One trial as scheduled.

    Attributes
    ----------
    trial_index: 0-based position in the participant's sequence (practice and checks included).
    stimulus_id: the clip.
    slots: condition ids in left, middle, right order (a frozen check slot is ``"frozen:<id>"``).
    is_practice: a practice trial (answers stored but marked, excluded from analysis by default).
    is_attention_check: an attention-check trial (see ``attention_check``).
    row: the participant's design row.
    """

    trial_index: int
    stimulus_id: str
    slots: tuple[str, str, str]
    is_practice: bool
    is_attention_check: bool
    row: int

    @property
    def slot_of(self) -> dict[str, int]:
        """Condition id -> slot index (0 left, 1 middle, 2 right)."""
        return {c: i for i, c in enumerate(self.slots)}


def latin_rows(design: Design) -> int:
    """Number of clip orders the design cycles through (Williams rows, or 1 for random/fixed order)."""
    if design.ordering != "balanced-latin-square":
        return 1
    return n_latin_rows(len(design.rotation_stimuli))


def n_rows(design: Design) -> int:
    """Number of distinct design rows: after this many participants clip order and slots are balanced."""
    rows = latin_rows(design)
    return math.lcm(rows, 6) if design.slot_assignment == "balanced" else rows


def default_row(design: Design, participant_id: str) -> int:
    """Row derived from the participant id alone (used when no database assigns rows)."""
    return participant_seed(design.seed, participant_id, "row") % n_rows(design)


def attention_positions(n_rated: int, n_checks: int) -> list[int]:
    """Number of rated trials before each attention check (see the module notes).

    >>> attention_positions(8, 2), attention_positions(4, 1), attention_positions(1, 2)
    ([2, 5], [2], [1, 1])
    """
    return [max(1, (i + 1) * n_rated // (n_checks + 1)) if n_rated else 0 for i in range(n_checks)]


def place_check(nominal: int, order: list[str], stimulus_id: str) -> int:
    """Rated trials before a check: ``nominal`` moved off any neighbour showing the same clip.

    >>> place_check(2, ["a", "b", "c", "d"], "b"), place_check(2, ["a", "b", "c", "d"], "x")
    (3, 2)
    """
    m = len(order)

    def clear(k: int) -> bool:
        return order[k - 1] != stimulus_id and (k >= m or order[k] != stimulus_id)

    for delta in range(0, m + 1):
        for k in ((nominal + delta, nominal - delta) if delta else (nominal,)):
            if 1 <= k <= m and clear(k):
                return k
    return nominal


def participant_schedule(design: Design, participant_id: str, row: int | None = None) -> list[TrialPlan]:
    """Every trial of one participant, in presentation order (see the module notes for the rules)."""
    if row is None:
        row = default_row(design, participant_id)
    row = int(row)
    if row < 0:
        raise ValueError(f"design row must be >= 0, got {row}")
    conds = design.condition_ids
    mode = design.slot_assignment
    k = row % 6

    def arrange(perm: tuple[int, int, int]) -> tuple[str, str, str]:
        return (conds[perm[0]], conds[perm[1]], conds[perm[2]])

    order = latin_row(design, row % latin_rows(design), participant_id)
    # Practice and checks draw from shifted streams so they do not eat into the rated trials' balance.
    rated_perms = slot_permutations(len(order), participant_seed(design.seed, participant_id, "slots"), k, mode)
    practice_perms = slot_permutations(len(design.practice),
                                       participant_seed(design.seed, participant_id, "practice"), k + 3, mode)
    check_perms = slot_permutations(len(design.attention_checks),
                                    participant_seed(design.seed, participant_id, "checks"), k + 1, mode)

    entries: list[tuple[str, tuple[str, str, str], bool, bool]] = []
    for sid, perm in zip(design.practice, practice_perms):
        entries.append((sid, arrange(perm), True, False))
    after = [place_check(k, order, c.stimulus)
             for k, c in zip(attention_positions(len(order), len(design.attention_checks)), design.attention_checks)]
    for t, (sid, perm) in enumerate(zip(order, rated_perms)):
        entries.append((sid, arrange(perm), False, False))
        for i, check in enumerate(design.attention_checks):
            if after[i] == t + 1:
                slots = list(arrange(check_perms[i]))
                if check.kind == "frozen":
                    s = (row + i) % 3
                    slots[s] = FROZEN_PREFIX + slots[s]
                entries.append((check.stimulus, (slots[0], slots[1], slots[2]), False, True))
    return [TrialPlan(i, sid, slots, prac, att, row) for i, (sid, slots, prac, att) in enumerate(entries)]


def participant_ids(n_participants: int) -> list[str]:
    """Default participant ids ``P01, P02, ...`` (zero-padded to the width of the largest)."""
    width = max(2, len(str(n_participants)))
    return [f"P{k + 1:0{width}d}" for k in range(n_participants)]


def schedule_frame(plans: dict[str, list[TrialPlan]]) -> pd.DataFrame:
    """One row per participant x trial, columns :data:`SCHEDULE_COLUMNS`."""
    records = [
        (pid, p.row, p.trial_index, p.stimulus_id, p.is_practice, p.is_attention_check, *p.slots)
        for pid, trials in plans.items() for p in trials
    ]
    return pd.DataFrame.from_records(records, columns=SCHEDULE_COLUMNS)


def full_schedule(design: Design, n_participants: int) -> pd.DataFrame:
    """The plan for participants ``P01..PNN`` arriving in order (participant ``k`` gets row ``k mod n_rows``).

    >>> from studyapp.resources import demo_design
    >>> from studyapp.study.design import load_design
    >>> full_schedule(load_design(demo_design()), 2).shape[1]
    9
    """
    if n_participants < 1:
        raise ValueError(f"need at least one participant, got {n_participants}")
    rows = n_rows(design)
    return schedule_frame({pid: participant_schedule(design, pid, k % rows)
                           for k, pid in enumerate(participant_ids(n_participants))})


def balance_counts(df: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """Balance of a schedule's rated trials (practice and attention checks left out).

    Returns ``position_x_stimulus`` (rated-trial position, 1-based, x stimulus: how often each clip comes
    at each position) and ``slot_x_condition`` (condition x slot: how often each condition sits in each slot).
    """
    rated = df[~df["is_practice"].astype(bool) & ~df["is_attention_check"].astype(bool)].copy()
    rated["position"] = rated.groupby("participant").cumcount() + 1
    pos = pd.crosstab(rated["position"], rated["stimulus"])
    long = rated.melt(id_vars=["participant"], value_vars=[f"slot_{s}" for s in SLOT_NAMES],
                      var_name="slot", value_name="condition")
    long["slot"] = pd.Categorical(long["slot"].str.removeprefix("slot_"), categories=list(SLOT_NAMES))
    slots = pd.crosstab(long["condition"], long["slot"], dropna=False)
    return {"position_x_stimulus": pos, "slot_x_condition": slots}
