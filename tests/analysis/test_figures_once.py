"""Every figure is drawn once per file it is written to (issue 20): no ``bbox_inches="tight"`` measuring draw,
and the statistics never import matplotlib (it is imported when the figures are written)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from matplotlib.figure import Figure

from results_analysis.analysis import run_analysis
from results_analysis.report import write_figures
from results_analysis.simulate import simulate_results


def test_each_figure_is_drawn_once_per_file(tmp_path: Path, monkeypatch) -> None:
    a = run_analysis(simulate_results(8, 2, seed=1), n_boot=50)
    draws: dict[int, int] = {}
    real = Figure.draw

    def counting(self, renderer):
        draws[id(self)] = draws.get(id(self), 0) + 1
        return real(self, renderer)

    monkeypatch.setattr(Figure, "draw", counting)
    write_figures(a, tmp_path)
    files = sorted(p.name for p in tmp_path.iterdir())
    assert len(files) == 8 and {p.rsplit(".", 1)[1] for p in files} == {"png", "svg"}
    assert len(draws) == 4 and set(draws.values()) == {2}  # 4 figures, one draw for the PNG, one for the SVG


def test_statistics_import_no_plotting_module() -> None:
    code = ("import sys\nfrom results_analysis.analysis import run_analysis\nfrom results_analysis.loader import "
            "load_results\nfrom results_analysis.report import write_outputs\n"
            "from results_analysis.simulate import simulate_results\n"
            "run_analysis(simulate_results(6, 2, seed=1), n_boot=20)\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'matplotlib'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
