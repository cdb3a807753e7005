"""A motion encoder the user provides (ONNX) for the Frechet Gesture Distance (FGD, Yoon et al. 2020).

FGD compares the distribution of a model's motion with a reference (real) motion in the feature space of
a trained encoder. studyapp ships no encoder and downloads none: the user gives a ``.onnx`` file and
studyapp checks that it fits what it will be fed.

The encoder contract:

* one input, float32, shape ``[batch, T, D]``: ``T`` consecutive frames of the motion as played (the
  avatar's joints, world positions in metres minus joint 0 (the root), at the playback rate), flattened
  per frame to ``D = 3 x joints`` values (joint-major: ``x0 y0 z0 x1 ...``). ``batch`` may be symbolic;
  ``D`` must be a number equal to 3 x the avatar's joints; a numeric ``T`` is the window length, a
  symbolic one takes :data:`DEFAULT_WINDOW` frames;
* its first output is ``[batch, E]``: one feature vector per window.

Windows start every ``T // 2`` frames (half overlap); a clip shorter than one window gives none.

>>> pos = np.arange(10 * 2 * 3, dtype=float).reshape(10, 2, 3)
>>> motion_windows(pos, 4).shape                     # windows at frames 0, 2, 4, 6
(4, 4, 6)
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from studyapp.errors import InputError

#: Window length (frames) for an encoder whose input leaves ``T`` open (34, as Yoon et al.'s FGD encoder).
DEFAULT_WINDOW = 34


def motion_windows(pos: np.ndarray, window: int, stride: int | None = None) -> np.ndarray:
    """``(W, window, J * 3)`` root-relative windows of ``(F, J, 3)`` positions, every ``stride`` frames."""
    p = np.asarray(pos, dtype=np.float64)
    if p.ndim != 3 or p.shape[2] != 3:
        raise ValueError(f"joint positions must be (frames, joints, 3), got shape {p.shape}")
    stride = max(1, window // 2) if stride is None else stride
    rel = (p - p[:, :1]).reshape(len(p), -1)
    if len(rel) < window:
        return np.zeros((0, window, rel.shape[1]))
    starts = np.arange(0, len(rel) - window + 1, stride)
    return np.lib.stride_tricks.sliding_window_view(rel, window, axis=0)[starts].transpose(0, 2, 1).copy()


class MotionEncoder:
    """A user's ONNX motion encoder, checked against the contract above on load."""

    def __init__(self, path: str | Path) -> None:
        from studyapp.models.runner import load_session

        self.path = Path(path)
        self.session = load_session(self.path)
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        if len(inputs) != 1:
            raise InputError(self.path, "inputs", f"{len(inputs)} inputs ({', '.join(i.name for i in inputs)}); "
                             "an FGD encoder takes one input [batch, frames, 3 x joints]")
        inp = inputs[0]
        shape = list(inp.shape)
        if len(shape) != 3 or not isinstance(shape[2], int):
            raise InputError(self.path, f"input {inp.name!r}", f"shape {shape}; expected [batch, frames, D] with D "
                             "a number (3 x the avatar's joints)")
        if "float" not in str(inp.type) or "16" in str(inp.type) or "double" in str(inp.type):
            raise InputError(self.path, f"input {inp.name!r}", f"type {inp.type}; expected tensor(float)")
        out_shape = list(outputs[0].shape)
        if len(out_shape) != 2:
            raise InputError(self.path, f"output {outputs[0].name!r}", f"shape {out_shape}; expected [batch, features]")
        self.input_name = inp.name
        self.n_features = int(shape[2])
        self.window = int(shape[1]) if isinstance(shape[1], int) and shape[1] > 0 else DEFAULT_WINDOW

    def check_joints(self, n_joints: int) -> None:
        """Refuse, naming both numbers, an encoder that does not take this avatar's joint count."""
        if self.n_features != 3 * n_joints:
            raise InputError(self.path, f"input {self.input_name!r}",
                             f"expects {self.n_features} values per frame, but the motion as played has "
                             f"{n_joints} joints ({3 * n_joints} values: x, y, z per joint); use an encoder "
                             "trained on this avatar's skeleton")

    def encode(self, pos: np.ndarray) -> np.ndarray:
        """``(W, E)`` features of the windows of ``(F, J, 3)`` positions (``(0, E)`` when shorter than a window)."""
        pos = np.asarray(pos)
        self.check_joints(pos.shape[1])
        win = motion_windows(pos, self.window).astype(np.float32)
        if len(win) == 0:
            return np.zeros((0, 0))
        out = self.session.run(None, {self.input_name: win})[0]
        out = np.asarray(out, dtype=np.float64)
        if out.ndim != 2 or len(out) != len(win):
            raise InputError(self.path, "output", f"shape {out.shape} for {len(win)} windows; expected "
                             f"({len(win)}, features)")
        return out


__all__ = ["DEFAULT_WINDOW", "MotionEncoder", "motion_windows"]
