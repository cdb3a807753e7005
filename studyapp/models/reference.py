"""A reference gesture model built in code with ``onnx.helper`` (no torch): **untrained**.

It is shaped like FaceCapGes -- an audio encoder (1D convolution over the feature window), a face
encoder, a head encoder and a previous-pose encoder feeding an LSTM decoder that emits 6D rotations for
the 47 BEAT upper-body joints -- with fixed-seed random weights. Its motion means nothing: it exists to
exercise the model contract end to end and to measure per-frame latency honestly, with the same
operators and sizes a real model of this kind has. The output is ``base 6D + 0.3 * tanh(...)`` where
the base pose is BEAT's T-pose with the arms lowered (:data:`BASE_POSE_DEG`), so the avatar moves a
little around a relaxed standing pose and always renders sensibly.

``python -m studyapp.models.reference OUT.onnx`` writes it; the bytes depend only on the code, so the copy
shipped in ``studyapp/models/data/`` can be checked against a fresh build.

>>> import tempfile, os, onnx
>>> path = build_reference_model(os.path.join(tempfile.mkdtemp(), "ref.onnx"))
>>> [i.name for i in onnx.load(path).graph.input]
['audio', 'face', 'head', 'prev_pose', 'state_in_h', 'state_in_c']
"""
from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from studyapp.models import contract as C

OPSET = 17
IR_VERSION = 8  # readable by onnxruntime >= 1.10
DESCRIPTION = ("Untrained reference model (fixed-seed random weights) shaped like FaceCapGes: audio conv encoder, "
               "face, head and previous-pose encoders, LSTM decoder, 6D output for the 47 BEAT upper-body joints. "
               "For testing the studyapp model contract and measuring latency only.")


@dataclass(frozen=True)
class ReferenceConfig:
    """Sizes of the reference model (defaults are the shipped model)."""

    fps: float = 15.0
    window: int = 8
    n_mels: int = 64
    n_joints: int = 47
    conv_channels: int = 64
    audio_hidden: int = 128
    face_hidden: int = 64
    head_hidden: int = 32
    pose_hidden: int = 64
    lstm_hidden: int = 256
    output_gain: float = 0.3
    seed: int = 20240607
    previous_pose: bool = True

    @property
    def audio_features(self) -> tuple[str, ...]:
        return (f"log_mel:{self.n_mels}", "energy", "f0")

    @property
    def audio_dim(self) -> int:
        return self.n_mels + 2


class _Graph:
    """Accumulates nodes and initializers with unique names."""

    def __init__(self, prefix: str = "") -> None:
        self.nodes: list[onnx.NodeProto] = []
        self.inits: list[onnx.TensorProto] = []
        self.prefix = prefix
        self._n = 0

    def name(self, base: str) -> str:
        self._n += 1
        return f"{self.prefix}{base}_{self._n}"

    def const(self, base: str, value: np.ndarray) -> str:
        name = self.name(base)
        self.inits.append(numpy_helper.from_array(np.asarray(value), name))
        return name

    def op(self, op_type: str, inputs: list[str], outputs: int | list[str] = 1, **attrs) -> list[str]:
        outs = [self.name(op_type.lower()) for _ in range(outputs)] if isinstance(outputs, int) else outputs
        self.nodes.append(helper.make_node(op_type, inputs, outs, name=self.name(op_type), **attrs))
        return outs

    def op1(self, op_type: str, inputs: list[str], **attrs) -> str:
        return self.op(op_type, inputs, 1, **attrs)[0]


def _weights(cfg: ReferenceConfig) -> dict[str, np.ndarray]:
    """Fixed-seed weights (Glorot-uniform matrices, small biases), float32."""
    rng = np.random.default_rng(cfg.seed)

    def glorot(n_out: int, n_in: int, gain: float = 1.0) -> np.ndarray:
        lim = gain * np.sqrt(6.0 / (n_in + n_out))
        return rng.uniform(-lim, lim, (n_out, n_in)).astype(np.float32)

    def bias(n: int) -> np.ndarray:
        return rng.uniform(-0.05, 0.05, n).astype(np.float32)

    w, a, j6 = cfg.window, cfg.audio_dim, cfg.n_joints * 6
    conv_w = cfg.window - 2
    h = cfg.lstm_hidden
    enc = cfg.audio_hidden + cfg.face_hidden + cfg.head_hidden + (cfg.pose_hidden if cfg.previous_pose else 0)
    # Rough standardisation of raw features: log-mel ~[-23, 5], energy ~[0, 0.3], f0 in Hz.
    shift = np.array([10.0] * cfg.n_mels + [0.0, 0.0], np.float32)
    scale = np.array([0.1] * cfg.n_mels + [10.0, 1.0 / 300.0], np.float32)
    return {
        "feat_shift": shift, "feat_scale": scale,
        "conv_w": (glorot(cfg.conv_channels, a * 3)).reshape(cfg.conv_channels, a, 3),
        "conv_b": bias(cfg.conv_channels),
        "audio_w": glorot(cfg.audio_hidden, cfg.conv_channels * conv_w), "audio_b": bias(cfg.audio_hidden),
        "face_w": glorot(cfg.face_hidden, w * C.N_ARKIT), "face_b": bias(cfg.face_hidden),
        "head_w": glorot(cfg.head_hidden, w * 6), "head_b": bias(cfg.head_hidden),
        "pose_w": glorot(cfg.pose_hidden, j6), "pose_b": bias(cfg.pose_hidden),
        # ONNX LSTM gate order is i, o, f, c.
        "lstm_w": glorot(4 * h, enc)[None], "lstm_r": glorot(4 * h, h)[None],
        "lstm_b": np.concatenate([bias(4 * h), bias(4 * h)])[None],
        "out_w": glorot(j6, h, gain=3.0), "out_b": bias(j6),
        "rest": base_pose_sixd(_joints(cfg)).reshape(-1),
    }


#: Local rotations (intrinsic XYZ Euler, degrees) that turn BEAT's T-pose into a relaxed pose: upper
#: arms lowered ~70 degrees, elbows bent 40 degrees forward (BEAT faces +Z, right arm along -X).
BASE_POSE_DEG = {
    "RightArm": (0.0, 0.0, 70.0), "LeftArm": (0.0, 0.0, -70.0),
    "RightForeArm": (0.0, 40.0, 0.0), "LeftForeArm": (0.0, -40.0, 0.0),
}


def base_pose_sixd(joints: tuple[str, ...]) -> np.ndarray:
    """``(J, 6)`` the pose the reference model moves around: identity except :data:`BASE_POSE_DEG`."""
    from studyapp.motion.rotations import euler_to_quat, quat_to_sixd

    euler = np.array([BASE_POSE_DEG.get(j, (0.0, 0.0, 0.0)) for j in joints])
    return quat_to_sixd(euler_to_quat(euler, "XYZ")).astype(np.float32)


def _core(g: _Graph, cfg: ReferenceConfig, wts: dict[str, np.ndarray], audio: str, face: str, head: str,
          prev: str | None, h0: str, c0: str) -> tuple[str, str, str]:
    """Encoders + LSTM + output head over ``N`` frames: 1 for a step, ``T`` for a whole sequence.

    The frames become the LSTM's time axis (batch 1), so a step is a sequence of length one and the
    whole-sequence graph computes the same recurrence. Returns (rotations [N, J, 6], h and c [1, 1, H]).
    """
    k = {n: g.const(n, v) for n, v in wts.items() if prev is not None or not n.startswith("pose_")}
    shape = lambda *dims: g.const("shape", np.array(dims, np.int64))  # noqa: E731
    a = g.op1("Mul", [g.op1("Add", [audio, k["feat_shift"]]), k["feat_scale"]])  # [N, W, A]
    a = g.op1("Transpose", [a], perm=[0, 2, 1])                                   # [N, A, W]
    a = g.op1("Relu", [g.op1("Conv", [a, k["conv_w"], k["conv_b"]], kernel_shape=[3])])  # [N, C, W-2]
    a = g.op1("Reshape", [a, shape(-1, cfg.conv_channels * (cfg.window - 2))])
    a = g.op1("Relu", [g.op1("Gemm", [a, k["audio_w"], k["audio_b"]], transB=1)])
    f = g.op1("Reshape", [face, shape(-1, cfg.window * C.N_ARKIT)])
    f = g.op1("Relu", [g.op1("Gemm", [f, k["face_w"], k["face_b"]], transB=1)])
    hd = g.op1("Reshape", [head, shape(-1, cfg.window * 6)])
    hd = g.op1("Relu", [g.op1("Gemm", [hd, k["head_w"], k["head_b"]], transB=1)])
    parts = [a, f, hd]
    if prev is not None:
        p = g.op1("Sub", [g.op1("Reshape", [prev, shape(-1, cfg.n_joints * 6)]), k["rest"]])
        parts.append(g.op1("Relu", [g.op1("Gemm", [p, k["pose_w"], k["pose_b"]], transB=1)]))
    x = g.op1("Concat", parts, axis=1)                                            # [N, E]
    x = g.op1("Unsqueeze", [x, g.const("axes", np.array([1], np.int64))])        # [N, 1, E]: seq N, batch 1
    y, h, c = g.op("LSTM", [x, k["lstm_w"], k["lstm_r"], k["lstm_b"], "", h0, c0], 3, hidden_size=cfg.lstm_hidden)
    y = g.op1("Reshape", [y, shape(-1, cfg.lstm_hidden)])                        # [N, H]
    y = g.op1("Tanh", [g.op1("Gemm", [y, k["out_w"], k["out_b"]], transB=1)])
    y = g.op1("Add", [g.op1("Mul", [y, g.const("gain", np.float32(cfg.output_gain))]), k["rest"]])
    rot = g.op1("Reshape", [y, shape(-1, cfg.n_joints, 6)])
    return rot, h, c


def _joints(cfg: ReferenceConfig) -> tuple[str, ...]:
    joints = C.default_joints()
    if cfg.n_joints != len(joints):
        raise ValueError(f"the reference model drives the {len(joints)} BEAT upper-body joints, got n_joints={cfg.n_joints}")
    return joints


def _finish(graph: onnx.GraphProto, cfg: ReferenceConfig, description: str) -> onnx.ModelProto:
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="studyapp.models.reference", producer_version=C.CONTRACT_VERSION)
    model.ir_version = IR_VERSION
    props = C.metadata_props(fps=cfg.fps, window=cfg.window, audio_features=cfg.audio_features, rotation="6d",
                             joints=_joints(cfg), description=description)
    helper.set_model_props(model, props)
    onnx.checker.check_model(model, full_check=True)
    return model


def _f32(name: str, shape: list) -> onnx.ValueInfoProto:
    return helper.make_tensor_value_info(name, TensorProto.FLOAT, shape)


def reference_model(cfg: ReferenceConfig = ReferenceConfig()) -> onnx.ModelProto:
    """The streaming (one frame a step) reference model as an ``onnx.ModelProto``."""
    g = _Graph()
    wts = _weights(cfg)
    h_shape = [1, 1, cfg.lstm_hidden]
    prev = C.PREV_POSE if cfg.previous_pose else None
    rot, h, c = _core(g, cfg, wts, C.AUDIO, C.FACE, C.HEAD, prev, "state_in_h", "state_in_c")
    g.op("Identity", [rot], [C.ROTATIONS])
    g.op("Identity", [h], ["state_out_h"])
    g.op("Identity", [c], ["state_out_c"])
    inputs = [_f32(C.AUDIO, [1, cfg.window, cfg.audio_dim]), _f32(C.FACE, [1, cfg.window, C.N_ARKIT]),
              _f32(C.HEAD, [1, cfg.window, 6])]
    if prev:
        inputs.append(_f32(C.PREV_POSE, [1, cfg.n_joints, 6]))
    inputs += [_f32("state_in_h", h_shape), _f32("state_in_c", h_shape)]
    outputs = [_f32(C.ROTATIONS, [1, cfg.n_joints, 6]), _f32("state_out_h", h_shape), _f32("state_out_c", h_shape)]
    graph = helper.make_graph(g.nodes, "reference_gesture", inputs, outputs, g.inits)
    return _finish(graph, cfg, DESCRIPTION)


def reference_sequence_model(cfg: ReferenceConfig = ReferenceConfig()) -> onnx.ModelProto:
    """The same network over a whole sequence at once, for checking the streaming runner.

    Inputs are pre-windowed: ``audio [T, W, A]``, ``face [T, W, 52]``, ``head [T, W, 6]``; output
    ``rotations [T, J, 6]``. Without a previous-pose input the frames become the LSTM's time axis (one
    LSTM call over ``T`` steps); with it, the output feeds back, so the step network runs inside a
    ``Scan`` that carries ``(h, c, previous pose)``. State starts at zero and the previous pose at rest.
    """
    wts = _weights(cfg)
    h_shape = [1, 1, cfg.lstm_hidden]
    t = "T"
    inputs = [_f32(C.AUDIO, [t, cfg.window, cfg.audio_dim]), _f32(C.FACE, [t, cfg.window, C.N_ARKIT]),
              _f32(C.HEAD, [t, cfg.window, 6])]
    outputs = [_f32(C.ROTATIONS, [t, cfg.n_joints, 6])]
    g = _Graph()
    zeros = g.const("h0", np.zeros(h_shape, np.float32))
    if not cfg.previous_pose:
        rot, _, _ = _core(g, cfg, wts, C.AUDIO, C.FACE, C.HEAD, None, zeros, zeros)
        g.op("Identity", [rot], [C.ROTATIONS])
    else:
        body = _Graph(prefix="body_")
        unsq = lambda x: body.op1("Unsqueeze", [x, body.const("axes", np.array([0], np.int64))])  # noqa: E731
        rot, h, c = _core(body, cfg, wts, unsq("a_t"), unsq("f_t"), unsq("hd_t"), "prev", "h", "c")
        body.op("Identity", [h], ["h_out"])
        body.op("Identity", [c], ["c_out"])
        body.op("Identity", [rot], ["prev_out"])
        body.op("Identity", [rot], ["rot_t"])
        body_graph = helper.make_graph(
            body.nodes, "step",
            [_f32("h", h_shape), _f32("c", h_shape), _f32("prev", [1, cfg.n_joints, 6]),
             _f32("a_t", [cfg.window, cfg.audio_dim]), _f32("f_t", [cfg.window, C.N_ARKIT]), _f32("hd_t", [cfg.window, 6])],
            [_f32("h_out", h_shape), _f32("c_out", h_shape), _f32("prev_out", [1, cfg.n_joints, 6]),
             _f32("rot_t", [1, cfg.n_joints, 6])],
            body.inits,
        )
        # The runner starts prev_pose at identity (the contract's rest pose), so the twin does too.
        rest = g.const("rest_pose", np.tile(np.array([1, 0, 0, 0, 1, 0], np.float32), (1, cfg.n_joints, 1)))
        _, _, _, stacked = g.op("Scan", [zeros, zeros, rest, C.AUDIO, C.FACE, C.HEAD], 4,
                                body=body_graph, num_scan_inputs=3)
        g.op("Reshape", [stacked, g.const("shape", np.array([-1, cfg.n_joints, 6], np.int64))], [C.ROTATIONS])
    graph = helper.make_graph(g.nodes, "reference_gesture_sequence", inputs, outputs, g.inits)
    return _finish(graph, cfg, "Whole-sequence twin of the reference model (for tests).")


def build_reference_model(path: str | Path, cfg: ReferenceConfig = ReferenceConfig()) -> Path:
    """Write the streaming reference model to ``path`` (parent folders are created) and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(reference_model(cfg).SerializeToString())
    return path


def shipped_reference_model() -> Path:
    """The reference model file that ships inside the package."""
    return Path(__file__).resolve().parent / "data" / "reference_gesture.onnx"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m studyapp.models.reference", description=__doc__.split("\n")[0])
    parser.add_argument("out", help="where to write the .onnx file")
    args = parser.parse_args(argv)
    path = build_reference_model(args.out)
    print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
