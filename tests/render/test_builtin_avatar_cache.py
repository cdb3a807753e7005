"""The built-in avatar is modelled once per machine and read back from the disk cache afterwards
(issue 20: modelling it cost up to 0.9 s of a participant's first frame); a damaged cache file is rebuilt."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

from studyapp.render import avatar as A


def _same(a: A.Avatar, b: A.Avatar) -> None:
    for k in A._CACHED_ARRAYS:
        x, y = getattr(a, k), getattr(b, k)
        assert x.dtype == y.dtype and np.array_equal(x, y), k
    assert a.skeleton.names == b.skeleton.names and a.morph_names == b.morph_names and a.name == b.name


def test_cached_avatar_equals_the_modelled_one_and_a_damaged_file_is_rebuilt(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.setenv("STUDYAPP_CACHE_DIR", str(tmp_path))
    fresh = A._build()
    first = A._load_or_build()                       # models it and writes the file
    files = list((tmp_path / "avatar").glob("builtin-*.npz"))
    assert len(files) == 1 and files[0] == A._cache_file()
    _same(first, fresh)

    calls = []
    monkeypatch.setattr(A, "_build", lambda: calls.append(1) or fresh)
    _same(A._load_or_build(), fresh)                 # read back, not modelled
    assert calls == []

    files[0].write_bytes(files[0].read_bytes()[:5000])  # cut short: rebuilt, and the file mended
    _same(A._load_or_build(), fresh)
    assert calls == [1]
    _same(A._load_or_build(), fresh)
    assert calls == [1]


def test_a_second_process_reads_the_avatar_from_the_cache(tmp_path: Path) -> None:
    code = ("import os, time; from studyapp.render import avatar as A; t = time.perf_counter(); "
            "A.build_default_avatar(); print(time.perf_counter() - t)")
    env = {**__import__("os").environ, "STUDYAPP_CACHE_DIR": str(tmp_path)}
    run = lambda: float(subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True,
                                       check=True).stdout)
    cold, warm = run(), run()
    assert len(list((tmp_path / "avatar").iterdir())) == 1
    assert warm < cold / 3, (cold, warm)
