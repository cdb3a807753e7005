"""The motion metrics against answers known in closed form or computed independently (plain loops)."""
from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from scipy import linalg

from studyapp.motion import metrics as M

FPS = 60.0


def _sinusoid(amp: float, freq: float, seconds: float, n_joints: int = 3) -> np.ndarray:
    """Joint 0 still (the root), the others x = amp sin(2 pi f t): a whole number of periods."""
    t = np.arange(int(round(seconds * FPS))) / FPS
    pos = np.zeros((t.size, n_joints, 3))
    pos[:, 1:, 0] = amp * np.sin(2 * np.pi * freq * t)[:, None]
    return pos


def test_jerk_and_acceleration_of_a_sinusoid_match_the_closed_form():
    amp, freq = 0.2, 0.75  # 80 frames a period, 30 periods: the sampled mean of |sin| is 2/pi to 1e-4
    pos = _sinusoid(amp, freq, 40.0)
    w, h = 2 * np.pi * freq, 1 / FPS
    # k-th finite difference of A sin(w t) has amplitude A (2 sin(w h / 2))^k; the mean of |sin| over whole
    # periods is 2 / pi; joint 0 does not move, so 2 of 3 joints carry it.
    for k, fn in ((2, M.mean_acceleration), (3, M.mean_jerk)):
        expected = (2 / 3) * amp * (2 * math.sin(w * h / 2)) ** k * FPS ** k * (2 / np.pi)
        assert fn(pos, FPS) == pytest.approx(expected, rel=1e-3)
    # and the continuous derivative amplitude A w^3 it approximates
    assert M.mean_jerk(pos, FPS) == pytest.approx((2 / 3) * amp * w ** 3 * 2 / np.pi, rel=1e-2)


def test_frozen_share_is_exactly_the_held_steps():
    rng = np.random.default_rng(0)
    pos = np.cumsum(rng.normal(0, 0.01, (101, 4, 3)), axis=0)   # 100 steps, every joint moving ~0.6 m/s
    pos[40:71] = pos[40]                                         # frames 40..70 held: steps 40..69 = 30 steps
    assert M.frozen_share(pos, FPS) == pytest.approx(0.30, abs=1e-12)
    loops = sum(all(np.linalg.norm(pos[i + 1, j] - pos[i, j]) * FPS < M.FROZEN_SPEED for j in range(4))
                for i in range(100)) / 100
    assert M.frozen_share(pos, FPS) == loops
    pos[10, 2] += 1e-5  # one joint creeping (0.6 mm/s at 60 fps steps) stays frozen; 1 cm/s does not
    assert M.frozen_share(pos, FPS) == pytest.approx(0.30, abs=1e-12)


def _beat_motion(beats: np.ndarray, seconds: float) -> np.ndarray:
    """A hand whose speed is |sin| shaped with zeros exactly at ``beats`` (and nowhere else)."""
    t = (np.arange(int(seconds * FPS) + 1)) / FPS
    edges = np.concatenate([[0.0], beats, [seconds]])
    speed = np.zeros_like(t)
    for a, b in zip(edges[:-1], edges[1:]):
        inside = (t >= a) & (t <= b)
        speed[inside] = np.sin(np.pi * (t[inside] - a) / (b - a))
    x = np.concatenate([[0.0], np.cumsum(speed[:-1]) / FPS])
    pos = np.zeros((t.size, 2, 3))
    pos[:, 1, 0] = x
    return pos


def test_motion_beats_fall_on_the_velocity_minima_and_score_one_on_the_onsets():
    beats = np.array([0.8, 1.7, 2.4, 3.5])
    pos = _beat_motion(beats, 4.5)
    found = M.motion_beats(pos, FPS)
    assert len(found) == len(beats)
    # the smoothing (1/12 s) moves a minimum between unequal strokes by a frame or two
    assert np.abs(found - beats).max() <= 2.0 / FPS
    assert M.beat_align_score(found, beats) == pytest.approx(1.0, abs=2e-3)
    shifted = beats + 0.25  # every onset 250 ms late: exp(-0.25^2 / (2 * 0.3^2))
    assert M.beat_align_score(found, shifted) == pytest.approx(math.exp(-0.25 ** 2 / (2 * 0.3 ** 2)), abs=0.03)  # beats within 2 frames: at most 0.03 apart


def test_beat_align_score_equals_a_loop():
    rng = np.random.default_rng(3)
    mb, on = np.sort(rng.uniform(0, 10, 17)), np.sort(rng.uniform(0, 10, 23))
    for over, src, ref in (("motion", mb, on), ("onsets", on, mb)):
        total = 0.0
        for s in src:
            d = min(abs(s - r) for r in ref)
            total += math.exp(-d * d / (2 * 0.3 * 0.3))
        assert M.beat_align_score(mb, on, over=over) == pytest.approx(total / len(src), abs=1e-12)
    assert math.isnan(M.beat_align_score(np.zeros(0), on))


def test_a_held_pose_has_no_beats():
    assert M.motion_beats(np.zeros((120, 3, 3)), FPS).size == 0


def test_l1_diversity_equals_a_loop_over_segment_pairs():
    rng = np.random.default_rng(1)
    pos = rng.normal(0, 0.1, (65, 4, 3))
    seg = 15  # 4 segments, 5 frames dropped
    segs = [pos[i * seg:(i + 1) * seg] - pos[i * seg:(i + 1) * seg, :1] for i in range(4)]
    dists = [np.abs(a - b).sum() / (seg * 4) for a, b in itertools.combinations(segs, 2)]
    assert M.l1_diversity(pos, seg) == pytest.approx(np.mean(dists), rel=1e-12)
    # a repeated gesture has no diversity; a standing place does not add any
    rep = np.tile(pos[:seg], (4, 1, 1)) + np.repeat(np.arange(4), seg)[:, None, None] * 0.5
    assert M.l1_diversity(rep, seg) == pytest.approx(0.0, abs=1e-12)
    assert math.isnan(M.l1_diversity(pos[:20], seg))


def _frechet_by_eigh(a: np.ndarray, b: np.ndarray) -> float:
    """tr((S1 S2)^1/2) = tr((S1^1/2 S2 S1^1/2)^1/2), both square roots of symmetric matrices by eigh."""
    def sym_sqrt(s):
        w, v = np.linalg.eigh(s)
        return (v * np.sqrt(np.clip(w, 0, None))) @ v.T
    mu1, mu2 = a.mean(0), b.mean(0)
    s1 = (a - mu1).T @ (a - mu1) / (len(a) - 1)
    s2 = (b - mu2).T @ (b - mu2) / (len(b) - 1)
    r = sym_sqrt(s1)
    return float(((mu1 - mu2) ** 2).sum() + np.trace(s1) + np.trace(s2) - 2 * np.trace(sym_sqrt(r @ s2 @ r)))


def test_frechet_distance_matches_an_independent_formula_and_the_gaussian_closed_form():
    rng = np.random.default_rng(2)
    a = rng.normal(0, 1, (400, 5))
    b = rng.normal(0.5, 2, (300, 5)) @ rng.normal(0, 1, (5, 5))
    assert M.frechet_distance(a, b) == pytest.approx(_frechet_by_eigh(a, b), rel=1e-8)
    assert M.frechet_distance(a, a) == pytest.approx(0.0, abs=1e-8)
    # 1-D: (mu1 - mu2)^2 + (s1 - s2)^2
    x, y = rng.normal(0, 1, (500, 1)), rng.normal(0, 1, (500, 1))
    y = 3 + 2 * (y - y.mean()) / y.std(ddof=1)
    x = (x - x.mean()) / x.std(ddof=1)
    assert M.frechet_distance(x, y) == pytest.approx(9 + 1, rel=1e-9)
    assert linalg  # scipy's sqrtm is what the module uses; the check above avoids it


def test_bad_shapes_are_refused():
    with pytest.raises(ValueError, match=r"\(frames, joints, 3\)"):
        M.mean_jerk(np.zeros((10, 3)), FPS)
