"""The contract between studyapp and a live ONNX gesture model (the full text is in ``CONTRACT.md``).

A model is run once per motion frame, causally. Its graph inputs are chosen by name:

================  ======================  ===================================================
input             shape                   content
================  ======================  ===================================================
``audio``         ``[1, W, A]``           audio features of frames ``t-W+1 .. t`` (required)
``face``          ``[1, W, 52]``          ARKit weights, Apple order, same frames (optional)
``head``          ``[1, W, 6]``           head rotation as 6D, same frames (optional)
``prev_pose``     ``[1, J, R]``           the model's own output at frame ``t-1`` (optional)
``state_in_X``    any static shape        recurrent state; fed from output ``state_out_X``
================  ======================  ===================================================

and it must output ``rotations`` ``[1, J, R]``: local rotations of the declared joints at frame ``t``
(``R`` = 6 for 6D, first two matrix columns; 4 for quaternions, x y z w), plus ``state_out_X`` for every
``state_in_X``. ``W``, ``A``, ``J``, ``R`` come from the model's ``metadata_props``:

* ``studyapp.fps`` (required): the frame rate the model was trained at, e.g. ``15``;
* ``studyapp.window`` (required): ``W``, frames per input window;
* ``studyapp.audio_features`` (required): comma-separated feature names in column order, e.g.
  ``log_mel:64,energy,f0`` (see :mod:`studyapp.audio.features`); ``A`` is their total width;
* ``studyapp.rotation`` (required): ``6d`` or ``quat``;
* ``studyapp.joints`` (optional): comma-separated BEAT joint names, default the 47 upper-body joints.

:func:`read_spec` checks a loaded model against all of this and raises :class:`~studyapp.errors.InputError`
naming the model file, the input/output or metadata key and the mismatch.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from studyapp.audio.features import parse_feature
from studyapp.errors import InputError

CONTRACT_VERSION = "1"

AUDIO, FACE, HEAD, PREV_POSE = "audio", "face", "head", "prev_pose"
ROTATIONS = "rotations"
STATE_IN, STATE_OUT = "state_in_", "state_out_"

META_FPS = "studyapp.fps"
META_WINDOW = "studyapp.window"
META_FEATURES = "studyapp.audio_features"
META_ROTATION = "studyapp.rotation"
META_JOINTS = "studyapp.joints"
META_CONTRACT = "studyapp.contract"

N_ARKIT = 52
HEAD_WIDTH = 6
ROTATION_WIDTHS = {"6d": 6, "quat": 4}
_ROTATION_ALIASES = {"6d": "6d", "sixd": "6d", "6D": "6d", "quat": "quat", "quaternion": "quat", "quat_xyzw": "quat"}
_FLOAT = "tensor(float)"


@dataclass(frozen=True)
class ModelSpec:
    """What a model declares and needs, read from its graph and metadata.

    Attributes
    ----------
    path:
        The model file (for messages and hashing).
    fps:
        Frame rate the model runs at.
    window:
        ``W``: frames of audio/face/head history per step (the current frame is the last row).
    audio_features:
        Feature names in column order (``"log_mel:64"``, ``"energy"``, ``"f0"``).
    audio_dim:
        ``A``: total feature width.
    rotation:
        ``"6d"`` or ``"quat"``.
    joints:
        Names of the joints the output rows drive, in row order.
    inputs:
        The contract inputs the model takes, a subset of ``audio, face, head, prev_pose``.
    states:
        ``{X: shape}`` for each ``state_in_X`` / ``state_out_X`` pair.
    metadata:
        All ``metadata_props`` of the model.
    """

    path: Path
    fps: float
    window: int
    audio_features: tuple[str, ...]
    audio_dim: int
    rotation: str
    joints: tuple[str, ...]
    inputs: tuple[str, ...]
    states: dict[str, tuple[int, ...]] = field(default_factory=dict)
    metadata: dict[str, str] = field(default_factory=dict)

    @property
    def rotation_width(self) -> int:
        return ROTATION_WIDTHS[self.rotation]

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    def takes(self, name: str) -> bool:
        """Whether the model has the contract input ``name`` (``"face"``, ``"head"``, ``"prev_pose"``)."""
        return name in self.inputs


def default_joints() -> tuple[str, ...]:
    """The 47 BEAT upper-body joints, the joint list a model gets when it declares none."""
    from studyapp.motion.beat import BEAT_UPPER_BODY

    return tuple(BEAT_UPPER_BODY)


def metadata_props(
    *, fps: float, window: int, audio_features: list[str] | tuple[str, ...], rotation: str,
    joints: list[str] | tuple[str, ...] | None = None, description: str = "",
) -> dict[str, str]:
    """The ``metadata_props`` a model exporter writes, as a dict of strings.

    >>> metadata_props(fps=15, window=8, audio_features=["log_mel:64", "energy"], rotation="6d")["studyapp.audio_features"]
    'log_mel:64,energy'
    """
    props = {
        META_CONTRACT: CONTRACT_VERSION,
        META_FPS: f"{float(fps):g}",
        META_WINDOW: str(int(window)),
        META_FEATURES: ",".join(audio_features),
        META_ROTATION: rotation,
    }
    if joints is not None:
        props[META_JOINTS] = ",".join(joints)
    if description:
        props["studyapp.description"] = description
    return props


def _meta_error(path: Path, key: str, problem: str) -> InputError:
    return InputError(path, f"metadata {key!r}", problem)


def _parse_metadata(path: Path, meta: dict[str, str]) -> tuple[float, int, tuple[str, ...], int, str, tuple[str, ...]]:
    for key in (META_FPS, META_WINDOW, META_FEATURES, META_ROTATION):
        if key not in meta or not meta[key].strip():
            raise _meta_error(path, key, f"missing; a studyapp model must declare {key} in its ONNX metadata_props "
                                         f"(see studyapp/models/CONTRACT.md)")
    try:
        fps = float(meta[META_FPS])
    except ValueError:
        raise _meta_error(path, META_FPS, f"{meta[META_FPS]!r} is not a number") from None
    if not (fps > 0 and fps < 1000):
        raise _meta_error(path, META_FPS, f"{fps} is not a usable frame rate")
    try:
        window = int(meta[META_WINDOW])
    except ValueError:
        raise _meta_error(path, META_WINDOW, f"{meta[META_WINDOW]!r} is not a whole number of frames") from None
    if window < 1:
        raise _meta_error(path, META_WINDOW, f"must be at least 1, got {window}")
    features = tuple(f.strip() for f in meta[META_FEATURES].split(",") if f.strip())
    width = 0
    for f in features:
        try:
            width += parse_feature(f)[1]
        except ValueError as exc:
            raise _meta_error(path, META_FEATURES, str(exc)) from None
    rotation = _ROTATION_ALIASES.get(meta[META_ROTATION].strip())
    if rotation is None:
        raise _meta_error(path, META_ROTATION, f"{meta[META_ROTATION]!r} is not one of '6d', 'quat'")
    if META_JOINTS in meta:
        joints = tuple(j.strip() for j in meta[META_JOINTS].split(",") if j.strip())
        if not joints:
            raise _meta_error(path, META_JOINTS, "is empty; leave it out to mean the 47 BEAT upper-body joints")
        dup = sorted({j for j in joints if joints.count(j) > 1})
        if dup:
            raise _meta_error(path, META_JOINTS, f"joints listed twice: {', '.join(dup)}")
        _check_beat_joints(path, joints)
    else:
        joints = default_joints()
    return fps, window, features, width, rotation, joints


def _check_beat_joints(path: Path, joints: tuple[str, ...]) -> None:
    from studyapp.motion.beat import beat_skeleton

    known = set(beat_skeleton().names)
    unknown = [j for j in joints if j not in known]
    if unknown:
        raise _meta_error(path, META_JOINTS, f"not joints of the BEAT skeleton: {', '.join(unknown[:8])}"
                                             + (" ..." if len(unknown) > 8 else ""))


def _fmt(shape: Any) -> str:
    return "[" + ", ".join("?" if not isinstance(d, int) else str(d) for d in shape) + "]"


def _check_shape(path: Path, kind: str, name: str, actual: list[Any], expected: list[int], why: str) -> None:
    """``actual`` may use symbolic/None dims for the leading batch axis only."""
    ok = len(actual) == len(expected) and all(
        (a == e) or (i == 0 and not isinstance(a, int)) for i, (a, e) in enumerate(zip(actual, expected))
    )
    if not ok:
        raise InputError(path, f"{kind} {name!r}", f"shape {_fmt(actual)} but the contract needs {_fmt(expected)} ({why})")


def read_spec(session: Any, path: str | Path) -> ModelSpec:
    """Check an ``onnxruntime.InferenceSession`` against the contract and return its :class:`ModelSpec`."""
    path = Path(path)
    meta = dict(session.get_modelmeta().custom_metadata_map)
    fps, window, features, width, rotation, joints = _parse_metadata(path, meta)
    n_joints, rwidth = len(joints), ROTATION_WIDTHS[rotation]
    known = {
        AUDIO: ([1, window, width], f"window {window} from {META_WINDOW} x {width} audio feature columns from "
                                    f"{META_FEATURES} {meta[META_FEATURES]!r}"),
        FACE: ([1, window, N_ARKIT], f"window {window} x {N_ARKIT} ARKit blendshapes"),
        HEAD: ([1, window, HEAD_WIDTH], f"window {window} x 6D head rotation"),
        PREV_POSE: ([1, n_joints, rwidth], f"{n_joints} joints x {rwidth} numbers for rotation {rotation!r}"),
    }
    inputs: list[str] = []
    states_in: dict[str, list[Any]] = {}
    for arg in session.get_inputs():
        if arg.type != _FLOAT:
            raise InputError(path, f"input {arg.name!r}", f"type {arg.type} but the contract uses float32 ({_FLOAT})")
        if arg.name.startswith(STATE_IN):
            if not all(isinstance(d, int) and d > 0 for d in arg.shape):
                raise InputError(path, f"input {arg.name!r}", f"state shape {_fmt(arg.shape)} must be fully static")
            states_in[arg.name[len(STATE_IN):]] = list(arg.shape)
        elif arg.name in known:
            _check_shape(path, "input", arg.name, list(arg.shape), *known[arg.name])
            inputs.append(arg.name)
        else:
            raise InputError(path, f"input {arg.name!r}", "is not a contract input; expected "
                             f"{', '.join(known)} or {STATE_IN}<name> (see studyapp/models/CONTRACT.md)")
    if AUDIO not in inputs:
        raise InputError(path, f"input {AUDIO!r}", "missing; every studyapp gesture model takes audio features")
    outputs = {o.name: o for o in session.get_outputs()}
    if ROTATIONS not in outputs:
        raise InputError(path, f"output {ROTATIONS!r}", f"missing; the model's outputs are {', '.join(outputs) or 'none'}")
    out = outputs[ROTATIONS]
    if out.type != _FLOAT:
        raise InputError(path, f"output {ROTATIONS!r}", f"type {out.type} but the contract uses float32")
    _check_shape(path, "output", ROTATIONS, list(out.shape), [1, n_joints, rwidth],
                 f"{n_joints} joints from {META_JOINTS if META_JOINTS in meta else 'the default 47 BEAT upper-body joints'}"
                 f" x {rwidth} for rotation {rotation!r}")
    for name, shape in states_in.items():
        o = outputs.get(STATE_OUT + name)
        if o is None:
            raise InputError(path, f"output {STATE_OUT + name!r}", f"missing; input {STATE_IN + name!r} needs it to carry state")
        _check_shape(path, "output", o.name, list(o.shape), shape, f"the shape of input {STATE_IN + name!r}")
    for name in outputs:
        if name.startswith(STATE_OUT) and name[len(STATE_OUT):] not in states_in:
            raise InputError(path, f"output {name!r}", f"has no matching input {STATE_IN + name[len(STATE_OUT):]!r}")
    return ModelSpec(
        path=path, fps=fps, window=window, audio_features=features, audio_dim=width, rotation=rotation,
        joints=joints, inputs=tuple(inputs), states={k: tuple(v) for k, v in states_in.items()}, metadata=meta,
    )
