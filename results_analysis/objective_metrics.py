"""Objective metrics beside the subjective ranks: the table of ``studyapp metrics``, correlated with mean ranks.

The input is a CSV with a ``condition`` column and numeric metric columns, one row per condition x stimulus
(x sample), as ``studyapp metrics DESIGN --out metrics.csv`` writes it. Columns that describe a row rather
than measure it (:data:`DESCRIPTIVE`) and non-numeric ones are not metrics. Each metric is averaged per
condition over its rows; per criterion, Spearman's rank correlation between those means and the
conditions' subjective mean ranks (Table 2 of the report; 1 = best) is computed over the conditions both
files share. With ``k`` conditions there are only ``k`` points, so the p-value is exact: the share of the
``k!`` orderings of the metric means whose ``|rho|`` is at least the observed one (``k`` up to 8; scipy's
t approximation above). A negative rho means conditions with higher values of the metric were ranked better.

>>> import pandas as pd
>>> table = pd.DataFrame({"condition": ["a", "b", "c"], "stimulus": "s1", "jerk_m_s3": [1.0, 2.0, 3.0]})
>>> corr = metric_correlations(metric_means(table), {"realism": {"a": 1.2, "b": 2.0, "c": 2.8}})
>>> corr[["criterion", "metric", "n", "rho", "p"]].values.tolist()
[['realism', 'jerk_m_s3', 3, 1.0, 0.3333333333333333]]
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from results_analysis.errors import AnalysisInputError, unreadable_csv
from results_analysis.study_meta import with_criterion_label

#: Columns of a metrics table that describe a row, not measure the motion.
DESCRIPTIVE = frozenset({"condition", "stimulus", "sample", "duration_s", "fps", "n_motion_beats", "n_onsets"})
#: Largest number of conditions for which the p-value is computed exactly, over all orderings.
EXACT_MAX_K = 8


def load_metrics(path: str | Path) -> pd.DataFrame:
    """Read and check a metrics CSV (a ``condition`` column and at least one numeric metric column)."""
    path = Path(path)
    try:
        table = pd.read_csv(path)
    except FileNotFoundError:
        raise AnalysisInputError(path, None, "metrics file not found") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise unreadable_csv(path, exc) from None
    if "condition" not in table.columns:
        raise AnalysisInputError(path, "header", "no 'condition' column; expected the CSV of `studyapp metrics "
                                 "DESIGN --out FILE`")
    table["condition"] = table["condition"].astype(str)
    if not metric_columns(table):
        raise AnalysisInputError(path, "header", f"no numeric metric column among {list(table.columns)}")
    return table


def metric_columns(table: pd.DataFrame) -> list[str]:
    """The metric columns of a table: numeric and not :data:`DESCRIPTIVE`, in file order."""
    return [c for c in table.columns if c not in DESCRIPTIVE and pd.api.types.is_numeric_dtype(table[c])]


def metric_means(table: pd.DataFrame) -> pd.DataFrame:
    """Mean of each metric per condition (rows: conditions in first-seen order), NaN rows ignored."""
    cols = metric_columns(table)
    return table.groupby("condition", sort=False)[cols].mean()


def spearman_exact(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Spearman's rho (average ranks for ties) and its two-sided p-value, exact over all orderings up to
    :data:`EXACT_MAX_K` points. NaN when a variable is constant or there are fewer than 3 points."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    n = len(x)
    if n < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return float("nan"), float("nan")
    rx, ry = stats.rankdata(x), stats.rankdata(y)
    rho = float(np.corrcoef(rx, ry)[0, 1])
    if n > EXACT_MAX_K:
        return rho, float(stats.spearmanr(x, y).pvalue)
    perms = np.array(list(itertools.permutations(range(n))))
    rys = ry[perms]
    num = ((rys - rys.mean(axis=1, keepdims=True)) * (rx - rx.mean())).sum(axis=1)
    den = np.sqrt(((rys - rys.mean(axis=1, keepdims=True)) ** 2).sum(axis=1) * ((rx - rx.mean()) ** 2).sum())
    p = float(np.mean(np.abs(num / den) >= abs(rho) - 1e-12))
    return rho, p


def metric_correlations(means: pd.DataFrame, mean_ranks: dict[str, dict[str, float]]) -> pd.DataFrame:
    """Per criterion x metric: Spearman's rho between the condition means and the mean ranks, with n and p."""
    rows = []
    for crit, ranks in mean_ranks.items():
        shared = [c for c in ranks if c in means.index]
        for metric in means.columns:
            vals = means.loc[shared, metric].to_numpy(float)
            rk = np.array([ranks[c] for c in shared], float)
            ok = np.isfinite(vals) & np.isfinite(rk)
            rho, p = spearman_exact(vals[ok], rk[ok])
            rows.append({"criterion": crit, "metric": metric, "n": int(ok.sum()), "rho": rho, "p": p})
    return pd.DataFrame(rows, columns=["criterion", "metric", "n", "rho", "p"])


@dataclass
class MetricsComparison:
    """The metrics table's per-condition means and their correlations with the subjective mean ranks."""

    means: pd.DataFrame
    correlations: pd.DataFrame
    missing: list[str]  # analysed conditions the metrics file lacks
    extra: list[str]    # conditions of the metrics file the analysis does not have
    #: condition id -> the name the report shows (its design label); stats.json and the tables keep ids
    labels: dict[str, str] = field(default_factory=dict)
    #: criterion id -> the name the report shows (its design label); the table has it beside the id
    criterion_labels: dict[str, str] = field(default_factory=dict)

    def as_dict(self) -> dict:
        return {"means": {c: {m: _num(v) for m, v in row.items()} for c, row in self.means.iterrows()},
                "correlations": [{k: (_num(v) if isinstance(v, float) else v) for k, v in r.items()}
                                 for r in self.correlations.to_dict("records")],
                "missing_conditions": self.missing, "extra_conditions": self.extra}

    def write_tables(self, folder: Path) -> None:
        folder.mkdir(parents=True, exist_ok=True)
        self.means.reset_index().to_csv(folder / "metrics_by_condition.csv", index=False)
        with_criterion_label(self.correlations, self.criterion_labels).to_csv(
            folder / "metrics_rank_correlation.csv", index=False)

    def add_to(self, doc) -> None:
        """Append the section to a :class:`results_analysis.document.Document`."""
        doc.h(1, "Objective metrics")
        n_cond = int(self.correlations["n"].max()) if len(self.correlations) else 0
        text = (f"Objective metrics of the motion as played (from `studyapp metrics`), averaged per condition over "
                f"the stimuli, beside the subjective mean ranks (1 = best). Spearman's ρ is computed per criterion "
                f"over the {n_cond} conditions; with so few points the p-value is exact (all orderings) and "
                f"cannot be small: with 3 conditions the smallest possible is 0.33. A negative ρ means conditions "
                f"with higher values of the metric were ranked better.")
        if self.missing:
            text += f" The metrics file has no rows for {', '.join(self.labels.get(c, c) for c in self.missing)}, left out."
        if self.extra:
            text += f" Its conditions {', '.join(self.extra)} are not in the results, left out."
        doc.p(text)
        show = self.means.copy()
        for col in show.columns:  # per column: DataFrame.map needs pandas 2.1
            show[col] = ["—" if not math.isfinite(v) else f"{v:.4g}" for v in show[col]]
        show.index = [self.labels.get(c, c) for c in show.index]
        show.index.name = "condition"
        doc.table(show.reset_index(), "Objective metrics per condition (mean over stimuli).")
        corr = self.correlations.copy()
        corr["criterion"] = [self.criterion_labels.get(c, c) for c in corr["criterion"]]
        corr["rho"] = [("—" if not math.isfinite(v) else f"{v:.2f}") for v in corr["rho"]]
        corr["p"] = [("—" if not math.isfinite(v) else f"{v:.3g}") for v in corr["p"]]
        doc.table(corr.rename(columns={"rho": "Spearman ρ", "p": "p (exact)", "n": "conditions"}),
                  "Rank correlation between each metric and the subjective mean rank, per criterion.")


def compare_metrics(table: pd.DataFrame, mean_ranks: dict[str, dict[str, float]],
                    labels: dict[str, str] | None = None,
                    criterion_labels: dict[str, str] | None = None) -> MetricsComparison:
    """Per-condition means of a metrics table and their correlations with ``mean_ranks`` (criterion ->
    condition -> mean rank); ``labels`` (condition id -> label) only changes what the report section shows,
    ``criterion_labels`` (criterion id -> label) that and the table's ``criterion_label`` column."""
    means = metric_means(table)
    analysed = list(dict.fromkeys(c for r in mean_ranks.values() for c in r))
    return MetricsComparison(means=means, correlations=metric_correlations(means, mean_ranks),
                             missing=[c for c in analysed if c not in means.index],
                             extra=[c for c in means.index if c not in analysed], labels=dict(labels or {}),
                             criterion_labels=dict(criterion_labels or {}))


def _num(v):
    return None if isinstance(v, float) and not math.isfinite(v) else float(v)


__all__ = ["DESCRIPTIVE", "MetricsComparison", "compare_metrics", "load_metrics", "metric_columns", "metric_correlations",
           "metric_means", "spearman_exact"]
