"""The one trial timeline (studyapp.study.timeline) and the played duration stored with every trial."""
from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from studyapp.audio.wav import AudioClip
from studyapp.face.animation import FaceAnimation
from studyapp.motion.skeleton import Motion, Skeleton
from studyapp.study import timeline as tl

SK = Skeleton(("Hips", "Spine"), np.array([-1, 0]), np.array([[0.0, 1.0, 0.0], [0.0, 0.2, 0.0]]))


def ramp(n: int, fps: float) -> Motion:
    """A motion whose Spine translation x is its frame number: every frame is recognisable after fitting."""
    m = Motion.rest(SK, n_frames=n, fps=fps)
    m.translations[:, 1, 0] = np.arange(n)
    return m


@pytest.mark.parametrize("n, fps, trial, end, expected", [
    (300, 30.0, 1.2, None, list(range(36))),                       # 10 s cut to 1.2 s
    (39, 30.0, 1.2, None, list(range(36))),                        # 1.3 s cut
    (33, 30.0, 1.2, None, list(range(33)) + [32, 32, 32]),          # 0.1 s short: within tolerance, held
    (20, 30.0, 1.2, "hold", list(range(20)) + [19] * 16),
    (20, 30.0, 1.2, "loop", list(range(20)) + list(range(16))),
    (20, 30.0, 1.2, None, list(range(20)) + [19] * 16),             # refused by validate; held if built anyway
    (13, 10.0, 1.25, None, list(range(13))),                        # ceil(12.5) = 13 frames cover 1.25 s
])
def test_fit_motion_cuts_holds_and_loops(n: int, fps: float, trial: float, end: str | None, expected: list) -> None:
    fitted = tl.fit_motion(ramp(n, fps), trial, end)
    assert fitted.translations[:, 1, 0].astype(int).tolist() == expected
    assert fitted.fps == fps and fitted.duration >= trial - 1e-9 and fitted.duration < trial + 1 / fps


def test_medium_end_names_the_choice() -> None:
    assert tl.medium_end(10.0, 1.2, None) == "cut"
    assert tl.medium_end(1.0, 1.2, None) == "hold"             # 0.2 s short is the tolerance
    assert tl.medium_end(0.99, 1.2, None) == "short"
    assert tl.medium_end(0.5, 1.2, "loop") == "loop" and tl.medium_end(0.5, 1.2, "hold") == "hold"


def test_trial_duration_is_duration_s_else_the_audio() -> None:
    assert tl.trial_duration(1.2, 4.9) == 1.2 and tl.trial_duration(None, 4.9) == 4.9


def test_face_and_audio_are_cut_to_the_trial() -> None:
    w = np.zeros((147, 52), np.float32)
    w[:, 0] = np.linspace(0, 1, 147)
    face = FaceAnimation(w, 30.0, head_rotation=np.tile(np.arange(147.0)[:, None], (1, 3)))
    cut = tl.fit_face(face, 1.2)
    assert cut.n_frames == 36 and np.array_equal(cut.weights, face.weights[:36])
    assert np.array_equal(cut.head_rotation, face.head_rotation[:36])
    held = tl.fit_face(face, 5.0)  # 0.1 s short: the last frame held
    assert held.n_frames == 150 and np.array_equal(held.weights[147:], np.repeat(face.weights[-1:], 3, axis=0))
    audio = AudioClip(np.arange(16000 * 5, dtype=np.float32) / 1e5, 16000)
    assert len(tl.cut_audio(audio, 1.2).samples) == 19200
    assert tl.cut_audio(audio, 9.0) is audio


def test_the_window_path_takes_its_length_from_the_timeline(tmp_path: Path) -> None:
    """TrialView (the window's and the offscreen bot's trial) plays the scene's duration, which is the
    timeline's, not the longest motion (the old 10 s over a 2.8 s trial)."""
    from studyapp.render.scene import build_trial_scene
    from studyapp.study.design import load_design
    from studyapp.study.schedule import participant_schedule
    from studyapp.study.stimuli import load_trial_media
    from fixtures.synthetic import write_synthetic_study
    from studyapp.ui.trial import TrialView

    design_path = write_synthetic_study(tmp_path / "s", n_stimuli=2, seconds=3.0, practice=False)
    design_path.write_text(design_path.read_text().replace('audio = "audio/s1.wav"',
                                                           'audio = "audio/s1.wav"\nduration_s = 1.7'))
    design = load_design(design_path)
    plan = next(p for p in participant_schedule(design, "P1") if p.stimulus_id == "s1")

    class App:  # what TrialView reads from the app
        renderer = None

    App.design = design
    view = TrialView.__new__(TrialView)
    view.app, view.plan, view.scene = App, plan, None
    view.load()
    assert view.duration_s == 1.7 == build_trial_scene(None, load_trial_media(design, plan)).duration


# ---------------------------------------------------------------------------------------------------------
# trial_duration_s in the results


def _downgrade_to_v1(path: Path) -> None:
    """What a studyapp before trial_duration_s wrote: schema version 1, no such column."""
    with sqlite3.connect(path) as con:
        con.execute("ALTER TABLE conditions DROP COLUMN label")  # added by 4
        for column in ("sample_left", "sample_middle", "sample_right", "trial_duration_s"):  # added by 3, 2
            con.execute(f"ALTER TABLE trials DROP COLUMN {column}")
        con.execute("DROP TABLE row_checksums")  # added by 5
        con.execute("DROP TABLE criteria")  # added by 7
        for table in ("trial_slots", "judgements"):  # added by 6
            con.execute(f"DROP TABLE {table}")
        for column in ("block", "paradigm"):  # added by 6
            con.execute(f"ALTER TABLE trials DROP COLUMN {column}")
        con.execute("UPDATE schema_version SET version = 1")


def test_every_trial_stores_its_duration_and_old_databases_stay_readable(tmp_path: Path) -> None:
    from results_analysis.sqlite_schema import tidy_from_connection
    from studyapp.bots.session_driver import run_bot_session
    from studyapp.study.design import load_design
    from studyapp.study.export import export_dataframe
    from studyapp.study.storage import SCHEMA_VERSION, ResultsDB
    from fixtures.synthetic import write_synthetic_study

    path = write_synthetic_study(tmp_path / "s", n_stimuli=2, seconds=1.5, practice=False)
    path.write_text(path.read_text().replace('audio = "audio/s2.wav"', 'audio = "audio/s2.wav"\nduration_s = 0.9'))
    design = load_design(path)
    db_path = tmp_path / "r.sqlite"
    with ResultsDB(db_path, design) as db:
        run_bot_session(design, db, "P1", "random", 0)
    df = export_dataframe(db_path)
    by_stim = df.groupby("stimulus")["trial_duration_s"].unique().to_dict()
    assert {k: v.tolist() for k, v in by_stim.items()} == {"s1": [1.5], "s2": [0.9]}  # audio length / duration_s

    _downgrade_to_v1(db_path)
    with sqlite3.connect(db_path) as con:  # the analysis reads a version 1 file as it is
        old = tidy_from_connection(con, db_path)
    assert "trial_duration_s" in old.columns and old["trial_duration_s"].isna().all() and len(old) == len(df)
    with ResultsDB(db_path, design) as db:  # studyapp upgrades it in place and goes on
        assert db.connection.execute("SELECT version FROM schema_version").fetchone()[0] == SCHEMA_VERSION == 7
        run_bot_session(design, db, "P2", "random", 1)
    df = export_dataframe(db_path)
    assert df[df.participant == "P1"]["trial_duration_s"].isna().all()    # not recorded then: empty, not made up
    assert sorted(df[df.participant == "P2"]["trial_duration_s"].unique()) == [0.9, 1.5]
    with sqlite3.connect(db_path) as con:
        new = tidy_from_connection(con, db_path)
    pd.testing.assert_series_equal(new["trial_duration_s"], df["trial_duration_s"], check_names=False)
