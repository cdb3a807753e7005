"""An SMPL-X file's face as ARKit weights: the jaw drives jawOpen (0..25 degrees -> 0..1), FLAME expressions
only through the user's (E, 52) map; `studyapp convert X.npz face.csv` writes it for a stimulus."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from studyapp.cli import main
from studyapp.face.arkit import ARKIT_INDEX, ARKIT_NAMES
from studyapp.face.io import load_face
from studyapp.face.smplx import jaw_open_weight, smplx_face

BEAT2 = Path(__file__).resolve().parents[1] / "data" / "samples" / "motion" / "beat2_smplx_2_scott_0_1_1_excerpt.npz"


def test_jaw_opening_is_the_downward_turn_of_the_chin_scaled_to_25_degrees():
    # a jaw opened 10 degrees about x and also turned 20 degrees sideways (about y, after the opening):
    # the chin still points 10 degrees down
    opened = Rotation.from_euler("YX", [20.0, 10.0], degrees=True).as_rotvec()
    sideways = Rotation.from_euler("Y", 20.0, degrees=True).as_rotvec()
    jaw = np.array([opened, sideways, [np.radians(-5.0), 0, 0], [np.radians(30.0), 0, 0]])
    np.testing.assert_allclose(jaw_open_weight(jaw), [10 / 25, 0.0, 0.0, 1.0], atol=1e-9)


def test_flame_expressions_need_a_map_and_are_then_mapped_linearly():
    f = 3
    jaw = np.zeros((f, 3))
    jaw[:, 0] = np.radians([0.0, 5.0, 20.0])
    expr = np.zeros((f, 100))
    expr[:, 0] = [0.0, 1.0, 2.0]
    with pytest.warns(UserWarning, match="100 FLAME expression coefficients ignored"):
        plain = smplx_face(jaw, 30.0, expr)
    assert np.count_nonzero(plain.weights[:, ARKIT_INDEX["jawopen"]]) == 2
    assert np.count_nonzero(np.delete(plain.weights, ARKIT_INDEX["jawopen"], axis=1)) == 0
    fmap = np.zeros((100, 52))
    fmap[0, ARKIT_NAMES.index("mouthSmileLeft")] = 0.3
    fmap[0, ARKIT_NAMES.index("jawOpen")] = 0.1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mapped = smplx_face(jaw, 30.0, expr, fmap)
    np.testing.assert_allclose(mapped.weight("mouthSmileLeft"), [0.0, 0.3, 0.6], atol=1e-6)
    # jawOpen: the larger of the map's (0, 0.1, 0.2) and the jaw's (0, 0.2, 0.8)
    np.testing.assert_allclose(mapped.weight("jawOpen"), [0.0, 0.2, 0.8], atol=1e-6)


def test_convert_writes_the_beat2_jaw_as_a_face_csv(tmp_path, capsys):
    out = tmp_path / "face.csv"
    assert main(["convert", str(BEAT2), str(out)]) == 0
    face = load_face(out)
    raw = np.load(BEAT2)["poses"].reshape(-1, 55, 3)[:, 22].astype(np.float64)
    # this file's jaw turns about x only (its other components stay under half a degree)
    expected = np.clip(np.degrees(raw[:, 0]) / 25.0, 0.0, 1.0)
    assert face.n_frames == 300 and face.fps == 30.0
    np.testing.assert_allclose(face.weight("jawOpen"), expected, atol=2e-3)
    assert face.weight("jawOpen").max() > 0.1
    assert "FLAME expression coefficients ignored" in capsys.readouterr().err


def test_a_flame_map_of_the_wrong_shape_is_refused_by_file(tmp_path, capsys):
    bad = tmp_path / "map.npy"
    np.save(bad, np.zeros((52, 100)))
    assert main(["convert", str(BEAT2), str(tmp_path / "f.csv"), "--flame-map", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "map.npy" in err and "(100, 52)" in err and len(err.strip().splitlines()) == 1
    good = tmp_path / "good.npy"
    np.save(good, np.zeros((100, 52)))
    assert main(["convert", str(BEAT2), str(tmp_path / "f.csv"), "--flame-map", str(good)]) == 0


def test_a_bvh_has_no_face_to_write(tmp_path, capsys):
    src = BEAT2.parent / "zeggs_067_Speech_2_x_1_0_excerpt.bvh"
    assert main(["convert", str(src), str(tmp_path / "f.csv")]) == 2
    assert "only an SMPL-X file's face" in capsys.readouterr().err
    assert not (tmp_path / "f.csv").exists()
