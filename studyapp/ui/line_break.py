"""Line breaks for text in scripts written without spaces (Chinese, Japanese), which ImGui cannot wrap.

ImGui wraps text only at spaces and ASCII punctuation, so a Chinese paragraph runs on until its next space
(often a number's, "第 3") and breaks there, leaving ragged lines that end far before the edge. Chinese and
Japanese may break between any two characters, except before closing punctuation (，。）」 ...) and after
opening punctuation (（「“ ...), the basic kinsoku rule. :func:`break_lines` puts those breaks in, greedily,
measuring with the caller's ``measure`` (the current font's advance widths); text with no such characters
is returned unchanged, so Latin text keeps ImGui's own wrapping.
"""
from __future__ import annotations

import re
from collections.abc import Callable

#: Characters of scripts without spaces between words: a line may break before any of them.
_CJK = re.compile(r"[\u2e80-\u9fff\uac00-\ud7af\uf900-\ufaff\uff00-\uffef\u3000-\u303f]")
#: Never at the start of a line (closing punctuation, CJK and ASCII).
_NO_START = set("，。、；：？！）》」』】〕〉”’…—·％,.;:!?)]}%")
#: Never at the end of a line (opening punctuation).
_NO_END = set("（《「『【〔〈“‘([{")


def _units(line: str) -> list[str]:
    """The pieces of ``line`` between which it may break: each CJK character (with the punctuation that must
    stay with it) and each run of other characters up to and including its trailing spaces."""
    units: list[str] = []
    for ch in line:
        if not units:
            units.append(ch)
            continue
        prev = units[-1]
        glued = ch in _NO_START or prev[-1] in _NO_END
        after_space = prev[-1].isspace() and not ch.isspace()
        if not glued and (after_space or _CJK.match(ch) or (_CJK.match(prev[-1]) and not ch.isspace())):
            units.append(ch)
        else:
            units[-1] = prev + ch
    return units


def break_lines(text: str, width: float, measure: Callable[[str], float]) -> str:
    """``text`` with line breaks where a line would pass ``width`` (pixels, measured by ``measure``); only
    text with CJK characters is changed, and its own line breaks are kept.

    >>> break_lines("请观看每个片段，然后回答。", 40.0, lambda s: 10.0 * len(s))
    '请观看每\\n个片段，\\n然后回\\n答。'
    >>> break_lines("Watch each clip", 40.0, lambda s: 10.0 * len(s))
    'Watch each clip'
    """
    if width <= 0 or not _CJK.search(text):
        return text
    out = []
    for line in text.split("\n"):
        rows: list[str] = []
        cur, cur_w = "", 0.0
        for unit in _units(line):
            w = measure(unit)
            if cur and cur_w + measure(unit.rstrip()) > width:
                rows.append(cur.rstrip())
                cur, cur_w = unit.lstrip(), measure(unit.lstrip())
            else:
                cur, cur_w = cur + unit, cur_w + w
        rows.append(cur.rstrip())
        out.append("\n".join(rows))
    return "\n".join(out)
