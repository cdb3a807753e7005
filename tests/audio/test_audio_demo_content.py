"""The demo study's stimuli: shipped files equal their generator's output and have the designed properties.

Motion properties are measured on the shipped BVH files through the real BVH reader and forward
kinematics, the way a viewer (or the careful-viewer bot) sees them.
"""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from studyapp.audio.wav import AudioClip, load_wav, summarize
from studyapp.demo_content import CLIP_SECONDS, CLIPS, FPS, generate
from studyapp.demo_content.gestures import CONDITIONS, LAG_S, gesture_motion
from studyapp.demo_content.signals import delay, speech_energy
from studyapp.durations import duration_mismatches
from studyapp.face.io import load_face
from studyapp.motion.beat import beat_skeleton
from studyapp.motion.bvh import read_bvh_channels, read_bvh
from studyapp.motion.fk import joint_positions
from studyapp.resources import designs_dir

SHIPPED = designs_dir() / "demo"
CLIP_NAMES = [c.name for c in CLIPS]


@pytest.fixture(scope="module")
def regenerated(tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("demo")
    return out, generate(out)


@pytest.fixture(scope="module")
def energies() -> dict[str, np.ndarray]:
    return {c: speech_energy(load_wav(SHIPPED / "audio" / f"{c}.wav"), FPS) for c in CLIP_NAMES}


@pytest.fixture(scope="module")
def hands() -> dict[tuple[str, str], np.ndarray]:
    """World positions (F, 2, 3) of the right and left wrist for every shipped clip and condition."""
    out = {}
    for cond in CONDITIONS:
        for c in CLIP_NAMES:
            m = read_bvh(SHIPPED / "motion" / cond / f"{c}.bvh")
            sk = m.skeleton
            p = joint_positions(m)
            out[cond, c] = p[:, [sk.index("RightHand"), sk.index("LeftHand")]]
            out[cond, c, "all"] = p
    return out


def _hand_speed(h: np.ndarray) -> np.ndarray:
    return np.linalg.norm(np.gradient(h, axis=0), axis=2).sum(axis=1) * FPS


def _xcorr(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """Normalized correlation of a(t + lag) with b(t) for lag in [-max_lag, max_lag]."""
    a = (a - a.mean()) / a.std()
    b = (b - b.mean()) / b.std()
    n = a.size
    return np.array([np.mean(a[max(0, k):n + min(0, k)] * b[max(0, -k):n - max(0, k)])
                     for k in range(-max_lag, max_lag + 1)])


# ------------------------------------------------------------------------------------ shipped == generated

def test_shipped_files_are_exactly_the_generator_output(regenerated) -> None:
    out, written = regenerated
    made = sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file())
    shipped = sorted(p.relative_to(SHIPPED).as_posix() for p in SHIPPED.rglob("*") if p.is_file())
    assert made == shipped
    assert len(made) == 4 + 4 + 12 + 1
    assert written["motion"]["lagged"]["clip03"] == out / "motion" / "lagged" / "clip03.bvh"
    for rel in made:
        a, b = (out / rel).read_bytes(), (SHIPPED / rel).read_bytes()
        if a == b:
            continue
        # Not byte-identical (another platform's libm): the numbers must still agree.
        if rel.endswith(".wav"):
            np.testing.assert_allclose(load_wav(out / rel).samples, load_wav(SHIPPED / rel).samples, atol=2 / 32768)
        elif rel.endswith(".csv"):
            ra, rb = list(csv.reader(open(out / rel))), list(csv.reader(open(SHIPPED / rel)))
            assert ra[0] == rb[0]
            np.testing.assert_allclose(np.array(ra[1:], float), np.array(rb[1:], float), atol=2e-4)
        elif rel.endswith(".bvh"):
            np.testing.assert_allclose(read_bvh_channels(out / rel).channels, read_bvh_channels(SHIPPED / rel).channels,
                                       atol=0.02)
        else:
            assert json.loads(a) == json.loads(b), rel


def test_folder_is_small() -> None:
    total = sum(p.stat().st_size for p in SHIPPED.rglob("*") if p.is_file())
    assert total < 4.0e6, total


def test_generation_is_deterministic() -> None:
    e = np.abs(np.sin(np.linspace(0, 20, 90)))
    sk = beat_skeleton()
    a = gesture_motion(sk, e, FPS, 5, "synced")
    b = gesture_motion(sk, e, FPS, 5, "synced")
    np.testing.assert_array_equal(a.rotations, b.rotations)
    with pytest.raises(ValueError, match="unknown condition"):
        gesture_motion(sk, e, FPS, 5, "jittery")


# ------------------------------------------------------------------------------------ audio

def _f0_track(x: np.ndarray, sr: int, energy: np.ndarray) -> np.ndarray:
    """Pitch of loud 40 ms frames by autocorrelation (lag search 80-260 Hz), independent of the synthesizer."""
    hop = int(sr / FPS)
    win = int(0.04 * sr)
    out = []
    for i in np.flatnonzero(energy > 0.3):
        seg = x[i * hop: i * hop + win]
        if seg.size < win:
            continue
        seg = seg - seg.mean()
        ac = np.correlate(seg, seg, "full")[win - 1:]
        lo, hi = int(sr / 260), int(sr / 80)
        lag = lo + int(np.argmax(ac[lo:hi]))
        if ac[lag] > 0.3 * ac[0]:
            out.append(sr / lag)
    return np.array(out)


def test_audio_format_and_speech_like_structure(energies) -> None:
    medians = {}
    for spec in CLIPS:
        p = SHIPPED / "audio" / f"{spec.name}.wav"
        s = summarize(p)
        assert (s["sample_rate"], s["channels"], s["bits"], s["dtype"]) == (16000, 1, 16, "int16")
        assert s["duration"] == CLIP_SECONDS
        assert 0.5 < s["peak"] < 1.0
        clip = load_wav(p)
        e = energies[spec.name]
        # Phrase pauses: at least two silent stretches of >= 0.3 s inside the clip (not counting the ends).
        voiced = np.flatnonzero(e > 0.05)
        gaps = np.diff(voiced)
        assert np.sum(gaps >= 0.3 * FPS) >= 2
        # Syllable rate: the envelope's modulation spectrum over the voiced span peaks at 3-5 Hz... or close.
        span = e[voiced[0]: voiced[-1] + 1]
        spec_ = np.abs(np.fft.rfft(span - span.mean()))
        freqs = np.fft.rfftfreq(span.size, 1 / FPS)
        band = (freqs >= 1.0) & (freqs <= 10.0)
        assert 2.5 <= freqs[band][np.argmax(spec_[band])] <= 5.5
        f0 = _f0_track(clip.mono(), 16000, e)
        assert f0.size > 20
        assert np.percentile(f0, 5) > 95 and np.percentile(f0, 95) < 230
        assert np.ptp(np.percentile(f0, [10, 90])) > 10  # the pitch contour varies
        medians[spec.name] = (spec.speaker, float(np.median(f0)))
        # Formant-like timbre: the voice band holds nearly everything, the first-formant region (300 Hz-1 kHz)
        # more than the fundamental region does, and the second/third formants are audible (not a bare buzz).
        spectrum = np.abs(np.fft.rfft(clip.mono())) ** 2
        f = np.fft.rfftfreq(clip.n_samples, 1 / 16000)
        share = {band: spectrum[(f > band[0]) & (f < band[1])].sum() / spectrum.sum()
                 for band in ((80, 4000), (80, 300), (300, 1000), (1000, 4000))}
        assert share[80, 4000] > 0.9
        assert share[300, 1000] > share[80, 300]
        assert share[1000, 4000] > 0.01
    spk1 = [m for s, m in medians.values() if s == "spk1"]
    spk2 = [m for s, m in medians.values() if s == "spk2"]
    assert max(spk1) + 30 < min(spk2), medians


def test_clips_differ(energies) -> None:
    es = [energies[c] for c in CLIP_NAMES]
    for i in range(4):
        for j in range(i + 1, 4):
            assert abs(np.corrcoef(es[i], es[j])[0, 1]) < 0.5


# ------------------------------------------------------------------------------------ face

def test_face_follows_speech_blinks_and_expressions(energies) -> None:
    for c in CLIP_NAMES:
        face = load_face(SHIPPED / "face" / f"{c}.csv")
        e = energies[c]
        assert face.fps == FPS and face.n_frames == e.size and face.missing == ()
        assert np.corrcoef(face.weight("jawOpen"), e)[0, 1] > 0.8
        blink = face.weight("eyeBlinkLeft")
        np.testing.assert_array_equal(blink, face.weight("eyeBlinkRight"))
        closed = blink > 0.5
        n_blinks = int(np.sum(np.diff(closed.astype(int)) == 1))
        assert 2 <= n_blinks <= 6 and blink.max() > 0.9
        assert face.weight("browInnerUp").max() > 0.25
        assert face.weight("mouthSmileLeft").max() > 0.25
        assert np.abs(np.diff(face.weight("jawOpen"))).max() < 0.35  # smooth, no popping


# ------------------------------------------------------------------------------------ motion

def test_all_media_of_a_clip_last_equally_long() -> None:
    for c in CLIP_NAMES:
        items = {"audio": (load_wav(SHIPPED / "audio" / f"{c}.wav").duration, "wav"),
                 "face": (load_face(SHIPPED / "face" / f"{c}.csv").duration, "csv")}
        for cond in CONDITIONS:
            m = read_bvh(SHIPPED / "motion" / cond / f"{c}.bvh")
            assert m.skeleton.n_joints == 75 and m.fps == FPS
            items[f"motion:{cond}"] = (m.duration, cond)
        assert duration_mismatches(items, tolerance_s=1 / FPS + 1e-9) == []


def test_synced_beats_land_on_speech_and_lagged_is_300ms_late(energies, hands) -> None:
    max_lag = 12
    lag_frames = round(LAG_S * FPS)
    for c in CLIP_NAMES:
        e = energies[c]
        xs = {cond: _xcorr(_hand_speed(hands[cond, c]), e, max_lag) for cond in ("synced", "lagged")}
        best = {cond: int(np.argmax(x)) - max_lag for cond, x in xs.items()}
        assert abs(best["synced"]) <= 2, (c, best)
        assert abs(best["lagged"] - lag_frames) <= 2, (c, best)
        assert xs["synced"][max_lag] > xs["lagged"][max_lag] + 0.05, c
        assert xs["synced"][max_lag] > 0.3, c


def test_lagged_is_synced_shifted_by_300ms(hands) -> None:
    k = round(LAG_S * FPS)
    for c in CLIP_NAMES:
        s, lg = _hand_speed(hands["synced", c]), _hand_speed(hands["lagged", c])
        # same amplitude, later: correlation of the shifted speeds is near 1 away from the clip ends
        assert np.corrcoef(s[20:-40], lg[20 + k:-40 + k])[0, 1] > 0.9
        assert lg.mean() == pytest.approx(s.mean(), rel=0.2)


def test_static_moves_much_less(hands) -> None:
    for c in CLIP_NAMES:
        assert _hand_speed(hands["static", c]).mean() < 0.1 * _hand_speed(hands["synced", c]).mean()
        assert _hand_speed(hands["static", c]).max() < 10.0  # cm/s: idle drift only
        assert np.ptp(hands["static", c][..., 1], axis=0).max() < 3.0


def test_rest_pose_is_natural_and_gestures_reach_the_chest(hands) -> None:
    sk = beat_skeleton()
    for c in CLIP_NAMES:
        rest = hands["static", c]
        p = hands["static", c, "all"]
        hips_y = p[:, sk.index("Hips"), 1]
        shoulder_y = p[:, sk.index("RightArm"), 1]
        # Arms hang: hands near hip height, close to the body (a T-pose would have them at |x| ~ 76 cm).
        assert np.all(rest[..., 1] < hips_y[:, None] + 15) and np.all(rest[..., 1] > hips_y[:, None] - 15)
        assert np.all(np.abs(rest[..., 0]) < 40)
        # Feet on the floor.
        assert abs(p[0].min(axis=0)[1]) < 3.0
        g = hands["synced", c]
        pg = hands["synced", c, "all"]
        chest = pg[:, sk.index("Spine3")]
        in_space = (g[..., 2] > chest[:, None, 2] + 20) & (g[..., 1] > hips_y[:, None] + 25) & \
                   (g[..., 1] < shoulder_y[:, None] + 15)
        assert in_space.any(axis=1).mean() > 0.4  # a hand is in the gesture space for much of the clip
        assert np.all(g[..., 1] < shoulder_y[:, None] + 15)  # never far above the shoulders


def test_motion_is_smooth(hands) -> None:
    for cond in CONDITIONS:
        for c in CLIP_NAMES:
            h = hands[cond, c]
            # frame-to-frame acceleration of the wrists stays below 5 cm/frame^2 (45 m/s^2)...
            assert np.abs(np.diff(h, 2, axis=0)).max() < 5.0, (cond, c)
            # ...and almost no speed variance sits above 8 Hz (jitter would).
            sp = _hand_speed(h)
            power = np.abs(np.fft.rfft(sp - sp.mean())) ** 2
            freqs = np.fft.rfftfreq(sp.size, 1 / FPS)
            assert power[freqs > 8].sum() < 0.05 * power.sum(), (cond, c)


def test_gestures_vary(hands) -> None:
    """Strokes differ: the wrist displacement of the synced strokes is not one repeated pattern."""
    for c in CLIP_NAMES:
        h = hands["synced", c][:, 0]
        d = np.diff(h, axis=0)
        fast = np.linalg.norm(d, axis=1) > np.percentile(np.linalg.norm(d, axis=1), 90)
        dirs = d[fast] / np.linalg.norm(d[fast], axis=1, keepdims=True)
        assert np.linalg.svd(dirs - dirs.mean(0), compute_uv=False)[1] > 0.5  # not all along one line


# ------------------------------------------------------------------------------------ signals

def test_speech_energy_alignment_and_normalization() -> None:
    sr = 16000
    x = np.zeros(sr)
    x[sr // 2:] = 0.3 * np.sin(2 * np.pi * 150 * np.arange(sr // 2) / sr)
    e = speech_energy(AudioClip(x.astype(np.float32), sr), FPS)
    assert e.shape == (30,) and e.max() == pytest.approx(1.0)
    assert np.all(e[:15] < 1e-9)          # frames centred before 0.5 s - half a frame see silence...
    assert e[15] == pytest.approx(np.sqrt(0.5), abs=0.03)  # ...the frame at 0.5 s straddles the onset
    assert np.all(e[16:29] > 0.99)
    assert speech_energy(AudioClip(np.zeros(1600, np.float32), sr), FPS).max() == 0


def test_delay() -> None:
    s = np.arange(1.0, 6.0)
    np.testing.assert_array_equal(delay(s, 10, 0.2), [0, 0, 1, 2, 3])
    np.testing.assert_array_equal(delay(s, 10, 0.2, hold_first=True), [1, 1, 1, 2, 3])
    np.testing.assert_array_equal(delay(s, 10, 0.0), s)
    np.testing.assert_array_equal(delay(s, 10, 9.0), np.zeros(5))
