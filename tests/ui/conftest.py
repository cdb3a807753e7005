"""Fixtures for the participant UI tests: a GL context, a tiny study, a virtual X display."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time

import pytest

# the tiny studies are shared with the scripted participant's tests (tests/bots)
from fixtures.studies import secrets_of, tied_study, tiny_study  # noqa: F401


@pytest.fixture(scope="session")
def gl_ctx():
    from studyapp.render.context import create_offscreen_context

    try:
        return create_offscreen_context()
    except Exception as exc:  # no EGL/OSMesa: the GL tests cannot run here
        pytest.skip(f"no headless OpenGL context: {exc}")


@pytest.fixture(scope="module")
def xvfb_display():
    """A private Xvfb display (1280x800x24) for the window tests; DISPLAY is set while the module runs.

    One display per module, not per test: GLFW stays initialised on the X display it opened, so the
    display lives as long as the module's windows, and GLFW is shut down with it (the next module's
    windows then open on that module's own display).
    """
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (apt install xvfb)")
    for n in range(140, 200):
        if not os.path.exists(f"/tmp/.X11-unix/X{n}") and not os.path.exists(f"/tmp/.X{n}-lock"):
            break
    proc = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", "1280x800x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for _ in range(100):
        if os.path.exists(f"/tmp/.X11-unix/X{n}"):
            break
        time.sleep(0.05)
    old = os.environ.get("DISPLAY")
    os.environ["DISPLAY"] = f":{n}"
    try:
        yield f":{n}"
    finally:
        if "glfw" in sys.modules:
            sys.modules["glfw"].terminate()  # else GLFW keeps talking to this display once it is gone
        if old is None:
            os.environ.pop("DISPLAY", None)
        else:
            os.environ["DISPLAY"] = old
        proc.terminate()
        proc.wait(timeout=10)
