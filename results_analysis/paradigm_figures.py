"""Figures of the pairwise, mismatch and rating blocks (matplotlib, object-oriented API, headless), in the
style, colours and CJK-capable fonts of :mod:`results_analysis.figures`.

* :func:`interval_figure` — one dot with its interval per condition, one panel per criterion: Elo (pairwise),
  matched-preference rate (mismatch, chance 0.5 dotted), mean rating (rating, 0..100).
* :func:`win_matrix_figure` — per criterion a k x k grid: the share of points the row condition took off the
  column condition (wins + ties/2 over comparisons), with the wins/ties/losses written in each cell.

Every function returns a Figure; :func:`results_analysis.figures.save` writes it once as PNG and SVG.
"""
from __future__ import annotations

from collections.abc import Sequence

import matplotlib
import numpy as np
import pandas as pd

from results_analysis.figures import _STYLE, _caption_y, _figure, _fit_width, condition_color


def interval_figure(tables: dict[str, pd.DataFrame], conditions: Sequence[str], *, value: str, xlabel: str,
                    caption: str, chance: float | None = None, xlim: tuple[float, float] | None = None,
                    fmt: str = "{:.2f}"):
    """Dots (``value``) with ``ci_low``..``ci_high`` lines per condition, one panel per criterion; a condition
    whose value is NaN (not estimable) is named in red with the table's ``note`` instead of a dot.

    >>> t = pd.DataFrame({"condition": ["A", "B"], "elo": [50.0, -50.0], "ci_low": [10.0, -90.0],
    ...                   "ci_high": [90.0, -10.0]})
    >>> fig = interval_figure({"realism": t}, ["A", "B"], value="elo", xlabel="Elo", caption="Elo.", chance=0)
    >>> len(fig.axes)
    1
    """
    with matplotlib.rc_context(_STYLE):
        crits = list(tables)
        conds = list(conditions)
        k = len(conds)
        fig = _figure((2.6 * len(crits) + 0.8, 0.42 * k + 1.4))
        axes = fig.subplots(1, len(crits), sharey=True, squeeze=False)
        y = np.arange(k)[::-1]
        finite = [v for t in tables.values() for col in (value, "ci_low", "ci_high")
                  for v in t[col].to_numpy(dtype=float) if np.isfinite(v)]
        if xlim is None:
            lo, hi = (min(finite), max(finite)) if finite else (-1.0, 1.0)
            pad = 0.08 * max(hi - lo, 1e-9)
            xlim = (lo - pad, hi + pad)
        for ax, crit in zip(axes[0], crits):
            t = tables[crit].set_index("condition").reindex(conds)
            for i, c in enumerate(conds):
                v = float(t.loc[c, value])
                if not np.isfinite(v):
                    note = t.loc[c, "note"] if "note" in t.columns and isinstance(t.loc[c, "note"], str) else ""
                    ax.text(xlim[0], y[i], f" not estimable{f' ({note})' if note else ''}", ha="left",
                            va="center", fontsize=7, color="#b00020", style="italic")
                    continue
                lo_i, hi_i = float(t.loc[c, "ci_low"]), float(t.loc[c, "ci_high"])
                if np.isfinite(lo_i) and np.isfinite(hi_i):
                    ax.plot([lo_i, hi_i], [y[i], y[i]], color=condition_color(i), lw=2.2, solid_capstyle="round")
                ax.plot(v, y[i], "o", color=condition_color(i), ms=6, mec="white", mew=0.8)
                ax.text(v, y[i] + 0.22, fmt.format(v), ha="center", va="bottom", fontsize=7.5, color="#333333")
            if chance is not None:
                ax.axvline(chance, color="#999999", lw=0.8, ls=":", zorder=0)
            ax.set_xlim(*xlim)
            ax.set_ylim(-0.6, k - 0.3)
            ax.set_yticks(y)
            ax.set_yticklabels(conds)
            ax.tick_params(axis="y", length=0)
            ax.spines["left"].set_visible(False)
            ax.set_title(str(crit))
            ax.set_xlabel(xlabel)
            ax.grid(axis="x", color="#e5e5e5", lw=0.6)
            ax.set_axisbelow(True)
        _fit_width(fig, fig.text(0.5, _caption_y(fig), caption, ha="center", va="bottom", fontsize=7.5,
                                 color="#444444"))
        fig.tight_layout(rect=(0, 0.06, 1, 1))
        return fig


def win_matrix_figure(wins: dict[str, pd.DataFrame], conditions: Sequence[str]):
    """Per criterion the k x k grid of :func:`results_analysis.pairwise.win_matrix` (row = a, column = b).

    >>> w = pd.DataFrame({"a": ["X", "Y"], "b": ["Y", "X"], "wins": [3, 1], "ties": [1, 1], "losses": [1, 3],
    ...                   "n": [5, 5], "score": [0.7, 0.3]})
    >>> len(win_matrix_figure({"realism": w}, ["X", "Y"]).axes)
    2
    """
    with matplotlib.rc_context(_STYLE):
        crits = list(wins)
        conds = list(conditions)
        k = len(conds)
        side = 0.75 * k + 1.2
        fig = _figure((side * len(crits) + 1.0, side + 0.6))
        # matplotlib's default bottom margin (0.11) plus room for the caption line under the axis label
        axes = fig.subplots(1, len(crits), squeeze=False, gridspec_kw={"bottom": 0.11 + 0.2 / fig.get_figheight()})
        cmap = matplotlib.colormaps["RdBu"]
        image = None
        for ax, crit in zip(axes[0], crits):
            t = wins[crit].set_index(["a", "b"])
            grid = np.full((k, k), np.nan)
            for i, a in enumerate(conds):
                for j, b in enumerate(conds):
                    if i == j or (a, b) not in t.index:
                        continue
                    r = t.loc[(a, b)]
                    grid[i, j] = r["score"]
                    if r["n"]:
                        dark = abs(float(r["score"]) - 0.5) > 0.3
                        ax.text(j, i, f"{r['score']:.0%}\n{int(r['wins'])}/{int(r['ties'])}/{int(r['losses'])}",
                                ha="center", va="center", fontsize=7, color="white" if dark else "#1a1a1a")
            image = ax.imshow(grid, cmap=cmap, vmin=0.0, vmax=1.0)
            ax.set_xticks(np.arange(k))
            ax.set_xticklabels(conds, rotation=30, ha="right")
            ax.set_yticks(np.arange(k))
            ax.set_yticklabels(conds)
            ax.set_title(str(crit))
            ax.set_xlabel("against")
            for s in ax.spines.values():
                s.set_visible(False)
        fig.colorbar(image, ax=list(axes[0]), shrink=0.8, label="share of points (row over column)")
        _fit_width(fig, fig.text(0.5, _caption_y(fig), "Cell: how often the row condition was preferred to the column "
                                 "condition (ties half); wins/ties/losses below.", ha="center", va="bottom",
                                 fontsize=7.5, color="#444444"))
        return fig
