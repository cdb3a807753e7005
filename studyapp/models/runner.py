"""Run a contract-conforming ONNX gesture model causally, one frame at a time, as live use would.

The runner owns the sliding input windows and the recurrent state, so a caller only hands over the
newest frame's inputs. Windows start filled with the "nothing yet" value: zeros for audio features and
blendshapes, the identity rotation for the head; the previous pose starts at the rest pose (identity).

>>> import tempfile, os, numpy as np
>>> from studyapp.models.reference import build_reference_model
>>> model = StreamingGestureModel(build_reference_model(os.path.join(tempfile.mkdtemp(), "m.onnx")))
>>> model.step(np.zeros(model.spec.audio_dim, np.float32)).shape
(47, 6)
>>> model.run_sequence(np.zeros((5, model.spec.audio_dim), np.float32)).shape
(5, 47, 6)
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import onnxruntime as ort

from studyapp.errors import InputError
from studyapp.models import contract as C

IDENTITY_6D = np.array([1, 0, 0, 0, 1, 0], np.float32)
IDENTITY_QUAT = np.array([0, 0, 0, 1], np.float32)


def identity_rotations(n_joints: int, rotation: str) -> np.ndarray:
    """``(J, R)`` identity rotations in the contract representation (``"6d"`` or ``"quat"``)."""
    return np.tile(IDENTITY_6D if rotation == "6d" else IDENTITY_QUAT, (n_joints, 1))


def load_session(path: str | Path, threads: int = 1) -> ort.InferenceSession:
    """An onnxruntime CPU session; ``threads=1`` keeps a study PC's render loop free and latency steady."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, None, "model file not found")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = int(threads)
    opts.inter_op_num_threads = 1
    opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    opts.log_severity_level = 3
    try:
        return ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises several unrelated types for unreadable models
        raise InputError(path, None, f"onnxruntime cannot load the model: {exc}") from None


class StreamingGestureModel:
    """A loaded gesture model with its input windows and recurrent state.

    Parameters
    ----------
    path:
        The ``.onnx`` file; checked against :mod:`studyapp.models.contract` on load.
    threads:
        onnxruntime intra-op threads (1 by default).

    Attributes
    ----------
    spec:
        The model's :class:`~studyapp.models.contract.ModelSpec`.
    latencies_ms:
        Wall time of every :meth:`step` since construction or :meth:`reset` (window update, inference
        and state hand-over), in milliseconds.
    """

    def __init__(self, path: str | Path, threads: int = 1) -> None:
        self.path = Path(path)
        self.session = load_session(self.path, threads)
        self.spec = C.read_spec(self.session, self.path)
        self._outputs = [C.ROTATIONS] + [C.STATE_OUT + s for s in self.spec.states]
        self.latencies_ms: list[float] = []
        self.warm_up()

    def warm_up(self, steps: int = 3) -> None:
        """Run a few silent frames and :meth:`reset`, so the first real frame does not pay onnxruntime's
        first-run allocations (a live condition would stutter on frame 0 otherwise)."""
        self.reset()
        for _ in range(steps):
            self.step(np.zeros(self.spec.audio_dim, np.float32))
        self.reset()

    def reset(self) -> None:
        """Forget all history: empty windows, zero state, rest pose, no latencies."""
        s, w = self.spec, self.spec.window
        self._feeds: dict[str, np.ndarray] = {C.AUDIO: np.zeros((1, w, s.audio_dim), np.float32)}
        if s.takes(C.FACE):
            self._feeds[C.FACE] = np.zeros((1, w, C.N_ARKIT), np.float32)
        if s.takes(C.HEAD):
            self._feeds[C.HEAD] = np.tile(IDENTITY_6D, (1, w, 1))
        if s.takes(C.PREV_POSE):
            self._feeds[C.PREV_POSE] = identity_rotations(s.n_joints, s.rotation)[None]
        for name, shape in s.states.items():
            self._feeds[C.STATE_IN + name] = np.zeros(shape, np.float32)
        self.latencies_ms = []

    def _push(self, name: str, value: np.ndarray | None, width: int) -> None:
        buf = self._feeds.get(name)
        if buf is None:
            return
        buf[0, :-1] = buf[0, 1:]
        if value is None:  # no data for this frame: hold the last one
            return
        v = np.asarray(value, np.float32).reshape(-1)
        if v.size != width:
            raise InputError(None, f"input {name!r}", f"frame has {v.size} values, the model takes {width}")
        buf[0, -1] = v

    def step(self, features_t: np.ndarray, face_t: np.ndarray | None = None,
             head6d_t: np.ndarray | None = None) -> np.ndarray:
        """Rotations ``(J, R)`` for the next frame from that frame's inputs only.

        ``features_t`` is the ``(A,)`` audio feature row (columns in ``spec.audio_features`` order),
        ``face_t`` the ``(52,)`` ARKit weights and ``head6d_t`` the ``(6,)`` head rotation; inputs the model
        does not take are ignored, and ``None`` repeats the previous frame's value.
        """
        t0 = time.perf_counter()
        self._push(C.AUDIO, features_t, self.spec.audio_dim)
        self._push(C.FACE, face_t, C.N_ARKIT)
        self._push(C.HEAD, head6d_t, C.HEAD_WIDTH)
        outs = self.session.run(self._outputs, self._feeds)
        rot = outs[0]
        if rot.shape != (1, self.spec.n_joints, self.spec.rotation_width):
            raise InputError(self.path, f"output {C.ROTATIONS!r}",
                             f"returned shape {list(rot.shape)}, expected [1, {self.spec.n_joints}, {self.spec.rotation_width}]")
        for name, value in zip(self.spec.states, outs[1:]):
            self._feeds[C.STATE_IN + name] = value
        if C.PREV_POSE in self._feeds:
            self._feeds[C.PREV_POSE] = rot
        self.latencies_ms.append((time.perf_counter() - t0) * 1e3)
        return rot[0]

    def run_sequence(self, features: np.ndarray, face: np.ndarray | None = None, head6d: np.ndarray | None = None,
                     *, reset: bool = True) -> np.ndarray:
        """``(F, J, R)``: :meth:`step` over ``(F, A)`` features, ``(F, 52)`` face and ``(F, 6)`` head rows."""
        features = np.asarray(features, np.float32)
        n = features.shape[0]
        for name, arr, width in ((C.FACE, face, C.N_ARKIT), (C.HEAD, head6d, C.HEAD_WIDTH)):
            if arr is not None and np.shape(arr) != (n, width):
                raise InputError(None, name, f"shape {np.shape(arr)}, expected ({n}, {width}) to match the audio features")
        if features.ndim != 2 or features.shape[1] != self.spec.audio_dim:
            raise InputError(None, "audio features", f"shape {features.shape}, expected (frames, {self.spec.audio_dim})")
        if reset:
            self.reset()
        out = np.empty((n, self.spec.n_joints, self.spec.rotation_width), np.float32)
        for i in range(n):
            out[i] = self.step(features[i], None if face is None else face[i], None if head6d is None else head6d[i])
        return out

    def latency_summary(self) -> dict[str, float]:
        """Median, 99th percentile, max and mean of :attr:`latencies_ms`, and the frame count."""
        lat = np.asarray(self.latencies_ms, dtype=np.float64)
        if lat.size == 0:
            return {"frames": 0, "median_ms": float("nan"), "p99_ms": float("nan"), "max_ms": float("nan"),
                    "mean_ms": float("nan")}
        return {"frames": int(lat.size), "median_ms": float(np.median(lat)), "p99_ms": float(np.percentile(lat, 99)),
                "max_ms": float(lat.max()), "mean_ms": float(lat.mean())}
