"""Trial media loading (slot order, cache, frozen slots, live models) and the careful viewer's scores."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from studyapp.audio.wav import save_wav
from studyapp.demo_content.gestures import gesture_motion
from studyapp.demo_content.signals import speech_energy
from studyapp.demo_content.speech import SPEAKERS, synthesize_speech
from studyapp.face.animation import FaceAnimation
from studyapp.face.io import save_face_csv
from studyapp.motion.beat import beat_skeleton
from studyapp.motion.bvh import write_bvh
from studyapp.motion.skeleton import Motion
from studyapp.study import stimuli
from studyapp.bots.careful import careful_scores, motion_measures, scores_from_measures
from studyapp.study.design import load_design
from studyapp.study.schedule import TrialPlan, participant_schedule
from studyapp.study.stimuli import TrialMedia, frozen_motion, load_head, load_trial_media

FPS = 30.0
SECONDS = 10.0
CONDS = ("synced", "lagged", "static")

DESIGN = '''title = "Stimuli test"
[[conditions]]
id = "synced"
motion = "motion/synced/{stimulus}.bvh"
[[conditions]]
id = "lagged"
motion = "motion/lagged/{stimulus}.bvh"
[[conditions]]
id = "static"
motion = "motion/static/{stimulus}.bvh"
[[stimuli]]
id = "a"
audio = "audio/a.wav"
face = "face/a.csv"
tags = { speaker = "spk1" }
[[stimuli]]
id = "b"
audio = "audio/b.wav"
tags = { speaker = "spk2" }
duration_s = 3.0
[[attention_checks]]
stimulus = "a"
kind = "frozen"
[slots]
labels = "LMR"
'''


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    """Two 10 s clips of synthetic speech with the demo's three kinds of motion (the demo generator's code)."""
    root = tmp_path_factory.mktemp("stim")
    sk = beat_skeleton()
    for seed, (sid, spk) in enumerate((("a", "spk1"), ("b", "spk2")), start=11):
        audio, _ = synthesize_speech(SPEAKERS[spk], seed, duration_s=SECONDS)
        (root / "audio").mkdir(exist_ok=True)
        save_wav(audio, root / "audio" / f"{sid}.wav")
        energy = speech_energy(audio, FPS)
        for cond in CONDS:
            (root / "motion" / cond).mkdir(parents=True, exist_ok=True)
            write_bvh(gesture_motion(sk, energy, FPS, seed, cond), root / "motion" / cond / f"{sid}.bvh")
    (root / "face").mkdir()
    face = FaceAnimation.neutral(int(SECONDS * FPS), FPS)
    face.weights[:, 17] = np.linspace(0, 1, face.n_frames)
    save_face_csv(face, root / "face" / "a.csv")
    (root / "design.toml").write_text(DESIGN)
    return root


@pytest.fixture()
def design(study: Path):
    stimuli.clear_cache()
    return load_design(study / "design.toml")


def plan(slots: tuple[str, str, str], stimulus: str = "a", index: int = 0) -> TrialPlan:
    return TrialPlan(index, stimulus, slots, False, False, 0)


def test_media_in_slot_order(design, study: Path) -> None:
    media = load_trial_media(design, plan(("static", "synced", "lagged")))
    assert isinstance(media, TrialMedia)
    assert [Path(m.source).parent.name for m in media.motions] == ["static", "synced", "lagged"]
    assert media.motions[0].skeleton.n_joints == 75 and media.motions[1].fps == FPS
    assert media.audio.sample_rate == 16000 and media.audio.duration == pytest.approx(SECONDS)
    assert media.face.n_frames == int(SECONDS * FPS) and media.face.weights[-1].max() == pytest.approx(1.0)
    assert media.labels == ("L", "M", "R") and media.avatar == media.avatar_spec == "builtin"
    assert media.duration_s == pytest.approx(SECONDS) and media.criteria == ("realism", "synchronization", "diversity")
    assert media.name_maps == ({}, {}, {})


def test_duration_and_missing_face(design) -> None:
    media = load_trial_media(design, plan(CONDS, "b"))
    assert media.duration_s == 3.0
    assert media.face.duration >= 3.0 and not media.face.weights.any()  # neutral face, long enough


def test_replay_costs_no_loading(design, monkeypatch) -> None:
    first = load_trial_media(design, plan(CONDS))

    def boom(*a, **k):
        raise AssertionError("a replay must not read files again")

    monkeypatch.setattr("studyapp.motion.io.load_motion", boom)
    monkeypatch.setattr("studyapp.audio.wav.load_wav", boom)
    monkeypatch.setattr("studyapp.face.io.load_face", boom)
    again = load_trial_media(design, plan(CONDS))
    assert again is first
    # Another slot order of the same clip reuses the decoded files (validation already warmed them too).
    other = load_trial_media(design, plan(("lagged", "static", "synced"), index=3))
    assert other.motions[2] is first.motions[0]
    assert stimuli.cache_info()["media_hits"] >= 1


def test_frozen_slot_holds_first_frame(design) -> None:
    media = load_trial_media(design, plan(("synced", "frozen:lagged", "static")))
    frozen, lagged = media.motions[1], load_trial_media(design, plan(CONDS)).motions[1]
    assert frozen.n_frames == int(SECONDS * FPS)
    np.testing.assert_array_equal(frozen.rotations, np.repeat(lagged.rotations[:1], frozen.n_frames, axis=0))
    assert frozen.skeleton is lagged.skeleton


def test_schedule_plans_load(design) -> None:
    plans = participant_schedule(design, "P1", row=1)
    check = next(p for p in plans if p.is_attention_check)
    media = load_trial_media(design, check)
    still = media.motions[check.slots.index(next(s for s in check.slots if s.startswith("frozen:")))]
    assert np.ptp(still.rotations, axis=0).max() == 0.0


def test_live_model_condition(study: Path, tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("STUDYAPP_CACHE_DIR", str(tmp_path / "cache"))
    from studyapp.models.reference import shipped_reference_model

    text = DESIGN.replace('motion = "motion/lagged/{stimulus}.bvh"', 'model = "builtin:reference"')
    (study / "live.toml").write_text(text)
    d = load_design(study / "live.toml")
    assert d.conditions[1].is_live
    media = load_trial_media(d, plan(("lagged", "synced", "static")))
    live = media.motions[0]
    assert live.skeleton.n_joints == 75 and "(live)" in live.source
    assert live.duration == pytest.approx(SECONDS, abs=2 / live.fps)
    assert np.ptp(live.rotations, axis=0).max() > 1e-3  # the model moves the figure
    # A path to a copy works the same way, relative to the design file.
    shutil.copy(shipped_reference_model(), study / "ref.onnx")
    (study / "live2.toml").write_text(text.replace("builtin:reference", "ref.onnx"))
    media2 = load_trial_media(load_design(study / "live2.toml"), plan(("lagged", "synced", "static")))
    np.testing.assert_allclose(media2.motions[0].rotations, live.rotations)


def test_live_model_problems_are_reported(study: Path) -> None:
    from studyapp.study.design import validate_design

    (study / "bad.onnx").write_bytes(b"not a model")
    text = DESIGN.replace('motion = "motion/lagged/{stimulus}.bvh"', 'model = "bad.onnx"')
    (study / "bad.toml").write_text(text)
    probs = validate_design(study / "bad.toml")
    assert [p.key for p in probs] == ["conditions[1].model"] and "ONNX" in probs[0].message


def test_head_file_loader(tmp_path: Path) -> None:
    p = tmp_path / "head.csv"
    p.write_text("Timecode,HeadYaw,HeadPitch,HeadRoll,Other\n0,0.1,0.2,0.3,9\n1,0.4,0.5,0.6,9\n")
    np.testing.assert_allclose(load_head(p), [[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]])
    bad = tmp_path / "bad.csv"
    bad.write_text("yaw,pitch\n1,2\n")
    with pytest.raises(Exception, match="yaw, pitch and roll"):
        load_head(bad)


def rank_order(scores: tuple[float, float, float], slots) -> list[str]:
    return [slots[i] for i in np.argsort(scores)[::-1]]


def test_careful_scores_rank_the_synthetic_conditions(design) -> None:
    for sid in ("a", "b"):
        media = load_trial_media(design, plan(("static", "lagged", "synced"), sid))
        s = careful_scores(media)
        assert set(s) == {"realism", "synchronization", "diversity"}
        assert rank_order(s["synchronization"], media.slots) == ["synced", "lagged", "static"]
        assert rank_order(s["diversity"], media.slots)[-1] == "static"
        # a quiet figure is plausible, gestures 300 ms late are not: realism disagrees with diversity on the
        # 10 s clip a; the 3 s clip b is too short to notice the lag, so there static is simply least real
        if sid == "a":
            assert rank_order(s["realism"], media.slots) == ["synced", "static", "lagged"]
        else:
            assert rank_order(s["realism"], media.slots)[-1] == "static"
        frozen = careful_scores(load_trial_media(design, plan(("static", "frozen:synced", "lagged"), sid)))
        assert int(np.argmin(frozen["realism"])) == 1


def test_careful_penalises_jitter_and_ignores_units(design) -> None:
    media = load_trial_media(design, plan(CONDS))
    smooth = media.motions[0]
    energy = speech_energy(media.audio, smooth.fps)
    rng = np.random.default_rng(0)
    rot = smooth.rotations + rng.normal(0, 0.03, smooth.rotations.shape)
    rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
    jittery = Motion(smooth.skeleton, smooth.fps, rot, smooth.translations)
    a = scores_from_measures(motion_measures(smooth, energy, media.duration_s))
    b = scores_from_measures(motion_measures(jittery, energy, media.duration_s))
    assert b["realism"] < 0.5 * a["realism"]
    # The same motion in metres instead of centimetres scores the same.
    from studyapp.motion.skeleton import Skeleton

    sk = smooth.skeleton
    metres = Motion(Skeleton(sk.names, sk.parents, sk.offsets / 100, sk.channels,
                             {j: v / 100 for j, v in sk.end_sites.items()}, unit_scale=1.0), smooth.fps,
                    smooth.rotations, smooth.translations / 100)
    c = scores_from_measures(motion_measures(metres, energy, media.duration_s))
    for k in a:
        assert c[k] == pytest.approx(a[k], rel=1e-6)


def test_frozen_motion_length() -> None:
    m = Motion.rest(beat_skeleton(), 5, 15.0)
    assert frozen_motion(m, 2.0).n_frames == 30 and frozen_motion(m, 0.01).n_frames == 1


def test_file_cache_is_bounded_by_bytes_and_count() -> None:
    cache = stimuli._LRU(size=3, max_bytes=1000)
    made = []

    def make(n):
        made.append(n)
        return np.zeros(n, np.uint8)

    a = cache.get("a", lambda: make(400))
    assert cache.get("a", lambda: make(1)) is a and made == [400]
    cache.get("b", lambda: make(400))
    cache.get("c", lambda: make(400))      # 1200 bytes > 1000: the oldest ("a") goes
    assert len(cache) == 2 and cache.n_bytes == 800
    cache.get("a", lambda: make(400))
    assert made == [400, 400, 400, 400]    # "a" had to be made again
    cache.get("huge", lambda: make(5000))  # larger than the budget: kept alone, it is the one in use
    assert len(cache) == 1 and cache.n_bytes == 5000
    for k in "wxyz":
        cache.get(k, lambda: make(1))
    assert len(cache) == 3                 # the count bound
