"""The server's secret and the opaque tokens derived from it: session, media, play and CSRF tokens.

Every token is an HMAC-SHA256 of a purpose and the participant id (and a trial index for media) under the
server's secret, cut to 128 bits and written URL-safe. So tokens are unguessable without the secret, differ
for every participant and trial (two participants seeing the same video get unrelated URLs: nothing groups a
condition), and survive a server restart with no table of their own: after a restart a session token is found
again by recomputing the token of each stored participant (:meth:`Tokens.participant_for`).

The secret is 32 random bytes (:mod:`secrets`) kept in a file readable by its owner only, created on first
use; deleting it invalidates every link handed out before.

>>> t = Tokens(b"k" * 32)
>>> t.session("P01") == t.session("P01") != t.session("P02")
True
>>> len(t.session("P01")), t.media("P01", 3) != t.media("P01", 4)
(22, True)
>>> t.participant_for(t.session("P02"), ["P01", "P02"])
'P02'
>>> ticket = t.play("P01", 7, 1700000000.25)
>>> t.play_started("P01", 7, ticket), t.play_started("P01", 8, ticket), t.play_started("P02", 7, ticket)
(1700000000.25, None, None)
"""
from __future__ import annotations

import base64
import hashlib
import hmac
import os
import secrets
from pathlib import Path
from typing import Iterable

from studyapp.errors import InputError

SECRET_BYTES = 32
#: A token as it appears in a URL: 22 URL-safe base64 characters (128 bits).
TOKEN_CHARS = 22


def load_or_create_secret(path: Path) -> bytes:
    """The secret stored in ``path``, created (owner-only, 0600) when the file does not exist."""
    path = Path(path)
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as fh:
            fh.write(secrets.token_bytes(SECRET_BYTES))
            fh.flush()
            os.fsync(fh.fileno())
    data = path.read_bytes()
    if len(data) != SECRET_BYTES:
        raise InputError(path, None, f"the server's secret must be {SECRET_BYTES} bytes, this file has {len(data)}; "
                         "delete it to make a new one (links handed out before stop working)")
    return data


class Tokens:
    """Tokens of one server secret (see the module docstring)."""

    def __init__(self, secret: bytes) -> None:
        self._secret = bytes(secret)
        self._known: dict[str, str] = {}
        # a participant's session and CSRF tokens, made once (every page and action of theirs needs both)
        self._session_of: dict[str, str] = {}
        self._csrf_of: dict[str, str] = {}

    def _mac(self, *parts: object) -> str:
        msg = "\0".join(str(p) for p in parts).encode("utf-8")
        digest = hmac.new(self._secret, msg, hashlib.sha256).digest()[:16]
        return base64.urlsafe_b64encode(digest).decode("ascii").rstrip("=")

    def session(self, participant: str) -> str:
        """The participant's session token (their pages live under ``/s/<token>/``)."""
        tok = self._session_of.get(participant)
        if tok is None:
            tok = self._session_of[participant] = self._mac("session", participant)
            self._known[tok] = participant
        return tok

    def media(self, participant: str, trial_index: int) -> str:
        """The name of one trial's video for one participant."""
        return self._mac("media", participant, int(trial_index))

    def csrf(self, participant: str) -> str:
        """The token every state-changing request of this participant must carry."""
        tok = self._csrf_of.get(participant)
        if tok is None:
            tok = self._csrf_of[participant] = self._mac("csrf", participant)
        return tok

    def play(self, participant: str, play_id: int, started: float) -> str:
        """The ticket of one play, ``<play id>.<start time in ms>.<mac>``: the page sends it back when the clip
        ends, so whichever server process gets that request knows when the play started (by the server's clock)
        without keeping anything in memory."""
        ms = int(round(float(started) * 1000))
        return f"{int(play_id)}.{ms}.{self._mac('play', participant, int(play_id), ms)}"

    def play_started(self, participant: str, play_id: int, ticket: object) -> float | None:
        """The start time (seconds) in a ticket of this participant's play ``play_id``; None when the ticket is
        not one (malformed, forged, another play's or another participant's)."""
        if not isinstance(ticket, str) or len(ticket) > 80 or ticket.count(".") != 2:
            return None
        pid_text, ms_text, mac = ticket.split(".")
        if not (pid_text.isdigit() and ms_text.isdigit()) or int(pid_text) != int(play_id):
            return None
        if not hmac.compare_digest(mac, self._mac("play", participant, int(play_id), int(ms_text))):
            return None
        return int(ms_text) / 1000.0

    def entry_csrf(self, nonce: str) -> str:
        """The CSRF token of the consent page, bound to a random ``nonce`` the page carries too."""
        return self._mac("entry", nonce)

    def dashboard(self, nonce: str) -> str:
        """The experimenter's login cookie value for a random ``nonce``: ``nonce.mac``."""
        return f"{nonce}.{self._mac('dashboard', nonce)}"

    def dashboard_valid(self, cookie: str | None) -> bool:
        if not cookie or "." not in cookie:
            return False
        nonce = cookie.split(".", 1)[0]
        return hmac.compare_digest(cookie, self.dashboard(nonce))

    def participant_for(self, token: str, participants: Iterable[str]) -> str | None:
        """The participant whose session token is ``token`` (searched in ``participants`` once, then cached)."""
        if token in self._known:
            return self._known[token]
        for pid in participants:
            if hmac.compare_digest(self.session(pid), token):
                return pid
        return None


def same(a: str | None, b: str) -> bool:
    """Constant-time comparison of a token received with the one expected (None never matches)."""
    return a is not None and hmac.compare_digest(a.encode("utf-8", "replace"), b.encode("utf-8"))
