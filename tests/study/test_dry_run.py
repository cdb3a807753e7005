"""``validate`` is a dry run: it builds every stimulus's scene as a participant gets it, so a design that
validates cannot fail at run time for a reason its files already show; and a session that cannot start
leaves no participant behind."""
from __future__ import annotations

import json
import os
import shutil
import sqlite3
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from studyapp.study.design import validate_design
from fixtures.synthetic import bvh_text, write_synthetic_study

AVATARS = Path(__file__).parents[1] / "data" / "samples" / "avatars"
CLI = [sys.executable, "-m", "studyapp.cli"]


def with_avatar(design: Path, avatar: str) -> Path:
    design.write_text(design.read_text() + f'\n[avatar]\nmodel = "{avatar}"\n')
    return design


def singular_bind_copy(src: Path, dst: Path, joint: int = 2) -> None:
    """``src`` (a GLB/VRM) with one joint's inverse bind matrix zeroed: a file exporters do write when a
    bone has zero scale, and one no skinning can invert."""
    data = src.read_bytes()
    (json_len,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20:20 + json_len])
    bin_start = 20 + json_len + 8
    acc = doc["accessors"][doc["skins"][0]["inverseBindMatrices"]]
    view = doc["bufferViews"][acc["bufferView"]]
    at = bin_start + view.get("byteOffset", 0) + acc.get("byteOffset", 0) + 64 * joint
    dst.write_bytes(data[:at] + bytes(64) + data[at + 64:])


@pytest.fixture()
def study(tmp_path: Path) -> Path:
    return write_synthetic_study(tmp_path / "study", n_stimuli=2, seconds=1.0, practice=False)


def test_a_humanoid_vrm_validates(study: Path) -> None:
    shutil.copy(AVATARS / "cryptovoxels_vrm0.vrm", study.parent / "person.vrm")
    assert validate_design(with_avatar(study, "person.vrm")) == []


def test_a_non_humanoid_avatar_is_one_problem_not_one_per_scene(study: Path) -> None:
    shutil.copy(AVATARS / "Fox.glb", study.parent / "Fox.glb")
    problems = validate_design(with_avatar(study, "Fox.glb"))
    assert len(problems) == 1, [str(p) for p in problems]  # said once, not for each of the 6 scenes
    assert problems[0].key.startswith("avatar") and "Fox.glb" in problems[0].message


def test_an_avatar_with_a_singular_bind_matrix_is_a_problem_not_a_crash(study: Path, tmp_path: Path) -> None:
    singular_bind_copy(AVATARS / "cryptovoxels_vrm0.vrm", study.parent / "broken.vrm")
    problems = validate_design(with_avatar(study, "broken.vrm"))
    assert [p.key for p in problems] == ["avatar.model"], [str(p) for p in problems]
    message = problems[0].message  # the file, the JSON place and the problem, from the reader itself
    assert "broken.vrm" in message and "key skins[0].inverseBindMatrices, matrix 2: singular" in message


def test_a_slot_the_scene_builder_refuses_names_condition_stimulus_and_file(study: Path, monkeypatch) -> None:
    """validate reports what the participant's scene builder itself refuses (whatever the cause: here it
    refuses one motion file) as one problem line naming the condition, the stimulus and the file, and the
    other slots of that scene are still checked."""
    from studyapp.errors import InputError
    from studyapp.render import scene as scene_mod

    bad = study.parent / "motion" / "lagged" / "s2.bvh"
    real = scene_mod.prepare_slot
    built = []

    def prepare(avatar, motion, face, name_map=None, **kw):
        if motion.source == str(bad):
            raise InputError(None, "name map", "cannot retarget: no joint for LeftUpperArm")
        built.append(motion.source)
        return real(avatar, motion, face, name_map=name_map, **kw)

    monkeypatch.setattr(scene_mod, "prepare_slot", prepare)
    problems = validate_design(study)
    assert len(problems) == 1, [str(p) for p in problems]
    p = problems[0]
    assert p.key == "conditions[1]" and "'lagged'" in p.message and "stimulus 's2'" in p.message
    assert str(bad) in p.message and "no joint for LeftUpperArm" in p.message and "name_map" in p.fix
    # every other condition x stimulus was built once: 2 stimuli x 3 conditions, less the refused one
    assert sorted(built) == sorted(str(study.parent / "motion" / c / f"{s}.bvh")
                                   for c in ("synced", "lagged", "static") for s in ("s1", "s2")
                                   if (c, s) != ("lagged", "s2"))


def test_frame_rate_check_takes_duration_s_into_account(tmp_path: Path) -> None:
    """A true 30 fps, 10 s file over 4.9 s of audio: with duration_s = 4 it plays its first 4 s, which is
    right; only without duration_s is "the header lies, it is 60 fps" the fix that makes durations agree."""
    study = write_synthetic_study(tmp_path / "study", n_stimuli=2, seconds=4.9, practice=False)
    (study.parent / "motion" / "static" / "s1.bvh").write_text(bvh_text(np.zeros(300)))  # 300 frames at 30 fps
    text = study.read_text().replace("fps = 30.0\n", "")
    study.write_text(text)
    problems = validate_design(study)
    assert [p.key for p in problems] == ["conditions[2].fps"] and "fps = 60" in problems[0].fix
    study.write_text(text.replace('audio = "audio/s1.wav"', 'audio = "audio/s1.wav"\nduration_s = 4.0'))
    assert validate_design(study) == []


def run(*args: object) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "MPLBACKEND": "Agg"})


def test_a_session_that_cannot_start_leaves_the_participant_free_to_start(study: Path) -> None:
    """Real processes: a broken avatar stops the run before anyone is registered; fixed, the same id runs."""
    db = study.parent / "r.sqlite"
    singular_bind_copy(AVATARS / "cryptovoxels_vrm0.vrm", study.parent / "avatar.vrm")
    design = with_avatar(study, "avatar.vrm")
    bad = run("run", design, "--participant", "P01", "--offscreen", "--bot", "careful", "--results", db)
    assert bad.returncode == 2 and "avatar.vrm" in bad.stderr and "Traceback" not in bad.stderr
    assert not db.exists()
    shutil.copy(AVATARS / "cryptovoxels_vrm0.vrm", study.parent / "avatar.vrm")  # the fix
    good = run("run", design, "--participant", "P01", "--offscreen", "--bot", "careful", "--results", db)
    assert good.returncode == 0, good.stdout + good.stderr
    with sqlite3.connect(db) as con:
        assert con.execute("SELECT status FROM participants WHERE id = 'P01'").fetchall() == [("done",)]
        assert con.execute("SELECT COUNT(*) FROM trials WHERE participant = 'P01'").fetchone()[0] == 2


def test_a_failure_at_run_time_removes_the_participant_it_registered(study: Path, monkeypatch, capsys) -> None:
    """Whatever stops a session before its first answer (here a scene that cannot be built at the first clip),
    the participant it registered goes, and a results file it created and left empty goes too."""
    from studyapp.cli import main
    from studyapp.render.scene import SlotError
    from studyapp.study.storage import ResultsDB
    from studyapp.ui.trial import TrialView

    def broken(self):
        raise SlotError(1, "motion.bvh", "avatar", "cannot retarget")

    db = study.parent / "r.sqlite"
    monkeypatch.setattr(TrialView, "load", broken)
    assert main(["run", str(study), "--participant", "P01", "--offscreen", "--bot", "careful", "--results", str(db)]) == 2
    assert "cannot retarget" in capsys.readouterr().err and not db.exists()
    monkeypatch.undo()
    # A database with a participant who did answer keeps them; only the one who could not start goes.
    assert main(["run", str(study), "--participant", "P01", "--no-render", "--bot", "random", "--results", str(db)]) == 0
    monkeypatch.setattr(TrialView, "load", broken)
    assert main(["run", str(study), "--participant", "P02", "--offscreen", "--bot", "careful", "--results", str(db)]) == 2
    with ResultsDB(db, create=False) as rdb:
        assert [p.id for p in rdb.participants()] == ["P01"] and {s["participant"] for s in rdb.sessions()} == {"P01"}
