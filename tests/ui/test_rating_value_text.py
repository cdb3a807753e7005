"""The rating slider's value is readable wherever the handle is (offscreen, EGL): at 0, 1, 49, 50, 51, 99 and
100 the value's text lies inside the slider, whole, and clear of the handle (ImGui's own slider centres the
text in the track, so at 50 the handle covered it)."""
from __future__ import annotations

import numpy as np
import pytest

from fixtures.paradigm_studies import SCRIPT_STORED, paradigm_study  # noqa: F401
from test_paradigm_screens import ScriptedBot, stored

pytestmark = pytest.mark.gl

#: (criterion, slot) -> the value shown, for the rating trial's six sliders.
VALUES = {("realism", 0): 0, ("realism", 1): 50, ("realism", 2): 100,
          ("diversity", 0): 1, ("diversity", 1): 49, ("diversity", 2): 99}
EXTRA = {("realism", 1): (51,)}   # a second look: just past the middle


def _boxes(rgb: np.ndarray, rect) -> tuple[tuple[int, int, int, int] | None, tuple[int, int, int, int] | None, int]:
    """Inside one slider's rectangle: the bounding box of the handle's pixels, that of the text's (bright
    pixels), and the number of text pixels."""
    from studyapp.ui.screens.rating_panel import GRAB_COLOR

    x0, y0, x1, y1 = (int(round(v)) for v in rect)
    part = rgb[y0:y1, x0:x1].astype(int)
    handle = np.abs(part - np.array(GRAB_COLOR[:3]) * 255).max(axis=2) < 30
    text = part.min(axis=2) > 170          # the light text; the track, the frame and the handle are darker

    def box(mask):
        ys, xs = np.nonzero(mask)
        return None if not len(xs) else (x0 + xs.min(), y0 + ys.min(), x0 + xs.max(), y0 + ys.max())
    return box(handle), box(text), int(text.sum())


def test_the_value_is_readable_at_every_handle_position(paradigm_study, tmp_path):
    design, db = paradigm_study
    seen: list = []

    class Looking(ScriptedBot):
        def on_screen(self, trial, part):
            if (trial, part) != (3, "answer"):
                return
            for extra in (False, True):
                def put(extra=extra):
                    r = self.app.trial_view().answer
                    active = r.active
                    for (c, s), v in VALUES.items():
                        r.set(c, s, EXTRA.get((c, s), (v,))[0] if extra else v)
                    r.active = active
                self.steps.append(put)
                self.wait(3)
                self.steps.append(lambda extra=extra: seen.append(
                    (extra, self.screenshot("values"), dict(self.app.ui.rects))))

            def clear():  # back to untouched, so the script answers as always
                r = self.app.trial_view().answer
                for c, s in VALUES:
                    r.unset(c, s)
            self.steps.append(clear)
            self.wait(2)

    bot = Looking(design, db, "S3", "ordered", 0, out_dir=tmp_path)
    try:
        assert bot.run() == 0
    finally:
        bot.close()
    assert stored(db, "S3") == SCRIPT_STORED
    assert len(seen) == 2
    for extra, rgb, rects in seen:
        for (c, s), v in VALUES.items():
            value = EXTRA.get((c, s), (v,))[0] if extra else v
            rect = rects[("slider", c, s)]
            handle, text, n = _boxes(rgb, rect)
            assert handle is not None, (c, s, value)
            assert text is not None and n >= 8 * len(str(value)), (c, s, value, n)   # the digits are there
            # the text clear of the handle, with a pixel between them
            apart = text[2] < handle[0] - 1 or text[0] > handle[2] + 1
            assert apart, f"value {value} ({c}, slot {s}): text {text} touches the handle {handle}"
            # and whole inside the slider's frame (not cut at its ends)
            x0, y0, x1, y1 = rect
            assert x0 + 1 <= text[0] and text[2] <= x1 - 1, (value, text, rect)
