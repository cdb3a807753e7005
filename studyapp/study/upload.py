"""A remote participant's answers, uploaded to the study server as they are committed (``bundle --upload-url``).

The participant's local results database stays the source of truth: every answer is committed there first, by
the session, exactly as without a server, and the results zip is still written at the end (the fallback). An
:class:`Uploader` thread, with its own read-only connection to that database, notices each commit (SQLite's
``PRAGMA data_version``, polled every :data:`POLL_S`) and sends the participant's rows so far; it never touches
the session's connection, so the frame loop is never blocked or slowed by the network.

What one upload carries
    The participant's whole results file so far (:func:`studyapp.study.bundle.results_payload`, in the bundle's
    blinded ids), plays of answered trials only. The server runs the checks of ``merge`` on it and keeps it when
    it extends what it holds (:mod:`studyapp.web.uploads`), so the same upload sent twice is ignored, a lost
    reply is harmless, and an answer can never be changed: a different answer for a stored trial is refused.
    An upload is a few kilobytes per answered trial.

What was acknowledged
    ``<results>.uploaded.json`` next to the local database records, per participant, the state the server
    acknowledged (answered trials, status, questionnaire answers), written atomically after each reply. A run
    started after a crash, a restart or a network outage compares it with the local database and sends what
    is missing at once; an unreachable server is tried again (every :data:`RETRY_S` .. :data:`RETRY_MAX_S`
    seconds) for as long as the session runs, and :data:`END_GRACE_S` after its end. A refusal (the server's checks, a wrong secret) is recorded with
    the state refused, which is not sent again (a later commit is): the results zip is then the way those
    answers reach the experimenter.

Requests are signed: ``X-Studyapp-Signature`` is an HMAC-SHA256 (:func:`signature`), under the bundle's upload
secret, of the bundle's hash, the participant id and the body. The secret is in the bundle, so anyone holding
the bundle can upload as any of its roster ids: the same as mailing a results zip today. Answers are checked
(:mod:`studyapp.study.returned`) whoever sends them.

>>> signature("00" * 32, "abc", "R01", b"{}") == signature("00" * 32, "abc", "R01", b"{}")
True
>>> signature("00" * 32, "abc", "R01", b"{}") != signature("00" * 32, "abc", "R02", b"{}")
True
"""
from __future__ import annotations

import hashlib
import hmac
import json
import os
import sqlite3
import threading
import time
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from studyapp.errors import InputError

#: The server's upload address, relative to the study server's address recorded in the bundle.
UPLOAD_PATH = "/upload"
HEADER_BUNDLE = "x-studyapp-bundle"
HEADER_PARTICIPANT = "x-studyapp-participant"
HEADER_SIGNATURE = "x-studyapp-signature"
#: How often the worker looks for a new commit (one cheap pragma), and how it waits after a failed try.
POLL_S = 0.2
RETRY_S = 0.5
RETRY_MAX_S = 5.0
#: At the session's end an unreachable server is tried for this long more before the participant reads that not
#: everything was sent.
END_GRACE_S = 5.0
#: Seconds one request may take before it counts as failed (and is tried again).
REQUEST_TIMEOUT_S = 10.0
_LOOPBACK = ("127.0.0.1", "localhost", "::1")


def check_upload_url(url: str) -> str:
    """The study server's address for ``bundle --upload-url``: ``https://``, or ``http://`` on this machine only
    (answers must not cross a network unencrypted).

    >>> check_upload_url("https://study.example.org/"), check_upload_url("http://127.0.0.1:8000")
    ('https://study.example.org', 'http://127.0.0.1:8000')
    """
    parts = urllib.parse.urlsplit(url)
    if parts.scheme == "https" or (parts.scheme == "http" and parts.hostname in _LOOPBACK):
        if parts.hostname and not parts.query and not parts.fragment:
            return url.rstrip("/")
    raise InputError(None, "--upload-url", f"{url!r} is not a study server address: give https://HOST[/PATH] "
                     "(plain http:// only for 127.0.0.1 or localhost)")


def signature(secret: str, bundle_hash: str, participant: str, body: bytes) -> str:
    """The HMAC-SHA256 (hex) that authenticates one upload (see the module docstring)."""
    msg = b"\0".join([bundle_hash.encode("utf-8"), participant.encode("utf-8"), hashlib.sha256(body).digest()])
    return hmac.new(secret.encode("utf-8"), msg, hashlib.sha256).hexdigest()


def upload_state(payload: Mapping[str, Any]) -> dict[str, Any]:
    """What an upload holds, as the worker and the server compare it: answered trials, status, questionnaire."""
    parts = payload.get("participants") or [{}]
    return {"trials": len(payload.get("trials", [])), "status": parts[0].get("status"),
            "questionnaire": len(payload.get("questionnaire", []))}


@dataclass
class _ReadOnly:
    """What :func:`~studyapp.study.bundle.results_payload` reads: a connection and the design hash."""

    connection: sqlite3.Connection
    design_hash: str


def snapshot(con: sqlite3.Connection, design_hash: str, study: str, participant: str) -> dict[str, Any]:
    """The participant's results file so far; plays only of answered trials (a clip being watched is not an
    answer yet, and its play has no end)."""
    from studyapp.study.bundle import results_payload

    payload = results_payload(_ReadOnly(con, design_hash), participant, study)
    answered = {t["trial_index"] for t in payload["trials"]}
    payload["plays"] = [p for p in payload["plays"] if p["trial_index"] in answered]
    return payload


class AckFile:
    """``<results>.uploaded.json``: per participant, the state the server acknowledged (or its refusal)."""

    def __init__(self, results: Path) -> None:
        self.path = Path(results).with_name(Path(results).name + ".uploaded.json")

    def read(self) -> dict[str, Any]:
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return {}   # none yet, or torn by a crash: everything is sent again and the server ignores repeats
        return data if isinstance(data, dict) else {}

    def get(self, participant: str) -> dict[str, Any]:
        entry = self.read().get(participant)
        return entry if isinstance(entry, dict) else {}

    def put(self, participant: str, entry: dict[str, Any]) -> None:
        data = self.read()
        data[participant] = entry
        tmp = self.path.with_name(self.path.name + ".part")
        with open(tmp, "w", encoding="utf-8") as fh:
            json.dump(data, fh, indent=1, sort_keys=True)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path)


@dataclass(frozen=True)
class Outcome:
    """How the uploads ended: everything committed locally reached the server, or not (and why not)."""

    all_sent: bool
    refused: str | None = None
    #: still trying (the last try reached the server): the final screen says it is sending
    sending: bool = False


class Uploader(threading.Thread):
    """The background worker of one participant's uploads (see the module docstring); ``finish`` ends it."""

    def __init__(self, results: Path, bundle_hash: str, study: str, participant: str, url: str, secret: str) -> None:
        super().__init__(name="studyapp-upload", daemon=True)
        self.results, self.bundle_hash, self.study, self.participant = Path(results), bundle_hash, study, participant
        self.url, self.secret = url.rstrip("/") + UPLOAD_PATH, secret
        self.acks = AckFile(self.results)
        self._stopping = threading.Event()
        self._wake = threading.Event()
        self._lock = threading.Lock()
        self._current: dict[str, Any] | None = None
        self._failing = False
        earlier = self.acks.get(participant)
        self._acked = earlier.get("acknowledged") or {}
        #: the message and the state of the last refusal: that state is not sent again, a newer one is
        self._refused: tuple[str, dict[str, Any]] | None = (
            (earlier["refused"], earlier.get("refused_state")) if isinstance(earlier.get("refused"), str) else None)

    def run(self) -> None:
        con = sqlite3.connect(f"file:{self.results}?mode=ro", uri=True, timeout=5.0, isolation_level=None)
        con.row_factory = sqlite3.Row
        version, wait, give_up = None, RETRY_S, 0.0
        try:
            while True:
                try:
                    seen = con.execute("PRAGMA data_version").fetchone()[0]
                    if seen != version:   # something was committed since the last look (or this is the first)
                        self._send_if_new(con)
                        version, wait = seen, RETRY_S
                except (OSError, urllib.error.URLError, ValueError, TimeoutError, sqlite3.Error):
                    # unreachable, busy, a torn reply, the local database busy: nothing is lost (the local
                    # database keeps everything); try again, and at the session's end for END_GRACE_S more
                    self._failing = True
                    if self._stopping.is_set():
                        give_up = give_up or time.monotonic() + END_GRACE_S
                        if time.monotonic() >= give_up:
                            return
                        time.sleep(1.0)
                        continue
                    self._stopping.wait(wait)
                    wait = min(wait * 2, RETRY_MAX_S)
                    continue
                if self._stopping.is_set():
                    return
                self._wake.wait(POLL_S)
                self._wake.clear()
        finally:
            con.close()

    def _up_to_date(self) -> bool:
        with self._lock:
            return self._current is not None and self._current == self._acked

    def _send_if_new(self, con: sqlite3.Connection) -> None:
        con.execute("BEGIN")   # one consistent read of every table
        try:
            if con.execute("SELECT 1 FROM participants WHERE id = ?", (self.participant,)).fetchone() is None:
                payload = None
            else:
                payload = snapshot(con, self.bundle_hash, self.study, self.participant)
        finally:
            con.execute("COMMIT")
        state = None if payload is None else upload_state(payload)
        if state is None or state["trials"] == 0 and state["status"] == "active":
            state = self._acked   # no answer yet: nothing to send
        with self._lock:
            self._current = state
        if state == self._acked or (self._refused is not None and state == self._refused[1]):
            return
        body = json.dumps({"payload": payload}, sort_keys=True, default=str).encode("utf-8")
        req = urllib.request.Request(self.url, data=body, method="POST", headers={
            "content-type": "application/json", HEADER_BUNDLE: self.bundle_hash, HEADER_PARTICIPANT: self.participant,
            HEADER_SIGNATURE: signature(self.secret, self.bundle_hash, self.participant, body)})
        try:
            with urllib.request.urlopen(req, timeout=REQUEST_TIMEOUT_S) as reply:
                json.loads(reply.read(64 * 1024))
        except urllib.error.HTTPError as exc:
            if exc.code not in (400, 401, 403, 409, 413, 422):
                raise   # 429, 5xx: try again later
            try:
                message = str(json.loads(exc.read(64 * 1024)).get("error", ""))[:500]
            except (ValueError, AttributeError, OSError):
                message = ""
            # Not sent again as it is; a later commit is (the session writes a trial and then the participant's
            # status in two transactions, and the checks may refuse what lies between)
            self._refused = (message or f"HTTP {exc.code}", state)
            self.acks.put(self.participant, {"acknowledged": self._acked, "refused": self._refused[0],
                                             "refused_state": state})
            return
        with self._lock:
            self._acked, self._refused, self._failing = state, None, False
        self.acks.put(self.participant, {"acknowledged": state})

    def finish(self, wait_s: float = 15.0) -> Outcome:
        """Stop after everything committed so far was sent (waiting at most ``wait_s``); how it went."""
        self._stopping.set()
        self._wake.set()
        self.join(wait_s)
        now = self.outcome()
        return Outcome(now.all_sent, now.refused)   # the worker stops with the program: no longer sending

    def outcome(self) -> Outcome:
        """How the uploads stand now, without waiting (the final screen asks every frame)."""
        with self._lock:
            current, acked, refused = self._current, self._acked, self._refused
        if current is not None and current == acked:
            return Outcome(True)
        refused_now = refused[0] if refused and refused[1] == current else None
        return Outcome(False, refused_now, sending=refused_now is None and not self._failing and self.is_alive())


def final_message(outcome: Outcome) -> str:
    """What the participant reads at the end of a session with uploads."""
    if outcome.all_sent:
        return "All your answers reached the study server."
    if outcome.sending:
        return "Sending your answers to the study server..."
    if outcome.refused:
        return (f"The study server did not accept your answers ({outcome.refused}). Your answers are saved on this "
                "computer: please send your results file to the experimenter.")
    return ("Not all your answers reached the study server (no connection). They are saved on this computer: run "
            "the study again later to send them, or send your results file to the experimenter.")
