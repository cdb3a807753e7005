"""The participant's session as a state machine, drivable without a window.

States, in order: ``WELCOME`` (consent) -> ``INSTRUCTIONS`` -> ``ENV_CHECK`` -> ``PRACTICE`` -> ``TRIALS``
-> ``QUESTIONNAIRE`` -> ``DONE``; ``ENDED_EARLY`` replaces the rest after too many failed attention checks,
``DECLINED`` when the participant does not consent (:meth:`Session.decline_consent`). Phases with nothing
to do (no practice clips, no questionnaire) are skipped.

Not consenting ends the session at once and is recorded: the participant's status becomes ``ended_early``
(the results schema has no other status for it) and the session's ``machine`` record gets
``"consent": "declined"`` with the time; nothing else is stored, no trial is ever shown, so the export and
the analysis have no answers of that participant, and a merge sees an ended-early participant with none.
A resumed participant (one with stored answers) is greeted with :attr:`Session.resume_point`
("welcome back, continuing at clip k of n"), which also says whether a clip was played but left
unanswered last time: that half-finished answer was dropped, and the clip is shown again.

The UI's screens call the methods; bots and tests call the same methods, so what is tested is what
participants run. Rules the machine enforces:

* an answer is committed (one transaction for all ranks of a trial) before the next trial becomes current;
* there is no going back, and an answered trial can never be answered again;
* with ``must_watch_fully`` a clip must have been played to its end once in this session before ranking;
  with ``allow_replay = false`` it can be played only once;
* ranks are complete (every criterion, every slot) and, unless the design allows ties, a permutation of
  1..3. With ties allowed, tied ranks are stored as average ranks (1, 1, 3 -> 1.5, 1.5, 3), the convention
  of the Friedman test;
* starting the same participant again resumes at the first unanswered trial, on the same Latin-square row
  and therefore with the same schedule; a finished participant is refused unless ``allow_rerun``, which
  records a new participant ``<id>-rerun<k>`` on the same row (earlier answers are never touched).

Response paradigms (``[[blocks]]``, see :class:`~studyapp.study.design.Block`): each trial's plan says its
``paradigm``, and the answer goes through that paradigm's method, under the rules above (no going back, watch
once, one transaction, resume at the first unanswered trial):

* ``rank``: :meth:`Session.submit_ranking` (stored in ``responses``);
* ``pairwise`` and ``mismatch``: :meth:`Session.submit_preference` with ``{criterion: level}``, level in
  -2..2 (5 levels) or -1..1 (3 levels), NEGATIVE = the LEFT figure preferred, POSITIVE = the RIGHT one, 0 = no
  preference; ``reasons`` a subset of the block's ``reasons``, allowed only when some level is not 0. Stored in
  ``judgements`` as the preference FOR each slot (left ``-level``, right ``+level``), the reasons on both rows;
* ``rating``: :meth:`Session.submit_ratings` with ``{criterion: {slot: 0..100}}`` for every slot: the UI
  passes only sliders the participant moved, so a missing one is refused with a message for the participant.

Every trial also stores its slots (``trial_slots``: condition, whose motion, sample). A block with
``instructions`` shows them before its first trial: :meth:`Session.block_instructions` returns the text while
they are due, and playing or answering waits for :meth:`Session.finish_block_instructions`; a participant
resumed inside a block does not see them again (one who resumes at the block's first trial does).

Restoring a session: everything the rules above need is in the database, so ``Session(design, db, id,
session_id=N)`` continues stored session ``N`` where it stands, with no object kept in memory between two
calls (the browser server restores the session for every request, in whichever of its processes gets it).
The phase comes from the session's ``machine`` record (``consent_at``/``resumed_at``, :data:`INSTRUCTIONS_AT`,
:data:`ENV_CHECK_AT`, written as the participant passes each screen, then the first unanswered trial as
always); the current clip's plays from the ``plays`` rows of this session (the open one, the completed ones,
those a front end lost: :data:`LOST_PLAYS`); dismissed block instructions from :data:`BLOCK_INTROS`; the time
the clip was shown from this session's latest answer (else its environment check). A desktop session writes
the same records, so one it left can be continued the same way.

Attention checks (``design.attention_checks``): a trial whose plan has ``is_attention_check`` is scored by
:func:`attention_passed`; when more checks fail than ``design.max_attention_failures`` allows, the session
ends early with a polite message.

Example (with a loaded ``design`` and a :class:`~studyapp.study.storage.ResultsDB` ``db``)::

    s = Session(design, db, "P01")
    s.accept_consent(); s.finish_instructions(); s.record_env_check({"gl_renderer": "llvmpipe"})
    while s.current_trial() is not None:
        s.record_play_started(); s.record_play_finished(True)
        s.submit_ranking({c.id: {0: 1, 1: 2, 2: 3} for c in design.criteria})
"""
from __future__ import annotations

import enum
import time
from datetime import datetime
from dataclasses import asdict, dataclass, is_dataclass
from typing import Any, Callable, Mapping, Sequence

from studyapp import __version__
from studyapp.errors import InputError, StudyappError
from studyapp.study.design.texts import EN as EN_TEXTS
from studyapp.study.design.texts import text as design_text
from studyapp.study.storage import (
    Judgement,
    ParticipantRecord,
    Response,
    ResultsDB,
    TrialRecord,
    machine_basics,
    now_iso,
)


class State(str, enum.Enum):
    WELCOME = "welcome"
    INSTRUCTIONS = "instructions"
    ENV_CHECK = "env_check"
    PRACTICE = "practice"
    TRIALS = "trials"
    QUESTIONNAIRE = "questionnaire"
    DONE = "done"
    ENDED_EARLY = "ended_early"
    DECLINED = "declined"


#: Keys of a session's ``machine`` record that say how far it got, so it can be restored from the database
#: (``Session(..., session_id=...)``): the instructions read, the environment check done, the blocks whose
#: instructions were dismissed, and the plays a front end lost (not counted against ``allow_replay = false``).
INSTRUCTIONS_AT = "instructions_at"
ENV_CHECK_AT = "env_check_at"
BLOCK_INTROS = "block_intros_seen"
LOST_PLAYS = "lost_plays"


class SessionError(StudyappError):
    """A method was called in a state where it makes no sense (a UI bug, not a participant error)."""


class RankingError(StudyappError):
    """The submitted ranking is incomplete or invalid; the message is written for the participant."""


class ParticipantFinishedError(StudyappError):
    """The participant already completed (or ended) the study; running again needs an explicit rerun."""


@dataclass
class PlayStats:
    """What the player measured during one play of a clip (all optional; bots leave them empty)."""

    frames_shown: int | None = None
    dropped_frames: int | None = None
    refresh_hz: float | None = None
    worst_av_offset_ms: float | None = None


# The English texts; a design's language and [texts] choose what participants read (design.texts).
# ENDED_EARLY_MESSAGE must not say "nothing more is needed": a remote participant still sends the results file.
ENDED_EARLY_MESSAGE = EN_TEXTS["final.ended_early_text"]
DONE_MESSAGE = EN_TEXTS["final.done_text"]
DECLINED_MESSAGE = EN_TEXTS["final.declined_text"]


@dataclass(frozen=True)
class ResumePoint:
    """Where a resumed participant continues: clip ``k`` of ``n`` (of the practice clips when ``practice``);
    ``dropped``: a clip was played last time but not answered, so that half-finished answer was dropped."""

    k: int
    n: int
    practice: bool
    dropped: bool


def _stats_dict(stats: PlayStats | Mapping[str, Any] | None) -> dict[str, Any]:
    if stats is None:
        return {}
    if is_dataclass(stats):
        return {k: v for k, v in asdict(stats).items() if v is not None}
    return {k: v for k, v in dict(stats).items() if v is not None}


def _average_ranks(values: Sequence[float]) -> tuple[float, float, float]:
    # Average ("fractional") ranks of three values; tiny, and keeps scipy.stats' slow import off the
    # path between a click and the commit.
    out = []
    for v in values:
        below = sum(x < v for x in values)
        equal = sum(x == v for x in values)
        out.append(below + (equal + 1) / 2)
    return (float(out[0]), float(out[1]), float(out[2]))


def normalise_ranks(
    ranks: Mapping[str, Mapping[Any, Any]], criteria: Sequence[str], allow_ties: bool
) -> dict[str, tuple[float, float, float]]:
    """Check a submitted ranking and return ``{criterion: (rank of slot 0, slot 1, slot 2)}``.

    Slots may be given as ints or digit strings. Raises :class:`RankingError` with a message for the
    participant when a criterion or slot is missing, a rank is outside 1..3, or ranks tie without
    ``allow_ties``.

    >>> normalise_ranks({"realism": {0: 2, 1: 1, 2: 3}}, ["realism"], False)
    {'realism': (2.0, 1.0, 3.0)}
    >>> normalise_ranks({"realism": {"0": 1, "1": 1, "2": 3}}, ["realism"], True)
    {'realism': (1.5, 1.5, 3.0)}
    """
    unknown = sorted(set(ranks) - set(criteria))
    if unknown:
        raise RankingError(f"unknown question(s): {', '.join(unknown)}")
    out: dict[str, tuple[float, float, float]] = {}
    for crit in criteria:
        given = ranks.get(crit)
        if not given:
            raise RankingError(f"Please rank all three for '{crit}'.")
        by_slot: dict[int, float] = {}
        for k, v in given.items():
            try:
                slot = int(k)
                value = float(v)
            except (TypeError, ValueError):
                raise RankingError(f"'{crit}': {k!r} -> {v!r} is not a slot and a rank") from None
            if slot not in (0, 1, 2):
                raise RankingError(f"'{crit}': there is no slot {slot}")
            if value not in (1.0, 2.0, 3.0):
                raise RankingError(f"'{crit}': ranks go from 1 (best) to 3, not {v!r}")
            by_slot[slot] = value
        if set(by_slot) != {0, 1, 2}:
            raise RankingError(f"Please rank all three for '{crit}'.")
        values = [by_slot[0], by_slot[1], by_slot[2]]
        if len(set(values)) < 3 and not allow_ties:
            raise RankingError(f"'{crit}': each rank (1, 2, 3) can be given only once; ties are not allowed.")
        out[crit] = _average_ranks(values)
    return out


def is_stored_ranking(values: Sequence[float], allow_ties: bool) -> bool:
    """True when ``values`` (one criterion, slots left to right) is what :func:`normalise_ranks` stores:
    1, 2 and 3 each once, or, with ``allow_ties``, the average ranks of a tied ranking (1.5, 1.5, 3).

    >>> is_stored_ranking((3.0, 1.0, 2.0), False), is_stored_ranking((2.0, 2.0, 2.0), True)
    (True, True)
    >>> is_stored_ranking((1.0, 1.0, 3.0), True), is_stored_ranking((2.0, 2.0, 2.0), False)
    (False, False)
    """
    if len(values) != 3 or any(v not in (1.0, 1.5, 2.0, 2.5, 3.0) for v in values):
        return False
    # average ranks are their own average ranks: (1, 1, 3) is not, (1.5, 1.5, 3) is
    if tuple(values) != _average_ranks(values):
        return False
    return allow_ties or len(set(values)) == 3


def normalise_preference(levels: Mapping[str, Any], reasons: Sequence[str], criteria: Sequence[str],
                         n_levels: int = 5, offered: Sequence[str] = ()) -> dict[str, int]:
    """Check a pairwise/mismatch answer and return ``{criterion: level}`` (see the module notes).

    Raises :class:`RankingError` with a message for the participant when a criterion is missing, a level is
    outside the block's scale, or reasons are not the block's or come with "no preference" on every criterion.

    >>> normalise_preference({"realism": -2}, ["Hands"], ["realism"], 5, ["Hands", "Timing"])
    {'realism': -2}
    >>> normalise_preference({"realism": 2}, [], ["realism"], 3)
    Traceback (most recent call last):
    ...
    studyapp.study.session.RankingError: 'realism': choose one of -1, 0, 1
    """
    from studyapp.study.design.schema import PREFERENCE_LEVELS

    allowed = PREFERENCE_LEVELS.get(int(n_levels), PREFERENCE_LEVELS[5])
    unknown = sorted(set(levels) - set(criteria))
    if unknown:
        raise RankingError(f"unknown question(s): {', '.join(unknown)}")
    out: dict[str, int] = {}
    for crit in criteria:
        if crit not in levels or levels[crit] is None:
            raise RankingError(f"Please choose an answer for '{crit}'.")
        v = levels[crit]
        try:
            level = int(v)
            ok = not isinstance(v, bool) and float(v) == level and level in allowed
        except (TypeError, ValueError, OverflowError):
            ok = False
        if not ok:
            raise RankingError(f"'{crit}': choose one of {', '.join(str(a) for a in allowed)}")
        out[crit] = level
    given = list(reasons or ())
    strange = [r for r in given if r not in offered]
    if strange:
        raise RankingError(f"unknown reason(s): {', '.join(map(str, strange))}")
    if len(set(given)) != len(given):
        raise RankingError("each reason can be chosen once")
    if given and all(level == 0 for level in out.values()):
        raise RankingError("Reasons are asked only when you prefer one of the two.")
    return out


def normalise_ratings(ratings: Mapping[str, Mapping[Any, Any]], criteria: Sequence[str],
                      n_slots: int) -> dict[str, tuple[float, ...]]:
    """Check a rating answer and return ``{criterion: (rating of slot 0, slot 1, ...)}``, each in 0..100.

    >>> normalise_ratings({"realism": {0: 80, "1": 12.5}}, ["realism"], 2)
    {'realism': (80.0, 12.5)}
    >>> normalise_ratings({"realism": {0: 80}}, ["realism"], 2)
    Traceback (most recent call last):
    ...
    studyapp.study.session.RankingError: Please move every slider for 'realism' (1 not yet moved).
    """
    import math

    unknown = sorted(set(ratings) - set(criteria))
    if unknown:
        raise RankingError(f"unknown question(s): {', '.join(unknown)}")
    out: dict[str, tuple[float, ...]] = {}
    for crit in criteria:
        by_slot: dict[int, float] = {}
        for k, v in (ratings.get(crit) or {}).items():
            try:
                slot, value = int(k), float(v)
            except (TypeError, ValueError, OverflowError):
                raise RankingError(f"'{crit}': {k!r} -> {v!r} is not a slot and a rating") from None
            if not 0 <= slot < n_slots:
                raise RankingError(f"'{crit}': there is no slot {slot}")
            if isinstance(v, bool) or not math.isfinite(value) or not 0 <= value <= 100:
                raise RankingError(f"'{crit}': ratings go from 0 to 100, not {v!r}")
            by_slot[slot] = value
        missing = n_slots - len(by_slot)
        if missing:
            raise RankingError(f"Please move every slider for '{crit}' ({missing} not yet moved).")
        out[crit] = tuple(by_slot[i] for i in range(n_slots))
    return out


def attention_passed(design: Any, plan: Any, ranks: Mapping[str, tuple[float, float, float]]) -> bool | None:
    """Score an attention-check trial; ``None`` when the trial is not one (or no check names its stimulus).

    The rule is the design's (:meth:`studyapp.study.design.AttentionCheck.passed`): the deciding slot (the
    frozen slot, or the known-worst condition) must get the expected rank on the expected criterion; a tie
    that includes the expected rank passes.
    """
    if not getattr(plan, "is_attention_check", False):
        return None
    checks = [c for c in getattr(design, "attention_checks", []) or [] if c.stimulus == plan.stimulus_id]
    if not checks:
        return None
    try:
        return bool(checks[0].passed(tuple(plan.slots), ranks))
    except (ValueError, KeyError):
        return None


def trial_duration_s(design: Any, plan: Any) -> float | None:
    """Seconds the trial of ``plan`` plays by its timeline (``studyapp.study.timeline``); None if unknown."""
    from studyapp.study.stimuli import load_audio
    from studyapp.study.timeline import trial_duration

    try:
        stim = design.stimulus(plan.stimulus_id)
        if stim.duration_s is not None:
            return float(stim.duration_s)
        return round(trial_duration(None, load_audio(stim.audio).duration), 6)
    except (AttributeError, KeyError, OSError, ValueError):
        return None  # a stand-in design without stimulus files (tests) records no duration


def prepare_participant(
    design: Any,
    db: ResultsDB,
    participant_id: str,
    *,
    row: int | None = None,
    groups: Mapping[str, str] | None = None,
    allow_rerun: bool = False,
    n_rows: int | None = None,
    known: ParticipantRecord | None = None,
) -> ParticipantRecord:
    """The participant record a session should run: existing (resume), new (next free row), or a rerun.

    Raises :class:`ParticipantFinishedError` for a participant who already finished (unless
    ``allow_rerun``: then a new participant ``<id>-rerun<k>`` on the same row is registered), and
    :class:`InputError` when ``row`` contradicts the row a resumed participant already follows.
    ``known``: the participant's record as the caller has just read it (the same checks, one query less).
    """

    def rows() -> int:
        if n_rows is not None:
            return int(n_rows)
        from studyapp.study.schedule import n_rows as schedule_rows

        return int(schedule_rows(design))

    def new(pid: str, on_row: int | None, extra: Mapping[str, str]) -> ParticipantRecord:
        base = {k: str(v) for k, v in (getattr(design, "groups", None) or {}).items()}
        return db.add_participant(pid, rows(), row=on_row, groups={**base, **extra})

    rec = known if known is not None and known.id == participant_id else db.participant(participant_id)
    if rec is None:
        return new(participant_id, row, dict(groups or {}))
    if rec.status != "active":
        if not allow_rerun:
            what = "completed the study" if rec.status == "done" else "ended the study early"
            raise ParticipantFinishedError(
                f"participant {participant_id!r} already {what} ({rec.completed}) in {db.path}. "
                "Use a new participant id, or --allow-rerun to record a separate run")
        k = 2
        while db.participant(f"{participant_id}-rerun{k}") is not None:
            k += 1
        return new(f"{participant_id}-rerun{k}", rec.latin_row,
                   {**rec.groups, **(groups or {}), "rerun_of": participant_id})
    if row is not None and row != rec.latin_row:
        raise InputError(db.path, "--row", f"participant {participant_id!r} already follows Latin-square row "
                         f"{rec.latin_row}; a resumed session keeps its row (drop --row, or use a new id)")
    if groups:
        db.update_groups(rec.id, dict(groups))
        rec = db.participant(rec.id) or rec
    return rec


class Session:
    """One participant going through the study (see the module docstring for the rules).

    Parameters
    ----------
    design:
        The loaded :class:`~studyapp.study.design.Design`.
    db:
        The study's results database.
    participant_id:
        As typed by the experimenter. A known id resumes; a new id is assigned a Latin-square row.
    row:
        Explicit Latin-square row for a new participant (``None``: the least used row).
    groups:
        Extra participant groups stored with the participant (e.g. ``{"device": "vr"}``); the design's
        ``groups`` are added automatically.
    allow_rerun:
        Let a finished participant run again as a new participant ``<id>-rerun<k>``.
    plans, n_rows:
        A schedule to use instead of :func:`studyapp.study.schedule.participant_schedule` (tests, bundles).
    on_saved:
        Called with the :class:`TrialPlan` after its answer is committed (bots print "saved trial K").
    machine:
        More keys for the new session's ``machine`` record (the front end: ``{"frontend": "browser"}``).
    session_id:
        Continue this stored session of the participant instead of starting one: its state is restored from
        the database alone (see "Restoring a session" in the module notes), so a front end that keeps no
        session in memory (the browser server, any of its processes) drives the same state machine.
    play_duration_s:
        With ``session_id``: ``f(plan)``, the scene length the front end gave :meth:`record_play_started`
        (stored with the answer as ``trial_duration_s`` when the current clip was played in this session).
    participant:
        The participant's record as the front end has just read it (the browser server, under the
        participant's lock): not read again (see :func:`prepare_participant`).
    """

    def __init__(
        self,
        design: Any,
        db: ResultsDB,
        participant_id: str,
        *,
        row: int | None = None,
        groups: Mapping[str, str] | None = None,
        allow_rerun: bool = False,
        plans: Sequence[Any] | None = None,
        n_rows: int | None = None,
        on_saved: Callable[[Any], None] | None = None,
        machine: Mapping[str, Any] | None = None,
        session_id: int | None = None,
        play_duration_s: Callable[[Any], float | None] | None = None,
        participant: ParticipantRecord | None = None,
    ) -> None:
        self.design = design
        self.db = db
        self.on_saved = on_saved
        self.criteria: list[str] = [c.id for c in design.criteria]
        self.playback = design.playback
        rec = prepare_participant(design, db, participant_id, row=row, groups=groups, allow_rerun=allow_rerun,
                                  n_rows=n_rows, known=participant)
        self.participant: ParticipantRecord = rec
        self.participant_id: str = rec.id
        self.row: int = rec.latin_row
        if plans is None:
            from studyapp.study.schedule import participant_schedule

            plans = participant_schedule(design, self.participant_id, self.row)
        self.plans: list[Any] = list(plans)
        self.n_practice: int = sum(1 for p in self.plans if p.is_practice)
        self.n_trials: int = len(self.plans) - self.n_practice
        answered = db.answered_trials(self.participant_id)
        self._pos = next((i for i, p in enumerate(self.plans) if p.trial_index not in answered), len(self.plans))
        self.state: State = State.WELCOME
        self._intro_seen: set[str] = set()  # blocks whose instructions were dismissed in this session
        #: The results file to send back (remote bundle runs), set when the session ends; the final screen shows it.
        self.results_file: Any = None
        self._reset_trial()
        if session_id is not None:
            self.session_id: int = int(session_id)
            self._restore(answered, play_duration_s)
            return
        self.resumed: bool = bool(answered)
        if answered:
            self._check_same_schedule()
        self.session_id = db.start_session(self.participant_id, {**machine_basics(), "app_version": __version__,
                                                                 **dict(machine or {})})

    # ------------------------------------------------------------------ setup helpers
    def _check_same_schedule(self) -> None:
        # A resumed participant must see the rest of the schedule they started; if the stored answers do
        # not match today's plan (scheduling code or design order changed), continuing would mix orders.
        from studyapp.study.schedule import three_slots

        by_index = {p.trial_index: p for p in self.plans}
        slots: dict[int, list[tuple[str, str]]] = {}
        for r in self.db.trial_slots(self.participant_id):
            slots.setdefault(r["trial_index"], []).append((r["condition"], r["motion_stimulus"]))
        for t in self.db.trials(self.participant_id):
            plan = by_index.get(t["trial_index"])
            stored = (t["stimulus"], (t["slot_left"], t["slot_middle"], t["slot_right"]),
                      t.get("block") or "main", t.get("paradigm") or "rank")
            same = plan is not None and stored == (plan.stimulus_id, three_slots(plan.slots),
                                                   getattr(plan, "block", "main"), getattr(plan, "paradigm", "rank"))
            if same and t["trial_index"] in slots:  # schema 6 stores every slot and whose motion it played
                same = slots[t["trial_index"]] == [(c, plan.motion_stimulus(i)) for i, c in enumerate(plan.slots)]
            if not same:
                raise InputError(self.db.path, f"participant {self.participant_id}, trial {t['trial_index']}",
                                 "the stored answer does not match this participant's schedule (was the design's "
                                 "order or the studyapp version changed?); continue with the original version, "
                                 "or use a new participant id")

    def _restore(self, answered: set[int], play_duration_s: Callable[[Any], float | None] | None) -> None:
        """The state of stored session :attr:`session_id`, from the database alone (see the module notes)."""
        row = next((s for s in self.db.sessions(self.participant_id) if s["id"] == self.session_id), None)
        if row is None:
            raise SessionError(f"participant {self.participant_id!r} has no session {self.session_id}")
        m = row["machine"]
        self._intro_seen = set(m.get(BLOCK_INTROS, []))
        if m.get("consent") == "declined":
            self.resumed = False
            self.state = State.DECLINED
            return
        consented = "consent_at" in m or "resumed_at" in m
        # before consent nothing of this session is answered: earlier answers make it a resumed one
        self.resumed = "resumed_at" in m if consented else bool(answered)
        if not consented:
            return                                    # WELCOME
        if INSTRUCTIONS_AT not in m:
            self.state = State.INSTRUCTIONS
            return
        if ENV_CHECK_AT not in m:
            self.state = State.ENV_CHECK
            return
        self._advance()                               # the one rule for what comes next (it may finish)
        plan = self.current_trial()
        if plan is None:
            return
        # shown when this session last moved on: its latest answer, else its environment check
        mine = [t["answered_at"] for t in self.db.trials(self.participant_id) if t["session"] == self.session_id]
        self._shown_wall = max(mine) if mine else m[ENV_CHECK_AT]
        try:
            ago = time.time() - datetime.fromisoformat(self._shown_wall).timestamp()
            self._shown_mono = time.monotonic() - max(0.0, ago)
        except (TypeError, ValueError):
            self._shown_mono = None
        lost = set(m.get(LOST_PLAYS, []))
        plays = [p for p in self.db.plays(self.participant_id)
                 if p["session"] == self.session_id and p["trial_index"] == plan.trial_index]
        open_ = [p["id"] for p in plays if p["ended"] is None]
        self._play_id = open_[-1] if open_ else None
        self._plays = sum(1 for p in plays if p["id"] not in lost)
        self._completed_plays = sum(1 for p in plays if p["completed"])
        if plays and play_duration_s is not None:
            self._played_s = play_duration_s(plan)

    def _reset_trial(self) -> None:
        self._shown_wall: str | None = None
        self._shown_mono: float | None = None
        self._play_id: int | None = None
        self._completed_plays = 0
        self._plays = 0
        self._frames_shown: int | None = None
        self._dropped: int | None = None
        self._refresh: float | None = None
        self._worst_av: float | None = None
        self._played_s: float | None = None

    def _expect(self, *states: State) -> None:
        if self.state not in states:
            raise SessionError(f"cannot do that in state {self.state.value} (expected {', '.join(s.value for s in states)})")

    # ------------------------------------------------------------------ the fixed screens
    def accept_consent(self) -> State:
        """The participant agreed on the welcome screen."""
        self._expect(State.WELCOME)
        self.db.update_session_machine(self.session_id, {"resumed_at" if self.resumed else "consent_at": now_iso()})
        self.state = State.INSTRUCTIONS
        return self.state

    def decline_consent(self) -> State:
        """The participant does not consent: the session ends here, recorded as declined (see the module)."""
        self._expect(State.WELCOME)
        self.db.update_session_machine(self.session_id, {"consent": "declined", "consent_declined_at": now_iso()})
        self.state = State.DECLINED
        self._finish("ended_early")
        return self.state

    @property
    def resume_point(self) -> ResumePoint | None:
        """None for a new participant; else where this participant continues (see :class:`ResumePoint`)."""
        if not self.resumed:
            return None
        if self._pos >= len(self.plans):
            return ResumePoint(self.n_trials, self.n_trials, False, False)
        plan = self.plans[self._pos]
        k = sum(1 for p in self.plans[: self._pos + 1] if p.is_practice == plan.is_practice)
        n = self.n_practice if plan.is_practice else self.n_trials
        dropped = any(p["trial_index"] == plan.trial_index for p in self.db.plays(self.participant_id))
        return ResumePoint(k, n, bool(plan.is_practice), dropped)

    def finish_instructions(self) -> State:
        self._expect(State.INSTRUCTIONS)
        self.db.update_session_machine(self.session_id, {INSTRUCTIONS_AT: now_iso()})
        self.state = State.ENV_CHECK
        return self.state

    def record_env_check(self, info: Mapping[str, Any] | None = None) -> State:
        """Store what the environment check found (GL renderer, refresh rate, audio device and latency, ...)
        with this session, then go to the first unanswered trial (or further)."""
        self._expect(State.ENV_CHECK)
        self.db.update_session_machine(self.session_id, {**dict(info or {}), ENV_CHECK_AT: now_iso()})
        self._advance()
        return self.state

    # ------------------------------------------------------------------ progress
    def _advance(self) -> None:
        self._reset_trial()
        limit = getattr(self.design, "max_attention_failures", None)
        if limit is not None and self.db.attention_failures(self.participant_id) > limit:
            self.state = State.ENDED_EARLY
            self._finish("ended_early")
            return
        if self._pos < len(self.plans):
            self.state = State.PRACTICE if self.plans[self._pos].is_practice else State.TRIALS
            self._shown_wall = now_iso()
            self._shown_mono = time.monotonic()
            return
        items = list(getattr(self.design, "questionnaire", None) or [])
        if items and not self.db.questionnaire(self.participant_id):
            self.state = State.QUESTIONNAIRE
            return
        self.state = State.DONE
        self._finish("done")

    def _finish(self, status: str) -> None:
        self.db.set_status(self.participant_id, status)
        self.db.end_session(self.session_id)
        # A remote (bundle) run sets this hook on the database to pack the participant's results file,
        # so whichever front end drives the session (window, offscreen, bot) produces it and can show it.
        hook = getattr(self.db, "on_participant_finished", None)
        if hook is not None:
            self.results_file = hook(self.participant_id)

    def current_trial(self) -> Any | None:
        """The :class:`TrialPlan` to show now, or ``None`` outside the practice and trial phases."""
        if self.state in (State.PRACTICE, State.TRIALS):
            return self.plans[self._pos]
        return None

    def trial_number(self) -> int:
        """1-based number of the current clip within its phase (practice clips are counted separately)."""
        plan = self.current_trial()
        if plan is None:
            return 0
        return sum(1 for p in self.plans[: self._pos + 1] if p.is_practice == plan.is_practice)

    def phase_total(self) -> int:
        plan = self.current_trial()
        if plan is None:
            return 0
        return self.n_practice if plan.is_practice else self.n_trials

    def progress_label(self) -> str:
        """``"Practice clip 1 of 2"`` / ``"Clip 3 of 8"`` / ``""``."""
        plan = self.current_trial()
        if plan is None:
            return ""
        key = "progress.practice" if plan.is_practice else "progress.clip"
        return design_text(self.design, key, k=self.trial_number(), n=self.phase_total())

    @property
    def answered(self) -> int:
        """Trials answered so far (all sessions of this participant)."""
        return self._pos

    # ------------------------------------------------------------------ playback
    @property
    def plays(self) -> int:
        """Plays of the current clip in this session."""
        return self._plays

    @property
    def play_id(self) -> int | None:
        """The id (``plays`` table) of the play started and not yet reported finished, or None."""
        return self._play_id

    @property
    def playing(self) -> bool:
        """A play of the current clip started and has not been reported finished (a browser page reloaded
        mid-clip leaves one open: the server closes it as not completed before the next play)."""
        return self._play_id is not None

    def can_play(self) -> bool:
        if self.current_trial() is None or self._play_id is not None:
            return False
        return bool(self.playback.allow_replay) or self._plays == 0

    def record_play_started(self, duration_s: float | None = None) -> int:
        """The clip started playing (from the start). Returns the play's id.

        ``duration_s``: how long the player's scene lasts; stored with the answer as ``trial_duration_s``.
        Without it (a pilot bot with no scene) the trial's timeline says (:func:`trial_duration_s`).
        """
        self._expect(State.PRACTICE, State.TRIALS)
        if self._play_id is not None:
            raise SessionError("the clip is already playing")
        if not self.can_play():
            raise SessionError("this study allows each clip to be played only once")
        if self.block_instructions() is not None:
            raise SessionError("the block's instructions come first (finish_block_instructions)")
        plan = self.plans[self._pos]
        self._play_id = self.db.start_play(self.participant_id, plan.trial_index, self.session_id)
        self._plays += 1
        if duration_s is not None:
            self._played_s = float(duration_s)
        return self._play_id

    def record_play_finished(self, completed: bool, stats: PlayStats | Mapping[str, Any] | None = None) -> None:
        """The play ended: ``completed`` when it reached the clip's end (not stopped or interrupted)."""
        self._expect(State.PRACTICE, State.TRIALS)
        if self._play_id is None:
            raise SessionError("no clip is playing")
        self.db.finish_play(self._play_id, completed)
        self._play_id = None
        if completed:
            self._completed_plays += 1
        self._add_stats(_stats_dict(stats))

    def _add_stats(self, s: Mapping[str, Any]) -> None:
        if s.get("frames_shown") is not None:
            self._frames_shown = (self._frames_shown or 0) + int(s["frames_shown"])
        if s.get("dropped_frames") is not None:
            self._dropped = (self._dropped or 0) + int(s["dropped_frames"])
        if s.get("refresh_hz") is not None:
            self._refresh = float(s["refresh_hz"])
        if s.get("worst_av_offset_ms") is not None:
            w = abs(float(s["worst_av_offset_ms"]))
            self._worst_av = w if self._worst_av is None else max(self._worst_av, w)

    def abandon_play(self) -> None:
        """The front end lost the open play (a browser page reloaded mid-clip): it is recorded as not
        completed and, as after a restart, does not count against ``allow_replay = false``."""
        self._expect(State.PRACTICE, State.TRIALS)
        if self._play_id is None:
            raise SessionError("no clip is playing")
        lost = self._play_id
        self.record_play_finished(False)
        row = next((s for s in self.db.sessions(self.participant_id) if s["id"] == self.session_id), None)
        known = list(row["machine"].get(LOST_PLAYS, [])) if row is not None else []
        self.db.update_session_machine(self.session_id, {LOST_PLAYS: [*known, lost]})
        self._plays -= 1

    def can_rank(self) -> bool:
        """True when the ranking may be submitted (the clip was watched fully once, if the design asks)."""
        if self.current_trial() is None or self._play_id is not None:
            return False
        return self._completed_plays > 0 or not bool(self.playback.must_watch_fully)

    # ------------------------------------------------------------------ answers
    # ------------------------------------------------------------------ blocks
    def _block(self, plan: Any) -> Any:
        """The trial's block (``"main"`` of a design without blocks, or a stand-in design without any)."""
        finder = getattr(self.design, "block", None)
        try:
            return finder(getattr(plan, "block", "main")) if finder is not None else None
        except KeyError:
            return None

    def criteria_of(self, plan: Any) -> list[str]:
        """The criteria a trial asks (its block's)."""
        block = self._block(plan)
        return list(block.criteria) if block is not None else list(self.criteria)

    def block_instructions(self) -> str | None:
        """The current block's instructions while they are due (before its first trial), else None."""
        plan = self.current_trial()
        if plan is None:
            return None
        block = self._block(plan)
        if block is None or not block.instructions or block.id in self._intro_seen:
            return None
        # every trial before the current one is answered: one of this block among them means it started
        # before (in this session or an earlier one)
        if any(getattr(p, "block", "main") == block.id for p in self.plans[:self._pos]):
            return None
        return block.instructions

    def finish_block_instructions(self) -> None:
        """The participant read the block's instructions; the block's first trial may play."""
        self._expect(State.PRACTICE, State.TRIALS)
        plan = self.current_trial()
        if self.block_instructions() is None:
            raise SessionError("no block instructions are due")
        self._intro_seen.add(getattr(plan, "block", "main"))
        self.db.update_session_machine(self.session_id, {BLOCK_INTROS: sorted(self._intro_seen)})

    # ------------------------------------------------------------------ answers
    def _ready_to_answer(self, paradigms: tuple[str, ...]) -> Any:
        """The current plan, after the checks every answer shares (state, paradigm, watched once)."""
        self._expect(State.PRACTICE, State.TRIALS)
        plan = self.plans[self._pos]
        paradigm = getattr(plan, "paradigm", "rank")
        if paradigm not in paradigms:
            raise SessionError(f"trial {plan.trial_index} is a {paradigm} trial; answer it with "
                               + {"rank": "submit_ranking", "rating": "submit_ratings"}.get(paradigm, "submit_preference"))
        if self.block_instructions() is not None:
            raise SessionError("the block's instructions come first (finish_block_instructions)")
        if self._play_id is not None:
            raise RankingError("Please wait until the clip has finished playing.")
        if not self.can_rank():
            raise RankingError("Please watch the clip to the end before answering.")
        return plan

    def _record(self, plan: Any, passed: bool | None) -> TrialRecord:
        return TrialRecord(
            participant=self.participant_id,
            trial_index=int(plan.trial_index),
            stimulus=plan.stimulus_id,
            is_practice=bool(plan.is_practice),
            is_attention_check=bool(plan.is_attention_check),
            slots=tuple(plan.slots),
            samples=tuple(plan.samples),
            shown_at=self._shown_wall,
            answered_at=now_iso(),
            response_time_s=None if self._shown_mono is None else round(time.monotonic() - self._shown_mono, 4),
            plays=self.db.play_count(self.participant_id, plan.trial_index),
            frames_shown=self._frames_shown,
            dropped_frames=self._dropped,
            refresh_hz=self._refresh,
            worst_av_offset_ms=self._worst_av,
            attention_passed=passed,
            session=self.session_id,
            trial_duration_s=self._played_s if self._played_s is not None else trial_duration_s(self.design, plan),
            block=getattr(plan, "block", "main"),
            paradigm=getattr(plan, "paradigm", "rank"),
            motion_stimuli=tuple(getattr(plan, "motion_stimuli", ()) or ()),
        )

    def _commit(self, plan: Any, record: TrialRecord, responses: Sequence[Response],
                judgements: Sequence[Judgement] = ()) -> State:
        self.db.save_trial(record, responses, judgements)  # durable when it returns
        self._pos += 1
        if self.on_saved is not None:
            self.on_saved(plan)
        self._advance()
        return self.state

    def submit_ranking(
        self,
        ranks: Mapping[str, Mapping[Any, Any]],
        stats: PlayStats | Mapping[str, Any] | None = None,
    ) -> State:
        """Validate, commit (one transaction) and advance to the next trial; returns the new state.

        ``ranks`` is ``{criterion id: {slot index 0..2: rank 1..3}}``; ``stats`` may add playback figures
        not reported through :meth:`record_play_finished`.
        """
        plan = self._ready_to_answer(("rank",))
        allow_ties = bool(getattr(self.playback, "allow_ties", False))
        clean = normalise_ranks(ranks, self.criteria_of(plan), allow_ties)
        self._add_stats(_stats_dict(stats))
        record = self._record(plan, attention_passed(self.design, plan, clean))
        responses = [
            Response(criterion=crit, condition=plan.slots[slot], slot=slot, rank=r)
            for crit in self.criteria_of(plan)
            for slot, r in enumerate(clean[crit])
        ]
        return self._commit(plan, record, responses)

    def submit_preference(
        self,
        levels: Mapping[str, int],
        reasons: Sequence[str] = (),
        stats: PlayStats | Mapping[str, Any] | None = None,
    ) -> State:
        """Answer a pairwise or mismatch trial (see the module notes): ``levels[criterion]`` NEGATIVE = left
        preferred, POSITIVE = right, 0 = none; ``reasons`` from the block's list, only when some level != 0."""
        plan = self._ready_to_answer(("pairwise", "mismatch"))
        block = self._block(plan)
        clean = normalise_preference(levels, reasons, self.criteria_of(plan),
                                     int(getattr(block, "levels", 5)), tuple(getattr(block, "reasons", ())))
        self._add_stats(_stats_dict(stats))
        chosen = tuple(r for r in getattr(block, "reasons", ()) if r in set(reasons))  # the block's order
        judgements = [Judgement(crit, plan.slots[slot], slot, float(-level if slot == 0 else level), chosen)
                      for crit, level in clean.items() for slot in (0, 1)]
        return self._commit(plan, self._record(plan, None), (), judgements)

    def submit_ratings(
        self,
        ratings: Mapping[str, Mapping[Any, float]],
        stats: PlayStats | Mapping[str, Any] | None = None,
    ) -> State:
        """Answer a rating trial: ``ratings[criterion][slot]`` in 0..100 for every criterion and slot."""
        plan = self._ready_to_answer(("rating",))
        clean = normalise_ratings(ratings, self.criteria_of(plan), len(plan.slots))
        self._add_stats(_stats_dict(stats))
        judgements = [Judgement(crit, plan.slots[slot], slot, value)
                      for crit, values in clean.items() for slot, value in enumerate(values)]
        return self._commit(plan, self._record(plan, None), (), judgements)

    # ------------------------------------------------------------------ questionnaire
    @property
    def questionnaire_items(self) -> list[Any]:
        return list(getattr(self.design, "questionnaire", None) or [])

    def submit_questionnaire(self, answers: Mapping[str, Any]) -> State:
        """Store the questionnaire: every item but ``text`` must be answered (see
        :meth:`~studyapp.study.design.QuestionItem.check_answer` for what each kind accepts and stores)."""
        self._expect(State.QUESTIONNAIRE)
        items = {q.id: q for q in self.questionnaire_items}
        unknown = sorted(set(answers) - set(items))
        if unknown:
            raise RankingError(f"unknown question(s): {', '.join(unknown)}")
        clean: dict[str, Any] = {}
        for qid, q in items.items():
            value, problem = q.check_answer(answers.get(qid))
            if problem is not None:
                raise RankingError(problem)
            clean[qid] = int(value) if q.kind == "likert" else value
        self.db.save_questionnaire(self.participant_id, clean,
                                   {q.id: (q.kind, getattr(q, "scale", None)) for q in items.values()})
        self.state = State.DONE
        self._finish("done")
        return self.state

    # ------------------------------------------------------------------ the end
    @property
    def finished(self) -> bool:
        return self.state in (State.DONE, State.ENDED_EARLY, State.DECLINED)

    @property
    def end_message(self) -> str:
        if self.state is State.ENDED_EARLY:
            return design_text(self.design, "final.ended_early_text")
        if self.state is State.DECLINED:
            return design_text(self.design, "final.declined_text")
        if self.state is State.DONE:
            return getattr(self.design, "completion", "") or design_text(self.design, "final.done_text")
        return ""

    def close(self) -> None:
        """Mark this session's end time (the participant may still resume later)."""
        if not self.finished:
            self.db.end_session(self.session_id)

