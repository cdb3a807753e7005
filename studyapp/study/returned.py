"""Checks of one returned results file, before anything of it is merged: pure functions, rows in, problems out.

A results file carries its own sha256, so anyone can edit ``results.json`` and recompute the checksum; the
checksum proves only that the file arrived as it left the participant's PC. What is checked here is what
the file *says was answered*, against what the study makes possible (after the bundle key has mapped the
opaque ids back to the real condition and stimulus ids):

* **roster**: the participant id is on the bundle's roster (unless unlisted ids are allowed), and a
  listed id follows the Latin-square row the roster gave it; with a bundle that ships one stimulus per
  participant and trial (:mod:`studyapp.study.shipped`), every trial is one the bundle made for this
  participant at this place (:func:`map_ids`), so another participant's answers under a new id are refused
  even before anyone else's answers are in the database;
* **schedule**: every trial's index, stimulus, practice and attention-check flags, slots (which condition
  sat left, middle, right) and samples equal the schedule recomputed by
  :func:`studyapp.study.schedule.participant_schedule` from the design's seed, the id and the row -- the
  same function the session runs, never a second implementation; answered trials are ``0 .. k-1`` (the
  session answers in order), all of them for a participant who finished;
* **criteria** (results of schema 7): the file's criteria are the design's, with the design's labels and
  questions (the merge stores the lab design's own, never the file's);
* **slots** (results of schema 6): every trial's ``trial_slots`` rows are the scheduled slots: condition,
  the stimulus whose motion each played (a mismatch trial's other clip) and sample, and its ``block`` and
  ``paradigm`` are the scheduled ones (a file without them is one rank block "main");
* **answers**: every rank trial has, for every criterion of its block, one rank per slot for the condition in
  that slot, and the ranks are what the session stores (:func:`studyapp.study.session.is_stored_ranking`:
  a permutation of 1..3, or with ties allowed their average ranks); every pairwise and mismatch trial has,
  per criterion, the two slots' preferences ``-p`` and ``p`` with ``p`` a level of the block's scale, and
  reasons from the block's list (none when every level is 0, none in a mismatch block), the same on both
  rows; every rating trial has, per criterion, a rating in 0..100 for every slot (every slider moved); no
  trial has answers of another paradigm; attention checks are re-scored with
  :func:`studyapp.study.session.attention_passed` and must say what the file says, and a participant
  past the design's failure limit must have ended early, with no answers after that; questionnaire
  answers are the design's items, Likert values in 1..points;
* **timings**: timestamps are ISO 8601 and increase from trial to trial, no time is negative, and where
  the design requires watching (``must_watch_fully``) each answer came at least the clip's length after
  the clip was shown, after a completed play that lasted the clip's length (give or take
  :data:`WATCH_SLACK_S` of timer resolution);
* **recorded fields**: play counts, frame counts, refresh rates and durations are of the kind the session
  writes, and each trial's play count is the number of its plays in the file;
* **copies**: no trial has the same clip and the same shown and answered times, to the millisecond, as a
  trial of another participant (in the database, or in another file of the same merge): the same
  answers under a new id.

Each problem is one :class:`Finding` (the place in the file and what is wrong); merging imports nothing
from a file with any. What these checks cannot catch is said plainly in the README ("What a returned
results file can prove"): a participant who edits only their own ranks, consistently, leaves a file that
is indistinguishable from one they could have answered.

>>> valid_stored_ranking((2.0, 1.0, 3.0), False), valid_stored_ranking((1.5, 1.5, 3.0), False)
(True, False)
>>> valid_stored_ranking((1.5, 1.5, 3.0), True), valid_stored_ranking((99, -5, "abc"), True)
(True, False)
"""
from __future__ import annotations

import json

import math
from dataclasses import dataclass
from datetime import datetime
from typing import Any, Callable, Iterable, Mapping, Sequence

from studyapp.study.design import FROZEN_PREFIX, Design
from studyapp.study.design.schema import PREFERENCE_LEVELS
from studyapp.study.schedule import TrialPlan, n_rows, participant_schedule, three_slots
from studyapp.study.session import attention_passed, is_stored_ranking

#: Seconds of timer resolution allowed when an answer must come after a whole clip was watched: the
#: stored times have millisecond resolution and a player may end on the frame before the last sample.
WATCH_SLACK_S = 0.1

#: Trial-row fields compared with the schedule, with the :class:`TrialPlan` value each must equal.
_PLAN_FIELDS: tuple[tuple[str, Callable[[TrialPlan], Any]], ...] = (
    ("stimulus", lambda p: p.stimulus_id),
    ("is_practice", lambda p: int(p.is_practice)),
    ("is_attention_check", lambda p: int(p.is_attention_check)),
    ("slot_left", lambda p: three_slots(p.slots)[0]),
    ("slot_middle", lambda p: three_slots(p.slots)[1]),
    ("slot_right", lambda p: three_slots(p.slots)[2]),
    ("sample_left", lambda p: three_slots(p.samples, None)[0]),
    ("sample_middle", lambda p: three_slots(p.samples, None)[1]),
    ("sample_right", lambda p: three_slots(p.samples, None)[2]),
    ("block", lambda p: p.block),
    ("paradigm", lambda p: p.paradigm),
)
#: What a trial row without the field (a file written before schema 6) means.
_ABSENT = {"block": "main", "paradigm": "rank"}

Row = Mapping[str, Any]


@dataclass(frozen=True)
class Finding:
    """One problem in a returned file: ``where`` in ``results.json`` (e.g. ``trial 3``) and what is wrong."""

    where: str
    problem: str

    def __str__(self) -> str:
        return f"{self.where}: {self.problem}" if self.where else self.problem


def valid_stored_ranking(values: Sequence[Any], allow_ties: bool) -> bool:
    """True when three stored ranks are a ranking the session can store (see the module notes)."""
    if len(values) != 3 or not all(_is_number(v) for v in values):
        return False
    return is_stored_ranking(tuple(float(v) for v in values), allow_ties)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _time(v: Any) -> datetime | None:
    if not isinstance(v, str):
        return None
    try:
        t = datetime.fromisoformat(v)
    except ValueError:
        return None
    return t if t.tzinfo is not None else None


def _trial_name(t: Row) -> str:
    return f"trial {t.get('trial_index')!r}" if not _is_int(t.get("trial_index")) else f"trial {t['trial_index']}"


# ------------------------------------------------------------------------------------------ ids
def map_ids(payload: Mapping[str, Any], conditions: Mapping[str, str], stimuli: Mapping[str, str],
            strict: bool, trials: Mapping[str, Mapping[str, Any]] | None = None) -> tuple[dict[str, Any], list[Finding]]:
    """``payload`` with the bundle's opaque condition and stimulus ids replaced by the real ones.

    ``strict`` (a bundle's results): an id the key does not know -- a real condition name written into
    the file, an edited id -- is a finding (and stays as it is, so the schedule check shows where).
    ``trials`` (keys of bundles that ship one stimulus per participant and trial, see
    :mod:`studyapp.study.shipped`): shipped stimulus -> its participant, trial index, real stimulus and
    ``{token: real condition}`` / ``{token: sample}``; conditions and samples are then mapped per trial, and a
    shipped stimulus answered by another participant or at another trial index is a finding.
    """
    if trials is not None:
        return _map_trials(payload, trials)
    found: dict[str, Finding] = {}

    def cond(c: Any, where: str) -> Any:
        if not isinstance(c, str):
            return c
        frozen = c.startswith(FROZEN_PREFIX)
        bare = c[len(FROZEN_PREFIX):] if frozen else c
        if bare in conditions:
            return (FROZEN_PREFIX if frozen else "") + conditions[bare]
        if strict:
            found.setdefault(f"c{c}", Finding(where, f"condition id {c!r} is not one of the bundle's: the file "
                                                      "was edited (a real condition name, or an invented id)"))
        return c

    def stim(s: Any, where: str) -> Any:
        if isinstance(s, str) and s in stimuli:
            return stimuli[s]
        if strict:
            found.setdefault(f"s{s}", Finding(where, f"stimulus id {s!r} is not one of the bundle's: the file "
                                                      "was edited"))
        return s

    slots = ("slot_left", "slot_middle", "slot_right")
    # a two-slot trial's empty middle slot is no id
    trials = [{**t, "stimulus": stim(t.get("stimulus"), _trial_name(t)),
               **{k: cond(t.get(k), _trial_name(t)) if t.get(k) != "" else "" for k in slots}}
              for t in payload["trials"]]
    responses = [{**r, "condition": cond(r.get("condition"), f"responses of {_trial_name(r)}")}
                 for r in payload["responses"]]
    out = {**payload, "trials": trials, "responses": responses}
    if "trial_slots" in payload:
        out["trial_slots"] = [{**r, "condition": cond(r.get("condition"), f"slots of {_trial_name(r)}"),
                               "motion_stimulus": stim(r.get("motion_stimulus"), f"slots of {_trial_name(r)}")}
                              for r in payload["trial_slots"]]
    if "judgements" in payload:
        out["judgements"] = [{**r, "condition": cond(r.get("condition"), f"answers of {_trial_name(r)}")}
                             for r in payload["judgements"]]
    return out, list(found.values())


def _map_trials(payload: Mapping[str, Any], trials: Mapping[str, Mapping[str, Any]]) -> tuple[dict[str, Any], list[Finding]]:
    """:func:`map_ids` for per-trial keys: tokens mean something only within their own shipped stimulus."""
    found: list[Finding] = []
    pid = payload.get("participant")
    by_index: dict[Any, Mapping[str, Any]] = {}
    slots = ("slot_left", "slot_middle", "slot_right")
    samples = ("sample_left", "sample_middle", "sample_right")

    def cond(entry: Mapping[str, Any] | None, c: Any, where: str) -> Any:
        if entry is None or not isinstance(c, str) or c == "":  # "": a two-slot trial's empty middle slot
            return c
        frozen = c.startswith(FROZEN_PREFIX)
        real = entry["conditions"].get(c.removeprefix(FROZEN_PREFIX))
        if real is None:
            found.append(Finding(where, f"condition id {c!r} is not one of the bundle's: the file was edited (a "
                                        "real condition name, or an invented id)"))
            return c
        return (FROZEN_PREFIX if frozen else "") + real

    mapped_trials = []
    foreign: dict[str, list[Any]] = {}  # participant the bundle made a trial for -> trial indices in this file
    moved: list[Any] = []
    for t in payload["trials"]:
        where = _trial_name(t)
        entry = trials.get(t.get("stimulus")) if isinstance(t.get("stimulus"), str) else None
        if entry is None:
            found.append(Finding(where, f"stimulus id {t.get('stimulus')!r} is not one of the bundle's: the file "
                                        "was edited"))
            mapped_trials.append(dict(t))
            continue
        if entry["participant"] != pid:
            foreign.setdefault(str(entry["participant"]), []).append(t.get("trial_index"))
        elif entry["trial_index"] != t.get("trial_index"):
            moved.append(t.get("trial_index"))
        by_index.setdefault(t.get("trial_index"), entry)
        shown = [t.get(k) for k in slots]
        wrong = [k for k in samples if t.get(k) not in (1, None)]
        if wrong:
            found.append(Finding(where, f"{wrong[0]} is {t.get(wrong[0])!r}, but a bundle's session records 1 (the "
                                        "bundle picks the sample): the file was edited"))
        row = {**t, "stimulus": entry["stimulus"], **{k: cond(entry, c, where) for k, c in zip(slots, shown)}}
        for k, c in zip(samples, shown):
            tok = c.removeprefix(FROZEN_PREFIX) if isinstance(c, str) else c
            row[k] = entry["samples"].get(tok, t.get(k)) if isinstance(tok, str) and tok else t.get(k)
        mapped_trials.append(row)
    for other, idx in foreign.items():
        found.append(Finding(f"participant {pid}", f"{len(idx)} of {len(payload['trials'])} trials are those the "
                                                   f"bundle made for participant {other}: their answers under "
                                                   "another id (the file was edited)"))
    if moved:
        found.append(Finding("trials " + ", ".join(map(str, moved[:6])), "each shows the clip and models of another "
                                                                       "trial: the file was edited"))
    responses = [{**r, "condition": cond(by_index.get(r.get("trial_index")), r.get("condition"),
                                         f"responses of {_trial_name(r)}")} for r in payload["responses"]]
    out = {**payload, "trials": mapped_trials, "responses": responses}
    if "trial_slots" in payload:
        # a token stands for (condition, the clip whose motion it plays, sample) within its own trial
        slot_rows = []
        for r in payload["trial_slots"]:
            entry, tok = by_index.get(r.get("trial_index")), r.get("condition")
            row = {**r, "condition": cond(entry, tok, f"slots of {_trial_name(r)}")}
            if entry is not None and isinstance(tok, str):
                bare = tok.removeprefix(FROZEN_PREFIX)
                row["motion_stimulus"] = entry.get("motions", {}).get(bare, entry["stimulus"])
                row["sample"] = entry["samples"].get(bare, r.get("sample"))
            slot_rows.append(row)
        out["trial_slots"] = slot_rows
    if "judgements" in payload:
        out["judgements"] = [{**r, "condition": cond(by_index.get(r.get("trial_index")), r.get("condition"),
                                                     f"answers of {_trial_name(r)}")} for r in payload["judgements"]]
    unique = list(dict.fromkeys(found))
    return out, unique


# ------------------------------------------------------------------------------------------ roster and row
def check_participant(participant: Row, roster: Mapping[str, int] | None, allow_unlisted: bool,
                      rows: int) -> list[Finding]:
    """The id is on the roster (``None``: results of the lab's own design, which has none) and the row fits."""
    out = []
    pid, row = participant.get("id"), participant.get("latin_row")
    if not isinstance(pid, str) or not pid.strip():
        return [Finding("participant", f"the participant id {pid!r} is not an id")]
    if not _is_int(row) or not 0 <= row < rows:
        out.append(Finding(f"participant {pid}", f"Latin-square row {row!r} is not one of the design's rows "
                                                 f"0..{rows - 1}"))
    if roster is not None:
        if pid in roster:
            if _is_int(row) and row != roster[pid]:
                out.append(Finding(f"participant {pid}", f"follows Latin-square row {row}, but the roster gave "
                                                         f"this id row {roster[pid]}"))
        elif not allow_unlisted:
            out.append(Finding(f"participant {pid}", "this id is not on the bundle's roster (ids handed out: "
                               f"{', '.join(sorted(roster)) or 'none'}); merge with --allow-unlisted if you "
                               "let participants choose their own ids"))
    if participant.get("status") not in ("active", "done", "ended_early"):
        out.append(Finding(f"participant {pid}", f"status {participant.get('status')!r} is not one the "
                                                 "session writes"))
    return out


def check_rows_belong(pid: str, payload: Mapping[str, Any]) -> list[Finding]:
    """Every row names the file's participant (a file edited to a new id in one place only disagrees)."""
    names = {r.get("participant") for table in ("sessions", "trials", "responses", "plays", "questionnaire",
                                                "trial_slots", "judgements")
             for r in payload.get(table, [])}
    names |= {payload.get("participant")}
    other = sorted(str(n) for n in names - {pid})
    return [Finding("participant", f"rows of participant(s) {', '.join(other)} in the file of participant "
                                   f"{pid}: the file was edited")] if other else []


# ------------------------------------------------------------------------------------------ schedule
def check_schedule(trials: Sequence[Row], plans: Sequence[TrialPlan], status: Any) -> list[Finding]:
    """Every trial is the scheduled one, answered in order (see the module notes)."""
    out = []
    seen: set[int] = set()
    for t in trials:
        i = t.get("trial_index")
        if not _is_int(i) or not 0 <= i < len(plans):
            out.append(Finding(_trial_name(t), f"this trial index is not in the participant's schedule "
                                               f"(trials 0..{len(plans) - 1})"))
            continue
        if i in seen:
            out.append(Finding(f"trial {i}", "answered twice in the file"))
            continue
        seen.add(i)
        plan = plans[i]
        wrong = [f"{name} is {t.get(name)!r}, the schedule has {want(plan)!r}"
                 for name, want in _PLAN_FIELDS if t.get(name, _ABSENT.get(name)) != want(plan)]
        if wrong:
            out.append(Finding(f"trial {i}", "not the scheduled trial: " + "; ".join(wrong)))
    if seen:
        gaps = sorted(set(range(max(seen) + 1)) - seen)
        if gaps:
            out.append(Finding(f"trial {gaps[0]}", f"missing although trial {max(seen)} was answered (a session "
                                                   "answers in order)"))
    if status == "done" and len(seen) != len(plans):
        out.append(Finding("participant", f"marked as finished with {len(seen)} of {len(plans)} trials answered"))
    return out


def check_slots(trials: Sequence[Row], slot_rows: Sequence[Row], plans: Sequence[TrialPlan]) -> list[Finding]:
    """Each trial's ``trial_slots`` rows are its scheduled slots: condition, whose motion, sample (schema 6)."""
    out = []
    by_trial: dict[Any, list[Row]] = {}
    for r in slot_rows:
        by_trial.setdefault(r.get("trial_index"), []).append(r)
    answered = {t.get("trial_index") for t in trials}
    for i in sorted((k for k in by_trial if k not in answered), key=repr):
        out.append(Finding(f"slots of trial {i!r}", "slots of a trial the file does not contain"))
    for t in trials:
        i = t.get("trial_index")
        if not _is_int(i) or not 0 <= i < len(plans):
            continue  # the schedule check's finding
        plan = plans[i]
        got = sorted(((r.get("slot"), r.get("condition"), r.get("motion_stimulus"), r.get("sample"))
                      for r in by_trial.get(i, [])), key=repr)
        want = [(k, c, plan.motion_stimulus(k), plan.samples[k]) for k, c in enumerate(plan.slots)]
        if got != sorted(want, key=repr):
            out.append(Finding(f"trial {i}", f"its slots (condition, motion of which clip, sample) are {got!r}, the "
                                             f"schedule has {want!r}"))
    return out


def _block_of(design: Design, plan: TrialPlan) -> Any:
    try:
        return design.block(plan.block)
    except KeyError:
        return None  # the schedule check says the trial is not the scheduled one


def check_judgements(trials: Sequence[Row], judgements: Sequence[Row], plans: Sequence[TrialPlan],
                     design: Design) -> list[Finding]:
    """Pairwise, mismatch and rating answers as the session stores them (see the module notes)."""
    out = []
    by_trial: dict[Any, list[Row]] = {}
    for r in judgements:
        by_trial.setdefault(r.get("trial_index"), []).append(r)
    answered = {t.get("trial_index") for t in trials}
    for i in sorted((k for k in by_trial if k not in answered), key=repr):
        out.append(Finding(f"answers of trial {i!r}", "answers for a trial the file does not contain"))
    for t in sorted((t for t in trials if _is_int(t.get("trial_index")) and 0 <= t["trial_index"] < len(plans)),
                    key=lambda t: t["trial_index"]):
        i = t["trial_index"]
        plan, rows = plans[i], by_trial.get(i, [])
        block = _block_of(design, plan)
        if plan.paradigm == "rank" or block is None:
            if rows:
                out.append(Finding(f"trial {i}", f"preferences or ratings on a {plan.paradigm} trial"))
            continue
        for crit in sorted({r.get("criterion") for r in rows} - set(block.criteria), key=repr):
            out.append(Finding(f"trial {i}", f"answers on {crit!r}, which block {block.id!r} does not ask"))
        n = len(plan.slots)
        for crit in block.criteria:
            given = {r.get("slot"): r for r in rows if r.get("criterion") == crit}
            if len(given) != len([r for r in rows if r.get("criterion") == crit]) or set(given) != set(range(n)):
                out.append(Finding(f"trial {i}, {crit}", f"needs one answer for each of the {n} slots, the file has "
                                                         f"slots {sorted(given, key=repr)}"))
                continue
            wrong = [k for k in range(n) if given[k].get("condition") != plan.slots[k]]
            if wrong:
                out.append(Finding(f"trial {i}, {crit}", "answers are given to " + ", ".join(
                    f"{given[k].get('condition')!r} in slot {k}" for k in wrong) + ", but the trial's slots show "
                    + ", ".join(f"{plan.slots[k]!r}" for k in wrong)))
                continue
            values = [given[k].get("value") for k in range(n)]
            if plan.paradigm == "rating":
                if not all(_is_number(v) and 0 <= v <= 100 for v in values):
                    out.append(Finding(f"trial {i}, {crit}", f"ratings {values!r} are not all in 0..100"))
                continue
            allowed = PREFERENCE_LEVELS.get(block.levels, PREFERENCE_LEVELS[5])
            if not (all(_is_number(v) for v in values) and values[1] in allowed and values[0] == -values[1]):
                out.append(Finding(f"trial {i}, {crit}", f"preferences {values!r} are not a preference: the two "
                                                         f"slots get -p and p, p one of {list(allowed)}"))
        if plan.paradigm in ("pairwise", "mismatch") and rows:
            out += _check_reasons(i, rows, block)
    return out


def _check_reasons(i: int, rows: Sequence[Row], block: Any) -> list[Finding]:
    texts = {r.get("reasons") for r in rows}
    if len(texts) != 1:
        return [Finding(f"trial {i}", "the reasons differ between the answer's rows")]
    text = next(iter(texts))
    try:
        chosen = json.loads(text) if text is not None else []
    except (TypeError, ValueError):
        return [Finding(f"trial {i}", f"reasons {text!r} are not a JSON list")]
    offered = list(block.reasons)
    if not isinstance(chosen, list) or any(c not in offered for c in chosen) or \
            chosen != [r for r in offered if r in chosen]:
        return [Finding(f"trial {i}", f"reasons {chosen!r} are not some of the block's reasons, in its order")]
    if chosen and all(r.get("value") == 0 for r in rows):
        return [Finding(f"trial {i}", "reasons given without a preference (the session asks them only for one)")]
    return []


# ------------------------------------------------------------------------------------------ answers
def check_answers(trials: Sequence[Row], responses: Sequence[Row], plans: Sequence[TrialPlan], design: Design,
                  status: Any) -> list[Finding]:
    """Complete, valid rankings for the scheduled conditions; attention checks scored as the session scores."""
    out = []
    allow_ties = bool(design.playback.allow_ties)
    by_trial: dict[Any, list[Row]] = {}
    for r in responses:
        by_trial.setdefault(r.get("trial_index"), []).append(r)
    answered = {t.get("trial_index") for t in trials}
    for i in sorted((k for k in by_trial if k not in answered), key=repr):
        out.append(Finding(f"responses of trial {i!r}", "ranks for a trial the file does not contain"))
    failures = 0
    limit = design.max_attention_failures
    ordered = sorted((t for t in trials if _is_int(t.get("trial_index")) and 0 <= t["trial_index"] < len(plans)),
                     key=lambda t: t["trial_index"])
    for t in ordered:
        i = t["trial_index"]
        plan = plans[i]
        if limit is not None and failures > limit:
            out.append(Finding(f"trial {i}", f"answered after {failures} failed attention checks, but the session "
                                             f"ends after {limit + 1}"))
            break
        ranks: dict[str, tuple[float, float, float]] = {}
        rows = by_trial.get(i, [])
        block = _block_of(design, plan)
        if plan.paradigm != "rank" or block is None:  # answered in judgements (check_judgements)
            if rows:
                out.append(Finding(f"trial {i}", f"ranks on a {plan.paradigm} trial"))
            continue
        criteria = list(block.criteria)
        # Ranks must name the conditions of the trial row's own slots; whether those are the scheduled ones is
        # the schedule check's finding, so a consistent edit of one trial is one message, not four.
        slots = (t.get("slot_left"), t.get("slot_middle"), t.get("slot_right"))
        for crit in sorted({r.get("criterion") for r in rows} - set(criteria), key=repr):
            out.append(Finding(f"trial {i}", f"ranks on {crit!r}, which is not a question of this design"))
        for crit in criteria:
            given = [r for r in rows if r.get("criterion") == crit]
            by_slot = {r.get("slot"): r for r in given}
            if len(given) != 3 or set(by_slot) != {0, 1, 2}:
                out.append(Finding(f"trial {i}, {crit}", f"needs one rank for each of the 3 slots, the file has "
                                                         f"slots {sorted((r.get('slot') for r in given), key=repr)}"))
                continue
            wrong = [s for s in (0, 1, 2) if by_slot[s].get("condition") != slots[s]]
            if wrong:
                out.append(Finding(f"trial {i}, {crit}", "ranks are given to " + ", ".join(
                    f"{by_slot[s].get('condition')!r} in slot {s}" for s in wrong) + ", but the trial's slots show "
                    + ", ".join(f"{slots[s]!r}" for s in wrong)))
                continue
            values = [by_slot[s].get("rank") for s in (0, 1, 2)]
            if not valid_stored_ranking(values, allow_ties):
                rule = "average ranks of 1..3 (ties allowed)" if allow_ties else "1, 2 and 3, each once"
                out.append(Finding(f"trial {i}, {crit}", f"ranks {values!r} are not a ranking: they must be {rule}"))
                continue
            ranks[crit] = (float(values[0]), float(values[1]), float(values[2]))
        if len(ranks) != len(criteria) or not plan.is_attention_check or slots != plan.slots:
            if t.get("attention_passed") is not None and not plan.is_attention_check:
                out.append(Finding(f"trial {i}", "an attention-check result on a trial that is not a check"))
            continue
        passed = attention_passed(design, plan, ranks)
        stored = t.get("attention_passed")
        if (None if passed is None else int(passed)) != stored:
            out.append(Finding(f"trial {i}", f"attention check recorded as {stored!r}, but its ranks "
                                             f"{'pass' if passed else 'fail'} it"))
        failures += passed is False
    if limit is not None and failures > limit and status != "ended_early":
        out.append(Finding("participant", f"{failures} failed attention checks (the design allows {limit}), but "
                                          f"the status is {status!r}, not ended_early"))
    return out


def check_questionnaire(rows: Sequence[Row], design: Design, status: Any) -> list[Finding]:
    """Answers to the design's items only; Likert answers whole numbers in 1..points; choice and number
    answers what the session stores for them (:meth:`~studyapp.study.design.QuestionItem.check_answer`)."""
    out = []
    items = {q.id: q for q in design.questionnaire}
    seen = set()
    for r in rows:
        qid = r.get("item")
        q = items.get(qid)
        if q is None:
            out.append(Finding(f"questionnaire {qid!r}", "not an item of this design's questionnaire"))
            continue
        seen.add(qid)
        if q.kind == "likert":
            try:
                v = int(r.get("value"))
                ok = str(v) == str(r.get("value")).strip() and 1 <= v <= int(q.points)
            except (TypeError, ValueError):
                ok = False
            if not ok:
                out.append(Finding(f"questionnaire {qid}", f"answer {r.get('value')!r} is not one of 1..{q.points}"))
        elif q.kind in ("choice", "number"):
            value = r.get("value")
            try:
                given = json.loads(value) if q.kind == "choice" and q.multiple else value
            except (TypeError, ValueError):
                given = None
            stored, problem = q.check_answer(given)
            if problem is not None or stored != value:
                out.append(Finding(f"questionnaire {qid}", f"answer {value!r} is not a valid {q.kind} answer"))
    if status == "done" and rows and set(items) - seen:
        out.append(Finding("questionnaire", f"items {sorted(set(items) - seen)} unanswered in a finished study"))
    return out


# ------------------------------------------------------------------------------------------ recorded fields
def _count(v: Any) -> bool:
    return _is_int(v) and v >= 0


def _measure(v: Any) -> bool:
    return _is_number(v) and v >= 0


#: What the session writes in each field the other checks do not cover (None allowed where it may be
#: unmeasured): a value of another kind was put there by hand.
_FIELDS: dict[str, dict[str, tuple[Callable[[Any], bool], bool, str]]] = {
    "trials": {"plays": (_count, False, "a count"), "frames_shown": (_count, True, "a count"),
               "dropped_frames": (_count, True, "a count"), "refresh_hz": (_measure, True, "a rate in Hz"),
               "worst_av_offset_ms": (_measure, True, "milliseconds"),
               "trial_duration_s": (_measure, True, "seconds"), "app_version": (lambda v: isinstance(v, str), False,
                                                                                "a version")},
    "plays": {"completed": (lambda v: v in (0, 1) and not isinstance(v, float), False, "0 or 1")},
}


def check_fields(payload: Mapping[str, Any]) -> list[Finding]:
    """Recorded measurements are of the kind the session writes, and each trial's play count is its plays.

    One finding per field, naming the first rows where it is wrong.
    """
    out = []
    for table, fields in _FIELDS.items():
        for name, (ok, optional, kind) in fields.items():
            bad = [_trial_name(r) for r in payload[table]
                   if not ((optional and r.get(name) is None) or ok(r.get(name)))]
            if bad:
                out.append(Finding(", ".join(bad[:3]) + (" ..." if len(bad) > 3 else ""),
                                   f"{table}.{name} is not {kind}"))
    counted: dict[Any, int] = {}
    for p in payload["plays"]:
        i = p.get("trial_index")
        counted[i] = counted.get(i, 0) + 1 if _is_int(i) else 0
    wrong = [t.get("trial_index") for t in payload["trials"]
             if _count(t.get("plays")) and t.get("plays") != counted.get(t.get("trial_index"), 0)]
    if wrong:
        out.append(Finding("trials " + ", ".join(map(str, wrong[:6])), "the play count is not the number of plays "
                                                                     "the file records for the trial"))
    return out


# ------------------------------------------------------------------------------------------ timings
def check_timings(trials: Sequence[Row], plays: Sequence[Row], durations: Mapping[int, float | None],
                  must_watch: bool) -> list[Finding]:
    """Readable, increasing, non-negative times; with ``must_watch`` no answer before a whole clip played.

    ``durations`` maps a trial index to the seconds its clip plays by the design (``None``: unknown).
    Problems that repeat over trials are one finding naming the trials.
    """
    out = []
    unreadable: list[str] = []
    backwards: list[int] = []
    too_soon: list[str] = []
    not_watched: list[int] = []
    plays_by: dict[Any, list[Row]] = {}
    for p in plays:
        plays_by.setdefault(p.get("trial_index"), []).append(p)
        if _time(p.get("started")) is None or (p.get("ended") is not None and _time(p.get("ended")) is None):
            unreadable.append(f"play of {_trial_name(p)}")
    last: datetime | None = None
    for t in sorted((t for t in trials if _is_int(t.get("trial_index"))), key=lambda t: t["trial_index"]):
        i = t["trial_index"]
        answered = _time(t.get("answered_at"))
        shown = _time(t.get("shown_at")) if t.get("shown_at") is not None else None
        rt = t.get("response_time_s")
        if answered is None or (t.get("shown_at") is not None and shown is None):
            unreadable.append(f"trial {i}")
            continue
        if rt is not None and (not _is_number(rt) or rt < 0):
            out.append(Finding(f"trial {i}", f"response time {rt!r} is not a non-negative number of seconds"))
            rt = None
        if last is not None and answered <= last:
            backwards.append(i)
        last = answered
        if shown is not None and answered < shown:
            out.append(Finding(f"trial {i}", "answered before it was shown"))
            continue
        need = durations.get(i)
        if not must_watch or need is None:
            continue
        waited = [x for x in ((answered - shown).total_seconds() if shown is not None else None, rt) if x is not None]
        if waited and min(waited) < need - WATCH_SLACK_S:
            too_soon.append(f"{i} ({min(waited):.3f} s)")
            continue
        full = []
        for p in plays_by.get(i, []):
            start, end = _time(p.get("started")), _time(p.get("ended"))
            if p.get("completed") in (1, True) and start is not None and end is not None and end <= answered:
                full.append((end - start).total_seconds())
        if not full or max(full) < need - WATCH_SLACK_S:
            not_watched.append(i)
    if unreadable:
        out.append(Finding(", ".join(unreadable[:5]), "a time is not an ISO 8601 timestamp with a time zone"))
    if backwards:
        out.append(Finding(("trial " if len(backwards) == 1 else "trials ") + ", ".join(map(str, backwards[:6])),
                           "answered no later than the trial before it (answers are given in order)"))
    if too_soon:
        out.append(Finding("trials " + ", ".join(too_soon[:6]) + (" ..." if len(too_soon) > 6 else ""),
                           "answered sooner after the clip was shown than the clip lasts, although the design "
                           "requires watching it to the end first"))
    if not_watched:
        out.append(Finding("trials " + ", ".join(map(str, not_watched[:6])) + (" ..." if len(not_watched) > 6 else ""),
                           "no completed play as long as the clip before the answer, although the design "
                           "requires watching it to the end first"))
    return out


# ------------------------------------------------------------------------------------------ copies
def fingerprint(trial: Row) -> tuple[Any, Any, Any]:
    """What no two participants share by chance: the clip and the shown and answered times (milliseconds)."""
    return trial.get("stimulus"), trial.get("shown_at"), trial.get("answered_at")


def check_copies(pid: str, trials: Sequence[Row], others: Mapping[str, Iterable[Row]]) -> list[Finding]:
    """Trials identical in :func:`fingerprint` to another participant's: one finding per such participant."""
    mine = {fingerprint(t) for t in trials if t.get("answered_at") is not None}
    out = []
    for other, rows in others.items():
        if other == pid:
            continue
        same = mine & {fingerprint(t) for t in rows}
        if same:
            out.append(Finding(f"participant {pid}", f"{len(same)} of {len(trials)} trials have the same clips "
                                                     f"and the same shown and answered times as participant "
                                                     f"{other}'s: a copy of their answers under another id"))
    return out


# ------------------------------------------------------------------------------------------ criteria
def check_criteria(rows: Any, design: Design) -> list[Finding]:
    """The file's ``criteria`` rows (schema 7) are the design's criteria, each with its label and question.

    >>> from studyapp.study.design.model import Criterion
    >>> from types import SimpleNamespace as NS
    >>> d = NS(criteria=[Criterion("sync", "Synchronization with speech", "Which is in time?")])
    >>> check_criteria([{"id": "sync", "label": "Synchronization with speech", "question": "Which is in time?"}], d)
    []
    >>> [f.problem[:40] for f in check_criteria([{"id": "sync", "label": "Sync", "question": "Which is in time?"}], d)]
    ["criterion 'sync' is labelled 'Sync' in t"]
    """
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        return [Finding("criteria", "not a list of criteria rows")]
    want = {c.id: c for c in design.criteria}
    out = []
    for r in rows:
        c = want.get(r.get("id"))  # type: ignore[arg-type]
        if c is None:
            out.append(Finding("criteria", f"criterion {r.get('id')!r} is not one of the design's "
                                           f"({', '.join(want)})"))
            continue
        for name in ("label", "question"):
            if r.get(name) != getattr(c, name):
                out.append(Finding("criteria", f"criterion {c.id!r} is {'labelled' if name == 'label' else 'asked'} "
                                               f"{r.get(name)!r} in the file, {getattr(c, name)!r} in the design: the "
                                               "file was not made from this study's design"))
    return out


# ------------------------------------------------------------------------------------------ all of it
def check_returned(payload: Mapping[str, Any], design: Design, *, roster: Mapping[str, int] | None,
                   allow_unlisted: bool, others: Mapping[str, Iterable[Row]],
                   duration_of: Callable[[TrialPlan], float | None]) -> list[Finding]:
    """Every check above on one parsed results file whose ids are the real ones (see :func:`map_ids`).

    ``roster``: the bundle's roster (``None`` for results of the lab's own design); ``others``: the trials
    of every other participant, by id; ``duration_of``: seconds a scheduled trial plays
    (:func:`studyapp.study.session.trial_duration_s` for the design).
    """
    parts = payload["participants"]
    if not isinstance(parts, list) or len(parts) != 1 or not isinstance(parts[0], dict):
        return [Finding("participants", f"expected one participant in the file, found "
                                        f"{len(parts) if isinstance(parts, list) else parts!r}")]
    p = parts[0]
    rows = n_rows(design)
    out = check_participant(p, roster, allow_unlisted, rows)
    pid = p.get("id")
    if not isinstance(pid, str):
        return out
    out += check_rows_belong(pid, payload)
    if "criteria" in payload:  # a file of schema 7 or later
        out += check_criteria(payload["criteria"], design)
    row = p.get("latin_row")
    if not _is_int(row) or not 0 <= row < rows:
        return out
    plans = participant_schedule(design, pid, row)
    trials, status = payload["trials"], p.get("status")
    out += check_schedule(trials, plans, status)
    if "trial_slots" in payload:  # a file of schema 6 or later
        out += check_slots(trials, payload["trial_slots"], plans)
    out += check_answers(trials, payload["responses"], plans, design, status)
    out += check_judgements(trials, payload.get("judgements", []), plans, design)
    out += check_questionnaire(payload["questionnaire"], design, status)
    durations = {t["trial_index"]: duration_of(plans[t["trial_index"]]) for t in trials
                 if _is_int(t.get("trial_index")) and 0 <= t["trial_index"] < len(plans)}
    out += check_fields(payload)
    out += check_timings(trials, payload["plays"], durations, bool(design.playback.must_watch_fully))
    out += check_copies(pid, trials, others)
    return out
