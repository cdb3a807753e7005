"""Load on the study server: many browser participants at once over loopback, on SQLite and on PostgreSQL.

``studyapp serve``'s app (the same :func:`studyapp.web.app.build_app`, :class:`~studyapp.web.flow.Flow` and
results database as the command) runs in its own process under uvicorn; ``--participants`` simulated
participants (200 by default) start together from one asyncio process, each with its own connection and
cookies and its own client address (``X-Forwarded-For``, as behind the README's reverse proxy, so each gets the
server's per-client rate limits), and each walks the whole flow: the study link with Prolific's parameters,
consent, instructions, the sound check, then every trial (the video, play, the clip's length in real time,
ended, the answer) to the completion page. The answer's round trip is the answer-commit latency: the server
replies only after the answer is committed (WAL + fsync on SQLite; ``synchronous_commit = on`` on
PostgreSQL, a throw-away server with fsync on, reached over TCP on 127.0.0.1).

Afterwards the database itself is read: every participant done, every answer the server acknowledged stored
exactly once (trial indices 0..n-1 each once, 3 ranks per criterion), no row without its checksum. Figures:
p50/p99 answer-commit latency, answers per second, lost and duplicated answers, with the load average.

The trial videos are stand-ins (one small H.264 clip per trial, tests/fixtures/web_study.py): this measures the
server and its database, not video encoding (``studyapp prerender`` has its own benchmark).

``--workers N`` (PostgreSQL only) runs N server processes on N ports and sends each participant's consecutive
requests to them in turn, as a reverse proxy spreading requests over several ``studyapp serve`` processes would:
any process serves any request, since none keeps a participant's session in memory.

Usage: ``python benchmarks/bench_serve_load.py [--participants N] [--stimuli K] [--backends sqlite,postgresql]
[--workers N]``
"""
from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the synthetic study, stand-in videos and PostgreSQL server are fixtures
sys.path.insert(0, str(Path(__file__).resolve().parent))

from figures import load_average, record  # noqa: E402

CLIP_S = 1.0
#: A kept-alive connection is dropped by the client after 3 s idle, before uvicorn's 5 s: otherwise a request
#: sent as the server closes the idle connection fails (a browser would send it again; httpx does not).
KEEPALIVE = __import__("httpx").Limits(keepalive_expiry=3.0)
COMPLETION = "BENCH123"


def write_design(folder: Path, n_stimuli: int) -> Path:
    from fixtures.synthetic import write_synthetic_study

    path = write_synthetic_study(folder, n_stimuli=n_stimuli, seconds=CLIP_S, practice=True, name="load")
    path.write_text(path.read_text() + f'\n[online]\nabandon_after_min = 120\ncompletion_code = "{COMPLETION}"\n')
    return path


# ------------------------------------------------------------------ the server process
def serve(design_path: Path, db: str, port: int, videos: Path, commits_out: Path) -> None:
    """Run the study server on ``port`` until SIGINT (what ``studyapp serve`` runs, with stand-in videos);
    then write how long each answer took inside the server from ``ResultsDB.save_trial`` until the COMMIT that
    made it durable (its own, or its group's: :meth:`ResultsDB.batch`) to ``commits_out``, so the figures split
    the commit from the queueing in front of it."""
    import uvicorn

    from fixtures.web_study import ClipVideos
    from studyapp.cli.serve import make_app
    from studyapp.study.storage import ResultsDB

    commits: list[float] = []
    pending: list[float] = []   # answers given to the database, not yet durable
    save_trial, tx_exit = ResultsDB.save_trial, ResultsDB._Tx.__exit__

    def timed(self: ResultsDB, *args: Any, **kw: Any) -> None:
        pending.append(time.perf_counter())
        save_trial(self, *args, **kw)

    def durable(self: Any, *exc: Any) -> None:
        # a COMMIT (not a savepoint of a group commit): the answers given since are on disk now
        tx_exit(self, *exc)
        if getattr(self, "nested", None) is None and exc[0] is None:
            now = time.perf_counter()
            commits.extend(now - t0 for t0 in pending)
            pending.clear()

    ResultsDB.save_trial = timed  # type: ignore[method-assign]
    ResultsDB._Tx.__exit__ = durable  # type: ignore[method-assign]
    app = make_app(design_path, db, None, design_path.with_name("serve-secret"), None,
                   videos=ClipVideos(videos, seconds=CLIP_S))
    profile_to = os.environ.get("STUDYAPP_BENCH_PROFILE")  # a file: where the server's time goes (cProfile)
    profiler = None
    if profile_to:
        import cProfile

        profiler = cProfile.Profile()
        profiler.enable()
        try:   # the database thread too (cProfile sees one thread)
            from studyapp.web.dbthread import DatabaseThread
        except ImportError:
            pass
        else:
            loop = DatabaseThread._loop

            def profiled(self: Any, *args: Any) -> None:
                p = cProfile.Profile()
                p.enable()
                try:
                    loop(self, *args)
                finally:
                    p.disable()
                    p.dump_stats(f"{profile_to}.dbthread.{threading.current_thread().name}")

            DatabaseThread._loop = profiled  # type: ignore[method-assign]
    try:
        uvicorn.run(app, host="127.0.0.1", port=port, proxy_headers=True, forwarded_allow_ips="127.0.0.1",
                    server_header=False, log_level="warning", backlog=2048)
    except KeyboardInterrupt:  # uvicorn shuts down on SIGINT, then raises it again
        pass
    finally:
        # the server's CPU time (all its threads): what the requests cost, whatever else the machine runs
        commits_out.write_text(json.dumps({"commits": commits, "cpu_s": time.process_time()}))
        if profiler is not None:
            profiler.disable()
            profiler.dump_stats(f"{profile_to}.{Path(db).name[:20]}")


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def start_server(design: Path, db: str, videos: Path, commits_out: Path) -> tuple[subprocess.Popen, str]:
    port = _free_port()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, __file__, "--serve", str(design), db, str(port), str(videos),
                             str(commits_out)], env=env)
    base = f"http://127.0.0.1:{port}"
    import httpx

    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"the server exited ({proc.returncode})")
        try:
            if httpx.get(base + "/a/app.css", timeout=2).status_code == 200:
                return proc, base
        except httpx.HTTPError:
            time.sleep(0.2)
    proc.kill()
    raise RuntimeError("the server did not start within 120 s")


# ------------------------------------------------------------------ the participants
def _state(html: str) -> dict[str, Any]:
    m = re.search(r'<script id="state" type="application/json">(.*?)</script>', html, re.S)
    if not m:
        raise RuntimeError(f"no page state in {html[:200]!r}")
    return json.loads(m.group(1))


class _Turns:
    """URLs on the server processes in turn, starting at participant ``k``'s own (one server: always it)."""

    def __init__(self, bases: list[str], k: int) -> None:
        self.bases, self.k = bases, k

    def __call__(self, path: str) -> str:
        self.k += 1
        return self.bases[self.k % len(self.bases)] + path


async def participant(bases: list[str], k: int, latencies: list[float], acked: dict[str, int]) -> None:
    import httpx

    pid = f"bench{k:04d}"
    headers = {"X-Forwarded-For": f"10.{k // 65536 % 256}.{k // 256 % 256}.{k % 256}"}
    at = _Turns(bases, k)

    class Client:   # every request to the next server process
        def __init__(self, c: httpx.AsyncClient) -> None:
            self.c = c

        async def get(self, path: str, **kw: Any) -> Any:
            return await self.c.get(at(path), **kw)

        async def post(self, path: str, **kw: Any) -> Any:
            return await self.c.post(at(path), **kw)

    async with httpx.AsyncClient(headers=headers, timeout=120, limits=KEEPALIVE) as raw:
        c = Client(raw)
        r = await c.get(f"/?PROLIFIC_PID={pid}&STUDY_ID=load&SESSION_ID=s{k}")
        r.raise_for_status()
        s = _state(r.text)
        r = await c.post("/start", json={"nonce": s["nonce"], "csrf": s["entry_csrf"], "consent": True,
                                         "params": s["params"]})
        r.raise_for_status()
        go = r.json()["go"]
        r = await c.get(go)
        r.raise_for_status()
        state = _state(r.text)

        async def act(name: str, body: dict[str, Any] | None = None) -> dict[str, Any]:
            resp = await c.post(go + name, json=body or {}, headers={"X-CSRF-Token": state.get("csrf", "")})
            if resp.status_code != 200:
                raise RuntimeError(f"{pid} {name}: HTTP {resp.status_code} {resp.text[:200]}")
            state.update(resp.json())
            return state

        await act("continue")
        await act("sound", {"user_agent": "bench", "screen_w": 1920, "screen_h": 1080})
        while state["screen"] == "trial":
            (await c.get(state["video"])).raise_for_status()
            await act("play")
            await asyncio.sleep(CLIP_S)  # the clip plays: the server checks it was watched to its end
            await act("ended", {"play": state.get("play")})   # the ticket the play's reply carried
            ranks = {crit["id"]: {"0": 1, "1": 2, "2": 3} for crit in state["criteria"]}
            t0 = time.perf_counter()
            resp = await c.post(go + "answer", json={"ranks": ranks}, headers={"X-CSRF-Token": state["csrf"]})
            dt = time.perf_counter() - t0
            if resp.status_code != 200:
                raise RuntimeError(f"{pid} answer: HTTP {resp.status_code} {resp.text[:200]}")
            latencies.append(dt)
            acked[pid] = acked.get(pid, 0) + 1  # the server said it is stored
            state.update(resp.json())
        if state["screen"] != "done":
            raise RuntimeError(f"{pid} ended on {state['screen']!r}, not the completion page")


async def crowd(bases: list[str], n: int) -> tuple[list[float], dict[str, int], float, list[str]]:
    latencies: list[float] = []
    acked: dict[str, int] = {}
    t0 = time.perf_counter()
    results = await asyncio.gather(*(participant(bases, k, latencies, acked) for k in range(n)),
                                   return_exceptions=True)
    failures = [f"{type(r).__name__}: {r}" for r in results if isinstance(r, BaseException)]
    return latencies, acked, time.perf_counter() - t0, failures


# ------------------------------------------------------------------ checking the database
def check_database(target: Path | str, design: Any, acked: dict[str, int]) -> tuple[int, int, int]:
    """(lost, duplicated, participants done), read from the database itself (opening it verifies every row's
    checksum)."""
    from studyapp.study.storage import open_results

    db = open_results(target, create=False)
    try:
        n_crit = len(design.criteria)
        lost = dup = done = 0
        for rec in db.participants():
            done += rec.status == "done"
            idx = [t["trial_index"] for t in db.trials(rec.id)]
            ranks = {(r["trial_index"], r["criterion"], r["slot"]) for r in db.responses(rec.id)}
            rank_rows = len(db.responses(rec.id))
            lost += max(0, acked.pop(rec.id, 0) - len(set(idx)))       # acknowledged, not stored
            lost += len(set(idx)) * n_crit * 3 - len(ranks)              # an answer stored without all its ranks
            dup += (len(idx) - len(set(idx))) + (rank_rows - len(ranks))  # the same answer stored twice
            if sorted(set(idx)) != list(range(len(set(idx)))):
                lost += 1  # a gap: an answer missing before a later one
        lost += sum(acked.values())  # acknowledged answers of a participant the database does not know
    finally:
        db.close()
    return lost, dup, done


def _pct(sorted_ms: list[float], q: float) -> float:
    """The q-quantile (nearest rank) of sorted values; NaN for none."""
    if not sorted_ms:
        return float("nan")
    return statistics.median(sorted_ms) if q == 0.5 else sorted_ms[min(len(sorted_ms) - 1,
                                                                        int(round(q * (len(sorted_ms) - 1))))]


def run_backend(name: str, target: Path | str, server_url: str, design_path: Path, videos: Path,
                n: int, workers: int = 1) -> dict[str, Any]:
    from studyapp.study.design import load_design

    design = load_design(design_path, check_files=False)
    outs = [design_path.with_name(f"commits-{name}-{workers}-{j}.json") for j in range(workers)]
    servers = [start_server(design_path, server_url, videos, out) for out in outs]
    load_before = load_average()
    try:
        latencies, acked, wall, failures = asyncio.run(crowd([base for _, base in servers], n))
    finally:
        for proc, _ in servers:
            proc.send_signal(signal.SIGINT)
        for proc, _ in servers:
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
    load_after = load_average()
    lost, dup, done = check_database(target, design, acked)
    ms = sorted(x * 1e3 for x in latencies)
    p50, p99 = _pct(ms, 0.5), _pct(ms, 0.99)
    logs = [json.loads(out.read_text()) for out in outs if out.exists()]
    commits = sorted(x * 1e3 for log in logs for x in log["commits"])
    cpu_s = sum(log["cpu_s"] for log in logs)
    return {"backend": name if workers == 1 else f"{name}x{workers}", "participants": n, "done": done, "answers": len(ms), "p50_ms": p50, "p99_ms": p99,
            "commit_p50_ms": _pct(commits, 0.5), "commit_p99_ms": _pct(commits, 0.99), "commits": len(commits),
            "max_ms": ms[-1] if ms else float("nan"), "server_cpu_s": cpu_s, "answers_per_s": len(ms) / wall, "wall_s": wall,
            "lost": lost, "duplicated": dup, "failures": failures, "load_before": load_before,
            "load_after": load_after}


def main(argv: list[str]) -> int:
    if argv[:1] == ["--serve"]:
        serve(Path(argv[1]), argv[2], int(argv[3]), Path(argv[4]), Path(argv[5]))
        return 0
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--participants", type=int, default=200)
    ap.add_argument("--stimuli", type=int, default=3, help="rotation clips per participant (plus one practice)")
    ap.add_argument("--backends", default="sqlite,postgresql")
    ap.add_argument("--workers", type=int, default=1, help="server processes on PostgreSQL (default 1)")
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-serve-") as tmp:
        folder = Path(tmp)
        design_path = write_design(folder / "study", args.stimuli)
        videos = folder / "videos"
        for name in args.backends.split(","):
            if name == "sqlite":
                target = folder / "load.results.sqlite"
                if args.workers > 1:
                    raise SystemExit("--workers needs PostgreSQL: an SQLite file is served by one process")
                rows.append(run_backend(name, target, str(target), design_path, videos, args.participants))
            elif name == "postgresql":
                from fixtures.postgres import TempPostgres

                pg = TempPostgres(fsync=True, max_connections=50).start()
                try:
                    pg.new_database("load")
                    tcp = pg.url("load", tcp=True)
                    rows.append(run_backend(name, tcp, tcp, design_path, videos, args.participants, args.workers))
                finally:
                    pg.stop()
            else:
                raise SystemExit(f"unknown backend {name!r}: sqlite or postgresql")
    trials = args.stimuli + 1
    print(f"{args.participants} participants at once on loopback, {trials} trials each (clip {CLIP_S:.0f} s watched "
          f"in real time), {args.workers} server process(es); {os.cpu_count()} cores")
    print("answer round trip: the participant's POST until the reply, which the server sends once the answer is "
          "committed; commit: inside the server, from ResultsDB.save_trial until the COMMIT that made it durable; cpu s: "
          "the server processes' CPU time (all threads, start-up included)")
    print(f"{'backend':<11} {'done':>5} {'answers':>8} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8} {'commit p50':>10} "
          f"{'commit p99':>10} {'ans/s':>7} {'wall s':>7} {'cpu s':>6} {'lost':>5} {'dup':>4}  load avg (1 min) before/after")
    ok = True
    for r in rows:
        print(f"{r['backend']:<11} {r['done']:>5} {r['answers']:>8} {r['p50_ms']:>8.1f} {r['p99_ms']:>8.1f} "
              f"{r['max_ms']:>8.1f} {r['commit_p50_ms']:>10.1f} {r['commit_p99_ms']:>10.1f} "
              f"{r['answers_per_s']:>7.1f} {r['wall_s']:>7.1f} {r['server_cpu_s']:>6.1f} {r['lost']:>5} "
              f"{r['duplicated']:>4}  {r['load_before']:.2f} / {r['load_after']:.2f}")
        for f in r["failures"][:5]:
            print(f"  participant failed: {f}")
        ok &= not r["failures"] and r["lost"] == 0 and r["duplicated"] == 0 and r["done"] == args.participants
        extra = dict(participants=r["participants"], answers=r["answers"], lost=r["lost"], duplicated=r["duplicated"],
                     load_average=r["load_after"])
        record(f"serve_{r['backend']}_answer_commit_p50_ms", r["p50_ms"], None, "ms", **extra)
        record(f"serve_{r['backend']}_answer_commit_p99_ms", r["p99_ms"], None, "ms", **extra)
        record(f"serve_{r['backend']}_commit_p50_ms", r["commit_p50_ms"], None, "ms", **extra)
        record(f"serve_{r['backend']}_commit_p99_ms", r["commit_p99_ms"], None, "ms", **extra)
        record(f"serve_{r['backend']}_server_cpu_s", r["server_cpu_s"], None, "s", **extra)
        record(f"serve_{r['backend']}_lost_or_duplicated", r["lost"] + r["duplicated"], None, "answers", **extra)
    print("every acknowledged answer stored exactly once" if ok else "FAILED: see above")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
