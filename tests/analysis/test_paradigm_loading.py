"""Paradigm blocks through the loader, the analysis, the report and the command line.

A CSV and a schema-6 database of the same answers load to the same analysis; old rank-only files load exactly
as before; ``rank`` is needed on rank rows only; the rank analysis sees only rank rows; the report has one
section per block with its tables and figures (Chinese labels drawn with a CJK font).
"""
from __future__ import annotations

import json
import sqlite3
import warnings

import numpy as np
import pandas as pd
import pytest

from results_analysis.analysis import run_analysis
from results_analysis.cli import main
from results_analysis.errors import AnalysisInputError
from results_analysis.loader import load_results
from results_analysis.paradigm_analysis import analyze_blocks
from results_analysis.report import analyze
from results_analysis.simulate import simulate_paradigm, simulate_results
from results_analysis.validate import validate_results


@pytest.fixture(scope="module")
def study() -> pd.DataFrame:
    """A rank block, then pairwise, mismatch and rating blocks (with a hidden reference P03 rates low)."""
    rank = simulate_results(10, 3, seed=1, n_attention=0).assign(block="main", paradigm="rank")
    start = int(rank["trial_index"].max()) + 1
    return pd.concat([rank,
                      simulate_paradigm("pairwise", 10, 6, trial_offset=start, seed=1),
                      simulate_paradigm("mismatch", 10, 6, trial_offset=start + 6, seed=1),
                      simulate_paradigm("rating", 10, 4, trial_offset=start + 12, reference="ref",
                                        bad_raters=["P03"], seed=1)], ignore_index=True)


def test_old_rank_only_csv_loads_as_one_rank_block(tmp_path) -> None:
    df = simulate_results(6, 2, seed=3)
    df.to_csv(tmp_path / "r.csv", index=False)
    got = load_results(tmp_path / "r.csv")
    assert got["rank"].tolist() == df["rank"].astype(float).tolist()
    assert set(got["paradigm"]) == {"rank"} and set(got["block"]) == {"main"}
    a = run_analysis(got, n_boot=0)
    assert a.paradigm_blocks == {} and list(a.criteria) == ["realism", "synchronization", "diversity"]


def test_rank_is_needed_on_rank_rows_only(tmp_path, study) -> None:
    study.to_csv(tmp_path / "s.csv", index=False)
    got = load_results(tmp_path / "s.csv")
    assert got.loc[got["paradigm"] != "rank", "rank"].isna().all()
    assert got.loc[got["paradigm"] == "rank", "rank"].notna().all()
    broken = study.copy()
    broken.loc[3, "rank"] = np.nan  # a rank row
    broken.to_csv(tmp_path / "b.csv", index=False)
    with pytest.raises(AnalysisInputError, match=r"b\.csv: line 5, column 'rank'"):
        load_results(tmp_path / "b.csv")
    # a study of other paradigms only: its rank column is empty
    study[study["paradigm"] != "rank"].to_csv(tmp_path / "p.csv", index=False)
    assert load_results(tmp_path / "p.csv")["rank"].isna().all()


def test_an_unknown_paradigm_is_named_with_its_line(tmp_path, study) -> None:
    bad = study.copy()
    bad.loc[len(bad) - 3, "paradigm"] = "slider"
    bad.to_csv(tmp_path / "u.csv", index=False)
    with pytest.raises(AnalysisInputError, match=rf"line {len(bad) - 1}, column 'paradigm': 'slider' is not one of "
                                                 "rank, pairwise"):
        run_analysis(load_results(tmp_path / "u.csv"), n_boot=0, paradigm_n_boot=0)


def test_rank_analysis_uses_only_rank_rows(study) -> None:
    mixed = run_analysis(study, n_boot=50, paradigm_n_boot=100)
    alone = run_analysis(study[study["paradigm"] == "rank"], n_boot=50)
    for crit in alone.criteria:
        assert mixed.criteria[crit].friedman.chi2 == alone.criteria[crit].friedman.chi2
        assert mixed.criteria[crit].friedman.n_blocks == alone.criteria[crit].friedman.n_blocks
    assert mixed.conditions == alone.conditions
    assert [(b.block, b.paradigm) for b in mixed.paradigm_blocks.values()] == [
        ("pairwise", "pairwise"), ("mismatch", "mismatch"), ("rating", "rating")]
    # the public validator checks (and returns) the rank rows
    assert set(validate_results(study)["paradigm"]) == {"rank"}
    # excluding a participant from the study leaves them out of every block
    out = run_analysis(study, n_boot=0, paradigm_n_boot=0, exclude=["P02"])
    assert all(b.n_participants == 9 for b in out.paradigm_blocks.values())


def _write_schema6(df: pd.DataFrame, path) -> None:
    """A results database laid out as schema 6 (paradigms.md section 4), written from a tidy frame."""
    con = sqlite3.connect(path)
    con.executescript("""
    CREATE TABLE trials (participant TEXT, trial_index INTEGER, session INTEGER, stimulus TEXT, plays INTEGER,
        response_time_s REAL, is_practice INTEGER, is_attention_check INTEGER, attention_passed INTEGER,
        trial_duration_s REAL, sample_left INTEGER, sample_middle INTEGER, sample_right INTEGER, block TEXT,
        paradigm TEXT, PRIMARY KEY (participant, trial_index));
    CREATE TABLE responses (participant TEXT, trial_index INTEGER, criterion TEXT, condition TEXT, slot INTEGER,
        rank REAL, design_hash TEXT, app_version TEXT);
    CREATE TABLE trial_slots (participant TEXT, trial_index INTEGER, slot INTEGER, condition TEXT,
        motion_stimulus TEXT, sample INTEGER, design_hash TEXT, app_version TEXT);
    CREATE TABLE judgements (participant TEXT, trial_index INTEGER, criterion TEXT, slot INTEGER, condition TEXT,
        value REAL NOT NULL, reasons TEXT, design_hash TEXT, app_version TEXT);
    """)
    trials = df.drop_duplicates(["participant", "trial_index"])
    con.executemany("INSERT INTO trials VALUES (?,?,?,?,?,?,?,?,?,NULL,NULL,NULL,NULL,?,?)", [
        (r.participant, int(r.trial_index), 1, r.stimulus, int(r.plays), float(r.response_time_s),
         int(r.is_practice), int(r.is_attention_check), int(r.attention_passed) if r.is_attention_check else None,
         None if r.paradigm == "rank" else r.block, None if r.paradigm == "rank" else r.paradigm)
        for r in trials.itertuples()])
    slots = df.drop_duplicates(["participant", "trial_index", "slot"])
    con.executemany("INSERT INTO trial_slots VALUES (?,?,?,?,?,NULL,'h','v')", [
        (r.participant, int(r.trial_index), int(r.slot), r.condition,
         r.motion_stimulus if isinstance(r.motion_stimulus, str) else r.stimulus) for r in slots.itertuples()])
    rank = df[df["paradigm"] == "rank"]
    con.executemany("INSERT INTO responses VALUES (?,?,?,?,?,?,'h','v')", [
        (r.participant, int(r.trial_index), r.criterion, r.condition, int(r.slot), float(r["rank"]))
        for _, r in rank.iterrows()])
    other = df[df["paradigm"] != "rank"]
    con.executemany("INSERT INTO judgements VALUES (?,?,?,?,?,?,?,'h','v')", [
        (r.participant, int(r.trial_index), r.criterion, int(r.slot), r.condition,
         float(r.rating if r.paradigm == "rating" else r.preference), r.reasons or None)
        for r in other.itertuples()])
    con.commit()
    con.close()


def test_a_schema6_database_loads_like_its_csv(tmp_path, study) -> None:
    _write_schema6(study, tmp_path / "s.sqlite")
    study.to_csv(tmp_path / "s.csv", index=False)
    db, csv = load_results(tmp_path / "s.sqlite"), load_results(tmp_path / "s.csv")
    for col in ("block", "paradigm", "rating", "preference", "matched", "motion_stimulus"):
        assert col in db.columns
    m = db[db["paradigm"] == "mismatch"]
    assert (m["matched"] == (m["motion_stimulus"] == m["stimulus"]).astype(float)).all()
    assert set(m["matched"]) == {0.0, 1.0}
    assert db.loc[db["paradigm"] == "rank", ["block", "rating", "preference"]].assign(
        r=lambda t: t.rating.isna() & t.preference.isna())["r"].all()
    a, b = analyze_blocks(db, n_boot=200), analyze_blocks(csv, n_boot=200)
    assert list(a) == list(b) == ["pairwise", "mismatch", "rating"]
    pd.testing.assert_frame_equal(a["pairwise"].results["realism"].elo, b["pairwise"].results["realism"].elo)
    pd.testing.assert_frame_equal(a["mismatch"].results["realism"].rates, b["mismatch"].results["realism"].rates)
    pd.testing.assert_frame_equal(a["rating"].results["realism"].summary, b["rating"].results["realism"].summary)
    # the rank analysis of the database is the CSV's
    assert run_analysis(db, n_boot=0, paradigm_n_boot=0).criteria["realism"].friedman.chi2 == pytest.approx(
        run_analysis(csv, n_boot=0, paradigm_n_boot=0).criteria["realism"].friedman.chi2)
    # a bad judgement is reported with its table and row
    con = sqlite3.connect(tmp_path / "s.sqlite")
    con.execute("UPDATE judgements SET value = 7 WHERE rowid = 3")
    con.commit()
    con.close()
    with pytest.raises(AnalysisInputError, match=r"judgements row 3 .*column 'preference'"):
        analyze_blocks(load_results(tmp_path / "s.sqlite"), n_boot=0)


def test_report_has_a_section_per_block(tmp_path, study) -> None:
    out = tmp_path / "out"
    analyze(study, out, n_boot=50, paradigm_n_boot=300, reference="ref", screen_reference=True)
    md = (out / "report.md").read_text()
    for heading in ("## Block pairwise (pairwise)", "## Block mismatch (mismatch)", "## Block rating (rating)"):
        assert md.count(heading) == 1
    assert md.index("Friedman tests per criterion") < md.index("## Block pairwise")
    for name in ("block_pairwise_elo", "block_pairwise_wins", "block_mismatch_mismatch", "block_rating_ratings",
                 "rank_shares"):
        assert (out / "figures" / f"{name}.png").stat().st_size > 0
        assert md.count(f"figures/{name}.png") == 1  # each figure drawn and shown once
    stats = json.loads((out / "stats.json").read_text())["_blocks"]
    elo = {r["condition"]: r["elo"] for r in stats["pairwise"]["criteria"]["realism"]["elo"]}
    assert sum(elo.values()) == pytest.approx(0.0, abs=1e-9)
    assert [r["participant"] for r in stats["rating"]["excluded"]] == ["P03"]
    assert "P03 (rated the hidden reference below 90" in md
    table = pd.read_csv(out / "tables" / "block_mismatch_mismatch_comparisons.csv")
    assert {"p_barnard", "p_barnard_adjusted", "p_bootstrap_adjusted"} <= set(table.columns)


def test_cli_analyses_a_study_of_other_paradigms_only_with_chinese_labels(tmp_path, study, capsys) -> None:
    from results_analysis import figures

    labels = {"A": "模型甲", "B": "模型乙", "C": "真人动作", "ref": "参考"}
    other = study[study["paradigm"] != "rank"]
    other.assign(condition_label=other["condition"].map(labels)).to_csv(tmp_path / "p.csv", index=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rc = main([str(tmp_path / "p.csv"), "--out", str(tmp_path / "o"), "--reference", "参考",  # a label
                   "--screen-reference", "--paradigm-bootstrap", "200"])
    printed = capsys.readouterr().out
    assert rc == 0
    assert "block pairwise (pairwise, 10 participants): realism: Elo A " in printed
    assert "screened out: P03" in printed
    assert not (tmp_path / "o" / "tables" / "friedman.csv").exists()  # no rank block, no rank tables
    md = (tmp_path / "o" / "report.md").read_text()
    assert "## Block mismatch (mismatch)" in md and "| 模型甲 | +" in md  # tables show the labels
    assert "P03 (rated the hidden reference below 90" in md and "hidden reference (参考)" in md
    if len(figures.font_families()) < 2:  # pragma: no cover - the CI installs fonts-wqy-microhei
        pytest.skip("no CJK font installed (apt install fonts-wqy-microhei): glyphs not checked")
    assert [str(w.message) for w in caught if "missing from font" in str(w.message)] == []
    svg = (tmp_path / "o" / "figures" / "block_pairwise_elo.svg").read_text()
    assert "模型甲" in svg and "真人动作" in svg


def test_screening_out_everyone_says_which_reference_and_rule_and_what_to_do(study) -> None:
    """A wrong --reference (a system every participant rates below 90) screens out everyone: the one line names
    the condition, the rule and the way out, rather than only that nobody is left."""
    from results_analysis.paradigm_analysis import analyze_block

    rating = study[study["paradigm"] == "rating"].copy()
    rating.attrs["source"] = "s.csv"
    with pytest.raises(AnalysisInputError, match=r"hidden reference 'A' below 90 in more than 15% of the items "
                                                 r"-- fix: .*leave out --screen-reference"):
        analyze_block(rating, "rating", "rating", n_boot=0, reference="A", screen=True)
