"""`validate` fills the GL driver's shader cache with what a participant's first trial frame draws
(studyapp.render.warmup), so that frame compiles nothing; with no GL it does nothing and says why."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from studyapp.resources import demo_design

FIRST_FRAME = r"""
from studyapp.render.context import create_offscreen_context
from studyapp.render.renderer import Renderer
from studyapp.render.scene import build_trial_scene
from studyapp.resources import demo_design
from studyapp.study.design import load_design
from studyapp.study.schedule import participant_schedule
from studyapp.study.stimuli import load_trial_media
design = load_design(demo_design(), reuse_check=True)
plan = [p for p in participant_schedule(design, "P01", row=0) if not p.is_practice][0]
ctx = create_offscreen_context()
renderer = Renderer(ctx)
scene = build_trial_scene(renderer, load_trial_media(design, plan))
# as the participant window's scene cache draws a 1280x720 trial frame above its 84-pixel answer footer
renderer.draw_canvas(scene, 0.0, (1280, 720), (0, 84, 1280, 636), (0.11, 0.12, 0.14))
ctx.finish()
"""


def _cache_files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file()} if folder.is_dir() else set()


def test_validate_compiles_what_the_first_trial_frame_draws(tmp_path):
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "xdg"), "STUDYAPP_CACHE_DIR": str(tmp_path / "app")}
    for var in ("MESA_SHADER_CACHE_DIR", "MESA_GLSL_CACHE_DIR", "MESA_SHADER_CACHE_DISABLE", "MESA_GLSL_CACHE_DISABLE"):
        env.pop(var, None)
    mesa = tmp_path / "xdg" / "mesa_shader_cache"
    run = subprocess.run([sys.executable, "-m", "studyapp.cli", "validate", str(demo_design())], env=env,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "OK, the design can run." in run.stdout
    warmed = _cache_files(mesa)
    assert warmed, "validate left the driver's shader cache empty"
    assert list((tmp_path / "app" / "gl-warm").iterdir()), "no warm-up record"
    # the participant's first trial frame (another process) finds every program compiled: it adds nothing
    subprocess.run([sys.executable, "-c", FIRST_FRAME], env=env, check=True, capture_output=True, timeout=300)
    assert _cache_files(mesa) == warmed
    # a second validate finds the record and leaves the cache as it is
    subprocess.run([sys.executable, "-m", "studyapp.cli", "validate", str(demo_design())], env=env, check=True,
                   capture_output=True, timeout=300)
    assert _cache_files(mesa) == warmed


def test_warm_up_with_no_gl_context_does_nothing(tmp_path, monkeypatch, avatar):
    from studyapp.render import context, warmup

    def no_gl():
        raise context.ContextError("no EGL here")

    monkeypatch.setattr(context, "create_offscreen_context", no_gl)
    monkeypatch.setenv("STUDYAPP_CACHE_DIR", str(tmp_path / "app"))
    assert warmup.warm_shader_cache([avatar], [None]) == "no offscreen GL context (ContextError)"
    assert not warmup.warm_record([None]).exists()
    assert not warmup.is_warm([None])


def test_warm_record_follows_the_driver_cache_folder_and_avatar_files(tmp_path, monkeypatch):
    from studyapp.render import warmup

    monkeypatch.setenv("STUDYAPP_CACHE_DIR", str(tmp_path / "app"))
    monkeypatch.delenv("MESA_SHADER_CACHE_DIR", raising=False)
    monkeypatch.delenv("MESA_GLSL_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "a"))
    builtin = warmup.warm_record([None])
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "b"))
    assert warmup.warm_record([None]) != builtin  # another driver cache: warm again
    model = tmp_path / "model.glb"
    model.write_bytes(b"x")
    first = warmup.warm_record([None, model])
    model.write_bytes(b"xy")
    assert warmup.warm_record([None, model]) != first  # a changed avatar file: warm again
