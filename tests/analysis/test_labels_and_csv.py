"""Labels, the design's order and the study's title in the report, and a CSV export that gives the same
report as its database (ranks, labels, order, title and questionnaire all travel in the CSV)."""
from __future__ import annotations

import json
import re
from pathlib import Path

import pandas as pd
import pytest

from results_analysis import analyze
from results_analysis.analysis import run_analysis
from results_analysis.cli import main
from results_analysis.errors import AnalysisInputError
from results_analysis.simulate import simulate_results
from results_analysis.study_meta import condition_labels, condition_order, criterion_labels, questionnaire_from_results


@pytest.fixture(scope="module")
def demo_reports(tmp_path_factory) -> tuple[Path, Path, object]:
    """The demo design run by four careful bots; the report from the .sqlite and from its CSV export."""
    from studyapp.bots.session_driver import run_bot_session
    from studyapp.resources import demo_design
    from studyapp.study.design import load_design
    from studyapp.study.export import export_dataframe
    from studyapp.study.storage import ResultsDB

    tmp = tmp_path_factory.mktemp("labels")
    design = load_design(demo_design(), check_files=False)
    db_path = tmp / "demo.results.sqlite"
    with ResultsDB(db_path, design) as db:
        for i in range(4):
            run_bot_session(design, db, f"P{i + 1}", "careful", 10 + i)
    export_dataframe(db_path).to_csv(tmp / "results.csv", index=False)
    args = ["--bootstrap", "200", "--permutations", "0"]
    assert main([str(db_path), "--out", str(tmp / "from_db"), *args]) == 0
    assert main([str(tmp / "results.csv"), "--out", str(tmp / "from_csv"), *args]) == 0
    return tmp / "from_db", tmp / "from_csv", design


def test_csv_and_database_give_the_same_report(demo_reports) -> None:
    from_db, from_csv, design = demo_reports
    db_stats = json.loads((from_db / "stats.json").read_text())
    csv_stats = json.loads((from_csv / "stats.json").read_text())
    db_stats["_meta"].pop("source"), csv_stats["_meta"].pop("source")
    assert db_stats == csv_stats
    assert "_questionnaire" in csv_stats  # the CSV brought the questionnaire without --questionnaire
    from results_analysis import load_study_title

    folder = from_db.parent
    assert load_study_title(folder / "results.csv") == load_study_title(folder / "demo.results.sqlite") == design.title
    tables = sorted(p.name for p in (from_db / "tables").iterdir())
    assert tables == sorted(p.name for p in (from_csv / "tables").iterdir())
    assert "questionnaire_items.csv" in tables
    for name in tables:
        assert (from_db / "tables" / name).read_bytes() == (from_csv / "tables" / name).read_bytes(), name
    db_md, csv_md = (from_db / "report.md").read_text(), (from_csv / "report.md").read_text()
    assert db_md == csv_md


def test_report_shows_labels_in_the_design_order_and_the_study_title(demo_reports) -> None:
    from_db, _, design = demo_reports
    labels = [c.label for c in design.conditions]
    assert labels == ["Speech-synced", "Lagged 300 ms", "Near-static"]
    stats = json.loads((from_db / "stats.json").read_text())
    assert stats["_meta"]["conditions"] == ["synced", "lagged", "static"]  # ids, in the design's order
    assert stats["_meta"]["labels"] == dict(zip(design.condition_ids, labels))
    for crit in ("realism", "synchronization", "diversity"):
        assert set(stats[crit]["mean_rank"]) == set(design.condition_ids)
    table = pd.read_csv(from_db / "tables" / "conditions.csv")
    for crit, rows in table.groupby("criterion", sort=False):
        assert rows["condition"].tolist() == labels, crit
    bt = pd.read_csv(from_db / "tables" / "bradley_terry.csv")
    assert bt[bt.criterion == "realism"]["condition"].tolist() == labels
    pairs = pd.read_csv(from_db / "tables" / "posthoc_nemenyi.csv")
    assert set(pairs["a"]) | set(pairs["b"]) == set(labels)
    md = (from_db / "report.md").read_text()
    assert md.splitlines()[0] == f"# {design.title}"
    for cid in design.condition_ids:  # no id reaches the report's text or tables ("Speech-synced" is a label)
        assert not re.search(rf"(?<![\w-]){cid}(?![\w-])", md), cid
    svg = (from_db / "figures" / "rank_shares.svg").read_text()
    assert all(label in svg for label in labels)
    assert not any(re.search(rf">\s*{cid}\s*<", svg) for cid in design.condition_ids)
    # rows of Table 2 in the design's order (the demo's ids are not in alphabetical order)
    rows = [ln for ln in md.splitlines() if ln.startswith("| Realism |") and "%" in ln][:3]  # Table 2 first
    assert [next(lb for lb in labels if f"| {lb} |" in r) for r in rows] == labels
    assert sorted(design.condition_ids) != design.condition_ids


def test_old_csv_without_the_new_columns_still_works(tmp_path: Path) -> None:
    """An export from before labels: ids in their order, no title but the file name, no questionnaire."""
    df = simulate_results(8, 3, seed=4)
    assert not {"condition_label", "condition_position", "study_title"} & set(df.columns)
    df.to_csv(tmp_path / "old.csv", index=False)
    assert main([str(tmp_path / "old.csv"), "--out", str(tmp_path / "a"), "--bootstrap", "50"]) == 0
    stats = json.loads((tmp_path / "a" / "stats.json").read_text())
    assert stats["_meta"]["conditions"] == sorted(df["condition"].unique())
    assert stats["_meta"]["labels"] == {c: c for c in stats["_meta"]["conditions"]}
    assert (tmp_path / "a" / "report.md").read_text().startswith("# Results: old.csv")
    assert "_questionnaire" not in stats


def test_order_and_labels_from_the_columns_and_their_errors() -> None:
    df = pd.DataFrame({"condition": ["b", "a", "c", "x"], "condition_label": ["Base", None, "Ours", None],
                       "condition_position": [0, 1, 2, None], "_where": ["line 2", "line 3", "line 4", "line 5"]})
    assert condition_order(df) == ["b", "a", "c", "x"]  # a pseudo-condition without a place comes last
    assert condition_labels(df) == {"b": "Base", "a": "a", "c": "Ours", "x": "x"}
    clash = df.assign(condition_label=["Ours", None, "ours", None])
    with pytest.raises(AnalysisInputError, match="'b' and 'c' would both be shown as 'ours'"):
        condition_labels(clash)
    two = pd.concat([df, df.assign(condition_label="Other", _where="line 9")])
    with pytest.raises(AnalysisInputError, match=r"line 9, column 'condition_label'.*'b' is labelled both"):
        condition_labels(two)
    moved = pd.concat([df, df.assign(condition_position=[5, 1, 2, None], _where="line 7")])
    with pytest.raises(AnalysisInputError, match="line 7, column 'condition_position'.*positions 0 and 5"):
        condition_order(moved)


def test_criterion_labels_in_order_of_appearance_and_a_second_label_named_at_its_row() -> None:
    df = pd.DataFrame({"criterion": ["sync", "real", "sync", "div", "real"],
                       "criterion_label": ["In  time\nwith speech", "Realism", "In time with speech", None, "Realism"]})
    assert criterion_labels(df) == {"sync": "In time with speech", "real": "Realism", "div": "div"}
    assert criterion_labels(df.drop(columns="criterion_label")) == {"sync": "sync", "real": "real", "div": "div"}
    two = df.assign(criterion_label=["A", "R", "A", None, "Other"])
    with pytest.raises(AnalysisInputError, match=r"row 5, column 'criterion_label'.*'real' is labelled both 'R' and"):
        criterion_labels(two)
    where = two.assign(_where=[f"line {k}" for k in range(2, 7)])
    with pytest.raises(AnalysisInputError, match=r"line 6, column 'criterion_label'"):
        criterion_labels(where)


def test_questionnaire_columns_become_answers_and_disagreeing_rows_are_refused() -> None:
    df = pd.DataFrame({"participant": ["P1", "P1", "P2"], "_where": ["line 2", "line 3", "line 4"],
                       "questionnaire:ease:q1": ["5", "5", "3"], "questionnaire::fun.q2": ["2", "2", None]})
    q = questionnaire_from_results(df)
    assert q[["participant", "item", "scale", "value"]].values.tolist() == [
        ["P1", "q1", "ease", "5"], ["P2", "q1", "ease", "3"], ["P1", "fun.q2", "fun", "2"]]
    bad = df.assign(**{"questionnaire:ease:q1": ["5", "4", "3"]})
    with pytest.raises(AnalysisInputError, match="line 2 and line 3, column 'questionnaire:ease:q1'"):
        questionnaire_from_results(bad)
    assert questionnaire_from_results(df.drop(columns=[c for c in df if c.startswith("questionnaire:")])) is None


def test_analyze_from_python_uses_the_labels(tmp_path: Path) -> None:
    df = simulate_results(6, 3, seed=1)
    ids = sorted(df["condition"].unique())
    names = {ids[0]: "Zeta model", ids[1]: "Alpha model", ids[2]: "Mid model"}
    order = {ids[2]: 0, ids[0]: 1, ids[1]: 2}
    df = df.assign(condition_label=df["condition"].map(names), condition_position=df["condition"].map(order))
    a = analyze(df, tmp_path, n_boot=50, groups=["speaker"])
    assert a.conditions == [ids[2], ids[0], ids[1]] and a.labels == names
    t = pd.read_csv(tmp_path / "tables" / "conditions.csv")
    assert t[t.criterion == t.criterion.iloc[0]]["condition"].tolist() == ["Mid model", "Zeta model", "Alpha model"]
    # the breakdown's per-condition columns are named by label too, and hold the same numbers
    by = pd.read_csv(tmp_path / "tables" / "by_speaker.csv")
    raw = a.groups["speaker"]
    for cid, label in names.items():
        assert by[f"mean_rank_{label}"].tolist() == pytest.approx(raw[f"mean_rank_{cid}"].tolist())
        assert f"mean_rank_{cid}" not in by.columns
    assert "mean rank Mid model" in (tmp_path / "report.md").read_text()
    # the questionnaire columns are answers, not a grouping
    from results_analysis.analysis import group_columns
    assert group_columns(df.assign(**{"questionnaire:ease:q1": "3"})) == ["speaker", "device"]


def test_the_report_names_the_friedman_mean_ranks_apart_from_the_mean_over_all_answers(tmp_path) -> None:
    """With several trials per participant the participant-level Friedman test ranks each participant's mean
    ranks again, so Figure 2 and Table 3 place a condition elsewhere than Table 2's mean over all answers: the
    captions must say which is which (a reviewer saw 2.67 in one and 2.50 in the other, both 'mean rank')."""
    df = simulate_results(9, 4, criteria=("realism",), n_attention=0, seed=3)
    a = run_analysis(df, n_boot=50)
    c = a.criteria["realism"]
    friedman = dict(zip(a.conditions, c.friedman.mean_rank))
    plain = c.summary.set_index("condition")["mean_rank"]
    assert max(abs(friedman[x] - plain[x]) for x in a.conditions) > 0.05  # the two really differ here
    df.to_csv(tmp_path / "r.csv", index=False)
    assert main([str(tmp_path / "r.csv"), "--out", str(tmp_path / "p"), "--bootstrap", "50"]) == 0
    report = (tmp_path / "p" / "report.md").read_text(encoding="utf-8")
    assert "Positions are the Friedman test's mean ranks" in report
    assert "Δ: difference of the Friedman test's mean ranks, as placed in Figure 2" in report
    assert "Table 2. Ranks per condition (1 = best): mean over all answers" in report
    # trial blocks: the Friedman ranks are the answers' own, and nothing claims otherwise
    assert main([str(tmp_path / "r.csv"), "--out", str(tmp_path / "t"), "--bootstrap", "50", "--block", "trial"]) == 0
    trial = (tmp_path / "t" / "report.md").read_text(encoding="utf-8")
    assert "Friedman test's mean ranks" not in trial and "Δ: difference of mean ranks" in trial


def _labelled_study(tmp_path: Path) -> tuple[Path, dict[str, str]]:
    """A rank study with a pairwise, a mismatch and a rating block, its criteria labelled (a schema 7 export)."""
    from results_analysis.simulate import simulate_paradigm

    labels = {"realism": "Looks real", "synchronization": "Synchronization with speech", "diversity": "Variety"}
    ranks = simulate_results(8, 3, speakers=2, seed=3)
    parts, offset = [ranks], int(ranks["trial_index"].max()) + 1
    for i, paradigm in enumerate(("pairwise", "mismatch", "rating")):
        parts.append(simulate_paradigm(paradigm, 8, 3, conditions=("FaceCapGes", "DiffSHEG", "CaMN"),
                                       criteria=("realism", "synchronization"), block=paradigm[:2],
                                       trial_offset=offset + 100 * i, seed=i))
    df = pd.concat(parts, ignore_index=True)
    df.assign(criterion_label=df["criterion"].map(labels)).to_csv(tmp_path / "r.csv", index=False)
    pd.DataFrame({"condition": ["FaceCapGes", "DiffSHEG", "CaMN"], "stimulus": "s1",
                  "jerk": [1.0, 2.5, 3.1]}).to_csv(tmp_path / "metrics.csv", index=False)
    return tmp_path / "r.csv", labels


def test_tables_keep_criterion_ids_with_their_labels_beside_and_the_console_names_labels(tmp_path, capsys) -> None:
    """Every CSV table that names criteria keeps the id in ``criterion`` (what a script selects and joins on)
    and has the design's label in ``criterion_label`` right after it, as the tidy export does; the console
    summary, like the report, names each criterion by its label."""
    results, labels = _labelled_study(tmp_path)
    args = ["--bootstrap", "50", "--paradigm-bootstrap", "50", "--permutations", "0", "--group", "speaker",
            "--metrics", str(tmp_path / "metrics.csv")]
    assert main([str(results), "--out", str(tmp_path / "a"), *args]) == 0
    console = capsys.readouterr().out
    named = 0
    for path in sorted((tmp_path / "a" / "tables").glob("*.csv")):
        t = pd.read_csv(path)
        if "criterion" not in t.columns:
            continue
        named += 1
        cols = list(t.columns)
        assert cols[cols.index("criterion") + 1] == "criterion_label", path.name
        assert set(t["criterion"]) <= set(labels), path.name  # the ids stay
        assert (t["criterion_label"] == t["criterion"].map(labels)).all(), path.name
    # the rank tables, effect sizes, agreement, the breakdown, the metrics and every block's tables
    assert named >= 20
    lines = console.splitlines()
    for crit, label in labels.items():
        assert any(x.startswith(f"{label}: chi2(2) = ") for x in lines), console
        assert not any(x.startswith(f"{crit}:") for x in lines), console
    blocks = [x for x in lines if x.startswith("block ")]
    assert len(blocks) == 3 and all("Looks real: " in x and "Synchronization with speech: " in x and
                                    "realism:" not in x for x in blocks), blocks
    # the report's objective-metrics table names criteria by label too
    md = (tmp_path / "a" / "report.md").read_text(encoding="utf-8")
    assert "| Looks real | jerk |" in md and "| realism | jerk |" not in md

    # a file without labels (an export before schema 7): the label column is the id, so scripts see one layout
    pd.read_csv(results).drop(columns="criterion_label").to_csv(tmp_path / "old.csv", index=False)
    assert main([str(tmp_path / "old.csv"), "--out", str(tmp_path / "b"), *args]) == 0
    assert any(x.startswith("realism: chi2(2) = ") for x in capsys.readouterr().out.splitlines())
    old = pd.read_csv(tmp_path / "b" / "tables" / "friedman.csv")
    assert list(old.columns[:2]) == ["criterion", "criterion_label"]
    assert (old["criterion_label"] == old["criterion"]).all()
