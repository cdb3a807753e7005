"""Helpers for the renderer tests (posing the avatar, CPU reference skinning, projection, sample files).

A uniquely named module rather than conftest.py: several test folders have a conftest, and importing
names from "conftest" picks whichever was imported first.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from studyapp.motion.skeleton import Motion

SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"  # copies of ../shared/samples (see its README)


def posed(avatar, rotvecs_deg: dict[str, tuple[float, float, float]], n_frames: int = 1, fps: float = 30.0) -> Motion:
    """A motion on the avatar's skeleton holding the rest pose with extra local rotations (degrees)."""
    m = Motion.rest(avatar.skeleton, n_frames, fps)
    for name, rv in rotvecs_deg.items():
        j = avatar.skeleton.index(name)
        m.rotations[:, j] = (Rotation.from_quat(m.rotations[:, j]) * Rotation.from_rotvec(np.radians(rv))).as_quat()
    return m


#: Arms relaxed at the sides, elbows a little bent: a natural standing pose for the T-posed avatar.
RELAXED = {"LeftUpperArm": (0, 0, -72), "RightUpperArm": (0, 0, 72),
           "LeftLowerArm": (0, -15, 0), "RightLowerArm": (0, 15, 0)}


def skin_cpu(avatar, palette: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Reference CPU skinning (+ morphs) of every vertex, for checking where the GPU should draw."""
    v = avatar.vertices.astype(np.float64)
    if weights is not None:
        v = v + np.tensordot(weights, avatar.morph_deltas, axes=1)
    vh = np.c_[v, np.ones(len(v))]
    out = np.zeros((len(v), 4))
    for k in range(4):
        out += avatar.weights[:, k:k + 1] * np.einsum("vij,vj->vi", palette[avatar.joints[:, k]].astype(np.float64), vh)
    return out[:, :3]


def project(camera, points: np.ndarray, viewport: tuple[int, int, int, int], full_height: int) -> np.ndarray:
    """Pixel (column, row-from-top) of world points drawn with ``camera`` into ``viewport``."""
    x, y, w, h = viewport
    clip = np.c_[points, np.ones(len(points))] @ camera.view_proj(w / h).T
    ndc = clip[:, :3] / clip[:, 3:4]
    px = x + (ndc[:, 0] + 1) / 2 * w
    py = y + (ndc[:, 1] + 1) / 2 * h
    return np.c_[px, full_height - py]
