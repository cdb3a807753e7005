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

from results_analysis.pairwise import elo_win_probability


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


# --- the other response paradigms ------------------------------------------------------------------------

def simulate_paradigm(paradigm: str, n_participants: int = 24, n_stimuli: int = 8, *,
                      conditions: Sequence[str] = ("A", "B", "C"), criteria: Sequence[str] = ("realism",),
                      truth: Mapping[str, float] | None = None, block: str | None = None, levels: int = 5,
                      tie_rate: float = 0.2, reference: str | None = None, reference_mean: float = 97.0,
                      bad_raters: Sequence[str] = (), noise_sd: float = 12.0, participant_sd: float = 6.0,
                      speakers: int = 2, trial_offset: int = 0, seed: int = 0) -> pd.DataFrame:
    """A tidy results frame of one ``pairwise``, ``mismatch`` or ``rating`` block with a known truth.

    ``truth`` per condition (default: evenly spread):

    * pairwise: Elo (mean 0). A trial shows two conditions; the left one's *expected score* (win 1, tie 1/2,
      loss 0) is :func:`results_analysis.pairwise.elo_win_probability` of the Elo difference: a tie with
      probability ``tie_rate``, else a win or loss drawn so that the expectation holds. Every unordered pair appears equally often (pairs
      rotate over stimuli and participants), sides alternate.
    * mismatch: the matched-preference rate (expected score of the matched slot); ties with ``tie_rate``.
      Conditions rotate over stimuli, the matched slot alternates sides, the mismatched motion is another
      stimulus with the same ``speaker`` tag.
    * rating: the mean rating 0..100; each participant adds an offset (``participant_sd``) and each rating noise
      (``noise_sd``), clipped to 0..100. ``reference`` adds a hidden reference condition to every trial, rated
      around ``reference_mean`` (participants in ``bad_raters`` rate it around 50: MUSHRA screening finds them).

    Preferences are clearly (+-2) or slightly (+-1) at random with ``levels=5``, +-1 with ``levels=3``.

    >>> df = simulate_paradigm("pairwise", 6, 3, seed=1)
    >>> len(df), sorted(set(df.paradigm)), float(df.groupby(["participant", "trial_index"]).preference.sum().abs().max())
    (36, ['pairwise'], 0.0)
    """
    if paradigm not in ("pairwise", "mismatch", "rating"):
        raise ValueError(f"paradigm must be pairwise, mismatch or rating, not {paradigm!r}")
    rng = np.random.default_rng(seed)
    conditions, criteria = list(conditions), list(criteria)
    k = len(conditions)
    if truth is None:
        spread = {"pairwise": np.linspace(150, -150, k), "mismatch": np.linspace(0.75, 0.5, k),
                  "rating": np.linspace(70, 30, k)}[paradigm]
        truth = dict(zip(conditions, spread.tolist()))
    block = block or paradigm
    width = max(2, len(str(n_participants)))
    participants = [f"P{i + 1:0{width}d}" for i in range(n_participants)]
    stim = [f"clip{s + 1}" for s in range(n_stimuli)]
    speaker = {s: f"speaker{i % speakers + 1}" for i, s in enumerate(stim)}
    pairs = [(i, j) for i in range(k) for j in range(i + 1, k)]
    rows: list[dict] = []

    def score(p_win: float) -> float:
        """1, 1/2 or 0 with expectation p_win (ties with tie_rate, or less where p_win is near 0 or 1)."""
        t = min(tie_rate, 2 * p_win, 2 * (1 - p_win))
        u = rng.random()
        return 0.5 if u < t else (1.0 if u < t + (p_win - t / 2) else 0.0)

    def level(s: float) -> float:
        mag = 1.0 if levels == 3 else float(rng.choice([1.0, 2.0]))
        return 0.0 if s == 0.5 else (mag if s == 1.0 else -mag)

    for p_i, p in enumerate(participants):
        offset = rng.normal(0.0, participant_sd)
        for s_i, s in enumerate(stim):
            t = trial_offset + s_i
            base = dict(participant=p, session=1, trial_index=t, stimulus=s, rank=np.nan, plays=1,
                        response_time_s=float(rng.gamma(4.0, 4.0)), is_practice=False, is_attention_check=False,
                        attention_passed=True, block=block, paradigm=paradigm, speaker=speaker[s],
                        design_hash="synthetic", app_version="synthetic")
            if paradigm == "pairwise":
                i, j = pairs[(p_i + s_i) % len(pairs)]
                if (p_i // len(pairs) + s_i) % 2:
                    i, j = j, i
                for crit in criteria:
                    pref = level(score(float(elo_win_probability(truth[conditions[i]] - truth[conditions[j]]))))
                    reasons = "[]" if pref == 0 else '["Hands"]'
                    for slot, c, v in ((0, i, pref), (1, j, -pref)):
                        rows.append(base | dict(criterion=crit, condition=conditions[c], slot=slot, rating=np.nan,
                                                preference=v, matched=np.nan, motion_stimulus=s, reasons=reasons))
            elif paradigm == "mismatch":
                c = conditions[(p_i + s_i) % k]
                same = [o for o in stim if speaker[o] == speaker[s] and o != s] or [o for o in stim if o != s]
                other = same[(p_i + s_i) % len(same)]
                left_matched = (p_i + s_i // k) % 2 == 0
                for crit in criteria:
                    pref = level(score(truth[c]))  # for the matched slot
                    for slot in (0, 1):
                        matched = (slot == 0) == left_matched
                        rows.append(base | dict(criterion=crit, condition=c, slot=slot, rating=np.nan,
                                                preference=pref if matched else -pref, matched=float(matched),
                                                motion_stimulus=s if matched else other, reasons="[]"))
            else:
                shown = conditions + ([reference] if reference else [])
                order = [shown[(x + p_i + s_i) % len(shown)] for x in range(len(shown))]
                for crit in criteria:
                    for slot, c in enumerate(order):
                        if c == reference:
                            mean = 50.0 if p in bad_raters else reference_mean
                            value = mean + rng.normal(0.0, 1.5)
                        else:
                            value = truth[c] + offset + rng.normal(0.0, noise_sd)
                        rows.append(base | dict(criterion=crit, condition=c, slot=slot,
                                                rating=float(np.clip(round(value), 0, 100)), preference=np.nan,
                                                matched=np.nan, motion_stimulus=s, reasons=""))
    return pd.DataFrame(rows)
