"""The browser participant's flow: the desktop's :class:`~studyapp.study.session.Session`, driven over HTTP.

There is one path: every page a browser participant sees is a state of the same session state machine the
desktop runs, and every answer goes through the same ``Session.submit_*`` methods, committed (one
transaction) before the reply that shows the next trial is sent. This module knows nothing of HTTP: it turns
a session into the JSON a page shows (:meth:`Flow.state`) and an action into a session call
(:meth:`Flow.act`); :mod:`studyapp.web.app` puts it on the network.

Participants and their rows
    A participant is created only when they consent (or decline) on the first page, never by opening the
    link, so a link preview or a visitor who leaves at once takes no Latin-square row. Their id is Prolific's
    ``PROLIFIC_PID`` when the link carries one (``STUDY_ID`` and ``SESSION_ID`` are recorded in the session's
    machine record, with ``frontend = "browser"``), else ``web-<12 random hex digits>``. The row is the least
    used one, chosen in the database's write transaction (:meth:`~studyapp.study.storage.ResultsDB.add_participant`),
    so lab stations and browser participants share one balance.

One session, any process
    No participant state is kept in a server's memory: every request restores the participant's session from
    the results database (``Session(..., session_id=...)``: the phase, the current trial, its plays, see
    :mod:`studyapp.study.session`), does its one step through the session's methods and forgets it. So any
    server process on the same PostgreSQL database (``studyapp serve --workers N``, or several servers behind
    one reverse proxy sharing the secret file) can serve any request of any participant, and a server restart
    changes nothing a participant sees. The session continued is the participant's latest one when it is an
    open browser session, else a new one starts. One participant's requests run one at a time across processes
    (:meth:`~studyapp.study.storage.ResultsDB.exclusive`, a PostgreSQL advisory lock per participant), as they
    do on one process's database thread (:mod:`studyapp.web.dbthread`). What a process keeps is only what the
    design and a participant's id and row determine (schedules, texts, tokens): worked out again by any process.

Coming back
    Reloading a page shows the same state, and so does a server restart. The study link opened again with the
    same ``PROLIFIC_PID`` continues an unfinished participant; a participant who finished (or ended) is refused.
    A participant whose latest session was not an open browser one (one begun at a lab station) starts a new
    session at the first unanswered trial, with a "welcome back" page first, as on the desktop (a clip played
    but not answered is shown again and must be watched again).

Abandonment
    A browser participant with no activity for the design's ``[online] abandon_after_min`` is abandoned when the
    server next assigns a row (looking at most once per :data:`SWEEP_EVERY_S`) or shows the dashboard
    (:meth:`Flow.sweep`): status ``ended_early``, and the
    last session's machine record gets :data:`~studyapp.study.storage.ABANDONED` (the time) and
    ``abandon_after_min``. Their answers are kept; their row is given out again. Coming back later, they read
    that the session was closed. Activity is the latest session start or end, play start or end, and answer, and
    the latest request of any server process (the session's :data:`SEEN_AT`, written at most once per
    :data:`SEEN_EVERY_S`).

Paradigms
    A trial's page carries its paradigm (``rank``, ``pairwise``, ``mismatch``, ``rating``) and the answer goes to
    the session's method for it (``submit_ranking``, ``submit_preference``, ``submit_ratings``), which checks
    it; a block's instructions come first (``block`` action, ``Session.finish_block_instructions``). An answer
    the session refuses is a 422 with its message for the participant; a request the session's state does not
    allow (a stale or forged page) is a 400.

Must watch once
    The page reports when the video starts (``play``) and when it fires ``ended``; the server counts the play
    as complete only when at least the video's length (less :data:`WATCH_SLACK_S`) passed between the two,
    so a page that skips ahead or speeds up has not watched. The reply to ``play`` carries a signed ticket with
    the play's id and start time (:meth:`~studyapp.web.tokens.Tokens.play`); the page sends it with ``ended``,
    so the process that gets ``ended`` knows the start without any memory of the one that got ``play``.
    Several machines behind one proxy must keep their clocks in step (NTP).
"""
from __future__ import annotations

import re
import secrets
import threading
import time
from collections import OrderedDict
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator, Mapping

from studyapp.study.design.texts import fill
from studyapp.study.session import (ParticipantFinishedError, RankingError, Session, SessionError, State,
                                    trial_duration_s)
from studyapp.study.storage import ABANDONED, ParticipantRecord, ResultsDB, now_iso
from studyapp.web.media import TrialVideos, duration_s
from studyapp.web.security import BadRequest, finite_number
from studyapp.web.tokens import Tokens

#: Prolific's URL parameters, recorded with the session (``PROLIFIC_PID`` is the participant id).
PROLIFIC_PARAMS = ("PROLIFIC_PID", "STUDY_ID", "SESSION_ID")
_PARAM_RE = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
#: A completed play may end this much sooner than the video's length (timer granularity, start latency).
WATCH_SLACK_S = 0.5
#: Abandonment is looked for at most this often (it reads every unfinished participant's record); the
#: timeout itself is minutes to hours.
SWEEP_EVERY_S = 60.0
#: A participant's presence (any request) is written to their session at most this often.
SEEN_EVERY_S = 60.0
#: The key of a session's ``machine`` record holding the latest request's time (ISO 8601, UTC).
SEEN_AT = "seen_at"
#: The longest text answer kept (a questionnaire comment).
MAX_TEXT_CHARS = 5000
#: How many participants' schedules a server process keeps (see :meth:`Flow.plans`).
PLANS_KEPT = 4096


def digit_points(n_anchors: int) -> list[float]:
    """Where the number keys 1, 2, .. put a rating slider, as on the desktop (``studyapp.ui.rating``, a module
    of the same layer): the centres of the anchors' equal intervals on 0..100, or 10, 20, .. 90 without anchors.

    >>> digit_points(3), digit_points(0)[:3]
    ([16.67, 50.0, 83.33], [10.0, 20.0, 30.0])
    """
    if not n_anchors:
        return [10.0 * k for k in range(1, 10)]
    return [round(100.0 * (k + 0.5) / n_anchors, 2) for k in range(min(n_anchors, 9))]


class Refused(Exception):
    """The participant cannot (or can no longer) take part; ``key`` names the participant text."""

    def __init__(self, key: str) -> None:
        super().__init__(key)
        self.key = key


class NotSaved(Exception):
    """An answer the session refused; the message is for the participant (nothing was stored)."""


def prolific_params(query: Mapping[str, str]) -> dict[str, str]:
    """The Prolific parameters of a link; a malformed value makes the link invalid (:class:`Refused`).

    >>> prolific_params({"PROLIFIC_PID": "5f1c0ffee", "STUDY_ID": "s1", "x": "y"})
    {'PROLIFIC_PID': '5f1c0ffee', 'STUDY_ID': 's1'}
    """
    out = {}
    for name in PROLIFIC_PARAMS:
        value = query.get(name)
        if value is None or value == "":
            continue
        if not _PARAM_RE.match(value):
            raise Refused("online.bad_link")
        out[name] = value
    return out


def _lazy(read: Callable[[], Iterable[str]]) -> Iterator[str]:
    """``read()``'s items, read only when the first one is asked for."""
    yield from read()


def _seconds(iso: str | None) -> float | None:
    if not iso:
        return None
    try:
        return datetime.fromisoformat(iso).timestamp()
    except ValueError:
        return None


class Flow:
    """Every browser participant of one study (see the module docstring)."""

    def __init__(self, design: Any, db: ResultsDB, tokens: Tokens, videos: TrialVideos,
                 clock: Callable[[], float] = time.time) -> None:
        self.design = design
        self._db = db
        self._local = threading.local()
        self.tokens = tokens
        self.videos = videos
        self.clock = clock
        self._lengths: dict[Path, float] = {}
        self._minutes: int | None = None
        self._swept: float | None = None
        self._n_rows: int | None = None
        self._texts: dict[str, str] = {}
        #: Participants' schedules, worked out from the design, their id and row alone (never changed by what
        #: they do): kept so a request restores a session without drawing its schedule again. Losing them
        #: changes nothing (any process draws the same), so this is no participant state.
        self._plans: OrderedDict[tuple[str, int], list[Any]] = OrderedDict()

    # ------------------------------------------------------------------ the database
    @property
    def db(self) -> ResultsDB:
        """The results database as the calling thread reaches it: its own connection when it opened one
        (:meth:`use_own_connection`), else the one the flow was made with."""
        return getattr(self._local, "db", None) or self._db

    def use_own_connection(self) -> None:
        """Give the calling thread a connection of its own to the database (one more of a server process's
        database threads on PostgreSQL, whose requests then run side by side)."""
        if getattr(self._local, "db", None) is None:
            self._local.db = self._db.twin()

    def close_own_connection(self) -> None:
        db = getattr(self._local, "db", None)
        if db is not None:
            self._local.db = None
            db.close()

    # ------------------------------------------------------------------ texts
    def t(self, key: str, **values: Any) -> str:
        if values:
            return self.design.text(key, **values)
        text = self._texts.get(key)   # a page shows dozens of fixed texts: each is filled in once
        if text is None:
            text = self._texts[key] = self.design.text(key)
        return text

    def _page(self, screen: str, **extra: Any) -> dict[str, Any]:
        return {"screen": screen, "title": self.design.title, "lang": self.design.language, **extra}

    # ------------------------------------------------------------------ entry and start
    def entry(self, query: Mapping[str, str]) -> dict[str, Any]:
        """What the study link shows: the consent page, a redirect to the participant's pages (an unfinished
        participant coming back), or a refusal (:class:`Refused`)."""
        params = prolific_params(query)
        pid = params.get("PROLIFIC_PID")
        if pid is not None and self.db.participant(pid) is not None:
            self.sweep()
            rec = self.db.participant(pid)
            if rec is not None and rec.status != "active":
                raise Refused("online.expired" if self._abandoned(pid) else "online.already_done")
            return {"redirect": f"/s/{self.tokens.session(pid)}/"}
        nonce = secrets.token_urlsafe(16)
        return self._page(
            "welcome", nonce=nonce, entry_csrf=self.tokens.entry_csrf(nonce), params=params,
            heading=self.t("welcome.title"),
            consent=fill(self.design.consent or self.t("welcome.consent"), minutes=self.estimated_minutes()),
            note=self.t("welcome.agree_note"), agree=self.t("welcome.agree"), decline=self.t("welcome.decline"),
            decline_ask=self.t("welcome.decline_ask"), decline_confirm=self.t("welcome.decline_confirm"),
            decline_back=self.t("welcome.decline_back"))

    def estimated_minutes(self) -> int:
        """About how long the study takes: each trial's timeline plus 40 s to answer (as the desktop says);
        worked out once (it reads every clip's audio header)."""
        if self._minutes is None:
            from studyapp.study.schedule import participant_schedule

            total = 0.0
            for plan in participant_schedule(self.design, "estimate", 0):
                total += (trial_duration_s(self.design, plan) or 30.0) + 40.0
            self._minutes = max(2, int(round(total / 60.0)))
        return self._minutes

    def start(self, body: Mapping[str, Any]) -> str:
        """The consent page's answer: create the participant (or find the one coming back) and return their
        session token. ``body``: ``nonce``, ``csrf`` (:meth:`Tokens.entry_csrf`), ``consent`` (bool),
        ``params`` (the link's Prolific parameters)."""
        nonce, csrf = body.get("nonce"), body.get("csrf")
        if not isinstance(nonce, str) or not isinstance(csrf, str) or csrf != self.tokens.entry_csrf(nonce):
            raise BadRequest("bad entry CSRF token")
        consent = body.get("consent")
        if not isinstance(consent, bool):
            raise BadRequest("consent must be true or false")
        raw = body.get("params") or {}
        if not isinstance(raw, dict) or not all(isinstance(v, str) for v in raw.values()):
            raise BadRequest("params must map names to strings")
        params = prolific_params(raw)
        pid = params.get("PROLIFIC_PID") or f"web-{secrets.token_hex(6)}"
        self.sweep()
        with self.db.exclusive(pid):
            try:
                session, seen = self._open(pid, params, rec=self.db.participant(pid))
            except ParticipantFinishedError:
                raise Refused("online.expired" if self._abandoned(pid) else "online.already_done") from None
            if session.state is State.WELCOME and not session.resumed:
                if consent:
                    session.accept_consent()
                else:
                    session.decline_consent()
            self._touch(session, seen)
        return self.tokens.session(pid)

    def _open(self, pid: str, params: Mapping[str, str] | None = None, create: bool = True,
              rec: ParticipantRecord | None = None) -> tuple[Session, float | None]:
        """The participant's session, restored from the database: their open browser session (see "One
        session, any process"), else (``create``) a new one (a new participant is registered on the least used
        row); without ``create`` and with no open session, :class:`Refused`. ``rec``: the participant's record
        when the caller read it (None: a new participant). Also returns when the session's presence was last
        written (:data:`SEEN_AT`, seconds; None when never)."""
        sessions = self.db.sessions(pid)
        last = sessions[-1] if sessions else None
        plans = None if rec is None else self.plans(pid, rec.latin_row)
        if last is not None and last["ended"] is None and last["machine"].get("frontend") == "browser":
            session = Session(self.design, self.db, pid, session_id=last["id"], play_duration_s=self._length,
                              plans=plans, n_rows=self.n_rows(), participant=rec)
            return session, _seconds(last["machine"].get(SEEN_AT))
        if not create:
            raise Refused("online.bad_link")
        now = self._now_iso()
        session = Session(self.design, self.db, pid, plans=plans, n_rows=self.n_rows(), participant=rec, machine={
            "frontend": "browser", SEEN_AT: now, **{f"prolific_{k.lower()}": v for k, v in (params or {}).items()}})
        if rec is None:
            self._keep(session.participant_id, session.row, session.plans)
        elif not session.resumed:
            session.accept_consent()   # consented when the record was made; nothing answered yet
        return session, _seconds(now)

    def n_rows(self) -> int:
        """The design's number of Latin-square rows (worked out once)."""
        if self._n_rows is None:
            from studyapp.study.schedule import n_rows

            self._n_rows = int(n_rows(self.design))
        return self._n_rows

    def plans(self, pid: str, row: int) -> list[Any]:
        """The participant's schedule (:func:`~studyapp.study.schedule.participant_schedule`), drawn once per
        process for the last :data:`PLANS_KEPT` participants seen."""
        key = (pid, int(row))
        plans = self._plans.get(key)
        if plans is None:
            from studyapp.study.schedule import participant_schedule

            plans = participant_schedule(self.design, pid, int(row))
            self._keep(pid, row, plans)
        else:
            try:
                self._plans.move_to_end(key)
            except KeyError:   # another database thread dropped it meanwhile: it is kept again next time
                pass
        return plans

    def _keep(self, pid: str, row: int, plans: list[Any]) -> None:
        self._plans[(pid, int(row))] = list(plans)
        while len(self._plans) > PLANS_KEPT:
            try:
                self._plans.popitem(last=False)
            except KeyError:
                break

    def participant_for(self, token: str) -> str:
        # the ids are read only when the token is not one this process has seen (a participant another process
        # registered): a known token costs no query
        pid = self.tokens.participant_for(token, _lazy(self.db.participant_ids))
        if pid is None:
            raise Refused("online.bad_link")
        return pid

    # ------------------------------------------------------------------ abandonment
    def _touch(self, session: Session, seen: float | None) -> None:
        """Record that the participant is here (their session's :data:`SEEN_AT`, at most once per
        :data:`SEEN_EVERY_S`; ``seen``: when it was written last, as :meth:`_open` read it): a page read for a
        long time is activity too, whichever process served it."""
        if session.finished:
            return
        now = self.clock()
        if seen is None or now - seen >= SEEN_EVERY_S:
            self.db.update_session_machine(session.session_id, {SEEN_AT: self._now_iso()})

    def _now_iso(self) -> str:
        return datetime.fromtimestamp(self.clock(), timezone.utc).isoformat(timespec="milliseconds")

    def _abandoned(self, pid: str) -> bool:
        return any(ABANDONED in s["machine"] for s in self.db.sessions(pid))

    def last_activity(self, pid: str) -> float:
        """The time (seconds since the epoch) of the participant's latest recorded or seen activity."""
        times: list[float | None] = []
        for s in self.db.sessions(pid):
            times += [_seconds(s["started"]), _seconds(s["ended"]), _seconds(s["machine"].get(SEEN_AT))]
        for p in self.db.plays(pid):
            times += [_seconds(p["started"]), _seconds(p["ended"])]
        times += [_seconds(t["answered_at"]) for t in self.db.trials(pid)]
        return max((t for t in times if t is not None), default=0.0)

    def sweep(self, force: bool = False) -> list[str]:
        """Mark every browser participant inactive for longer than ``abandon_after_min`` abandoned (see the
        module docstring); returns their ids. It reads every unfinished participant's record, so it runs at
        most once per :data:`SWEEP_EVERY_S` unless ``force`` (the dashboard)."""
        limit_s = float(self.design.online.abandon_after_min) * 60.0
        now = self.clock()
        if not force and self._swept is not None and now - self._swept < SWEEP_EVERY_S:
            return []
        self._swept = now
        out = []
        for rec in self.db.participants():
            if rec.status != "active":
                continue
            sessions = self.db.sessions(rec.id)
            if not sessions or not any(s["machine"].get("frontend") == "browser" for s in sessions):
                continue   # a lab participant: the experimenter decides when they stop
            if now - self.last_activity(rec.id) <= limit_s:
                continue
            with self.db.exclusive(rec.id):   # not while another process serves them; looked at again inside
                current = self.db.participant(rec.id)
                if current is None or current.status != "active" or now - self.last_activity(rec.id) <= limit_s:
                    continue
                sessions = self.db.sessions(rec.id)
                self.db.update_session_machine(sessions[-1]["id"], {
                    ABANDONED: now_iso(), "abandon_after_min": self.design.online.abandon_after_min})
                self.db.set_status(rec.id, "ended_early")
                for s in sessions:
                    if s["ended"] is None and s["machine"].get("frontend") == "browser":
                        self.db.end_session(s["id"])
            out.append(rec.id)
        return out

    # ------------------------------------------------------------------ what a page shows
    def state(self, pid: str) -> dict[str, Any]:
        """The page the participant sees now, as JSON."""
        return self._step(pid, lambda session: self._show(session, pid))

    def _step(self, pid: str, step: Callable[[Session], dict[str, Any]]) -> dict[str, Any]:
        """``step(session)`` on the participant's session, restored and marked seen, while no other request of
        theirs runs (:meth:`~studyapp.study.storage.ResultsDB.exclusive`); the final page instead for one who
        no longer takes part, :class:`Refused` for an unknown one. What every request of a page goes through."""
        with self.db.exclusive(pid):
            rec = self.db.participant(pid)
            if rec is None:
                raise Refused("online.bad_link")
            if rec.status != "active":
                return self._final(pid, rec.status)
            session, seen = self._open(pid, rec=rec)
            self._touch(session, seen)
            return step(session)

    def _show(self, session: Session, pid: str) -> dict[str, Any]:
        tok = self.tokens.session(pid)
        common = {"csrf": self.tokens.csrf(pid), "base": f"/s/{tok}/"}
        st = session.state
        if st is State.WELCOME:   # a resumed participant after a restart: "welcome back"
            rp = session.resume_point
            lines = []
            if rp is not None:
                lines.append(self.t("welcome.back_practice" if rp.practice else "welcome.back_clip", k=rp.k, n=rp.n))
                if rp.dropped:
                    lines.append(self.t("welcome.back_dropped"))
            return self._page("back", heading=self.t("welcome.back_title"), lines=lines,
                              button=self.t("page.continue"), **common)
        if st is State.INSTRUCTIONS:
            return self._page("instructions", heading=self.t("instructions.title"),
                              text=self.design.instructions, questions_title=self.t("instructions.questions"),
                              criteria=self._criteria(), how_title=self._how_title(),
                              how="\n\n".join(self._how()),
                              ties=self.t("instructions.ties") if self.design.playback.allow_ties else "",
                              button=self.t("page.continue"), **common)
        if st is State.ENV_CHECK:
            return self._page("soundcheck", heading=self.t("env.sound_title"), text=self.t("env.sound_text"),
                              play=self.t("env.sound_button").replace(" (T)", ""), tone="/a/tone.wav",
                              button=self.t("online.sound_heard"), **common)
        if st in (State.PRACTICE, State.TRIALS):
            return self._trial(session, pid, tok, common)
        if st is State.QUESTIONNAIRE:
            return self._page("questionnaire", heading=self.t("questionnaire.title"),
                              intro=self.t("questionnaire.intro"), items=self._items(),
                              button=self.t("questionnaire.submit"), missing=self.t("questionnaire.missing"), **common)
        return self._final(pid, "done" if st is State.DONE else "ended_early")

    def _final(self, pid: str, status: str) -> dict[str, Any]:
        if status == "done":
            online = self.design.online
            return self._page("done", heading=self.t("final.done"),
                              text=self.design.completion or self.t("final.done_text"),
                              code=self.t("online.code", code=online.completion_code) if online.completion_code else "",
                              redirect=online.completion_url, button=self.t("online.return"))
        declined = any(s["machine"].get("consent") == "declined" for s in self.db.sessions(pid))
        if declined:
            return self._page("declined", heading=self.t("final.declined"), text=self.t("final.declined_text"))
        text = self.t("online.expired") if self._abandoned(pid) else self.t("final.ended_early_text")
        return self._page("ended", heading=self.t("final.ended_early"), text=text)

    def _criteria(self, ids: list[str] | None = None) -> list[dict[str, str]]:
        return [{"id": c.id, "label": c.label, "question": c.question, "explanation": c.explanation}
                for c in self.design.criteria if ids is None or c.id in ids]

    def _how_title(self) -> str:
        """"How to rank" for a ranking-only design, else "How to answer" (as the desktop's instructions)."""
        only_rank = [b.paradigm for b in self.design.trial_blocks] == ["rank"]
        return self.t("instructions.how_title" if only_rank else "instructions.how_answer_title")

    def _how(self) -> list[str]:
        """How to answer, for each paradigm the design's blocks use (in their order)."""
        out: list[str] = []
        for block in self.design.trial_blocks:
            if block.paradigm == "rank":
                text = self.t("instructions.how", keys=self._rank_keys(self._labels(3)))
            elif block.paradigm in ("pairwise", "mismatch"):
                names = self.design.slot_labels_for(2) or ("1", "2")  # what the answers call the figures
                first, last = names[0], names[-1]
                text = self.t("instructions.how_pref", n=block.levels, first=first, last=last)
                if block.reasons:
                    text += "\n\n" + self.t("instructions.how_reasons")
            else:
                text = self.t("instructions.how_rating", n=len(digit_points(len(block.anchors))))
            if text not in out:
                out.append(text)
        return out

    def _labels(self, n: int) -> list[str]:
        """The figures' labels on a trial of ``n`` figures, left to right."""
        return list(self.design.slot_labels_for(n) or [str(k + 1) for k in range(n)])

    @staticmethod
    def _rank_keys(labels: list[str]) -> str:
        """Which number key picks which figure, as the desktop says it: the digits name figures, not ranks.

        >>> Flow._rank_keys(["A", "B", "C"])
        '1 = A, 2 = B, 3 = C'
        """
        return ", ".join(f"{i + 1} = {label}" for i, label in enumerate(labels))

    def _items(self) -> list[dict[str, Any]]:
        out = []
        for q in self.design.questionnaire:
            item: dict[str, Any] = {"id": q.id, "kind": q.kind, "text": q.text}
            if q.kind == "likert":
                item.update(points=int(q.points), anchors=list(q.anchors))
            elif q.kind == "choice":
                item.update(options=list(q.options), multiple=bool(q.multiple),
                            hint=self.t("questionnaire.all_that_apply") if q.multiple else "")
            elif q.kind == "number":
                key = "questionnaire.whole_number" if q.integer else "questionnaire.number"
                from studyapp.study.design.model import plain_number

                item.update(min=q.min, max=q.max, integer=bool(q.integer),
                            hint=self.t(key, min=plain_number(q.min), max=plain_number(q.max)))
            out.append(item)
        return out

    def _trial(self, session: Session, pid: str, tok: str, common: dict[str, Any]) -> dict[str, Any]:
        plan = session.current_trial()
        intro = session.block_instructions()
        if intro is not None:
            return self._page("block", heading=self.t("block.title"), text=intro, button=self.t("block.continue"),
                              **common)
        pos = session.plans.index(plan)
        nxt = session.plans[pos + 1] if pos + 1 < len(session.plans) else None
        if nxt is None:
            next_key = "rank.finish"
        elif plan.is_practice and not nxt.is_practice:
            next_key = "rank.start_study"
        else:
            next_key = "rank.next_practice" if plan.is_practice else "rank.next"
        labels = self._labels(len(plan.slots))
        paradigm = getattr(plan, "paradigm", "rank")
        block = self.design.block(getattr(plan, "block", "main"))
        pb = self.design.playback
        texts = {k: self.t(k) for k in ("trial.play", "trial.replay", "trial.ready", "trial.watch", "rank.wait",
                                        "rank.next_ok", "trial.loading")}
        if paradigm == "rank":
            texts |= {k: self.t(k) for k in ("trial.rank_now", "trial.rank_replay", "rank.first", "rank.second",
                                             "rank.third", "rank.drop_here", "rank.tie_on", "rank.tie_off")}
            texts |= {"start_hint": self.t("rank.start_hint", keys=self._rank_keys(labels)),
                      "still": self.t("rank.still", criteria="{criteria}")}
            answer: dict[str, Any] = {}
        elif paradigm in ("pairwise", "mismatch"):
            texts |= {"trial.rank_now": self.t("trial.answer_now"), "trial.rank_replay": self.t("trial.answer_replay"),
                      "reasons": self.t("pref.reasons"), "still": self.t("pref.still", criteria="{criteria}"),
                      "start_hint": self.t("pref.start_hint", n=block.levels)}
            answer = {"options": self._preference_options(block.levels, labels), "reasons": list(block.reasons)}
        else:
            texts |= {"trial.rank_now": self.t("trial.answer_now"), "trial.rank_replay": self.t("trial.answer_replay"),
                      "unset": self.t("rating.unset"), "still": self.t("rating.still", sliders="{criteria}"),
                      "start_hint": self.t("rating.start_hint", n=len(digit_points(len(block.anchors))))}
            answer = {"anchors": list(block.anchors), "points": digit_points(len(block.anchors))}
        texts["next"] = self.t(next_key)
        return self._page(
            "trial", paradigm=paradigm, progress=session.progress_label(),
            practice_note=self.t("trial.practice_note") if plan.is_practice else "",
            video=f"/s/{tok}/{self.tokens.media(pid, plan.trial_index)}.mp4", labels=labels,
            criteria=self._criteria(session.criteria_of(plan)),
            # a play still open here belongs to a page that was reloaded: the next "play" closes it
            can_play=session.can_play() or session.playing, can_rank=session.can_rank(),
            allow_replay=bool(pb.allow_replay), allow_ties=bool(pb.allow_ties), texts=texts, **answer, **common)

    def _preference_options(self, levels: int, labels: list[str]) -> list[dict[str, Any]]:
        """The answers of a preference question, left to right: (value, text); NEGATIVE = the left figure."""
        left, right = labels[0], labels[-1]
        if int(levels) == 3:
            return [{"value": -1, "text": self.t("pref.better", figure=left)},
                    {"value": 0, "text": self.t("pref.equal")},
                    {"value": 1, "text": self.t("pref.better", figure=right)}]
        return [{"value": -2, "text": self.t("pref.clearly", figure=left)},
                {"value": -1, "text": self.t("pref.slightly", figure=left)},
                {"value": 0, "text": self.t("pref.equal")},
                {"value": 1, "text": self.t("pref.slightly", figure=right)},
                {"value": 2, "text": self.t("pref.clearly", figure=right)}]

    # ------------------------------------------------------------------ media
    def media(self, pid: str, name: str) -> Path:
        """The current trial's video file, when ``name`` is its opaque name for this participant."""
        rec = self.db.participant(pid)
        if rec is None or rec.status != "active":
            raise Refused("online.bad_link")
        plan = self._open(pid, create=False, rec=rec)[0].current_trial()
        if plan is None or name != self.tokens.media(pid, plan.trial_index):
            raise Refused("online.bad_link")
        return self.videos.video(plan)

    def _length(self, plan: Any) -> float:
        path = self.videos.video(plan)
        if path not in self._lengths:
            self._lengths[path] = duration_s(path)
        return self._lengths[path]

    # ------------------------------------------------------------------ actions
    def act(self, pid: str, action: str, body: Mapping[str, Any]) -> dict[str, Any]:
        """Do one participant action and return the page to show next (raises :class:`NotSaved` with the
        participant's message when the session refuses an answer, :class:`BadRequest` for a malformed one)."""
        def step(session: Session) -> dict[str, Any]:
            extra = self._act(session, pid, action, body)
            if session.finished:
                return self._final(pid, "done" if session.state is State.DONE else "ended_early")
            return {**self._show(session, pid), **extra}

        return self._step(pid, step)

    def _act(self, session: Session, pid: str, action: str, body: Mapping[str, Any]) -> dict[str, Any]:
        """Do ``action`` on the session; what the reply carries besides the page (the ticket of a play)."""
        try:
            if action == "continue":
                if session.state is State.WELCOME:
                    session.accept_consent()
                    session.finish_instructions()
                    session.record_env_check({"frontend": "browser", "resumed_in_browser": True})
                elif session.state is State.INSTRUCTIONS:
                    session.finish_instructions()
                else:
                    raise BadRequest(f"nothing to continue in state {session.state.value}")
            elif action == "sound":
                session.record_env_check(self._env(body))
            elif action == "play":
                return {"play": self._play(session, pid)}
            elif action == "ended":
                self._ended(session, pid, body)
            elif action == "block":
                session.finish_block_instructions()
            elif action == "answer":
                self._answer(session, body)
            elif action == "questionnaire":
                session.submit_questionnaire(self._answers(body))
            else:
                raise BadRequest(f"unknown action {action!r}")
        except RankingError as exc:          # the participant's answer breaks a rule: they can fix it
            raise NotSaved(str(exc)) from None
        except SessionError as exc:          # not possible in this state: a stale or forged page
            raise BadRequest(str(exc)) from None
        return {}

    @staticmethod
    def _answer(session: Session, body: Mapping[str, Any]) -> None:
        """The current trial's answer, by its paradigm, through the session's method for it (which checks it)."""
        plan = session.current_trial()
        if plan is None:
            raise BadRequest("no trial to answer now")
        paradigm = getattr(plan, "paradigm", "rank")
        if paradigm == "rank":
            ranks = body.get("ranks")
            if not isinstance(ranks, dict) or not all(isinstance(v, dict) for v in ranks.values()):
                raise BadRequest("ranks must map each question to {slot: rank}")
            session.submit_ranking(ranks)
        elif paradigm in ("pairwise", "mismatch"):
            levels, reasons = body.get("levels"), body.get("reasons", [])
            if not isinstance(levels, dict) or not all(isinstance(v, int) and not isinstance(v, bool)
                                                       for v in levels.values()):
                raise BadRequest("levels must map each question to a whole number")
            if not isinstance(reasons, list) or not all(isinstance(r, str) for r in reasons) or len(reasons) > 50:
                raise BadRequest("reasons must be a list of texts")
            session.submit_preference(levels, reasons)
        else:
            ratings = body.get("ratings")
            if not isinstance(ratings, dict) or not all(
                    isinstance(v, dict) and all(finite_number(x, -1e9, 1e9) is not None for x in v.values())
                    for v in ratings.values()):
                raise BadRequest("ratings must map each question to {slot: number}")
            session.submit_ratings(ratings)

    @staticmethod
    def _env(body: Mapping[str, Any]) -> dict[str, Any]:
        """What the page reports about the browser: checked, cut to size (it is the participant's to say)."""
        ua = body.get("user_agent")
        info: dict[str, Any] = {"frontend": "browser", "sound_check": "heard"}
        if isinstance(ua, str):
            info["user_agent"] = ua[:300]
        w, h = finite_number(body.get("screen_w"), 1, 100_000), finite_number(body.get("screen_h"), 1, 100_000)
        if w is not None and h is not None:
            info["screen"] = f"{int(w)}x{int(h)}"
        return info

    def _play(self, session: Session, pid: str) -> str:
        if session.playing:
            # the page was reloaded (or lost) while a play was open: that play did not finish
            session.abandon_play()
        plan = session.current_trial()
        if plan is None:
            raise BadRequest("no clip to play now")
        play_id = session.record_play_started(duration_s=self._length(plan))
        return self.tokens.play(pid, play_id, self.clock())

    def _ended(self, session: Session, pid: str, body: Mapping[str, Any]) -> None:
        play_id, plan = session.play_id, session.current_trial()
        started = None if play_id is None else self.tokens.play_started(pid, play_id, body.get("play"))
        if started is None or plan is None:
            raise BadRequest("no clip is playing (or not the play this page started)")
        watched = self.clock() - started >= self._length(plan) - WATCH_SLACK_S
        session.record_play_finished(watched)

    def _answers(self, body: Mapping[str, Any]) -> dict[str, Any]:
        answers = body.get("answers")
        if not isinstance(answers, dict):
            raise BadRequest("answers must be an object")
        clean: dict[str, Any] = {}
        for k, v in answers.items():
            if isinstance(v, list):
                if len(v) > 100 or not all(isinstance(x, str) and len(x) <= MAX_TEXT_CHARS for x in v):
                    raise BadRequest(f"answer {k!r}: a list of texts expected")
            elif isinstance(v, str):
                if len(v) > MAX_TEXT_CHARS:
                    raise NotSaved(f"{k}: at most {MAX_TEXT_CHARS} characters")
            elif v is not None and finite_number(v, -1e12, 1e12) is None:
                raise BadRequest(f"answer {k!r}: not a text, number or list")
            clean[str(k)] = v
        return clean
