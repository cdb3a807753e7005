"""``POST /upload``: a desktop bundle participant's answers, received as they are committed (:mod:`studyapp.study.upload`).

A request is one participant's results file so far, in the bundle's blinded ids, signed with the bundle's upload
secret (:func:`studyapp.study.upload.signature`). :meth:`UploadDesk.receive`, in order:

1. finds the bundle's key in the results database by the bundle hash the request names (made with
   ``bundle --results <this database> --upload-url ...``) and checks the signature; an unknown bundle and a wrong
   signature get the same 401, so the reply does not tell which bundles exist;
2. maps the blinded ids back and runs every check of ``merge`` (:func:`studyapp.study.returned.map_ids`,
   :func:`~studyapp.study.returned.check_returned`: roster, schedule, answers, timings, copies), so an upload
   can hold nothing a mailed results zip could not; a file with any problem stores nothing (422);
3. compares it with what is stored for the participant: nothing stored -> stored; the same answers -> nothing
   to do (a repeat, 200); every stored answer kept and more added -> the participant's rows replaced in one
   transaction (:meth:`~studyapp.study.storage.ResultsDB.import_participant`); a different answer for a stored
   trial, or a participant of the same id not uploaded through this bundle -> refused (409).

Stored participants get the groups ``remote = yes``, ``bundle`` (the hash's first 12 digits, as ``merge`` writes
it) and ``upload = yes``, so ``merge`` of the same participant's zip afterwards says "already merged", and the
dashboard and ``export`` see them like any other participant.

Threat model: the secret travels inside the bundle, so anyone holding the bundle can upload as any roster id of
it, as anyone holding it could mail a results zip today; the checks of step 2 are what stands between such a
sender and the data. Without the bundle no upload passes step 1. Replies name no condition: the checks' findings
(which do, after the mapping) go to the server's log only, the sender reads how many problems there were.
"""
from __future__ import annotations

import hmac
import json
import logging
from typing import Any, Callable, Mapping

from studyapp.study.returned import Finding, check_returned, map_ids
from studyapp.study.session import trial_duration_s
from studyapp.study.storage import ResultsDB
from studyapp.study.upload import HEADER_BUNDLE, HEADER_PARTICIPANT, HEADER_SIGNATURE, signature, upload_state

_log = logging.getLogger(__name__)

#: The largest upload read: one participant's results file (a few kilobytes per trial).
MAX_UPLOAD_BYTES = 4 << 20
#: How far a participant got: an upload never takes a finished participant back to unfinished.
_STAGE = {"active": 0, "done": 1, "ended_early": 1}


class UploadRefused(Exception):
    """An upload that is not stored; ``status`` is the HTTP status, the message is for the participant."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status


def _answers(trials: list[dict[str, Any]], responses: list[dict[str, Any]],
             judgements: list[dict[str, Any]]) -> dict[int, tuple[Any, ...]]:
    """Each answered trial's answer as stored (trial index -> clip, answer time, ranks, judgements)."""
    ranks: dict[int, list[tuple[Any, ...]]] = {}
    for r in responses:
        ranks.setdefault(r["trial_index"], []).append((r["criterion"], r["slot"], r["condition"], float(r["rank"])))
    judged: dict[int, list[tuple[Any, ...]]] = {}
    for j in judgements:
        judged.setdefault(j["trial_index"], []).append((j["criterion"], j["slot"], j["condition"], float(j["value"]),
                                                        j["reasons"]))
    return {t["trial_index"]: (t["stimulus"], t["answered_at"], sorted(ranks.get(t["trial_index"], [])),
                               sorted(judged.get(t["trial_index"], []))) for t in trials}


class UploadDesk:
    """The upload endpoint's logic for one study (no HTTP here: :mod:`studyapp.web.app` puts it on the network)."""

    def __init__(self, design: Any, db: ResultsDB | Callable[[], ResultsDB]) -> None:
        """``db``: the results database, or a function giving the one to use now (the calling database
        thread's connection, :attr:`studyapp.web.flow.Flow.db`)."""
        self.design, self._db = design, db
        self._durations: dict[str, float | None] = {}

    @property
    def db(self) -> ResultsDB:
        return self._db() if callable(self._db) else self._db

    def receive(self, headers: Mapping[str, str], body: bytes) -> dict[str, Any]:
        """Check and store one upload; the state the server now holds. Raises :class:`UploadRefused`."""
        bundle, pid = headers.get(HEADER_BUNDLE, ""), headers.get(HEADER_PARTICIPANT, "")
        key = self.db.bundle_key(bundle) if bundle and len(bundle) <= 128 else None
        secret = (key or {}).get("upload_secret")
        if (not isinstance(secret, str) or key.get("design_hash") != self.db.design_hash or not pid
                or not hmac.compare_digest(signature(secret, bundle, pid, body), headers.get(HEADER_SIGNATURE, ""))):
            raise UploadRefused(401, "this study file cannot upload to this server (unknown study file or wrong "
                                     "signature)")
        try:
            payload = json.loads(body.decode("utf-8"))["payload"]
            if not isinstance(payload, dict) or payload.get("design_hash") != bundle or payload.get("participant") != pid:
                raise ValueError("the upload is not this participant's results of this study file")
            parts = payload["participants"]
            if not isinstance(parts, list) or len(parts) != 1 or not isinstance(parts[0], dict) or parts[0].get("id") != pid:
                raise ValueError("the upload holds another participant")
            mapped, findings = map_ids(payload, key.get("conditions", {}), key.get("stimuli", {}), strict=True,
                                       trials=key.get("trials"))
            roster = {str(k): int(v) for k, v in key.get("roster", {}).items()}
            findings += check_returned(mapped, self.design, roster=roster, allow_unlisted=False,
                                       others=self._others(pid), duration_of=self._duration)
        except (ValueError, KeyError, TypeError, AttributeError, IndexError, RecursionError) as exc:
            raise UploadRefused(400, f"not a studyapp upload ({type(exc).__name__})") from None
        if findings:
            self._log_findings(pid, findings)
            n = len(findings)
            raise UploadRefused(422, f"{n} problem{'s' if n != 1 else ''} in the answers (the study's checks refused "
                                     "them; nothing was stored)")
        return self._store(bundle, pid, mapped)

    def _others(self, pid: str) -> dict[str, list[dict[str, Any]]]:
        others: dict[str, list[dict[str, Any]]] = {}
        for t in self.db.trials():
            if t["participant"] != pid:
                others.setdefault(t["participant"], []).append(t)
        return others

    def _duration(self, plan: Any) -> float | None:
        if plan.stimulus_id not in self._durations:
            self._durations[plan.stimulus_id] = trial_duration_s(self.design, plan)
        return self._durations[plan.stimulus_id]

    @staticmethod
    def _log_findings(pid: str, findings: list[Finding]) -> None:
        _log.warning("refused an upload of participant %s: %s", pid, "; ".join(map(str, findings[:20])))

    def _store(self, bundle: str, pid: str, payload: dict[str, Any]) -> dict[str, Any]:
        state = upload_state(payload)
        stored = self.db.participant(pid)
        new = _answers(payload["trials"], payload["responses"], payload.get("judgements", []))
        if stored is not None:
            if stored.groups.get("upload") != "yes" or stored.groups.get("bundle") != bundle[:12]:
                raise UploadRefused(409, f"participant {pid} is already in the study's database, not uploaded with "
                                         "this study file; nothing was stored")
            old = _answers(self.db.trials(pid), self.db.responses(pid), self.db.judgements(pid))
            changed = sorted(i for i in old if i in new and new[i] != old[i])
            if changed:
                raise UploadRefused(409, f"trial {changed[0]} already has a different answer on the server; answers "
                                         "cannot be changed, nothing was stored")
            held = {"trials": len(old), "status": stored.status, "questionnaire": len(self.db.questionnaire(pid))}
            extends = (set(new) >= set(old) and state["questionnaire"] >= held["questionnaire"]
                       and _STAGE.get(state["status"], 0) >= _STAGE.get(held["status"], 0))
            if state == held or not extends:
                return held   # a repeat, or an older upload arriving late: what is stored stays
        p = payload["participants"][0]
        groups = json.loads(p["groups"]) if isinstance(p.get("groups"), str) else {}
        groups.update({"remote": "yes", "bundle": bundle[:12], "upload": "yes"})
        self.db.import_participant({**p, "groups": json.dumps(groups, sort_keys=True)}, payload["sessions"],
                                   payload["trials"], payload["responses"], payload["plays"],
                                   payload["questionnaire"], payload.get("trial_slots", []),
                                   payload.get("judgements", []), replace=stored is not None)
        _log.info("upload of participant %s: %d answered trials, status %s", pid, state["trials"], state["status"])
        return state

