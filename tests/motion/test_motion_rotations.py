"""Rotation conversions against independently built matrices, plus hypothesis round trips."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from studyapp.motion import rotations as R


def axis_matrix(axis: str, deg: float) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return {
        "X": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        "Y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        "Z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    }[axis]


angles3 = st.tuples(*[st.floats(-180, 180, allow_nan=False)] * 3)
unit_quats = arrays(np.float64, 4, elements=st.floats(-1, 1, allow_nan=False)).filter(lambda q: np.linalg.norm(q) > 0.1)


@pytest.mark.parametrize("order", R.ORDERS)
def test_euler_is_intrinsic_product_in_channel_order(order):
    ang = np.array([31.0, -47.0, 112.0])
    expect = axis_matrix(order[0], ang[0]) @ axis_matrix(order[1], ang[1]) @ axis_matrix(order[2], ang[2])
    np.testing.assert_allclose(R.quat_to_matrix(R.euler_to_quat(ang, order)), expect, atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(order=st.sampled_from(R.ORDERS), ang=angles3)
def test_euler_round_trip_all_orders_via_matrices(order, ang):
    # compare matrices, not angles: at gimbal lock the angles are not unique but the rotation is
    q = R.euler_to_quat(np.array(ang), order)
    back = R.euler_to_quat(R.quat_to_euler(q, order), order)
    np.testing.assert_allclose(R.quat_to_matrix(back), R.quat_to_matrix(q), atol=1e-7)


@pytest.mark.parametrize("order", ["XYZ", "ZXY", "ZYX", "YXZ"])
def test_euler_gimbal_lock_still_reproduces_rotation(order):
    ang = np.array([[30.0, 90.0, 40.0], [10.0, -90.0, -70.0]])
    q = R.euler_to_quat(ang, order)
    back = R.quat_to_euler(q, order)
    np.testing.assert_allclose(R.quat_to_matrix(R.euler_to_quat(back, order)), R.quat_to_matrix(q), atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(q=unit_quats)
def test_representation_round_trips(q):
    q = q / np.linalg.norm(q)
    m = R.quat_to_matrix(q)
    for rep in ("axis_angle", "quat", "quat_wxyz", "sixd", "sixd_rows", "matrix"):
        back = R.to_quat(R.from_quat(q, rep), rep)
        np.testing.assert_allclose(R.quat_to_matrix(back), m, atol=1e-9, err_msg=rep)
    np.testing.assert_allclose(R.quat_to_matrix(R.matrix_to_quat(m)), m, atol=1e-9)


def test_sixd_layout_is_first_two_columns():
    m = axis_matrix("Z", 30) @ axis_matrix("X", 50)
    d6 = R.matrix_to_sixd(m)
    np.testing.assert_allclose(d6, [m[0, 0], m[1, 0], m[2, 0], m[0, 1], m[1, 1], m[2, 1]])
    # Gram-Schmidt: scaled / skewed columns still give the same rotation
    noisy = np.concatenate([d6[:3] * 3.0, d6[3:] * 0.5 + d6[:3] * 0.2])
    np.testing.assert_allclose(R.sixd_to_matrix(noisy), m, atol=1e-12)


def pytorch3d_rotation_6d_to_matrix(d6: np.ndarray) -> np.ndarray:
    """numpy transcription of PyTorch3D's ``rotation_6d_to_matrix``: Gram-Schmidt, stacked ``dim=-2`` (rows)."""
    a1, a2 = d6[..., :3], d6[..., 3:]
    b1 = a1 / np.linalg.norm(a1, axis=-1, keepdims=True)
    b2 = a2 - (b1 * a2).sum(-1, keepdims=True) * b1
    b2 = b2 / np.linalg.norm(b2, axis=-1, keepdims=True)
    return np.stack((b1, b2, np.cross(b1, b2)), axis=-2)


@pytest.mark.parametrize(
    "m,cols,rows",
    [
        # 90 degrees about Z: x -> y, y -> -x
        (axis_matrix("Z", 90), [0, 1, 0, -1, 0, 0], [0, -1, 0, 1, 0, 0]),
        # Rz(90) @ Rx(90) = [[0,0,1],[1,0,0],[0,1,0]]: a permutation whose six entries differ per layout
        (axis_matrix("Z", 90) @ axis_matrix("X", 90), [0, 1, 0, 0, 0, 1], [0, 0, 1, 1, 0, 0]),
    ],
)
def test_both_sixd_layouts_of_known_matrices(m, cols, rows):
    np.testing.assert_allclose(R.matrix_to_sixd(m), cols, atol=1e-15)
    np.testing.assert_allclose(R.matrix_to_sixd_rows(m), rows, atol=1e-15)
    np.testing.assert_allclose(R.sixd_to_matrix(np.array(cols, float)), m, atol=1e-15)
    np.testing.assert_allclose(R.sixd_rows_to_matrix(np.array(rows, float)), m, atol=1e-15)
    q = R.matrix_to_quat(m)
    np.testing.assert_allclose(R.from_quat(q, "sixd"), cols, atol=1e-15)
    np.testing.assert_allclose(R.from_quat(q, "sixd_rows"), rows, atol=1e-15)
    np.testing.assert_allclose(R.quat_to_matrix(R.to_quat(np.array(rows, float), "sixd_rows")), m, atol=1e-15)


def test_sixd_rows_matches_pytorch3d_flattening_batched():
    rng = np.random.default_rng(4)
    m = R.quat_to_matrix(R.quat_normalize(rng.normal(size=(5, 7, 4))))
    d6 = R.matrix_to_sixd_rows(m)
    # PyTorch3D matrix_to_rotation_6d: matrix[..., :2, :].reshape(batch_dim + (6,))
    np.testing.assert_array_equal(d6, m[..., :2, :].reshape(5, 7, 6))
    assert d6.shape == (5, 7, 6) and R.sixd_rows_to_quat(d6).shape == (5, 7, 4)
    np.testing.assert_allclose(R.sixd_rows_to_matrix(d6), m, atol=1e-12)
    # network output is not orthonormal: both sides orthogonalise the rows the same way
    noisy = d6 * rng.uniform(0.5, 2.0, size=(5, 7, 1)) + rng.normal(scale=0.1, size=d6.shape)
    np.testing.assert_allclose(R.sixd_rows_to_matrix(noisy), pytorch3d_rotation_6d_to_matrix(noisy), atol=1e-12)
    # read with the column layout, row data gives the transposed (inverse) rotation: the bug this avoids
    np.testing.assert_allclose(R.sixd_to_matrix(d6), np.swapaxes(m, -1, -2), atol=1e-12)
    single = np.eye(3)
    out = R.matrix_to_sixd_rows(single)
    out[0] = 5.0
    assert single[0, 0] == 1.0  # a copy, never a view into the caller's matrix


@settings(max_examples=60, deadline=None)
@given(q=unit_quats)
def test_sixd_layouts_are_each_others_transpose(q):
    m = R.quat_to_matrix(q / np.linalg.norm(q))
    np.testing.assert_allclose(R.matrix_to_sixd_rows(m), R.matrix_to_sixd(m.T), atol=1e-15)
    np.testing.assert_allclose(R.matrix_to_sixd_rows(m), m[:2, :].ravel(), atol=0)
    np.testing.assert_allclose(R.sixd_rows_to_matrix(R.matrix_to_sixd_rows(m)), m, atol=1e-12)


def test_axis_angle_and_multiply_against_matrices():
    v = np.array([0.0, 0.0, math.pi / 2])
    np.testing.assert_allclose(R.quat_to_matrix(R.axis_angle_to_quat(v)), axis_matrix("Z", 90), atol=1e-12)
    a, b = R.euler_to_quat([20.0, 0, 0], "XYZ"), R.euler_to_quat([0.0, 35.0, 0], "XYZ")
    np.testing.assert_allclose(R.quat_to_matrix(R.quat_multiply(a, b)), axis_matrix("X", 20) @ axis_matrix("Y", 35), atol=1e-12)
    np.testing.assert_allclose(R.quat_multiply(a, R.quat_inverse(a)), [0, 0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(R.quat_to_axis_angle(R.axis_angle_to_quat(v)), v, atol=1e-12)


def test_batched_shapes_and_empty():
    ang = np.random.default_rng(0).uniform(-180, 180, (5, 7, 3))
    q = R.euler_to_quat(ang, "ZXY")
    assert q.shape == (5, 7, 4) and R.quat_to_matrix(q).shape == (5, 7, 3, 3)
    assert R.quat_to_sixd(q).shape == (5, 7, 6) and R.sixd_to_quat(R.quat_to_sixd(q)).shape == (5, 7, 4)
    assert R.euler_to_quat(np.zeros((0, 3)), "XYZ").shape == (0, 4)


def test_slerp_halfway_and_short_arc():
    q0 = R.euler_to_quat([0.0, 0, 0], "XYZ")
    q1 = R.euler_to_quat([0.0, 0, 90.0], "XYZ")
    mid = R.quat_slerp(q0, q1, 0.5)
    np.testing.assert_allclose(R.quat_to_matrix(mid), axis_matrix("Z", 45), atol=1e-12)
    # -q1 is the same rotation: slerp must still take the 45 degree path
    np.testing.assert_allclose(R.quat_to_matrix(R.quat_slerp(q0, -q1, 0.5)), axis_matrix("Z", 45), atol=1e-12)
    np.testing.assert_allclose(R.quat_slerp(q0, q1, np.array([0.0, 1.0]))[1], q1, atol=1e-12)


def test_quat_between_maps_directions():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(20, 3)), rng.normal(size=(20, 3))
    q = R.quat_between(a, b)
    got = R.quat_rotate(q, a / np.linalg.norm(a, axis=1, keepdims=True))
    np.testing.assert_allclose(got, b / np.linalg.norm(b, axis=1, keepdims=True), atol=1e-9)
    opp = R.quat_between([1.0, 0, 0], [-1.0, 0, 0])
    np.testing.assert_allclose(R.quat_rotate(opp, [1.0, 0, 0]), [-1, 0, 0], atol=1e-12)


def test_bad_input_raises():
    with pytest.raises(ValueError):
        R.euler_to_quat([0, 0, 0], "XXY")
    with pytest.raises(ValueError):
        R.to_quat(np.zeros((3, 5)), "sixd")
    with pytest.raises(ValueError):
        R.to_quat(np.zeros(3), "euler")
    with pytest.raises(ValueError):
        R.quat_normalize(np.zeros(4))
    with pytest.raises(ValueError):
        R.to_quat(np.zeros(3), "bogus")
    with pytest.raises(ValueError, match="zero first row"):
        R.to_quat(np.zeros(6), "sixd_rows")
    with pytest.raises(ValueError, match="parallel rows"):
        R.sixd_rows_to_matrix(np.array([1.0, 0, 0, 2.0, 0, 0]))
    with pytest.raises(ValueError, match="zero first column"):
        R.sixd_to_matrix(np.zeros(6))
    assert R.representation_width("sixd_rows") == 6


def test_matrix_to_quat_matches_scipy_without_importing_it() -> None:
    """Proper rotations are converted in numpy (scipy.spatial costs ~0.8 s before a first frame), with
    scipy's canonical quaternions; the half-turns, where the trace is smallest, included."""
    import subprocess
    import sys

    from scipy.spatial.transform import Rotation

    half_turns = [Rotation.from_rotvec(np.pi * np.asarray(a, float) / np.linalg.norm(a)).as_matrix()
                  for a in ([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, -1, 1], [1, 1, 1])]
    ms = np.concatenate([Rotation.random(5000, random_state=3).as_matrix(), np.eye(3)[None], half_turns])
    np.testing.assert_allclose(R.matrix_to_quat(ms), Rotation.from_matrix(ms).as_quat(canonical=True), atol=1e-12)
    skewed = ms[:3] * 1.01  # not a rotation: scipy's projection, as before
    np.testing.assert_allclose(R.matrix_to_quat(skewed), Rotation.from_matrix(skewed).as_quat(canonical=True))
    code = ("import sys, numpy as np; from studyapp.motion.rotations import matrix_to_quat; "
            "matrix_to_quat(np.eye(3)[None].repeat(4, 0)); print('scipy.spatial' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() == "False"


def test_rotvec_and_matrix_conversions_are_scipys() -> None:
    """axis-angle and matrix conversions are numpy ports of scipy's (a participant's install has no scipy)."""
    from scipy.spatial.transform import Rotation

    from studyapp.motion.rotations import axis_angle_to_quat, matrix_to_quat, quat_to_axis_angle

    rng = np.random.default_rng(11)
    v = np.concatenate([rng.standard_normal((300, 3)) * s for s in (1e-7, 1e-4, 1e-3, 0.02, 1.0, 3.0, 10.0)]
                       + [np.zeros((1, 3)), [[np.pi, 0.0, 0.0]]])
    np.testing.assert_allclose(axis_angle_to_quat(v), Rotation.from_rotvec(v).as_quat(), rtol=0, atol=1e-15)
    q = rng.standard_normal((2000, 4)) * rng.uniform(0.1, 3.0, (2000, 1))
    q[:5, :3] *= 1e-6
    np.testing.assert_allclose(quat_to_axis_angle(q), Rotation.from_quat(q).as_rotvec(), rtol=0, atol=1e-14)
    # matrices off a rotation by up to 0.1 are projected to the nearest one, as scipy does
    m = Rotation.random(1000, random_state=3).as_matrix()
    m = m + rng.standard_normal(m.shape) * np.repeat([1e-13, 1e-10, 1e-6, 1e-3, 0.1], 200)[:, None, None]
    np.testing.assert_allclose(matrix_to_quat(m), Rotation.from_matrix(m).as_quat(canonical=True), rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="Non-positive determinant"):
        matrix_to_quat(np.diag([1.0, 1.0, -1.0]))
