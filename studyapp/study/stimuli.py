"""Load what one trial shows: the clip's audio and face, and each slot's body motion.

:func:`load_trial_media` is called every time a trial starts and on every replay, so everything it reads
goes through a small in-process LRU cache keyed by file identity (path, size, modification time) and
loading options: a replay, or the attention-check repeat of a clip, costs a dictionary lookup. Validation
(:func:`check_stimulus_files`, run by :func:`~studyapp.study.design.load_design`) reads the same files the
same way, so it also warms the cache for the first trial. A session start whose design passed the full check
before (:mod:`studyapp.study.design.validated`: same design hash, same code) skips it and reads only each
trial's own files, when the trial loads.

Live conditions (``model = "x.onnx"``) run the model over the stimulus through
:func:`studyapp.models.live.motion_for_stimulus`, which keeps its own disk cache.

Example
-------
>>> from studyapp.resources import demo_design
>>> from studyapp.study.design import load_design
>>> from studyapp.study.schedule import participant_schedule
>>> design = load_design(demo_design())
>>> media = load_trial_media(design, participant_schedule(design, "P01", row=0)[1])
>>> len(media.motions), media.labels, round(media.duration_s)
(3, ('A', 'B', 'C'), 10)
"""
from __future__ import annotations

import csv
import math
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Hashable

import numpy as np

from studyapp.audio.wav import AudioClip
from studyapp.errors import InputError
from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_INDEX
from studyapp.motion.skeleton import Motion
from studyapp.study.design import (BUILTIN_REFERENCE, FROZEN_PREFIX, Condition, Design, Stimulus, model_path,
                                   motion_path, played_pairs, resolve)
from studyapp.study.design.parse import is_smpl_file, missing_array_settings
from studyapp.study.schedule import TrialPlan
from studyapp.study.timeline import (DURATION_TOLERANCE_S, MOTION_END_CHOICES, cut_audio, fit_face, fit_motion,
                                     medium_end, trial_duration)

#: Frame rate of the neutral face used for stimuli without face data.
NEUTRAL_FACE_FPS = 30.0


@dataclass
class TrialMedia:
    """Everything the viewer needs for one trial.

    Attributes
    ----------
    plan: the scheduled trial.
    audio: the clip's speech.
    face: ARKit blendshapes shared by every avatar (a neutral face when the stimulus has none).
    motions: body motion per slot, left to right (3 for rank, 2 pairwise/mismatch, every figure for rating);
    a slot plays the motion of ``plan.motion_stimulus(slot)`` (a mismatch trial's other clip).
    Audio, face and motions are already fitted to the trial's timeline (:mod:`studyapp.study.timeline`):
    cut to ``duration_s``, a short motion held or looped as its condition's ``motion_end`` says.
    avatar: ``"builtin"`` or the absolute path of a glTF/VRM avatar.
    labels: slot labels shown to the participant (``("A", "B", "C")``; ``("A", "B")`` for two slots) or None.
    duration_s: how long the trial plays (the stimulus's ``duration_s`` or its audio's length).
    criteria: the trial's block's criterion ids, in order (what the participant judges the slots on).
    name_maps: per slot, the condition's ``name_map`` (source joint -> humanoid bone) for retargeting.
    avatar_bone_map: the design's ``[avatar.bone_map]`` (avatar joint -> humanoid bone).
    framing: the design's ``[display] framing`` (``"upper-body"`` or ``"full-body"``).
    slot_faces: per slot, the face that slot shows instead of ``face``, or None: with no stimulus face file, a
    slot whose motion file is SMPL-X opens its jaw as that file's jaw does (:func:`slot_face`); empty when no
    slot has one.
    """

    plan: TrialPlan
    audio: AudioClip
    face: FaceAnimation
    motions: tuple[Motion, ...]
    avatar: str
    labels: tuple[str, ...] | None
    duration_s: float
    criteria: tuple[str, ...] = ()
    name_maps: tuple[dict[str, str], ...] = ({}, {}, {})
    avatar_bone_map: dict[str, str] | None = None
    framing: str = "upper-body"
    slot_faces: tuple[FaceAnimation | None, ...] = ()

    @property
    def avatar_spec(self) -> str:
        """Alias of ``avatar`` (the name the renderer uses)."""
        return self.avatar

    @property
    def slots(self) -> tuple[str, ...]:
        return self.plan.slots


# ---------------------------------------------------------------------------------------------------------
# A small thread-safe LRU cache (the UI may preload the next trial on a worker thread)


def _nbytes(value: Any) -> int:
    """Approximate memory held by a cached value (its numpy arrays)."""
    if isinstance(value, np.ndarray):
        return value.nbytes
    if isinstance(value, TrialMedia):
        return 0  # its parts are accounted for in the file cache
    arrays = [getattr(value, a, None) for a in ("rotations", "translations", "samples", "weights", "head_rotation")]
    return sum(a.nbytes for a in arrays if isinstance(a, np.ndarray))


class _LRU:
    """Least-recently-used cache bounded by entry count and by the bytes of the arrays it holds."""

    def __init__(self, size: int, max_bytes: int) -> None:
        self.size = size
        self.max_bytes = max_bytes
        self._data: OrderedDict[Hashable, tuple[Any, int]] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    def get(self, key: Hashable, make: Callable[[], Any]) -> Any:
        with self._lock:
            if key in self._data:
                self._data.move_to_end(key)
                self.hits += 1
                return self._data[key][0]
        value = make()  # outside the lock: loading may take a while and must not block other lookups
        weight = _nbytes(value)
        with self._lock:
            self.misses += 1
            if key in self._data:
                self._bytes -= self._data[key][1]
            self._data[key] = (value, weight)
            self._data.move_to_end(key)
            self._bytes += weight
            # Keep at least the newest entry, however large: the trial on screen needs it.
            while len(self._data) > 1 and (len(self._data) > self.size or self._bytes > self.max_bytes):
                _, (_, w) = self._data.popitem(last=False)
                self._bytes -= w
        return value

    def clear(self) -> None:
        with self._lock:
            self._data.clear()
            self._bytes = 0
            self.hits = self.misses = 0

    @property
    def n_bytes(self) -> int:
        return self._bytes

    def __len__(self) -> int:
        return len(self._data)


#: Decoded files (audio, faces, motions, templates, live model output). 48 entries cover a study of 8 clips x
#: 3 conditions with room to spare; the byte budget keeps studies of long 120 fps clips from filling memory.
_FILES = _LRU(48, 768 << 20)
#: Assembled TrialMedia: the current trial, its replays, a preloaded next one.
_MEDIA = _LRU(8, 1 << 62)


def clear_cache() -> None:
    """Forget every cached file and trial (tests; or after stimulus files changed on disk)."""
    _FILES.clear()
    _MEDIA.clear()


def cache_info() -> dict[str, int]:
    """Hits and misses of the file and trial caches since the last :func:`clear_cache`."""
    return {"file_hits": _FILES.hits, "file_misses": _FILES.misses, "file_bytes": _FILES.n_bytes,
            "files": len(_FILES), "media_hits": _MEDIA.hits, "media_misses": _MEDIA.misses}


def _file_id(path: Path) -> tuple[str, int, int]:
    st = Path(path).stat()
    return (str(path), st.st_size, st.st_mtime_ns)


# ---------------------------------------------------------------------------------------------------------
# Loaders (each cached by file identity)


def load_audio(path: Path) -> AudioClip:
    from studyapp.audio.wav import load_wav

    return _FILES.get(("audio", _file_id(path)), lambda: load_wav(path))


def load_stimulus_face(stimulus: Stimulus, n_frames_hint: float | None = None) -> FaceAnimation:
    """The stimulus's face animation, or a neutral face ``n_frames_hint`` seconds long when it has none."""
    if stimulus.face is None:
        seconds = n_frames_hint or 1.0
        return FaceAnimation.neutral(max(1, math.ceil(seconds * NEUTRAL_FACE_FPS)), NEUTRAL_FACE_FPS)
    from studyapp.face.io import load_face

    return _FILES.get(("face", _file_id(stimulus.face)), lambda: load_face(stimulus.face))


def load_head(path: Path) -> np.ndarray:
    """Head rotation ``(F, 3)`` yaw, pitch, roll in radians, at the face's frame rate.

    ``.npy``: an ``(F, 3)`` array. ``.csv``: a header row with ``yaw``, ``pitch``, ``roll`` columns (any case,
    optional ``head`` prefix, e.g. Live Link Face's ``HeadYaw``), other columns ignored.
    """
    def read() -> np.ndarray:
        if path.suffix.lower() == ".npy":
            from studyapp.safe_io import load_npy

            arr = load_npy(path)
            if arr.ndim != 2 or arr.shape[1] != 3 or arr.dtype.kind not in "biuf":
                raise InputError(path, "array shape", f"{arr.shape}, expected (frames, 3) yaw/pitch/roll radians")
            return arr.astype(np.float64)
        with open(path, newline="", encoding="utf-8-sig") as f:
            rows = list(csv.reader(f))
        if not rows:
            raise InputError(path, "line 1", "empty file; expected a header with yaw, pitch, roll")
        header = [h.strip().lower().removeprefix("head").lstrip("_") for h in rows[0]]
        try:
            cols = [header.index(n) for n in ("yaw", "pitch", "roll")]
        except ValueError:
            raise InputError(path, "line 1", f"header {rows[0]} lacks yaw, pitch and roll columns") from None
        out = np.empty((len(rows) - 1, 3))
        for i, row in enumerate(rows[1:]):
            try:
                out[i] = [float(row[c]) for c in cols]
            except (ValueError, IndexError):
                raise InputError(path, f"line {i + 2}", f"expected numbers in the yaw/pitch/roll columns: {row}") from None
        return out

    return _FILES.get(("head", _file_id(path)), read)


def _load_template(design: Design, condition: Condition) -> Motion | None:
    if condition.template is None:
        return None
    from studyapp.motion.io import load_motion

    path = resolve(design, condition.template)
    return _FILES.get(("template", _file_id(path)), lambda: load_motion(path))


def load_condition_motion(design: Design, condition: Condition, stimulus: Stimulus, sample: int = 1) -> Motion:
    """Body motion of one condition for one stimulus (file, or live model output); ``sample`` (1-based) picks
    one of the files of a condition with ``samples > 1``."""
    if condition.model is not None:
        return _live_motion(design, condition, stimulus)
    from studyapp.motion.io import load_motion

    path = motion_path(design, condition, stimulus, sample)
    template = _load_template(design, condition)
    kwargs: dict[str, Any] = {}
    if condition.rotation_order:
        kwargs["order"] = condition.rotation_order
    if condition.is_array:
        kwargs.update(joints=list(condition.joints) if condition.joints else None, degrees=condition.degrees)
    body_model = resolve(design, condition.body_model) if condition.body_model is not None else None
    key = ("motion", _file_id(path), condition.fps, condition.representation, condition.template,
           condition.rotation_order, condition.joints, condition.degrees, body_model)
    return _FILES.get(key, lambda: load_motion(path, fps=condition.fps, template=template,
                                               representation=condition.representation, body_model=body_model,
                                               **kwargs))


def _live_motion(design: Design, condition: Condition, stimulus: Stimulus) -> Motion:
    from studyapp.models.live import motion_for_stimulus

    model = model_path(design, condition)
    audio = load_audio(stimulus.audio)
    face = load_stimulus_face(stimulus) if stimulus.face is not None else None
    head = load_head(stimulus.head) if stimulus.head is not None else None
    template = _load_template(design, condition)
    key = ("live", _file_id(model), _file_id(stimulus.audio),
           None if stimulus.face is None else _file_id(stimulus.face),
           None if stimulus.head is None else _file_id(stimulus.head), condition.template)
    return _FILES.get(key, lambda: motion_for_stimulus(model, audio, face, head, template))


def _smplx_jaw_face(path: Path, fps: float | None) -> FaceAnimation | None:
    """``jawOpen`` from an SMPL-X file's jaw (:func:`studyapp.face.smplx.smplx_face`), or None for any other
    file and for a jaw that never opens. FLAME expressions need a map no design key gives, so they are left
    out here (``view`` and ``convert`` take ``--flame-map``)."""
    from studyapp.motion.smpl import read_smpl, recognise_smpl

    if path.suffix.lower() not in (".npz", ".npy") or recognise_smpl(path) != "smplx":
        return None
    from studyapp.face.smplx import smplx_face

    data = read_smpl(path, fps=fps)
    if data.jaw is None or not np.any(data.jaw):
        return None
    return smplx_face(data.jaw, data.fps, None, None, source=str(path))


def slot_face(design: Design, condition: Condition, stimulus: Stimulus, sample: int, shared: FaceAnimation,
              frozen: bool = False) -> FaceAnimation | None:
    """The face of one slot when its motion file is SMPL-X with a jaw that moves and the stimulus has no face
    file, else None (the slot shows the trial's shared face).

    An SMPL-X file's jaw is part of what its model generated, as the body is, so with no face of the
    stimulus's own that slot's ``jawOpen`` follows it, as in ``view`` (a frozen slot holds its first frame,
    as its body does). A stimulus face file is the one face every figure of the trial shows: a model's jaw
    in its place would make that figure's mouth the one that differs (BEAT2's fitted jaws open under 4
    degrees, so its figure would all but stop speaking beside lip-synced ones).
    """
    if condition.model is not None or stimulus.face is not None:
        return None
    path = motion_path(design, condition, stimulus, sample)
    jaw = _FILES.get(("smplx jaw", _file_id(path), condition.fps), lambda: _smplx_jaw_face(path, condition.fps))
    if jaw is None:
        return None
    times = np.arange(max(1, math.ceil(shared.duration * jaw.fps - 1e-9))) / jaw.fps
    weights = np.zeros((len(times), jaw.weights.shape[1]), np.float32)
    col = ARKIT_INDEX["jawopen"]
    weights[:, col] = jaw.weights[0, col] if frozen else jaw.sample(times)[:, col]
    return FaceAnimation(weights, jaw.fps, source=f"jaw of {path}")


def frozen_motion(motion: Motion, duration_s: float) -> Motion:
    """The first frame of ``motion`` held for ``duration_s`` (the frozen slot of an attention check)."""
    n = max(1, math.ceil(duration_s * motion.fps - 1e-9))
    rot = np.repeat(motion.rotations[:1], n, axis=0)
    trans = np.repeat(motion.translations[:1], n, axis=0)
    return Motion(motion.skeleton, motion.fps, rot, trans, source=f"frozen first frame of {motion.source}")


def slot_motion(design: Design, slot_condition: str, stimulus: Stimulus, duration_s: float, sample: int = 1) -> Motion:
    """Motion for one slot's condition id and sample (``frozen:<id>`` gives the frozen first frame of ``<id>``)."""
    if slot_condition.startswith(FROZEN_PREFIX):
        base = load_condition_motion(design, design.condition(slot_condition[len(FROZEN_PREFIX):]), stimulus, sample)
        return frozen_motion(base, duration_s)
    return load_condition_motion(design, design.condition(slot_condition), stimulus, sample)


def load_trial_media(design: Design, plan: TrialPlan) -> TrialMedia:
    """Audio, face and the three slot motions of one trial (cached: replays cost nothing)."""
    key = (design.design_hash, str(design.path), plan)
    return _MEDIA.get(key, lambda: _assemble(design, plan))


def _assemble(design: Design, plan: TrialPlan) -> TrialMedia:
    # Every medium is fitted to the one timeline here, so whoever plays the media plays the same trial.
    stimulus = design.stimulus(plan.stimulus_id)
    audio = load_audio(stimulus.audio)
    duration = trial_duration(stimulus.duration_s, audio.duration)
    face = fit_face(load_stimulus_face(stimulus, duration), duration)
    conds = [design.condition(cid.removeprefix(FROZEN_PREFIX)) for cid in plan.slots]
    # A slot plays the motion of its motion stimulus (a mismatch trial's other clip) on this trial's
    # timeline: cut, held or looped like any motion, under the trial's audio and face.
    motions = tuple(fit_motion(slot_motion(design, cid, design.stimulus(plan.motion_stimulus(i)), duration, k),
                               duration, cond.motion_end)
                    for i, (cid, cond, k) in enumerate(zip(plan.slots, conds, plan.samples)))
    maps = tuple(dict(cond.name_map) for cond in conds)
    # A mismatch trial shows the shared face in every slot: a jaw speaking another clip would give its figure away.
    own_clip = all(plan.motion_stimulus(i) == plan.stimulus_id for i in range(len(plan.slots)))
    faces = tuple(slot_face(design, cond, stimulus, k, face, frozen=cid.startswith(FROZEN_PREFIX)) if own_clip else None
                  for cid, cond, k in zip(plan.slots, conds, plan.samples))
    # a dry run's plan (validate) belongs to no block: it shows every criterion
    block = next((b for b in design.trial_blocks if b.id == plan.block), None)
    return TrialMedia(plan=plan, audio=cut_audio(audio, duration), face=face, motions=motions,  # type: ignore[arg-type]
                      avatar=design.avatar_for(stimulus), labels=design.slot_labels_for(len(plan.slots)),
                      duration_s=float(duration),
                      criteria=block.criteria if block is not None else tuple(design.criterion_ids), name_maps=maps,  # type: ignore[arg-type]
                      avatar_bone_map=dict(design.avatar_bone_map), framing=design.display.framing,
                      slot_faces=faces if any(f is not None for f in faces) else ())


# ---------------------------------------------------------------------------------------------------------
# Validation of the files a design references (called by design.validate_design)


def _problem_text(exc: Exception, *, with_path: bool = True) -> str:
    if isinstance(exc, InputError):
        if not with_path:  # the caller names the file itself
            return ", ".join(p for p in (exc.where, exc.problem) if p)
        return str(exc)  # names the file too: the design key alone does not say which of many files is bad
    return f"{type(exc).__name__}: {exc}"


def check_stimulus_files(design: Design) -> list[tuple[str, str, str]]:
    """Problems ``(key, message, fix)`` found by reading every file a design references.

    Reads each audio, face, head and motion file (motion: of each (condition, stimulus) pair some trial plays,
    :func:`~studyapp.study.design.played_pairs`), checks each stimulus's media against its trial's
    timeline (:mod:`studyapp.study.timeline`) and that each condition's skeleton has the humanoid bones,
    then does a dry run: per stimulus it assembles the media and builds the scene a participant gets
    (every condition's motion retargeted with its own ``name_map`` onto the stimulus's avatar, the face
    mapped, all cut to the timeline; live models run once per stimulus, cached on disk), on the CPU with no
    GL. Missing files are reported by the design loader and skipped here.
    """
    from studyapp.durations import duration_mismatches

    problems: list[tuple[str, str, str]] = []
    unreadable: dict[tuple[int, str], list[tuple[str, Path]]] = {}  # (condition, problem) -> clips
    wrong_rate: dict[int, tuple[float, float, list[str]]] = {}      # condition -> (file fps, true fps, clips)
    skeletons_checked: set[tuple[int, tuple[str, ...]]] = set()
    array_settings_missing: set[int] = set()  # conditions whose NPZ/NPY files are raw arrays lacking settings
    cond_index = {c.id: i for i, c in enumerate(design.conditions)}

    found, bad_avatars = _check_avatars(design)
    problems += found
    for ci, cond in enumerate(design.conditions):
        if cond.template is not None and resolve(design, cond.template).is_file():
            try:
                _load_template(design, cond)
            except (InputError, ValueError, OSError) as exc:
                problems.append((f"conditions[{ci}].template", f"cannot read the template: {_problem_text(exc)}",
                                 "give a readable BVH file"))
        if cond.model is not None:
            problems += _check_model(design, ci, cond)

    model_ok = {ci for ci, cond in enumerate(design.conditions)
                if cond.model is not None and model_path(design, cond).is_file()
                and not any(p[0].startswith(f"conditions[{ci}]") for p in problems)}
    played = played_pairs(design)  # a (condition, stimulus) no trial plays needs no file and is not checked
    retarget_bad: set[int] = set()
    built: set[tuple] = set()  # scenes the dry run built (see _scene_identity)
    dry_failures: dict[tuple[str, str], list[tuple[int, str, str]]] = {}  # (avatar, problem) -> (ci, stim, file)
    on_screen = {sid for clips in played.values() for sid in clips}  # a clip no trial shows builds no scene
    for si, stim in enumerate(design.stimuli):
        items: dict[str, tuple[float, str]] = {}
        n_before = len(problems)
        # conditions whose media for this stimulus were read without a problem
        ready: list[int] = [ci for ci in sorted(model_ok) if stim.id in played[design.conditions[ci].id]]
        if stim.audio.is_file():
            try:
                items["audio"] = (load_audio(stim.audio).duration, str(stim.audio))
            except (InputError, ValueError, OSError) as exc:
                problems.append((f"stimuli[{si}].audio", f"cannot read the audio: {_problem_text(exc)}",
                                 "give a PCM or float WAV file"))
        face_fps = None
        if stim.face is not None and stim.face.is_file():
            try:
                face = load_stimulus_face(stim)
                items["face"] = (face.duration, str(stim.face))
                face_fps = face.fps
            except (InputError, ValueError, OSError) as exc:
                problems.append((f"stimuli[{si}].face", f"cannot read the face animation: {_problem_text(exc)}",
                                 "give an ARKit CSV, Live Link Face CSV, BEAT JSON or NPY/NPZ file"))
        if stim.head is not None and stim.head.is_file():
            try:
                head = load_head(stim.head)
                if face_fps:  # head rows come at the face's frame rate, so only then do they have a length
                    items["head"] = (len(head) / face_fps, str(stim.head))
            except (InputError, ValueError, OSError) as exc:
                problems.append((f"stimuli[{si}].head", f"cannot read the head rotation: {_problem_text(exc)}",
                                 "give an (F, 3) NPY or a CSV with yaw, pitch, roll columns (radians)"))
        audio_s = items.get("audio", (None, ""))[0]
        for cond in design.conditions:
            ci = cond_index[cond.id]
            if cond.motion is None or stim.id not in played[cond.id]:
                continue  # live conditions are generated to the audio's length
            good_samples = 0
            for k in range(1, cond.samples + 1):  # every sample is a file a participant may be shown
                try:
                    path = motion_path(design, cond, stim, k)
                except KeyError:
                    break  # the pattern names a tag this stimulus lacks: reported with the pattern
                if not path.is_file():
                    continue
                if not _array_settings_complete(cond) and not is_smpl_file(path):
                    array_settings_missing.add(ci)  # reported once per condition below
                    break
                try:
                    motion = load_condition_motion(design, cond, stim, k)
                except (InputError, ValueError, OSError, KeyError) as exc:
                    clip = stim.id if cond.samples == 1 else f"{stim.id} sample {k}"
                    unreadable.setdefault((ci, _problem_text(exc, with_path=False)), []).append((clip, path))
                    continue
                rate = _likely_true_fps(cond, motion, audio_s, stim.duration_s)
                if rate is not None:
                    clips = wrong_rate.setdefault(ci, (motion.fps, rate, []))[2]
                    if stim.id not in clips:  # one name per clip, however many of its samples say so
                        clips.append(stim.id)
                    continue  # its length is explained; a "durations differ" line would point at the wrong fix
                items[_motion_label(cond, k)] = (motion.duration, str(path))
                sig = (ci, motion.skeleton.names)
                if sig not in skeletons_checked:
                    skeletons_checked.add(sig)
                    found = _check_retarget(ci, cond, motion, path)
                    if found:
                        retarget_bad.add(ci)
                    problems += found
                good_samples += 1
            if good_samples == cond.samples:
                ready.append(ci)
        problems += _check_durations(si, stim, items, duration_mismatches,
                                     {_motion_label(c, k): (i, c) for i, c in enumerate(design.conditions)
                                      for k in range(1, c.samples + 1)})
        avatar = design.avatar_for(stim)
        present = all(f is None or Path(f).is_file() for f in (stim.face, stim.head)) and (
            avatar in ("builtin", "") or Path(avatar).is_file()) and avatar not in bad_avatars
        # (missing files are the loader's to report, bad avatars _check_avatars's)
        if "audio" in items and present and len(problems) == n_before and stim.id in on_screen:
            # Only a stimulus whose files passed the checks above: a scene from bad files fails for reasons
            # already reported, with a less helpful message.
            good = [ci for ci in sorted(ready) if ci not in retarget_bad]
            # One scene per sample number: scene k shows sample k of every condition that has one.
            for k in range(1, max((design.conditions[ci].samples for ci in good), default=1) + 1):
                shown = [ci for ci in good if design.conditions[ci].samples >= k]
                # A clip reused under another id (a practice copy, tag patterns) gives the very same scene:
                # build it once, so no file's palettes are computed twice.
                scene_id = _scene_identity(design, stim, shown, k)
                if scene_id not in built:
                    built.add(scene_id)
                    for key, failure in _dry_run(design, stim, shown, k).items():
                        dry_failures.setdefault(key, []).extend(failure)
    for (avatar, text), where in dry_failures.items():
        problems.append(_dry_run_problem(design, avatar, text, where))
    if not problems:  # the combinations only mismatch trials make, once every file reads
        problems += _check_mismatched(design)
    for ci in sorted(array_settings_missing):
        c = design.conditions[ci]
        problems += missing_array_settings(f"conditions[{ci}]", c.template, c.representation, c.fps)
    # One line per condition and cause, not one per clip: a setting of the condition is usually the cause.
    for (ci, text), where in unreadable.items():
        cond = design.conditions[ci]
        clips = ", ".join(sid for sid, _ in where)
        if cond.samples > 1:  # entries are "<stimulus> sample <k>"
            what = f"stimulus {where[0][0]}" if len(where) == 1 else f"{len(where)} files ({clips})"
        else:
            what = f"stimulus {where[0][0]!r}" if len(where) == 1 else f"{len(where)} stimuli ({clips})"
        problems.append((f"conditions[{ci}].motion", f"cannot read the motion of {cond.id!r} for {what}, e.g. "
                         f"{where[0][1]}: {text}", _unreadable_fix(cond)))
    for ci, (file_fps, rate, clips) in wrong_rate.items():
        cond = design.conditions[ci]
        ratio = file_fps / rate
        how = f"{ratio:.3g} times shorter" if ratio > 1 else f"{1 / ratio:.3g} times longer"
        problems.append((f"conditions[{ci}].fps", f"the motion of {cond.id!r} is {how} than the audio at the "
                         f"{file_fps:.3g} fps its files state, and as long as the audio at {rate:g} fps "
                         f"({', '.join(clips)}): the files' frame rate (BVH Frame Time) is probably wrong",
                         f"add fps = {rate:g} to this condition (it overrides the files' frame rate)"))
    return problems


def _check_mismatched(design: Design) -> list[tuple[str, str, str]]:
    """Each mismatch block's motions played under another clip's speech: a motion shorter than the trial it
    is mismatched into needs its condition's ``motion_end`` (one problem per condition, naming the pairs)."""
    from studyapp.study.schedule import mismatch_sources

    short: dict[int, list[str]] = {}
    seconds: dict[tuple[str, str, int], float] = {}  # each motion's length, read once however often mismatched

    def length(cond: Condition, source: str, k: int) -> float:
        if (cond.id, source, k) not in seconds:
            seconds[cond.id, source, k] = load_condition_motion(design, cond, design.stimulus(source), k).duration
        return seconds[cond.id, source, k]

    for n, block in enumerate(design.trial_blocks):
        if block.paradigm != "mismatch":
            continue
        clips = list(block.stimuli) + ([p for p in design.practice if p not in block.stimuli] if n == 0 else [])
        for sid in clips:
            stim = design.stimulus(sid)
            trial_s = trial_duration(stim.duration_s, load_audio(stim.audio).duration)
            for source in mismatch_sources(design, block, sid):
                for cid in block.conditions:
                    ci = design.condition_ids.index(cid)
                    cond = design.conditions[ci]
                    if cond.motion_end is not None:
                        continue  # held or looped: never too short
                    for k in range(1, cond.samples + 1):
                        if medium_end(length(cond, source, k), trial_s, cond.motion_end) == "short":
                            short.setdefault(ci, []).append(f"{source} ({length(cond, source, k):.2f} s) under "
                                                            f"{sid} ({trial_s:.2f} s)")
    return [(f"conditions[{ci}].motion_end", f"condition {design.conditions[ci].id!r} is mismatched with clips "
             f"longer than its motion: {', '.join(pairs[:3])}{' ...' if len(pairs) > 3 else ''}; it would freeze",
             'set motion_end = "hold" or "loop" on the condition (mismatched motion is cut, held or looped to '
             "the trial), or give the block clips of similar length")
            for ci, pairs in short.items()]


def _motion_label(cond: Condition, sample: int) -> str:
    """A condition's motion among a stimulus's media in the duration checks (one per sample)."""
    return f"motion:{cond.id}" + (f":{sample}" if sample > 1 else "")


def _scene_identity(design: Design, stim: Stimulus, conds: list[int], sample: int = 1) -> tuple:
    """What a stimulus's dry-run scene depends on: its files, their reading settings, avatar and length."""
    def fid(path: Path | None):
        return None if path is None else _file_id(path)

    motions = []
    for ci in conds:
        c = design.conditions[ci]
        src = fid(model_path(design, c)) if c.model is not None else fid(motion_path(design, c, stim, sample))
        motions.append((src, c.fps, c.representation, c.template, c.rotation_order, c.joints, c.degrees,
                        tuple(sorted(c.name_map.items())), c.motion_end, c.body_model))
    # Sorted: the same motions in other slots check nothing new, and a bundle's design shows each clip's
    # models in a new order per trial (studyapp.study.shipped), which would otherwise rebuild every order.
    return (tuple(sorted(motions, key=repr)), fid(stim.audio), fid(stim.face), fid(stim.head), design.avatar_for(stim),
            stim.duration_s)


def _dry_run(design: Design, stim: Stimulus, conds: list[int],
             sample: int = 1) -> dict[tuple[str, str], list[tuple[int, str, str]]]:
    """Build the scene of ``stim`` with conditions ``conds`` (showing their ``sample``) in its slots exactly as a
    trial does (the same
    :func:`_assemble` and :func:`~studyapp.render.scene.build_trial_scene`, no GL); failures by
    ``(avatar, problem)`` -> ``[(condition index, stimulus id, file)]``.

    One scene holds up to three slots, so a design's three conditions cost one scene per stimulus: each
    motion file is retargeted, and its palettes computed, once.
    """
    from studyapp.render.scene import SlotError, build_trial_scene, slot_avatars

    avatar = design.avatar_for(stim)
    out: dict[tuple[str, str], list[tuple[int, str, str]]] = {}
    try:
        slot_avatars(avatar, 1, design.avatar_bone_map)
    except (InputError, OSError) as exc:
        # The avatar itself: every condition fails the same way, one line says it (for every stimulus using it).
        return {(avatar, f"cannot load the avatar: {_problem_text(exc, with_path=False)}"):
                [(ci, stim.id, avatar) for ci in conds]}
    for start in range(0, len(conds), 3):  # designs have 3 conditions; more are checked three at a time
        chunk = conds[start:start + 3]
        if not chunk:
            continue
        ids = tuple(design.conditions[ci].id for ci in chunk)
        plan = TrialPlan(trial_index=-1, stimulus_id=stim.id, slots=ids,  # type: ignore[arg-type]
                         is_practice=False, is_attention_check=False, row=0, samples=(sample,) * len(ids))
        while chunk:
            try:
                media = _assemble(design, plan)
                labels = media.labels[:len(chunk)] if media.labels else None  # fewer slots when a check failed
                build_trial_scene(None, media, labels=labels)
                break
            except SlotError as exc:
                ci = chunk[exc.slot]
                out.setdefault((avatar, ", ".join(p for p in (exc.where, exc.problem) if p)), []).append(
                    (ci, stim.id, str(exc.path or "")))
            except (InputError, ValueError, OSError, KeyError, ArithmeticError) as exc:
                # not one slot's fault (the face, the audio): every condition of this stimulus shares it
                out.setdefault((avatar, _problem_text(exc)), []).extend((ci, stim.id, str(stim.audio)) for ci in chunk)
                break
            # slots left of the refused one were built; those right of it still need their check
            chunk = chunk[chunk.index(ci) + 1:]
            plan = TrialPlan(trial_index=-1, stimulus_id=stim.id,  # type: ignore[arg-type]
                             slots=tuple(design.conditions[c].id for c in chunk), is_practice=False,
                             is_attention_check=False, row=0, samples=(sample,) * len(chunk))
    return out


def _dry_run_problem(design: Design, avatar: str, text: str, where: list[tuple[int, str, str]]) -> tuple[str, str, str]:
    """One problem line for one cause found by the dry run, naming the first condition, stimulus and file."""
    ci, sid, path = where[0]
    name = "the built-in avatar" if avatar in ("builtin", "") else f"the avatar {avatar}"
    more = f" (and {len(where) - 1} more condition x stimulus pairs)" if len(where) > 1 else ""
    if text.startswith("cannot load the avatar"):
        key = "avatar"
        stims = sorted({s for _, s, _ in where})
        msg = f"{name}, used by stimulus {', '.join(map(repr, stims))}: {text}"
        fix = "fix or re-export the avatar file, or use the built-in one (avatar.model = \"builtin\")"
    else:
        key = f"conditions[{ci}]"
        msg = (f"condition {design.conditions[ci].id!r}, stimulus {sid!r}: the motion {path} cannot be shown on "
               f"{name}{more}: {text}")
        if "avatar" in text or "target skeleton" in text:  # the avatar lacks humanoid bones, not the motion
            fix = ("give a humanoid avatar (bones named like Hips, Spine, Head, LeftUpperArm, ..., or a VRM), or "
                   "map its bones as the message says")
        else:
            fix = "add a [conditions.name_map] for this condition's joints, or re-export the motion"
    return key, msg, fix


#: Frame rates gesture pipelines write; a motion whose length matches the audio at one of these is mislabelled.
COMMON_FPS = (15.0, 20.0, 24.0, 25.0, 30.0, 50.0, 60.0, 100.0, 120.0)


def _likely_true_fps(cond: Condition, motion: Motion, audio_s: float | None,
                     duration_s: float | None = None) -> float | None:
    """The common frame rate at which ``motion`` lasts as long as the audio, when the rate it was read at
    does not (DiffSHEG writes ``Frame Time: 0.008333`` over 15 fps data); ``None`` otherwise.

    With a ``duration_s`` the motion only has to cover the trial: one that does (a longer motion is cut)
    has no frame-rate problem, whatever the audio's length, and a suggested rate must both cover the trial
    and match the audio.

    >>> from studyapp.motion.skeleton import Motion, Skeleton
    >>> sk = Skeleton(["Hips"], np.array([-1]), np.zeros((1, 3)))
    >>> m = Motion.rest(sk, n_frames=300, fps=30.0)            # a true 30 fps, 10 s file
    >>> _likely_true_fps(Condition("c", motion="{stimulus}.bvh"), m, 4.9)       # 4.9 s of audio, no duration_s
    60.0
    >>> _likely_true_fps(Condition("c", motion="{stimulus}.bvh"), m, 4.9, 4.0)  # the trial plays 4 s of it
    """
    if cond.fps is not None or not audio_s or motion.n_frames < 2:
        return None
    if abs(motion.duration - audio_s) <= DURATION_TOLERANCE_S:
        return None
    if duration_s is not None and motion.duration >= duration_s - DURATION_TOLERANCE_S:
        return None
    for rate in COMMON_FPS:
        # Only whole multiples of the stated rate (a header copied from a 120 fps data set over 15 fps
        # output): a clip a little short at 30 fps is a short clip, not one at 24 or 50 fps.
        ratio = max(rate, motion.fps) / min(rate, motion.fps)
        whole = round(ratio) >= 2 and abs(ratio - round(ratio)) < 0.01
        if whole and abs(motion.n_frames / rate - audio_s) <= DURATION_TOLERANCE_S:
            return rate
    return None


def _array_settings_complete(cond: Condition) -> bool:
    return not cond.is_array or None not in (cond.template, cond.representation, cond.fps)


def _unreadable_fix(cond: Condition) -> str:
    if cond.is_array:
        return ("check this condition's template, representation, joints and fps against how the model wrote "
                "its arrays (`studyapp inspect FILE` shows their shape), or, for SMPL-family files, its "
                "body_model; or re-export the files")
    return "fix or re-export the file (`studyapp inspect FILE` shows what is read)"


def _check_durations(si: int, stim: Stimulus, items: dict[str, tuple[float, str]], mismatches,
                     conditions: dict[str, tuple[int, Condition]] | None = None) -> list:
    """Each medium against the trial's timeline. A motion too short for it is its condition's problem unless
    the condition has a ``motion_end``; other media too short are the stimulus's. Without ``duration_s``
    the media must also not outlast the audio (they would be cut, but it usually means a wrong file or rate)."""
    key = f"stimuli[{si}]"
    conditions = conditions or {}
    if stim.duration_s is None and "audio" not in items:
        return []  # no timeline to compare with (the audio's problem is reported)
    trial_s = trial_duration(stim.duration_s, items["audio"][0] if "audio" in items else 0.0)
    where = "duration_s" if stim.duration_s is not None else "audio"
    out, rest = [], {}
    for label, (d, path) in items.items():
        ci, cond = conditions.get(label, (-1, None))
        if cond is None:
            rest[label] = (d, path)
            continue
        end = medium_end(d, trial_s, cond.motion_end)
        if end == "short":
            out.append((f"conditions[{ci}]", f"condition {cond.id!r}, stimulus {stim.id!r}: the motion {path} "
                        f"lasts {d:.3f} s but the trial plays {trial_s:.3f} s (its {where}); it would freeze for "
                        "the rest of the trial",
                        f'set motion_end = "hold" or "loop" on condition {cond.id!r}, '
                        f"{'lower' if stim.duration_s is not None else 'set'} duration_s (stimulus {stim.id!r}) "
                        f"to at most {d:.3f}, or give a motion at least {trial_s:.3f} s long"))
        elif not (end in MOTION_END_CHOICES and d < trial_s - DURATION_TOLERANCE_S):
            rest[label] = (d, path)  # a short motion its condition holds or loops is the timeline's business
    if stim.duration_s is None:  # longer media are cut to the audio, but usually mean a wrong file or rate
        return out + [(key, f"stimulus {stim.id!r}: {m}",
                       "re-export the files to the same length, or set duration_s to play only the common part")
                      for m in mismatches(rest, DURATION_TOLERANCE_S)]
    return out + [(f"{key}.duration_s", f"stimulus {stim.id!r} plays {stim.duration_s:.3f} s but {k} is only "
                   f"{d:.3f} s long ({p})", "lower duration_s or give longer files")
                  for k, (d, p) in rest.items() if d < stim.duration_s - DURATION_TOLERANCE_S]


def _check_avatars(design: Design) -> tuple[list[tuple[str, str, str]], set[str]]:
    """Each avatar file loads, is humanoid with the design's ``[avatar.bone_map]``, and every entry of that
    map names one of its joints (one problem per bad entry). Also returns the avatars with a problem (the dry
    run skips them: a scene on them fails for the reason already given)."""
    from studyapp.render.avatar_rig import avatar_problems

    out, bad = [], set()
    keys = [("avatar.model", design.avatar)]
    keys += [(f"avatar.by_speaker.{k}", v) for k, v in design.avatar_by_speaker.items()]
    for key, name in keys:
        path = resolve(design, name) if name != "builtin" else None
        if path is not None and path.is_file():
            try:
                found = [(k or key, msg, fix) for k, msg, fix in avatar_problems(path, design.avatar_bone_map)]
            except (ValueError, ArithmeticError, KeyError, IndexError) as exc:
                # numbers no skinning can use (a singular inverse bind matrix is a LinAlgError, a ValueError)
                found = [(key, f"cannot load the avatar {path}: {type(exc).__name__}: {exc}",
                          "export the avatar again from the modelling tool, or use the built-in one")]
            out += found
            if found:
                bad.add(str(path))
    return out, bad


def _check_retarget(ci: int, cond: Condition, motion: Motion, path: Path) -> list[tuple[str, str, str]]:
    """Can this skeleton be mapped onto the humanoid bones the avatars need (built-in maps + name_map)?"""
    from studyapp.motion.humanoid import REQUIRED_BONES
    from studyapp.motion.retarget import merge_name_map

    out = []
    good: dict[str, str] = {}
    for src, bone in cond.name_map.items():  # one problem per bad entry, not just the first
        try:
            merge_name_map(motion.skeleton, {src: bone})
            good[src] = bone
        except InputError as exc:
            out.append((f"conditions[{ci}].name_map.{src}", f"{exc.problem} (in {path.name})",
                        "use joint names from the motion file (studyapp inspect lists them) and Unity humanoid "
                        "bone names (Hips, Spine, Chest, UpperChest, Neck, Head, LeftUpperArm, ...)"))
    mapping = merge_name_map(motion.skeleton, good)
    missing = [b for b in REQUIRED_BONES if b not in set(mapping.values())]
    if missing:
        out.append((f"conditions[{ci}]", f"the skeleton of {path.name} ({motion.skeleton.n_joints} joints) cannot "
                    f"be retargeted: no joint maps to the required bones {', '.join(missing)}",
                    "add a [conditions.name_map] table: source joint name = humanoid bone name"))
    return out


def _check_model(design: Design, ci: int, cond: Condition) -> list[tuple[str, str, str]]:
    path = model_path(design, cond)
    if not path.is_file():
        if cond.model == BUILTIN_REFERENCE:
            return [(f"conditions[{ci}].model", f"the shipped reference model is missing: {path}",
                     "reinstall studyapp")]
        return []  # reported as a missing file by the design loader
    try:
        import onnxruntime as ort

        from studyapp.models.contract import read_spec

        session = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        read_spec(session, path)
    except ModuleNotFoundError:  # no "models" extra: the command says what to install, not "cannot load"
        raise
    except InputError as exc:
        return [(f"conditions[{ci}].model", f"the model does not follow the studyapp model contract: "
                 f"{_problem_text(exc)}", "see studyapp/models/CONTRACT.md")]
    except Exception as exc:  # onnxruntime raises its own exception types for unreadable graphs
        return [(f"conditions[{ci}].model", f"cannot load the ONNX model: {exc}"[:300],
                 "export the model again (ONNX opset supported by onnxruntime)")]
    return []
