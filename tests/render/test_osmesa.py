"""The OSMesa fallback renders the same trial as EGL (run in subprocesses: one GL platform per process)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

SCRIPT = r"""
import sys
from matplotlib.image import imread
from studyapp.render.context import create_offscreen_context
from studyapp.render.renderer import Renderer
from studyapp.render.scene import build_trial_scene
from studyapp.render.video import render_still
from studyapp.resources import demo_design
from studyapp.study.design import load_design
from studyapp.study.schedule import participant_schedule
from studyapp.study.stimuli import load_trial_media

ctx = create_offscreen_context()
print("RENDERER", ctx.info["GL_RENDERER"], "GLFW" if "glfw" in sys.modules else "EGL")
design = load_design(demo_design(), check_files=False)
plan = participant_schedule(design, "P01")[1]
scene = build_trial_scene(Renderer(ctx), load_trial_media(design, plan))
render_still(scene, 1.5, sys.argv[1], size=(480, 270))
"""


def _render(out: Path, backend: str) -> str:
    env = {**os.environ, "STUDYAPP_OFFSCREEN": backend}
    done = subprocess.run([sys.executable, "-c", SCRIPT, str(out)], env=env, capture_output=True, text=True,
                          timeout=300)
    if done.returncode != 0 and backend == "osmesa" and "OSMesa" in done.stderr and "libOSMesa" in done.stderr:
        pytest.skip("libosmesa6 is not installed")
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_osmesa_fallback_renders_the_same_trial_as_egl(tmp_path: Path) -> None:
    from matplotlib.image import imread

    said = _render(tmp_path / "osmesa.png", "osmesa")
    assert "RENDERER" in said and "GLFW" in said, said  # the context really came from GLFW's OSMesa path
    _render(tmp_path / "egl.png", "")
    a = (imread(tmp_path / "osmesa.png")[..., :3] * 255).astype(np.int16)
    b = (imread(tmp_path / "egl.png")[..., :3] * 255).astype(np.int16)
    assert a.shape == b.shape == (270, 480, 3)
    # three figures: each third differs from the plain background in its middle columns
    for k in range(3):
        third = a[:, k * 160:(k + 1) * 160]
        assert (np.abs(third - third[5:6, 5:6]).sum(-1) > 60).mean() > 0.05
    assert np.abs(a - b).mean() < 1.0, "OSMesa and EGL frames differ"
