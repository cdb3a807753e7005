"""Objective motion metrics of co-speech gesture papers, on joint positions: numpy in, numpy out.

Every function takes world joint positions ``(F, J, 3)`` (frames x joints x xyz, metres) sampled at
``fps`` frames per second, and is batched over frames (no Python loop over frames). Definitions:

* **Acceleration and jerk** (jitter): the mean, over frames and joints, of the Euclidean norm of the 2nd
  (3rd) finite difference of the positions, times ``fps**2`` (``fps**3``): metres per second squared (cubed).
* **Frozen share**: the share of the ``F - 1`` frame-to-frame steps in which *every* joint moves slower than
  :data:`FROZEN_SPEED` (5 mm/s): a held pose, not a slow gesture (idle sway moves centimetres a second).
* **Motion beats**: local minima of the kinematic velocity (the mean over joints of each joint's speed),
  smoothed with a Gaussian of :data:`BEAT_SMOOTH_S` seconds; a minimum must be the smallest value within
  :data:`BEAT_WINDOW_S` seconds either side (AIST++/Bailando and BEAT compute beats this way).
* **Beat alignment** (the Beat Align Score of BEAT, Liu et al. 2022, as in EMAGE): the mean, over motion
  beats, of ``exp(-d**2 / (2 sigma**2))`` with ``d`` the distance in seconds to the nearest audio onset and
  ``sigma`` = :data:`BEAT_SIGMA_S` = 0.3 s. 1 = every motion beat on an onset; NaN without beats or onsets.
  (Bailando's dance variant averages over the music beats instead; ``over="onsets"`` computes that.)
* **L1 diversity** (Audio2Gestures, Li et al. 2021): the motion is cut into non-overlapping segments of
  ``segment_frames`` frames (the remainder dropped); the score is the mean, over all pairs of segments, of
  their L1 distance: the sum over xyz of absolute differences, averaged over the segment's frames and
  joints (metres). Positions are taken relative to joint 0 (the root), so where a figure stands does not
  count as diversity.
* **Frechet distance** (FGD, Yoon et al. 2020, on an encoder's features): between Gaussians fitted to two
  feature sets, ``|mu1 - mu2|^2 + tr(S1 + S2 - 2 (S1 S2)^(1/2))``.

>>> t = np.arange(61) / 60.0
>>> pos = np.zeros((61, 2, 3)); pos[:, 1, 0] = 0.5 * t ** 2          # constant acceleration 1 m/s^2 on joint 1
>>> round(float(mean_acceleration(pos, 60.0)), 6), round(float(mean_jerk(pos, 60.0)), 6)
(0.5, 0.0)
>>> round(beat_align_score(np.array([1.0, 2.0]), np.array([1.0, 2.3])), 6)   # one beat on time, one 0.3 s off
0.803265
"""
from __future__ import annotations

import numpy as np
from scipy import linalg
from scipy.ndimage import gaussian_filter1d

#: Speed (m/s) under which every joint must stay for a frame-to-frame step to count as frozen.
FROZEN_SPEED = 0.005
#: Standard deviation (s) of the Gaussian in the Beat Align Score (BEAT, EMAGE).
BEAT_SIGMA_S = 0.3
#: Standard deviation (s) of the Gaussian smoothing the kinematic velocity before its minima are found.
BEAT_SMOOTH_S = 1.0 / 12.0
#: A motion beat is the lowest smoothed velocity within this many seconds either side.
BEAT_WINDOW_S = 0.1
#: Default L1-diversity segment length in seconds (the caller turns it into frames at its frame rate).
DIVERSITY_SEGMENT_S = 1.0


def _positions(pos: np.ndarray, min_frames: int = 1) -> np.ndarray:
    p = np.asarray(pos, dtype=np.float64)
    if p.ndim != 3 or p.shape[2] != 3:
        raise ValueError(f"joint positions must be (frames, joints, 3), got shape {p.shape}")
    if p.shape[0] < min_frames:
        raise ValueError(f"need at least {min_frames} frames, got {p.shape[0]}")
    return p


def joint_speed(pos: np.ndarray, fps: float) -> np.ndarray:
    """``(F - 1, J)`` speed of each joint over each frame-to-frame step, in m/s."""
    p = _positions(pos, 2)
    return np.linalg.norm(np.diff(p, axis=0), axis=2) * float(fps)


def mean_acceleration(pos: np.ndarray, fps: float) -> float:
    """Mean norm of the 2nd finite difference times ``fps**2`` (m/s^2); NaN under 3 frames."""
    p = _positions(pos)
    if p.shape[0] < 3:
        return float("nan")
    return float(np.linalg.norm(np.diff(p, 2, axis=0), axis=2).mean() * float(fps) ** 2)


def mean_jerk(pos: np.ndarray, fps: float) -> float:
    """Mean norm of the 3rd finite difference times ``fps**3`` (m/s^3); NaN under 4 frames."""
    p = _positions(pos)
    if p.shape[0] < 4:
        return float("nan")
    return float(np.linalg.norm(np.diff(p, 3, axis=0), axis=2).mean() * float(fps) ** 3)


def frozen_share(pos: np.ndarray, fps: float, threshold: float = FROZEN_SPEED) -> float:
    """Share of frame-to-frame steps in which every joint moves slower than ``threshold`` m/s; NaN under 2 frames."""
    p = _positions(pos)
    if p.shape[0] < 2:
        return float("nan")
    return float((joint_speed(p, fps).max(axis=1) < threshold).mean())


def kinematic_velocity(pos: np.ndarray, fps: float) -> np.ndarray:
    """``(F - 1,)`` mean joint speed per step (m/s): the signal whose minima are motion beats."""
    return joint_speed(pos, fps).mean(axis=1)


def motion_beats(pos: np.ndarray, fps: float, *, smooth_s: float = BEAT_SMOOTH_S,
                 window_s: float = BEAT_WINDOW_S) -> np.ndarray:
    """Times (s) of the motion beats: local minima of the smoothed kinematic velocity (see the module notes).

    The velocity of step ``i`` (frame ``i`` to ``i + 1``) is placed at time ``(i + 0.5) / fps``. A minimum
    must be strictly below its immediate neighbours and no higher than anything within ``window_s``; a
    flat stretch (a held pose) has no beat inside it.
    """
    p = _positions(pos)
    if p.shape[0] < 4:
        return np.zeros(0)
    v = kinematic_velocity(p, fps)
    if smooth_s > 0:
        v = gaussian_filter1d(v, smooth_s * fps, mode="nearest")
    w = max(1, int(round(window_s * fps)))
    padded = np.pad(v, w, mode="constant", constant_values=np.inf)
    neigh = np.lib.stride_tricks.sliding_window_view(padded, 2 * w + 1)  # (F-1, 2w+1), centre at w
    lowest = v <= neigh.min(axis=1)
    strict = np.zeros_like(lowest)
    strict[1:-1] = (v[1:-1] < v[:-2]) & (v[1:-1] < v[2:])
    idx = np.flatnonzero(lowest & strict)
    return (idx + 0.5) / float(fps)


def beat_align_score(motion_beat_times: np.ndarray, onset_times: np.ndarray, sigma: float = BEAT_SIGMA_S,
                     *, over: str = "motion") -> float:
    """Beat Align Score: mean of ``exp(-d^2 / (2 sigma^2))`` over motion beats (``over="motion"``, BEAT and
    EMAGE) or over onsets (``over="onsets"``, Bailando), ``d`` the distance to the nearest event of the other
    kind; NaN when either set is empty."""
    mb = np.asarray(motion_beat_times, dtype=np.float64).ravel()
    on = np.asarray(onset_times, dtype=np.float64).ravel()
    if over not in ("motion", "onsets"):
        raise ValueError(f"over must be 'motion' or 'onsets', not {over!r}")
    if mb.size == 0 or on.size == 0:
        return float("nan")
    src, ref = (mb, on) if over == "motion" else (on, mb)
    d = np.abs(src[:, None] - ref[None, :]).min(axis=1)
    return float(np.exp(-d ** 2 / (2.0 * sigma ** 2)).mean())


def l1_diversity(pos: np.ndarray, segment_frames: int) -> float:
    """Mean pairwise L1 distance between non-overlapping segments (see the module notes); NaN under 2 segments."""
    p = _positions(pos)
    if segment_frames < 1:
        raise ValueError(f"segment_frames must be at least 1, got {segment_frames}")
    n = p.shape[0] // segment_frames
    if n < 2:
        return float("nan")
    rel = p[: n * segment_frames] - p[: n * segment_frames, :1]
    seg = rel.reshape(n, -1)  # (segments, frames * joints * 3)
    per_point = segment_frames * p.shape[1]
    # Pairs in chunks of rows: n^2 x (L J 3) at once could be large for long clips.
    total, pairs = 0.0, n * (n - 1) // 2
    for i in range(n - 1):
        total += float(np.abs(seg[i + 1:] - seg[i]).sum())
    return total / per_point / pairs


def frechet_distance(feats_a: np.ndarray, feats_b: np.ndarray) -> float:
    """Frechet distance between Gaussians fitted to two ``(N, D)`` feature sets (unbiased covariances).

    The matrix square root is ``scipy.linalg.sqrtm``; its tiny imaginary part from rounding is dropped.
    """
    a = np.asarray(feats_a, dtype=np.float64)
    b = np.asarray(feats_b, dtype=np.float64)
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1]:
        raise ValueError(f"feature sets must be (N, D) with equal D, got {a.shape} and {b.shape}")
    if len(a) < 2 or len(b) < 2:
        raise ValueError(f"each feature set needs at least 2 rows, got {len(a)} and {len(b)}")
    mu_a, mu_b = a.mean(axis=0), b.mean(axis=0)
    s_a = np.atleast_2d(np.cov(a, rowvar=False))
    s_b = np.atleast_2d(np.cov(b, rowvar=False))
    covmean = linalg.sqrtm(s_a @ s_b)
    if not np.isfinite(covmean).all():  # singular product: regularise both, as the FID reference code does
        eps = np.eye(len(s_a)) * 1e-6
        covmean = linalg.sqrtm((s_a + eps) @ (s_b + eps))
    covmean = np.real(covmean)
    return float(np.sum((mu_a - mu_b) ** 2) + np.trace(s_a) + np.trace(s_b) - 2.0 * np.trace(covmean))


__all__ = ["BEAT_SIGMA_S", "BEAT_SMOOTH_S", "BEAT_WINDOW_S", "DIVERSITY_SEGMENT_S", "FROZEN_SPEED",
           "beat_align_score", "frechet_distance", "frozen_share", "joint_speed", "kinematic_velocity",
           "l1_diversity", "mean_acceleration", "mean_jerk", "motion_beats"]
