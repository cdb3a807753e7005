"""The readers survive seeded mutations of real files through the command line (issue 16, item 4).

One run of :mod:`tests.hardening.fuzz` (``STUDYAPP_FUZZ_CASES`` cases, 154 by default: 14 per reader,
two at a time, well under a minute on 2 cores) is shared by two verdicts, so a failure says whose
readers it is in: the text readers (BVH, face CSV/JSON, WAV, TOML designs) and the binary ones (NPY, NPZ,
glTF/GLB/VRM, results databases). Each fails on any traceback, hang, memory blow-up or crash and prints
the cases with the command that re-runs each one. ``STUDYAPP_FUZZ_SEED`` picks another seed.
"""
from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from hardening import mutations
from hardening.fuzz import READERS, classify, make_case

REPO = Path(__file__).resolve().parents[2]
CASES = int(os.environ.get("STUDYAPP_FUZZ_CASES", "154"))
SEED = int(os.environ.get("STUDYAPP_FUZZ_SEED", "16"))
TEXT = ("bvh", "face_csv", "face_json", "wav", "toml")
BINARY = tuple(r for r in READERS if r not in TEXT)


@pytest.fixture(scope="module")
def fuzz_run(tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("fuzz")
    proc = subprocess.run(
        [sys.executable, "-m", "tests.hardening.fuzz", "--cases", str(CASES), "--seed", str(SEED), "--jobs", "2",
         "--timeout", "30", "--work", str(out / "work"), "--json", str(out / "cases.json")],
        cwd=REPO, capture_output=True, text=True, timeout=60 + CASES * 10,
        env={**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")},
    )
    print(proc.stdout[-20000:], proc.stderr[-5000:])
    assert (out / "cases.json").exists(), proc.stderr[-3000:]
    return {**json.loads((out / "cases.json").read_text()), "report": proc.stdout}


def _failures(run: dict, readers: tuple[str, ...]) -> list[str]:
    return [f"[{c['outcome']}] {c['reader']}: {c['source']} + {'+'.join(c['mutations'])}: studyapp {' '.join(c['argv'])}"
            f"\n    {c['detail']}\n    python -m tests.hardening.fuzz --seed {run['seed']} --case {c['index']}"
            for c in run["cases"] if c["reader"] in readers and c["outcome"] in ("traceback", "blowup", "hang", "crash")]


def test_every_reader_is_fuzzed(fuzz_run):
    seen = {c["reader"] for c in fuzz_run["cases"]}
    assert seen == set(READERS), fuzz_run["report"]
    assert len(fuzz_run["cases"]) == CASES


def test_text_readers_survive_fuzzing(fuzz_run):
    bad = _failures(fuzz_run, TEXT)
    assert not bad, f"{len(bad)} failing cases:\n" + "\n".join(bad) + "\n\n" + fuzz_run["report"]


def test_binary_readers_survive_fuzzing(fuzz_run):
    bad = _failures(fuzz_run, BINARY)
    assert not bad, f"{len(bad)} failing cases:\n" + "\n".join(bad) + "\n\n" + fuzz_run["report"]


def test_same_seed_same_cases(tmp_path):
    corpus = {r: [] for r in READERS}
    from hardening.fuzz import Seed

    src = tmp_path / "a.bvh"
    src.write_bytes((REPO / "tests/data/samples/pybvh_test1_zyx_excerpt.bvh").read_bytes())
    for r in READERS:
        corpus[r].append(Seed(r, src, (("inspect", "{in}"),), ".bvh"))
    first = [make_case(7, i, corpus)[2] for i in range(0, 40, 11)]
    again = [make_case(7, i, corpus)[2] for i in range(0, 40, 11)]
    other = [make_case(8, i, corpus)[2] for i in range(0, 40, 11)]
    assert first == again
    assert first != other


def test_classification_of_child_outcomes():
    assert classify(None, "") == "hang"
    assert classify(0, "") == "ok"
    assert classify(2 << 8, "error: a.bvh, line 3: expected OFFSET\n") == "error"
    assert classify(71 << 8, "Traceback (most recent call last):\n  ...\nValueError: x\n") == "traceback"
    assert classify(71 << 8, "Traceback (most recent call last):\nnumpy.core._exceptions._ArrayMemoryError: "
                             "Unable to allocate 7.28 TiB\n") == "blowup"
    assert classify(11, "") == "crash"  # killed by SIGSEGV
    assert classify(int(signal.SIGXCPU), "") == "hang"  # past the CPU-time cap


def test_mutations_reach_the_attacks_of_issue_16():
    rng = random.Random(1)
    bvh = (REPO / "tests/data/samples/pybvh_test1_zyx_excerpt.bvh").read_bytes()
    deep = mutations.bvh_deep_chain(random.Random(3), bvh)
    assert deep.count(b"JOINT d") in (100, 1000, 5000)
    csv = (REPO / "tests/data/samples/livelinkface_S07-001_excerpt.csv").read_bytes()
    wide = mutations.csv_wide(random.Random(0), csv)
    assert wide.splitlines()[0].count(b",") >= 1000
    toml = (REPO / "study_designs/demo.toml").read_bytes()
    assert any(b"{stimulus:" in mutations.toml_pattern(random.Random(s), toml) for s in range(30))
    nested = mutations.json_deep(rng, b"1")
    assert nested.count(b"[") + nested.count(b"{") >= 1000
