"""ARKit blendshape weights from the face parameters of an SMPL-X file.

SMPL-X carries its face as a jaw rotation (joint 22) and FLAME expression coefficients; ARKit avatars have
blendshapes. Two mappings, both stated here:

* **jaw -> jawOpen**: the angle by which the jaw's forward axis (+z; SMPL-X rest frames are the world's)
  drops below the head's horizontal (x-z) plane, ``0`` to :data:`JAW_OPEN_FULL_DEG` degrees -> ``0`` to ``1``,
  clipped (a jaw turned up or only sideways opens nothing). 25 degrees is about a fully open mouth; speech moves
  the jaw a few degrees to some 15 (BEAT2's fitted jaws stay under about 4 degrees, so their mouths open little).
* **FLAME expressions -> ARKit**: no exact public mapping exists, so expressions are used only through a
  linear map the user gives, an ``(E, 52)`` ``.npy`` (``E`` coefficients, 52 ARKit shapes in Apple's order):
  ``weights = expressions @ map``, clipped to ``[0, 1]``; ``jawOpen`` is then the larger of the map's and the
  jaw's. Without a map the expressions are ignored with one warning.

>>> import numpy as np
>>> jaw = np.array([[0.0, 0.0, 0.0], [np.radians(12.5), 0.0, 0.0], [np.radians(40.0), 0.0, 0.0], [-0.2, 0.0, 0.0]])
>>> np.round(jaw_open_weight(jaw), 3).tolist()
[0.0, 0.5, 1.0, 0.0]
>>> face = smplx_face(jaw, fps=30.0)
>>> face.n_frames, float(face.weight("jawOpen")[1])
(4, 0.5)
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from studyapp.errors import InputError
from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_INDEX, N_ARKIT
from studyapp.safe_io import load_numpy

__all__ = ["JAW_OPEN_FULL_DEG", "jaw_open_weight", "load_flame_map", "smplx_face"]

#: Jaw opening (degrees) that reads as ``jawOpen = 1``.
JAW_OPEN_FULL_DEG = 25.0


def jaw_open_weight(jaw: np.ndarray) -> np.ndarray:
    """``(F,)`` jawOpen in ``[0, 1]`` from ``(F, 3)`` jaw axis-angle (see the module docstring)."""
    v = np.asarray(jaw, dtype=np.float64).reshape(-1, 3)
    theta = np.linalg.norm(v, axis=1)
    k = np.divide(v, theta[:, None], out=np.zeros_like(v), where=theta[:, None] > 1e-12)
    z = np.array([0.0, 0.0, 1.0])
    # Rodrigues: where the jaw's forward axis goes; how far it drops below the head's horizontal is the opening
    fwd = (z * np.cos(theta)[:, None] + np.cross(k, z) * np.sin(theta)[:, None]
           + k * (k @ z)[:, None] * (1.0 - np.cos(theta))[:, None])
    opening = np.degrees(np.arcsin(np.clip(-fwd[:, 1], -1.0, 1.0)))
    return np.clip(opening / JAW_OPEN_FULL_DEG, 0.0, 1.0) + 0.0  # + 0.0: no -0.0 in what is printed


def load_flame_map(path: str | Path, n_coefficients: int) -> np.ndarray:
    """The user's ``(E, 52)`` FLAME-to-ARKit map, checked against the file's ``E`` expression coefficients."""
    path = str(path)
    if not Path(path).is_file():
        raise InputError(path, None, "FLAME map file not found")
    m = load_numpy(path)
    if not isinstance(m, np.ndarray):
        m.close()
    if not isinstance(m, np.ndarray) or m.shape != (n_coefficients, N_ARKIT) or not np.issubdtype(m.dtype, np.number):
        shape = getattr(m, "shape", "an .npz archive")
        raise InputError(path, "array", f"shape {shape}; a FLAME map is ({n_coefficients}, {N_ARKIT}): one row per "
                                        "expression coefficient, one column per ARKit shape in Apple's order")
    if not np.isfinite(m).all():
        raise InputError(path, "array", "non-finite values")
    return m.astype(np.float64)


def smplx_face(jaw: np.ndarray, fps: float, expressions: np.ndarray | None = None,
               flame_map: np.ndarray | None = None, source: str = "") -> FaceAnimation:
    """A :class:`FaceAnimation` with ``jawOpen`` from the jaw and, given ``flame_map``, the mapped expressions."""
    weights = np.zeros((len(jaw), N_ARKIT))
    if expressions is not None and flame_map is not None:
        weights = np.clip(np.asarray(expressions, dtype=np.float64) @ flame_map, 0.0, 1.0)
    elif expressions is not None and np.any(expressions):
        warnings.warn(f"{source or 'SMPL-X file'}: {np.shape(expressions)[1]} FLAME expression coefficients ignored "
                      "(no exact FLAME-to-ARKit mapping exists; give your own (E, 52) map to use them); only the "
                      "jaw drives the face", stacklevel=2)
    j = ARKIT_INDEX["jawopen"]
    weights[:, j] = np.maximum(weights[:, j], jaw_open_weight(jaw))
    return FaceAnimation(weights, float(fps), source=source)
