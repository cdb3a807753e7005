"""The UI's Protocols (studyapp/ui/seams.py) state exactly what crosses each seam, and the real classes provide it.

Read from the source with :mod:`ast`: every attribute the screens and the trial view take from the app, and
every attribute the UI (and the offscreen driver, which holds the same session) takes from the session.
A Protocol member nobody uses, or a use the Protocol does not list, fails here; so does a member the real
:class:`StudyApp` or :class:`Session` lacks, or a method whose parameters differ.
"""
from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

import studyapp
from studyapp.study.session import Session
from studyapp.ui.seams import ParticipantSession, ScreenApp

PKG = Path(studyapp.__file__).resolve().parent


def protocol_members(proto: type) -> set[str]:
    names = set(getattr(proto, "__annotations__", {}))
    names |= {n for n, v in vars(proto).items()
              if not n.startswith("_") and (inspect.isfunction(v) or isinstance(v, property))}
    return names


def used_on(files: list[Path], holder: str) -> set[str]:
    """Attribute names read or written on ``holder`` (``holder.x``, ``self.holder.x``, ``app.holder.x``)."""
    used = set()
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Attribute):
                v = node.value
                if (isinstance(v, ast.Name) and v.id == holder) or (isinstance(v, ast.Attribute) and v.attr == holder):
                    used.add(node.attr)
    return used


SCREEN_FILES = sorted((PKG / "ui" / "screens").glob("*.py")) + [PKG / "ui" / "trial.py"]
SESSION_USERS = sorted((PKG / "ui").rglob("*.py")) + [PKG / "bots" / "ui_driver.py"]


def test_helpers_see_what_they_should(tmp_path: Path) -> None:
    src = tmp_path / "m.py"
    src.write_text("def f(app, session):\n    app.ui.text(app.scale)\n    self.app.clock = 1\n"
                   "    app.session.plays\n    session.close()\n    other.scale\n")
    assert used_on([src], "app") == {"ui", "scale", "clock", "session"}
    assert used_on([src], "session") == {"plays", "close"}

    class P(ParticipantSession):
        extra: int

    assert protocol_members(P) >= {"extra"}


def test_screen_app_lists_exactly_what_the_screens_use() -> None:
    used, listed = used_on(SCREEN_FILES, "app"), protocol_members(ScreenApp)
    assert used - listed == set(), "the screens use these, add them to ScreenApp"
    assert listed - used == set(), "ScreenApp lists these but no screen uses them"


def test_participant_session_lists_exactly_what_the_ui_uses() -> None:
    used, listed = used_on(SESSION_USERS, "session"), protocol_members(ParticipantSession)
    assert used - listed == set(), "the UI uses these, add them to ParticipantSession"
    assert listed - used == set(), "ParticipantSession lists these but the UI does not use them"


def _same_parameters(proto: type, impl: object, name: str) -> None:
    want = [p for p in inspect.signature(getattr(proto, name)).parameters if p != "self"]
    got = list(inspect.signature(getattr(impl, name)).parameters)
    assert got[: len(want)] == want, f"{name}: {got} does not start with {want}"


def test_the_session_provides_its_protocol(tiny_study) -> None:
    design, db = tiny_study
    session = Session(design, db, "S1")
    try:
        for name in sorted(protocol_members(ParticipantSession)):
            assert hasattr(session, name), name
            if inspect.isfunction(vars(ParticipantSession).get(name)):
                _same_parameters(ParticipantSession, session, name)
    finally:
        session.close()


@pytest.mark.gl
def test_the_app_provides_its_protocol(tiny_study, gl_ctx) -> None:
    from studyapp.audio.clock import SilentClock
    from studyapp.ui.app import StudyApp

    design, db = tiny_study
    session = Session(design, db, "S2")
    app = StudyApp(design, session, gl_ctx, SilentClock(virtual=True))
    try:
        for name in sorted(protocol_members(ScreenApp)):
            assert hasattr(app, name), name
            if inspect.isfunction(vars(ScreenApp).get(name)):
                _same_parameters(ScreenApp, app, name)
    finally:
        app.shutdown()
        session.close()


@pytest.mark.gl
def test_the_app_draws_before_the_audio_output_is_open_and_takes_it_once_open(tiny_study, gl_ctx, capsys) -> None:
    """An output still opening (studyapp run's PendingClock) holds up no frame; the app takes its clock after
    the first flip that finds it open, or at once when something needs the clock before that."""
    from studyapp.audio.clock import SilentClock
    from studyapp.audio.playback import PendingClock
    from studyapp.ui.app import StudyApp

    class Opening(PendingClock):  # no process: opens when the test says so
        def __init__(self) -> None:
            self.opened = False
            self.waited = 0
            self.clock = SilentClock(virtual=True)

        def done(self) -> bool:
            return self.opened

        def result(self):
            self.waited += 0 if self.opened else 1
            return self.clock, "audio output: Test (its latency is measured and compensated)"

    design, db = tiny_study
    fbo = gl_ctx.simple_framebuffer((640, 360))
    for needs_it_early in (False, True):
        session = Session(design, db, f"S{3 + needs_it_early}")
        opening = Opening()
        app = StudyApp(design, session, gl_ctx, opening)
        try:
            for k in range(3):
                app.frame(fbo, (640, 360), k / 60)
                app.after_flip(k / 60)
            assert app._pending_audio is opening and opening.waited == 0   # three frames, no wait
            if needs_it_early:
                assert app.clock is opening.clock and opening.waited == 1   # e.g. the sound check's tone
            else:
                opening.opened = True
                app.frame(fbo, (640, 360), 0.1)
                app.after_flip(0.1)
                assert app._pending_audio is None and opening.waited == 0
                assert app.clock is opening.clock
            assert capsys.readouterr().out.count("audio output: Test") == 1
        finally:
            app.shutdown()
            session.close()
