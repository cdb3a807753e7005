"""One path: what ``validate`` and a pilot check is what every participant path plays (issue 13).

Three real rigs (ZEGGS, Mixamo, CMU with renamed arm joints that need its condition's own ``name_map``)
as three "models", with motions of 10 s, 4 s and 1.3 s, all cut by ``duration_s = 1.2``: the design
validates, a scripted participant goes through the real app offscreen to the end, ``render`` writes a PNG
and an MP4 of the trial's length, and every trial records ``trial_duration_s`` = 1.2 in the export. Real
``studyapp`` processes throughout, as an experimenter runs them.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from studyapp.audio.wav import AudioClip, save_wav
from studyapp.face.animation import FaceAnimation
from studyapp.face.io import save_face_csv
from studyapp.motion.bvh import write_bvh
from studyapp.motion.io import load_motion
from studyapp.motion.skeleton import Motion

SAMPLES = Path(__file__).parent / "data" / "samples" / "motion"
CLI = [sys.executable, "-m", "studyapp.cli"]
AUDIO_S = 4.9
TRIAL_S = 1.2
#: CMU's arm joints renamed as no built-in map knows them, and the name_map that gives them back.
CMU_RENAMED = {"LeftArm": "L_humerus", "LeftForeArm": "L_radius", "LeftHand": "L_wrist",
               "RightArm": "R_humerus", "RightForeArm": "R_radius", "RightHand": "R_wrist"}
CMU_MAP = {"L_humerus": "LeftUpperArm", "L_radius": "LeftLowerArm", "L_wrist": "LeftHand",
           "R_humerus": "RightUpperArm", "R_radius": "RightLowerArm", "R_wrist": "RightHand"}

DESIGN = """title = "Three rigs"
[[conditions]]
id = "zeggs"
motion = "motion/zeggs/{{stimulus}}.bvh"
[[conditions]]
id = "mixamo"
motion = "motion/mixamo/{{stimulus}}.bvh"
[[conditions]]
id = "cmu"
motion = "motion/cmu/{{stimulus}}.bvh"
{cmu_extra}
[conditions.name_map]
{name_map}
[[stimuli]]
id = "s1"
audio = "audio/s1.wav"
face = "face/s1.csv"
duration_s = {duration}
[[stimuli]]
id = "s2"
audio = "audio/s2.wav"
duration_s = {duration}
"""


def design_text(duration: float = TRIAL_S, name_map: dict[str, str] = CMU_MAP, cmu_extra: str = "") -> str:
    return DESIGN.format(duration=duration, cmu_extra=cmu_extra,
                         name_map="\n".join(f'{k} = "{v}"' for k, v in name_map.items()))


def cut(motion: Motion, seconds: float) -> Motion:
    n = int(round(seconds * motion.fps))
    return Motion(motion.skeleton, motion.fps, motion.rotations[:n], motion.translations[:n], source=motion.source)


def renamed_bvh(src: Path, dst: Path, names: dict[str, str]) -> None:
    """``src`` with joints renamed (the BVH text itself, so nothing else changes)."""
    text = src.read_text()
    for old, new in names.items():
        text, n = re.subn(rf"(JOINT\s+){old}(\s)", rf"\g<1>{new}\g<2>", text)
        assert n == 1, old
    dst.write_text(text)


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("one_path")
    zeggs = load_motion(SAMPLES / "zeggs_067_Speech_2_x_1_0_excerpt.bvh")      # 300 frames at 30 fps: 10 s
    mixamo = load_motion(SAMPLES / "mixamo_Joe_SalsaDancing6_excerpt.bvh")     # 240 frames at 60 fps: 4 s
    renamed_bvh(SAMPLES / "cmu_01_01_excerpt.bvh", root / "cmu_renamed.bvh", CMU_RENAMED)
    cmu = cut(load_motion(root / "cmu_renamed.bvh"), 1.3)                      # 120 fps, cut to 1.3 s
    assert (zeggs.duration, mixamo.duration, cmu.duration) == pytest.approx((10.0, 4.0, 1.3))
    rng = np.random.default_rng(3)
    for sid in ("s1", "s2"):
        for name, m in (("zeggs", zeggs), ("mixamo", mixamo), ("cmu", cmu)):
            (root / "motion" / name).mkdir(parents=True, exist_ok=True)
            write_bvh(m, root / "motion" / name / f"{sid}.bvh")
        (root / "audio").mkdir(exist_ok=True)
        t = np.arange(int(AUDIO_S * 16000)) / 16000
        samples = 0.3 * np.sin(2 * np.pi * 180 * t) * (0.5 + 0.5 * np.sin(2 * np.pi * 3 * t)) \
            + 0.01 * rng.standard_normal(t.size)
        save_wav(AudioClip(samples.astype(np.float32), 16000), root / "audio" / f"{sid}.wav")
    face = FaceAnimation.neutral(int(AUDIO_S * 30), 30.0)
    face.weights[:, 17] = np.linspace(0, 1, face.n_frames)
    (root / "face").mkdir()
    save_face_csv(face, root / "face" / "s1.csv")
    (root / "design.toml").write_text(design_text())
    return root


def run(*args, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=600, cwd=cwd,
                          env={**os.environ, "MPLBACKEND": "Agg"})


def test_three_rigs_validate_run_render_and_record_the_trial_duration(study: Path, tmp_path: Path) -> None:
    design = study / "design.toml"
    checked = run("validate", design)
    assert checked.returncode == 0, checked.stdout + checked.stderr

    db = tmp_path / "r.sqlite"
    ran = run("run", design, "--participant", "P01", "--offscreen", "--bot", "careful", "--results", db)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "completed the study" in ran.stdout

    png, mp4 = tmp_path / "t0.png", tmp_path / "t0.mp4"
    still = run("render", design, "--participant", "P01", "--trial", "0", "--time", "1.0", "--out", png,
                "--size", "480x270")
    assert still.returncode == 0, still.stderr
    past = run("render", design, "--participant", "P01", "--trial", "0", "--time", "3.0", "--out", png)
    assert past.returncode != 0 and "1.20 s" in past.stderr  # the trial is 1.2 s, not the longest motion
    video = run("render", design, "--participant", "P01", "--trial", "0", "--out", mp4, "--size", "320x180",
                "--fps", "25")
    assert video.returncode == 0, video.stderr
    import av

    with av.open(str(mp4)) as container:
        vs = container.streams.video[0]
        frames = sum(1 for _ in container.decode(video=0))
        assert frames == round(TRIAL_S * 25)
        assert float(Fraction(frames) / vs.average_rate) == pytest.approx(TRIAL_S)
        aud = container.streams.audio[0]
        assert float(aud.duration * aud.time_base) == pytest.approx(TRIAL_S, abs=0.05)  # cut with the picture

    csv = tmp_path / "r.csv"
    exported = run("export", db, "--csv", csv)
    assert exported.returncode == 0, exported.stderr
    df = pd.read_csv(csv)
    assert sorted(df["stimulus"].unique()) == ["s1", "s2"]
    assert df["trial_duration_s"].tolist() == [TRIAL_S] * len(df) and len(df) == 2 * 3 * 3


def test_render_shows_the_row_the_results_database_gave_the_participant(study: Path, tmp_path: Path) -> None:
    """Rows are given in order of arrival, so ``render --participant`` must read the participant's row from the
    results database: derived from the id it showed another clip order than the participant saw."""
    from studyapp.study.design import load_design
    from studyapp.study.schedule import default_row

    design = study / "design.toml"
    db = tmp_path / "r.sqlite"
    loaded = load_design(design)
    pids = [f"P{k:02d}" for k in range(1, 5)]
    for pid in pids:
        done = run("run", design, "--participant", pid, "--no-render", "--bot", "ordered", "--results", db)
        assert done.returncode == 0, done.stdout + done.stderr
    rows = dict(zip(pids, range(len(pids))))  # first come, first row
    pid = next(p for p in pids if default_row(loaded, p) != rows[p])
    cwd_db = design.with_name("design.results.sqlite")
    assert not cwd_db.exists()

    def png(name: str, *extra) -> bytes:
        out = tmp_path / name
        done = run("render", design, "--participant", pid, "--trial", "0", "--time", "0.6", "--out", out,
                   "--size", "240x135", *extra)
        assert done.returncode == 0, done.stdout + done.stderr
        return out.read_bytes()

    recorded = png("db.png", "--results", db)
    assert recorded == png("row.png", "--row", rows[pid])  # no database: the row asked for
    assert recorded != png("id.png")  # no database, no row: the id's row, which is not the one it got
    wrong = run("render", design, "--participant", pid, "--trial", "0", "--time", "0.6", "--out",
                tmp_path / "x.png", "--results", db, "--row", (rows[pid] + 1) % 6)
    assert wrong.returncode == 2 and f"follows row {rows[pid]}" in wrong.stderr
    missing = run("render", design, "--participant", "Z99", "--trial", "0", "--time", "0.6", "--out",
                  tmp_path / "x.png", "--results", db)
    assert missing.returncode == 2 and "no participant 'Z99'" in missing.stderr


def test_scene_per_slot_maps_and_timeline(study: Path) -> None:
    """The scene a participant gets: each slot retargeted with its own condition's map, 1.2 s long, the
    short CMU motion playing to its own 1.3 s (not frozen) and the 10 s one cut."""
    from studyapp.render.scene import build_trial_scene
    from studyapp.study.design import load_design
    from studyapp.study.schedule import participant_schedule
    from studyapp.study.stimuli import clear_cache, load_trial_media

    clear_cache()
    design = load_design(study / "design.toml")
    plan = participant_schedule(design, "P01")[0]
    media = load_trial_media(design, plan)
    assert [dict(m) for m in media.name_maps] == [CMU_MAP if c == "cmu" else {} for c in plan.slots]
    scene = build_trial_scene(None, media)
    assert scene.duration == TRIAL_S == media.duration_s
    for m in media.motions:
        assert m.n_frames == int(np.ceil(TRIAL_S * m.fps - 1e-9))
    # every slot moves in its last 0.3 s: nothing froze before the trial's end
    for slot in scene.slots:
        a, b = slot.joints_at(TRIAL_S - 0.3), slot.joints_at(TRIAL_S - 0.02)
        assert np.abs(a - b).max() > 1e-3


def test_longer_trial_than_a_motion_is_refused_unless_motion_end(study: Path, tmp_path: Path) -> None:
    from studyapp.study.design import validate_design

    def problems(text: str) -> list:
        path = study / "longer.toml"
        path.write_text(text)
        return validate_design(path)

    found = problems(design_text(duration=2.0))
    assert [p.key for p in found] == ["conditions[2]", "conditions[2]"]  # cmu, on both stimuli
    msg = found[0].message
    assert "'cmu'" in msg and "'s1'" in msg and "motion/cmu/s1.bvh" in msg and "1.300 s" in msg and "2.000 s" in msg
    assert 'motion_end = "hold" or "loop"' in found[0].fix and "at most 1.300" in found[0].fix
    for end in ("hold", "loop"):
        assert problems(design_text(duration=2.0, cmu_extra=f'motion_end = "{end}"')) == []
    # without its name_map the renamed CMU rig cannot be retargeted: the map is what makes it work
    assert [p.key for p in problems(design_text(name_map={"Hips": "Hips"}))] == ["conditions[2]"]


def test_looped_motion_plays_again_from_its_start(study: Path) -> None:
    from studyapp.study.design import load_design
    from studyapp.study.schedule import participant_schedule
    from studyapp.study.stimuli import clear_cache, load_trial_media

    path = study / "loop.toml"
    path.write_text(design_text(duration=2.0, cmu_extra='motion_end = "loop"'))
    clear_cache()
    design = load_design(path)
    plan = participant_schedule(design, "P01")[0]
    media = load_trial_media(design, plan)
    cmu = media.motions[plan.slots.index("cmu")]
    source = load_motion(study / "motion" / "cmu" / "s1.bvh")
    assert cmu.n_frames == 240 and source.n_frames == 156
    np.testing.assert_allclose(cmu.rotations[156:], source.rotations[:84])  # 1.3 s on, it starts again
    assert media.duration_s == 2.0
