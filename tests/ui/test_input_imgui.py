"""Synthetic events through InputQueue reach real ImGui widgets (the path the bot and GLFW use)."""
import numpy as np
import pytest
from imgui_bundle import imgui

from studyapp.ui.input import InputQueue, digit_key
from studyapp.ui.layer import ImGuiLayer
from studyapp.ui.widgets import Painter

pytestmark = pytest.mark.gl


@pytest.fixture
def ui(gl_ctx):
    from studyapp.render.context import OffscreenTarget

    layer = ImGuiLayer(gl_ctx)
    target = OffscreenTarget(gl_ctx, (640, 360))
    painter = Painter()
    painter.layer = layer
    yield layer, target, painter
    layer.shutdown()
    target.release()


def _frame(layer, target, painter, queue, body):
    queue.apply(imgui.get_io())
    layer.new_frame((640, 360), 1 / 60)
    painter.begin_frame()
    imgui.set_next_window_pos((0, 0))
    imgui.set_next_window_size((640, 360))
    imgui.begin("##t", None, imgui.WindowFlags_.no_decoration)
    result = body()
    imgui.end()
    target.fbo.use()
    target.fbo.clear(0.0, 0.0, 0.0, 1.0)
    layer.render((640, 360))
    return result


def test_click_through_queue_presses_button(ui):
    layer, target, painter = ui
    q = InputQueue()
    presses = []
    body = lambda: presses.append(painter.button("Press me", key="b", size=(200, 60)))  # noqa: E731
    for _ in range(2):
        _frame(layer, target, painter, q, body)
    x0, y0, x1, y1 = painter.rects["b"]
    q.click((x0 + x1) / 2, (y0 + y1) / 2)
    for _ in range(4):
        _frame(layer, target, painter, q, body)
    assert presses.count(True) == 1
    # a click outside does nothing
    q.click(x1 + 50, y1 + 50)
    for _ in range(4):
        _frame(layer, target, painter, q, body)
    assert presses.count(True) == 1
    img = target.read_rgb()
    assert img[int(y0) + 5:int(y1) - 5, int(x0) + 5:int(x1) - 5].mean() > 20  # the button is drawn


def test_keys_and_text_reach_imgui(ui):
    layer, target, painter = ui
    q = InputQueue()
    seen = []
    body = lambda: seen.append((imgui.is_key_down(digit_key(2)), imgui.is_key_down(imgui.Key.enter)))  # noqa: E731
    _frame(layer, target, painter, q, body)
    q.key(digit_key(2), True)
    _frame(layer, target, painter, q, body)
    q.key(digit_key(2), False)
    q.key(imgui.Key.enter, True)
    _frame(layer, target, painter, q, body)
    _frame(layer, target, painter, q, body)
    assert seen[1] == (True, False)
    assert seen[-1] == (False, True)


def test_focus_callback_and_text_recording(ui):
    layer, target, painter = ui
    q = InputQueue()
    events = []
    q.on_focus = events.append
    q.focus(False)
    q.focus(True)
    assert events == [False, True] and q.focused
    _frame(layer, target, painter, q, lambda: painter.wrapped("Hello participant"))
    assert "Hello participant" in painter.drawn
    img = target.read_rgb()
    assert np.count_nonzero(img.sum(axis=2) > 300) > 50  # the text shows up as bright pixels
