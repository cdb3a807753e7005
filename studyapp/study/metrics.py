"""Objective metrics of a design's conditions, per condition and stimulus, from the motion as played.

For every stimulus of the rotation (the clips participants rank) and every sample of
every condition some trial plays on it (:func:`studyapp.study.design.played_pairs`: a design with
``[[blocks]]`` shows a condition only on its blocks' clips, and has motion files for those only), the trial
media are built exactly as a session builds them
(:func:`studyapp.study.stimuli.load_trial_media`: the condition's loader, its ``motion_end``, cut to the
trial's timeline) and turned into the scene the participant sees
(:func:`studyapp.render.scene.build_trial_scene`: retargeted onto the avatar with the condition's
``name_map``, resampled to the 60 fps playback rate, the face's head rotation added, the camera following the
hips). The metrics (:mod:`studyapp.motion.metrics`) run on that scene's world joint positions (metres), and
beat alignment on the audio onsets of the trial's audio (:mod:`studyapp.audio.onsets`).

One row per played condition x stimulus x sample, columns :data:`COLUMNS`. The conditions of one clip
are measured in scenes of at most :data:`studyapp.render.scene.MAX_SLOTS` figures (a design's blocks
together may play more on one clip than a trial shows); a figure's motion does not depend on the others.
With an encoder, ``fgd`` is each condition's Frechet Gesture Distance to the reference condition over all its windows of all stimuli (a
distribution-level number, repeated on each of the condition's rows; 0 for the reference itself).

>>> from studyapp.resources import demo_design
>>> from studyapp.study.design import load_design
>>> table = design_metrics(load_design(demo_design()))
>>> len(table), table["condition"].unique().tolist()
(12, ['synced', 'lagged', 'static'])
"""
from __future__ import annotations

from typing import Protocol

import numpy as np
import pandas as pd

from studyapp.audio.onsets import onset_times
from studyapp.errors import InputError
from studyapp.motion import metrics as mm
from studyapp.render.scene import MAX_SLOTS
from studyapp.study.design import Design, played_pairs
from studyapp.study.schedule import TrialPlan
from studyapp.study.stimuli import load_trial_media

#: Metric columns, in the order written; units in the names.
METRIC_COLUMNS = ("beat_align", "l1_diversity_m", "acceleration_m_s2", "jerk_m_s3", "frozen_share")
COLUMNS = ("condition", "stimulus", "sample", "duration_s", "fps", "n_motion_beats", "n_onsets") + METRIC_COLUMNS


class FeatureEncoder(Protocol):
    """What :func:`design_metrics` needs from an FGD encoder (:class:`studyapp.models.encoder.MotionEncoder`)."""

    def encode(self, pos: np.ndarray) -> np.ndarray: ...  # (F, J, 3) -> (windows, features)


def played_joints(design: Design, stimulus_id: str, condition_ids: tuple[str, ...],
                  samples: tuple[int, ...]) -> tuple[list[np.ndarray], float, np.ndarray, int, float]:
    """World joint positions ``(F, J, 3)`` of each condition as played for one stimulus, the playback rate,
    the trial's audio (mono samples), its sample rate and the trial's duration."""
    from studyapp.render.scene import build_trial_scene

    plan = TrialPlan(trial_index=-1, stimulus_id=stimulus_id, slots=condition_ids,  # type: ignore[arg-type]
                     is_practice=False, is_attention_check=False, row=0, samples=samples)
    media = load_trial_media(design, plan)
    scene = build_trial_scene(None, media, labels=None)
    fps = float(scene.slots[0].fps)
    joints = [np.asarray(s.joint_positions, np.float64) for s in scene.slots]
    return joints, fps, media.audio.samples.mean(axis=1), int(media.audio.sample_rate), float(media.duration_s)


def motion_metrics(pos: np.ndarray, fps: float, onsets: np.ndarray,
                   segment_s: float = mm.DIVERSITY_SEGMENT_S) -> dict[str, float | int]:
    """The metric columns of one motion (``(F, J, 3)`` at ``fps``) given its audio's onset times."""
    beats = mm.motion_beats(pos, fps)
    return {"n_motion_beats": int(beats.size), "n_onsets": int(np.asarray(onsets).size),
            "beat_align": mm.beat_align_score(beats, onsets),
            "l1_diversity_m": mm.l1_diversity(pos, max(1, int(round(segment_s * fps)))),
            "acceleration_m_s2": mm.mean_acceleration(pos, fps), "jerk_m_s3": mm.mean_jerk(pos, fps),
            "frozen_share": mm.frozen_share(pos, fps)}


def design_metrics(design: Design, *, encoder: FeatureEncoder | None = None, fgd_reference: str | None = None,
                   segment_s: float = mm.DIVERSITY_SEGMENT_S) -> pd.DataFrame:
    """The metrics table of a design (see the module notes); ``fgd_reference`` defaults to the first condition."""
    ids = design.condition_ids
    if fgd_reference is not None and fgd_reference not in ids:
        raise InputError(design.path, "--fgd-reference", f"{fgd_reference!r} is not a condition of the design "
                         f"({', '.join(ids)})")
    rows: list[dict] = []
    features: dict[str, list[np.ndarray]] = {c: [] for c in ids}
    n_samples = {c.id: max(1, c.samples) for c in design.conditions}
    played = played_pairs(design)
    for sid in design.rotation_stimuli:
        onsets = None
        for sample in range(1, max(n_samples.values()) + 1):
            conds = tuple(c for c in ids if n_samples[c] >= sample and sid in played[c])
            for part in (conds[i:i + MAX_SLOTS] for i in range(0, len(conds), MAX_SLOTS)):
                joints, fps, audio, sr, duration = played_joints(design, sid, part, (sample,) * len(part))
                if onsets is None:  # every sample plays the same audio
                    onsets = onset_times(audio, sr)
                for cid, pos in zip(part, joints):
                    rows.append({"condition": cid, "stimulus": sid, "sample": sample, "duration_s": duration,
                                 "fps": fps, **motion_metrics(pos, fps, onsets, segment_s)})
                    if encoder is not None:
                        features[cid].append(encoder.encode(pos))
    table = pd.DataFrame(rows, columns=list(COLUMNS))
    if encoder is not None:
        table["fgd"] = table["condition"].map(fgd_by_condition(features, fgd_reference or ids[0], design))
    return table


def fgd_by_condition(features: dict[str, list[np.ndarray]], reference: str, design: Design) -> dict[str, float]:
    """Frechet distance of each condition's pooled encoder features to the reference condition's."""
    pooled = {c: np.concatenate(f) if f else np.zeros((0, 0)) for c, f in features.items()}
    ref = pooled[reference]
    out = {}
    for cid, feats in pooled.items():
        if len(feats) < 2 or len(ref) < 2:
            raise InputError(design.path, "fgd", f"condition {cid if len(feats) < 2 else reference!r} gives fewer "
                             "than 2 encoder windows over all stimuli: its clips are shorter than the encoder's "
                             "window; FGD needs more motion")
        out[cid] = 0.0 if cid == reference else mm.frechet_distance(feats, ref)
    return out


__all__ = ["COLUMNS", "METRIC_COLUMNS", "FeatureEncoder", "design_metrics", "fgd_by_condition", "motion_metrics",
           "played_joints"]
