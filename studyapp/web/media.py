"""Where the server gets a trial's video, and how long it plays.

The server shows each trial as ONE pre-rendered MP4: every figure side by side with the audio muxed in,
rendered by the desktop's renderer and trial timeline (:mod:`studyapp.study.prerender`), so every participant
sees the same pixels and audio and video are in sync by construction. :class:`TrialVideos` is the seam: the
server asks it for a plan's file; :class:`PrerenderedVideos` renders (or finds in its cache) the file of a
plan; tests pass a stand-in with small generated clips.

The file's own name and metadata never reach the participant: the server sends its bytes under an opaque
per-participant name (:mod:`studyapp.web.tokens`), without its modification time.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

from studyapp.errors import InputError


class TrialVideos(Protocol):
    """Gives the video file of one trial plan (a :class:`~studyapp.study.schedule.TrialPlan`)."""

    def video(self, plan: Any) -> Path: ...


class PrerenderedVideos:
    """The videos of :mod:`studyapp.study.prerender`, rendered into ``cache_dir`` when not there yet."""

    def __init__(self, design: Any, cache_dir: Path) -> None:
        self.design = design
        self.cache_dir = Path(cache_dir)

    def video(self, plan: Any) -> Path:
        from studyapp.study.prerender import video_for

        return Path(video_for(self.design, plan, self.cache_dir))


def duration_s(path: Path) -> float:
    """Seconds an MP4 plays (its container's duration), read from the file's header."""
    import av

    try:
        with av.open(str(path)) as container:
            if container.duration is not None:
                return float(container.duration) / 1_000_000.0
            stream = container.streams.video[0]
            return float(stream.duration * stream.time_base)
    except (av.error.FFmpegError, IndexError, TypeError) as exc:   # damaged file, no video stream, no duration
        raise InputError(path, None, f"cannot read the trial video's length ({exc}); render it again with "
                         "`studyapp prerender`") from None
