"""Every malformed face file gives one InputError naming the file, the place and the problem."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from studyapp.errors import InputError
from studyapp.face.arkit import ARKIT_NAMES
from studyapp.face.io import load_face, summarize

LL_HEADER = "Timecode,BlendShapeCount," + ",".join(n[0].upper() + n[1:] for n in ARKIT_NAMES) + ",HeadYaw,HeadPitch,HeadRoll"
LL_ROW = "00:00:01:{:02d}.000,61," + ",".join(["0.1"] * 52) + ",0,0,0"


def _beat(**override) -> str:
    doc = {"names": ["jawOpen", "mouthClose"],
           "frames": [{"weights": [0.1, 0.2], "time": 0.0, "rotation": []},
                      {"weights": [0.3, 0.4], "time": 1 / 15, "rotation": []}]}
    doc.update(override)
    return json.dumps(doc, indent=1)


TEXT_CASES = [
    # (file name, content, expected place, expected words in the problem)
    ("empty.csv", "", None, "empty"),
    ("blank.csv", "\n\n  \n", None, "empty"),
    ("header_only.csv", "time,jawOpen\n", "line 2", "no data rows"),
    ("ragged.csv", "time,jawOpen,mouthClose\n0,0.1,0.2\n0.1,0.3\n", "line 3", "2 fields"),
    ("text_value.csv", "time,jawOpen\n0,0.1\n0.033,abc\n", "line 3, column jawOpen", "not a number"),
    ("empty_value.csv", "time,jawOpen\n0,0.1\n0.033,\n", "line 3, column jawOpen", "empty value"),
    ("nan.csv", "time,jawOpen\n0,nan\n0.033,0.1\n", "line 2, column jawOpen", "finite"),
    ("inf.csv", "time,jawOpen\n0,0.2\n0.033,inf\n", "line 3, column jawOpen", "finite"),
    ("unknown_layout.csv", "a,b,c\n1,2,3\n", "line 1", "unknown face data layout"),
    ("no_time.csv", "jawOpen,mouthClose\n0.1,0.2\n0.2,0.3\n", "line 1", "time"),
    ("time_backwards.csv", "time,jawOpen\n0,0.1\n0.2,0.1\n0.1,0.1\n", "line 4", "increase"),
    ("single_frame.csv", "time,jawOpen\n0,0.1\n", None, "single frame"),
    ("duplicate.csv", "time,jawOpen,JawOpen\n0,0.1,0.1\n0.1,0.1,0.1\n", "line 1", "duplicate"),
    ("same_shape.csv", "time,jawOpen,AK_18_JawOpen\n0,0.1,0.1\n0.1,0.1,0.1\n", "line 1, column AK_18_JawOpen", "both name"),
    ("percent.csv", "time,jawOpen\n0,12\n0.1,87\n", "line 2, column jawOpen", "divide by 100"),
    ("trailing_delims.csv", "time,jawOpen,\n0,0.1,\n0.1,x,\n", "line 3, column jawOpen", "not a number"),
    ("empty_header_cell.csv", "time,,jawOpen\n0,1,0.1\n0.1,1,0.1\n", "line 1, column 2", "empty column name"),
    ("ll_bad_timecode.csv", LL_HEADER + "\n" + LL_ROW.format(1) + "\n" + LL_ROW.format(3).replace("00:00:01:03.000", "1:2:3") + "\n",
     "line 3, column Timecode", "bad timecode"),
    ("ll_bad_count.csv", LL_HEADER + "\n" + LL_ROW.format(1).replace(",61,", ",x,") + "\n", "line 2, column BlendShapeCount", "not a number"),
    ("ll_value.csv", LL_HEADER + "\n" + LL_ROW.format(1) + "\n" + LL_ROW.format(3).replace("0.1,", "oops,", 1) + "\n",
     "line 3, column EyeBlinkLeft", "not a number"),
    ("ll_ragged.csv", LL_HEADER + "\n" + LL_ROW.format(1) + ",0.5\n", "line 2", "fields"),
    ("ll_frame_too_big.csv", LL_HEADER + "\n" + LL_ROW.format(1).replace("01:01.", "01:250.") + "\n" + LL_ROW.format(3) + "\n",
     "line 2", "timecode rate"),
    ("bad.json", '{"names": ["jawOpen"],\n "frames": [\n {"weights": [0.1],}\n]}', "line 3, column 20", "invalid JSON"),
    ("list.json", "[1, 2, 3]", None, "JSON object"),
    ("no_frames.json", json.dumps({"names": ["jawOpen"]}), "key frames", "missing"),
    ("no_names.json", json.dumps({"frames": []}), "key names", "missing"),
    ("names_not_strings.json", _beat(names=[1, 2]), "key names", "list of blendshape names"),
    ("empty_frames.json", _beat(frames=[]), "key frames", "non-empty"),
    ("frame_not_object.json", _beat(frames=[[0.1, 0.2]]), "key frames[0]", "object"),
    ("no_weights.json", _beat(frames=[{"weights": [0.1, 0.2], "time": 0}, {"time": 0.1}]), "key frames[1].weights", "missing"),
    ("no_time.json", _beat(frames=[{"weights": [0.1, 0.2]}, {"weights": [0.1, 0.2]}]), "key frames[0].time", "missing"),
    ("short_weights.json", _beat(frames=[{"weights": [0.1], "time": 0}]), "key frames[0].weights", "expected 2 weights"),
    ("text_weight.json", _beat(frames=[{"weights": [0.1, "x"], "time": 0}]), "key frames[0].weights[1] (mouthClose)", "not a number"),
    ("nan_weight.json", '{"names": ["jawOpen"], "frames": [{"weights": [NaN], "time": 0}]}', "key frames[0].weights[0] (jawOpen)", "finite"),
    ("bad_time.json", _beat(frames=[{"weights": [0.1, 0.2], "time": "0s"}]), "key frames[0].time", "not a finite number"),
    ("same_time.json", _beat(frames=[{"weights": [0.1, 0.2], "time": 0}, {"weights": [0.1, 0.2], "time": 0}]),
     "key frames[1].time", "increase"),
]


@pytest.mark.parametrize("name, content, where, words", TEXT_CASES, ids=[c[0] for c in TEXT_CASES])
def test_malformed_text_files(tmp_path: Path, name: str, content: str, where: str | None, words: str) -> None:
    p = tmp_path / name
    p.write_text(content)
    with pytest.raises(InputError) as exc:
        load_face(p)
    err = exc.value
    assert err.path == str(p) and str(p) in str(err)
    assert err.where == where
    assert words.lower() in err.problem.lower(), err.problem
    # summarize goes through the same checks
    with pytest.raises(InputError):
        summarize(p)


def test_missing_file_and_folder(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="file not found"):
        load_face(tmp_path / "nope.csv")
    with pytest.raises(InputError, match="not a regular file"):
        load_face(tmp_path)


def test_not_utf8(tmp_path: Path) -> None:
    p = tmp_path / "latin1.csv"
    p.write_bytes(b"time,jawOpen\n0,\xe9\xff\n")
    with pytest.raises(InputError, match="UTF-8") as exc:
        load_face(p)
    assert exc.value.where == "byte 15"


def test_bad_fps_argument(tmp_path: Path) -> None:
    p = tmp_path / "f.csv"
    p.write_text("jawOpen\n0.1\n")
    for bad in (0, -30, float("nan"), "30"):
        with pytest.raises(InputError, match="fps"):
            load_face(p, fps=bad)


@pytest.mark.parametrize("make, where, words", [
    (lambda p: np.savez(p, names=np.array(["jawOpen"])), "key weights", "missing"),
    (lambda p: np.savez(p, weights=np.zeros((2, 1))), "key names", "missing"),
    (lambda p: np.savez(p, weights=np.zeros((2, 2)), names=np.array(["jawOpen"]), fps=30), "key names", "2 strings"),
    (lambda p: np.savez(p, weights=np.zeros(3), names=np.array(["jawOpen"]), fps=30), "key weights", "numeric"),
    (lambda p: np.savez(p, weights=np.zeros((0, 1)), names=np.array(["jawOpen"]), fps=30), "key weights", "no frames"),
    (lambda p: np.savez(p, weights=np.zeros((2, 1)), names=np.array(["jawOpen"])), "key fps", "missing"),
    (lambda p: np.savez(p, weights=np.zeros((2, 1)), names=np.array(["jawOpen"]), fps=-1), "key fps", "positive"),
    (lambda p: np.savez(p, weights=np.array([[0.1], [np.nan]]), names=np.array(["jawOpen"]), fps=30),
     "key weights[1, 0] (jawOpen)", "not finite"),
    (lambda p: np.savez(p, weights=np.array([[50.0], [0.1]]), names=np.array(["jawOpen"]), fps=30),
     "key weights[0], column jawOpen", "divide by 100"),
])
def test_malformed_npz(tmp_path: Path, make, where: str, words: str) -> None:
    p = tmp_path / "f.npz"
    make(p)
    with pytest.raises(InputError) as exc:
        load_face(p)
    assert exc.value.path == str(p) and exc.value.where == where and words in exc.value.problem


@pytest.mark.parametrize("array, fps, where, words", [
    (np.zeros((3, 51)), 30.0, "array shape", "(frames, 52)"),
    (np.zeros((0, 52)), 30.0, "array shape", "no frames"),
    (np.zeros((3, 52)), None, None, "pass fps"),
    (np.where(np.eye(3, 52) > 0, np.nan, 0.0), 30.0, "row 0, column 0 (eyeBlinkLeft)", "not finite"),
    (np.array(["a"] * 52).reshape(1, 52), 30.0, "array shape", "numbers"),
])
def test_malformed_npy(tmp_path: Path, array: np.ndarray, fps, where, words: str) -> None:
    p = tmp_path / "f.npy"
    np.save(p, array)
    with pytest.raises(InputError) as exc:
        load_face(p, fps=fps)
    assert exc.value.path == str(p) and exc.value.where == where and words in exc.value.problem


def test_truncated_and_fake_binaries(tmp_path: Path) -> None:
    good = tmp_path / "good.npz"
    np.savez(good, weights=np.zeros((2, 52)), names=np.array(ARKIT_NAMES), fps=30)
    cut = tmp_path / "cut.npz"
    cut.write_bytes(good.read_bytes()[:100])
    with pytest.raises(InputError, match="not a readable .npz file"):
        load_face(cut)
    npy = tmp_path / "good.npy"
    np.save(npy, np.zeros((5, 52)))
    cut_npy = tmp_path / "cut.npy"
    cut_npy.write_bytes(npy.read_bytes()[:200])
    with pytest.raises(InputError, match="cut off"):
        load_face(cut_npy, fps=30)
    fake = tmp_path / "fake.npy"
    fake.write_text("jawOpen\n0.1\n")
    with pytest.raises(InputError, match="not a NumPy .npy"):
        load_face(fake, fps=30)
