"""Criterion labels in the results (schema 7): the design's label and question of every criterion are stored
with the results, the tidy export and its CSV carry ``criterion_label``, the report and its figures name each
criterion by it (by its id for files without one), a version 6 database written by the old code is upgraded
in place, and a returned results file's criteria are checked against the design before a merge."""
from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path
from types import SimpleNamespace as NS

import pandas as pd
import pytest

from fixtures.synthetic import write_synthetic_study
from studyapp.study import row_checksums
from studyapp.study.storage import SCHEMA_VERSION, ResultsDB

DATA = Path(__file__).resolve().parents[1] / "data"

CRITERIA = '''
[[criteria]]
id = "real"
label = "Looks like a real person"
question = "Which motion looks most like a real person?"

[[criteria]]
id = "sync"
label = "Synchronization with speech"
question = "Which motion is best in time with the speech?"
'''
LABELS = {"real": "Looks like a real person", "sync": "Synchronization with speech"}


def _study(tmp_path: Path) -> Path:
    path = write_synthetic_study(tmp_path / "s", n_stimuli=3, seconds=0.3, practice=False)
    path.write_text(path.read_text() + CRITERIA)
    return path


@pytest.fixture
def labelled(tmp_path: Path) -> tuple[Path, Path]:
    """A study whose criteria have labels other than their ids, and its results of 6 bot participants (each
    watching every clip to its end, as a merge requires)."""
    from studyapp.bots.session_driver import run_bot_session
    from studyapp.study.design import load_design

    design_path = _study(tmp_path)
    design = load_design(design_path)
    db_path = tmp_path / "r.sqlite"
    with ResultsDB(db_path, design) as db:
        for k in range(6):
            run_bot_session(design, db, f"P{k + 1}", "ordered" if k % 2 else "random", k, pace_s=0.3)  # watched
    return design_path, db_path


def test_the_design_s_criterion_labels_are_stored_and_exported(labelled, tmp_path: Path) -> None:
    from studyapp.cli import main

    _, db_path = labelled
    with sqlite3.connect(db_path) as con:
        rows = con.execute("SELECT id, position, label, question FROM criteria ORDER BY position").fetchall()
    con.close()
    assert rows == [("real", 0, LABELS["real"], "Which motion looks most like a real person?"),
                    ("sync", 1, LABELS["sync"], "Which motion is best in time with the speech?")]
    out = tmp_path / "export.csv"
    assert main(["export", str(db_path), "--csv", str(out)]) == 0
    csv = pd.read_csv(out)
    assert list(csv.columns[4:6]) == ["criterion", "criterion_label"]
    assert dict(zip(csv["criterion"], csv["criterion_label"])) == LABELS


def test_a_schema_6_database_made_by_the_old_code_is_upgraded_in_place(tmp_path: Path) -> None:
    """tests/data/results_schema6.sqlite was written by studyapp before schema 7 (two bot participants of the
    synthetic study, default criteria): read as it is, the export names criteria by their ids; upgraded in
    place, every row is unchanged and every checksum verifies; once the design is recorded, its labels show."""
    from results_analysis import integrity
    from results_analysis.sqlite_schema import tidy_table
    from studyapp.study.export import export_dataframe

    path = tmp_path / "r.sqlite"
    shutil.copy(DATA / "results_schema6.sqlite", path)
    with sqlite3.connect(path) as con:
        assert con.execute("SELECT version FROM schema_version").fetchone()[0] == 6
        assert not con.execute("SELECT 1 FROM sqlite_master WHERE name = 'criteria'").fetchone()
        tables = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name")]
        before = {t: sorted(map(tuple, con.execute(f"SELECT * FROM {t}"))) for t in tables}
        old = tidy_table(con, path)  # the analysis reads a version 6 file as it is
    con.close()
    assert (old["criterion_label"] == old["criterion"]).all() and len(old) == 2 * 3 * 3 * 2
    with ResultsDB(path, create=False) as db:
        con = db.connection
        assert con.execute("SELECT version FROM schema_version").fetchone()[0] == SCHEMA_VERSION == 7
        assert row_checksums.verify(con) == [] and db.criteria() == []
        for t in tables:
            if t not in (row_checksums.TABLE, "schema_version"):
                assert sorted(map(tuple, con.execute(f"SELECT * FROM {t}"))) == before[t], t
    pd.testing.assert_frame_equal(export_dataframe(path), old)
    with ResultsDB(path, create=False) as db:  # what merge does once it has loaded the design
        db.store_design_metadata(NS(criteria=[NS(id="realism", label="Realism", question="Real?"),
                                              NS(id="synchronization", label="In time with speech", question="?")]))
    df = export_dataframe(path)
    assert dict(zip(df["criterion"], df["criterion_label"])) == {
        "realism": "Realism", "synchronization": "In time with speech", "diversity": "diversity"}
    with sqlite3.connect(path) as con:
        assert integrity.damaged_rows(con) == []  # results_analysis's own checksums cover the new table
    con.close()


def test_the_report_names_criteria_by_their_labels_and_old_files_by_their_ids(labelled, tmp_path: Path) -> None:
    from results_analysis.loader import load_results
    from results_analysis.report import analyze

    _, db_path = labelled
    df = load_results(db_path)
    out = tmp_path / "report"
    analyze(df, out, n_boot=40, paradigm_n_boot=40)
    md = (out / "report.md").read_text()
    assert f"**{LABELS['sync']}.** Mean ranks" in md and f"**{LABELS['real']}.** Mean ranks" in md
    assert "**Sync.**" not in md and "| sync " not in md  # neither the capitalised id nor the id in a table
    assert f"| {LABELS['sync']} " in md
    for fig in ("mean_ranks", "rank_shares", "critical_difference", "bradley_terry"):
        svg = (out / "figures" / f"{fig}.svg").read_text()
        assert LABELS["sync"] in svg and "Sync<" not in svg, fig
    stats = json.loads((out / "stats.json").read_text())
    assert "sync" in stats and stats["_meta"]["criterion_labels"] == LABELS  # numbers stay keyed by ids

    plain = tmp_path / "plain.csv"  # an export before schema 7 has no criterion_label column
    df.drop(columns=["criterion_label"]).to_csv(plain, index=False)
    analyze(load_results(plain), tmp_path / "old", n_boot=40, paradigm_n_boot=40)
    md = (tmp_path / "old" / "report.md").read_text()
    assert "**sync.** Mean ranks" in md and LABELS["sync"] not in md


def test_a_returned_file_s_criteria_are_checked_and_merge_records_the_design_s(labelled, tmp_path: Path) -> None:
    from studyapp.study.bundle import merge_results, results_payload
    from studyapp.study.design import load_design
    from studyapp.study.returned import check_returned
    from studyapp.study.session import trial_duration_s

    design_path, db_path = labelled
    design = load_design(design_path)
    with ResultsDB(db_path, create=False) as db:
        payload = results_payload(db, "P1", "s")
    assert [(c["id"], c["label"]) for c in payload["criteria"]] == list(LABELS.items())

    def findings(p: dict) -> list[str]:
        return [str(f) for f in check_returned(p, design, roster=None, allow_unlisted=True, others={},
                                               duration_of=lambda plan: trial_duration_s(design, plan))]

    assert findings(payload) == []
    edited = {**payload, "criteria": [{**payload["criteria"][1], "label": "Sync"}]}
    assert findings(edited) == [f"criteria: criterion 'sync' is labelled 'Sync' in the file, '{LABELS['sync']}' "
                                "in the design: the file was not made from this study's design"]
    foreign = {**payload, "criteria": [{"id": "diversity", "label": "Diversity", "question": "?"}]}
    assert findings(foreign) == ["criteria: criterion 'diversity' is not one of the design's (real, sync)"]

    # a database that never recorded the design's criteria (made without it) gets them from the merge
    from studyapp.study.bundle import write_results_file

    with ResultsDB(db_path, create=False) as db:
        returned = write_results_file(db, "P2", tmp_path / "returned")
    target = tmp_path / "lab.sqlite"
    ResultsDB(target, design_hash=design.design_hash, title=design.title).close()
    [report] = merge_results(target, [returned], design=design_path)
    assert report.ok, report.problems
    with ResultsDB(target, create=False) as db:
        assert [(c["id"], c["label"]) for c in db.criteria()] == list(LABELS.items())


def test_export_with_the_design_records_the_labels_of_an_upgraded_schema_6_database(tmp_path: Path, capsys,
                                                                                   monkeypatch) -> None:
    """A schema 6 database (tests/data/results_schema6.sqlite, made by the old code from the synthetic study
    rebuilt here byte for byte) exports criteria by their ids with a one-line note saying how to get the labels;
    ``export --design`` refuses another design in one line, recording nothing, and with the study's own design
    records its labels, which every later export keeps."""
    from studyapp.cli import main
    from studyapp.study.design import load_design

    path = tmp_path / "r.sqlite"
    shutil.copy(DATA / "results_schema6.sqlite", path)
    design = write_synthetic_study(tmp_path / "study", n_stimuli=2, seconds=1.0, practice=False)
    with sqlite3.connect(path) as con:
        recorded = con.execute("SELECT design_hash FROM study").fetchone()[0]
    con.close()
    assert load_design(design, check_files=False).design_hash == recorded, "the fixture no longer rebuilds the study"
    out = tmp_path / "a.csv"

    assert main(["export", str(path), "--csv", str(out)]) == 0
    notes = [x for x in capsys.readouterr().err.splitlines() if x.startswith("note:")]
    assert notes == ["note: the database records no criterion labels (made before schema 7), so the export names "
                     "criteria by their ids; add --design STUDY.toml to record the design's labels"]
    before = pd.read_csv(out)
    assert (before["criterion_label"] == before["criterion"]).all()

    other = write_synthetic_study(tmp_path / "other", n_stimuli=3, seconds=1.0, practice=False)
    assert main(["export", str(path), "--csv", str(tmp_path / "b.csv"), "--design", str(other)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: {other}: not the design this results database was made for (design hash ")
    assert "\n" not in err and not (tmp_path / "b.csv").exists()
    with ResultsDB(path, create=False) as db:
        assert db.criteria() == []  # nothing recorded from another design

    checks, check = [], ResultsDB._check_rows
    monkeypatch.setattr(ResultsDB, "_check_rows", lambda db: (checks.append(db.path), check(db))[1])
    assert main(["export", str(path), "--csv", str(out), "--design", str(design)]) == 0
    assert "note:" not in capsys.readouterr().err
    assert checks == [path]  # opened once (each opening checks every row), not once per step
    labelled = pd.read_csv(out)
    names = {"realism": "Realism", "synchronization": "Synchronization", "diversity": "Diversity"}
    assert dict(zip(labelled["criterion"], labelled["criterion_label"])) == names
    pd.testing.assert_frame_equal(labelled.drop(columns="criterion_label"), before.drop(columns="criterion_label"))
    assert main(["export", str(path), "--csv", str(tmp_path / "c.csv")]) == 0  # recorded: no --design needed now
    assert "note:" not in capsys.readouterr().err
    assert dict(zip(*pd.read_csv(tmp_path / "c.csv")[["criterion", "criterion_label"]].T.values)) == names
