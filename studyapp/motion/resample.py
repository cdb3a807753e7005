"""Changing a motion's frame rate and cutting it to a time range.

>>> import numpy as np
>>> from studyapp.motion.beat import beat_skeleton
>>> from studyapp.motion.skeleton import Motion
>>> m = Motion.rest(beat_skeleton(), n_frames=15, fps=15)   # 1 s at 15 fps
>>> up = resample(m, 60)
>>> up.n_frames, up.duration
(60, 1.0)
>>> trim(up, 0.25, 0.75).n_frames
30
"""
from __future__ import annotations

import math

import numpy as np

from studyapp.errors import InputError
from studyapp.motion.rotations import quat_slerp
from studyapp.motion.skeleton import Motion

__all__ = ["resample", "trim", "check_duration", "sample_times"]


def sample_times(n_frames: int, fps: float) -> np.ndarray:
    """Start times (seconds) of ``n_frames`` frames at ``fps``."""
    return np.arange(n_frames) / float(fps)


def resample(motion: Motion, fps: float) -> Motion:
    """The same motion at another frame rate, keeping its duration (``n_frames / fps``).

    Frame ``i`` of the result shows time ``i / fps``; it is interpolated between the two source frames
    around it (slerp for rotations, linear for translations). Times past the last source frame hold
    that frame, which is what a player showing ``n / fps`` seconds does too.
    """
    if not (fps > 0 and math.isfinite(fps)):
        raise ValueError(f"fps must be a positive number, got {fps}")
    if float(fps) == float(motion.fps):
        return Motion(motion.skeleton, motion.fps, motion.rotations.copy(), motion.translations.copy(), motion.source)
    n_src = motion.n_frames
    n_out = int(round(motion.duration * fps))
    if n_src == 0 or n_out == 0:
        j = motion.skeleton.n_joints
        return Motion(motion.skeleton, float(fps), np.zeros((0, j, 4)), np.zeros((0, j, 3)), motion.source)
    pos = np.minimum(np.arange(n_out) * (motion.fps / fps), n_src - 1)
    i0 = np.floor(pos).astype(np.int64)
    i1 = np.minimum(i0 + 1, n_src - 1)
    w = pos - i0
    rot = quat_slerp(motion.rotations[i0], motion.rotations[i1], np.broadcast_to(w[:, None], (n_out, motion.skeleton.n_joints)))
    trans = motion.translations[i0] * (1.0 - w)[:, None, None] + motion.translations[i1] * w[:, None, None]
    return Motion(motion.skeleton, float(fps), rot, trans, motion.source)


def trim(motion: Motion, start_s: float, end_s: float | None = None) -> Motion:
    """Frames whose start time lies in ``[start_s, end_s)`` (``end_s=None``: to the end)."""
    end_s = motion.duration if end_s is None else end_s
    if start_s < 0 or end_s < start_s:
        raise ValueError(f"invalid time range [{start_s}, {end_s}) for a {motion.duration:.3f} s motion")
    # a small epsilon so that 0.25 s at 60 fps lands on frame 15, not 14.999...
    a = int(math.ceil(start_s * motion.fps - 1e-9))
    b = int(math.ceil(end_s * motion.fps - 1e-9))
    a, b = min(a, motion.n_frames), min(b, motion.n_frames)
    return Motion(motion.skeleton, motion.fps, motion.rotations[a:b].copy(), motion.translations[a:b].copy(), motion.source)


def check_duration(motion: Motion, expected_s: float, tolerance_s: float, what: str) -> None:
    """Raise :class:`InputError` when ``motion`` lasts more than ``tolerance_s`` longer or shorter than expected.

    ``what`` names the thing being checked in the message (e.g. ``"motion for clip 3, model CaMN"``);
    the motion's ``source`` is the path reported.

    >>> from studyapp.motion.beat import beat_skeleton
    >>> m = Motion.rest(beat_skeleton(), n_frames=150, fps=15)
    >>> check_duration(m, 10.0, 0.1, "clip 1")
    >>> check_duration(m, 12.0, 0.1, "clip 1")
    Traceback (most recent call last):
    ...
    studyapp.errors.InputError: rest pose, duration: clip 1 lasts 10.000 s (150 frames at 15 fps) but 12.000 s were expected (tolerance 0.100 s); check the frame rate
    """
    actual = motion.duration
    if abs(actual - expected_s) > tolerance_s:
        raise InputError(
            motion.source or None,
            "duration",
            f"{what} lasts {actual:.3f} s ({motion.n_frames} frames at {motion.fps:g} fps) but "
            f"{expected_s:.3f} s were expected (tolerance {tolerance_s:.3f} s); check the frame rate",
        )
