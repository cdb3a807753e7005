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

Blocks (``[[blocks]]``, see :class:`studyapp.study.design.Block`). A design without blocks is the one rank
block ``"main"`` above, trial for trial. With blocks, the sequence is: the practice clips (trials of the FIRST
block's paradigm, its conditions; a rank block's practice is as above), then each block in design order, its
stimuli in the row's order (a Williams row over the block's stimuli, ``row mod L_b``); attention checks go
into the first ``rank`` block as above. ``trial_index`` counts over everything. Per block, with ``s`` the
position of the trial's stimulus in the block's ``stimuli`` and ``r`` the row:

* ``rank``: as above (slot rotation ``row mod 6``); its period is ``lcm(L_b, 6)`` (``L_b`` for random slots).
* ``pairwise``: the ``P = n(n-1)/2`` unordered pairs of the block's ``n`` conditions in
  ``itertools.combinations`` order; stimulus ``s`` shows pair ``(r + s) mod P``, in design order when
  ``(r // P + s)`` is even, swapped when odd (random slots: a seeded coin). Period ``lcm(L_b, 2P)``: over
  it every stimulus shows every pair equally often, each condition on the left as often as on the right.
* ``mismatch``: stimulus ``s`` shows condition ``(r + s) mod n`` in both slots; one slot plays the
  stimulus's own motion (``motion_stimuli`` = the stimulus), the other the same condition's motion for a
  source clip, ``O_s[(r // 2n) mod |O_s|]`` where ``O_s`` lists the block's other stimuli with the same
  ``match_tag`` value in block order; the matched motion is on the left when ``(r // n + s)`` is even. The
  audio and face are the trial's stimulus's in both slots. Period ``lcm(L_b, 2n * lcm(|O_s|))``: over it
  every condition x stimulus is matched-left as often as matched-right, with each source equally often on
  each side.
* ``rating``: the block's figures (conditions, then the hidden reference) rotated left by ``(r + s) mod k``
  (random slots: a seeded permutation). Period ``lcm(L_b, k)``: every figure in every slot equally often per
  stimulus; the reference is in every trial.

Practice clips of a pairwise, mismatch or rating first block follow the same rules with ``s`` = the practice
clip's position + 1 (so a practice clip that is also rated is shown differently), outside the balance.

:func:`n_rows` is the lcm of every block's period (and of the conditions' ``samples``).

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
from itertools import combinations
from typing import TYPE_CHECKING

import numpy as np

from studyapp.study.design import FROZEN_PREFIX, Block, Design
# one rule for which clips a mismatch trial may play, shared with the played pairs (design/played.py)
from studyapp.study.design.played import mismatch_sources
from studyapp.study.ordering import latin_row, n_latin_rows, participant_seed, slot_permutations

if TYPE_CHECKING:  # pandas is imported where a table is built: loading a design must not pay ~0.3-1 s for it
    import pandas as pd

SLOT_NAMES = ("left", "middle", "right")
SCHEDULE_COLUMNS = ["participant", "row", "trial_index", "stimulus", "is_practice", "is_attention_check",
                    "slot_left", "slot_middle", "slot_right", "sample_left", "sample_middle", "sample_right"]
#: Columns a design with ``[[blocks]]`` adds to its schedule table (slots and motion stimuli ``;``-joined).
BLOCK_COLUMNS = ["block", "paradigm", "slots", "motion_stimuli"]


def three_slots(values: tuple, empty: object = "") -> tuple:
    """A trial's per-slot values in the three left/middle/right columns of the results and schedule tables:
    three slots as they are; two slots (pairwise, mismatch, a two-figure rating) as ``(left, empty, right)``;
    more than three, the first three (the full list is stored per slot elsewhere).

    >>> three_slots(("a", "b")), three_slots(("a", "b", "c", "d"))
    (('a', '', 'b'), ('a', 'b', 'c'))
    """
    values = tuple(values)
    if len(values) == 2:
        return (values[0], empty, values[1])
    return tuple(values[:3]) + (empty,) * max(0, 3 - len(values))


@dataclass(frozen=True)
class TrialPlan:
    """One trial as scheduled.

    Attributes
    ----------
    trial_index: 0-based position in the participant's sequence (practice and checks included, all blocks).
    stimulus_id: the clip: its audio and face play for every slot.
    slots: condition ids per slot, left to right: 3 for rank (a frozen check slot is ``"frozen:<id>"``), 2 for
        pairwise and mismatch (mismatch: the same condition twice), every figure for rating.
    is_practice: a practice trial (answers stored but marked, excluded from analysis by default).
    is_attention_check: an attention-check trial (see ``attention_check``).
    row: the participant's design row.
    samples: per slot, the 1-based sample of the slot's condition shown (1 for a condition with one sample).
    block: the id of the trial's block (``"main"`` in a design without blocks).
    paradigm: ``"rank"``, ``"pairwise"``, ``"mismatch"`` or ``"rating"``: which answer the trial asks.
    motion_stimuli: per slot, the stimulus whose motion the slot plays; ``()`` means ``stimulus_id`` for all
        (mismatch trials name the source clip of the mismatched slot).
    """

    trial_index: int
    stimulus_id: str
    slots: tuple[str, ...]
    is_practice: bool
    is_attention_check: bool
    row: int
    samples: tuple[int, ...] = (1, 1, 1)
    block: str = "main"
    paradigm: str = "rank"
    motion_stimuli: tuple[str, ...] = ()

    @property
    def slot_of(self) -> dict[str, int]:
        """Condition id -> slot index (0 left, 1 middle, 2 right); a mismatch trial's one condition maps to
        its last slot, so use :attr:`matched_slot` there."""
        return {c: i for i, c in enumerate(self.slots)}

    def motion_stimulus(self, slot: int) -> str:
        """The stimulus whose motion slot ``slot`` plays."""
        return self.motion_stimuli[slot] if self.motion_stimuli else self.stimulus_id

    @property
    def matched_slot(self) -> int | None:
        """A mismatch trial's slot that plays the clip's own motion (None for other paradigms)."""
        if self.paradigm != "mismatch":
            return None
        return next(i for i in range(len(self.slots)) if self.motion_stimulus(i) == self.stimulus_id)


def latin_rows(design: Design) -> int:
    """Number of clip orders the design cycles through (Williams rows, or 1 for random/fixed order)."""
    if design.ordering != "balanced-latin-square":
        return 1
    return n_latin_rows(len(design.rotation_stimuli))


def n_rows(design: Design) -> int:
    """Number of distinct design rows: after this many participants clip order and slots are balanced."""
    rows = math.lcm(*(block_period(design, b) for b in design.trial_blocks))
    return math.lcm(rows, *(max(1, c.samples) for c in design.conditions))


def block_latin_rows(design: Design, block: Block) -> int:
    """Clip orders a block cycles through (Williams rows over its stimuli, 1 for random or fixed order)."""
    return n_latin_rows(len(block.stimuli)) if design.ordering == "balanced-latin-square" else 1


def block_period(design: Design, block: Block) -> int:
    """Rows after which the block is balanced (see the module notes)."""
    rows = block_latin_rows(design, block)
    balanced = design.slot_assignment == "balanced"
    if block.paradigm == "rank":
        return math.lcm(rows, 6) if balanced else rows
    if block.paradigm == "pairwise":
        return math.lcm(rows, 2 * max(1, math.comb(len(block.conditions), 2)))
    if block.paradigm == "mismatch":
        n = max(1, len(block.conditions))
        sources = [len(mismatch_sources(design, block, s)) or 1 for s in block.stimuli]
        return math.lcm(rows, 2 * n * math.lcm(*sources))
    return math.lcm(rows, len(block.figures)) if balanced else rows


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
    blocks = design.trial_blocks
    first_rank = next((b for b in blocks if b.paradigm == "rank"), None)
    # entries: (stimulus, slots, practice, check, block, motion stimuli)
    entries: list[tuple[str, tuple[str, ...], bool, bool, Block, tuple[str, ...]]] = []
    for sid, slots, motions in _block_trials(design, blocks[0], participant_id, row, list(design.practice),
                                             practice=True):
        entries.append((sid, slots, True, False, blocks[0], motions))
    for n, block in enumerate(blocks):
        suffix = "" if n == 0 else f":{block.id}"  # a design without blocks draws exactly as it always did
        order = latin_row(design, row % block_latin_rows(design, block), participant_id, block.stimuli,
                          "order" + suffix)
        trials = _block_trials(design, block, participant_id, row, order, practice=False, stream=suffix)
        checks = design.attention_checks if block is first_rank else []
        after = [place_check(k, order, c.stimulus)
                 for k, c in zip(attention_positions(len(order), len(checks)), checks)]
        check_perms = slot_permutations(len(checks), participant_seed(design.seed, participant_id, "checks" + suffix),
                                        row % 6 + 1, design.slot_assignment)
        conds = block.conditions
        for t, (sid, slots, motions) in enumerate(trials):
            entries.append((sid, slots, False, False, block, motions))
            for i, check in enumerate(checks):
                if after[i] == t + 1:
                    perm = check_perms[i]
                    cslots = [conds[perm[0]], conds[perm[1]], conds[perm[2]]]
                    if check.kind == "frozen":
                        s = (row + i) % 3
                        cslots[s] = FROZEN_PREFIX + cslots[s]
                    entries.append((check.stimulus, tuple(cslots), False, True, block, ()))
    plans = []
    for i, (sid, slots, prac, att, block, motions) in enumerate(entries):
        shown = motions or (sid,) * len(slots)
        samples = tuple(sample_for(design, row, m, c) for m, c in zip(shown, slots))
        plans.append(TrialPlan(i, sid, slots, prac, att, row, samples, block.id, block.paradigm, motions))
    return plans


def _block_trials(design: Design, block: Block, participant_id: str, row: int, order: list[str], *,
                  practice: bool, stream: str = "") -> list[tuple[str, tuple[str, ...], tuple[str, ...]]]:
    """``(stimulus, slots, motion stimuli)`` of a block's trials on the stimuli ``order`` (see the module
    notes); ``practice``: the practice clips, drawn from their own streams so they leave the balance alone."""
    mode = design.slot_assignment
    conds = block.conditions
    k = row % 6
    if block.paradigm == "rank":
        if practice:
            perms = slot_permutations(len(order), participant_seed(design.seed, participant_id, "practice" + stream),
                                      k + 3, mode)
        else:
            perms = slot_permutations(len(order), participant_seed(design.seed, participant_id, "slots" + stream),
                                      k, mode)
        return [(sid, (conds[p[0]], conds[p[1]], conds[p[2]]), ()) for sid, p in zip(order, perms)]
    rng = np.random.default_rng(participant_seed(design.seed, participant_id,
                                                 ("practice:" if practice else "sides:") + block.id))
    out: list[tuple[str, tuple[str, ...], tuple[str, ...]]] = []
    for j, sid in enumerate(order):
        # rated trials go by the stimulus's place in the block; practice clips by their own position, one
        # step on, so a practice clip that is also rated is not shown the same way twice
        s = j + 1 if practice or sid not in block.stimuli else block.stimuli.index(sid)
        if block.paradigm == "pairwise":
            pairs = list(combinations(conds, 2))
            p = len(pairs)
            pair = pairs[(row + s) % p]
            swap = bool(rng.integers(2)) if mode == "random" else (row // p + s) % 2 == 1
            out.append((sid, pair[::-1] if swap else pair, ()))
        elif block.paradigm == "mismatch":
            n = len(conds)
            cond = conds[(row + s) % n]
            sources = mismatch_sources(design, block, sid)
            source = sources[(row // (2 * n)) % len(sources)]
            left = (row // n + s) % 2 == 0
            out.append((sid, (cond, cond), (sid, source) if left else (source, sid)))
        else:  # rating
            figs = block.figures
            if mode == "random":
                out.append((sid, tuple(figs[i] for i in rng.permutation(len(figs))), ()))
            else:
                rot = (row + s) % len(figs)
                out.append((sid, tuple(figs[rot:] + figs[:rot]), ()))
    return out


def participant_ids(n_participants: int) -> list[str]:
    """Default participant ids ``P01, P02, ...`` (zero-padded to the width of the largest)."""
    width = max(2, len(str(n_participants)))
    return [f"P{k + 1:0{width}d}" for k in range(n_participants)]


def schedule_frame(plans: dict[str, list[TrialPlan]]) -> pd.DataFrame:
    """One row per participant x trial, columns :data:`SCHEDULE_COLUMNS` (slots as :func:`three_slots` puts
    them), plus :data:`BLOCK_COLUMNS` for a design with ``[[blocks]]``."""
    import pandas as pd

    blocked = any(p.block != "main" or p.paradigm != "rank" for trials in plans.values() for p in trials)
    records = [
        (pid, p.row, p.trial_index, p.stimulus_id, p.is_practice, p.is_attention_check, *three_slots(p.slots),
         *three_slots(p.samples, None))
        + ((p.block, p.paradigm, ";".join(p.slots), ";".join(p.motion_stimuli)) if blocked else ())
        for pid, trials in plans.items() for p in trials
    ]
    return pd.DataFrame.from_records(records, columns=SCHEDULE_COLUMNS + (BLOCK_COLUMNS if blocked else []))


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


def block_counts(df: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """Balance of a blocked schedule's rated trials (a table with :data:`BLOCK_COLUMNS`): ``figure_x_slot``
    ((block, condition) x slot position: how often each condition is shown in each slot; a mismatch trial
    counts its one condition in both) and ``matched_side`` ((block, condition, stimulus) x side of the
    figure playing its own motion, mismatch blocks only)."""
    import pandas as pd

    rated = df[~df["is_practice"].astype(bool) & ~df["is_attention_check"].astype(bool)]
    rows = [(b, c, i) for b, slots in zip(rated["block"], rated["slots"]) for i, c in enumerate(slots.split(";"))]
    seats = pd.DataFrame(rows, columns=["block", "condition", "slot"])
    out = {"figure_x_slot": pd.crosstab([seats["block"], seats["condition"]], seats["slot"])}
    mm = rated[rated["paradigm"] == "mismatch"]
    if len(mm):
        side = ["left" if m.split(";")[0] == s else "right" for m, s in zip(mm["motion_stimuli"], mm["stimulus"])]
        out["matched_side"] = pd.crosstab([mm["block"], mm["slot_left"], mm["stimulus"]],
                                          pd.Series(side, index=mm.index, name="matched"))
    return out


def balance_counts(df: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """Balance of a schedule's rated trials (practice and attention checks left out).

    Returns ``position_x_stimulus`` (rated-trial position, 1-based, x stimulus: how often each clip comes
    at each position), ``slot_x_condition`` (condition x slot: how often each condition sits in each slot)
    and ``sample_x_condition_stimulus`` ((condition, stimulus) x sample: how often each sample is shown).
    """
    import pandas as pd

    rated = df[~df["is_practice"].astype(bool) & ~df["is_attention_check"].astype(bool)].copy()
    if "paradigm" in rated:  # these counts are the rank blocks'; other paradigms are counted by their tests
        rated = rated[rated["paradigm"] == "rank"]
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
