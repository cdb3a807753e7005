"""Returned results files are checked answer by answer before anything is merged (``studyapp merge``).

A real bundle, a real remote session (the session bot, as a separate ``studyapp run`` process on the
"participant's PC"), a real results zip; then ``results.json`` is edited and its sha256 recomputed, so the
checksum passes and only the checks of :mod:`studyapp.study.returned` stand between the edit and the
database. Each edit is refused with its own message and nothing of it is imported; the untouched file
merges, and merging it again is "already merged" with exit status 0.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import zipfile
from io import StringIO
from pathlib import Path
from typing import Any, Callable

import pandas as pd
import pytest

from fixtures.synthetic import write_synthetic_study
from studyapp.study.bundle import merge_results, write_results_file
from studyapp.study.design import load_design
from studyapp.study.returned import check_timings, valid_stored_ranking
from studyapp.study.schedule import participant_schedule
from studyapp.study.storage import ResultsDB

CLI = [sys.executable, "-m", "studyapp.cli"]
CLIP_S = 0.3  # seconds per clip: the bots watch each clip this long, as the design requires


def _run(*args: Any, env: dict | None = None, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=300,
                          env={**os.environ, **(env or {})}, cwd=cwd)


@pytest.fixture(scope="module")
def returned(tmp_path_factory) -> dict[str, Any]:
    """A bundle with a roster of 3, and participant R01's results file from a real remote session."""
    root = tmp_path_factory.mktemp("returned")
    design = write_synthetic_study(root / "study", n_stimuli=3, seconds=CLIP_S, attention_check=True)
    lab_db = design.with_name("tiny.results.sqlite")
    bundled = _run("bundle", design, "-o", root / "send" / "study.zip", "--participants", "3")
    assert bundled.returncode == 0, bundled.stderr
    home = root / "participant"
    home.mkdir()
    env = {"HOME": str(home), "XDG_CACHE_HOME": str(home / ".cache"), "XDG_DATA_HOME": str(home / ".local/share"),
           "STUDYAPP_RESULTS_DIR": str(home / "studyapp-results")}
    remote = _run("run", root / "send" / "study.zip", "--participant", "R01", "--no-render", "--bot", "ordered",
                  "--bot-pace", str(CLIP_S), env=env, cwd=home)
    assert remote.returncode == 0, remote.stderr
    [results_zip] = (home / "studyapp-results").glob("results-*-R01-*.zip")
    exported = _run("key", lab_db, root / "send" / "study.zip", "-o", root / "private" / "study.key.json")
    assert exported.returncode == 0, exported.stderr
    key = json.loads((root / "private" / "study.key.json").read_text())
    return {"root": root, "design": design, "db": lab_db, "zip": results_zip, "key": key,
            "bundle": root / "send" / "study.zip"}


def _fresh_db(returned: dict[str, Any], tmp_path: Path) -> Path:
    """A copy of the experimenter's database (holding the bundle's key) next to a copy of the design."""
    folder = tmp_path / "lab"
    shutil.copytree(returned["design"].parent, folder)
    return folder / returned["db"].name


def _edited(src: Path, out: Path, edit: Callable[[dict[str, Any]], None]) -> Path:
    """``src`` with ``results.json`` edited and the manifest's sha256 recomputed, so the checksum passes."""
    with zipfile.ZipFile(src) as zf:
        payload = json.loads(zf.read("results.json"))
        manifest = json.loads(zf.read("manifest.json"))
    edit(payload)
    body = json.dumps(payload, indent=1, sort_keys=True).encode()
    manifest["files"]["results.json"] = hashlib.sha256(body).hexdigest()
    manifest["participant"] = payload["participant"]
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr("results.json", body)
        zf.writestr("manifest.json", json.dumps(manifest))
    return out


def _rank_of(payload: dict[str, Any], trial: int, slot: int, value: Any) -> None:
    row = next(r for r in payload["responses"] if r["trial_index"] == trial and r["slot"] == slot)
    row["rank"] = value


def _swap_two_conditions(payload: dict[str, Any]) -> None:
    """Trial 2 claims its left and middle slots showed each other's condition (ranks follow the conditions)."""
    t = next(t for t in payload["trials"] if t["trial_index"] == 2)
    t["slot_left"], t["slot_middle"] = t["slot_middle"], t["slot_left"]
    for r in payload["responses"]:
        if r["trial_index"] == 2 and r["slot"] in (0, 1):
            r["condition"] = t["slot_left"] if r["slot"] == 0 else t["slot_middle"]


def _rename(new_id: str) -> Callable[[dict[str, Any]], None]:
    """The whole file under another participant id: every row, the header, the manifest."""
    def edit(payload: dict[str, Any]) -> None:
        old = payload["participant"]
        payload["participant"] = new_id
        payload["participants"][0]["id"] = new_id
        for table in ("sessions", "trials", "trial_slots", "responses", "judgements", "plays", "questionnaire"):
            for r in payload.get(table, []):
                if r.get("participant") == old:
                    r["participant"] = new_id
    return edit


def _out_of_schedule(payload: dict[str, Any]) -> None:
    """The last trial moved to an index the schedule does not have."""
    last = max(t["trial_index"] for t in payload["trials"])
    for table in ("trials", "responses", "plays"):
        for r in payload[table]:
            if r["trial_index"] == last:
                r["trial_index"] = 40


def _other_stimulus(payload: dict[str, Any]) -> None:
    """Trial 1 claims to have shown the clip of trial 2."""
    by_index = {t["trial_index"]: t for t in payload["trials"]}
    by_index[1]["stimulus"] = by_index[2]["stimulus"]


def _participants(db: Path) -> set[str]:
    with ResultsDB(db, create=False) as d:
        return {p.id for p in d.participants()}


def test_edited_results_are_refused_each_with_its_own_message_and_nothing_is_imported(returned, tmp_path: Path) -> None:
    db = _fresh_db(returned, tmp_path)
    edits: dict[str, tuple[Callable[[dict[str, Any]], None], str]] = {
        "rank99": (lambda p: _rank_of(p, 1, 0, 99), "ranks [99, "),
        "minus5": (lambda p: _rank_of(p, 1, 2, -5), "-5"),
        "abc": (lambda p: _rank_of(p, 2, 1, "abc"), "'abc'"),
        "swapped": (_swap_two_conditions, "trial 2: not the scheduled trial: slot_left is "),
        "index": (_out_of_schedule, "trial 40: this trial index is not in the participant's schedule"),
        "stimulus": (_other_stimulus, "trial 1: not the scheduled trial: stimulus is "),
        "realname": (lambda p: p["trials"][0].update(slot_right="synced"), "condition id 'synced' is not one of "
                                                                           "the bundle's"),
    }
    files = {name: _edited(returned["zip"], tmp_path / f"results-{name}.zip", edit) for name, (edit, _) in edits.items()}
    merged = _run("merge", db, *files.values())
    assert merged.returncode == 1, merged.stdout + merged.stderr
    lines = merged.stdout.splitlines()
    for name, (_, message) in edits.items():
        f = files[name]
        assert f"REFUSED: {f}: " in merged.stdout and "nothing of this file was imported" in merged.stdout, name
        # one line per problem: the file, the place, what is wrong
        mine = [ln.strip() for ln in lines if ln.startswith(f"  {f}: ")]
        assert any(message in ln for ln in mine), (name, mine)
    assert "0 of 7 file(s) imported" in merged.stdout and "7 refused" in merged.stdout
    # ranks of 99, -5 and "abc" are named as rankings that are not rankings
    for name in ("rank99", "minus5", "abc"):
        assert any("are not a ranking: they must be 1, 2 and 3, each once" in ln
                   for ln in lines if ln.startswith(f"  {files[name]}: ")), name
    # the consistent swap is one problem (the schedule), not four
    assert len([ln for ln in lines if ln.startswith(f"  {files['swapped']}: ")]) == 1
    assert _participants(db) == set()
    with ResultsDB(db, create=False) as d:
        assert d.trials() == [] and d.responses() == []


def test_untouched_file_merges_once_then_already_merged_and_a_copy_under_a_new_id_is_refused(returned, tmp_path: Path) -> None:
    db = _fresh_db(returned, tmp_path)
    good = returned["zip"]
    # an id that is not on the roster, showing the trials the bundle made for R01 (the database holds no one
    # to copy yet): one line for each
    z9 = _edited(good, tmp_path / "results-Z9.zip", _rename("Z9"))
    unlisted = _run("merge", db, z9)
    assert unlisted.returncode == 1 and f"REFUSED: {z9}" in unlisted.stdout
    n = len(json.loads(zipfile.ZipFile(good).read("results.json"))["trials"])
    assert [ln for ln in unlisted.stdout.splitlines() if ln.startswith(f"  {z9}: ")] == [
        f"  {z9}: participant Z9: {n} of {n} trials are those the bundle made for participant R01: their answers "
        "under another id (the file was edited)",
        f"  {z9}: participant Z9: this id is not on the bundle's roster (ids handed out: R01, R02, R03); merge "
        "with --allow-unlisted if you let participants choose their own ids"]
    assert _participants(db) == set()

    first = _run("merge", db, good)
    assert first.returncode == 0 and f"imported: {good}: participant R01" in first.stdout, first.stdout + first.stderr
    twice = _run("merge", db, good)
    assert twice.returncode == 0, twice.stdout
    assert f"{good}: participant R01: already merged, nothing to do" in twice.stdout and "REFUSED" not in twice.stdout

    # the whole file under another roster id: another row (schedule) and R01's answers (copy)
    r02 = _edited(good, tmp_path / "results-R02.zip", _rename("R02"))
    # the same under an unlisted id the experimenter allows, on R01's row: only the copy check can tell
    copy = _run("merge", db, r02)
    assert copy.returncode == 1 and f"REFUSED: {r02}" in copy.stdout
    assert "participant R02: follows Latin-square row" in copy.stdout
    assert "as participant R01's: a copy of their answers under another id" in copy.stdout
    allowed = _run("merge", db, z9, "--allow-unlisted")
    assert allowed.returncode == 1 and f"REFUSED: {z9}" in allowed.stdout
    problems = [ln for ln in allowed.stdout.splitlines() if ln.startswith(f"  {z9}: ")]
    assert len(problems) == 2 and "the bundle made for participant R01" in problems[0], problems
    assert "a copy of their answers under another id" in problems[1], problems
    assert _participants(db) == {"R01"}

    # export with no output flag prints the CSV to stdout
    exported = _run("export", db)
    assert exported.returncode == 0, exported.stderr
    df = pd.read_csv(StringIO(exported.stdout))
    design = load_design(returned["design"])
    plans = participant_schedule(design, "R01", returned["key"]["roster"]["R01"])
    assert set(df["participant"]) == {"R01"} and len(df) == len(plans) * 3 * 3
    assert set(df["condition"]) == {"synced", "lagged", "static"}


def test_a_copy_inside_one_merge_batch_refuses_both_files(returned, tmp_path: Path) -> None:
    db = _fresh_db(returned, tmp_path)
    z9 = _edited(returned["zip"], tmp_path / "results-Z9.zip", _rename("Z9"))
    reports = merge_results(db, [returned["zip"], z9], allow_unlisted=True)
    assert [r.ok for r in reports] == [False, False]
    assert any("participant Z9's" in p for p in reports[0].problems), reports[0].problems
    assert any("participant R01's" in p for p in reports[1].problems), reports[1].problems
    assert _participants(db) == set()


def test_merge_given_the_study_bundle_says_so(returned, tmp_path: Path) -> None:
    db = _fresh_db(returned, tmp_path)
    reports = merge_results(db, [returned["bundle"]])
    assert not reports[0].ok
    assert "this is a study bundle" in reports[0].message and "send it again" not in reports[0].message


def test_merge_needs_the_studys_own_design(returned, tmp_path: Path) -> None:
    from studyapp.errors import InputError

    db = _fresh_db(returned, tmp_path)
    elsewhere = tmp_path / "lab.sqlite"
    shutil.copy(db, elsewhere)
    with pytest.raises(InputError, match="needs the design: give it with --design"):
        merge_results(elsewhere, [returned["zip"]])
    other = write_synthetic_study(tmp_path / "other", n_stimuli=2, name="other")
    with pytest.raises(InputError, match="not the design this results database was made for"):
        merge_results(elsewhere, [returned["zip"]], design=other)
    assert merge_results(elsewhere, [returned["zip"]], design=returned["design"])[0].ok


def test_answers_given_sooner_than_the_clip_lasts_are_refused(tmp_path: Path) -> None:
    """A bot that 'watches' nothing answers a 1-second clip within milliseconds: implausible when the design
    requires watching each clip to the end (``must_watch_fully``, the default)."""
    from studyapp.bots.session_driver import run_bot_session

    design_path = write_synthetic_study(tmp_path / "study", n_stimuli=2, practice=False)
    design = load_design(design_path)
    lab = design_path.with_name("tiny.results.sqlite")
    ResultsDB(lab, design).close()
    remote = ResultsDB(tmp_path / "remote.sqlite", design)
    run_bot_session(design, remote, "X1", "ordered", 1, pace_s=0.0)
    fast = write_results_file(remote, "X1", tmp_path / "outbox")
    remote.close()
    [report] = merge_results(lab, [fast])
    assert not report.ok
    assert any("answered sooner after the clip was shown than the clip lasts" in p for p in report.problems)
    assert _participants(lab) == set()


def test_timings_that_go_backwards_or_cannot_be_read_are_findings() -> None:
    trials = [{"trial_index": 0, "shown_at": "2026-01-01T10:00:00.000+00:00", "answered_at": "2026-01-01T10:00:05.000+00:00",
               "response_time_s": 5.0},
              {"trial_index": 1, "shown_at": "2026-01-01T10:00:05.100+00:00", "answered_at": "2026-01-01T10:00:04.000+00:00",
               "response_time_s": -1.0},
              {"trial_index": 2, "shown_at": None, "answered_at": "yesterday", "response_time_s": 1.0}]
    found = [str(f) for f in check_timings(trials, [], {}, must_watch=False)]
    assert any("trial 1: response time -1.0" in f for f in found), found
    assert any("trial 1: answered before it was shown" in f for f in found), found
    assert any("answered no later than the trial before it" in f for f in found), found
    assert any("trial 2" in f and "not an ISO 8601 timestamp" in f for f in found), found


@pytest.mark.parametrize("values, ties, ok", [
    ((1, 2, 3), False, True), ((3.0, 1.0, 2.0), False, True), ((1, 1, 3), False, False),
    ((1.5, 1.5, 3), True, True), ((2, 2, 2), True, True), ((1, 1, 3), True, False), ((1.5, 1.5, 3), False, False),
    ((99, 1, 2), False, False), ((-5, 1, 2), True, False), (("abc", 1, 2), False, False), ((True, 2, 3), False, False),
    ((1, 2), False, False), ((float("nan"), 1, 2), True, False),
])
def test_a_stored_ranking_is_a_permutation_or_the_average_ranks_of_a_tie(values, ties, ok) -> None:
    assert valid_stored_ranking(values, ties) is ok


def test_validate_counts_one_problem_in_the_singular(tmp_path: Path, capsys) -> None:
    from studyapp.cli import main

    design = write_synthetic_study(tmp_path / "study", n_stimuli=2)
    design.write_text(design.read_text().replace('practice = ["p1"]', 'practice = ["nope"]'))
    assert main(["validate", str(design), "--quick"]) == 1
    err = capsys.readouterr().err
    assert "1 problem: the design cannot run until it is fixed." in err, err


def test_random_edits_never_crash_merge_and_nothing_invalid_reaches_export(returned, tmp_path: Path) -> None:
    """Seeded random edits of one field each (checksum recomputed): every file is either refused with a
    message or imported, and whatever is imported exports as valid rankings of the real conditions."""
    import random

    from studyapp.study.export import export_dataframe

    db = _fresh_db(returned, tmp_path)
    pristine = db.read_bytes()
    with zipfile.ZipFile(returned["zip"]) as zf:
        base = json.loads(zf.read("results.json"))
    fields = [(table, i, name) for table in ("participants", "trials", "responses", "plays", "questionnaire")
              for i, row in enumerate(base[table]) for name in row]
    values = [None, -1, 0, 99, 2.5, "abc", True, [], {}, "2026-13-45T00:00:00", "synced", "R02"]
    rng = random.Random(16)
    outcomes = []
    for k in range(60):
        table, i, name = rng.choice(fields)
        value = rng.choice(values)

        def edit(payload: dict[str, Any], table=table, i=i, name=name, value=value) -> None:
            payload[table][i][name] = value

        f = _edited(returned["zip"], tmp_path / f"results-m{k}.zip", edit)
        for suffix in ("-wal", "-shm"):
            Path(f"{db}{suffix}").unlink(missing_ok=True)
        db.write_bytes(pristine)
        [report] = merge_results(db, [f])
        assert report.message and "\n" not in report.message, (table, name, value, report.message)
        outcomes.append(report.ok)
        if report.ok:
            df = export_dataframe(db)
            assert set(df["condition"]) <= {"synced", "lagged", "static"}, (table, name, value)
            assert df["rank"].isin([1.0, 2.0, 3.0]).all(), (table, name, value)
            assert (df.groupby(["trial_index", "criterion"])["rank"].apply(sorted).map(tuple) == (1.0, 2.0, 3.0)).all()
    assert 0 < sum(outcomes) < len(outcomes)  # some edits touch fields that prove nothing (e.g. a version), most are caught
