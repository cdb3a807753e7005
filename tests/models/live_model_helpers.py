"""Helpers for the live-model tests (a plain module: the tests folders are not packages)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from studyapp.models import contract as C

SR = 16000


def speech_like(seconds: float, sr: int = SR, seed: int = 0) -> np.ndarray:
    """A gliding harmonic 'voice' with syllable-rate loudness changes and a little noise."""
    t = np.arange(int(seconds * sr)) / sr
    f0 = 140 + 30 * np.sin(2 * np.pi * 0.4 * t)
    phase = 2 * np.pi * np.cumsum(f0) / sr
    voice = sum(a * np.sin(k * phase) for k, a in ((1, 0.3), (2, 0.15), (3, 0.08)))
    envelope = 0.5 + 0.5 * np.sin(2 * np.pi * 3.0 * t)
    noise = np.random.default_rng(seed).normal(0, 0.01, t.size)
    return (voice * envelope + noise).astype(np.float32)


def tiny_model(path: Path, inputs: dict[str, list], outputs: dict[str, list], meta: dict[str, str] | None,
               *, input_type: int = TensorProto.FLOAT, value: float = 0.0) -> Path:
    """A model with the given input/output names and shapes; every output is a constant ``value``.

    Lets contract tests write any (mis)shaped model in one line; ``meta`` None means no metadata.
    """
    nodes, inits = [], []
    for name, shape in outputs.items():
        static = [d if isinstance(d, int) else 1 for d in shape]
        inits.append(numpy_helper.from_array(np.full(static, value, np.float32), f"{name}_value"))
        nodes.append(helper.make_node("Identity", [f"{name}_value"], [name]))
    graph = helper.make_graph(
        nodes, "tiny",
        [helper.make_tensor_value_info(n, input_type, s) for n, s in inputs.items()],
        [helper.make_tensor_value_info(n, TensorProto.FLOAT, s) for n, s in outputs.items()],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    if meta:
        helper.set_model_props(model, meta)
    onnx.save(model, path)
    return path


def good_meta(**over: str) -> dict[str, str]:
    meta = C.metadata_props(fps=15, window=4, audio_features=["log_mel:8", "energy"], rotation="6d")
    meta.update(over)
    return {k: v for k, v in meta.items() if v is not None}
