"""Pre-rendered trial videos (issue 19 item 2): the desktop's pixels and sound, blind names, a resumable cache.

One tiny study (1 s clips, practice, an attention check, conditions named like published models) is shared
by every test; videos are small (192x108) so the whole file runs in seconds on two cores.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import av
import numpy as np
import pytest

from fixtures.studies import _model_named_conditions, secrets_of  # noqa: F401 (a fixture)
from fixtures.synthetic import write_synthetic_study
from studyapp.study.design import load_design
from studyapp.study import prerender as pr

SIZE = (192, 108)
SETTINGS = pr.RenderSettings(size=SIZE, fps=30)
CLI = [sys.executable, "-m", "studyapp.cli"]


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    folder = tmp_path_factory.mktemp("prerender")
    path = _model_named_conditions(write_synthetic_study(folder / "study", n_stimuli=2, seconds=1.0,
                                                         attention_check=True))
    path.write_text(path.read_text().replace('condition = "static"', 'condition = "CaMN"'))
    return load_design(path)


@pytest.fixture(scope="module")
def cache(study, tmp_path_factory):
    """The whole design pre-rendered once (in this process)."""
    folder = tmp_path_factory.mktemp("cache")
    calls = []
    report = pr.prerender(study, folder, progress=lambda d, t: calls.append((d, t)), settings=SETTINGS)
    return folder, report, calls


def decoded(path: Path) -> tuple[list[np.ndarray], float, dict]:
    """RGB frames, audio seconds (decoded samples / rate) and stream facts of an MP4."""
    with av.open(str(path)) as f:
        v = f.streams.video[0]
        facts = {"codec": v.codec_context.name, "pix_fmt": v.codec_context.pix_fmt,
                 "audio": f.streams.audio[0].codec_context.name, "rate": f.streams.audio[0].rate}
        frames = [fr.to_ndarray(format="rgb24") for fr in f.decode(video=0)]
    with av.open(str(path)) as f:
        n = sum(fr.samples for fr in f.decode(audio=0))
    return frames, n / facts["rate"], facts


def desktop_frames(design, plan, times) -> list[np.ndarray]:
    """What the desktop app draws for this trial at these times (its scene builder and offscreen frames)."""
    from studyapp.render.scene import build_trial_scene
    from studyapp.render.video import render_frames
    from studyapp.study.stimuli import load_trial_media

    scene = build_trial_scene(None, load_trial_media(design, plan))
    return [f.copy() for f in render_frames(scene, times, SIZE)]


def test_prerender_covers_every_row_and_reports_progress(study, cache):
    folder, report, calls = cache
    plans = pr.distinct_trials(study)
    # every trial any row's participant gets is there, under its content hash
    for row in range(pr.n_rows(study)):
        for plan in pr.participant_schedule(study, f"X{row}", row=row):
            assert pr.cached_path(study, plan, folder, SETTINGS).is_file()
    assert report.total == report.rendered == len(plans) == len(list(folder.glob("*.mp4")))
    assert calls[0] == (0, len(plans)) and calls[-1] == (len(plans), len(plans))
    assert [d for d, _ in calls] == sorted(d for d, _ in calls)
    # a second run renders nothing
    again = pr.prerender(study, folder, settings=SETTINGS)
    assert (again.rendered, again.cached) == (0, len(plans))


def test_video_shows_the_desktop_frames_with_its_audio(study, cache):
    folder, _, _ = cache
    plan = next(p for p in pr.distinct_trials(study) if p.is_attention_check)  # a 'known-worst' check
    path = pr.video_for(study, plan, folder, SETTINGS)
    frames, audio_s, facts = decoded(path)
    assert facts == {"codec": "h264", "pix_fmt": "yuv420p", "audio": "aac", "rate": facts["rate"]}
    assert len(frames) == 30  # 1 s at 30 fps
    assert abs(audio_s - len(frames) / 30) <= 1 / 30
    raw = path.read_bytes()
    assert raw.index(b"moov") < raw.index(b"mdat"), "index not at the front (no faststart)"
    ks = [0, 11, 29]
    other = replace(plan, slots=plan.slots[::-1], samples=plan.samples[::-1])  # the same figures, swapped
    codec, swapped = [], []
    for k, want, wrong in zip(ks, desktop_frames(study, plan, [k / 30 for k in ks]),
                              desktop_frames(study, other, [k / 30 for k in ks])):
        got = frames[k].astype(np.float64)
        diff = np.abs(got - want)
        psnr = 10 * np.log10(255.0 ** 2 / max(np.mean(diff ** 2), 1e-9))
        assert diff.mean() < 2.0 and psnr > 32, (k, diff.mean(), psnr)
        codec.append(block_error(got, want))
        swapped.append(block_error(got, wrong))
    # the tolerance is tight enough to tell the trial from the same figures in another order
    assert max(codec) < 0.5 * max(swapped), (codec, swapped)


def block_error(a: np.ndarray, b: np.ndarray, n: int = 12) -> float:
    """The largest mean absolute difference over ``n`` x ``n`` pixel blocks (a misplaced figure shows up)."""
    h, w = (a.shape[0] // n) * n, (a.shape[1] // n) * n
    d = np.abs(a[:h, :w].astype(np.float64) - b[:h, :w]).mean(axis=2)
    return float(d.reshape(h // n, n, w // n, n).mean(axis=(1, 3)).max())


def test_slot_orders_composed_from_rotations_are_the_drawn_orders(study):
    """Each figure is drawn once per place and frame; every order composed from those drawings is, pixel for
    pixel, the scene the desktop builds for that order (camera and labels do not depend on slot order)."""
    from studyapp.render.scene import build_trial_scene
    from studyapp.render.video import order_frames, play_frames
    from studyapp.study.stimuli import load_trial_media

    group = max(pr.group_trials(pr.distinct_trials(study)), key=len)
    assert len(group) == 6
    base = build_trial_scene(None, load_trial_media(study, group[0]))
    orders = [pr._order_of(group[0], p) for p in group]
    assert len(set(orders)) == 6
    composed = list(order_frames(base, orders, 4, 4, SIZE, duration=base.duration))  # at 0, .25, .5, .75 s
    for j, plan in enumerate(group):
        own = build_trial_scene(None, load_trial_media(study, plan))
        drawn = list(play_frames(own, 4, 4, SIZE, duration=own.duration))
        for k in range(4):
            assert np.array_equal(composed[k][j], drawn[k]), (plan.slots, k)
    # and the orders really differ (the figures move differently)
    assert not np.array_equal(composed[3][0], composed[3][1])


def test_a_two_slot_trial_renders_two_figures(study, tmp_path):
    """Whatever slots a plan has, its video shows them (here two, unlabelled: the slot labels of a
    three-figure design do not fit two figures)."""
    path = tmp_path / "unlabelled.toml"
    path.write_text(study.path.read_text().replace('audio = "audio/', f'audio = "{study.path.parent}/audio/')
                    .replace('motion = "motion/', f'motion = "{study.path.parent}/motion/')
                    + '\n[slots]\nlabels = "none"\n')
    study = load_design(path)
    plan = pr.distinct_trials(study)[0]
    two = replace(plan, slots=plan.slots[:2], samples=plan.samples[:2])
    path = pr.video_for(study, two, tmp_path, SETTINGS)
    assert path != pr.cached_path(study, plan, tmp_path, SETTINGS)
    frames, audio_s, _ = decoded(path)
    (want,) = desktop_frames(study, two, [0.5])
    assert np.abs(frames[15].astype(float) - want).mean() < 2.0
    assert abs(audio_s - len(frames) / 30) <= 1 / 30


def test_nothing_in_names_or_bytes_reveals_a_condition(study, cache, secrets_of):
    folder, _, _ = cache
    secrets = secrets_of(study) + [c.label for c in study.conditions if c.label] + [s.id for s in study.stimuli]
    secrets += [study.title, "lagged", "synced", "static"]
    files = sorted(folder.iterdir())
    assert files and all(re.fullmatch(r"[0-9a-f]{64}\.mp4", p.name) for p in files)
    for p in files:
        raw = p.read_bytes()
        for s in secrets:  # shorter strings turn up by chance in compressed bytes (the tags are checked below)
            assert len(s) < 4 or s.encode() not in raw, (p.name, s)
        with av.open(str(p)) as f:
            tags = dict(f.metadata)
            for st in f.streams:
                tags.update({f"{st.type}.{k}": v for k, v in st.metadata.items()})
        assert not any(k in tags for k in ("title", "comment", "encoder")), tags
        for v in tags.values():
            assert not any(s.lower() in str(v).lower() for s in secrets), tags


def test_key_follows_the_bytes_that_change_the_picture(study, tmp_path):
    plans = pr.distinct_trials(study)
    keys = {pr.trial_identity(p): pr.trial_key(study, p, SETTINGS) for p in plans}
    assert len(set(keys.values())) == len(plans)
    again = load_design(study.path)
    assert keys == {pr.trial_identity(p): pr.trial_key(again, p, SETTINGS) for p in plans}
    assert pr.trial_key(study, plans[0], pr.RenderSettings(size=(1280, 720))) != keys[pr.trial_identity(plans[0])]
    # one motion file changes: exactly the trials that show it get new keys
    cond = study.conditions[0]
    motion = pr.motion_path(study, cond, study.stimulus("s1"))
    old = motion.read_bytes()
    try:
        motion.write_bytes(old.replace(b"Frame Time", b"Frame  Time", 1))
        os.utime(motion, ns=(time.time_ns(), time.time_ns() + 10**9))
        changed = {pr.trial_identity(p) for p in plans if pr.trial_key(study, p, SETTINGS) != keys[pr.trial_identity(p)]}
    finally:
        motion.write_bytes(old)
    uses = {pr.trial_identity(p) for p in plans if p.stimulus_id == "s1"
            and any(s.removeprefix("frozen:") == cond.id for s in p.slots)}
    assert changed == uses and uses


def test_killed_prerender_resumes_with_nothing_half_written(study, tmp_path):
    """A real `studyapp prerender` process is killed mid-way; every video it left is whole, the next run
    (two processes, progress bar on) renders only the rest and leaves the finished ones untouched."""
    cache_dir = tmp_path / "videos"
    env = dict(os.environ, PYTHONPATH=str(Path(pr.__file__).parents[2]) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = CLI + ["prerender", str(study.path), "--cache", str(cache_dir), "--size", "%dx%d" % SIZE]
    proc = subprocess.Popen(cmd + ["--quiet"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not list(cache_dir.glob("*.mp4")) and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    first = {p.name: p.stat() for p in cache_dir.glob("*.mp4")}
    total = len(pr.distinct_trials(study))
    assert 0 < len(first) < total, "kill the process after its first video and before its last"
    for name in first:
        frames, audio_s, _ = decoded(cache_dir / name)
        assert len(frames) == 30 and abs(audio_s - 1.0) <= 1 / 30
    out = subprocess.run(cmd + ["--jobs", "2"], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert f"{total - len(first)} rendered" in out.stdout and f"{len(first)} already there" in out.stdout
    assert re.search(rf"\[#+\] {total}/{total} videos", out.stderr), out.stderr
    assert len(list(cache_dir.glob("*.mp4"))) == total and not list(cache_dir.glob(".part-*"))
    for name, st in first.items():
        now = (cache_dir / name).stat()
        assert (now.st_ino, now.st_mtime_ns) == (st.st_ino, st.st_mtime_ns)
    for plan in pr.distinct_trials(study):
        assert pr.cached_path(study, plan, cache_dir, SETTINGS).is_file()


def test_only_parts_of_finished_processes_are_removed(tmp_path):
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    key = "0" * 64
    stale = tmp_path / f"{pr.PART_PREFIX}{key}-{int(dead.stdout)}-abcd1234"
    mine = tmp_path / f"{pr.PART_PREFIX}{key}-{os.getpid()}-abcd1234"
    video = tmp_path / f"{key}.mp4"
    for p in (stale, mine, video):
        p.write_bytes(b"x")
    assert pr.remove_stale_parts(tmp_path) == 1
    assert not stale.exists() and mine.exists() and video.exists()
