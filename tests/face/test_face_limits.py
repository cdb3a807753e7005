"""Face-file limits of issue 16, on the real samples edited the way the fuzzer edits them.

Before: a 1.2 MB CSV with 100k columns hung (duplicate-column checks quadratic in the columns), JSON nested
100k deep ended in a RecursionError, and a time stamp of 10^9 s asked for billions of resampled frames.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from studyapp.errors import InputError
from studyapp.face.io import MAX_CSV_COLUMNS, MAX_JSON_DEPTH, load_face

REPO = Path(__file__).resolve().parents[2]
SAMPLES = REPO / "tests/data/samples"
DEMO_CSV = REPO / "study_designs/demo/face/clip01.csv"


def test_a_csv_with_100k_columns_is_refused_quickly(tmp_path):
    """Through the command line under a 60 s cap: before, it hung."""
    lines = DEMO_CSV.read_text(encoding="utf-8").splitlines()
    header = lines[0] + "".join(f",extra{k:06d}" for k in range(100_000))
    path = tmp_path / "wide.csv"
    path.write_text("\n".join([header, *lines[1:]]) + "\n", encoding="utf-8")
    assert path.stat().st_size > 1_000_000
    proc = subprocess.run([sys.executable, "-m", "studyapp.cli", "inspect", str(path)], capture_output=True,
                          text=True, timeout=60, cwd=REPO)
    assert proc.returncode == 2
    n = 100_000 + lines[0].count(",") + 1
    assert proc.stderr.strip() == (f"error: {path}, line 1: the header has {n:,} columns; a face CSV has at most "
                                   f"{MAX_CSV_COLUMNS:,} (52 ARKit shapes and a few more)")


@pytest.mark.parametrize("opener", ["[", '{"a":'])
def test_json_nested_100k_deep_is_refused(tmp_path, opener):
    closer = "]" if opener == "[" else "}"
    text = (SAMPLES / "beat_face51_diffsheg_gt_excerpt.json").read_text(encoding="utf-8")
    path = tmp_path / "deep.json"
    path.write_text(opener * 100_000 + text + closer * 100_000, encoding="utf-8")
    with pytest.raises(InputError) as err:
        load_face(path)
    column = len(opener) * MAX_JSON_DEPTH + 1  # the first opener past the limit, on line 1
    assert str(err.value) == (f"{path}, line 1, column {column}: JSON nested more than {MAX_JSON_DEPTH} deep; "
                              "BEAT facial JSON nests 3 deep")


def test_brackets_inside_json_strings_do_not_count(tmp_path):
    doc = json.loads((SAMPLES / "beat_face51_diffsheg_gt_excerpt.json").read_text(encoding="utf-8"))
    doc["comment"] = "[" * 1000 + '\\"{' * 100
    path = tmp_path / "strings.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    assert load_face(path).n_frames == len(doc["frames"])


def test_a_time_stamp_far_beyond_the_others_is_refused(tmp_path):
    """Uneven stamps are resampled onto a regular grid; a stamp of 10^9 s would make that grid 3*10^10 frames."""
    lines = DEMO_CSV.read_text(encoding="utf-8").splitlines()
    assert lines[0].startswith("time,")
    cells = lines[-1].split(",")
    cells[0] = "1000000000"
    lines[-1] = ",".join(cells)
    path = tmp_path / "gap.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(InputError) as err:
        load_face(path)
    assert str(err.value).startswith(f"{path}, line {len(lines)}: time stamps jump from ")
    assert "to 1e+09 s" in str(err.value) and "(a wrong time stamp?)" in str(err.value)


def test_time_stamps_implying_an_absurd_frame_rate_are_refused(tmp_path):
    lines = DEMO_CSV.read_text(encoding="utf-8").splitlines()
    rows = [ln.split(",") for ln in lines[1:]]
    for i, cells in enumerate(rows):
        cells[0] = f"{i * 1e-300:.3e}"  # evenly spaced, 1e300 frames per second
    path = tmp_path / "rate.csv"
    path.write_text("\n".join([lines[0], *(",".join(c) for c in rows)]) + "\n", encoding="utf-8")
    with pytest.raises(InputError) as err:
        load_face(path)
    assert str(err.value).startswith(f"{path}, line 3: time stamps 0, 1e-300, ... imply ")
