"""Fixtures for the renderer tests: one headless GL context and renderer, the built-in avatar, Xvfb."""
from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from studyapp.render.avatar import build_default_avatar


@pytest.fixture(scope="session")
def avatar():
    return build_default_avatar()


@pytest.fixture(scope="session")
def _session_ctx():
    from studyapp.render.context import create_offscreen_context

    return create_offscreen_context()


@pytest.fixture()
def gl_ctx(_session_ctx):
    # Made current for every test: tests of the CLI create contexts of their own, which become current and
    # would leave later draws on the shared context pointing at another context's objects (a crash in Mesa).
    with _session_ctx:
        yield _session_ctx


@pytest.fixture(scope="session")
def _session_renderer(_session_ctx):
    from studyapp.render.renderer import Renderer

    # Made current here too: a session fixture is set up before the test's gl_ctx enters, while whatever
    # context an earlier test left current (another test file's own context) still is.
    with _session_ctx:
        return Renderer(_session_ctx)


@pytest.fixture()
def renderer(gl_ctx, _session_renderer):
    return _session_renderer


def _free_display() -> int:
    for n in range(90, 140):
        if not Path(f"/tmp/.X11-unix/X{n}").exists() and not Path(f"/tmp/.X{n}-lock").exists():
            return n
    raise RuntimeError("no free X display number")


@pytest.fixture(scope="session")
def xvfb_display():
    """Start Xvfb on a free display for window tests (skips only when Xvfb is not installed)."""
    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb) -- window tests need an X server")
    n = _free_display()
    proc = subprocess.Popen([exe, f":{n}", "-screen", "0", "1280x1024x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 10
    while not Path(f"/tmp/.X11-unix/X{n}").exists():
        if proc.poll() is not None or time.time() > deadline:
            proc.kill()
            raise RuntimeError(f"Xvfb :{n} did not start")
        time.sleep(0.05)
    old = os.environ.get("DISPLAY")
    os.environ["DISPLAY"] = f":{n}"
    yield f":{n}"
    if old is None:
        os.environ.pop("DISPLAY", None)
    else:
        os.environ["DISPLAY"] = old
    proc.terminate()
    try:
        proc.wait(5)
    except subprocess.TimeoutExpired:
        proc.kill()
