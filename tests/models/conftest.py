"""Fixtures for the live-model tests: the reference model, built once per run."""
from __future__ import annotations

from pathlib import Path

import pytest

from studyapp.models.reference import ReferenceConfig, build_reference_model


@pytest.fixture(scope="session")
def ref_model(tmp_path_factory) -> Path:
    return build_reference_model(tmp_path_factory.mktemp("models") / "reference.onnx")


@pytest.fixture(scope="session")
def ref_model_no_prev(tmp_path_factory) -> Path:
    return build_reference_model(tmp_path_factory.mktemp("models") / "reference_no_prev.onnx",
                                 ReferenceConfig(previous_pose=False))
