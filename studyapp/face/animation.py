"""Facial animation as ARKit blendshape weights over time, in one canonical layout.

Every importer produces a :class:`FaceAnimation` whose columns are in :data:`ARKIT_NAMES` order whatever the
source's column order was, so the renderer can bind morph targets once by name and index frames blindly.

>>> import numpy as np
>>> face = FaceAnimation.neutral(4, fps=2.0)
>>> face.n_frames, face.duration
(4, 2.0)
>>> face.weights[:, ARKIT_INDEX["jawopen"]] = [0.0, 1.0, 0.5, 0.0]
>>> face.sample(np.array([0.25, 0.75]))[:, ARKIT_INDEX["jawopen"]].tolist()
[0.5, 0.75]
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from studyapp.face.arkit import ARKIT_INDEX, ARKIT_NAMES, N_ARKIT, match_arkit_name


def _interp_frames(values: np.ndarray, fps: float, times_s: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``(F, C)`` frame values at arbitrary times, clamped to the first/last frame."""
    n = values.shape[0]
    pos = np.clip(np.asarray(times_s, dtype=np.float64) * fps, 0.0, n - 1)
    i0 = np.floor(pos).astype(np.int64)
    i1 = np.minimum(i0 + 1, n - 1)
    frac = (pos - i0)[..., None]
    out = values[i0] * (1.0 - frac) + values[i1] * frac
    return out


@dataclass(eq=False)
class FaceAnimation:
    """ARKit blendshape weights sampled at a fixed rate.

    Attributes
    ----------
    weights:
        ``(F, 52)`` float32 in :data:`ARKIT_NAMES` order, clipped to ``[0, 1]`` on construction.
    fps:
        Frames per second (frame ``i`` is at ``i / fps`` seconds).
    head_rotation:
        ``(F, 3)`` head yaw, pitch, roll in radians when the source records it, else ``None``.
    source:
        File path or description, for messages.
    missing:
        ARKit names the source did not have (their weights are 0).
    unknown:
        Names in the source that are not ARKit blendshapes (ignored).
    """

    weights: np.ndarray
    fps: float
    head_rotation: np.ndarray | None = None
    source: str = ""
    missing: tuple[str, ...] = field(default_factory=tuple)
    unknown: tuple[str, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        w = np.asarray(self.weights, dtype=np.float32)
        if w.ndim != 2 or w.shape[1] != N_ARKIT:
            raise ValueError(f"weights must be (frames, {N_ARKIT}) in ARKit order, got {w.shape}")
        if not np.isfinite(w).all():
            raise ValueError("weights contain NaN or infinite values")
        self.weights = np.clip(w, 0.0, 1.0)
        fps = float(self.fps)
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be a positive number, got {self.fps}")
        self.fps = fps
        if self.head_rotation is not None:
            h = np.asarray(self.head_rotation, dtype=np.float32)
            if h.shape != (w.shape[0], 3):
                raise ValueError(f"head_rotation must be ({w.shape[0]}, 3), got {h.shape}")
            self.head_rotation = h
        self.missing = tuple(self.missing)
        self.unknown = tuple(self.unknown)

    @property
    def n_frames(self) -> int:
        return int(self.weights.shape[0])

    @property
    def duration(self) -> float:
        """Length in seconds (``n_frames / fps``, the same convention as :class:`~studyapp.motion.skeleton.Motion`)."""
        return self.n_frames / self.fps

    @classmethod
    def neutral(cls, n_frames: int, fps: float) -> "FaceAnimation":
        """A face at rest (all weights 0) for ``n_frames``; stands in where a study has no face data."""
        return cls(np.zeros((int(n_frames), N_ARKIT), np.float32), fps, source="neutral face")

    def sample(self, times_s: np.ndarray) -> np.ndarray:
        """``(T, 52)`` weights at ``times_s`` seconds: linear between frames, held at the ends.

        >>> FaceAnimation.neutral(3, 30.0).sample(np.array([-1.0, 0.02, 99.0])).shape
        (3, 52)
        """
        times = np.atleast_1d(np.asarray(times_s, dtype=np.float64))
        if self.n_frames == 0:
            return np.zeros(times.shape + (N_ARKIT,), np.float32)
        return _interp_frames(self.weights, self.fps, times).astype(np.float32)

    def sample_head(self, times_s: np.ndarray) -> np.ndarray | None:
        """``(T, 3)`` head yaw/pitch/roll at ``times_s``, or ``None`` when the source has none."""
        if self.head_rotation is None or self.n_frames == 0:
            return None
        times = np.atleast_1d(np.asarray(times_s, dtype=np.float64))
        return _interp_frames(self.head_rotation, self.fps, times).astype(np.float32)

    def resample(self, fps: float) -> "FaceAnimation":
        """The same animation at another frame rate, keeping its duration (to the nearest frame).

        >>> FaceAnimation.neutral(60, 60.0).resample(30.0).n_frames
        30
        """
        fps = float(fps)
        if not (np.isfinite(fps) and fps > 0):
            raise ValueError(f"fps must be a positive number, got {fps}")
        n = int(round(self.n_frames * fps / self.fps))
        times = np.arange(n) / fps
        head = self.sample_head(times) if n else (None if self.head_rotation is None else np.zeros((0, 3)))
        return FaceAnimation(
            self.sample(times) if n else np.zeros((0, N_ARKIT), np.float32),
            fps, head, self.source, self.missing, self.unknown,
        )

    def weight(self, name: str) -> np.ndarray:
        """The ``(F,)`` weight curve of one blendshape, by any name :func:`match_arkit_name` accepts.

        >>> FaceAnimation.neutral(2, 30.0).weight("JawOpen").tolist()
        [0.0, 0.0]
        """
        canon = match_arkit_name(name)
        if canon is None:
            raise KeyError(f"{name!r} is not an ARKit blendshape name")
        return self.weights[:, ARKIT_INDEX[canon.lower()]]


__all__ = ["FaceAnimation", "ARKIT_NAMES", "ARKIT_INDEX"]
