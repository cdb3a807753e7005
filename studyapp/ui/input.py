"""All input reaches Dear ImGui through this one queue.

GLFW callbacks (the real window), the offscreen bot and tests push the same events here, so the bot
and the tests exercise exactly the code path a participant's mouse and keyboard take. Coordinates are
framebuffer pixels (the UI works in pixels and scales itself; see :mod:`studyapp.ui.layer`), so GLFW's
cursor positions (screen coordinates) are multiplied by the framebuffer/window ratio on HiDPI screens.

Example (no window needed):

>>> q = InputQueue()
>>> q.mouse_move(10, 20); q.mouse_button(0, True); q.focus(False)
>>> [e.kind for e in q.pending()]
['pos', 'button', 'focus']
>>> q.focused
False
"""
from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class InputEvent:
    """One input event: ``kind`` is pos / button / key / char / scroll / focus."""

    kind: str
    a: Any = None
    b: Any = None


def _glfw_key_map() -> dict[int, Any]:
    import glfw
    from imgui_bundle import imgui

    K = imgui.Key
    m = {
        glfw.KEY_TAB: K.tab, glfw.KEY_LEFT: K.left_arrow, glfw.KEY_RIGHT: K.right_arrow,
        glfw.KEY_UP: K.up_arrow, glfw.KEY_DOWN: K.down_arrow, glfw.KEY_PAGE_UP: K.page_up,
        glfw.KEY_PAGE_DOWN: K.page_down, glfw.KEY_HOME: K.home, glfw.KEY_END: K.end,
        glfw.KEY_INSERT: K.insert, glfw.KEY_DELETE: K.delete, glfw.KEY_BACKSPACE: K.backspace,
        glfw.KEY_SPACE: K.space, glfw.KEY_ENTER: K.enter, glfw.KEY_ESCAPE: K.escape,
        glfw.KEY_KP_ENTER: K.keypad_enter, glfw.KEY_LEFT_SHIFT: K.left_shift,
        glfw.KEY_RIGHT_SHIFT: K.right_shift, glfw.KEY_LEFT_CONTROL: K.left_ctrl,
        glfw.KEY_RIGHT_CONTROL: K.right_ctrl, glfw.KEY_LEFT_ALT: K.left_alt, glfw.KEY_RIGHT_ALT: K.right_alt,
        glfw.KEY_LEFT_SUPER: K.left_super, glfw.KEY_RIGHT_SUPER: K.right_super, glfw.KEY_F11: K.f11,
    }
    for i in range(10):
        m[glfw.KEY_0 + i] = digit_key(i)
        m[glfw.KEY_KP_0 + i] = getattr(K, f"keypad{i}")
    for i, ch in enumerate("abcdefghijklmnopqrstuvwxyz"):
        m[glfw.KEY_A + i] = getattr(K, ch)
    return {k: v for k, v in m.items() if v is not None}


def digit_key(i: int) -> Any:
    """The ImGui key of the digit ``i`` (top row; the binding names them ``Key._0`` .. ``Key._9``)."""
    from imgui_bundle import imgui

    return getattr(imgui.Key, f"_{i}")


_MOD_KEYS = None


def _mod_for(key: Any) -> Any:
    global _MOD_KEYS
    from imgui_bundle import imgui

    if _MOD_KEYS is None:
        K = imgui.Key
        _MOD_KEYS = {
            K.left_shift: K.mod_shift, K.right_shift: K.mod_shift, K.left_ctrl: K.mod_ctrl,
            K.right_ctrl: K.mod_ctrl, K.left_alt: K.mod_alt, K.right_alt: K.mod_alt,
            K.left_super: K.mod_super, K.right_super: K.mod_super,
        }
    return _MOD_KEYS.get(key)


class InputQueue:
    """A FIFO of input events, fed by GLFW or synthesized, drained into ImGui once per frame."""

    def __init__(self) -> None:
        self._events: deque[InputEvent] = deque()
        self.focused = True
        #: Called with ``False``/``True`` when the window loses/gains focus (the app pauses playback).
        self.on_focus: Callable[[bool], None] | None = None
        self.mouse_pos = (-1.0, -1.0)
        self._key_map: dict[int, Any] | None = None

    # -- synthesized events (bot, tests) and the GLFW callbacks both end here --------------------
    def mouse_move(self, x: float, y: float) -> None:
        self.mouse_pos = (float(x), float(y))
        self._events.append(InputEvent("pos", float(x), float(y)))

    def mouse_button(self, button: int, down: bool) -> None:
        self._events.append(InputEvent("button", int(button), bool(down)))

    def key(self, imgui_key: Any, down: bool) -> None:
        self._events.append(InputEvent("key", imgui_key, bool(down)))

    def char(self, codepoint: int | str) -> None:
        cp = ord(codepoint) if isinstance(codepoint, str) else int(codepoint)
        self._events.append(InputEvent("char", cp))

    def scroll(self, dx: float, dy: float) -> None:
        self._events.append(InputEvent("scroll", float(dx), float(dy)))

    def focus(self, focused: bool) -> None:
        self.focused = bool(focused)
        self._events.append(InputEvent("focus", bool(focused)))
        if self.on_focus is not None:
            self.on_focus(bool(focused))

    # -- convenience for scripted input --------------------------------------------------------
    def click(self, x: float, y: float, button: int = 0) -> None:
        """Move, press and release (ImGui's trickled queue spreads these over frames)."""
        self.mouse_move(x, y)
        self.mouse_button(button, True)
        self.mouse_button(button, False)

    def tap(self, imgui_key: Any) -> None:
        self.key(imgui_key, True)
        self.key(imgui_key, False)

    def type_text(self, text: str) -> None:
        for ch in text:
            self.char(ch)

    def pending(self) -> list[InputEvent]:
        return list(self._events)

    def __len__(self) -> int:
        return len(self._events)

    # -- draining ----------------------------------------------------------------------------------
    def apply(self, io: Any) -> int:
        """Hand every queued event to ImGui's ``io`` (in order); returns how many were applied."""
        n = 0
        while self._events:
            e = self._events.popleft()
            n += 1
            if e.kind == "pos":
                io.add_mouse_pos_event(e.a, e.b)
            elif e.kind == "button":
                io.add_mouse_button_event(e.a, e.b)
            elif e.kind == "key":
                mod = _mod_for(e.a)
                if mod is not None:
                    io.add_key_event(mod, e.b)
                io.add_key_event(e.a, e.b)
            elif e.kind == "char":
                io.add_input_character(e.a)
            elif e.kind == "scroll":
                io.add_mouse_wheel_event(e.a, e.b)
            elif e.kind == "focus":
                io.add_focus_event(e.a)
        return n

    # -- GLFW ----------------------------------------------------------------------------------
    def attach_glfw(self, window: Any) -> None:
        """Install GLFW callbacks on a :class:`studyapp.render.context.Window` that feed this queue."""
        import glfw

        handle = window.handle
        self._key_map = _glfw_key_map()

        def ratio() -> tuple[float, float]:
            fw, fh = glfw.get_framebuffer_size(handle)
            ww, wh = glfw.get_window_size(handle)
            return (fw / ww if ww else 1.0), (fh / wh if wh else 1.0)

        def on_cursor(_w, x, y):
            rx, ry = ratio()
            self.mouse_move(x * rx, y * ry)

        def on_button(_w, button, action, _mods):
            if action in (glfw.PRESS, glfw.RELEASE) and 0 <= button < 5:
                self.mouse_button(button, action == glfw.PRESS)

        def on_key(key, _scancode, action, _mods):
            k = self._key_map.get(key) if self._key_map else None
            if k is not None and action in (glfw.PRESS, glfw.RELEASE):
                self.key(k, action == glfw.PRESS)

        glfw.set_cursor_pos_callback(handle, on_cursor)
        glfw.set_mouse_button_callback(handle, on_button)
        glfw.set_scroll_callback(handle, lambda _w, dx, dy: self.scroll(dx, dy))
        glfw.set_char_callback(handle, lambda _w, cp: self.char(cp))
        glfw.set_window_focus_callback(handle, lambda _w, f: self.focus(bool(f)))
        window.on_key(on_key)
