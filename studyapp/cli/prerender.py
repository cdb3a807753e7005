"""``studyapp prerender``: every trial of a design as an MP4, for the browser study server (see
:mod:`studyapp.study.prerender`)."""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import TextIO

from studyapp.cli.render import _size


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "prerender", help="render every trial a design can show to MP4 (for browser participants)",
        description="Render every distinct trial of the design (all design rows, every slot order) to an MP4 "
        "with the figures side by side and the speech muxed in, exactly as the desktop app shows it. Videos are "
        "cached by a content hash of everything that changes them: run it again after a change, or after an "
        "interruption, and only what is missing is rendered.",
    )
    p.add_argument("design", help="study design (.toml)")
    p.add_argument("--cache", help="folder of the videos (default: 'prerendered' next to the design)")
    p.add_argument("--jobs", type=int, default=1, help="render in this many processes (default 1; the number of "
                   "CPU cores is a good choice on a machine without a GPU)")
    p.add_argument("--size", type=_size, default=(1280, 720), help="video size, WxH (default 1280x720)")
    p.add_argument("--fps", type=int, default=30, help="frames per second (default 30)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar: one summary line at the end (CI)")
    p.set_defaults(func=cmd_prerender)


class ProgressBar:
    """``[#####-----] 12/30 videos, 1m20s left`` redrawn in place on a terminal; a line per 10 % elsewhere."""

    def __init__(self, stream: TextIO = sys.stderr, width: int = 30) -> None:
        self.stream = stream
        self.width = width
        self.tty = stream.isatty()
        self.t0 = time.perf_counter()
        self.first: int | None = None
        self.last_tenth = -1

    def __call__(self, done: int, total: int) -> None:
        if self.first is None:
            self.first = done
        frac = done / total if total else 1.0
        fill = int(round(frac * self.width))
        text = f"[{'#' * fill}{'-' * (self.width - fill)}] {done}/{total} videos"
        rendered = done - self.first
        if 0 < rendered and done < total:
            left = (time.perf_counter() - self.t0) / rendered * (total - done)
            text += f", {int(left // 60)}m{int(left % 60):02d}s left"
        if self.tty:
            self.stream.write("\r" + text.ljust(self.width + 40) + ("\n" if done >= total else ""))
            self.stream.flush()
        elif int(frac * 10) != self.last_tenth or done >= total:
            self.last_tenth = int(frac * 10)
            print(text, file=self.stream, flush=True)


def cmd_prerender(args: argparse.Namespace) -> int:
    from studyapp.cli.extras import require

    require("prerender", "av")  # before minutes of rendering, not after
    from studyapp.study.design import load_design
    from studyapp.study.prerender import RenderSettings, prerender

    design = load_design(args.design)
    cache = Path(args.cache) if args.cache else Path(args.design).resolve().parent / "prerendered"
    jobs = args.jobs
    if jobs < 1:
        print(f"error: --jobs must be at least 1, got {jobs}", file=sys.stderr)
        return 2
    if args.fps < 1:
        print(f"error: --fps must be at least 1, got {args.fps}", file=sys.stderr)
        return 2
    report = prerender(design, cache, progress=None if args.quiet else ProgressBar(), jobs=jobs,
                       settings=RenderSettings(size=args.size, fps=args.fps))
    rate = f", {report.realtime_factor:.2f}x real time" if report.rendered else ""
    print(f"{report.total} trial videos in {cache}: {report.rendered} rendered ({report.video_seconds:.0f} s of video "
          f"in {report.wall_s:.0f} s{rate}), {report.cached} already there"
          + (f"; {os.cpu_count()} cores, --jobs {jobs}" if report.rendered else ""))
    return 0
