"""Live model conditions: run an ONNX gesture model over a stimulus and get BEAT-skeleton motion.

The model runs causally, one frame at a time, exactly as it would beside a live speaker
(:class:`~studyapp.models.runner.StreamingGestureModel`); the result is cached on disk under a key made
of the model file's hash and the input data's hashes, so a study session that shows the same stimulus
again (or a second session on the same PC) gets it at once.

Cache folder: ``$STUDYAPP_CACHE_DIR`` if set, else the platform's user cache (``$XDG_CACHE_HOME/studyapp``
or ``~/.cache/studyapp`` on Linux, ``~/Library/Caches/studyapp`` on macOS, ``%LOCALAPPDATA%\\studyapp\\Cache``
on Windows), sub-folder ``models/``. Deleting it is always safe.
"""
from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import platformdirs

from studyapp.audio.features import compute_features, n_feature_frames
from studyapp.audio.wav import AudioClip
from studyapp.errors import InputError
from studyapp.face.animation import FaceAnimation
from studyapp.models import contract as C
from studyapp.models.runner import StreamingGestureModel
from studyapp.motion import rotations as rot
from studyapp.motion.skeleton import Motion, Skeleton
from studyapp.safe_io import open_npz, require

log = logging.getLogger(__name__)

#: Bumped whenever feature extraction or input assembly changes, so stale cache entries are never used.
CACHE_FORMAT = "studyapp-live-1"

#: How many times a model has actually been run by :func:`generate` in this process (tests read it).
RUN_COUNT = 0


def cache_dir() -> Path:
    """The folder generated motion is cached in (created on first use)."""
    env = os.environ.get("STUDYAPP_CACHE_DIR")
    base = Path(env) if env else Path(platformdirs.user_cache_dir("studyapp", appauthor=False))
    return base / "models"


def head_to_sixd(head: np.ndarray) -> np.ndarray:
    """``(F, 3)`` head yaw, pitch, roll (radians) to ``(F, 6)`` 6D rotations.

    Yaw turns about +Y (up), pitch about +X, roll about +Z, applied intrinsically in that order
    (``R = R_Y(yaw) R_X(pitch) R_Z(roll)``), the usual head convention of ARKit / Live Link Face.

    >>> head_to_sixd(np.zeros((1, 3))).tolist()
    [[1.0, 0.0, 0.0, 0.0, 1.0, 0.0]]
    """
    head = np.asarray(head, dtype=np.float64).reshape(-1, 3)
    return rot.quat_to_sixd(rot.euler_to_quat(head, "YXZ", degrees=False))


@dataclass
class ModelInputs:
    """Per-frame model inputs for a stimulus, at the model's frame rate.

    ``features`` ``(F, A)``; ``face`` ``(F, 52)`` or None; ``head6d`` ``(F, 6)`` or None.
    """

    features: np.ndarray
    face: np.ndarray | None
    head6d: np.ndarray | None
    fps: float

    @property
    def n_frames(self) -> int:
        return int(self.features.shape[0])


def stimulus_inputs(spec: C.ModelSpec, audio: AudioClip, face: FaceAnimation | None = None,
                    head: np.ndarray | None = None, fps: float | None = None) -> ModelInputs:
    """Assemble a model's inputs for a stimulus, one row per frame at ``fps`` (default the model's).

    There are ``ceil(audio duration * fps)`` frames. The face is sampled at the frame times (linear,
    held past its ends). ``head`` is ``(H, 3)`` yaw/pitch/roll radians at the face's frame rate (the
    model's when there is no face); without it the face's own head rotation is used, else none.
    """
    fps = float(fps or spec.fps)
    mono = audio.mono()
    n = n_feature_frames(mono.size, audio.sample_rate, fps)
    feats = compute_features(spec.audio_features, mono, audio.sample_rate, fps, n_frames=n)
    features = np.concatenate([feats[name] for name in spec.audio_features], axis=1).astype(np.float32)
    times = np.arange(n) / fps
    face_rows = face.sample(times) if face is not None else None
    head6d = None
    if head is not None:
        head = np.asarray(head, dtype=np.float64)
        if head.ndim != 2 or head.shape[1] != 3:
            raise InputError(None, "head rotation", f"shape {head.shape}, expected (frames, 3) yaw/pitch/roll in radians")
        src_fps = face.fps if face is not None else fps
        idx = np.clip(times * src_fps, 0, max(head.shape[0] - 1, 0))
        i0 = np.floor(idx).astype(np.int64)
        i1 = np.minimum(i0 + 1, head.shape[0] - 1)
        frac = (idx - i0)[:, None]
        head6d = head_to_sixd(head[i0] * (1 - frac) + head[i1] * frac).astype(np.float32)
    elif face is not None and face.head_rotation is not None:
        head6d = head_to_sixd(face.sample_head(times)).astype(np.float32)
    return ModelInputs(features, face_rows, head6d, fps)


def generate(model: StreamingGestureModel | str | Path, inputs: ModelInputs) -> np.ndarray:
    """Run the model causally over ``inputs``; ``(F, J, R)`` raw output (latencies stay on the model)."""
    global RUN_COUNT
    if not isinstance(model, StreamingGestureModel):
        model = StreamingGestureModel(model)
    RUN_COUNT += 1
    out = model.run_sequence(inputs.features, inputs.face, inputs.head6d)
    if not np.isfinite(out).all():
        bad = int(np.argmax(~np.isfinite(out).reshape(out.shape[0], -1).all(axis=1)))
        raise InputError(model.path, f"output {C.ROTATIONS!r}", f"non-finite values from frame {bad} on")
    return out


def output_to_quat(output: np.ndarray, rotation: str) -> np.ndarray:
    """``(F, J, R)`` model output to unit quaternions ``(F, J, 4)``."""
    if rotation == "6d":
        return rot.sixd_to_quat(output)
    return rot.quat_normalize(output)


def to_beat_motion(output: np.ndarray, spec: C.ModelSpec, fps: float, template: Motion | Skeleton | None = None,
                   source: str = "") -> Motion:
    """Model output on the declared joints -> :class:`Motion` on the BEAT skeleton.

    The 47 upper-body joints go through ``beat_motion_from_upper_body`` (joints the model does not
    drive stay at rest); declared joints outside the upper body are set afterwards. ``template`` is a
    BEAT-layout skeleton, or a motion whose skeleton and first-frame hips position are used (e.g. a
    recorded clip of the same speaker, so the generated avatar stands where the recorded one does).
    """
    from studyapp.motion.beat import BEAT_UPPER_BODY, beat_motion_from_upper_body

    quats = output_to_quat(output, spec.rotation)
    n = quats.shape[0]
    upper = np.zeros((n, len(BEAT_UPPER_BODY), 4))
    upper[..., 3] = 1.0
    index = {name: i for i, name in enumerate(BEAT_UPPER_BODY)}
    extra = []
    for j, name in enumerate(spec.joints):
        if name in index:
            upper[:, index[name]] = quats[:, j]
        else:
            extra.append((j, name))
    if isinstance(template, Motion):
        motion = beat_motion_from_upper_body(upper, fps, root=template.translations[0, 0], skeleton=template.skeleton)
    else:
        motion = beat_motion_from_upper_body(upper, fps, skeleton=template)
    for j, name in extra:
        motion.rotations[:, motion.skeleton.index(name)] = quats[:, j]
    motion.source = source or str(spec.path)
    return motion


def _hash_array(h: "hashlib._Hash", label: str, a: np.ndarray | None, *extra: object) -> None:
    h.update(label.encode())
    if a is None:
        h.update(b"none")
        return
    a = np.ascontiguousarray(a)
    h.update(f"{a.dtype.str}{a.shape}{extra}".encode())
    h.update(a.tobytes())


def cache_key(model_path: str | Path, audio: AudioClip, face: FaceAnimation | None, head: np.ndarray | None) -> str:
    """Hex key from the model file's bytes and the stimulus data (not file names or times)."""
    h = hashlib.sha256(CACHE_FORMAT.encode())
    h.update(hashlib.sha256(Path(model_path).read_bytes()).digest())
    _hash_array(h, "audio", audio.samples, audio.sample_rate)
    _hash_array(h, "face", None if face is None else face.weights, None if face is None else face.fps)
    _hash_array(h, "face_head", None if face is None else face.head_rotation)
    _hash_array(h, "head", None if head is None else np.asarray(head, np.float64))
    return h.hexdigest()


def _save_atomic(path: Path, **arrays: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp.npz")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
        os.replace(tmp, path)  # readers never see half a file
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def motion_for_stimulus(model_path: str | Path, audio: AudioClip, face: FaceAnimation | None = None,
                        head: np.ndarray | None = None, template: Motion | Skeleton | None = None) -> Motion:
    """BEAT-skeleton motion a model generates for a stimulus, streamed frame by frame, cached on disk.

    ``head`` is ``(H, 3)`` yaw/pitch/roll radians at the face's frame rate (see :func:`stimulus_inputs`);
    ``template`` (a BEAT-layout skeleton or motion) sets the skeleton and hips position, see
    :func:`to_beat_motion`; it does not change the model's output, so it is not part of the cache key.
    The motion has ``ceil(audio duration * model fps)`` frames at the model's frame rate.
    """
    model_path = Path(model_path)
    if not model_path.is_file():
        raise InputError(model_path, None, "model file not found")
    path = cache_dir() / f"{cache_key(model_path, audio, face, head)}.npz"
    model = StreamingGestureModel(model_path)
    spec = model.spec
    output = None
    if path.is_file():
        try:
            with open_npz(path) as z:
                output = require(z["rotations"], path, "key rotations", shape=(None, spec.n_joints, spec.rotation_width))
            log.debug("live model cache hit: %s", path)
        except InputError as exc:  # a damaged entry is regenerated, never fatal
            log.warning("ignoring unreadable cache entry: %s", exc)
            output = None
    if output is None:
        inputs = stimulus_inputs(spec, audio, face, head)
        output = generate(model, inputs)
        _save_atomic(path, rotations=output)
        lat = model.latency_summary()
        log.info("generated %d frames with %s (median %.3f ms/frame); cached in %s",
                 output.shape[0], model_path.name, lat["median_ms"], path)
    return to_beat_motion(output, spec, spec.fps, template, source=f"{model_path} (live)")
