"""EXT_meshopt_compression and KHR_mesh_quantization: the decoder against published vectors, and gltfpack-style
files (written here by a small encoder that follows the spec) decoding to the vertices of the uncompressed file.

gltfpack is not needed to run these tests: the small fixtures come from the encoder below;
the decoder is also checked on the byte streams from meshoptimizer's own test suite (demo/tests.cpp), which
its reference decoder turns into the listed values, and on two files gltfpack itself wrote (see below).
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from render_helpers import SAMPLES
from test_gltf import bar_gltf, write_gltf
from studyapp.errors import InputError
from studyapp.render.gltf import load_gltf
from studyapp.render.meshopt import MeshoptError, decode_view

# --- published vectors: zeux/meshoptimizer demo/tests.cpp (kVertexDataV0, kIndexDataV1, kIndexSequenceV1) ----

VERTEX_DATA_V0 = bytes([
    0xa0, 0x01, 0x3f, 0x00, 0x00, 0x00, 0x58, 0x57, 0x58, 0x01, 0x26, 0x00, 0x00, 0x00, 0x01,
    0x0c, 0x00, 0x00, 0x00, 0x58, 0x01, 0x08, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01,
    0x3f, 0x00, 0x00, 0x00, 0x17, 0x18, 0x17, 0x01, 0x26, 0x00, 0x00, 0x00, 0x01, 0x0c, 0x00,
    0x00, 0x00, 0x17, 0x01, 0x08, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00])
# struct PV { uint16 px, py, pz; uint8 nu, nv; uint16 tx, ty; } x 4
VERTEX_BUFFER = [((0, 0, 0), (0, 0), (0, 0)), ((300, 0, 0), (0, 0), (500, 0)),
                 ((0, 300, 0), (0, 0), (0, 500)), ((300, 300, 0), (0, 0), (500, 500))]
INDEX_DATA_V1 = bytes([0xe1, 0xf0, 0x10, 0xfe, 0x1f, 0x3d, 0x00, 0x0a, 0x00, 0x76, 0x87, 0x56, 0x67, 0x78, 0xa9,
                       0x86, 0x65, 0x89, 0x68, 0x98, 0x01, 0x69, 0x00, 0x00])
INDEX_BUFFER_TRICKY = [0, 1, 2, 2, 1, 3, 0, 1, 2, 2, 1, 5, 2, 1, 4]
INDEX_SEQUENCE_V1 = bytes([0xd1, 0x00, 0x04, 0xcd, 0x01, 0x04, 0x07, 0x98, 0x1f, 0x00, 0x00, 0x00, 0x00])
INDEX_SEQUENCE = [0, 1, 51, 2, 49, 1000]


def test_decoder_reproduces_the_reference_test_vectors():
    pv = np.dtype([("p", "<u2", 3), ("n", "u1", 2), ("t", "<u2", 2)])
    got = np.frombuffer(decode_view(VERTEX_DATA_V0, 4, 12, "ATTRIBUTES"), pv)
    assert [(tuple(r["p"]), tuple(r["n"]), tuple(r["t"])) for r in got] == VERTEX_BUFFER
    tri = np.frombuffer(decode_view(INDEX_DATA_V1, 15, 4, "TRIANGLES"), np.uint32)
    assert tri.tolist() == INDEX_BUFFER_TRICKY
    seq = np.frombuffer(decode_view(INDEX_SEQUENCE_V1, 6, 2, "INDICES"), np.uint16)
    assert seq.tolist() == INDEX_SEQUENCE


VERTEX_DATA_V1 = bytes([
    0xa1, 0xee, 0xaa, 0xee, 0x00, 0x4b, 0x4b, 0x4b, 0x00, 0x00, 0x4b, 0x00, 0x00, 0x7d, 0x7d, 0x7d,
    0x00, 0x00, 0x7d, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x62, 0x00, 0x62])
# "a valid v1 encoding ... that exercised all features of the format" (kVertexDataV1Custom)
VERTEX_DATA_V1_CUSTOM = bytes([
    0xa1, 0xd4, 0x94, 0xd4, 0x01, 0x0e, 0x00, 0x58, 0x57, 0x58, 0x02, 0x02, 0x12, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x03, 0x00, 0x00, 0x58, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x00, 0x02, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x03, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x0e, 0x00, 0x7d, 0x7d, 0x7d, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x7d, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x01, 0x62])


@pytest.mark.parametrize("stream", [VERTEX_DATA_V1, VERTEX_DATA_V1_CUSTOM])
def test_decoder_reproduces_the_version_1_reference_vectors(stream):
    # KHR_meshopt_compression's attribute format: control modes, literal bytes, 16-bit and rotated XOR deltas
    pv = np.dtype([("p", "<u2", 3), ("n", "u1", 2), ("t", "<u2", 2)])
    got = np.frombuffer(decode_view(stream, 4, 12, "ATTRIBUTES"), pv)
    assert [(tuple(r["p"]), tuple(r["n"]), tuple(r["t"])) for r in got] == VERTEX_BUFFER


def test_malformed_streams_are_refused():
    with pytest.raises(MeshoptError, match="header"):
        decode_view(b"\x00" + VERTEX_DATA_V0[1:], 4, 12, "ATTRIBUTES")
    with pytest.raises(MeshoptError, match="more than it decodes"):
        decode_view(VERTEX_DATA_V0[:1] + b"\x00" + VERTEX_DATA_V0[1:], 4, 12, "ATTRIBUTES")
    with pytest.raises(MeshoptError, match="unread"):
        decode_view(INDEX_SEQUENCE_V1[:-4] + b"\x00" + INDEX_SEQUENCE_V1[-4:], 6, 4, "INDICES")


# --- a small encoder written from the spec, for fixtures ---------------------------------------------------

def _zigzag8(d: np.ndarray) -> np.ndarray:
    d = d.astype(np.uint8)
    return np.where(d & 0x80, ~(d << 1), d << 1).astype(np.uint8)


def _encode_group(vals: np.ndarray) -> tuple[int, bytes]:
    """The smallest of the four group codings for 16 zigzag bytes."""
    if not vals.any():
        return 0, b""
    best = (3, bytes(vals))
    for mode, bits in ((1, 2), (2, 4)):
        sentinel = (1 << bits) - 1
        codes = np.minimum(vals, sentinel)
        per = 8 // bits
        packed = bytearray()
        for i in range(0, 16, per):
            b = 0
            for k in range(per):
                b = (b << bits) | int(codes[i + k])
            packed.append(b)
        extra = bytes(vals[vals >= sentinel])
        if len(packed) + len(extra) < len(best[1]):
            best = (mode, bytes(packed) + extra)
    return best


def encode_attributes(raw: bytes, count: int, stride: int) -> bytes:
    data = np.frombuffer(raw, np.uint8).reshape(count, stride)
    out = bytearray([0xA0])
    block = min((8192 // stride) & ~15, 256)
    last = data[0].copy()  # baseline: the first element itself
    for start in range(0, count, block):
        chunk = data[start: start + block]
        n = len(chunk)
        groups = (n + 15) // 16
        for k in range(stride):
            col = chunk[:, k].astype(np.int64)
            prev = np.r_[last[k], col[:-1]]
            z = np.zeros(groups * 16, np.uint8)
            z[:n] = _zigzag8((col - prev) & 0xFF)
            header = bytearray((groups + 3) // 4)
            body = bytearray()
            for g in range(groups):
                mode, payload = _encode_group(z[g * 16: g * 16 + 16])
                header[g // 4] |= mode << ((g % 4) * 2)
                body += payload
            out += header + body
        last = chunk[-1].copy()
    tail = max(stride, 32)
    out += bytes(tail - stride) + data[0].tobytes()
    return bytes(out)


def _leb(v: int) -> bytes:
    out = bytearray()
    while True:
        b = v & 0x7F
        v >>= 7
        out.append(b | (0x80 if v else 0))
        if not v:
            return bytes(out)


def encode_triangles(indices: np.ndarray) -> bytes:
    """Every triangle as code 0xff with three explicit zigzag index deltas (valid, if not small)."""
    codes, extra, last = bytearray(), bytearray(), 0
    for a, b, c in np.asarray(indices, np.int64).reshape(-1, 3):
        codes.append(0xFF)
        extra.append(0xFF)
        for v in (a, b, c):
            d = int(v) - last
            extra += _leb(((d << 1) ^ (d >> 31)) & 0xFFFFFFFF)
            last = int(v)
    return bytes([0xE1]) + bytes(codes) + bytes(extra) + bytes(16)


def test_encoder_and_decoder_agree_over_several_blocks_and_all_group_codings():
    rng = np.random.default_rng(3)
    count, stride = 700, 12  # blocks of 256: three blocks, the last one short
    smooth = np.cumsum(rng.integers(-3, 4, (count, 3)), 0).astype("<i4")  # small deltas: 2- and 4-bit groups
    noise = rng.integers(0, 2**31, (count, 1)).astype("<i4")  # raw groups
    raw = np.concatenate([smooth[:, :2], noise], 1).tobytes()
    enc = encode_attributes(raw, count, stride)
    assert len(enc) < len(raw)
    assert decode_view(enc, count, stride, "ATTRIBUTES") == raw
    tri = rng.integers(0, 5000, 90)
    assert np.frombuffer(decode_view(encode_triangles(tri), 90, 4, "TRIANGLES"), np.uint32).tolist() == tri.tolist()


def test_filters_decode_unit_vectors_quaternions_and_floats():
    rng = np.random.default_rng(5)
    n = rng.normal(size=(64, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    # octahedral encoding (spec appendix B, inverted), K = 12 bits in 16-bit components
    one = (1 << 11) - 1
    p = n[:, :2] / np.abs(n).sum(1, keepdims=True)
    neg = n[:, 2] < 0
    p[neg] = (1 - np.abs(p[neg][:, ::-1])) * np.where(p[neg] >= 0, 1, -1)
    q = np.c_[np.round(p * one), np.full(64, one), np.zeros(64)].astype("<i2")
    dec = np.frombuffer(decode_view(encode_attributes(q.tobytes(), 64, 8), 64, 8, "ATTRIBUTES", "OCTAHEDRAL"), "<i2")
    dec = dec.reshape(64, 4)[:, :3] / 32767.0
    assert np.abs(dec - n).max() < 2e-3
    # quaternion: largest component dropped, the rest scaled by sqrt(2), index in the low bits of the fourth
    quat = rng.normal(size=(32, 4))
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    big = np.abs(quat).argmax(1)
    quat *= np.where(quat[np.arange(32), big] < 0, -1, 1)[:, None]
    one = (1 << 15) - 1
    enc = np.zeros((32, 4), np.int64)
    for i in range(32):
        rest = [quat[i, (big[i] + 1 + k) % 4] for k in range(3)]
        enc[i, :3] = np.round(np.array(rest) * np.sqrt(2) * one)
        enc[i, 3] = (one & ~3) | big[i]
    dec = np.frombuffer(decode_view(encode_attributes(enc.astype("<i2").tobytes(), 32, 8), 32, 8, "ATTRIBUTES",
                                    "QUATERNION"), "<i2").reshape(32, 4) / 32767.0
    assert np.abs(dec - quat).max() < 2e-4
    # exponential: 2^e * m exactly
    vals = np.array([1.5, -0.25, 1024.0, 3.0e-3], np.float64)
    e = np.array([-20, -20, 0, -20])  # a 24-bit signed mantissa each
    m = np.round(vals / 2.0 ** e).astype(np.int64)
    packed = ((e.astype(np.int64) << 24) | (m & 0xFFFFFF)).astype(np.uint32).astype("<u4")
    enc = encode_attributes(packed.tobytes(), 4, 4)
    out = np.frombuffer(decode_view(enc, 4, 4, "ATTRIBUTES", "EXPONENTIAL"), "<f4")
    assert np.allclose(out, m * 2.0 ** e, rtol=1e-7) and np.allclose(out, vals, rtol=1e-4)  # 2^-20 steps


# --- gltfpack-style files ----------------------------------------------------------------------------------

def _compress(gltf: dict, data: bytes, *, rigid: bool) -> tuple[dict, bytes]:
    """The bar with quantized positions (uint16), normalized-short UVs, meshopt-compressed vertex and index
    views, and a placeholder fallback buffer: what gltfpack -cc writes. Positions are dequantized by the
    inverse bind matrices (skinned) or by the mesh node's scale and translation (``rigid``)."""
    g = json.loads(json.dumps(gltf))
    acc, views = g["accessors"], g["bufferViews"]

    def arr(i, dtype, width):
        v = views[acc[i]["bufferView"]]
        return np.frombuffer(data, dtype, acc[i]["count"] * width, v["byteOffset"]).reshape(-1, width)

    pos = arr(0, np.float32, 3).astype(np.float64)
    lo, hi = pos.min(0), pos.max(0)
    scale = float((hi - lo).max() / 65535)
    qpos = np.round((pos - lo) / scale).astype("<u2")
    qpos = np.c_[qpos, np.zeros(len(qpos), "<u2")]  # gltfpack pads positions to 8 bytes
    idx = arr(1, np.uint16, 1).reshape(-1)
    # UVs squeezed into [0.25, 0.75] and stretched back by KHR_texture_transform, as gltfpack does with bounds
    uv = np.round((arr(7, np.float32, 2) * 0.5 + 0.25) * 65535).astype("<u2")
    g["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"] = {
        "KHR_texture_transform": {"offset": [-0.5, -0.5], "scale": [2.0, 2.0]}}
    dq = np.eye(4)
    dq[:3, :3] *= scale
    dq[:3, 3] = lo
    ibm = arr(6, np.float32, 16).reshape(-1, 4, 4).transpose(0, 2, 1).astype(np.float64) @ dq
    ibm = np.ascontiguousarray(ibm.transpose(0, 2, 1), np.float32)
    comp = bytearray(data)
    streams = [(qpos.tobytes(), len(qpos), 8, "ATTRIBUTES"), (idx.astype("<u2").tobytes(), len(idx), 2, "TRIANGLES"),
               (uv.tobytes(), len(uv), 4, "ATTRIBUTES")]
    new_views = []
    fallback_len = 0
    for raw, count, stride, mode in streams:
        enc = raw if mode != "ATTRIBUTES" else encode_attributes(raw, count, stride)
        if mode == "TRIANGLES":
            enc = encode_triangles(np.frombuffer(raw, "<u2"))
        while len(comp) % 4:
            comp.append(0)
        ext = {"buffer": 0, "byteOffset": len(comp), "byteLength": len(enc), "byteStride": stride, "count": count,
               "mode": mode}
        comp += enc
        view = {"buffer": 1, "byteOffset": fallback_len, "byteLength": count * stride,
                "extensions": {"EXT_meshopt_compression": ext}}
        if mode == "ATTRIBUTES":
            view["byteStride"] = stride
        fallback_len += count * stride + (-count * stride) % 4
        new_views.append(view)
    while len(comp) % 4:
        comp.append(0)
    ibm_view = {"buffer": 0, "byteOffset": len(comp), "byteLength": ibm.nbytes}
    comp += ibm.tobytes()
    base = len(views)
    views += new_views + [ibm_view]
    acc[0] = {"bufferView": base, "componentType": 5123, "count": len(qpos), "type": "VEC3",
              "min": [0, 0, 0], "max": [int(x) for x in qpos[:, :3].max(0)]}
    acc[1] = {"bufferView": base + 1, "componentType": 5123, "count": len(idx), "type": "SCALAR"}
    acc[7] = {"bufferView": base + 2, "componentType": 5123, "count": len(uv), "type": "VEC2", "normalized": True}
    acc[6] = {"bufferView": base + 3, "componentType": 5126, "count": len(ibm), "type": "MAT4"}
    g["buffers"] = [{"byteLength": len(comp)},
                    {"byteLength": fallback_len, "extensions": {"EXT_meshopt_compression": {"fallback": True}}}]
    g["extensionsUsed"] = g["extensionsRequired"] = ["EXT_meshopt_compression", "KHR_mesh_quantization",
                                                     "KHR_texture_transform"]
    if rigid:
        body = g["nodes"][3]
        del body["skin"]
        body.update({"scale": [scale] * 3, "translation": [float(x) for x in lo]})
        g["nodes"][1]["children"] = [2, 3]  # the mesh hangs from the Root joint
        g["scenes"][0]["nodes"] = [0]
        del g["skins"]
    return g, bytes(comp)


@pytest.mark.parametrize("rigid", [False, True])
def test_gltfpack_style_file_decodes_to_the_uncompressed_vertices(tmp_path, rigid):
    gltf, data = bar_gltf(texture=True)
    plain = load_gltf(write_gltf(tmp_path, gltf, data, "plain.glb", "glb"))
    cg, cdata = _compress(gltf, data, rigid=rigid)
    packed = write_gltf(tmp_path, cg, cdata, "packed.glb", "glb")
    assert packed.stat().st_size < (tmp_path / "plain.glb").stat().st_size + 2000
    av = load_gltf(packed)
    extent = float(np.ptp(plain.vertices, 0).max())
    assert np.abs(av.vertices - plain.vertices).max() < 2 * extent / 65535
    assert (av.indices == plain.indices).all()
    assert np.abs(av.uv - plain.uv).max() < 2 / 65535 + 1e-7
    assert np.allclose(av.normals, plain.normals, atol=1e-3)
    if not rigid:
        assert (av.joints == plain.joints).all() and np.allclose(av.weights, plain.weights)


def test_bad_meshopt_stream_names_the_file_and_view(tmp_path):
    gltf, data = bar_gltf(texture=True)
    cg, cdata = _compress(gltf, data, rigid=False)
    ext = cg["bufferViews"][-4]["extensions"]["EXT_meshopt_compression"]
    assert ext["mode"] == "ATTRIBUTES"
    ext["byteLength"] -= 3
    with pytest.raises(InputError, match=r"packed.glb, key bufferViews\[\d+\].extensions.EXT_meshopt_compression: "
                                         r"cannot decode"):
        load_gltf(write_gltf(tmp_path, cg, cdata, "packed.glb", "glb"))


# --- real gltfpack output ----------------------------------------------------------------------------------
# Made once with gltfpack 1.3.0 (npm): `gltfpack -i builtin.glb -o builtin.gltfpack-cc.glb -cc -kn -ke` on the
# built-in avatar exported by export_glb, and the same (without -ke) on RobotExpressive.glb. Positions are
# 14-bit integers, normals 8-bit, morph deltas quantized; every vertex, index and morph view is meshopt-coded.

PACKED = SAMPLES / "avatars"


def _matches(reference, points):
    from scipy.spatial import cKDTree

    dist, idx = cKDTree(reference).query(points)
    back, _ = cKDTree(points).query(reference)
    return dist, back, idx


def test_gltfpack_output_of_the_builtin_avatar_decodes_to_its_vertices_and_morphs(avatar):
    from scipy.spatial import cKDTree

    packed = load_gltf(PACKED / "builtin.gltfpack-cc.glb")
    assert packed.n_vertices == avatar.n_vertices and packed.n_triangles == avatar.n_triangles
    assert packed.skeleton.names == avatar.skeleton.names
    step = float(np.ptp(avatar.vertices, 0).max()) / (2 ** 14 - 1)  # 14-bit positions
    dist, back, idx = _matches(avatar.vertices, packed.vertices)
    assert dist.max() < step and back.max() < step  # same point set, to the quantization step
    # morph deltas of all 52 ARKit shapes come through (gltfpack reorders vertices: matched by position)
    assert np.abs(packed.morph_deltas - avatar.morph_deltas[:, idx]).max() < 2e-4
    # normals to 8 bits, against the best of the vertices sharing a position (seams split normals)
    near = cKDTree(avatar.vertices).query_ball_point(packed.vertices, 2 * step)
    err = [np.linalg.norm(avatar.normals[n] - packed.normals[j], axis=1).min() for j, n in enumerate(near)]
    assert max(err) < 0.03
    # triangles: the same set of corner positions
    tri_a = np.sort(np.round(avatar.vertices[avatar.indices] / step).astype(np.int64).reshape(-1, 9), 1)
    tri_b = np.sort(np.round(packed.vertices[packed.indices] / step).astype(np.int64).reshape(-1, 9), 1)
    assert np.abs(np.sort(tri_a.sum(1)) - np.sort(tri_b.sum(1))).max() <= 9


def test_gltfpack_khr_version_decodes_to_the_same_bytes_as_the_ext_version():
    # `gltfpack -cc -ce khr` writes KHR_meshopt_compression with version-1 attribute streams; every buffer view
    # (vertices, indices, and the octahedral, quaternion and exponential filtered animation data) must decode
    # to exactly the bytes its EXT (version 0) twin decodes to
    from studyapp.render.gltf import _Doc

    khr = _Doc(PACKED / "RobotExpressive.gltfpack-khr.glb")
    ext = _Doc(PACKED / "RobotExpressive.gltfpack-cc.glb")
    filters = set()
    for i, view in enumerate(khr.gltf["bufferViews"]):
        if "KHR_meshopt_compression" in view.get("extensions", {}):
            spec = view["extensions"]["KHR_meshopt_compression"]
            filters.add(spec.get("filter", "NONE"))
            assert khr.view_bytes(i)[0] == ext.view_bytes(i)[0], (i, spec)
    assert {"OCTAHEDRAL", "QUATERNION", "EXPONENTIAL"} <= filters
    a, b = load_gltf(PACKED / "RobotExpressive.gltfpack-khr.glb"), load_gltf(PACKED / "RobotExpressive.gltfpack-cc.glb")
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.indices, b.indices)


def test_color_filter_decodes_ycocg():
    # spec appendix B, filter 4, inverted for 8-bit colours with K = 8 (alpha 7 bits + marker bit 7)
    rgba = np.array([[255, 0, 0, 255], [10, 200, 30, 128], [90, 90, 90, 0]], np.int64)
    r, g, b, a = rgba.T
    y = (r + 2 * g + b) // 4
    co, cg = (r - b) // 2, (2 * g - r - b) // 4
    a7 = (a >> 1) | 0x80
    enc = np.stack([y, co, cg, a7], 1).astype(np.int64)
    raw = (enc & 0xFF).astype(np.uint8).tobytes()
    dec = np.frombuffer(decode_view(encode_attributes(raw, 3, 4), 3, 4, "ATTRIBUTES", "COLOR"), np.uint8)
    assert np.abs(dec.reshape(3, 4).astype(int) - rgba).max() <= 3


def test_gltfpack_robot_keeps_rigid_parts_on_their_bones():
    plain = load_gltf(PACKED / "RobotExpressive.glb")
    packed = load_gltf(PACKED / "RobotExpressive.gltfpack-cc.glb")
    assert packed.skeleton.names == plain.skeleton.names
    # gltfpack quantizes all meshes over one range in their own (scaled) units, coarser than the figure's box:
    # allow 1/4000 of the figure's size (the robot is 4.5 units tall; 1.1 mm on a 1.8 m person)
    tol = float(np.ptp(plain.vertices, 0).max()) / 4000
    dist, back, idx = _matches(plain.vertices, packed.vertices)
    assert dist.max() < tol and back.max() < tol
    assert (packed.joints[:, 0] == plain.joints[idx, 0]).all()  # each part still hangs from its bone


@pytest.mark.gl
def test_gltfpack_builtin_renders_like_the_builtin(renderer, avatar):
    from render_helpers import RELAXED, posed
    from studyapp.render.context import OffscreenTarget
    from studyapp.render.pose import prepare_slot
    from studyapp.render.scene import make_scene
    from studyapp.face.animation import FaceAnimation

    packed = load_gltf(PACKED / "builtin.gltfpack-cc.glb")
    face = FaceAnimation.neutral(2, 30.0)
    face.weights[:, avatar.morph_index("jawOpen")] = 1.0
    images = []
    camera = None
    for av in (avatar, packed):
        slot = prepare_slot(av, posed(av, RELAXED, 2), face)
        scene = make_scene([slot], av)
        camera = camera or scene.camera
        scene.camera = camera
        target = OffscreenTarget(renderer.ctx, (240, 320))
        renderer.draw_trial(scene, 0.0, target.fbo)
        images.append(target.read_rgb().astype(int))
        target.release()
    a, b = images
    # gltfpack drops studyapp's material-id attribute, so highlights differ a little; the figure is the same
    assert np.abs(a - b).mean() < 2.0
    assert (np.abs(a - b).max(-1) > 60).mean() < 0.005
