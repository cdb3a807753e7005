"""Bundles are confined to themselves, and every zip a participant or experimenter opens has limits.

A bundle's manifest must list exactly the files in its zip; its ``design`` entry and every file its study.toml
names (audio, face, head, motion patterns, templates, models, avatars) must be one of those files. Each is
checked before anything is extracted or followed: the tests run ``studyapp run`` in a child process with an
audit hook on ``open`` and point the design at a FIFO outside the bundle, which blocks whoever opens it.
"""
from __future__ import annotations

import hashlib
import json
import os
import time
import zipfile
from pathlib import Path
from typing import Any, Callable

import pytest

from fixtures.synthetic import write_synthetic_study
from fixtures.zips import Member, capped_cli, write_zip, zeros_crc, zeros_stream
from studyapp import tomlfile
from studyapp.errors import InputError
from studyapp.resources import demo_design
from studyapp.study.bundle import bundle_design_paths, make_bundle, open_bundle
from studyapp.study.design import referenced_files, resolve
from studyapp.study.design.parse import parse_design


@pytest.fixture(scope="module")
def bundled(tmp_path_factory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("confined")
    design_path = write_synthetic_study(root / "study", n_stimuli=2, seconds=0.3)
    return design_path, make_bundle(design_path, root / "study.zip", participants=1).path


def rebundle(src: Path, dst: Path, *, design: Callable[[dict[str, Any]], None] | None = None,
             manifest: Callable[[dict[str, Any]], None] | None = None, extra: dict[str, bytes] | None = None) -> Path:
    """``src`` with its study.toml and manifest edited as an attacker would (checksums recomputed)."""
    with zipfile.ZipFile(src) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    man = json.loads(members.pop("manifest.json"))
    if design is not None:
        raw = tomlfile.loads(members["study.toml"].decode())
        design(raw)
        members["study.toml"] = tomlfile.dumps(raw).encode()
        man["files"]["study.toml"] = hashlib.sha256(members["study.toml"]).hexdigest()
    if manifest is not None:
        manifest(man)
    with zipfile.ZipFile(dst, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("manifest.json", json.dumps(man))
        for n, data in {**members, **(extra or {})}.items():
            zf.writestr(n, data)
    return dst


_AUDIT = """
import atexit, os, sys
_opened = []
def _hook(event, args):
    if event == "open" and isinstance(args[0], (str, bytes)):
        _opened.append(os.fsdecode(args[0]))
sys.addaudithook(_hook)
atexit.register(lambda: open(os.environ["OPEN_LOG"], "w").write("\\n".join(_opened)))
"""


def _participant_env(tmp_path: Path) -> dict[str, str]:
    return {"HOME": str(tmp_path / "home"), "XDG_CACHE_HOME": str(tmp_path / "cache"),
            "XDG_DATA_HOME": str(tmp_path / "data"), "STUDYAPP_RESULTS_DIR": str(tmp_path / "outbox"),
            "OPEN_LOG": str(tmp_path / "opened.txt")}


def _set_audio(value: str) -> Callable[[dict[str, Any]], None]:
    return lambda raw: raw["stimuli"][0].__setitem__("audio", value)


def _set_motion(value: str) -> Callable[[dict[str, Any]], None]:
    return lambda raw: raw["conditions"][1].__setitem__("motion", value)


def _set_avatar(value: str) -> Callable[[dict[str, Any]], None]:
    return lambda raw: raw.__setitem__("avatar", {"model": value})


@pytest.mark.parametrize("edit, key", [
    (lambda fifo: _set_audio(str(fifo)), "stimuli[0].audio"),                          # absolute
    (lambda fifo: _set_audio(str(fifo.with_name("real.wav"))), "stimuli[0].audio"),     # a real WAV there
    (lambda fifo: _set_audio(os.path.relpath(fifo, fifo.parents[3])), "stimuli[0].audio"),  # ../../ from a cache
    (lambda fifo: _set_audio("media/../../../outside/secret.wav"), "stimuli[0].audio"),
    (lambda fifo: _set_audio("..\\..\\outside\\secret.wav"), "stimuli[0].audio"),       # backslashes
    (lambda fifo: _set_audio("C:/outside/secret.wav"), "stimuli[0].audio"),             # a drive letter
    (lambda fifo: _set_audio("~/secret.wav"), "stimuli[0].audio"),                      # the participant's home
    (lambda fifo: _set_motion(str(fifo.parent / "{stimulus}.bvh")), "conditions[1].motion"),
    (lambda fifo: _set_avatar(str(fifo.with_suffix(".glb"))), "avatar.model"),
])
def test_a_bundle_whose_design_points_outside_is_refused_before_anything_is_read(
        bundled, tmp_path: Path, edit, key: str) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    fifo = outside / "secret.wav"
    os.mkfifo(fifo)                       # whoever opens it for reading waits forever
    os.mkfifo(fifo.with_suffix(".glb"))
    for sid in ("s1", "s2"):
        os.mkfifo(outside / f"{sid}.bvh")
    with zipfile.ZipFile(bundled[1]) as zf:          # a WAV that would play, were it opened
        (outside / "real.wav").write_bytes(zf.read(next(n for n in zf.namelist() if n.endswith(".wav"))))
    (tmp_path / "home").mkdir()
    os.symlink(fifo, tmp_path / "home" / "secret.wav")
    bad = rebundle(bundled[1], tmp_path / "study.zip", design=edit(fifo))
    t0 = time.monotonic()
    run = capped_cli(["run", str(bad), "--participant", "R01", "--no-render", "--bot", "random"],
                     env=_participant_env(tmp_path), preamble=_AUDIT, timeout=120)
    assert run.rc == 2 and "Traceback" not in run.err, run.err
    line, = [ln for ln in run.err.splitlines() if ln.strip()]
    assert f"study.toml, {key}" in line and ("outside the bundle" in line or "not a file of the bundle" in line), line
    opened = (tmp_path / "opened.txt").read_text().splitlines()
    assert str(bad) in opened        # the hook saw the bundle itself being read
    assert not [p for p in opened if str(outside) in p or "/outside/" in p or "secret." in p], opened
    # nothing was extracted either: the check comes before the cache is written
    assert not (tmp_path / "cache" / "studyapp" / "bundles").exists() or not any(
        (tmp_path / "cache" / "studyapp" / "bundles").iterdir())
    assert time.monotonic() - t0 < 60


def test_the_manifest_must_cover_every_file_and_name_its_design(bundled, tmp_path: Path) -> None:
    src = bundled[1]
    cache = tmp_path / "cache"
    cases = {
        "extra": (rebundle(src, tmp_path / "extra.zip", extra={"media/m_extra.wav": b"RIFF"}),
                  "media/m_extra.wav", "not in its manifest"),
        "unlisted": (rebundle(src, tmp_path / "unlisted.zip", design=_set_audio("media/m_nothere.wav")),
                     "study.toml, stimuli[0].audio", "not a file of the bundle's manifest"),
        "design-out": (rebundle(src, tmp_path / "d1.zip", manifest=lambda m: m.__setitem__("design", "../x.toml")),
                       "manifest.json", "design entry '../x.toml'"),
        "design-abs": (rebundle(src, tmp_path / "d2.zip", manifest=lambda m: m.__setitem__("design", "/etc/passwd")),
                       "manifest.json", "design entry '/etc/passwd'"),
        "missing": (rebundle(src, tmp_path / "missing.zip",
                             manifest=lambda m: m["files"].__setitem__("media/m_gone.wav", "0" * 64)),
                    "media/m_gone.wav", "missing from the zip"),
        "format-spec": (rebundle(src, tmp_path / "spec.zip", design=_set_motion("media/m_{stimulus:>99999999}.bvh")),
                        "study.toml, conditions[1].motion", "not a plain {name}"),
        "attribute": (rebundle(src, tmp_path / "attr.zip", design=_set_motion("media/{stimulus.__class__}.bvh")),
                      "study.toml, conditions[1].motion", "which a stimulus does not set"),
    }
    for name, (path, where, words) in cases.items():
        with pytest.raises(InputError) as exc:
            open_bundle(path, cache=cache / name)
        assert exc.value.path == str(path) and exc.value.where == where and words in exc.value.problem, (name, exc.value)
        assert not (cache / name).exists(), name
    # the untouched bundle opens
    assert open_bundle(src, cache=cache / "good").design_path.is_file()


def test_a_link_planted_in_the_extracted_copy_is_replaced_not_followed(bundled, tmp_path: Path) -> None:
    opened = open_bundle(bundled[1], cache=tmp_path / "cache")
    victim = next((opened.folder / "media").iterdir())
    outside = tmp_path / "outside.bin"
    outside.write_bytes(victim.read_bytes())        # same bytes: a checksum alone would accept the link
    victim.unlink()
    victim.symlink_to(outside)
    again = open_bundle(bundled[1], cache=tmp_path / "cache")
    assert not (again.folder / victim.relative_to(opened.folder)).is_symlink()


def test_a_zip_bomb_bundle_is_refused_by_run_fast_with_bounded_memory(bundled, tmp_path: Path) -> None:
    with zipfile.ZipFile(bundled[1]) as zf:
        members = [Member(n, zf.read(n)) for n in zf.namelist() if n != "manifest.json"]
        man = json.loads(zf.read("manifest.json"))
    stream, size = zeros_stream(256)                 # 4 GB of zeros in about 4 MB
    man["files"]["media/m_bomb.wav"] = "0" * 64
    bomb = write_zip(tmp_path / "bomb.zip", [Member("manifest.json", json.dumps(man).encode()), *members,
                                             Member("media/m_bomb.wav", stream=stream, size=size)])
    t0 = time.monotonic()
    run = capped_cli(["run", str(bomb), "--participant", "R01", "--no-render", "--bot", "random"],
                     env=_participant_env(tmp_path))
    assert run.rc == 2 and "Traceback" not in run.err, run.err
    assert "media/m_bomb.wav" in run.err and "4.0 GB" in run.err
    assert time.monotonic() - t0 < 60 and run.peak_mb < 500, run.peak_mb


def test_merge_refuses_a_results_zip_with_a_2_gb_member_within_a_3_gb_address_space(bundled, tmp_path: Path) -> None:
    design_path = bundled[0]
    results = design_path.with_name(f"{design_path.stem}.results.sqlite")
    assert results.is_file()
    stream, size = zeros_stream(128)                 # 2 GB of zeros, a valid member with its true CRC
    manifest = {"format": "studyapp-results", "version": 1, "participant": "R01", "study": "tiny",
                "design_hash": "0" * 64, "files": {"results.json": "0" * 64}}
    big = write_zip(tmp_path / "results-tiny-R01.zip", [
        Member("manifest.json", json.dumps(manifest).encode()),
        Member("results.json", stream=stream, size=size, crc=zeros_crc(128))])
    with zipfile.ZipFile(big) as zf:                 # an ordinary zip, as far as the zipfile module sees
        assert zf.getinfo("results.json").file_size == 2 << 30
    t0 = time.monotonic()
    run = capped_cli(["merge", str(results), str(big)], cap_bytes=3 << 30)
    assert "Traceback" not in run.err and "MemoryError" not in run.err, run.err
    assert run.rc == 1, (run.out, run.err)
    assert f"REFUSED: {big}: results.json: expands to 2.0 GB" in run.out, run.out
    assert time.monotonic() - t0 < 60 and run.peak_mb < 500, run.peak_mb


_EVERY_PATH_KEY = """
title = "every path"
[[conditions]]
id = "a"
motion = "m/{speaker}/{stimulus}_{sample}.npy"
samples = 2
template = "t.bvh"
representation = "axis_angle"
fps = 30
[[conditions]]
id = "b"
model = "models/x.onnx"
[[conditions]]
id = "c"
motion = "smpl/{stimulus}.npz"
body_model = "models/SMPLX_NEUTRAL.npz"
[[stimuli]]
id = "s1"
audio = "a/s1.wav"
face = "f/s1.csv"
head = "h/s1.npy"
tags = { speaker = "x" }
[[stimuli]]
id = "s2"
audio = "a/s2.wav"
tags = { speaker = "y" }
[avatar]
model = "av.glb"
[avatar.by_speaker]
x = "b.vrm"
y = "builtin"
"""


@pytest.mark.parametrize("which", ["every-key", "demo"])
def test_the_confinement_check_sees_every_file_the_design_package_knows(tmp_path: Path, which: str) -> None:
    """One list of a design's files is the design package's (``referenced_files``); the bundle check walks the
    raw TOML (it must not follow a path before checking it), so it is held to that list here."""
    if which == "demo":
        path = demo_design()
    else:
        path = tmp_path / "d.toml"
        path.write_text(_EVERY_PATH_KEY, encoding="utf-8")
    design, _ = parse_design(path, False)
    assert design is not None
    known = referenced_files(design)
    walked = dict(bundle_design_paths(tomlfile.loads(path.read_text(encoding="utf-8")), 100))
    assert set(walked) == set(known)
    assert len(known) >= (13 if which == "every-key" else 8)
    for key, value in walked.items():
        assert resolve(design, value) == known[key], key


def test_merge_given_a_large_bundle_says_it_is_a_bundle(tmp_path: Path) -> None:
    """A bundle is over a results file's limits (members, sizes); merge still says what the file is."""
    from studyapp.study.bundle import _read_results_file

    members = [Member("manifest.json", json.dumps({"format": "studyapp-bundle"}).encode())]
    members += [Member(f"media/m_{i:02d}.wav", b"RIFF" * 10) for i in range(40)]
    big = write_zip(tmp_path / "study.zip", members)
    with pytest.raises(InputError, match="this is a study bundle"):
        _read_results_file(big)
