"""``studyapp serve``: the browser study server (:mod:`studyapp.web`) for online participants.

``--workers N`` runs N server processes on one port (uvicorn's workers): the parent checks the design, renders
the missing videos and makes the secret, then each worker builds the same app (:func:`worker_app`, from the
settings the parent leaves in :data:`WORKER_ENV`) on its own database connection. The participant flow keeps
nothing in a process's memory (:mod:`studyapp.web.flow`), so any worker serves any request; several workers
need PostgreSQL, since an SQLite file is written by one server process.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any

from studyapp.cli.render import _size
from studyapp.errors import InputError

PASSWORD_ENV = "STUDYAPP_SERVE_PASSWORD"
#: Where ``--workers`` leaves the server's settings for its worker processes (JSON; no password, only its file).
WORKER_ENV = "STUDYAPP_SERVE_WORKER"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve",
        help="serve a study to participants in their web browser (online studies, Prolific)",
        description="Serve a study design to browser participants: consent, instructions, a sound check, "
        "practice, the trials as pre-rendered videos, the answers (ranking, preferences, ratings), attention "
        "checks, the questionnaire and the "
        "completion code or redirect. Answers go to the same results database as `studyapp run` (every answer "
        "committed before the next clip). Put it behind an HTTPS reverse proxy (README, 'Online studies').",
    )
    p.add_argument("design", type=Path, help="study design (.toml)")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: behind a reverse "
                   "proxy on the same machine)")
    p.add_argument("--port", type=int, default=8000, help="port to listen on (default 8000)")
    p.add_argument("--db", help="results database: a file path or sqlite:///PATH, or postgresql://USER@HOST/DB "
                   "(default: <design>.results.sqlite next to the design, shared with `studyapp run`)")
    p.add_argument("--cache", type=Path, help="folder of the pre-rendered trial videos, as for `studyapp prerender` "
                   "(default: 'prerendered' next to the design); videos missing there are rendered before the "
                   "server starts listening")
    p.add_argument("--size", type=_size, default=(1280, 720), help="video size, WxH, as given to `studyapp "
                   "prerender` (default 1280x720)")
    p.add_argument("--fps", type=int, default=30, help="video frame rate, as given to `studyapp prerender` (default 30)")
    p.add_argument("--jobs", type=int, default=1, help="processes rendering missing videos (default 1)")
    p.add_argument("--secret-file", type=Path, help="the server's secret, which signs participant links (made on "
                   "first start; default: <design>.serve-secret next to the design)")
    p.add_argument("--workers", type=int, default=1, help="server processes sharing the port (default 1); more "
                   "than one needs a PostgreSQL --db (README, 'Several server processes')")
    p.add_argument("--password-file", type=Path, help="file whose first line is the experimenter dashboard's "
                   f"password (or set {PASSWORD_ENV}); without either, /dashboard is off")
    p.set_defaults(func=_cmd_serve)


def dashboard_password(password_file: Path | None) -> str | None:
    """The dashboard password: the file's first line, else the environment variable, else None (off)."""
    if password_file is not None:
        try:
            lines = password_file.read_text(encoding="utf-8").splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(password_file, None, f"cannot read the password file ({exc})") from None
        if not lines or len(lines[0].strip()) < 8:
            raise InputError(password_file, "line 1", "the dashboard password must be at least 8 characters")
        return lines[0].strip()
    value = os.environ.get(PASSWORD_ENV, "").strip()
    if value and len(value) < 8:
        raise InputError(None, PASSWORD_ENV, "the dashboard password must be at least 8 characters")
    return value or None


def results_url(design_path: Path, db_url: str | None) -> str:
    """``--db``, else ``<design>.results.sqlite`` next to the design (the database ``studyapp run`` uses)."""
    from studyapp.cli.session import default_results_path

    return db_url or str(default_results_path(design_path))


def load_for_serve(design_path: Path, db_url: str | None) -> tuple[Any, str]:
    """The design (checked as for ``studyapp run``) and the database URL the server uses."""
    from studyapp.cli.session import load_design_for_run
    from studyapp.web.database import sqlite_path

    url = results_url(design_path, db_url)
    if url.startswith(("postgresql://", "postgres://")):
        from studyapp.study.design import load_design

        return load_design(design_path, reuse_check=True), url   # the database compares the design hash
    return load_design_for_run(design_path, Path(sqlite_path(url))), url


def default_cache(design_path: Path) -> Path:
    """Where ``studyapp prerender`` puts a design's videos by default."""
    return design_path.resolve().parent / "prerendered"


def secret_path(design_path: Path, secret_file: Path | None) -> Path:
    """``--secret-file``, else ``<design>.serve-secret`` next to the design."""
    return secret_file or design_path.with_name(f"{design_path.stem}.serve-secret")


def check_workers(workers: int, url: str) -> None:
    """``--workers``: at least 1, and more than 1 only on PostgreSQL (one line otherwise)."""
    if workers < 1:
        raise InputError(None, "--workers", "must be at least 1")
    if workers > 1 and not url.startswith(("postgresql://", "postgres://")):
        raise InputError(None, "--workers", f"{workers} server processes need a PostgreSQL database (--db "
                         "postgresql://USER@HOST/DB); an SQLite file is served by one process: drop --workers")


def worker_app() -> Any:
    """The app of one ``--workers`` process, from the settings in :data:`WORKER_ENV` (uvicorn's app factory)."""
    from studyapp.study.prerender import RenderSettings

    cfg = json.loads(os.environ[WORKER_ENV])
    design_path = Path(cfg["design"])
    design, url = load_for_serve(design_path, cfg["db"])
    password = dashboard_password(Path(cfg["password_file"]) if cfg["password_file"] else None)
    settings = RenderSettings(size=tuple(cfg["size"]), fps=int(cfg["fps"]))
    return make_app(design_path, url, Path(cfg["cache"]), Path(cfg["secret_file"]), password, design=design,
                    settings=settings)


def make_app(design_path: Path, db_url: str | None, cache_dir: Path | None, secret_file: Path | None,
             password: str | None, videos: Any = None, *, design: Any = None, settings: Any = None) -> Any:
    """The server's ASGI app for a design. ``videos``: a :class:`~studyapp.web.media.TrialVideos` to use
    instead of the pre-rendered ones (tests); ``design``: the design already loaded by :func:`load_for_serve`;
    ``settings``: the :class:`~studyapp.study.prerender.RenderSettings` the videos were rendered with."""
    from studyapp.web.app import build_app
    from studyapp.web.database import open_results
    from studyapp.web.flow import Flow
    from studyapp.web.media import PrerenderedVideos
    from studyapp.web.tokens import Tokens, load_or_create_secret

    if design is None:
        loaded, url = load_for_serve(design_path, db_url)
    else:
        loaded, url = design, results_url(design_path, db_url)
    tokens = Tokens(load_or_create_secret(secret_path(design_path, secret_file)))
    source = videos or PrerenderedVideos(loaded, cache_dir or default_cache(design_path), settings)

    def open_flow() -> Flow:
        return Flow(loaded, open_results(url, loaded), tokens, source)

    return build_app(open_flow, password=password)


def _cmd_serve(args: argparse.Namespace) -> int:
    from studyapp.cli.extras import require

    # the server's extra: the framework and its server, av to pre-render, pandas for the dashboard's export
    require("serve", "starlette", "uvicorn", "av", "pandas", extra="server")
    import uvicorn

    from studyapp.cli.prerender import ProgressBar
    from studyapp.study.prerender import RenderSettings, prerender

    if args.fps < 1 or args.jobs < 1:
        raise InputError(None, "--fps/--jobs", "must be at least 1")
    check_workers(args.workers, results_url(args.design, args.db))
    password = dashboard_password(args.password_file)
    design, url = load_for_serve(args.design, args.db)
    settings = RenderSettings(size=args.size, fps=args.fps)
    cache = args.cache or default_cache(args.design)
    report = prerender(design, cache, progress=ProgressBar(), jobs=args.jobs, settings=settings)
    print(f"{report.total} trial videos in {cache} ({report.rendered} rendered now)", flush=True)
    if args.workers > 1:
        from studyapp.web.tokens import load_or_create_secret

        secret = secret_path(args.design, args.secret_file)
        load_or_create_secret(secret)   # made here once: the workers only read it
        os.environ[WORKER_ENV] = json.dumps({
            "design": str(args.design.resolve()), "db": url, "cache": str(Path(cache).resolve()),
            "secret_file": str(secret.resolve()), "size": list(args.size), "fps": args.fps,
            "password_file": str(args.password_file.resolve()) if args.password_file else None})
        app: Any = "studyapp.cli.serve:worker_app"
    else:
        app = make_app(args.design, url, cache, args.secret_file, password, design=design, settings=settings)
    if password is None:
        print(f"note: the experimenter dashboard is off (give --password-file or set {PASSWORD_ENV})", file=sys.stderr)
    workers = f" with {args.workers} server processes" if args.workers > 1 else ""
    print(f"Serving {args.design} at http://{args.host}:{args.port}/{workers} (participants: /?PROLIFIC_PID=...; "
          f"dashboard: /dashboard). Stop with Ctrl+C.", flush=True)
    # proxy_headers: behind a reverse proxy on this machine the client's address (rate limits) and the scheme
    # (secure cookies) come from its X-Forwarded-* headers; from anyone else they are ignored.
    uvicorn.run(app, host=args.host, port=args.port, proxy_headers=True, forwarded_allow_ips="127.0.0.1",
                server_header=False, log_level="info", factory=args.workers > 1,
                workers=args.workers if args.workers > 1 else None)
    return 0
