"""BVH limits of issue 16: each attack, made from a real sample file, is one InputError naming the line.

Without the limits a 1,000-deep joint chain and ``CHANNELS Infinity`` gave tracebacks and a BVH whose
10 MB of frames sit on one line hung the tokenizer (millions of columns) past 700 MB.
"""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from studyapp.errors import InputError
from studyapp.motion.bvh import MAX_HEADER_LINE, MAX_JOINT_DEPTH, read_bvh

REPO = Path(__file__).resolve().parents[2]
CMU = REPO / "tests/data/samples/motion/cmu_01_01_excerpt.bvh"


def _sample() -> bytes:
    return CMU.read_bytes()


def test_a_1000_deep_joint_chain_is_refused(tmp_path):
    src = _sample()
    at = re.search(rb"CHANNELS[^\n]*\n", src).end()  # under the root's channels
    depth = 1000
    chain = b"".join(b"JOINT d%d\n{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n" % k for k in range(depth))
    chain += b"End Site\n{\nOFFSET 0 1 0\n}\n" + b"}\n" * depth
    path = tmp_path / "deep.bvh"
    path.write_bytes(src[:at] + chain + src[at:])
    with pytest.raises(InputError) as err:
        read_bvh(path)
    line = src[:at].count(b"\n") + 1 + 4 * MAX_JOINT_DEPTH  # the JOINT keyword one past the limit
    assert f"line {line}:" in str(err.value) and f"more than {MAX_JOINT_DEPTH} deep" in str(err.value)


@pytest.mark.parametrize("count", ["Infinity", "-inf", "NaN", "3.5", "1e9"])
def test_a_channel_count_that_is_not_a_small_whole_number_is_refused(tmp_path, count):
    src = _sample()
    m = re.search(rb"CHANNELS (3)", src)
    path = tmp_path / "channels.bvh"
    path.write_bytes(src[:m.start(1)] + count.encode() + src[m.end(1):])
    with pytest.raises(InputError) as err:
        read_bvh(path)
    line = src[:m.start()].count(b"\n") + 1
    assert str(err.value).startswith(f"{path}, line {line}: ")
    assert f"declares {count} channels" in str(err.value)


def test_a_header_line_past_the_limit_is_refused(tmp_path):
    src = _sample()
    first_offset = src.index(b"OFFSET")
    path = tmp_path / "long_header.bvh"
    written = src[:first_offset] + b"OFFSET " + b"0 " * MAX_HEADER_LINE + src[first_offset + 6:]
    path.write_bytes(written)
    with pytest.raises(InputError) as err:
        read_bvh(path)
    line = src[:first_offset].count(b"\n") + 1
    length = len(written.split(b"\n")[line - 1])
    assert f"line {line}: line is {length:,} characters long" in str(err.value)


def test_ten_megabytes_of_frames_on_one_line_are_refused_quickly(tmp_path):
    """Through the command line, under a 1.5 GB address space and 60 s: before, it hung past 700 MB."""
    src = _sample()
    head, sep, body = src.partition(b"Frame Time:")
    eol = body.index(b"\n") + 1
    frames = body[eol:].replace(b"\r", b"").replace(b"\n", b" ")
    path = tmp_path / "one_line.bvh"
    path.write_bytes(head + sep + body[:eol] + (frames * (10_000_000 // len(frames) + 1))[:10_000_000] + b"\n")
    data_line = (head + sep + body[:eol]).count(b"\n") + 1
    code = ("import resource, sys; resource.setrlimit(resource.RLIMIT_AS, (1536 << 20, 1536 << 20)); "
            "from studyapp.cli import main; sys.exit(main(sys.argv[1:]))")
    proc = subprocess.run([sys.executable, "-c", code, "inspect", str(path)], capture_output=True, text=True,
                          timeout=60, cwd=REPO)
    assert proc.returncode == 2, proc.stderr[-2000:]
    assert "Traceback" not in proc.stderr
    assert proc.stderr.strip() == (f"error: {path}, line {data_line}: frame line is 10,000,000 characters long; "
                                   f"96 channels take at most {96 * 64 + 1024:,} (are the line breaks missing?)")


def test_a_header_frame_count_far_beyond_the_data_is_only_a_note(tmp_path):
    src = _sample()
    path = tmp_path / "frames.bvh"
    path.write_bytes(re.sub(rb"Frames:\s*\d+", b"Frames: 1000000000000", src))
    n = read_bvh(CMU).n_frames
    with pytest.warns(UserWarning, match=f"header says Frames: 1000000000000 but the file has {n} data lines"):
        motion = read_bvh(path)
    assert motion.n_frames == n


@pytest.mark.parametrize("frame_time", ["9223372036854775807", "61"])
def test_a_frame_time_of_more_than_a_minute_is_refused(tmp_path, frame_time):
    """Fuzz case 2255 (seed 16): a huge frame time made `convert --fps 30` ask numpy for ~10^20 frames."""
    src = _sample()
    path = tmp_path / "slow.bvh"
    path.write_bytes(re.sub(rb"Frame Time:\s*[0-9.eE+-]+", b"Frame Time: " + frame_time.encode(), src))
    line = src[:src.index(b"Frame Time:")].count(b"\n") + 1
    with pytest.raises(InputError, match=f"line {line}: frame time {frame_time} s is longer than 60 s per frame"):
        read_bvh(path)
