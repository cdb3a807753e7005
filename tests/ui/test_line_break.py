"""Line breaks in Chinese text (studyapp.ui.line_break), with a fixed-advance measure."""
import re

from studyapp.ui.line_break import break_lines


def width(s: str) -> float:
    """20 px per CJK character, 10 px per other character."""
    return sum(20.0 if ord(c) >= 0x2E80 else 10.0 for c in s)


def test_lines_fill_the_width_and_keep_punctuation_and_words_whole() -> None:
    text = "片段播放完毕后，人物下方会出现一个面板（第 1 到第 3）。键盘：1 = A, 2 = B。Enter 继续，Backspace 清除。"
    out = break_lines(text, 200.0, width)
    lines = out.split("\n")
    assert out.replace("\n", "").replace(" ", "") == text.replace(" ", "")   # nothing lost or added
    assert all(width(ln) <= 200.0 for ln in lines), lines
    # no line ends early: the next line's first piece (a character with its opening mark, or a word) would
    # not have fitted
    first = [re.match(r"[A-Za-z0-9]+|（.|.", nxt).group() for nxt in lines[1:]]
    assert all(width(ln) + width(f) > 200.0 for ln, f in zip(lines, first)), lines
    assert not [ln for ln in lines if ln[0] in "，。）：、"], lines                  # kinsoku: no closing mark first
    assert not [ln for ln in lines if ln[-1] in "（"], lines                        # nor an opening one last
    assert any(ln.startswith("Backspace") for ln in lines), lines                  # a word stays whole


def test_text_without_cjk_and_its_own_line_breaks_are_kept() -> None:
    assert break_lines("Watch each clip, then rank.", 50.0, width) == "Watch each clip, then rank."
    assert break_lines("第一行\n第二行", 500.0, width) == "第一行\n第二行"
