"""Analysis figures draw Chinese labels (condition labels, criteria) with a CJK font, not as empty boxes."""
from __future__ import annotations

import warnings

import pytest


def test_chinese_labels_have_glyphs_in_the_figures(tmp_path):
    from matplotlib import font_manager

    from results_analysis import figures

    if len(figures.font_families()) < 2:  # pragma: no cover - the CI installs fonts-wqy-microhei
        pytest.skip("no CJK font installed (apt install fonts-wqy-microhei)")
    results = {"真实感": ({"模型甲": 1.4, "模型乙": 2.1, "真人动作": 2.5}, 0.8),
               "同步性": ({"模型甲": 1.9, "模型乙": 2.2, "真人动作": 1.9}, 0.8)}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fig = figures.cd_diagram(results)
        paths = figures.save(fig, tmp_path, "cd")
    missing = [str(w.message) for w in caught if "missing from font" in str(w.message)]
    assert missing == []
    assert all(p.stat().st_size > 0 for p in paths)
    # and the family that supplies them is a CJK one matplotlib can find
    assert font_manager.findfont(figures.font_families()[1], fallback_to_default=False)
