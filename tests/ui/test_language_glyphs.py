"""A design in Chinese shows every participant screen without a missing glyph, checked in the pixels.

A scripted participant goes through every screen of a ``language = "zh"`` design offscreen and the test
collects every string drawn. Each distinct character of them is then drawn alone into a cell of a grid,
with the same fonts, next to a character no font has (U+0378, unassigned): Dear ImGui draws its fallback
glyph for a character its fonts lack, so a character whose pixels match that cell, or that leaves its
cell blank, is missing.
"""
from __future__ import annotations

import numpy as np
import pytest

from studyapp.bots.ui_driver import UIBot

pytestmark = pytest.mark.gl

CELL = 36
NO_GLYPH = "\u0378"


def _zh_study(tmp_path):
    from fixtures.synthetic import write_synthetic_study
    from studyapp.study.design import load_design
    from studyapp.study.design.fonts import design_fallback_font
    from studyapp.study.storage import ResultsDB

    path = write_synthetic_study(tmp_path / "s", n_stimuli=1, seconds=1.0, practice=True, questionnaire=True)
    path.write_text('language = "zh"\ninstructions = "请认真观看每个片段，然后排序。"\n'
                    + path.read_text().replace("instructions =", "# instructions =", 1))
    design = load_design(path)
    if design_fallback_font(design)[0] is None:  # pragma: no cover - the CI installs fonts-wqy-microhei
        pytest.skip("no CJK font installed (apt install fonts-wqy-microhei)")
    return design, ResultsDB(tmp_path / "r.sqlite", design)


def _glyph_cells(design, db, chars: list[str], monkeypatch) -> tuple[list[np.ndarray], np.ndarray]:
    """Each character of ``chars`` drawn alone in a cell (regular font, body size); and the no-glyph cell."""
    from imgui_bundle import imgui

    from studyapp.ui.screens import welcome
    from studyapp.ui.screens.common import PAGE_FLAGS

    cols = 1280 // CELL
    cells = chars + [NO_GLYPH]

    def draw(app):
        imgui.set_next_window_pos((0, 0))
        imgui.set_next_window_size((1280, 720))
        imgui.begin("##glyphs", None, PAGE_FLAGS)
        dl = imgui.get_window_draw_list()
        white = imgui.get_color_u32(imgui.ImVec4(1, 1, 1, 1))
        for i, ch in enumerate(cells):
            x, y = (i % cols) * CELL + 6, (i // cols) * CELL + 6
            dl.add_text(app.layer.font, 24.0, imgui.ImVec2(x, y), white, ch)
        imgui.end()

    monkeypatch.setattr(welcome, "draw", draw)
    bot = UIBot(design, db, "G1", "ordered", 1, size=(1280, 720))
    try:
        for _ in range(3):
            bot.frame()
        rgb = bot.target.read_rgb().astype(np.float32).mean(axis=2)
    finally:
        bot.close()
    out = []
    for i in range(len(cells)):
        x, y = (i % cols) * CELL, (i // cols) * CELL
        out.append(rgb[y:y + CELL, x:x + CELL])
    return out[:-1], out[-1]


def test_every_character_on_every_chinese_screen_has_a_glyph(tmp_path, monkeypatch, secrets_of):
    design, db = _zh_study(tmp_path)
    bot = UIBot(design, db, "P1", "ordered", 1, size=(1280, 720))
    screens = set()
    orig = bot.frame

    def frame():
        orig()
        screens.add(bot.app.screen_key().split(":")[0])

    bot.frame = frame
    try:
        assert bot.run() == 0
        drawn = set(bot.app.ui.drawn)
        assert bot.app.ui.leaks(secrets_of(design)) == []
        assert bot.app.ui.cut_off == []
    finally:
        bot.close()
    assert {"welcome", "instructions", "env_check", "practice", "trials", "questionnaire", "done"} <= screens
    # the screens spoke Chinese: the built-in texts came from the zh table
    assert design.text("instructions.how_title") in drawn and design.text("questionnaire.submit") in drawn
    chars = sorted({c for s in drawn for c in s if c.isprintable() and not c.isspace()})
    cjk = [c for c in chars if ord(c) >= 0x2E80]
    assert len(cjk) > 150, len(cjk)
    cells, none = _glyph_cells(design, db, chars, monkeypatch)
    db.close()
    assert none.max() > 100  # the fallback glyph is drawn (so "looks like it" is a real comparison)
    missing = [c for c, cell in zip(chars, cells)
               if cell.max() < 100 or np.abs(cell - none).mean() < 2.0]
    assert missing == [], "".join(missing)


def test_without_the_system_font_the_same_check_finds_the_missing_glyphs(tmp_path, monkeypatch):
    """The check itself: with no font merged in, Chinese characters draw as the fallback glyph."""
    from studyapp.study.design import fonts

    design, db = _zh_study(tmp_path)
    monkeypatch.setattr(fonts, "design_fallback_font", lambda d: (None, set()))
    chars = list("请观看片段") + ["A"]
    cells, none = _glyph_cells(design, db, chars, monkeypatch)
    db.close()
    missing = [c for c, cell in zip(chars, cells) if cell.max() < 100 or np.abs(cell - none).mean() < 2.0]
    assert missing == list("请观看片段")


def _text_lines(rgb: np.ndarray, x0: int = 200, x1: int = 1120, bottom: int = 630) -> list[tuple[int, int, int]]:
    """The page's rows of light text: (top, bottom, right end) of each band of rows with text pixels."""
    bright = rgb[:bottom, x0:x1].astype(int).sum(axis=2) > 450
    rows, out, y = bright.any(axis=1), [], 0
    while y < len(rows):
        if not rows[y]:
            y += 1
            continue
        top = y
        while y < len(rows) and rows[y]:
            y += 1
        out.append((top, y, x0 + int(np.nonzero(bright[top:y].any(axis=0))[0].max())))
    return out


def test_chinese_paragraphs_wrap_at_the_edge_not_at_their_spaces(tmp_path):
    """ImGui wraps only at spaces: the Chinese "how to rank" text (a few spaces, around numbers) broke far
    before the edge. Every line of a paragraph but its last now reaches to within two characters of the
    page's widest line, in the pixels of the instructions page."""
    design, db = _zh_study(tmp_path)
    bot = UIBot(design, db, "P1", "ordered", 1, size=(1280, 720))
    try:
        for _ in range(400):
            bot.step()
            if bot.app.screen_key() == "instructions" and bot._prev_key == "instructions":
                break
        assert bot.app.screen_key() == "instructions"
        for _ in range(2):
            bot.frame()
        rgb = bot.target.read_rgb()
    finally:
        bot.close()
        db.close()
    lines = _text_lines(rgb)
    widest = max(right for _, _, right in lines)
    # lines of one paragraph are 4 px apart here; paragraphs and items 14 px or more
    inner = [(top, right) for (top, bottom, right), nxt in zip(lines, lines[1:]) if nxt[0] - bottom <= 6]
    assert len(inner) >= 2, lines
    assert [(top, right) for top, right in inner if right < widest - 40] == [], (widest, lines)
