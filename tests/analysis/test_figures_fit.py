"""Every figure keeps its legend and caption inside the canvas when a block asks ONE criterion (the layout the
README recommends, one aspect per block): the files are saved without ``bbox_inches="tight"``, so a figure
sized for one narrow panel cut its rank legend and its caption at both edges."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from results_analysis.cli import main
from results_analysis.simulate import simulate_paradigm, simulate_results


def _ink_at_edges(png: Path) -> list[str]:
    """The edges (2 pixels wide) that hold anything but the white background."""
    a = np.asarray(Image.open(png).convert("L"), dtype=np.int16)
    edges = {"left": a[:, :2], "right": a[:, -2:], "top": a[:2, :], "bottom": a[-2:, :]}
    return [name for name, px in edges.items() if (px < 250).any()]


@pytest.fixture(scope="module")
def figures_dir(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("fit")
    rank = simulate_results(8, 2, criteria=("realism",), n_attention=0, seed=4).assign(block="main",
                                                                                         paradigm="rank")
    start = int(rank["trial_index"].max()) + 1
    df = pd.concat([rank,
                    simulate_paradigm("pairwise", 8, 6, trial_offset=start, seed=4),
                    simulate_paradigm("mismatch", 8, 6, trial_offset=start + 6, block="mm", seed=4),
                    simulate_paradigm("rating", 8, 4, trial_offset=start + 12, block="rt", reference="ref",
                                      seed=4)], ignore_index=True)
    df.to_csv(tmp / "r.csv", index=False)
    assert main([str(tmp / "r.csv"), "--out", str(tmp / "a"), "--bootstrap", "50", "--paradigm-bootstrap", "50",
                 "--reference", "ref"]) == 0
    return tmp / "a" / "figures"


@pytest.mark.parametrize("name", ["rank_shares", "mean_ranks", "bradley_terry", "critical_difference"])
def test_rank_figures_of_one_criterion_keep_everything_inside(figures_dir: Path, name: str) -> None:
    assert _ink_at_edges(figures_dir / f"{name}.png") == []


def test_block_figures_of_one_criterion_keep_everything_inside(figures_dir: Path) -> None:
    pngs = sorted(figures_dir.glob("block_*.png"))
    assert len(pngs) == 4  # pairwise Elo and wins, mismatch rates, ratings
    assert {p.name: _ink_at_edges(p) for p in pngs} == {p.name: [] for p in pngs}


def test_a_condition_without_strength_is_named_above_the_axis(tmp_path: Path) -> None:
    from results_analysis import figures

    t = pd.DataFrame({"condition": ["A", "B", "C"], "strength": [0.7, 0.3, np.nan], "ci_low": [0.5, 0.1, np.nan],
                      "ci_high": [0.9, 0.5, np.nan], "estimable": [True, True, False], "note": ["", "", "never won"]})
    fig = figures.bt_figure({"realism": t}, ["A", "B", "C"])
    figures.save(fig, tmp_path, "bt")
    ax = fig.axes[0]
    (note,) = [x for x in ax.texts if x.get_text().startswith("not estimable")]
    # the bottom row (C) had no bar, so the axes ended at the lowest bar and the x axis crossed the note
    assert note.get_window_extent().y0 > ax.get_window_extent().y0
    assert _ink_at_edges(tmp_path / "bt.png") == []
