"""A participant's trials: which clip, which condition in which slot, practice and attention checks.

The schedule is a pure function of (design, participant id, design row): the same inputs give the same
trials on any machine, so a session can be resumed or audited from the design file alone.

Design rows. A participant's *row* (assigned by the results database, in order of arrival) picks both the
clip order and the slot rotation: Latin-square row ``row mod L`` (``L`` rows of the Williams square, 1 for
random or fixed order) and slot rotation ``row mod 6`` (balanced assignment). :func:`n_rows` is
``lcm(L, 6)`` for balanced slots and ``L`` for random ones (times whatever the conditions' ``samples`` add to
that least common multiple), so every block of ``n_rows`` consecutive participants is fully balanced in
every respect.

Samples. A condition with ``samples = N`` shows, in every trial of stimulus ``s``, sample
``(row + s + c) mod N + 1`` (1-based; ``s`` the stimulus's position in the design, ``c`` the condition's):
any ``N`` consecutive rows show each sample of each condition x stimulus once, and within one participant
the samples differ across clips and conditions rather than all being sample 1. A frozen slot shows the
first frame of the sample its condition would have shown.

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
from typing import TYPE_CHECKING

from studyapp.study.design import FROZEN_PREFIX, Design
from studyapp.study.ordering import latin_row, n_latin_rows, participant_seed, slot_permutations

if TYPE_CHECKING:  # pandas is imported where a table is built: loading a design must not pay ~0.3-1 s for it
    import pandas as pd

SLOT_NAMES = ("left", "middle", "right")
SCHEDULE_COLUMNS = ["participant", "row", "trial_index", "stimulus", "is_practice", "is_attention_check",
                    "slot_left", "slot_middle", "slot_right", "sample_left", "sample_middle", "sample_right"]


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
    samples: per slot, the 1-based sample of the slot's condition shown (1 for a condition with one sample).
    """

    trial_index: int
    stimulus_id: str
    slots: tuple[str, str, str]
    is_practice: bool
    is_attention_check: bool
    row: int
    samples: tuple[int, ...] = (1, 1, 1)

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
    rows = math.lcm(rows, 6) if design.slot_assignment == "balanced" else rows
    return math.lcm(rows, *(max(1, c.samples) for c in design.conditions))


def sample_for(design: Design, row: int, stimulus_id: str, condition_id: str) -> int:
    """The 1-based sample of a condition shown to design row ``row`` for a stimulus (see the module notes).

    >>> from dataclasses import replace
    >>> from studyapp.resources import demo_design
    >>> from studyapp.study.design import load_design
    >>> d = load_design(demo_design())
    >>> d.conditions[1] = replace(d.conditions[1], samples=3)
    >>> [sample_for(d, row, "clip01", "lagged") for row in range(4)], sample_for(d, 0, "clip01", "synced")
    ([2, 3, 1, 2], 1)
    """
    ids = design.condition_ids
    cid = condition_id.removeprefix(FROZEN_PREFIX)
    n = max(1, design.condition(cid).samples)
    stim_pos = [s.id for s in design.stimuli].index(stimulus_id)
    return (row + stim_pos + ids.index(cid)) % n + 1


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
    return [TrialPlan(i, sid, slots, prac, att, row, tuple(sample_for(design, row, sid, c) for c in slots))
            for i, (sid, slots, prac, att) in enumerate(entries)]


def participant_ids(n_participants: int) -> list[str]:
    """Default participant ids ``P01, P02, ...`` (zero-padded to the width of the largest)."""
    width = max(2, len(str(n_participants)))
    return [f"P{k + 1:0{width}d}" for k in range(n_participants)]


def schedule_frame(plans: dict[str, list[TrialPlan]]) -> pd.DataFrame:
    """One row per participant x trial, columns :data:`SCHEDULE_COLUMNS`."""
    import pandas as pd

    records = [
        (pid, p.row, p.trial_index, p.stimulus_id, p.is_practice, p.is_attention_check, *p.slots, *p.samples)
        for pid, trials in plans.items() for p in trials
    ]
    return pd.DataFrame.from_records(records, columns=SCHEDULE_COLUMNS)


def full_schedule(design: Design, n_participants: int) -> pd.DataFrame:
    """The plan for participants ``P01..PNN`` arriving in order (participant ``k`` gets row ``k mod n_rows``).

    >>> from studyapp.resources import demo_design
    >>> from studyapp.study.design import load_design
    >>> full_schedule(load_design(demo_design()), 2).shape[1]
    12
    """
    if n_participants < 1:
        raise ValueError(f"need at least one participant, got {n_participants}")
    rows = n_rows(design)
    return schedule_frame({pid: participant_schedule(design, pid, k % rows)
                           for k, pid in enumerate(participant_ids(n_participants))})


def balance_counts(df: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """Balance of a schedule's rated trials (practice and attention checks left out).

    Returns ``position_x_stimulus`` (rated-trial position, 1-based, x stimulus: how often each clip comes
    at each position), ``slot_x_condition`` (condition x slot: how often each condition sits in each slot)
    and ``sample_x_condition_stimulus`` ((condition, stimulus) x sample: how often each sample is shown).
    """
    import pandas as pd

    rated = df[~df["is_practice"].astype(bool) & ~df["is_attention_check"].astype(bool)].copy()
    rated["position"] = rated.groupby("participant").cumcount() + 1
    pos = pd.crosstab(rated["position"], rated["stimulus"])
    long = rated.melt(id_vars=["participant"], value_vars=[f"slot_{s}" for s in SLOT_NAMES],
                      var_name="slot", value_name="condition")
    long["slot"] = pd.Categorical(long["slot"].str.removeprefix("slot_"), categories=list(SLOT_NAMES))
    slots = pd.crosstab(long["condition"], long["slot"], dropna=False)
    shown = pd.DataFrame({
        "condition": pd.concat([rated[f"slot_{s}"] for s in SLOT_NAMES], ignore_index=True),
        "stimulus": pd.concat([rated["stimulus"]] * len(SLOT_NAMES), ignore_index=True),
        "sample": pd.concat([rated[f"sample_{s}"] for s in SLOT_NAMES], ignore_index=True),
    })
    samples = pd.crosstab([shown["condition"], shown["stimulus"]], shown["sample"])
    return {"position_x_stimulus": pos, "slot_x_condition": slots, "sample_x_condition_stimulus": samples}
