"""The experimenter's dashboard: progress per Latin-square row, completions, attention-check failures, median
durations, and the results as CSV (the same table as ``studyapp export``).

Behind a password (``studyapp serve --password-file FILE`` or the ``STUDYAPP_SERVE_PASSWORD`` environment
variable; without one the dashboard is off and every ``/dashboard`` address answers 404). Logging in sets an
HttpOnly, SameSite=Strict cookie signed with the server's secret; logins are rate-limited per client.

How participants are counted (:func:`summarize`): ``done`` completed; ``active`` still going; of the
``ended_early`` ones, ``declined`` did not consent, ``abandoned`` were left unfinished past the design's
``[online] abandon_after_min`` (see :mod:`studyapp.web.flow`), and ``attention`` are the rest (ended by
failed attention checks).
"""
from __future__ import annotations

import secrets
import statistics
from typing import TYPE_CHECKING, Any, Awaitable, Callable

import anyio.to_thread
from starlette.requests import Request
from starlette.responses import HTMLResponse, JSONResponse, Response

from studyapp.study.storage import ABANDONED, ResultsDB
from studyapp.web.security import BadRequest, RateLimiter
from studyapp.web.tokens import same

if TYPE_CHECKING:
    from studyapp.web.dbthread import DatabaseThread
    from studyapp.web.flow import Flow

COOKIE = "studyapp_dashboard"
KINDS = ("done", "active", "attention", "abandoned", "declined")


def _kind(status: str, machines: list[dict[str, Any]]) -> str:
    if status in ("done", "active"):
        return status
    if any(m.get("consent") == "declined" for m in machines):
        return "declined"
    if any(ABANDONED in m for m in machines):
        return "abandoned"
    return "attention"


def summarize(db: ResultsDB, n_rows: int) -> dict[str, Any]:
    """The dashboard's figures (see the module docstring for the categories)."""
    from datetime import datetime

    rows = [{"row": r, **{k: 0 for k in KINDS}} for r in range(n_rows)]
    minutes, failed_checks, kinds = [], 0, {k: 0 for k in KINDS}
    for rec in db.participants():
        kind = _kind(rec.status, [s["machine"] for s in db.sessions(rec.id)])
        kinds[kind] += 1
        if 0 <= rec.latin_row < n_rows:
            rows[rec.latin_row][kind] += 1
        failed_checks += db.attention_failures(rec.id)
        if kind == "done" and rec.completed and rec.created:
            span = datetime.fromisoformat(rec.completed) - datetime.fromisoformat(rec.created)
            minutes.append(span.total_seconds() / 60.0)
    answer_s = [t["response_time_s"] for t in db.trials() if t["response_time_s"] is not None]
    return {"rows": rows, "totals": kinds, "participants": sum(kinds.values()),
            "failed_attention_checks": failed_checks,
            "median_minutes_to_complete": round(statistics.median(minutes), 2) if minutes else None,
            "median_seconds_per_trial": round(statistics.median(answer_s), 2) if answer_s else None}


class Dashboard:
    """The ``/dashboard`` pages of one server (``password`` None: off)."""

    def __init__(self, flow: "Flow", password: str | None, db_thread: "DatabaseThread") -> None:
        self.flow = flow
        self.password = password
        self.db_thread = db_thread

    def _logged_in(self, request: Request) -> bool:
        return self.flow.tokens.dashboard_valid(request.cookies.get(COOKIE))

    def _page(self, state: dict[str, Any]) -> HTMLResponse:
        from studyapp.web.app import page

        return HTMLResponse(page(f"Dashboard: {self.flow.design.title}", "en", state, script="dashboard.js"))

    async def handle(self, request: Request, rest: str, login_limit: RateLimiter,
                     body_of: Callable[[Request], Awaitable[dict[str, Any]]]) -> Response:
        if not self.password:
            return Response(status_code=404)
        if rest == "login" and request.method == "POST":
            if not login_limit.allow(request.client.host if request.client else "?"):
                return JSONResponse({"error": "too many attempts; wait a minute"}, status_code=429)
            try:
                body = await body_of(request)
            except BadRequest as exc:
                return JSONResponse({"error": str(exc)}, status_code=400)
            given = body.get("password")
            if not isinstance(given, str) or not same(given, self.password):
                return JSONResponse({"error": "wrong password"}, status_code=403)
            resp = JSONResponse({"go": "/dashboard"})
            resp.set_cookie(COOKIE, self.flow.tokens.dashboard(secrets.token_urlsafe(16)), httponly=True,
                            samesite="strict", secure=request.url.scheme == "https", path="/dashboard",
                            max_age=12 * 3600)
            return resp
        if request.method == "GET" and rest == "":
            if not self._logged_in(request):
                return self._page({"screen": "login", "title": self.flow.design.title})
            return self._page({"screen": "dashboard", "title": self.flow.design.title,
                               **await self.db_thread.run(self._figures)})
        if not self._logged_in(request):
            return Response(status_code=401)
        if rest == "logout" and request.method == "POST":
            try:
                await body_of(request)
            except BadRequest as exc:
                return JSONResponse({"error": str(exc)}, status_code=400)
            resp = JSONResponse({"go": "/dashboard"})
            resp.delete_cookie(COOKIE, path="/dashboard")
            return resp
        if rest == "export.csv" and request.method == "GET":
            # in a thread of its own, on a connection of its own: participants are served meanwhile
            csv = await anyio.to_thread.run_sync(export_csv, self.flow.db)
            return Response(csv, media_type="text/csv; charset=utf-8",
                            headers={"content-disposition": 'attachment; filename="results.csv"'})
        return Response(status_code=404)

    def _figures(self) -> dict[str, Any]:
        """The dashboard's figures, after looking for abandoned participants (on the database thread)."""
        self.flow.sweep(force=True)
        return summarize(self.flow.db, self.flow.n_rows())


def export_csv(db: ResultsDB) -> str:
    """The results as CSV (``studyapp export``'s table), read on a second connection to ``db``
    (:meth:`~studyapp.study.storage.ResultsDB.twin`): a long export in another thread leaves ``db``'s own
    connection, and so every participant's request, free."""
    from studyapp.study.export import export_dataframe

    reader = db.twin()
    try:
        return export_dataframe(reader).to_csv(index=False)
    finally:
        reader.close()
