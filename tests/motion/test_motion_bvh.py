"""BVH reader/writer: real samples, their quirks, malformed files and round trips."""
from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from motion_helpers import ALL_SAMPLES, BEAT_SAMPLE, MIXAMO_SAMPLE, PYBVH_SAMPLE, SMALL_BVH, write
from studyapp.errors import InputError
from studyapp.motion.beat import BEAT_JOINTS
from studyapp.motion.bvh import BvhWarning, read_bvh, read_bvh_channels, write_bvh
from studyapp.motion.fk import figure_height, joint_positions
from studyapp.motion.rotations import euler_to_quat, quat_to_matrix


# --- real samples -----------------------------------------------------------------------------


def test_beat_sample_hierarchy_units_and_first_values():
    d = read_bvh_channels(BEAT_SAMPLE)
    sk = d.skeleton
    assert sk.names == BEAT_JOINTS and d.channels.shape == (3, 228)
    assert sk.channels[0] == ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
    assert sk.names[sk.parents[sk.index("RightHandPinky")]] == "RightHandRing"
    assert sk.names[sk.parents[sk.index("RightHandThumb1")]] == "RightHandIndex"
    assert sk.unit_scale == 0.01 and len(sk.end_sites) == 13
    np.testing.assert_allclose(d.channels[0, :4], [-0.066987, -0.03775, -0.029248, -10.33119])
    # the writer cut the exponent's last digit: "-0.000000e+0" is still read, as zero
    assert d.channels[0, -1] == 0.0
    m = read_bvh(BEAT_SAMPLE)
    assert m.fps == 120.0  # the header (wrong for this file, see below)
    assert read_bvh(BEAT_SAMPLE, fps=15).fps == 15.0
    assert 170 < figure_height(m) < 190


def test_mixamo_sample_tabs_trailing_spaces_and_zyx():
    m = read_bvh(MIXAMO_SAMPLE)
    sk = m.skeleton
    assert sk.n_joints == 55 and sk.names[0] == "mixamorig:Hips" and m.fps == 30.0
    assert all(sk.rotation_order(j) == "ZYX" for j in range(sk.n_joints))
    np.testing.assert_allclose(sk.offsets[1], [0.0, 9.9235, -1.2273])
    np.testing.assert_allclose(m.translations[0, 0], [-0.2399, 98.2948, -0.5224])
    # root rotation is Z Y X in that order: 3.8145, 5.7945, -9.2380 degrees
    expect = euler_to_quat([3.8145, 5.7945, -9.2380], "ZYX")
    np.testing.assert_allclose(quat_to_matrix(m.rotations[0, 0]), quat_to_matrix(expect), atol=1e-12)
    assert sk.unit_scale == 0.01


def test_pybvh_sample_unknown_scale():
    m = read_bvh(PYBVH_SAMPLE)
    assert m.skeleton.n_joints == 24 and m.skeleton.unit_scale is None
    assert 55 < figure_height(m.skeleton) < 70


@pytest.mark.parametrize("sample", ALL_SAMPLES, ids=lambda p: p.stem)
def test_samples_round_trip_exactly(sample, tmp_path):
    d = read_bvh_channels(sample)
    out = tmp_path / "rt.bvh"
    write_bvh(read_bvh(sample), out)
    d2 = read_bvh_channels(out)
    assert d2.skeleton.names == d.skeleton.names and d2.skeleton.channels == d.skeleton.channels
    np.testing.assert_array_equal(d2.skeleton.parents, d.skeleton.parents)
    np.testing.assert_allclose(d2.skeleton.offsets, d.skeleton.offsets, atol=1e-6)
    assert sorted(d2.skeleton.end_sites) == sorted(d.skeleton.end_sites)
    np.testing.assert_allclose(d2.channels, d.channels, atol=1e-5)
    assert abs(d2.frame_time - d.frame_time) < 1e-9


@pytest.mark.parametrize("sample", ALL_SAMPLES, ids=lambda p: p.stem)
@pytest.mark.parametrize("order", ["ZXY", "XYZ", "YZX"])
def test_order_conversion_keeps_world_positions(sample, order, tmp_path):
    m = read_bvh(sample)
    out = tmp_path / "o.bvh"
    write_bvh(m, out, order=order)
    m2 = read_bvh(out)
    assert all(m2.skeleton.rotation_order(j) == order for j in range(m2.skeleton.n_joints))
    tol = 1e-4 * figure_height(m.skeleton)
    np.testing.assert_allclose(joint_positions(m2), joint_positions(m), atol=tol)


def test_modified_motion_is_written_from_rotations(tmp_path):
    m = read_bvh(write(tmp_path, SMALL_BVH))
    m.rotations[:, 1] = euler_to_quat([0.0, 0.0, 45.0], "ZXY")
    write_bvh(m, tmp_path / "mod.bvh")
    d = read_bvh_channels(tmp_path / "mod.bvh")
    np.testing.assert_allclose(d.channels[:, 6:9], [[0, 0, 45], [0, 0, 45]], atol=1e-6)


# --- quirks -----------------------------------------------------------------------------------


def test_header_frame_count_disagreeing_warns_and_trusts_data(tmp_path):
    p = write(tmp_path, SMALL_BVH.replace("Frames: 2", "Frames: 3"))
    with pytest.warns(BvhWarning, match="Frames: 3.*2 data lines"):
        d = read_bvh_channels(p)
    assert d.n_frames == 2 and d.header_frames == 3 and d.warnings


def test_float_frame_count_blank_lines_crlf_and_glued_braces(tmp_path):
    text = SMALL_BVH.replace("Frames: 2", "Frames: 2.0").replace("\nMOTION", "\n\nMOTION")
    text = text.replace("ROOT Hips\n{", "ROOT Hips {").replace("\n", "\r\n") + "\r\n\r\n"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = read_bvh(write(tmp_path, text))
    assert m.n_frames == 2 and m.fps == 30.0
    np.testing.assert_allclose(m.translations[1, 0], [1.5, 91.0, 2.5])


def test_position_channels_on_a_child_joint_replace_its_offset(tmp_path):
    text = SMALL_BVH.replace("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 4 Yposition Zrotation Xrotation Yrotation")
    text = text.replace("5.0 6.0 7.0", "12.5 5.0 6.0 7.0").replace("8.0 9.0 10.0", "13.5 8.0 9.0 10.0")
    m = read_bvh(write(tmp_path, text))
    np.testing.assert_allclose(m.translations[:, 1], [[0, 12.5, 0], [0, 13.5, 0]])


def test_dangling_exponent_is_read_as_mantissa(tmp_path):
    text = SMALL_BVH.replace("7.0\n1.5", "7.5e+\n1.5")
    d = read_bvh_channels(write(tmp_path, text))
    assert d.channels[0, -1] == 7.5


# --- malformed input --------------------------------------------------------------------------

BAD = {
    "wrong channel count": (SMALL_BVH.replace("8.0 9.0 10.0", "8.0 9.0"), 20, "2 .*9 channels|8 values"),
    "extra value": (SMALL_BVH.replace("5.0 6.0 7.0", "5.0 6.0 7.0 1.0"), 19, "10 values"),
    "nan": (SMALL_BVH.replace("6.0 7.0", "nan 7.0"), 19, "finite"),
    "inf": (SMALL_BVH.replace("9.0 10.0", "inf 10.0"), 20, "finite"),
    "not a number": (SMALL_BVH.replace("6.0 7.0", "6.0 abc"), 19, "not a number"),
    "unknown channel": (SMALL_BVH.replace("Zrotation Xrotation Yrotation\n\t\tEnd", "Zrotation Xrotation Wrotation\n\t\tEnd"), 9, "unknown channel 'Wrotation'"),
    "missing brace": (SMALL_BVH.replace("\t\t}\n\t}\n}", "\t\t}\n\t}"), 2, "never closed|missing"),
    "missing open brace": (SMALL_BVH.replace("\tJOINT Spine\n\t{", "\tJOINT Spine"), 7, "expected '\\{'"),
    "empty motion": (SMALL_BVH.split("1.0 90.0")[0], 19, "no motion data"),
    "no motion section": (SMALL_BVH.split("MOTION")[0], None, "MOTION"),
    "channel count too high": (SMALL_BVH.replace("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation"), 9, "declares 4 channels but lists 3"),
    "bad offset": (SMALL_BVH.replace("OFFSET 0.0 10.0 0.0", "OFFSET 0.0 ten 0.0"), 8, "number"),
    "not bvh": ("name,value\na,1\n", 1, "not a BVH file"),
    "bad frame time": (SMALL_BVH.replace("Frame Time: 0.0333333", "Frame Time: fast"), 18, "frame time"),
    "missing frames line": (SMALL_BVH.replace("Frames: 2\n", ""), 17, "Frames"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_malformed_files_name_file_line_and_problem(case, tmp_path):
    text, line, pattern = BAD[case]
    p = write(tmp_path, text, "bad.bvh")
    with pytest.raises(InputError) as err:
        read_bvh(p)
    e = err.value
    assert e.path == str(p)
    if line is not None:
        assert e.where == f"line {line}", str(e)
    assert re.search(pattern, e.problem), str(e)


def test_truncated_file_names_last_line(tmp_path):
    text = SMALL_BVH[: SMALL_BVH.rindex("9.0")]
    with pytest.raises(InputError, match="line 20.*truncated"):
        read_bvh(write(tmp_path, text))


def test_binary_file_is_rejected(tmp_path):
    p = tmp_path / "x.bvh"
    p.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00\x00")
    with pytest.raises(InputError, match="not a BVH file"):
        read_bvh(p)


# --- generated skeletons, layouts and whitespace ----------------------------------------------

_CHANNELS = ["Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation"]


@st.composite
def bvh_files(draw):
    n = draw(st.integers(1, 7))
    parents = [-1] + [draw(st.integers(0, j - 1)) for j in range(1, n)]
    layouts = []
    for j in range(n):
        chosen = draw(st.lists(st.sampled_from(_CHANNELS), unique=True, max_size=6, min_size=0 if j else 1))
        layouts.append(chosen)
    offsets = draw(st.lists(st.tuples(*[st.floats(-50, 50, allow_nan=False).map(lambda v: round(v, 4))] * 3), min_size=n, max_size=n))
    leaves = [j for j in range(n) if j not in parents[1:]]
    ends = {j: (0.0, round(draw(st.floats(0.5, 9)), 4), 0.0) for j in leaves if draw(st.booleans())}
    frames = draw(st.integers(1, 4))
    n_ch = sum(len(c) for c in layouts)
    values = np.array(draw(st.lists(st.floats(-360, 360, allow_nan=False).map(lambda v: round(v, 5)),
                                    min_size=frames * n_ch, max_size=frames * n_ch))).reshape(frames, n_ch)
    sep = draw(st.sampled_from([" ", "\t", "  ", " \t"]))
    indent = draw(st.sampled_from(["\t", "  ", ""]))
    trail = draw(st.sampled_from(["", " ", "\t"]))
    lines = ["HIERARCHY"]

    def emit(j, depth):
        ind = indent * depth
        lines.append(f"{ind}{'ROOT' if parents[j] < 0 else 'JOINT'} J{j}{trail}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}{indent}OFFSET{sep}{sep.join(str(v) for v in offsets[j])}{trail}")
        if layouts[j] or j == 0:
            lines.append(f"{ind}{indent}CHANNELS {len(layouts[j])} {' '.join(layouts[j])}{trail}")
        for c in range(n):
            if parents[c] == j:
                emit(c, depth + 1)
        if j in ends:
            lines.extend([f"{ind}{indent}End Site", f"{ind}{indent}{{", f"{ind}{indent * 2}OFFSET {' '.join(map(str, ends[j]))}", f"{ind}{indent}}}"])
        lines.append(f"{ind}}}")

    emit(0, 0)
    lines += ["MOTION", f"Frames:{sep}{frames}", f"Frame Time:{sep}0.04"]
    lines += [sep.join(repr(float(v)) for v in row) + trail for row in values]
    return "\n".join(lines) + "\n", parents, layouts, np.array(offsets), ends, values


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(case=bvh_files())
def test_generated_files_parse_and_round_trip(case, tmp_path):
    text, parents, layouts, offsets, ends, values = case
    # depth-first numbering is what the reader produces; map generated ids to read order
    p = write(tmp_path, text, "gen.bvh")
    d = read_bvh_channels(p)
    order = [int(n[1:]) for n in d.skeleton.names]
    assert sorted(order) == list(range(len(parents)))
    for new, old in enumerate(order):
        assert d.skeleton.channels[new] == tuple(layouts[old])
        np.testing.assert_allclose(d.skeleton.offsets[new], offsets[old])
        par = d.skeleton.parents[new]
        assert (par < 0 and parents[old] < 0) or order[par] == parents[old]
    assert {order[k] for k in d.skeleton.end_sites} == set(ends)
    # the file's channel columns follow the depth-first order too, which emit() also used
    np.testing.assert_allclose(d.channels, values, atol=1e-9)
    out = tmp_path / "gen_rt.bvh"
    write_bvh(read_bvh(p), out)
    d2 = read_bvh_channels(out)
    assert d2.skeleton.names == d.skeleton.names and d2.skeleton.channels == d.skeleton.channels
    np.testing.assert_allclose(d2.channels, d.channels, atol=1e-5)
