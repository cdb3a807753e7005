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
    """The videos of :mod:`studyapp.study.prerender` in ``cache_dir`` (``studyapp prerender``'s ``--cache``),
    rendered with ``settings``; a video not there yet is rendered when first asked for (``studyapp serve``
    renders every missing one before it starts listening, so none is rendered while a participant waits)."""

    def __init__(self, design: Any, cache_dir: Path, settings: Any = None) -> None:
        from studyapp.study.prerender import RenderSettings

        self.design = design
        self.cache_dir = Path(cache_dir)
        self.settings = settings or RenderSettings()
        self._paths: dict[tuple, Path] = {}

    def video(self, plan: Any) -> Path:
        from studyapp.study.prerender import trial_identity, video_for

        key = trial_identity(plan)
        if key not in self._paths:   # the cache key hashes every input file: computed once per trial
            self._paths[key] = Path(video_for(self.design, plan, self.cache_dir, self.settings))
        return self._paths[key]


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
