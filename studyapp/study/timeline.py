"""One trial's timeline: how long it plays, and what each medium does over that time.

This is the one place that decides it; the window, the offscreen bot, ``render`` (PNG and MP4), the bots'
pilots and ``validate`` all take a trial's length and its media from here, so none of them can play a
different trial than the others.

* The trial lasts the stimulus's ``duration_s`` when given, else its audio's length
  (:func:`trial_duration`).
* Every medium starts at 0 s. One longer than the trial is cut to it.
* One shorter than the trial by at most :data:`DURATION_TOLERANCE_S` holds its last frame (a rounding
  difference between exporters, invisible).
* A body motion shorter than that is refused by ``validate`` unless its condition says what to do
  (``motion_end = "hold"``: freeze on the last frame; ``"loop"``: start again from its first frame).
  Nothing freezes silently: a frozen figure loses on realism for a reason unrelated to the model.

Frame ``i`` of a fitted medium is at ``i / fps`` seconds; a medium at ``fps`` covers a trial of ``T``
seconds with ``ceil(T * fps)`` frames.

>>> trial_duration(1.2, 4.9), trial_duration(None, 4.9)
(1.2, 4.9)
>>> frame_indices(5, 10.0, 0.8, "hold").tolist()       # 0.5 s of motion, held to 0.8 s
[0, 1, 2, 3, 4, 4, 4, 4]
>>> frame_indices(5, 10.0, 0.8, "loop").tolist()
[0, 1, 2, 3, 4, 0, 1, 2]
>>> frame_indices(50, 10.0, 0.3, None).tolist()        # longer than the trial: cut
[0, 1, 2]
>>> medium_end(0.5, 0.8, None), medium_end(0.7, 0.8, None), medium_end(2.0, 0.8, "loop")
('short', 'hold', 'cut')
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # only for annotations: this module is pure numpy
    from studyapp.audio.wav import AudioClip
    from studyapp.face.animation import FaceAnimation
    from studyapp.motion.skeleton import Motion

#: Largest difference between a medium's length and the trial's that is a rounding matter (seconds).
DURATION_TOLERANCE_S = 0.2
#: What a condition's ``motion_end`` may ask for when its motion is shorter than the trial.
MOTION_END_CHOICES = ("hold", "loop")


def trial_duration(duration_s: float | None, audio_s: float) -> float:
    """Seconds a trial plays: the stimulus's ``duration_s`` when given, else the audio's length."""
    return float(duration_s) if duration_s is not None else float(audio_s)


def n_trial_frames(fps: float, trial_s: float) -> int:
    """Frames at ``fps`` that cover ``trial_s`` seconds (at least one)."""
    return max(1, math.ceil(trial_s * fps - 1e-9))


def medium_end(source_s: float, trial_s: float, motion_end: str | None) -> str:
    """What happens to a medium of ``source_s`` seconds in a trial of ``trial_s`` seconds.

    ``"cut"`` (as long or longer), ``"hold"`` (short within the tolerance, or ``motion_end = "hold"``),
    ``"loop"`` (``motion_end = "loop"``) or ``"short"``: too short, and nothing was asked for, which
    ``validate`` refuses.
    """
    if source_s >= trial_s - 1e-9:
        return "cut"
    if motion_end in MOTION_END_CHOICES:
        return motion_end
    if source_s >= trial_s - DURATION_TOLERANCE_S:
        return "hold"
    return "short"


def frame_indices(n_frames: int, fps: float, trial_s: float, motion_end: str | None) -> np.ndarray:
    """Source frame shown at each of the trial's frames (see :func:`n_trial_frames`), by :func:`medium_end`.

    A medium too short for the trial with no ``motion_end`` holds its last frame here: refusing it is
    ``validate``'s job, and a scene built anyway (``view``) must not crash.
    """
    if n_frames < 1:
        raise ValueError("a medium needs at least one frame")
    idx = np.arange(n_trial_frames(fps, trial_s))
    if medium_end(n_frames / fps, trial_s, motion_end) == "loop":
        return idx % n_frames
    return np.minimum(idx, n_frames - 1)


def fit_motion(motion: "Motion", trial_s: float, motion_end: str | None = None) -> "Motion":
    """``motion`` cut, held or looped to exactly cover the trial."""
    from studyapp.motion.skeleton import Motion

    idx = frame_indices(motion.n_frames, motion.fps, trial_s, motion_end)
    if len(idx) == motion.n_frames and np.array_equal(idx, np.arange(motion.n_frames)):
        return motion
    return Motion(motion.skeleton, motion.fps, motion.rotations[idx], motion.translations[idx], source=motion.source)


def fit_face(face: "FaceAnimation", trial_s: float) -> "FaceAnimation":
    """The face cut to the trial, or its last frame held (a face too short is refused by ``validate``)."""
    from studyapp.face.animation import FaceAnimation

    if face.n_frames == 0:
        return face
    idx = frame_indices(face.n_frames, face.fps, trial_s, None)
    if len(idx) == face.n_frames:
        return face
    head = None if face.head_rotation is None else face.head_rotation[idx]
    return FaceAnimation(face.weights[idx], face.fps, head, source=face.source, missing=face.missing,
                         unknown=face.unknown)


def cut_audio(audio: "AudioClip", trial_s: float) -> "AudioClip":
    """The audio cut at the trial's end (shorter audio is left as is: the trial ends in silence)."""
    from studyapp.audio.wav import AudioClip

    n = int(round(trial_s * audio.sample_rate))
    if len(audio.samples) <= n:
        return audio
    return AudioClip(audio.samples[:n], audio.sample_rate, source=audio.source)


__all__ = ["DURATION_TOLERANCE_S", "MOTION_END_CHOICES", "cut_audio", "fit_face", "fit_motion", "frame_indices",
           "medium_end", "n_trial_frames", "trial_duration"]
