"""Sizes a file claims are checked before they are trusted: NPY headers, NPZ members, zip directories.

The hostile files are built in milliseconds (:mod:`fixtures.zips`): a 4 MB ``.npz`` that really expands to
4 GB, an ``.npy`` header claiming 10^12 frames. The command line meets them in a child process whose address
space is capped, so a reader that trusted them would die of ``MemoryError`` (a traceback), not pass.
"""
from __future__ import annotations

import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fixtures.zips import Member, capped_cli, npy_header_bytes, write_zip, zeros_stream
from studyapp.errors import InputError
from studyapp.motion.arrays import load_motion_npz, save_motion_npz
from studyapp.motion.beat import beat_skeleton
from studyapp.motion.skeleton import Motion
from studyapp.safe_io import NPZ_ZIP, SafeZip, load_npy, npy_header, open_npz


def _one_line_refusal(run, *words: str) -> None:
    assert run.rc == 2, (run.rc, run.out, run.err)
    assert "Traceback" not in run.err and "MemoryError" not in run.err, run.err
    lines = [ln for ln in run.err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), run.err
    for w in words:
        assert w in lines[0], (w, lines[0])


def test_npy_header_claiming_1e12_frames_is_refused_before_its_data_is_read(tmp_path: Path) -> None:
    f = tmp_path / "huge.npy"
    f.write_bytes(npy_header_bytes((10 ** 12, 165)) + bytes(4 * 165 * 10))   # ten real frames
    with pytest.raises(InputError) as exc:
        load_npy(f)
    assert exc.value.path == str(f) and "1000000000000x165" in exc.value.problem and "refused" in exc.value.problem
    # a header within the limit that still claims more than the file holds: refused as cut off
    short = tmp_path / "short.npy"
    short.write_bytes(npy_header_bytes((1000, 165)) + bytes(4 * 165 * 10))
    with pytest.raises(InputError, match="660000 bytes.*6600 bytes follow"):
        npy_header(short)
    t0 = time.monotonic()
    run = capped_cli(["inspect", str(f)])
    _one_line_refusal(run, str(f), "1000000000000x165")
    assert time.monotonic() - t0 < 60 and run.peak_mb < 500, run.peak_mb


def test_npz_of_4_mb_that_expands_to_4_gb_is_refused_fast_with_bounded_memory(tmp_path: Path) -> None:
    # A real bomb: the member is a valid .npy (header + 4 GB of zeros), every stated size is honest.
    n = 256
    head = npy_header_bytes((n * (1 << 24) // (4 * 165), 165))
    stream, size = zeros_stream(n, head)
    bomb = write_zip(tmp_path / "bomb.npz", [Member("poses.npy", stream=stream, size=size)])
    assert bomb.stat().st_size < 5e6 and size >= 4 << 30
    with pytest.raises(InputError) as exc:
        open_npz(bomb)
    assert exc.value.where == "poses.npy" and "4.0 GB" in exc.value.problem
    for args in (["inspect", str(bomb)], ["convert", str(bomb), str(tmp_path / "o.bvh"), "--template", "beat",
                                          "--representation", "axis_angle", "--in-fps", "30"]):
        t0 = time.monotonic()
        run = capped_cli(args)
        _one_line_refusal(run, str(bomb), "poses.npy")
        assert time.monotonic() - t0 < 60 and run.peak_mb < 500, (args, run.peak_mb)


def test_a_member_that_expands_beyond_its_stated_size_is_refused_not_trusted(tmp_path: Path) -> None:
    stream, size = zeros_stream(4)          # 64 MB of zeros, stated as 1 MB
    liar = write_zip(tmp_path / "liar.npz", [Member("a.npy", stream=stream, size=1 << 20)])
    with SafeZip(liar, NPZ_ZIP) as zf, pytest.raises(InputError) as exc:
        zf.read("a.npy")
    assert exc.value.where == "a.npy" and ("beyond" in exc.value.problem or "damaged" in exc.value.problem)


def test_zip_directories_beyond_the_limits_are_refused(tmp_path: Path) -> None:
    many = tmp_path / "many.npz"
    with zipfile.ZipFile(many, "w") as zf:
        for i in range(NPZ_ZIP.max_members + 1):
            zf.writestr(f"a{i}.npy", b"")
    with pytest.raises(InputError, match="1001 members"):
        open_npz(many)
    link = write_zip(tmp_path / "link.npz", [Member("a.npy", b"/etc/passwd", external_attr=0o120777 << 16)])
    with pytest.raises(InputError, match="symbolic link"):
        open_npz(link)
    slip = write_zip(tmp_path / "slip.npz", [Member("../a.npy", b"x")])
    with pytest.raises(InputError, match="unsafe member name"):
        open_npz(slip)


def test_pickled_object_arrays_are_refused_by_name_and_skipped_on_request(tmp_path: Path) -> None:
    f = tmp_path / "mixed.npz"
    np.savez(f, poses=np.zeros((2, 165)), settings=np.array([{"a": 1}], dtype=object))
    with open_npz(f) as z:
        with pytest.raises(InputError, match="pickled Python objects"):
            z["settings"]
        assert list(z.arrays(skip_objects=True)) == ["poses"]


def _motion_npz(tmp_path: Path) -> tuple[Path, dict]:
    sk = beat_skeleton()
    m = Motion.rest(sk)
    f = tmp_path / "m.npz"
    save_motion_npz(Motion(sk, 30.0, np.repeat(m.rotations, 3, 0), np.repeat(m.translations, 3, 0)), f)
    with np.load(f) as z:
        return f, {k: z[k] for k in z.files}


@pytest.mark.parametrize("key, value, words", [
    ("rotations", lambda a: a.astype(str), "holds text"),
    ("fps", lambda a: np.array([30.0, 30.0, 30.0]), "has shape (3,)"),
    ("joints", lambda a: np.arange(len(a), dtype=float), "holds numbers"),
    ("parents", lambda a: a.astype(str), "holds text"),
    ("offsets", lambda a: a[:, :2], "has shape"),
    ("translations", lambda a: a[:1], "has shape"),
])
def test_a_motion_npz_written_by_studyapp_with_a_field_of_the_wrong_type_is_refused_by_name(
        tmp_path: Path, key: str, value, words: str) -> None:
    f, arrays = _motion_npz(tmp_path)
    assert load_motion_npz(f).n_frames == 3
    arrays[key] = value(arrays[key])
    np.savez(f, **arrays)
    with pytest.raises(InputError) as exc:
        load_motion_npz(f)
    assert exc.value.where == f"key {key}" and words in exc.value.problem, str(exc.value)


def test_the_real_beat2_sample_reads_as_numpy_reads_it() -> None:
    sample = Path(__file__).parent / "data" / "samples" / "motion" / "beat2_smplx_2_scott_0_1_1_excerpt.npz"
    with open_npz(sample) as z, np.load(sample) as ref:
        got = z.arrays()
        assert sorted(got) == sorted(ref.files)
        for k in ref.files:
            assert got[k].dtype == ref[k].dtype and np.array_equal(got[k], ref[k]), k


def test_a_pipe_named_like_an_array_is_refused_not_waited_on(tmp_path: Path) -> None:
    import os

    fifo = tmp_path / "clip.npy"
    os.mkfifo(fifo)
    run = capped_cli(["inspect", str(fifo)], timeout=60)   # opening it would wait for a writer forever
    _one_line_refusal(run, str(fifo), "not a regular file")


def test_npz_keys_that_differ_in_case_are_kept_apart(tmp_path: Path) -> None:
    f = tmp_path / "cases.npz"
    np.savez(f, a=np.zeros(2), A=np.ones(3))
    with open_npz(f) as z:
        assert z["a"].tolist() == [0.0, 0.0] and z["A"].tolist() == [1.0, 1.0, 1.0]
