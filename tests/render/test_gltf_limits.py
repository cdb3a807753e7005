"""Each size, index and path a glTF file claims is checked before it is trusted: one malformed real file per
limit (CesiumMan, edited in one place), refused with one InputError naming the file and the JSON place."""
from __future__ import annotations

import base64
import os
import struct
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from gltf_mutations import dump_json, pack_glb, split_glb
from render_helpers import SAMPLES
from studyapp.errors import InputError
from studyapp.render.avatar_report import summarize_avatar
from studyapp.render.gltf import load_gltf

CESIUM = SAMPLES / "avatars" / "CesiumMan.glb"
# CesiumMan's layout (see the file): the primitive's attributes and the skin's matrices
INDICES, JOINTS, NORMAL, POSITION, TEXCOORD, WEIGHTS, IBM = 0, 1, 2, 3, 4, 5, 82
POSITION_VIEW, IBM_VIEW, IMAGE_VIEW = 2, 7, 8


def _edited(tmp_path: Path, edit: Callable[[dict, bytearray], None], name: str = "avatar.glb") -> Path:
    doc, binary = split_glb(CESIUM.read_bytes())
    binary = bytearray(binary)
    edit(doc, binary)
    path = tmp_path / name
    path.write_bytes(pack_glb(doc, bytes(binary)))
    return path


def _refused(path: Path, where: str, *words: str) -> InputError:
    with pytest.raises(InputError) as caught:
        load_gltf(path)
    err = caught.value
    assert err.path == str(path) and err.where == where, str(err)
    assert "\n" not in str(err)
    for w in words:
        assert w in err.problem, str(err)
    return err


def _ibm_offset(doc: dict, k: int) -> int:
    return doc["bufferViews"][IBM_VIEW]["byteOffset"] + 64 * k


def test_the_unedited_file_loads(tmp_path: Path) -> None:
    avatar = load_gltf(_edited(tmp_path, lambda doc, b: None))
    assert avatar.n_vertices == 3273 and avatar.skeleton.n_joints == 19


# --- byte ranges ---------------------------------------------------------------------------

def test_accessor_reading_past_its_buffer_view(tmp_path: Path) -> None:
    # POSITION ends exactly at its view's end; one more element reads the next view's bytes
    def edit(doc: dict, b: bytearray) -> None:
        doc["accessors"][POSITION]["count"] += 1
    _refused(_edited(tmp_path, edit), f"key accessors[{POSITION}].count", "3274 elements", "bufferView 2 has 78552")


def test_buffer_view_past_its_buffer(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["bufferViews"][IMAGE_VIEW]["byteLength"] += 1_000_000
    _refused(_edited(tmp_path, edit), f"key bufferViews[{IMAGE_VIEW}].byteLength", "buffer 0, which has 637192")


def test_byte_stride_shorter_than_an_element(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["bufferViews"][POSITION_VIEW]["byteStride"] = 8
    _refused(_edited(tmp_path, edit), f"key bufferViews[{POSITION_VIEW}].byteStride", "shorter than one element")


def test_negative_count(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["accessors"][INDICES]["count"] = -3
    _refused(_edited(tmp_path, edit), f"key accessors[{INDICES}].count", "-3 is out of range")


def test_huge_count_without_data_is_refused_before_allocating(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        del doc["accessors"][IBM]["bufferView"]
        doc["accessors"][IBM]["count"] = 2**40
    _refused(_edited(tmp_path, edit), f"key accessors[{IBM}].count", "without a bufferView")


def test_attribute_count_differs_from_the_vertex_count(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["accessors"][NORMAL]["count"] -= 1
    _refused(_edited(tmp_path, edit), "key meshes[0].primitives[0].attributes.NORMAL", "3272 elements", "3273 vertices")


def test_float_joint_indices(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["accessors"][JOINTS]["componentType"] = 5126
    _refused(_edited(tmp_path, edit), "key meshes[0].primitives[0].attributes.JOINTS_0", "not unsigned integers")


def test_glb_chunk_longer_than_the_file(tmp_path: Path) -> None:
    path = tmp_path / "avatar.glb"
    raw = bytearray(CESIUM.read_bytes())
    raw[12:16] = struct.pack("<I", 2**31)
    path.write_bytes(bytes(raw))
    _refused(path, "byte 12", "runs past the end of the file")


# --- indices and the node hierarchy --------------------------------------------------------

def test_index_into_a_missing_array_item(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"] = 4000
    _refused(_edited(tmp_path, edit), "key meshes[0].primitives[0].attributes.TEXCOORD_0", "the file has 83 accessors")


def test_node_that_is_its_own_ancestor(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:  # leg_joint_R_5 (7) gets the root (0) as its child
        doc["nodes"][7]["children"] = [0]
    _refused(_edited(tmp_path, edit), "key nodes[7].children", "node 0 is its own ancestor")


def test_node_with_two_parents(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["nodes"][7]["children"] = [5]  # 5 is already the child of 4
    _refused(_edited(tmp_path, edit), "key nodes[7].children", "child of both node 4 and node 7")


def test_node_hierarchy_too_deep(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        start = len(doc["nodes"])
        doc["nodes"] += [{"children": [start + k + 1]} for k in range(999)] + [{"mesh": 0}]
        doc["nodes"][7]["children"] = [start]
    _refused(_edited(tmp_path, edit), "key nodes[272]", "levels below its root")


# --- skins ---------------------------------------------------------------------------------

def test_fewer_inverse_bind_matrices_than_joints(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["accessors"][IBM]["count"] = 10
    _refused(_edited(tmp_path, edit), "key skins[0].inverseBindMatrices", "10 matrices for 19 joints")


def test_singular_inverse_bind_matrix(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        at = _ibm_offset(doc, 4)
        b[at: at + 64] = bytes(60) + struct.pack("<f", 1.0)
    _refused(_edited(tmp_path, edit), "key skins[0].inverseBindMatrices", "matrix 4: singular")


# --- numbers -------------------------------------------------------------------------------

def test_nan_position(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        at = doc["bufferViews"][POSITION_VIEW]["byteOffset"] + doc["accessors"][POSITION]["byteOffset"] + 12 * 17
        b[at: at + 4] = struct.pack("<f", float("nan"))
    _refused(_edited(tmp_path, edit), f"key accessors[{POSITION}]", "element 17 is not a finite number")


def test_nan_in_a_node_rotation(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["nodes"][4]["rotation"] = [float("nan"), 0.0, 0.0, 1.0]
    _refused(_edited(tmp_path, edit), "key nodes[4].rotation[0]", "finite number")


def test_node_transform_overflowing(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["nodes"][3]["scale"] = [1e200, 1e200, 1e200]
        doc["nodes"][4]["scale"] = [1e200, 1e200, 1e200]
    _refused(_edited(tmp_path, edit), "key nodes[4]", "overflows")


def test_wrong_json_type(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["buffers"][0]["byteLength"] = {"a": 1}
    _refused(_edited(tmp_path, edit), "key buffers[0].byteLength", "must be an integer, not an object")


def test_json_nested_100000_deep(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["extras"], doc["extras_depth"] = "@DEEP@", 100_000
    _refused(_edited(tmp_path, edit), "JSON chunk", "nested 100001 levels deep")


def test_json_number_with_5000_digits(tmp_path: Path) -> None:
    path = tmp_path / "avatar.gltf"
    path.write_text('{"asset": {"version": "2.0"}, "nodes": [{"name": "a", "scale": [' + "7" * 5000 + ", 1, 1]}]}")
    _refused(path, None, "invalid JSON")


# --- files outside the glTF's folder, images -------------------------------------------------

def _split_gltf(tmp_path: Path, uri: str) -> Path:
    doc, binary = split_glb(CESIUM.read_bytes())
    (tmp_path / "outside.bin").write_bytes(binary)  # a perfectly good buffer, but not the glTF's to read
    folder = tmp_path / "avatar"
    folder.mkdir()
    doc["buffers"][0]["uri"] = uri
    path = folder / "avatar.gltf"
    path.write_bytes(dump_json(doc))
    return path


@pytest.mark.parametrize("uri", ["../outside.bin", "%2E%2E/outside.bin", "ABSOLUTE", "file://ABSOLUTE"])
def test_buffer_uri_outside_the_folder_is_not_opened(tmp_path: Path, uri: str) -> None:
    uri = uri.replace("ABSOLUTE", str(tmp_path / "outside.bin"))
    _refused(_split_gltf(tmp_path, uri), "key buffers[0].uri", "leads outside the glTF's folder")


def test_buffer_uri_through_a_symbolic_link_leading_outside(tmp_path: Path) -> None:
    path = _split_gltf(tmp_path, "inside.bin")
    os.symlink(tmp_path / "outside.bin", path.parent / "inside.bin")
    _refused(path, "key buffers[0].uri", "leads outside the glTF's folder")


def test_buffer_uri_inside_the_folder_loads(tmp_path: Path) -> None:
    path = _split_gltf(tmp_path, "bin/avatar.bin")
    (path.parent / "bin").mkdir()
    (tmp_path / "outside.bin").rename(path.parent / "bin" / "avatar.bin")
    assert load_gltf(path).n_vertices == 3273


def _png_header(width: int, height: int) -> bytes:
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\0" * 64)) + chunk(b"IEND", b""))


def test_texture_claiming_too_many_pixels(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["images"][0] = {"uri": "data:image/png;base64," + base64.b64encode(_png_header(10000, 10000)).decode()}
    _refused(_edited(tmp_path, edit), "images[0]", "10000 x 10000 pixels", "scale it down")


def test_bad_base64_image(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["images"][0] = {"uri": "data:image/png;base64,A"}
    _refused(_edited(tmp_path, edit), "key images[0].uri", "bad base64")


def test_inspect_reports_a_malformed_file_instead_of_crashing(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["extensionsRequired"] = [1, "KHR_materials_unlit"]
    report = summarize_avatar(_edited(tmp_path, edit))
    assert report["extensions_required"] == ["KHR_materials_unlit"]
    assert report["problems"] == ["key extensionsRequired[0]: must be a string, not an integer (1)"
                                  + "; the file is damaged or breaks the glTF 2.0 rules: download or export it "
                                  "again (the Khronos glTF Validator shows what is wrong)"]


def test_limits_keep_real_avatars_bit_identical(tmp_path: Path) -> None:
    # the checked reader returns exactly the arrays a plain read of the accessors gives
    doc, binary = split_glb(CESIUM.read_bytes())
    view = doc["bufferViews"][POSITION_VIEW]
    start = view["byteOffset"] + doc["accessors"][POSITION]["byteOffset"]
    raw = np.frombuffer(binary, np.float32, 3273 * 3, start).reshape(3273, 3)
    from studyapp.render.gltf import _Doc

    np.testing.assert_array_equal(_Doc(CESIUM).accessor(POSITION), raw)


def test_meshopt_view_decoding_to_too_many_bytes(tmp_path: Path) -> None:
    doc, binary = split_glb((SAMPLES / "avatars" / "RobotExpressive.gltfpack-khr.glb").read_bytes())
    k, view = next((k, v) for k, v in enumerate(doc["bufferViews"])
                   if "KHR_meshopt_compression" in v.get("extensions", {}))
    # 2**26 elements of 4 bytes or more: 256 MiB or more from a few kB, refused before decoding
    view["extensions"]["KHR_meshopt_compression"]["count"] = 2**26
    path = tmp_path / "avatar.glb"
    path.write_bytes(pack_glb(doc, binary))
    _refused(path, f"key bufferViews[{k}].extensions.KHR_meshopt_compression.count", "at most 67108864 are decoded")


def test_accessor_of_zero_elements(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        prim = doc["meshes"][0]["primitives"][0]
        prim["attributes"] = {"POSITION": POSITION}
        del prim["indices"]
        doc["accessors"][POSITION]["count"] = 0
    _refused(_edited(tmp_path, edit), f"key accessors[{POSITION}].count", "0 is out of range (1 to")


def test_a_part_hidden_by_a_zero_scale_is_left_out_not_a_crash(tmp_path: Path) -> None:
    # the VRM 1.0 sample's rigid props hang from bones; hiding one with scale 0 must not stop the others
    doc, binary = split_glb((SAMPLES / "avatars" / "VRMC_vrm_expressions_isBinary_Overrides.vrm").read_bytes())
    whole = load_gltf(SAMPLES / "avatars" / "VRMC_vrm_expressions_isBinary_Overrides.vrm")
    doc["nodes"][25]["scale"] = [0.0, 0.0, 0.0]  # "Meter Happy", mesh 2
    path = tmp_path / "avatar.vrm"
    path.write_bytes(pack_glb(doc, binary))
    avatar = load_gltf(path)
    assert "meshes[2].primitives[0]: its node 25 has a zero scale, not drawn" in avatar.notes
    assert avatar.n_vertices == whole.n_vertices - 4


def test_too_many_nodes(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["nodes"] += [{} for _ in range(20_000)]
    _refused(_edited(tmp_path, edit), "key nodes", "20022 nodes; at most 16384")


def test_json_with_too_many_values(tmp_path: Path) -> None:
    def edit(doc: dict, b: bytearray) -> None:
        doc["extras"] = [0] * 2_100_000
    _refused(_edited(tmp_path, edit), "JSON chunk", "at most 2000000 are read")


def test_textures_over_the_total_pixel_budget(monkeypatch: pytest.MonkeyPatch) -> None:
    # CesiumMan's one real texture (1024 x 1024) against a budget lowered below it: the sum is checked as
    # each texture is decoded, so many small-in-the-file, large-in-memory images stop at the budget
    import studyapp.render.gltf as gltf

    monkeypatch.setattr(gltf, "MAX_TEXTURE_PIXELS_TOTAL", 1024 * 1024 - 1)
    _refused(CESIUM, "key images[0]", "1048576 pixels; at most 1048575")


@pytest.mark.parametrize("target", ["/dev/zero", "fifo"])
def test_avatar_path_that_is_not_a_regular_file(tmp_path: Path, target: str) -> None:
    # read_bytes() on either would never return (a FIFO blocks, /dev/zero never ends)
    if target == "fifo":
        os.mkfifo(tmp_path / "fifo")
        target = str(tmp_path / "fifo")
    path = tmp_path / "avatar.glb"
    os.symlink(target, path)
    _refused(path, None, "not a regular file")
    report_error = pytest.raises(InputError, summarize_avatar, path)
    assert "not a regular file" in str(report_error.value)


def test_json_shape_skips_strings_with_escapes_in_linear_time() -> None:
    import time

    from studyapp.render.gltf_schema import json_shape

    # an escaped quote stays inside its string; an escaped backslash before a quote ends it
    assert json_shape(rb'{"a": "x\"[[[", "b": ["y\\", 1]}') == (2, 8)
    assert json_shape(rb'["\\\"]]]"]') == (1, 2)
    # a megabyte of escaped quotes (a regular expression over strings retries from every quote: quadratic)
    start = time.perf_counter()
    assert json_shape(b'["' + b'\\"' * 500_000 + b'"]') == (1, 2)
    assert time.perf_counter() - start < 2.0


def test_json_shape_is_the_same_read_in_small_chunks() -> None:
    import random

    from studyapp.render.gltf_schema import json_shape

    rng = random.Random(3)
    alphabet = b'[]{},:"\\\\ab'
    for _ in range(300):
        text = bytes(rng.choice(alphabet) for _ in range(rng.randrange(1, 60)))
        whole = json_shape(text)
        for chunk in (1, 2, 3, 7):
            assert json_shape(text, chunk) == whole, (text, chunk)
    # and on a real document
    doc, _ = split_glb(CESIUM.read_bytes())
    text = dump_json(doc)
    assert json_shape(text, 1000) == json_shape(text) == (6, 3884)


def test_json_shape_depth_matches_the_parsed_document() -> None:
    import json
    import random

    from studyapp.render.gltf_schema import json_shape

    rng = random.Random(5)

    def value(level: int) -> tuple[object, int]:
        kind = rng.random()
        if level > 6 or kind < 0.3:
            return "".join(rng.choice('ab"\\[]{},:') for _ in range(rng.randrange(6))), 0
        items = [value(level + 1) for _ in range(rng.randrange(4))]
        deepest = 1 + max((d for _, d in items), default=0)
        if kind < 0.65:
            return [v for v, _ in items], deepest
        return {f"k{i}\\\"[": v for i, (v, _) in enumerate(items)}, deepest

    for _ in range(200):
        doc, deepest = value(0)
        assert json_shape(json.dumps(doc).encode(), 5)[0] == deepest, json.dumps(doc)
