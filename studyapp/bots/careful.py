"""What a careful viewer perceives in each slot: the scores behind the ``careful`` bot's answers.

Rankings compare the scores of a trial's three slots (:func:`careful_scores`); ratings and two-figure
preferences need a scale that means the same in every trial, :func:`careful_ratings` (0..100 per criterion,
:func:`ratings_from_scores`); a mismatch trial is judged on :func:`alignment_ratings`, how well each slot's
motion fits the trial's speech.

Each score is a plain, documented signal measure (higher = better), computed on the hands because that is
where co-speech gesture lives, and normalised by the figure's height so units (cm, m) do not matter:

* **synchronization**: Pearson correlation ``r`` at lag 0 between the speed of the hands *relative to the
  chest* (a viewer reads gestures against the body; whole-body sway would only add noise) and the
  *accents* of the speech energy envelope (:func:`speech_accents`: its syllable peaks as short pulses
  weighted by loudness), frame by frame; mapped to ``(1 + r) / 2`` and times an *activity* factor: a
  figure that barely moves shows no synchrony to perceive, whatever its correlation, so it ranks below
  one that moves out of time. Accents rather than the raw envelope because what a viewer matches is beat
  strokes landing on stressed syllables: hands also move while preparing a stroke, during loud
  stretches, which blurs a correlation with the whole envelope.
* **diversity**: how much of the gesture space the hands cover (spread of hand positions relative to the
  chest, in figure heights, from their 10-90 % range, so the moments spent lifting the hands from rest do
  not count as variety) times how varied their movement is in time (0.5 + 0.5 x normalised
  spectral entropy of hand speed: one repeated rhythm scores low, varied strokes high).
* **realism**: could a real person move like this? Three things give a figure away: it is dead (a
  frozen pose; but a person standing quietly, breathing and swaying, is alive: the *alive* factor
  ``1 - exp(-a / 0.005)`` saturates already at idle sway), it jitters (smoothness ``(1 - h)^2``, with ``h``
  the fraction of hand velocity power above 6 Hz: gestures live below a few Hz, frame-to-frame jitter
  spreads its power up to the Nyquist rate), and its visible gestures are mistimed: real speakers' strokes
  land on the stressed syllables, so strokes that consistently come late or early look dubbed. The
  evidence is ``gap = r_best - r_0``: how much better hand speed would correlate with the speech accents
  if the motion were shifted (by up to +-0.5 s) than it does as played; ``mistimed = min(1, gap / 0.2)``,
  weighted by the activity factor (a still figure has no strokes to mistime), by ``MISTIMING_WEIGHT`` and
  by how long the viewer could watch: it takes several strokes to notice a consistent offset (in 3 s the
  quasi-periodic syllable rhythm makes a shift by one beat fit as well by chance), so the evidence counts
  not at all up to 3 s and fully from 5 s on. So realism and diversity disagree where they should: a
  figure that stands quietly is plausible but not diverse, one that gestures richly but off the beat is
  diverse but not plausible.

The activity factor is ``1 - exp(-a / 0.05)`` with ``a`` the mean world-space hand speed in figure heights
per second (gesturing hands move ~0.1-0.3 heights/s; idle sway well under 0.01).

>>> from studyapp.resources import demo_design
>>> from studyapp.study.design import load_design
>>> from studyapp.study.schedule import participant_schedule
>>> from studyapp.study.stimuli import load_trial_media
>>> d = load_design(demo_design())
>>> media = load_trial_media(d, participant_schedule(d, "P01", row=0)[1])
>>> sorted(careful_scores(media)) == sorted(c.id for c in d.criteria)
True
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from studyapp.motion.skeleton import Motion

if TYPE_CHECKING:
    from studyapp.study.stimuli import TrialMedia

#: Mean hand speed (figure heights per second) at which a figure counts as clearly moving.
ACTIVITY_REF = 0.05
#: Frequency (Hz) above which hand movement reads as jitter rather than gesture.
JITTER_HZ = 6.0
#: Mean hand speed (figure heights per second) at which a figure looks alive: idle breathing and sway.
ALIVE_REF = 0.005
#: Largest gesture-speech shift (s) looked for, and the correlation gain from shifting at which strokes
#: look plainly mistimed.
MAX_LAG_S = 0.5
TIMING_GAP_REF = 0.2
#: How much clearly mistimed, clearly visible gesturing takes off realism (0: none, 1: all of it).
MISTIMING_WEIGHT = 0.8
#: Clip length (s) below which timing is not judged, and from which it is judged fully.
TIMING_MIN_S, TIMING_FULL_S = 3.0, 5.0

_HAND_BONES = ("LeftHand", "RightHand")
_FALLBACK_BONES = ("LeftLowerArm", "RightLowerArm")
_BODY_BONES = ("UpperChest", "Chest", "Spine", "Hips")


def body_indices(motion: Motion) -> tuple[list[int], int]:
    """Joint indices of the hands (else forearms, else all joints) and of the chest (else spine, hips, root)."""
    from studyapp.motion.retarget import detect_name_map

    by_bone = {b: motion.skeleton.index(j) for j, b in detect_name_map(motion.skeleton).items()}
    hands = next(([by_bone[b] for b in want if b in by_bone] for want in (_HAND_BONES, _FALLBACK_BONES)
                  if any(b in by_bone for b in want)), list(range(motion.skeleton.n_joints)))
    chest = next((by_bone[b] for b in _BODY_BONES if b in by_bone), 0)
    return hands, chest


def speech_accents(energy: np.ndarray, fps: float) -> np.ndarray:
    """Syllable accents of an energy envelope: a 30 ms pulse at each peak, as tall as the peak.

    Peaks of the envelope smoothed over 50 ms, at least 0.2 of the maximum and 150 ms apart (syllables
    come at 3-7 per second).

    >>> e = np.zeros(30); e[10] = 1.0; e[20] = 0.5
    >>> a = speech_accents(e, 30.0)
    >>> int(np.argmax(a)), bool(a[20] > a[15])
    (10, True)
    """
    # scipy's smoothing and peak picking, in numpy: a participant's install (and its bot) has no scipy
    from studyapp.audio.dsp import find_peaks, gaussian_filter1d

    e = np.asarray(energy, dtype=np.float64)
    smooth = gaussian_filter1d(e, 0.05 * fps) if 0.05 * fps > 0.3 else e
    peaks = find_peaks(smooth, height=0.2 * max(smooth.max(initial=0.0), 1e-12),
                          distance=max(1, int(round(0.15 * fps))))
    pulses = np.zeros_like(smooth)
    pulses[peaks] = smooth[peaks]
    return gaussian_filter1d(pulses, 0.03 * fps) if 0.03 * fps > 0.3 else pulses


def motion_measures(motion: Motion, energy: np.ndarray | None, duration_s: float) -> dict[str, float]:
    """The raw measures behind the scores for one motion (``energy`` frame-aligned at the motion's rate)."""
    from studyapp.motion.fk import figure_height, joint_positions

    fps = float(motion.fps)
    n = max(1, min(motion.n_frames, int(round(duration_s * fps))))
    if n < 4:
        return {"activity": 0.0, "correlation": 0.0, "lag": 0.0, "timing_gap": 0.0, "seconds": n / fps,
                "spread": 0.0, "entropy": 0.0, "high_freq": 0.0}
    clipped = Motion(motion.skeleton, fps, motion.rotations[:n], motion.translations[:n])
    hands, chest = body_indices(motion)
    pos = joint_positions(clipped) / (figure_height(clipped) or 1.0)
    world = pos[:, hands]                       # (F, H, 3)
    rel = world - pos[:, [chest]]
    vel = np.gradient(world, 1.0 / fps, axis=0)
    speed = np.linalg.norm(vel, axis=-1)        # (F, H)
    activity = float(speed.mean())
    rel_speed = np.linalg.norm(np.gradient(rel, 1.0 / fps, axis=0), axis=-1).sum(axis=1)

    corr = lag = gap = 0.0
    if energy is not None:
        m = min(n, len(energy))
        a, b = rel_speed[:m], speech_accents(np.asarray(energy[:m], dtype=np.float64), fps)
        if m > 2 and a.std() > 1e-12 and b.std() > 1e-12:
            corr = float(np.corrcoef(a, b)[0, 1])
            lag, best_r = best_lag(a, b, fps)
            gap = max(0.0, best_r - corr)

    power = (np.abs(np.fft.rfft(vel, axis=0)) ** 2).sum(axis=(1, 2))
    freqs = np.fft.rfftfreq(n, 1.0 / fps)
    high = float(power[freqs > JITTER_HZ].sum() / power.sum()) if power.sum() > 1e-18 else 0.0

    # The 10-90 % range (in standard deviations of a normal: / 2.563) rather than the variance, whose
    # squares let the few frames spent lifting the hands from rest dominate (a 300 ms later start measured
    # ~20 % "more diverse"); unlike a median-based spread it keeps gestures made in under half the frames.
    lo, hi = np.percentile(rel, [10.0, 90.0], axis=0)                      # (H, 3) each
    spread = float(np.sqrt((((hi - lo) / 2.563) ** 2).sum(axis=-1).mean()))
    spec = np.abs(np.fft.rfft(rel_speed - rel_speed.mean()))[1:] ** 2
    entropy = 0.0
    if spec.sum() > 1e-18 and len(spec) > 1:
        p = spec / spec.sum()
        entropy = float(-(p[p > 0] * np.log(p[p > 0])).sum() / np.log(len(p)))
    return {"activity": activity, "correlation": corr, "lag": lag, "timing_gap": gap, "seconds": n / fps,
            "spread": spread, "entropy": entropy, "high_freq": high}


def best_lag(motion_speed: np.ndarray, accents: np.ndarray, fps: float) -> tuple[float, float]:
    """The lag (s; positive: the motion comes late) within +-``MAX_LAG_S`` at which ``motion_speed`` correlates
    best with ``accents`` (both frame-aligned), and that correlation.

    >>> t = np.arange(300) / 30.0
    >>> accents = np.exp(-0.5 * ((t[:, None] - np.arange(0.5, 10, 0.9)) / 0.05) ** 2).sum(axis=1)
    >>> lag, r = best_lag(np.roll(accents, 9), accents, 30.0)
    >>> round(lag, 3), r > 0.9
    (0.3, True)
    """
    n = min(len(motion_speed), len(accents))
    most = min(int(round(MAX_LAG_S * fps)), n - 3)
    best, best_r = 0, -np.inf
    for shift in range(-most, most + 1):
        a = motion_speed[shift:n] if shift >= 0 else motion_speed[:n + shift]
        b = accents[:n - shift] if shift >= 0 else accents[-shift:n]
        if a.std() > 1e-12 and b.std() > 1e-12:
            r = float(np.corrcoef(a, b)[0, 1])
            if r > best_r + 1e-12 or (abs(r - best_r) <= 1e-12 and abs(shift) < abs(best)):
                best, best_r = shift, r
    return best / fps, float(best_r if np.isfinite(best_r) else 0.0)


def scores_from_measures(m: dict[str, float]) -> dict[str, float]:
    """Per-criterion scores (higher = better) from :func:`motion_measures`."""
    active = 1.0 - np.exp(-m["activity"] / ACTIVITY_REF)
    alive = 1.0 - np.exp(-m["activity"] / ALIVE_REF)
    smooth = (1.0 - m["high_freq"]) ** 2
    watched = float(np.clip((m.get("seconds", 0.0) - TIMING_MIN_S) / (TIMING_FULL_S - TIMING_MIN_S), 0.0, 1.0))
    mistimed = watched * min(1.0, m.get("timing_gap", 0.0) / TIMING_GAP_REF)
    return {
        "synchronization": float(active * (1.0 + m["correlation"]) / 2.0),
        "diversity": float(m["spread"] * (0.5 + 0.5 * m["entropy"])),
        "realism": float(alive * smooth * (1.0 - MISTIMING_WEIGHT * active * mistimed)),
    }


def _slot_scores(media: "TrialMedia") -> list[dict[str, float]]:
    """:func:`scores_from_measures` of each slot's motion, against the trial's speech."""
    from studyapp.demo_content.signals import speech_energy

    energies: dict[float, np.ndarray] = {}
    per_slot = []
    for motion in media.motions:
        fps = float(motion.fps)
        if fps not in energies:
            energies[fps] = speech_energy(media.audio, fps)
        per_slot.append(scores_from_measures(motion_measures(motion, energies[fps], media.duration_s)))
    return per_slot


_KNOWN = ("realism", "synchronization", "diversity")


def careful_scores(media: "TrialMedia") -> dict[str, tuple[float, ...]]:
    """Scores per criterion for the trial's slots (left to right); higher = better.

    Criteria other than realism / synchronization / diversity (designs may define their own) get the mean
    of the slots' normalised known scores, so a careful viewer still prefers the better motion overall.
    """
    per_slot = _slot_scores(media)
    n = len(per_slot)
    out = {k: tuple(s[k] for s in per_slot) for k in _KNOWN}
    extra = {}
    for cid in media.criteria:
        if cid not in out:
            normed = []
            for k in _KNOWN:
                v = np.asarray(out[k], dtype=np.float64)
                rng = v.max() - v.min()
                normed.append((v - v.min()) / rng if rng > 0 else np.zeros(n))
            extra[cid] = tuple(float(x) for x in np.mean(normed, axis=0))
    return {**out, **extra}


#: Diversity score (figure heights, :func:`scores_from_measures`) at which a figure's rating reaches 63 of
#: 100: gesturing figures of the demo content score 0.03-0.06, a figure standing still under 0.01.
DIVERSITY_REF = 0.03


def ratings_from_scores(scores: dict[str, float]) -> dict[str, float]:
    """The scores of one figure on a 0..100 scale, the same for every trial (so figures of different trials
    can be compared, as ratings and preferences between two figures need): realism and synchronization are
    already 0..1 (times 100); diversity, unbounded, saturates as ``1 - exp(-d / DIVERSITY_REF)``.

    >>> ratings_from_scores({"realism": 0.9, "synchronization": 0.5, "diversity": 0.03})["diversity"]
    63.212055882855765
    """
    return {"realism": 100.0 * scores["realism"], "synchronization": 100.0 * scores["synchronization"],
            "diversity": 100.0 * (1.0 - float(np.exp(-scores["diversity"] / DIVERSITY_REF)))}


def careful_ratings(media: "TrialMedia") -> dict[str, tuple[float, ...]]:
    """What a careful viewer would rate each slot per criterion, 0..100 (:func:`ratings_from_scores`);
    criteria other than the known three get the mean of the three."""
    per_slot = [ratings_from_scores(s) for s in _slot_scores(media)]
    out = {k: tuple(r[k] for r in per_slot) for k in _KNOWN}
    for cid in media.criteria:
        if cid not in out:
            out[cid] = tuple(float(np.mean([r[k] for k in _KNOWN])) for r in per_slot)
    return out


def alignment_ratings(media: "TrialMedia") -> tuple[float, ...]:
    """How well each slot's motion fits the trial's speech, 0..100: the synchronization rating (hand strokes
    against the speech's syllable accents, times activity). What a careful viewer of a ``mismatch`` trial
    compares: the slot playing its own speech's motion should fit it better than one playing another clip's.

    Why not the Beat Align Score (:func:`studyapp.motion.metrics.beat_align_score` against
    :func:`studyapp.audio.onsets.onset_times`): syllable onsets come every ~0.25 s, so with its 0.3 s Gaussian
    almost any motion beat is near one; on the demo content it told a synced motion with its own speech from
    the same motion with the other clip's speech by under 0.01 in one of four pairs (the wrong way), where
    this measure differs by 0.13-0.29 in all four.
    """
    return tuple(100.0 * s["synchronization"] for s in _slot_scores(media))
