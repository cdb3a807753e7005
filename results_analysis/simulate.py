"""Synthetic study results in the tidy export format, for examples, tests and benchmarks.

Each participant ranks the conditions of every stimulus on every criterion. A ranking is drawn from a
Plackett-Luce model (the ranking analogue of Bradley-Terry): the best place goes to condition i with
probability proportional to its strength, then the next among the rest, and so on. Conditions are
assigned to slots at random, as in the app.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd


def simulate_results(n_participants: int = 24, n_stimuli: int = 8, *,
                     conditions: Sequence[str] = ("FaceCapGes", "DiffSHEG", "CaMN"),
                     criteria: Sequence[str] = ("realism", "synchronization", "diversity"),
                     strengths: Mapping[str, Sequence[float]] | Sequence[float] | None = None,
                     n_practice: int = 1, n_attention: int = 1, fail_attention: Sequence[str] = (),
                     speakers: int = 4, design_hash: str = "synthetic", seed: int = 0) -> pd.DataFrame:
    """A tidy results frame: participants P01.., stimuli clip1.. tagged with ``speaker``, participants
    grouped by ``device`` (vr / desktop), practice and attention-check trials included.

    ``strengths`` gives Plackett-Luce strengths per condition (one list, or one per criterion); by
    default the first condition is clearly best. Participants in ``fail_attention`` fail their checks.

    >>> df = simulate_results(4, 2, seed=1)
    >>> sorted(df.columns)[:4], len(df[~df.is_practice & ~df.is_attention_check])
    (['app_version', 'attention_passed', 'condition', 'criterion'], 72)
    """
    rng = np.random.default_rng(seed)
    conditions = list(conditions)
    criteria = list(criteria)
    k = len(conditions)
    if strengths is None:
        strengths = [4.0] + [1.0 + 0.5 * i for i in range(k - 1)][::-1]
    if not isinstance(strengths, Mapping):
        strengths = {c: strengths for c in criteria}
    width = len(str(n_participants))
    participants = [f"P{i + 1:0{max(2, width)}d}" for i in range(n_participants)]
    stim = [f"clip{s + 1}" for s in range(n_stimuli)]
    trials = []  # (stimulus, is_practice, is_attention_check)
    trials += [(f"practice{i + 1}", True, False) for i in range(n_practice)]
    rows: dict[str, list] = {}
    for p_i, p in enumerate(participants):
        order = [stim[i] for i in rng.permutation(n_stimuli)]
        seq = trials + [(s, False, False) for s in order]
        for a in range(n_attention):
            seq.insert(n_practice + (a + 1) * len(order) // (n_attention + 1) + a, (f"attention{a + 1}", False, True))
        part = _participant_rows(rng, p, p_i, seq, conditions, criteria, strengths, fail_attention, speakers,
                                 design_hash)
        for col, values in part.items():
            rows.setdefault(col, []).extend(values)
    return pd.DataFrame(rows)


def _participant_rows(rng, p, p_i, seq, conditions, criteria, strengths, fail_attention, speakers, design_hash):
    k = len(conditions)
    cols: dict[str, list] = {c: [] for c in (
        "participant", "session", "trial_index", "stimulus", "criterion", "condition", "slot", "rank", "plays",
        "response_time_s", "is_practice", "is_attention_check", "attention_passed", "speaker", "device",
        "design_hash", "app_version")}
    device = "vr" if p_i % 4 != 3 else "desktop"
    for t, (stimulus, practice, attention) in enumerate(seq):
        slots = rng.permutation(k)
        plays = int(rng.integers(1, 4))
        rt = float(rng.gamma(4.0, 5.0))
        passed = not (attention and p in fail_attention)
        speaker = f"speaker{(int(stimulus[4:]) - 1) % speakers + 1}" if stimulus.startswith("clip") else ""
        for crit in criteria:
            ranks = _plackett_luce_ranks(rng, np.asarray(strengths[crit], dtype=float))
            for c in range(k):
                cols["participant"].append(p)
                cols["session"].append(1)
                cols["trial_index"].append(t)
                cols["stimulus"].append(stimulus)
                cols["criterion"].append(crit)
                cols["condition"].append(conditions[c])
                cols["slot"].append(int(slots[c]))
                cols["rank"].append(float(ranks[c]))
                cols["plays"].append(plays)
                cols["response_time_s"].append(rt)
                cols["is_practice"].append(practice)
                cols["is_attention_check"].append(attention)
                cols["attention_passed"].append(passed)
                cols["speaker"].append(speaker)
                cols["device"].append(device)
                cols["design_hash"].append(design_hash)
                cols["app_version"].append("synthetic")
    return cols


def _plackett_luce_ranks(rng: np.random.Generator, strengths: np.ndarray) -> np.ndarray:
    """Ranks (1 = best) of one Plackett-Luce draw: Gumbel-max trick, order of log-strength + Gumbel noise."""
    keys = np.log(strengths) + rng.gumbel(size=strengths.size)
    order = np.argsort(-keys)
    ranks = np.empty(strengths.size)
    ranks[order] = np.arange(1, strengths.size + 1)
    return ranks
