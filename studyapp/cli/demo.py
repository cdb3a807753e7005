"""``studyapp demo``: the built-in demo study, end to end.

With a display it opens the demo study as a participant sees it (participant ``demo``, results in a
temporary database) and, when the participant is done, analyses the results. Without a display (or with
``--offscreen``) it shows what it can without one: a still and a short video of the first trial, the
scripted participant going through the whole study through the real session and UI code, a simulated
panel of further careful viewers so the statistics have something to work on, and the analysis report.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import sqlite3
import sys
import tempfile
from pathlib import Path

from studyapp.resources import demo_design

#: Number of simulated careful viewers added to the demo participant so the report has a panel to analyse.
DEFAULT_PANEL = 12


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="run the built-in demo study (window, or offscreen render + scripted participant + report)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--offscreen", action="store_true", help="never open a window, even with a display")
    p.add_argument("--out", type=Path, default=Path("demo-out"), help="output folder (default: ./demo-out)")
    p.add_argument("--panel", type=int, default=DEFAULT_PANEL,
                   help=f"simulated careful participants added for the analysis (default {DEFAULT_PANEL})")
    p.add_argument("--seed", type=int, default=1, help="seed of the scripted participants")
    p.add_argument("--no-video", action="store_true", help="skip the MP4 of the first trial")
    p.set_defaults(func=_cmd_demo)


def display_available() -> bool:
    """True when a window can plausibly be opened (an X or Wayland display, or a desktop OS)."""
    if sys.platform in ("win32", "darwin"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _cmd_demo(args: argparse.Namespace) -> int:
    from studyapp.cli.extras import require

    design_path = demo_design()
    offscreen = args.offscreen or not display_available()
    # the demo ends with the analysis report (and offscreen, an MP4): an experimenter's extras, checked up front
    require("demo", "pandas", "scipy", "matplotlib", *(("av",) if offscreen and not args.no_video else ()))
    if offscreen:
        if not args.offscreen:
            print("No display found: running the demo offscreen.")
        return run_offscreen_demo(design_path, args.out, panel=args.panel, seed=args.seed, video=not args.no_video)
    return run_window_demo(design_path, args.out)


def run_window_demo(design_path: Path, out: Path) -> int:
    from studyapp.audio.playback import PendingClock
    from studyapp.study.design import load_design
    from studyapp.study.storage import ResultsDB
    from studyapp.ui.app import run_window

    # the audio output opens in its own process while the design loads (as for `studyapp run`)
    audio = PendingClock(os.environ.get("STUDYAPP_AUDIO_DEVICE") or None)
    try:
        design = load_design(design_path, reuse_check=True)  # a session start: see study.design.validated
        tmp = Path(tempfile.mkdtemp(prefix="studyapp-demo-"))
        db = ResultsDB(tmp / "demo.results.sqlite", design)
        code = run_window(design, db, "demo", audio=audio)
        db.close()
    finally:
        audio.close()
    print(f"Demo results database: {tmp / 'demo.results.sqlite'}")
    report = _analyse(tmp / "demo.results.sqlite", out / "analysis", design)
    if report is not None:
        print(f"Analysis of the demo results: {report}")
        try:
            import webbrowser

            webbrowser.open(report.resolve().as_uri())
        except Exception:  # a browser is a convenience, never a failure
            pass
    return code


def run_offscreen_demo(design_path: Path, out: Path, *, panel: int, seed: int, video: bool = True) -> int:
    from studyapp.bots import run_bot
    from studyapp.study.design import load_design
    from studyapp.study.schedule import participant_schedule
    from studyapp.study.storage import ResultsDB

    out.mkdir(parents=True, exist_ok=True)
    design = load_design(design_path)
    db_path = out / "demo.results.sqlite"
    for stale in (db_path, db_path.with_name(db_path.name + "-wal"), db_path.with_name(db_path.name + "-shm")):
        stale.unlink(missing_ok=True)

    # 1. What a participant sees: a still and a short video of the demo participant's first rated trial.
    first = next(p for p in participant_schedule(design, "demo") if not p.is_practice)
    written = _render_first_trial(design, first, out, video=video)

    # 2. The demo participant, through the real session and UI code, with screenshots of each screen.
    db = ResultsDB(db_path, design)
    shots = out / "screens"
    code = run_bot(design, db, "demo", "careful", seed, render=True, out_dir=shots)
    if code != 0:
        print(f"error: the scripted participant stopped with code {code}", file=sys.stderr)
        return code
    # 3. A panel of further careful viewers (session level, no rendering) so the statistics have blocks.
    for i in range(panel):
        run_bot(design, db, f"sim{i + 1:02d}", "careful", seed + 1000 + i, render=False)
    db.close()

    report = _analyse(db_path, out / "analysis", design)
    # The analysis reads the database read-only, which leaves empty -wal/-shm files that only a writer can
    # remove; the demo owns this folder, so one writable open-and-close leaves just the .sqlite.
    con = sqlite3.connect(db_path)
    con.execute("SELECT 1 FROM sqlite_master LIMIT 1").fetchall()
    con.close()
    summary = {
        "design": str(design_path),
        "results_db": str(db_path),
        "still": str(written.get("still", "")),
        "video": str(written.get("video", "")),
        "screens": str(shots),
        "report": str(report) if report else None,
        "participants": 1 + panel,
    }
    (out / "demo-summary.json").write_text(json.dumps(summary, indent=2))
    print(f"Demo written to {out}:")
    for k, v in summary.items():
        print(f"  {k:13s} {v}")
    return 0


def _render_first_trial(design, plan, out: Path, *, video: bool) -> dict[str, Path]:
    from studyapp.render.context import create_offscreen_context
    from studyapp.render.renderer import Renderer
    from studyapp.render.scene import build_trial_scene
    from studyapp.render.video import render_still, render_video
    from studyapp.study.stimuli import load_trial_media

    media = load_trial_media(design, plan)
    ctx = create_offscreen_context()
    renderer = Renderer(ctx)
    scene = build_trial_scene(renderer, media)
    written = {"still": out / "first_trial.png"}
    render_still(scene, min(2.0, scene.duration / 2), written["still"], size=(1280, 720))
    if video:
        written["video"] = out / "first_trial.mp4"
        render_video(scene, media.audio, written["video"], size=(1280, 720), fps=30,
                     duration=min(4.0, scene.duration))
    return written


def _analyse(db_path: Path, out: Path, design) -> Path | None:
    from results_analysis import load_questionnaire
    from results_analysis.report import analyze
    from studyapp.study.export import export_dataframe

    df = export_dataframe(db_path)
    questionnaire = load_questionnaire(db_path)
    if df.empty:
        print("No answers were recorded, so there is nothing to analyse.")
        return None
    if out.exists():
        shutil.rmtree(out)
    analyze(df, out, title=f"{design.title}: results",
            questionnaire=questionnaire if len(questionnaire) else None)
    return out / "report.html"
