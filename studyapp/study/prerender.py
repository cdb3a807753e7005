"""Pre-rendered trial videos: every trial a design can show, as one MP4 each, for participants without a GPU.

A trial video is what the desktop app shows for that trial, made by the same code: the trial's media from
:func:`~studyapp.study.stimuli.load_trial_media` (the one trial timeline), its scene from
:func:`~studyapp.render.scene.build_trial_scene` and its frames from the one frame loop through
:mod:`studyapp.render.video` (H.264 yuv420p + AAC in MP4, index at the front). Every figure is in the one
picture, side by side, and the audio is muxed in, so picture and sound are in sync by construction.

API (the browser server codes against these two):

* :func:`video_for` ``(design, plan, cache_dir) -> Path``: the video of one scheduled trial (a
  :class:`~studyapp.study.schedule.TrialPlan` with any number of slots and per-slot ``motion_stimuli``),
  rendered now if the cache does not have it yet.
* :func:`prerender` ``(design, cache_dir, progress=None, jobs=1) -> PrerenderReport``: every distinct trial
  (:func:`distinct_trials`) of every design row, rendered once; what is cached already is skipped.

The cache. A video's file name is :func:`trial_key` + ``.mp4``: a sha256 over everything that changes its
pixels or its sound -- the bytes of the audio, face, head, motion, template, body-model, live-model and avatar
files the trial reads; the design keys that change how they are shown (per slot: frozen or not, sample,
whose motion, fps, representation, rotation order, joints, degrees, name map, motion end; the stimulus's
``duration_s``, the slot labels, the framing, the avatar bone map, the paradigm); the app version and
:data:`FORMAT`; and the renderer settings (:class:`RenderSettings`: size, frame rate, encoder settings,
anti-aliasing, the shader sources and, for the built-in avatar, its geometry). Neither condition ids nor
labels nor stimulus ids enter a name, a path or the file's metadata (MP4 tags are empty, FFmpeg's own
version tag is left out), so nothing served reveals or groups a condition. The GPU model is not part of
the key: a cache made on one machine is served from another; videos rendered by a GPU and by llvmpipe
differ only by anti-aliasing at the figures' edges.

Resumable. Each video is written to a temporary file in the cache folder (``.part-<key>-<pid>-<random>``), synced to
disk, then renamed to its final name (atomic on one file system) and the folder synced: a final name always
holds a whole video. A prerender killed at any moment leaves at most some temporary files, which the next
run removes (those of processes no longer running) before it renders what is missing.

Speed. The trials of one stimulus that show the same figures in different slot orders (the 6 orders of a
3-condition trial under balanced slot assignment) are rendered together: each figure is drawn once per place
per frame and every order is composed from those drawings (:class:`~studyapp.render.video.OrderFrames`,
pixel for pixel what drawing each order gives), each order encoded on a thread of its own. ``jobs`` > 1
renders groups in that many processes.

>>> from studyapp.resources import demo_design
>>> from studyapp.study.design import load_design
>>> trials = distinct_trials(load_design(demo_design()))
>>> len(trials), len({trial_identity(p) for p in trials})
(30, 30)
"""
from __future__ import annotations

import hashlib
import itertools
import json
import os
import secrets
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

from studyapp import __version__
from studyapp.errors import InputError, StudyappError
from studyapp.study.design import FROZEN_PREFIX, Design, model_path, motion_path, resolve
from studyapp.study.design.files import _file_digest
from studyapp.study.schedule import TrialPlan, n_rows, participant_ids, participant_schedule

#: Bump when a change of the code (not of any input hashed) changes what a video holds.
FORMAT = 1
SUFFIX = ".mp4"
PART_PREFIX = ".part-"


@dataclass(frozen=True)
class RenderSettings:
    """How trial videos are rendered; every field is part of the cache key."""

    size: tuple[int, int] = (1280, 720)
    fps: int = 30

    def describe(self) -> dict:
        """What of the renderer and encoder decides the pixels, as JSON-able data (the key hashes it)."""
        from studyapp.render.encode import SETTINGS
        from studyapp.render.renderer import Renderer

        return {"size": list(self.size), "fps": int(self.fps),
                "encoder": [SETTINGS.codec, SETTINGS.crf, SETTINGS.preset, SETTINGS.pix_fmt],
                "renderer": _renderer_defaults(Renderer), "shaders": _shader_digest()}


def _renderer_defaults(renderer_cls) -> list:
    import inspect

    sig = inspect.signature(renderer_cls.__init__)
    return [sig.parameters["samples"].default, sig.parameters["software_aa"].default]


_SHADERS: str | None = None
_BUILTIN: str | None = None


def _shader_digest() -> str:
    global _SHADERS
    if _SHADERS is None:
        from studyapp.resources import shader_dir

        h = hashlib.sha256()
        for p in sorted(shader_dir().iterdir()):
            if p.is_file():
                h.update(p.name.encode() + b"\0" + p.read_bytes() + b"\0")
        _SHADERS = h.hexdigest()
    return _SHADERS


def _builtin_avatar_digest() -> str:
    """The built-in avatar is made by code, not read from a file: its geometry is what the key hashes."""
    global _BUILTIN
    if _BUILTIN is None:
        import numpy as np

        from studyapp.render.avatar import build_default_avatar

        av = build_default_avatar()
        h = hashlib.sha256()
        for name in ("vertices", "normals", "faces", "joints", "weights", "inverse_bind", "morph_deltas"):
            arr = getattr(av, name, None)
            if arr is not None:
                h.update(name.encode() + np.ascontiguousarray(arr).tobytes())
        _BUILTIN = h.hexdigest()
    return _BUILTIN


# -- which trials ---------------------------------------------------------------------------------------------

def _motion_stimuli(plan: TrialPlan) -> tuple[str, ...]:
    """Per slot, whose motion it plays (``plan.motion_stimuli``; empty means the trial's own stimulus)."""
    ms = tuple(getattr(plan, "motion_stimuli", ()) or ())
    return ms if ms else (plan.stimulus_id,) * len(plan.slots)


def trial_identity(plan: TrialPlan) -> tuple:
    """What a trial shows, whoever sees it and wherever it comes in their sequence: the stimulus, the paradigm,
    and per slot the condition (``frozen:`` included), the sample and whose motion."""
    return (plan.stimulus_id, getattr(plan, "paradigm", "rank"), tuple(plan.slots), tuple(plan.samples),
            _motion_stimuli(plan))


def distinct_trials(design: Design) -> list[TrialPlan]:
    """One plan per distinct trial (:func:`trial_identity`) that the schedule gives any of the design's
    ``n_rows`` rows, in order of first appearance. Under ``slot_assignment = "random"`` every slot order of
    each trial can occur, so all of them are listed."""
    seen: dict[tuple, TrialPlan] = {}
    rows = n_rows(design)
    for row, pid in enumerate(participant_ids(rows)):
        for plan in participant_schedule(design, pid, row=row):
            seen.setdefault(trial_identity(plan), plan)
    if design.slot_assignment == "random":
        for plan in list(seen.values()):
            for order in itertools.permutations(range(len(plan.slots))):
                other = _reordered(plan, order)
                seen.setdefault(trial_identity(other), other)
    return list(seen.values())


def _reordered(plan: TrialPlan, order: Sequence[int]) -> TrialPlan:
    fields = {"slots": tuple(plan.slots[k] for k in order), "samples": tuple(plan.samples[k] for k in order)}
    if getattr(plan, "motion_stimuli", ()):
        fields["motion_stimuli"] = tuple(plan.motion_stimuli[k] for k in order)
    return replace(plan, **fields)


# -- the cache key --------------------------------------------------------------------------------------------

def _digest(path: Path | None) -> str | None:
    return None if path is None else _file_digest(Path(path))


def _slot_inputs(design: Design, slot: str, sample: int, motion_stimulus: str) -> dict:
    cond = design.condition(slot.removeprefix(FROZEN_PREFIX))
    stim = design.stimulus(motion_stimulus)
    out: dict = {"frozen": slot.startswith(FROZEN_PREFIX), "sample": int(sample),
                 "fps": cond.fps, "representation": cond.representation, "rotation_order": cond.rotation_order,
                 "joints": list(cond.joints) if cond.joints else None, "degrees": cond.degrees,
                 "name_map": sorted(dict(cond.name_map).items()), "motion_end": cond.motion_end,
                 "template": _digest(resolve(design, cond.template)) if cond.template else None,
                 "body_model": _digest(resolve(design, cond.body_model)) if cond.body_model else None}
    if cond.model is not None:  # a live model's output depends on the model and on what it listens to
        out["model"] = _digest(model_path(design, cond))
        out["model_input"] = [_digest(stim.audio), _digest(stim.face), _digest(stim.head)]
    else:
        out["motion"] = _digest(motion_path(design, cond, stim, sample))
    return out


def trial_key(design: Design, plan: TrialPlan, settings: RenderSettings = RenderSettings()) -> str:
    """The cache key of a trial's video (see the module notes): 64 hex digits."""
    stim = design.stimulus(plan.stimulus_id)
    avatar = design.avatar_for(stim)
    inputs = {
        "format": FORMAT, "app": __version__, "render": settings.describe(),
        "paradigm": getattr(plan, "paradigm", "rank"),
        "audio": _digest(stim.audio), "face": _digest(stim.face), "head": _digest(stim.head),
        "duration_s": stim.duration_s, "labels": list(design.slot_labels) if design.slot_labels else None,
        "framing": design.display.framing, "bone_map": sorted(dict(design.avatar_bone_map).items()),
        "avatar": _builtin_avatar_digest() if avatar == "builtin" else _digest(Path(avatar)),
        "slots": [_slot_inputs(design, s, k, m) for s, k, m in zip(plan.slots, plan.samples, _motion_stimuli(plan))],
    }
    return hashlib.sha256(json.dumps(inputs, sort_keys=True, default=str).encode()).hexdigest()


def cached_path(design: Design, plan: TrialPlan, cache_dir: str | Path,
                settings: RenderSettings = RenderSettings()) -> Path:
    """Where the video of ``plan`` is (or will be) in ``cache_dir``."""
    return Path(cache_dir) / (trial_key(design, plan, settings) + SUFFIX)


# -- writing one file safely ------------------------------------------------------------------------------

def _part_path(final: Path) -> Path:
    """``.part-<key>-<pid>-<random>``: unique to this writer, so two threads or processes rendering the same
    video never write into one file (the last rename wins; both hold the same video)."""
    return final.with_name(f"{PART_PREFIX}{final.stem}-{os.getpid()}-{secrets.token_hex(4)}")


def _publish(part: Path, final: Path) -> None:
    """Make a finished temporary file the final one: synced, renamed atomically, folder synced."""
    with open(part, "rb") as f:
        os.fsync(f.fileno())
    os.replace(part, final)
    _sync_dir(final.parent)


def _sync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:  # a platform without directory handles (Windows): the rename is all there is
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def remove_stale_parts(cache_dir: str | Path) -> int:
    """Delete temporary files left by prerender processes that are no longer running; returns how many."""
    removed = 0
    for p in Path(cache_dir).glob(PART_PREFIX + "*"):
        try:
            pid = int(p.name.rsplit("-", 2)[1])
        except (IndexError, ValueError):
            continue
        if _alive(pid):  # still writing it (this process included: another thread may be)
            continue
        p.unlink(missing_ok=True)
        removed += 1
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _cache_folder(cache_dir: str | Path) -> Path:
    folder = Path(cache_dir)
    if folder.exists() and not folder.is_dir():
        raise InputError(folder, None, "the video cache must be a folder, not a file")
    folder.mkdir(parents=True, exist_ok=True)
    return folder


# -- rendering -------------------------------------------------------------------------------------------------

#: MP4 file-level tags: none (an empty title and comment, so no tool fills in a file name).
METADATA: dict[str, str] = {}


def video_for(design: Design, plan: TrialPlan, cache_dir: str | Path,
              settings: RenderSettings = RenderSettings()) -> Path:
    """The MP4 of one trial, rendered into ``cache_dir`` if it is not there yet (see the module notes)."""
    folder = _cache_folder(cache_dir)
    final = cached_path(design, plan, folder, settings)
    if final.is_file():
        return final
    with _GL_LOCK:  # one GL context per process: one thread draws at a time
        if not final.is_file():  # another thread may have rendered it meanwhile
            _render_group(design, [plan], [final], settings)
    return final


_GL_LOCK = threading.RLock()


def _render_group(design: Design, plans: Sequence[TrialPlan], finals: Sequence[Path],
                  settings: RenderSettings, renderer=None) -> None:
    """Render trials that show the same figures in different slot orders (:func:`group_trials`) together."""
    from studyapp.render.scene import build_trial_scene
    from studyapp.render.video import _shared_context, render_order_videos
    from studyapp.render.renderer import Renderer
    from studyapp.study.stimuli import load_trial_media

    base = plans[0]
    media = load_trial_media(design, base)
    if renderer is None:
        renderer = _renderer(_shared_context(), Renderer)
    scene = build_trial_scene(renderer, media)
    orders = [_order_of(base, p) for p in plans]
    parts = [_part_path(f) for f in finals]
    try:
        render_order_videos(scene, orders, media.audio, parts, size=settings.size, fps=settings.fps,
                            renderer=renderer, duration=media.duration_s, metadata=METADATA)
        for part, final in zip(parts, finals):
            _publish(part, final)
    finally:
        for part in parts:
            part.unlink(missing_ok=True)


_RENDERERS: dict[int, object] = {}


def _renderer(ctx, cls):
    """One renderer per context and process (its programs and buffers are reused by every video)."""
    if id(ctx) not in _RENDERERS:
        _RENDERERS[id(ctx)] = cls(ctx)
    return _RENDERERS[id(ctx)]


def _figures(plan: TrialPlan) -> list[tuple]:
    return list(zip(plan.slots, plan.samples, _motion_stimuli(plan)))


def _order_of(base: TrialPlan, plan: TrialPlan) -> tuple[int, ...]:
    """``order[p]``: the slot of ``base`` whose figure ``plan`` shows in slot ``p``."""
    free = list(enumerate(_figures(base)))
    order = []
    for fig in _figures(plan):
        k = next(i for i, (j, f) in enumerate(free) if f == fig)
        order.append(free.pop(k)[0])
    return tuple(order)


def group_trials(plans: Sequence[TrialPlan]) -> list[list[TrialPlan]]:
    """Trials of the same stimulus and paradigm showing the same figures (in any slot order), grouped."""
    groups: dict[tuple, list[TrialPlan]] = {}
    for p in plans:
        key = (p.stimulus_id, getattr(p, "paradigm", "rank"), tuple(sorted(_figures(p))))
        groups.setdefault(key, []).append(p)
    return list(groups.values())


# -- the whole design ------------------------------------------------------------------------------------------

@dataclass
class PrerenderReport:
    """What :func:`prerender` did. ``videos`` maps each distinct trial (:func:`trial_identity`) to its file."""

    total: int
    cached: int
    rendered: int
    video_seconds: float
    wall_s: float
    videos: dict[tuple, Path] = field(default_factory=dict)

    @property
    def realtime_factor(self) -> float:
        """Seconds of video rendered per second of wall time (0 when nothing was rendered)."""
        return self.video_seconds / self.wall_s if self.rendered and self.wall_s > 0 else 0.0


Progress = Callable[[int, int], None]


def prerender(design: Design, cache_dir: str | Path, progress: Progress | None = None, jobs: int = 1,
              settings: RenderSettings = RenderSettings()) -> PrerenderReport:
    """Render every distinct trial of ``design`` that ``cache_dir`` lacks (see the module notes).

    ``progress(done, total)`` is called once at the start (with what the cache already has) and after each
    video; ``jobs`` processes render groups of trials side by side (1: in this process).
    """
    if jobs < 1:
        raise StudyappError(f"--jobs must be at least 1, got {jobs}")
    t0 = time.perf_counter()
    folder = _cache_folder(cache_dir)
    remove_stale_parts(folder)
    plans = distinct_trials(design)
    finals = {trial_identity(p): cached_path(design, p, folder, settings) for p in plans}
    missing = [p for p in plans if not finals[trial_identity(p)].is_file()]
    total = len(plans)
    done = total - len(missing)
    if progress is not None:
        progress(done, total)
    seconds = 0.0
    groups = group_trials(missing)
    tasks = [(g, [finals[trial_identity(p)] for p in g]) for g in groups]
    for n, dur in _run(design, tasks, settings, jobs):
        done += n
        seconds += n * dur
        if progress is not None:
            progress(done, total)
    return PrerenderReport(total=total, cached=total - len(missing), rendered=len(missing), video_seconds=seconds,
                           wall_s=time.perf_counter() - t0, videos=finals)


def _run(design: Design, tasks: list, settings: RenderSettings, jobs: int):
    """Yield ``(videos, seconds each)`` per finished group, rendered here or in ``jobs`` processes."""
    if jobs == 1 or len(tasks) <= 1:
        for plans, finals in tasks:
            with _GL_LOCK:
                _render_group(design, plans, finals, settings)
            yield len(plans), _duration(design, plans[0])
        return
    import multiprocessing

    # spawn: a fresh interpreter per worker, each with its own GL context (a forked one would share this one's)
    with multiprocessing.get_context("spawn").Pool(jobs) as pool:
        for result in pool.imap_unordered(_group_task, [(design, p, f, settings) for p, f in tasks]):
            if result[0] is not None:
                pool.terminate()
                path, where, problem = result[0]
                raise InputError(path, where, problem) if problem is not None else StudyappError(path)
            yield result[1:]


def _group_task(args) -> tuple:
    """Render one group; ``(error, videos, seconds)``, the error as plain data (it crosses processes)."""
    design, plans, finals, settings = args
    try:
        _render_group(design, plans, finals, settings)
    except InputError as exc:
        return (exc.path, exc.where, exc.problem), 0, 0.0
    except StudyappError as exc:
        return (str(exc), None, None), 0, 0.0
    return None, len(plans), _duration(design, plans[0])


def _duration(design: Design, plan: TrialPlan) -> float:
    from studyapp.study.stimuli import load_trial_media

    return float(load_trial_media(design, plan).duration_s)
