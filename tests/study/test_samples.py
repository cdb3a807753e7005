"""Several samples per stimulus (issue 15 item 5): a condition with ``samples = N`` gives N motion files per
clip (``{sample}`` = 1..N); the schedule picks one per participant and trial, balanced over participants, the
trial shows that file, and the answer records it, through export, the analysis reader and remote bundles.

The study: the tiny synthetic one, with ``lagged`` turned into a stochastic model of 3 samples whose files
hold the arms still at 10, 30 and 50 degrees, so the sample a slot shows can be read off its motion.
"""
from __future__ import annotations

import os
import re
import sqlite3
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from studyapp.motion.io import load_motion
from studyapp.study.design import load_design, motion_path, validate_design
from fixtures.synthetic import bvh_text, write_synthetic_study

N = 3
#: arm angle (degrees) held by each sample's file, sample 1..3
ANGLES = {1: 10.0, 2: 30.0, 3: 50.0}
PATTERN = '"motion/lagged/{stimulus}_{sample}.bvh"'


def stochastic_study(folder: Path, n_stimuli: int = 3, **kw) -> Path:
    path = write_synthetic_study(folder, n_stimuli=n_stimuli, practice=False, **kw)
    stims = [f"s{i + 1}" for i in range(n_stimuli)] + (["att1"] if kw.get("attention_check") else [])
    for sid in stims:
        n_frames = len(load_motion(folder / "motion" / "lagged" / f"{sid}.bvh").rotations)
        for k, angle in ANGLES.items():
            (folder / "motion" / "lagged" / f"{sid}_{k}.bvh").write_text(bvh_text(np.full(n_frames, angle)))
    text = path.read_text().replace('"motion/lagged/{stimulus}.bvh"', f"{PATTERN}\nsamples = {N}")
    path.write_text(text)
    return path


def _left_arm_z(motion) -> np.ndarray:
    """The LeftArm's Z rotation per frame in degrees (the synthetic BVH writes -70 + angle there)."""
    from scipy.spatial.transform import Rotation

    j = motion.skeleton.names.index("LeftArm")
    return Rotation.from_quat(np.asarray(motion.rotations)[:, j]).as_euler("ZXY", degrees=True)[:, 0]


# ---------------------------------------------------------------------------------------------------------
# the design


def test_a_design_with_samples_validates_and_names_every_file(tmp_path: Path) -> None:
    from studyapp.study.design import referenced_files

    path = stochastic_study(tmp_path)
    assert validate_design(path) == []
    d = load_design(path)
    lagged = d.condition("lagged")
    assert lagged.samples == N and d.condition("synced").samples == 1
    assert [motion_path(d, lagged, "s2", k).name for k in (1, 2, 3)] == ["s2_1.bvh", "s2_2.bvh", "s2_3.bvh"]
    files = referenced_files(d)
    assert sorted(p.name for k, p in files.items() if k.startswith("conditions[1].motion")) == sorted(
        f"s{i}_{k}.bvh" for i in (1, 2, 3) for k in (1, 2, 3))
    # conditions with one sample keep their keys (and so the hash of designs written before samples existed)
    assert "conditions[0].motion[s1]" in files and "conditions[1].motion[s1:3]" in files


@pytest.mark.parametrize("edit, key, words", [
    (lambda t: t.replace(f"\nsamples = {N}", ""), "conditions[1].motion", "no `samples`"),
    (lambda t: t.replace(PATTERN, '"motion/lagged/{stimulus}.bvh"'), "conditions[1].samples", "no {sample}"),
    (lambda t: t.replace(f"samples = {N}", "samples = 0"), "conditions[1].samples", "1 or more"),
])
def test_samples_and_the_placeholder_go_together(tmp_path: Path, edit, key, words) -> None:
    path = stochastic_study(tmp_path)
    path.write_text(edit(path.read_text()))
    problems = validate_design(path, check_files=False)
    assert [(p.key, words in p.message) for p in problems] == [(key, True)], [str(p) for p in problems]
    assert problems[0].line is not None


def test_a_missing_sample_file_is_reported_naming_the_file(tmp_path: Path) -> None:
    path = stochastic_study(tmp_path)
    gone = tmp_path / "motion" / "lagged" / "s2_3.bvh"
    gone.unlink()
    problems = validate_design(path)
    assert len(problems) == 1, [str(p) for p in problems]
    text = str(problems[0])
    assert problems[0].key == "conditions[1].motion" and str(gone) in text and "sample 3" in text, text


def test_an_unreadable_sample_file_is_reported(tmp_path: Path) -> None:
    path = stochastic_study(tmp_path)
    bad = tmp_path / "motion" / "lagged" / "s1_2.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n")
    problems = validate_design(path)
    hits = [str(p) for p in problems if p.key == "conditions[1].motion"]
    assert len(hits) == 1 and "stimulus s1 sample 2" in hits[0] and str(bad) in hits[0], [str(p) for p in problems]


# ---------------------------------------------------------------------------------------------------------
# the schedule


@pytest.mark.parametrize("n_participants", [3, 6])
def test_the_schedule_balances_samples_per_condition_and_stimulus(tmp_path: Path, n_participants: int) -> None:
    from studyapp.study.schedule import balance_counts, full_schedule, n_rows

    d = load_design(stochastic_study(tmp_path, attention_check=True))
    assert n_rows(d) % N == 0  # a full block of rows cycles through every sample
    df = full_schedule(d, n_participants)
    rated = df[~df.is_practice & ~df.is_attention_check]
    counts: dict[tuple[str, str], dict[int, int]] = {}
    for _, r in rated.iterrows():
        for slot in ("left", "middle", "right"):
            cell = counts.setdefault((r[f"slot_{slot}"], r["stimulus"]), {})
            cell[r[f"sample_{slot}"]] = cell.get(r[f"sample_{slot}"], 0) + 1
    per = n_participants // N
    for stim in ("s1", "s2", "s3"):
        assert counts[("lagged", stim)] == {1: per, 2: per, 3: per}, (stim, counts[("lagged", stim)])
        assert counts[("synced", stim)] == {1: n_participants}
    # `studyapp schedule` prints the same table
    table = balance_counts(df)["sample_x_condition_stimulus"]
    assert table.loc[("lagged", "s2")].tolist() == [per, per, per]
    # the same design, seed and participant give the same schedule
    again = full_schedule(load_design(tmp_path / "tiny.toml"), n_participants)
    assert again.equals(df)


def test_schedule_csv_shows_the_sample_of_every_slot(tmp_path: Path) -> None:
    import pandas as pd

    path = stochastic_study(tmp_path)
    out = tmp_path / "schedule.csv"
    ran = subprocess.run([sys.executable, "-m", "studyapp.cli", "schedule", str(path), "--participants", "3",
                          "--csv", str(out)], capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stderr
    assert "Samples shown" in ran.stdout
    df = pd.read_csv(out)
    lagged = [(r[f"sample_{s}"]) for _, r in df.iterrows() for s in ("left", "middle", "right")
              if r[f"slot_{s}"] == "lagged"]
    assert sorted(set(lagged)) == [1, 2, 3]
    others = [r[f"sample_{s}"] for _, r in df.iterrows() for s in ("left", "middle", "right") if r[f"slot_{s}"] != "lagged"]
    assert set(others) == {1}


# ---------------------------------------------------------------------------------------------------------
# what a trial shows and what is stored


def test_the_trial_shows_the_scheduled_sample(tmp_path: Path) -> None:
    from studyapp.study.schedule import participant_schedule
    from studyapp.study.stimuli import load_trial_media

    d = load_design(stochastic_study(tmp_path))
    seen = set()
    for row in range(N):
        for plan in participant_schedule(d, "P1", row=row):
            media = load_trial_media(d, plan)
            slot = plan.slots.index("lagged")
            k = plan.samples[slot]
            seen.add(k)
            # the slot's arms stand where that sample's file puts them, and nowhere another sample would
            z = _left_arm_z(media.motions[slot])
            assert np.allclose(z, -70.0 + ANGLES[k], atol=1e-3), (plan, k, z[:3])
    assert seen == {1, 2, 3}


def test_offscreen_bot_stores_and_exports_the_sample_shown(tmp_path: Path) -> None:
    import pandas as pd

    from results_analysis.sqlite_schema import tidy_from_connection
    from studyapp.study.export import export_dataframe
    from studyapp.study.schedule import participant_schedule

    path = stochastic_study(tmp_path)
    db = tmp_path / "r.sqlite"
    for pid in ("P01", "P02"):
        ran = subprocess.run([sys.executable, "-m", "studyapp.cli", "run", str(path), "--participant", pid,
                              "--offscreen", "--bot", "careful", "--results", str(db)],
                             capture_output=True, text=True, timeout=600, env={**os.environ, "MPLBACKEND": "Agg"})
        assert ran.returncode == 0, ran.stdout + ran.stderr
    d = load_design(path)
    with sqlite3.connect(db) as con:
        rows = dict(con.execute("SELECT id, latin_row FROM participants"))
        stored = con.execute("SELECT participant, trial_index, slot_left, slot_middle, slot_right, sample_left, "
                             "sample_middle, sample_right FROM trials").fetchall()
        tidy = tidy_from_connection(con, db)
    assert sorted(rows.values()) == [0, 1] and len(stored) == 6
    for pid, ti, *slots_and_samples in stored:
        plan = participant_schedule(d, pid, row=rows[pid])[ti]
        assert tuple(slots_and_samples) == (*plan.slots, *plan.samples)
    df = export_dataframe(db)
    assert "sample" in df.columns and df["sample"].notna().all()
    for _, r in df.iterrows():
        plan = participant_schedule(d, r.participant, row=rows[r.participant])[r.trial_index]
        assert plan.slots[r.slot] == r.condition and plan.samples[r.slot] == r["sample"]
    assert set(df[df.condition == "lagged"]["sample"]) > {1} and set(df[df.condition != "lagged"]["sample"]) == {1}
    pd.testing.assert_series_equal(tidy["sample"].astype("Int64"), df["sample"], check_names=False)


def test_a_schema_2_database_is_upgraded_and_its_trials_keep_no_sample(tmp_path: Path) -> None:
    from studyapp.bots.session_driver import run_bot_session
    from studyapp.study.export import export_dataframe
    from studyapp.study.storage import SCHEMA_VERSION, ResultsDB

    d = load_design(stochastic_study(tmp_path))
    db_path = tmp_path / "r.sqlite"
    with ResultsDB(db_path, d) as db:
        run_bot_session(d, db, "P1", "random", 0)
    with sqlite3.connect(db_path) as con:  # what studyapp wrote before samples: schema 2
        con.execute("ALTER TABLE conditions DROP COLUMN label")  # added by 4
        for column in ("sample_left", "sample_middle", "sample_right"):
            con.execute(f"ALTER TABLE trials DROP COLUMN {column}")
        con.execute("DROP TABLE row_checksums")  # added by 5
        con.execute("DROP TABLE criteria")  # added by 7
        for table in ("trial_slots", "judgements"):  # added by 6
            con.execute(f"DROP TABLE {table}")
        for column in ("block", "paradigm"):  # added by 6
            con.execute(f"ALTER TABLE trials DROP COLUMN {column}")
        con.execute("UPDATE schema_version SET version = 2")
    with ResultsDB(db_path, d) as db:
        assert db.connection.execute("SELECT version FROM schema_version").fetchone()[0] == SCHEMA_VERSION == 7
        run_bot_session(d, db, "P2", "random", 1)
    df = export_dataframe(db_path)
    assert df[df.participant == "P1"]["sample"].isna().all()  # not recorded then: empty, not made up
    assert df[df.participant == "P2"]["sample"].notna().all()


# ---------------------------------------------------------------------------------------------------------
# remote bundles


def _grams(text: str, n: int = 4) -> set[str]:
    return {text[i:i + n] for i in range(len(text) - n + 1)}


def test_bundle_ships_every_sample_under_its_own_name_and_merge_keeps_the_sample(tmp_path: Path) -> None:
    from fixtures.bundles import remote_run, shipped_motions
    from studyapp.study.bundle import make_bundle, merge_results, open_bundle
    from studyapp.study.export import export_dataframe
    from studyapp.study.schedule import participant_schedule

    path = stochastic_study(tmp_path / "lab")
    design = load_design(path)
    results = tmp_path / "lab.sqlite"
    # rows 0, 1 and 2 see samples 1, 2 and 3 of every clip between them
    info = make_bundle(path, tmp_path / "out" / "study.zip", participants=3, results=results, salt="qa-salt")
    names = [n for n in zipfile.ZipFile(info.path).namelist() if n.startswith("media/")]
    assert len(names) == 3 * (1 + 1 + N + 1)  # per clip: audio, synced, 3 lagged samples, static
    assert all(re.fullmatch(r"media/m_[0-9a-f]{12}\.(bvh|wav)", n) for n in names), names
    opened = open_bundle(info.path, cache=tmp_path / "cache")
    bundled = load_design(opened.design_path)
    assert all(c.samples == 1 for c in bundled.conditions)  # the bundle picks the sample of every trial
    files = set()
    for m in shipped_motions(info.key, opened.design_path):
        # each sample plays the very file it was made from
        assert m.path.read_bytes() == motion_path(design, m.condition, m.stimulus, m.sample).read_bytes()
        if m.condition == "lagged":
            files.add((m.stimulus, m.sample, m.path.stem[len("m_"):]))
    assert len(files) == len({f[2] for f in files}) == 3 * N
    assert not set.intersection(*(_grams(f[2]) for f in files)), "a name fragment ties one model's samples together"

    # a remote participant's answers come back with the sample each slot showed
    # watching each 1-second clip as long as it lasts: merge refuses answers given sooner
    returned = remote_run(info.path, tmp_path, "R01", pace_s=1.0)
    assert merge_results(results, [returned], design=path)[0].ok
    df = export_dataframe(results)
    row = info.roster["R01"]
    for _, r in df.iterrows():
        plan = participant_schedule(design, "R01", row=row)[r.trial_index]
        assert (plan.slots[r.slot], plan.samples[r.slot]) == (r.condition, r["sample"])


def test_samples_on_the_labs_smpl_body_model_are_each_bundled_as_their_own_motion(tmp_path: Path) -> None:
    """A condition whose SMPL-X files need the lab's body model travels as generated BVH: one per sample."""
    import json

    from studyapp.motion.fk import joint_positions
    from studyapp.motion.smpl import builtin_rest_joints, parents
    from studyapp.resources import designs_dir
    from fixtures.bundles import shipped_motions
    from studyapp.study.bundle import make_bundle, open_bundle
    from studyapp.study.stimuli import load_condition_motion

    model = tmp_path / "models" / "SMPLX_TEST.npz"  # synthetic: one vertex per joint (no licensed file in tests)
    model.parent.mkdir()
    kin = np.stack([np.where(parents("smplx") < 0, 2**32 - 1, parents("smplx")), np.arange(55)]).astype(np.uint32)
    np.savez(model, J_regressor=np.eye(55), v_template=builtin_rest_joints("smplx"),
             shapedirs=np.zeros((55, 3, 10)), kintree_table=kin)
    (tmp_path / "smplx").mkdir()
    for sid in ("clip01", "clip03"):
        data = dict(np.load(designs_dir() / "smplx_example" / "smplx" / f"{sid}.npz"))
        np.savez(tmp_path / "smplx" / f"{sid}_1.npz", **data)
        data["poses"] = data["poses"].copy()
        data["poses"][:, 16 * 3 + 2] += 0.8  # sample 2: the left shoulder raised 0.8 rad about z
        np.savez(tmp_path / "smplx" / f"{sid}_2.npz", **data)
    text = (designs_dir() / "smplx_example.toml").read_text().replace('"demo/', f'"{designs_dir()}/demo/').replace(
        '"smplx_example/smplh/', f'"{designs_dir()}/smplx_example/smplh/').replace(
        '"smplx_example/smplx/{stimulus}.npz"', '"smplx/{stimulus}_{sample}.npz"\nsamples = 2').replace(
        '# body_model = "models/SMPLX_NEUTRAL.npz"', 'body_model = "models/SMPLX_TEST.npz"')
    source = tmp_path / "smplx.toml"
    source.write_text(text)
    lab = load_design(source)
    assert lab.conditions[0].samples == 2 and lab.conditions[0].body_model is not None
    info = make_bundle(source, tmp_path / "smpl.zip", results=tmp_path / "smpl.sqlite", participants=2)
    opened = open_bundle(info.path, cache=tmp_path / "cache")
    bundled = load_design(opened.design_path)
    assert all(c.samples == 1 and c.motion.endswith(".bvh") for c in bundled.conditions)
    shipped = {(m.stimulus, m.sample): m for m in shipped_motions(info.key, opened.design_path)
               if m.condition == "emage_like"}
    assert {k for _, k in shipped} == {1, 2}  # two rows: both samples travel
    for lab_sid in {sid for sid, _ in shipped}:
        lab_stim = lab.stimulus(lab_sid)
        positions = []
        for k in (1, 2):
            m = shipped[(lab_sid, k)]
            got = load_condition_motion(bundled, bundled.condition(m.token), bundled.stimulus(m.shipped_stimulus))
            want = load_condition_motion(lab, lab.conditions[0], lab_stim, k)
            order = [got.skeleton.names.index(n) for n in want.skeleton.names]
            pos = joint_positions(got)[:, order] * got.skeleton.unit_scale
            assert np.abs(pos - joint_positions(want)).max() < 1e-3
            positions.append(pos)
        assert np.abs(positions[0] - positions[1]).max() > 0.05  # the two samples really differ
