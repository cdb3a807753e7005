"""Seeded mutations of the real avatars through the real reader: 0 tracebacks, 0 hangs, 0 memory blow-ups.

Every mutated file (bit flips, truncation, lying GLB lengths, JSON field edits, node cycles, deep JSON,
URIs leading outside the folder, singular or NaN data) is read by :func:`load_gltf` (what ``view`` and
``validate`` use) and by ``inspect``'s :func:`summarize_avatar` in a forked child capped at 1.5 GB of added address space and 20 s. It must
load or end in one :class:`InputError` line naming the file. CI runs a small size; a larger one on demand::

    STUDYAPP_GLTF_FUZZ_CASES=2000 STUDYAPP_GLTF_FUZZ_SEED=7 pytest tests/render/test_gltf_fuzz.py -s
"""
from __future__ import annotations

import collections
import json
import os
import random
from pathlib import Path

from gltf_mutations import HANG, INPUT_ERROR, MEMORY, OK, TRACEBACK, dump_json, mutate, mutate_doc, run_case, split_glb
from render_helpers import SAMPLES
from studyapp.render.avatar import build_default_avatar
from studyapp.render.avatar_report import summarize_avatar
from studyapp.render.gltf import export_glb, load_gltf

CASES = int(os.environ.get("STUDYAPP_GLTF_FUZZ_CASES", "120"))
SEED = int(os.environ.get("STUDYAPP_GLTF_FUZZ_SEED", "16"))
# the shared samples, one gltfpack (meshopt) file and the demo's built-in avatar; builtin.gltfpack-cc.glb is
# left out of CI: its meshopt decoding alone takes seconds per case
AVATARS = SAMPLES / "avatars"
BASES = ("CesiumMan.glb", "Fox.glb", "RobotExpressive.glb", "cryptovoxels_vrm0.vrm",
         "VRMC_vrm_expressions_isBinary_Overrides.vrm", "RobotExpressive.gltfpack-khr.glb")


def _read(path: Path) -> None:
    """``load_gltf`` (``view``, ``validate``), then ``inspect``'s report, which must survive the same file."""
    try:
        load_gltf(path)
    finally:
        summarize_avatar(path)


def test_mutated_avatars_never_crash_hang_or_blow_up(tmp_path: Path) -> None:
    builtin = export_glb(build_default_avatar(), tmp_path / "base" / "builtin.glb")
    bases = [AVATARS / name for name in BASES] + [builtin]
    raws = {p: p.read_bytes() for p in bases}
    # a secret beside the case folder: a URI that escapes must not reach it
    (tmp_path / "secret.bin").write_bytes(b"\0" * 4096)
    counts: collections.Counter = collections.Counter()
    per_base: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    bad = []
    for i in range(CASES):
        rng = random.Random(SEED * 1_000_003 + i)
        base = bases[i % len(bases)]
        folder = tmp_path / "case"
        folder.mkdir(exist_ok=True)
        for old in folder.iterdir():
            old.unlink()
        if i % 4 == 3:  # as a .gltf with an external .bin: the URI edits and JSON text paths
            doc, binary = split_glb(raws[base])
            binary = bytearray(binary)
            doc["buffers"][0]["uri"] = "avatar.bin"
            what = "gltf: " + mutate_doc(doc, binary, rng)
            (folder / "avatar.bin").write_bytes(bytes(binary))
            case = folder / "avatar.gltf"
            case.write_bytes(dump_json(doc))
        else:
            data, what = mutate(raws[base], rng)
            case = folder / f"avatar{base.suffix}"
            case.write_bytes(data)
        outcome, detail = run_case(case, _read)
        counts[outcome] += 1
        per_base[base.name][outcome] += 1
        if outcome in (TRACEBACK, HANG, MEMORY):
            bad.append(f"case {i} ({base.name}; {what[:120]}): {outcome}: {detail}")
        elif outcome == INPUT_ERROR and (not detail.startswith(str(case)) or "\n" in detail):
            bad.append(f"case {i} ({base.name}; {what[:120]}): message does not name the file in one line: {detail}")
    print(f"\nglTF fuzz, seed {SEED}, {CASES} cases: {dict(counts)}")
    for name, c in per_base.items():
        print(f"  {name}: {dict(c)}")
    assert not bad, f"{len(bad)} of {CASES} cases failed:\n" + "\n".join(bad[:40])
    # the mutations have teeth: most are refused, and some leave a loadable file
    assert counts[INPUT_ERROR] > CASES // 3 and counts[OK] > 0, counts


def _blow_up(path: Path) -> None:
    import numpy as np

    np.ones(2 * 2**30, np.uint8)  # 2 GiB, over the 1.5 GB cap


def _hang(path: Path) -> None:
    import time

    time.sleep(60)


def _crash(path: Path) -> None:
    [][1]


def test_the_harness_sees_blow_ups_hangs_and_tracebacks(tmp_path: Path) -> None:
    assert run_case(tmp_path, _blow_up)[0] == MEMORY
    assert run_case(tmp_path, _hang, time_cap=1.0)[0] == HANG
    outcome, detail = run_case(tmp_path, _crash)
    assert outcome == TRACEBACK and detail.startswith("IndexError at test_gltf_fuzz.py:")
    assert run_case(AVATARS / "Fox.glb", _read) == (OK, "")


def test_mutations_are_seeded(tmp_path: Path) -> None:
    raw = (AVATARS / "Fox.glb").read_bytes()
    first = [mutate(raw, random.Random(k)) for k in range(20)]
    again = [mutate(raw, random.Random(k)) for k in range(20)]
    assert first == again
    assert len({data for data, _ in first}) == 20
    json.dumps([what for _, what in first])
