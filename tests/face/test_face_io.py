"""Face file formats: the real samples, synthetic files with known content, round trips."""
from __future__ import annotations

import csv
import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from studyapp.face.animation import FaceAnimation
from studyapp.face.arkit import ARKIT_INDEX, ARKIT_NAMES
from studyapp.face.io import load_face, save_face_csv, summarize

# The shared real-world samples sit beside the checkout (../shared/samples).
SAMPLES = Path(__file__).resolve().parents[1] / "data" / "samples"  # copies of ../shared/samples (see its README)
LIVELINK = SAMPLES / "livelinkface_S07-001_excerpt.csv"
BEAT_JSON = SAMPLES / "beat_face51_diffsheg_gt_excerpt.json"


# --------------------------------------------------------------------------------------- real samples

def test_live_link_sample_maps_by_name_not_position() -> None:
    rows = list(csv.reader(open(LIVELINK)))
    header, data = rows[0], rows[1:]
    col = {h: i for i, h in enumerate(header)}
    face = load_face(LIVELINK)
    assert face.n_frames == 3 and face.fps == 30.0  # frame field steps by 2 on a 60 fps timecode
    assert face.missing == () and face.unknown == ()
    for pascal in ("JawOpen", "JawLeft", "JawRight", "MouthLeft", "MouthRight", "EyeBlinkLeft", "TongueOut",
                   "BrowInnerUp", "MouthSmileRight"):
        canon = pascal[0].lower() + pascal[1:]
        expected = [float(r[col[pascal]]) for r in data]
        np.testing.assert_allclose(face.weight(canon), expected, rtol=1e-6, atol=1e-9)
    # The file's positions differ from Apple's: JawRight is the 17th column of the file, jawLeft Apple's 16th.
    assert header.index("JawRight") < header.index("JawLeft")
    assert face.weights[0, ARKIT_INDEX["jawright"]] == pytest.approx(float(data[0][col["JawRight"]]))
    assert face.weights[0, ARKIT_INDEX["jawright"]] != face.weights[0, ARKIT_INDEX["jawleft"]]
    assert face.weights[0, ARKIT_INDEX["jawopen"]] == pytest.approx(0.0257464331)
    np.testing.assert_allclose(face.head_rotation, [[float(r[col[k]]) for k in ("HeadYaw", "HeadPitch", "HeadRoll")]
                                                    for r in data])


def test_live_link_fps_override() -> None:
    assert load_face(LIVELINK, fps=60.0).fps == 60.0


def test_beat_json_sample() -> None:
    doc = json.loads(BEAT_JSON.read_text())
    with pytest.warns(UserWarning, match="tongueOut"):
        face = load_face(BEAT_JSON)
    assert face.missing == ("tongueOut",) and face.unknown == ()
    assert face.n_frames == len(doc["frames"]) == 2 and face.fps == pytest.approx(15.0)
    assert face.head_rotation is None  # the sample's "rotation" lists are empty
    for k, name in enumerate(doc["names"]):
        np.testing.assert_allclose(face.weight(name), [f["weights"][k] for f in doc["frames"]], rtol=1e-6)
    assert np.all(face.weight("tongueOut") == 0)
    assert face.weight("jawOpen")[0] == pytest.approx(doc["frames"][0]["weights"][doc["names"].index("jawOpen")])


def test_summaries_of_samples() -> None:
    s = summarize(LIVELINK)
    assert (s["format"], s["frames"], s["fps"], s["shapes_found"], s["has_head_rotation"]) == ("livelink-csv", 3, 30.0, 52, True)
    assert s["duration"] == pytest.approx(0.1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # summarize reports missing shapes instead of warning
        b = summarize(BEAT_JSON)
    assert (b["format"], b["shapes_found"], b["missing"], b["has_head_rotation"]) == ("beat-json", 51, ["tongueOut"], False)


# --------------------------------------------------------------------------------------- synthetic files

def _livelink_text(timecodes: list[str], rng: np.random.Generator) -> tuple[str, np.ndarray]:
    names = list(ARKIT_NAMES)
    order = rng.permutation(52)
    header = ["Timecode", "BlendShapeCount"] + [names[i][0].upper() + names[i][1:] for i in order]
    header += ["HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll",
               "RightEyeYaw", "RightEyePitch", "RightEyeRoll"]
    w = rng.random((len(timecodes), 52)).round(6)
    lines = [",".join(header)]
    for i, tc in enumerate(timecodes):
        lines.append(",".join([tc, "61"] + [f"{w[i, k]:.6f}" for k in order] + ["0.1", "-0.2", "0.3"] + ["0.5"] * 6))
    return "\n".join(lines) + "\n", w


@pytest.mark.parametrize("timecodes, fps", [
    # 30 fps capture on a 60 fps timecode, crossing into the next second: frame field 56, 58, 00, 02.
    (["01:02:03:54.412", "01:02:03:56.412", "01:02:03:58.413", "01:02:04:00.412", "01:02:04:02.411"], 30.0),
    # 60 fps capture: every frame number.
    ([f"00:00:09:{f:02d}.500" for f in range(55, 60)] + [f"00:00:10:{f:02d}.500" for f in range(3)], 60.0),
    # 25 fps timecode with a wrap at 25: only rate 25 gives even steps (30 would not).
    (["10:00:00:22", "10:00:00:23", "10:00:00:24", "10:00:01:00", "10:00:01:01"], 25.0),
])
def test_live_link_rate_from_timecodes(tmp_path: Path, timecodes: list[str], fps: float) -> None:
    text, w = _livelink_text(timecodes, np.random.default_rng(0))
    p = tmp_path / "take.csv"
    p.write_text(text)
    face = load_face(p)
    assert face.fps == fps and face.n_frames == len(timecodes)
    np.testing.assert_allclose(face.weights, w, atol=1e-6)
    np.testing.assert_allclose(face.head_rotation, np.tile([0.1, -0.2, 0.3], (len(timecodes), 1)), atol=1e-7)


def test_plain_csv_any_column_order_and_case(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    names = ["JAWOPEN", "eyeblink_l", "AK_52_TongueOut", "subject", "mouthSmileLeft"]
    w = rng.random((6, 4)).round(5)
    lines = ["time," + ",".join(names)]
    for i in range(6):
        lines.append(f"{i / 25:.6f},{w[i, 0]},{w[i, 1]},{w[i, 2]},anna,{w[i, 3]}")
    p = tmp_path / "f.csv"
    p.write_text("\n".join(lines))
    with pytest.warns(UserWarning, match="48 ARKit"):
        face = load_face(p)
    assert face.fps == 25.0 and face.unknown == ("subject",) and len(face.missing) == 48
    np.testing.assert_allclose(face.weight("jawOpen"), w[:, 0], atol=1e-7)
    np.testing.assert_allclose(face.weight("eyeBlinkLeft"), w[:, 1], atol=1e-7)
    np.testing.assert_allclose(face.weight("tongueOut"), w[:, 2], atol=1e-7)
    np.testing.assert_allclose(face.weight("mouthSmileLeft"), w[:, 3], atol=1e-7)


def test_plain_csv_dropped_frame_is_resampled(tmp_path: Path) -> None:
    times = [0, 1, 2, 4, 5]  # frame 3 missing
    lines = ["time,jawOpen"] + [f"{t / 30:.6f},{t / 10}" for t in times]
    p = tmp_path / "f.csv"
    p.write_text("\n".join(lines))
    with pytest.warns(UserWarning) as record:
        face = load_face(p)
    assert any("uneven" in str(r.message) for r in record)
    assert face.fps == 30.0 and face.n_frames == 6
    np.testing.assert_allclose(face.weight("jawOpen"), [0, 0.1, 0.2, 0.3, 0.4, 0.5], atol=1e-6)


def test_plain_csv_without_time_uses_given_fps(tmp_path: Path) -> None:
    p = tmp_path / "f.csv"
    p.write_text("jawOpen;mouthClose\n0.5;0.25\n0.75;0\n")
    with pytest.warns(UserWarning):
        face = load_face(p, fps=50)
    assert face.fps == 50.0 and face.weight("mouthClose").tolist() == [0.25, 0.0]


def test_npz_and_npy(tmp_path: Path) -> None:
    rng = np.random.default_rng(2)
    w = rng.random((7, 52)).astype(np.float32)
    order = rng.permutation(52)
    np.savez(tmp_path / "f.npz", weights=w[:, order], names=np.array([ARKIT_NAMES[i].upper() for i in order]), fps=15.0)
    face = load_face(tmp_path / "f.npz")
    assert face.fps == 15.0
    np.testing.assert_array_equal(face.weights, w)
    np.save(tmp_path / "f.npy", w)
    face = load_face(tmp_path / "f.npy", fps=30)
    np.testing.assert_array_equal(face.weights, w)
    # Dispatch is by content: an NPZ under a .dat name still loads.
    (tmp_path / "f.dat").write_bytes((tmp_path / "f.npz").read_bytes())
    assert load_face(tmp_path / "f.dat").n_frames == 7


def test_beat_json_with_rotation_and_fps_from_times(tmp_path: Path) -> None:
    names = ["jawOpen", "mouthClose"]
    frames = [{"weights": [0.1 * i, 0.2], "time": i / 60, "rotation": [0.01 * i, 0.0, -0.01]} for i in range(5)]
    p = tmp_path / "f.json"
    p.write_text(json.dumps({"names": names, "frames": frames}))
    with pytest.warns(UserWarning):
        face = load_face(p)
    assert face.fps == 60.0
    np.testing.assert_allclose(face.head_rotation[:, 0], [0, 0.01, 0.02, 0.03, 0.04], atol=1e-7)


# --------------------------------------------------------------------------------------- round trips

@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    w=arrays(np.float32, st.tuples(st.integers(2, 12), st.just(52)), elements=st.floats(0, 1, width=32)),
    fps=st.sampled_from([15.0, 24.0, 25.0, 29.97002997002997, 30.0, 60.0, 120.0]),
    head=st.booleans(),
    decimals=st.integers(4, 8),
)
def test_csv_round_trip(tmp_path: Path, w: np.ndarray, fps: float, head: bool, decimals: int) -> None:
    rot = np.linspace(-0.5, 0.5, w.shape[0] * 3).reshape(-1, 3) if head else None
    face = FaceAnimation(w, fps, rot)
    p = tmp_path / "rt.csv"
    save_face_csv(face, p, decimals=decimals)
    back = load_face(p)
    assert back.n_frames == face.n_frames and back.missing == () and back.unknown == ()
    assert back.fps == pytest.approx(fps, rel=1e-9)
    np.testing.assert_allclose(back.weights, face.weights, atol=0.5 * 10.0 ** -decimals + 1e-7)
    if head:
        np.testing.assert_allclose(back.head_rotation, face.head_rotation, atol=0.5 * 10.0 ** -decimals + 1e-7)
    else:
        assert back.head_rotation is None
    # Writing what was read gives the same file: the text form is a fixed point.
    p2 = tmp_path / "rt2.csv"
    save_face_csv(back, p2, decimals=decimals)
    assert p2.read_text() == p.read_text()


def test_saved_csv_layout(tmp_path: Path) -> None:
    save_face_csv(FaceAnimation.neutral(2, 30.0), tmp_path / "n.csv")
    lines = (tmp_path / "n.csv").read_text().splitlines()
    assert lines[0].split(",") == ["time", *ARKIT_NAMES]
    assert lines[1] == ",".join(["0"] * 53)
    assert lines[2].split(",")[0] == "0.033333333"
