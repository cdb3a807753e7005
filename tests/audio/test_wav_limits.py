"""A WAV's unfinished ``data`` size (0xFFFFFFFF, as streaming writers leave it) is never trusted (issue 16).

Before, scipy was handed the claim and allocated 4 GiB for it: under a 1.5 GiB address space the demo clip
failed with "Unable to allocate 4.00 GiB". Now the data chunk is the rest of the file.
"""
from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import numpy as np

from studyapp.audio.wav import load_wav

REPO = Path(__file__).resolve().parents[2]
CLIP = REPO / "study_designs/demo/audio/clip01.wav"


def _unfinished(tmp_path: Path, size: int) -> Path:
    raw = bytearray(CLIP.read_bytes())
    at = raw.index(b"data") + 4
    struct.pack_into("<I", raw, at, size)
    path = tmp_path / "streamed.wav"
    path.write_bytes(bytes(raw))
    return path


def test_an_unfinished_data_size_reads_the_samples_the_file_holds_within_1_5_gib(tmp_path):
    path = _unfinished(tmp_path, 0xFFFFFFFF)
    out = tmp_path / "samples.npy"
    code = ("import resource, sys, numpy as np; resource.setrlimit(resource.RLIMIT_AS, (1536 << 20, 1536 << 20)); "
            "from studyapp.audio.wav import load_wav; np.save(sys.argv[2], load_wav(sys.argv[1]).samples)")
    proc = subprocess.run([sys.executable, "-c", code, str(path), str(out)], capture_output=True, text=True,
                          timeout=120, cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert np.array_equal(np.load(out), load_wav(CLIP).samples)


def test_a_zero_data_size_reads_the_samples_the_file_holds(tmp_path):
    clip = load_wav(_unfinished(tmp_path, 0))
    assert clip.sample_rate == 16000
    assert np.array_equal(clip.samples, load_wav(CLIP).samples)
