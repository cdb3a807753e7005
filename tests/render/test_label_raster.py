"""Slot labels are drawn with Pillow's FreeType and the DejaVu Sans Bold studyapp ships, without matplotlib
(0.3-1 s of a participant's first frame); the glyphs are those matplotlib's Agg draws, centred."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from studyapp.render.gpu import rasterize_label


def _matplotlib_label(text: str, height_px: int) -> np.ndarray:
    """The label as matplotlib's Agg draws it (how labels were made before)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    width_px = max(height_px, int(height_px * (0.75 * len(text) + 0.6)))
    fig = Figure(figsize=(width_px / 100, height_px / 100), dpi=100, facecolor="black")
    canvas = FigureCanvasAgg(fig)
    fig.text(0.5, 0.5, text, color="white", ha="center", va="center", fontsize=height_px * 0.95 * 72 / 100,
             family="DejaVu Sans", weight="bold")
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., 0]


@pytest.mark.parametrize("text,height", [("A", 32), ("B", 64), ("C", 20), ("AB", 48)])
def test_label_glyphs_match_matplotlibs_and_are_centred(text: str, height: int) -> None:
    got, want = rasterize_label(text, height), _matplotlib_label(text, height)
    assert got.shape == want.shape and got.dtype == np.uint8
    rows, cols = np.nonzero(got > 64)
    wrows, wcols = np.nonzero(want > 64)
    assert abs((rows.max() - rows.min()) - (wrows.max() - wrows.min())) <= 1          # same capital height
    assert abs((cols.max() - cols.min()) - (wcols.max() - wcols.min())) <= 1          # same width
    assert abs(int(got.sum()) - int(want.sum())) <= 0.03 * int(want.sum())             # same ink
    assert abs((rows.min() + rows.max()) / 2 - (height - 1) / 2) <= 1                  # centred


def test_labels_do_not_import_matplotlib() -> None:
    code = ("import sys; from studyapp.render.gpu import rasterize_label; rasterize_label('A', 40); "
            "print('matplotlib' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == "False"
