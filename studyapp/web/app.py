"""The study server's HTTP side (Starlette): routes, the page shell, the security rules around them.

Routes (nothing else is served: no directory listing, no file by path)::

    GET  /                       the study link: consent page (Prolific parameters in the query), or on to
                                 an unfinished participant's pages, or a refusal
    POST /start                  consent given or declined -> {"go": "/s/<token>/"}
    GET  /s/<token>/             the participant's current page (reload-safe)
    POST /s/<token>/<action>     continue | sound | block | play | ended | answer | questionnaire -> the next page
    GET  /s/<token>/<name>.mp4   the current trial's video (byte ranges), name opaque per participant + trial
    GET  /a/<asset>              the page's script, style sheet and test tone (a fixed list)
    GET  /dashboard ...          the experimenter's pages (:mod:`studyapp.web.dashboard`)
    POST /upload                 a desktop bundle participant's answers so far (:mod:`studyapp.web.uploads`)

Every participant page is one HTML shell with the page's state as JSON (``<script type="application/json">``,
not executed) and ``/a/app.js``, which draws it and posts actions; each action's reply is the next state.
All database work runs on the process's database thread (:mod:`studyapp.web.dbthread`), so the event loop
keeps serving while a commit waits for the disk. On SQLite it is one thread, one request at a time, so two
requests of one participant cannot interleave, and the requests that queue up meanwhile are committed together
(group commit), each one answered only once it is on disk. On PostgreSQL a few threads, each with its own
connection, run requests side by side, and the flow takes a per-participant lock for the same guarantee across
threads and server processes (:mod:`studyapp.web.flow`, "One session, any process"). The dashboard's export
reads on a connection of its own in another thread, so participants are served while it runs.
"""
from __future__ import annotations

import html
import io
import json
import logging
import os
import wave
from contextlib import asynccontextmanager
from importlib import resources
from typing import Any, AsyncIterator, Callable

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, HTMLResponse, JSONResponse, RedirectResponse, Response
from starlette.routing import Route
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from studyapp.errors import InputError
from studyapp.web.dashboard import Dashboard
from studyapp.web.dbthread import PG_THREADS, DatabaseThread
from studyapp.web.flow import Flow, NotSaved, Refused
from studyapp.web.security import SECURITY_HEADERS, BadRequest, RateLimiter, parse_json, same_origin
from studyapp.web.tokens import same
from studyapp.web.uploads import MAX_UPLOAD_BYTES, UploadDesk, UploadRefused

_log = logging.getLogger(__name__)

#: The assets a page may load, by URL name: (file in studyapp/web/assets, media type).
ASSETS = {"app.js": ("app.js", "text/javascript; charset=utf-8"),
          "app.css": ("app.css", "text/css; charset=utf-8"),
          "dashboard.js": ("dashboard.js", "text/javascript; charset=utf-8")}
ACTIONS = ("continue", "sound", "block", "play", "ended", "answer", "questionnaire")


def asset_text(name: str) -> str:
    return resources.files("studyapp.web").joinpath("assets", name).read_text(encoding="utf-8")


def tone_wav() -> bytes:
    """The sound check's beep as a 16-bit WAV file."""
    from studyapp.audio.playback import sound_check_tone

    pcm = sound_check_tone(sample_rate=48000)
    buf = io.BytesIO()
    with wave.open(buf, "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(pcm.sample_rate)
        w.writeframes((pcm.samples[:, 0] * 32767).astype("<i2").tobytes())
    return buf.getvalue()


def page(title: str, lang: str, state: dict[str, Any], script: str = "app.js") -> str:
    """The HTML shell of every page: the state as inert JSON, the script that draws it."""
    data = json.dumps(state, ensure_ascii=False).replace("&", "\\u0026").replace("<", "\\u003c").replace(">", "\\u003e")
    return (f'<!DOCTYPE html>\n<html lang="{html.escape(lang)}"><head><meta charset="utf-8">'
            '<meta name="viewport" content="width=device-width, initial-scale=1">'
            f'<title>{html.escape(title)}</title><link rel="stylesheet" href="/a/app.css"></head>'
            f'<body><main id="app"></main><script id="state" type="application/json">{data}</script>'
            f'<script src="/a/{script}"></script></body></html>')


class SecurityHeaders:
    """Adds :data:`~studyapp.web.security.SECURITY_HEADERS` to every response; ``no-store`` except assets."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        cacheable = scope["path"].startswith("/a/")

        async def send_with_headers(message: Message) -> None:
            if message["type"] == "http.response.start":
                headers = [(k, v) for k, v in message.get("headers", []) if k.lower() not in (b"server",)]
                have = {k.lower() for k, _ in headers}
                for k, v in SECURITY_HEADERS.items():
                    if k.encode() not in have:
                        headers.append((k.encode(), v.encode()))
                if b"cache-control" not in have:
                    headers.append((b"cache-control", b"public, max-age=300" if cacheable else b"no-store"))
                message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_headers)


def build_app(open_flow: Callable[[], Flow], *, password: str | None = None,
              limits: dict[str, RateLimiter] | None = None) -> ASGIApp:
    """The server of one study. ``open_flow`` is called once at start-up, on the process's database thread
    (the database connection is made there); ``password``: the dashboard's (None: the dashboard is off)."""
    state: dict[str, Any] = {}
    lim = {"action": RateLimiter(per_s=10.0, burst=40), "media": RateLimiter(per_s=20.0, burst=80),
           "start": RateLimiter(per_s=1.0, burst=30), "login": RateLimiter(per_s=5 / 60, burst=5),
           "upload": RateLimiter(per_s=5.0, burst=40),
           **(limits or {})}
    tone = tone_wav()

    @asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        db_thread = DatabaseThread()
        try:
            flow = await db_thread.run(open_flow)   # the connection is made on the thread that uses it
        except BaseException:
            db_thread.close()
            raise
        if flow.db.backend == "sqlite":   # one process: group commit (see studyapp.web.dbthread)
            db_thread.group_commit(flow.db)
        else:                             # connections side by side
            db_thread.add_threads(PG_THREADS - 1, flow.use_own_connection, flow.close_own_connection)
        state["db"] = db_thread
        state["flow"] = flow
        state["dashboard"] = Dashboard(flow, password, db_thread)
        state["uploads"] = UploadDesk(flow.design, lambda: flow.db)   # the calling thread's connection
        try:
            yield
        finally:
            db_thread.group_commit(None)
            await db_thread.run(flow.db.close)   # SQLite's on its own thread (the only one there is)
            db_thread.close()                    # the others' connections are closed by their threads

    def in_db(fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` on the database thread (awaitable)."""
        return state["db"].run(fn, *args)

    def flow() -> Flow:
        return state["flow"]

    def client(request: Request) -> str:
        return request.client.host if request.client else "?"

    def too_many() -> JSONResponse:
        return JSONResponse({"error": flow().t("online.busy")}, status_code=429)

    def refusal(exc: Refused, status: int = 403) -> HTMLResponse:
        st = {"screen": "refused", "heading": flow().design.title, "text": flow().t(exc.key)}
        return HTMLResponse(page(flow().design.title, flow().design.language, st), status_code=status)

    def checked_body(request: Request, raw: bytes) -> dict[str, Any]:
        """The JSON body of a state-changing request, after the CSRF-relevant checks every one of them gets."""
        if request.headers.get("content-type", "").split(";")[0].strip() != "application/json":
            raise BadRequest("content type must be application/json")
        if not same_origin(request.headers.get("origin"), request.headers.get("host"), request.url.scheme):
            raise BadRequest("cross-origin request")
        return parse_json(raw)

    async def body_of(request: Request) -> dict[str, Any]:
        return checked_body(request, await request.body())

    async def entry(request: Request) -> Response:
        try:
            st = await in_db(flow().entry, dict(request.query_params))
        except Refused as exc:
            return refusal(exc)
        if "redirect" in st:
            return RedirectResponse(st["redirect"], status_code=303)
        return HTMLResponse(page(flow().design.title, flow().design.language, st))

    async def start(request: Request) -> Response:
        if not lim["start"].allow(client(request)):
            return too_many()
        try:
            token = await in_db(flow().start, await body_of(request))
        except BadRequest as exc:
            return JSONResponse({"error": str(exc)}, status_code=400)
        except Refused as exc:
            return JSONResponse({"refused": flow().t(exc.key)}, status_code=403)
        return JSONResponse({"go": f"/s/{token}/"})

    async def participant_page(request: Request) -> Response:
        def work(token: str) -> dict[str, Any]:
            return flow().state(flow().participant_for(token))

        try:
            st = await in_db(work, request.path_params["token"])
        except Refused as exc:
            return refusal(exc, 404)
        return HTMLResponse(page(flow().design.title, flow().design.language, st))

    async def action(request: Request) -> Response:
        token, name = request.path_params["token"], request.path_params["action"]
        if not lim["action"].allow(token):
            return too_many()
        raw = await request.body()
        csrf = request.headers.get("x-csrf-token")

        def work() -> dict[str, Any]:   # the checks in this order, then the action, in one database job
            pid = flow().participant_for(token)
            if name not in ACTIONS:
                raise BadRequest("unknown action")
            body = checked_body(request, raw)
            if not same(csrf, flow().tokens.csrf(pid)):
                raise BadRequest("missing or wrong CSRF token")
            return flow().act(pid, name, body)

        try:
            return JSONResponse(await in_db(work))
        except Refused as exc:
            return JSONResponse({"refused": flow().t(exc.key)}, status_code=404)
        except BadRequest as exc:
            _log.info("refused a request: %s", exc)
            return JSONResponse({"error": str(exc)}, status_code=400)
        except NotSaved as exc:
            return JSONResponse({"error": flow().t("online.not_saved", problem=str(exc))}, status_code=422)
        except InputError as exc:   # the database could not store it (disk full, ...): nothing was saved
            _log.error("%s", exc)
            return JSONResponse({"error": flow().t("online.not_saved", problem="server error")}, status_code=503)

    async def media(request: Request) -> Response:
        token = request.path_params["token"]
        if not lim["media"].allow(token):
            return too_many()
        name = request.path_params["name"]
        try:
            path = await in_db(lambda: flow().media(flow().participant_for(token), name))
        except Refused:
            return Response(status_code=404)
        # no real modification time, no file name: both could tell two participants' clips apart or alike
        return FileResponse(path, media_type="video/mp4", stat_result=os.stat(path),
                            headers={"etag": f'"{name}"', "last-modified": "Thu, 01 Jan 1970 00:00:00 GMT"})

    async def asset(request: Request) -> Response:
        name = request.path_params["name"]
        if name == "tone.wav":
            return Response(tone, media_type="audio/wav")
        if name not in ASSETS:
            return Response(status_code=404)
        file, kind = ASSETS[name]
        return Response(asset_text(file), media_type=kind)

    async def dashboard(request: Request) -> Response:
        return await state["dashboard"].handle(request, request.path_params.get("rest", ""), lim["login"], body_of)

    async def upload(request: Request) -> Response:
        if not lim["upload"].allow(client(request)):
            return too_many()
        chunks, size = [], 0
        async for chunk in request.stream():
            size += len(chunk)
            if size > MAX_UPLOAD_BYTES:
                return JSONResponse({"error": f"upload over {MAX_UPLOAD_BYTES} bytes"}, status_code=413)
            chunks.append(chunk)
        try:
            return JSONResponse(await in_db(state["uploads"].receive, request.headers, b"".join(chunks)))
        except UploadRefused as exc:
            return JSONResponse({"error": str(exc)}, status_code=exc.status)
        except InputError as exc:   # the database could not store it: nothing was saved, the sender tries again
            _log.error("%s", exc)
            return JSONResponse({"error": "server error"}, status_code=503)

    async def not_found(request: Request) -> Response:
        return Response(status_code=404)

    async def database_problem(request: Request, exc: Exception) -> Response:
        # a read that shared a group commit that failed, or a database gone: one line in the log, 503 to the page
        _log.error("%s", exc)
        return JSONResponse({"error": "server error"}, status_code=503)

    routes = [
        Route("/", entry, methods=["GET"]),
        Route("/start", start, methods=["POST"]),
        Route("/s/{token:str}/", participant_page, methods=["GET"]),
        Route("/s/{token:str}/{name:str}.mp4", media, methods=["GET", "HEAD"]),
        Route("/s/{token:str}/{action:str}", action, methods=["POST"]),
        Route("/a/{name:str}", asset, methods=["GET"]),
        Route("/upload", upload, methods=["POST"]),
        Route("/dashboard", dashboard, methods=["GET", "POST"]),
        Route("/dashboard/{rest:str}", dashboard, methods=["GET", "POST"]),
    ]
    app = Starlette(routes=routes, lifespan=lifespan, exception_handlers={InputError: database_problem})
    return SecurityHeaders(app)
