"""Bad input is reported with the file, the row/column and the problem; exclusions are applied and listed."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from results_analysis import (AnalysisInputError, MixedDesignWarning, apply_exclusions, load_questionnaire,
                              load_results, run_analysis, simulate_results, validate_results)


def _write(tmp_path: Path, df: pd.DataFrame, name: str = "results.csv") -> Path:
    p = tmp_path / name
    df.to_csv(p, index=False)
    return p


@pytest.fixture
def clean() -> pd.DataFrame:
    return simulate_results(4, 3, seed=1, n_practice=0, n_attention=0)


def test_missing_column_names_file_and_column(tmp_path: Path, clean: pd.DataFrame) -> None:
    p = _write(tmp_path, clean.drop(columns=["rank"]))
    with pytest.raises(AnalysisInputError) as e:
        load_results(p)
    assert str(p) in str(e.value) and "rank" in e.value.where
    # the columns found are the file's own, without the loader's internal helper column
    found = e.value.problem.split("found: ", 1)[1]
    assert found.split(", ") == [c for c in clean.columns if c != "rank"]
    assert "_where" not in str(e.value)


def test_rank_out_of_range_names_line(tmp_path: Path, clean: pd.DataFrame) -> None:
    bad = clean.copy()
    bad.loc[7, "rank"] = 4
    p = _write(tmp_path, bad)
    with pytest.raises(AnalysisInputError) as e:
        validate_results(load_results(p))
    # row index 7 is line 9 of the file (line 1 is the header)
    assert e.value.path == str(p) and e.value.where == "line 9, column 'rank'"
    assert "rank 4 is outside 1..3" in e.value.problem


def test_non_numeric_rank_names_line(tmp_path: Path, clean: pd.DataFrame) -> None:
    bad = clean.astype({"rank": object})
    bad.loc[2, "rank"] = "first"
    with pytest.raises(AnalysisInputError, match=r"line 4, column 'rank': 'first' is not a number"):
        load_results(_write(tmp_path, bad))


def test_duplicated_rows_name_both_lines(tmp_path: Path, clean: pd.DataFrame) -> None:
    bad = pd.concat([clean, clean.iloc[[5]]], ignore_index=True)
    p = _write(tmp_path, bad)
    with pytest.raises(AnalysisInputError) as e:
        validate_results(load_results(p))
    assert e.value.where == f"line 7 and line {len(bad) + 1}"
    assert "appears more than once" in e.value.problem


def test_trial_not_ranking_every_condition(tmp_path: Path, clean: pd.DataFrame) -> None:
    row = clean.iloc[4]
    bad = clean.drop(index=4)
    p = _write(tmp_path, bad)
    df = load_results(p)
    with pytest.raises(AnalysisInputError) as e:
        validate_results(df)
    assert f"participant {row['participant']}" in e.value.where and row["criterion"] in e.value.where
    assert f"{row['condition']} missing" in e.value.problem
    # listwise deletion drops exactly that trial's criterion block
    kept = validate_results(df, incomplete="drop")
    assert kept.attrs["dropped_incomplete"] == 1
    assert len(kept) == len(clean) - 3
    a = run_analysis(df, incomplete="drop", block="trial", n_boot=50)
    assert a.criteria[row["criterion"]].friedman.n_blocks == 4 * 3 - 1
    assert a.dropped_incomplete == 1


def test_mixed_design_hashes_warn_with_names(clean: pd.DataFrame) -> None:
    df = clean.copy()
    df.loc[df.participant == "P01", "design_hash"] = "abc123"
    with pytest.warns(MixedDesignWarning, match=r"abc123 \(1 participant\), synthetic \(3 participants\)"):
        validate_results(df)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        a = run_analysis(df, n_boot=50)
    assert any("abc123" in w for w in a.warnings)


def test_bad_flag_value_names_column(tmp_path: Path, clean: pd.DataFrame) -> None:
    bad = clean.astype({"is_practice": object})
    bad.loc[0, "is_practice"] = "maybe"
    with pytest.raises(AnalysisInputError, match=r"line 2, column 'is_practice'"):
        load_results(_write(tmp_path, bad))


def test_csv_round_trip_keeps_types(tmp_path: Path) -> None:
    df = simulate_results(3, 2, seed=2)
    back = load_results(_write(tmp_path, df))
    assert back["is_practice"].dtype == bool and back["rank"].dtype == float
    assert back["is_practice"].sum() == df["is_practice"].sum()
    assert (back["participant"] == df["participant"]).all()


def test_exclusions_practice_attention_and_by_name() -> None:
    df = simulate_results(6, 3, seed=3, fail_attention=["P02"])
    kept, who = apply_exclusions(df)
    assert not kept["is_practice"].any() and not kept["is_attention_check"].any()
    assert who.empty and "P02" in set(kept["participant"])
    kept, who = apply_exclusions(df, exclude_failed_attention=True, exclude=["P04", "P99"])
    assert set(kept["participant"]) == {"P01", "P03", "P05", "P06"}
    reasons = dict(zip(who["participant"], who["reason"]))
    assert reasons == {"P02": "failed 1 of 1 attention check(s)", "P04": "excluded by name (--exclude)",
                       "P99": "excluded by name (--exclude), but has no answers"}


def test_questionnaire_csv_errors(tmp_path: Path) -> None:
    p = tmp_path / "q.csv"
    p.write_text("participant,item,scale,value\nP1,q1,ease,4\nP1,q1,ease,5\n")
    with pytest.raises(AnalysisInputError, match="line 2 and line 3"):
        load_questionnaire(p)
    p.write_text("participant,item,scale,value\nP1,q1,ease,lots\n")
    with pytest.raises(AnalysisInputError, match=r"line 2, column 'value'"):
        load_questionnaire(p)


def test_sqlite_database_gives_the_same_frame_as_the_schema_says(tmp_path: Path) -> None:
    storage = pytest.importorskip("studyapp.study.storage")
    from types import SimpleNamespace

    design = SimpleNamespace(design_hash="h1", title="t",
                             stimuli=[SimpleNamespace(id="clip1", tags={"speaker": "s1"}),
                                      SimpleNamespace(id="clip2", tags={"speaker": "s2"})],
                             conditions=[SimpleNamespace(id=c) for c in ("A", "B", "C")])
    db = storage.ResultsDB(tmp_path / "r.sqlite", design)
    expected = []
    for p_i, pid in enumerate(["P1", "P2", "P3"]):
        db.add_participant(pid, n_rows=1, groups={"device": "vr" if p_i else "desktop"})
        for t, (stim, practice, check) in enumerate([("clip1", True, False), ("clip2", False, True),
                                                     ("clip1", False, False), ("clip2", False, False)]):
            order = np.roll(np.array([1.0, 2.0, 3.0]), p_i + t)
            responses = [storage.Response(crit, c, s, float(order[s]))
                         for crit in ("realism", "sync") for s, c in enumerate("ABC")]
            db.save_trial(storage.TrialRecord(
                participant=pid, trial_index=t, stimulus=stim, is_practice=practice, is_attention_check=check,
                slots=("A", "B", "C"), answered_at="2026-01-01T00:00:00", plays=2, response_time_s=3.5,
                attention_passed=(pid != "P3") if check else None), responses)
            expected += [(pid, t, r.criterion, r.condition, r.rank) for r in responses]
    kinds = {"q1": ("likert", "ease"), "q2": ("likert", "ease"), "note": ("text", None)}
    db.save_questionnaire("P1", {"q1": 4, "q2": 5, "note": "nice"}, kinds)
    db.save_questionnaire("P2", {"q1": 2, "q2": 3, "note": "ok"}, kinds)
    db.close()
    df = load_results(tmp_path / "r.sqlite")
    got = sorted(zip(df.participant, df.trial_index.astype(int), df.criterion, df.condition, df["rank"]))
    assert got == sorted(expected)
    assert set(df.columns) >= {"speaker", "device", "is_practice", "is_attention_check", "attention_passed",
                               "design_hash", "session", "slot"}
    assert df.loc[df.stimulus == "clip2", "speaker"].eq("s2").all()
    assert df.loc[df.participant == "P1", "device"].eq("desktop").all()
    assert not df.loc[(df.participant == "P3") & df.is_attention_check, "attention_passed"].any()
    a = run_analysis(df, exclude_failed_attention=True, groups=["speaker"], n_boot=50,
                     questionnaire=load_questionnaire(tmp_path / "r.sqlite"))
    assert list(a.exclusions["participant"]) == ["P3"]
    assert a.criteria["realism"].friedman.n_blocks == 2  # the 2 kept participants (primary: participant blocks)
    assert a.criteria["realism"].sensitivity.n_blocks == 4  # 2 rated trials x 2 kept participants
    assert a.questionnaire_reliability[["scale", "n_items", "n_participants", "alpha"]].to_dict("records") == [
        {"scale": "ease", "n_items": 2, "n_participants": 2, "alpha": pytest.approx(2 * (1 - 2 / 4))}]
    # the text item is not summarised
    assert set(load_questionnaire(tmp_path / "r.sqlite")["item"]) == {"q1", "q2"}


def test_sqlite_loader_agrees_with_studyapp_export(tmp_path: Path) -> None:
    """Our own reader of the database and studyapp's exporter (via its CSV) give the same tidy frame."""
    storage = pytest.importorskip("studyapp.study.storage")
    export = pytest.importorskip("studyapp.study.export")
    from types import SimpleNamespace

    design = SimpleNamespace(design_hash="h2", title="t", stimuli=[SimpleNamespace(id="c1", tags={"speaker": "a"})],
                             conditions=[SimpleNamespace(id=c) for c in "XYZ"])
    db = storage.ResultsDB(tmp_path / "r.sqlite", design)
    for pid in ("P1", "P2"):
        db.add_participant(pid, n_rows=1, groups={"device": "vr"})
        for t in range(3):
            db.save_trial(storage.TrialRecord(
                participant=pid, trial_index=t, stimulus="c1", is_practice=t == 0, is_attention_check=t == 1,
                slots=("Z", "X", "Y"), answered_at="2026-01-01T00:00:00", plays=1, response_time_s=1.0 + t,
                attention_passed=True if t == 1 else None),
                [storage.Response("realism", c, s, float(s + 1)) for s, c in enumerate("ZXY")])
    db.close()
    csv = tmp_path / "export.csv"
    export.export_dataframe(tmp_path / "r.sqlite").to_csv(csv, index=False)
    ours = load_results(tmp_path / "r.sqlite").drop(columns="_where")
    theirs = load_results(csv).drop(columns="_where")
    cols = sorted(theirs.columns)
    assert sorted(ours.columns) == cols
    key = ["participant", "trial_index", "criterion", "condition"]
    pd.testing.assert_frame_equal(ours[cols].sort_values(key).reset_index(drop=True),
                                  theirs[cols].sort_values(key).reset_index(drop=True), check_dtype=False)


def test_skillings_mack_mode_keeps_incomplete_trials(clean: pd.DataFrame) -> None:
    bad = clean.drop(index=[4, 13])  # two trials lose one condition each (criteria may differ)
    a = run_analysis(bad, incomplete="skillings-mack", block="trial", n_boot=50)
    n_incomplete = sum(c.friedman.n_blocks < 12 for c in a.criteria.values())
    assert a.incomplete_blocks == 2 and n_incomplete >= 1
    for c in a.criteria.values():
        sm = c.skillings_mack
        assert sm is not None and sm.n_blocks == 12  # all trials, incomplete ones included
        assert sm.n_missing == 12 - c.friedman.n_blocks
        assert sm.n_permutations == 2000 and 0 < sm.p_permutation <= 1


def test_skillings_mack_permutation_p_reaches_stats_and_report(clean: pd.DataFrame, tmp_path: Path) -> None:
    import json

    from results_analysis.cli import main

    bad = clean.drop(index=[4, 13])
    src = tmp_path / "incomplete.csv"
    bad.to_csv(src, index=False)
    assert main([str(src), "--out", str(tmp_path / "a"), "--incomplete", "skillings-mack", "--permutations", "999",
                 "--bootstrap", "50"]) == 0
    stats_json = json.loads((tmp_path / "a" / "stats.json").read_text())
    for crit in bad["criterion"].unique():
        sm = stats_json[crit]["skillings_mack"]
        assert sm["n_permutations"] == 999 and 0 < sm["p_permutation"] <= 1
        assert sm["p_permutation"] * 1000 == pytest.approx(round(sm["p_permutation"] * 1000))  # (1 + hits) / 1000
    report = (tmp_path / "a" / "report.md").read_text()
    assert "permutation test with 999 within-trial shuffles" in report
    assert "Monte Carlo permutation p-value from 999 shuffles" in report
    assert main([str(src), "--out", str(tmp_path / "b"), "--incomplete", "skillings-mack", "--permutations", "0",
                 "--bootstrap", "50"]) == 0
    assert "permutation" not in (tmp_path / "b" / "report.md").read_text()


def test_a_postgresql_url_is_told_to_export_first() -> None:
    """``studyapp serve --db postgresql://...`` keeps results in PostgreSQL; the analysis reads files, so the
    message says how to get one (not "file not found" for a mangled path)."""
    with pytest.raises(AnalysisInputError, match=r"studyapp export URL --csv"):
        load_results("postgresql://postgres@/study?host=/tmp/pg&port=5432")
