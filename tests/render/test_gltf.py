"""glTF 2.0 / GLB / VRM import and GLB export, on files written here with real skins and morph targets."""
from __future__ import annotations

import base64
import io
import json
import struct

import matplotlib.image as mpimg
import numpy as np
import pytest

from render_helpers import RELAXED, posed
from studyapp.errors import InputError
from studyapp.face.arkit import ARKIT_NAMES
from studyapp.motion.skeleton import Motion
from studyapp.render.gltf import export_glb, load_gltf
from studyapp.render.pose import prepare_slot, skinning_palettes


def _pack(chunks: list[np.ndarray]) -> tuple[bytes, list[dict]]:
    data = bytearray()
    views = []
    for arr in chunks:
        while len(data) % 4:
            data.append(0)
        raw = np.ascontiguousarray(arr).tobytes()
        views.append({"buffer": 0, "byteOffset": len(data), "byteLength": len(raw)})
        data.extend(raw)
    return bytes(data), views


def bar_gltf(*, armature_scale: float = 1.0, mesh_in_rig_units: bool = False, vrm: str | None = None,
             texture: bool = False, extra: dict | None = None) -> tuple[dict, bytes]:
    """A 2-joint bar (0.2 m along +Y per joint, 3 rings of 4 vertices) with a skin and two morph targets.

    Joints hang under a non-joint ``Armature`` node with ``armature_scale`` (0.01 = a centimetre rig).
    Weights are normalized unsigned bytes, joints unsigned bytes. The ARKit target ``AK_17_JawOpen`` is
    a sparse accessor moving only vertex 10; ``wiggle`` is not ARKit and must be ignored.
    """
    s = armature_scale
    ring = np.array([[0.02, 0, 0.02], [-0.02, 0, 0.02], [-0.02, 0, -0.02], [0.02, 0, -0.02]], np.float32)
    pos = np.concatenate([ring + [0, y, 0] for y in (0.0, 0.2, 0.4)]).astype(np.float32)  # world metres
    if mesh_in_rig_units:
        pos = pos / s  # mesh data in rig units; the joints' world scale brings it to metres
    idx = []
    for r in range(2):
        for c in range(4):
            a, b = r * 4 + c, r * 4 + (c + 1) % 4
            idx += [a, b, a + 4, b, b + 4, a + 4]
    idx = np.array(idx, np.uint16)
    joints = np.zeros((12, 4), np.uint8)
    joints[:, 1] = 1
    w = np.zeros((12, 4), np.float32)
    w[:4, 0] = 1
    w[4:8, :2] = 0.5
    w[8:, 1] = 1
    weights = np.round(w * 255).astype(np.uint8)
    sparse_idx = np.array([10], np.uint16)
    sparse_val = np.array([[0.0, 0.05, 0.0]], np.float32) / (s if mesh_in_rig_units else 1.0)
    wiggle = np.full((12, 3), 0.01, np.float32)
    # joint world transforms (Armature scale s): joint0 at origin, joint1 at 0.2 m
    g0 = np.diag([s, s, s, 1.0])
    g1 = g0.copy()
    g1[:3, 3] = [0, 0.2, 0]
    ibm = np.stack([np.linalg.inv(g0), np.linalg.inv(g1)])
    if mesh_in_rig_units:  # as exporters of centimetre rigs write it: the bind includes the armature scale
        ibm = ibm @ np.diag([s, s, s, 1.0])
    ibm = np.ascontiguousarray(ibm.transpose(0, 2, 1), np.float32).reshape(2, 16)
    uv = np.c_[np.linspace(0, 1, 12), np.linspace(0, 1, 12)].astype(np.float32)
    chunks = [pos, idx, joints, weights, sparse_idx, sparse_val, wiggle, ibm, uv]
    data, views = _pack(chunks)
    acc = [
        {"bufferView": 0, "componentType": 5126, "count": 12, "type": "VEC3", "min": pos.min(0).tolist(), "max": pos.max(0).tolist()},
        {"bufferView": 1, "componentType": 5123, "count": len(idx), "type": "SCALAR"},
        {"bufferView": 2, "componentType": 5121, "count": 12, "type": "VEC4"},
        {"bufferView": 3, "componentType": 5121, "count": 12, "type": "VEC4", "normalized": True},
        {"componentType": 5126, "count": 12, "type": "VEC3",
         "sparse": {"count": 1, "indices": {"bufferView": 4, "componentType": 5123}, "values": {"bufferView": 5}}},
        {"bufferView": 6, "componentType": 5126, "count": 12, "type": "VEC3"},
        {"bufferView": 7, "componentType": 5126, "count": 2, "type": "MAT4"},
        {"bufferView": 8, "componentType": 5126, "count": 12, "type": "VEC2"},
    ]
    prim = {"attributes": {"POSITION": 0, "JOINTS_0": 2, "WEIGHTS_0": 3}, "indices": 1,
            "targets": [{"POSITION": 4}, {"POSITION": 5}], "material": 0}
    material = {"pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.25, 1.0, 1.0]}}
    gltf = {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0, 3]}], "scene": 0,
        "nodes": [
            {"name": "Armature", "scale": [s, s, s], "children": [1]},
            {"name": "Root", "children": [2]},
            {"name": "Tip", "translation": [0, 0.2 / s, 0]},
            {"name": "Body", "mesh": 0, "skin": 0},
        ],
        "meshes": [{"primitives": [prim], "extras": {"targetNames": ["AK_17_JawOpen", "wiggle"]}}],
        "skins": [{"joints": [1, 2], "inverseBindMatrices": 6}],
        "materials": [material],
        "accessors": acc,
        "bufferViews": views,
        "buffers": [{"byteLength": len(data)}],
    }
    if texture:
        img = np.zeros((4, 4, 3), np.uint8)
        img[:, :, 0] = 255  # pure red
        png = io.BytesIO()
        mpimg.imsave(png, img, format="png")
        gltf["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(png.getvalue()).decode()}]
        gltf["textures"] = [{"source": 0}]
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
        prim["attributes"]["TEXCOORD_0"] = 7
    if vrm == "0":
        gltf["extensions"] = {"VRM": {"humanoid": {"humanBones": [{"bone": "hips", "node": 1}, {"bone": "spine", "node": 2}]}}}
    elif vrm == "1":
        gltf["extensions"] = {"VRMC_vrm": {"specVersion": "1.0", "humanoid": {"humanBones": {
            "hips": {"node": 1}, "leftThumbMetacarpal": {"node": 2}}}}}
    if extra:
        gltf.update(extra)
    return gltf, data


def write_gltf(tmp_path, gltf, data, name="bar.gltf", how="external"):
    g = json.loads(json.dumps(gltf))
    if how == "external":
        (tmp_path / "bar.bin").write_bytes(data)
        g["buffers"][0]["uri"] = "bar.bin"
        path = tmp_path / name
        path.write_text(json.dumps(g))
    elif how == "datauri":
        g["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode()
        path = tmp_path / name
        path.write_text(json.dumps(g))
    else:  # glb
        js = json.dumps(g).encode()
        js += b" " * (-len(js) % 4)
        pad = data + b"\0" * (-len(data) % 4)
        path = tmp_path / name
        path.write_bytes(struct.pack("<III", 0x46546C67, 2, 28 + len(js) + len(pad))
                         + struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(pad), 0x004E4942) + pad)
    return path


@pytest.mark.parametrize("how", ["external", "datauri", "glb"])
def test_loads_skin_weights_and_sparse_morph(tmp_path, how):
    gltf, data = bar_gltf()
    av = load_gltf(write_gltf(tmp_path, gltf, data, "bar.glb" if how == "glb" else "bar.gltf", how))
    assert av.skeleton.names == ("Root", "Tip")
    assert av.skeleton.parents.tolist() == [-1, 0]
    assert np.allclose(av.skeleton.offsets[1], [0, 0.2, 0])
    assert av.n_vertices == 12 and av.n_triangles == 16
    assert np.allclose(av.weights.sum(1), 1)
    assert np.allclose(av.weights[4:8, :2], 0.5, atol=1 / 255)
    jaw = av.morph_deltas[ARKIT_NAMES.index("jawOpen")]
    assert np.allclose(jaw[10], [0, 0.05, 0]) and np.abs(np.delete(jaw, 10, 0)).max() == 0
    assert np.abs(np.delete(av.morph_deltas, ARKIT_NAMES.index("jawOpen"), 0)).max() == 0  # 'wiggle' ignored
    assert any("wiggle" in n for n in av.notes)
    assert np.allclose(av.colors, [0.5, 0.25, 1.0])


def test_centimetre_rig_comes_out_in_metres(tmp_path):
    gltf, data = bar_gltf(armature_scale=0.01, mesh_in_rig_units=True)
    av = load_gltf(write_gltf(tmp_path, gltf, data))
    assert np.allclose(av.skeleton.offsets[1], [0, 0.2, 0], atol=1e-6)
    assert np.allclose(av.vertices[:, 1].max(), 0.4, atol=1e-6)
    assert np.allclose(av.morph_deltas[ARKIT_NAMES.index("jawOpen"), 10], [0, 0.05, 0], atol=1e-6)


def test_skinning_bends_the_loaded_bar(tmp_path):
    gltf, data = bar_gltf()
    av = load_gltf(write_gltf(tmp_path, gltf, data))
    m = Motion.rest(av.skeleton, 1)
    m.rotations[0, 1] = [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)]  # Tip 90 degrees about +Z
    pal = skinning_palettes(av, m)[0]
    assert np.allclose(skinning_palettes(av, Motion.rest(av.skeleton, 1))[0], np.eye(4), atol=1e-6)
    v = np.c_[av.vertices, np.ones(12)]
    top = pal[1] @ v[8]  # fully weighted to Tip: rotated about the joint at y = 0.2
    assert np.allclose(top[:3], [-0.2, 0.22, 0.02], atol=1e-6)
    bottom = pal[0] @ v[0]
    assert np.allclose(bottom[:3], av.vertices[0], atol=1e-7)


def test_texture_and_uv_are_loaded(tmp_path):
    gltf, data = bar_gltf(texture=True)
    av = load_gltf(write_gltf(tmp_path, gltf, data))
    assert av.texture.shape == (4, 4, 4) and (av.texture[..., 0] == 255).all() and (av.texture[..., 1] == 0).all()
    assert av.uv.shape == (12, 2)


@pytest.mark.parametrize("version,expect", [("0", ("Hips", "Spine")), ("1", ("Hips", "LeftThumbProximal"))])
def test_vrm_humanoid_bones_get_unity_names(tmp_path, version, expect):
    gltf, data = bar_gltf(vrm=version)
    av = load_gltf(write_gltf(tmp_path, gltf, data, "bar.vrm", "glb"))
    assert av.skeleton.names == expect
    # facing is measured, not assumed from the VRM version: a bar has no left and right, so it stays as stored
    plain = load_gltf(write_gltf(tmp_path, *bar_gltf(), "plain.gltf"))
    assert np.allclose(av.vertices, plain.vertices, atol=1e-6)
    assert any("facing not measured" in n for n in av.notes)
    assert np.allclose(skinning_palettes(av, Motion.rest(av.skeleton, 1)), np.eye(4), atol=1e-6)


@pytest.mark.gl
def test_textured_gltf_renders_its_texture(tmp_path, renderer):
    from studyapp.render.context import OffscreenTarget
    from studyapp.render.camera import Camera
    from studyapp.render.scene import make_scene

    centres = []
    for textured in (False, True):
        av = load_gltf(write_gltf(tmp_path, *bar_gltf(texture=textured)))
        scene = make_scene([prepare_slot(av, Motion.rest(av.skeleton, 1), None)], av)
        scene.camera = Camera(eye=np.array([0.0, 0.2, 1.0]), target=np.array([0.0, 0.2, 0.0]), fov_y=30)
        target = OffscreenTarget(renderer.ctx, (64, 64))
        renderer.draw_trial(scene, 0.0, target.fbo)
        centres.append(target.read_rgb().astype(int)[24:40, 29:35].reshape(-1, 3).mean(0))
        target.release()
    plain, red = centres
    # factor (0.5, 0.25, 1) alone is blue-violet; times the red texture it has no blue or green left
    # (what green/blue remains is the white specular and rim light)
    assert plain[2] > plain[0] > plain[1]
    assert red[0] - red[2] > 80 and red[0] > plain[0] - 10 and red[2] < plain[2] - 80


@pytest.mark.parametrize("ext", ["KHR_draco_mesh_compression", "KHR_texture_basisu"])
def test_compressed_files_are_refused_clearly(tmp_path, ext):
    gltf, data = bar_gltf(extra={"extensionsUsed": [ext]})
    with pytest.raises(InputError, match=ext) as err:
        load_gltf(write_gltf(tmp_path, gltf, data))
    assert "bar.gltf" in str(err.value) and "re-export" in str(err.value)


def test_unknown_required_extension_and_ktx2_images_are_named(tmp_path):
    gltf, data = bar_gltf(extra={"extensionsRequired": ["EXT_unknown_thing"], "extensionsUsed": ["EXT_unknown_thing"]})
    with pytest.raises(InputError, match=r"bar.gltf, key extensionsRequired: required extension EXT_unknown_thing"):
        load_gltf(write_gltf(tmp_path, gltf, data))
    gltf, data = bar_gltf(extra={"images": [{"uri": "skin.ktx2"}]})
    with pytest.raises(InputError, match=r"bar.gltf, key images\[0\]: KTX2 textures are not supported"):
        load_gltf(write_gltf(tmp_path, gltf, data))
    # extensions that only change looks, or that are decoded, do not stop a file
    gltf, data = bar_gltf(extra={"extensionsRequired": ["KHR_materials_unlit", "KHR_mesh_quantization"]})
    assert load_gltf(write_gltf(tmp_path, gltf, data)).n_vertices == 12


def test_web_page_saved_as_glb_is_named_as_such(tmp_path):
    page = tmp_path / "Soldier.glb"
    page.write_text("<!DOCTYPE html>\n<html><head><title>Soldier.glb - GitHub</title></head></html>")
    with pytest.raises(InputError) as err:
        load_gltf(page)
    assert str(err.value).startswith(str(page) + ": not a GLB file (starts with '<!DOCTYPE'")
    assert "JSON" not in str(err.value)


def test_bad_json_and_missing_buffer(tmp_path):
    bad = tmp_path / "bad.gltf"
    bad.write_text('{"asset": {"version": "2.0"},\n "nodes": [}')
    with pytest.raises(InputError, match=r"bad.gltf, line 2"):
        load_gltf(bad)
    gltf, data = bar_gltf()
    path = write_gltf(tmp_path, gltf, data)
    (tmp_path / "bar.bin").unlink()
    with pytest.raises(InputError, match="bar.bin.*not found"):
        load_gltf(path)


def test_builtin_avatar_glb_round_trip(tmp_path, avatar):
    path = export_glb(avatar, tmp_path / "builtin.glb")
    assert path.read_bytes()[:4] == b"glTF"
    back = load_gltf(path)
    assert back.skeleton.names == avatar.skeleton.names
    assert np.array_equal(back.skeleton.parents, avatar.skeleton.parents)
    for attr in ("vertices", "normals", "indices", "colors", "joints", "weights", "morph_deltas", "material"):
        assert np.array_equal(getattr(back, attr), getattr(avatar, attr)), attr
    assert np.allclose(back.inverse_bind, avatar.inverse_bind, atol=1e-6)
    assert back.morph_names == avatar.morph_names
    assert back.double_sided is avatar.double_sided is False  # closed surfaces: drawn with back-face culling


@pytest.mark.gl
def test_round_tripped_avatar_renders_the_same_pixels(tmp_path, avatar, renderer):
    from studyapp.face.animation import FaceAnimation
    from studyapp.render.context import OffscreenTarget
    from studyapp.render.scene import make_scene

    back = load_gltf(export_glb(avatar, tmp_path / "builtin.glb"))
    face = np.zeros((2, 52), np.float32)
    face[:, ARKIT_NAMES.index("jawOpen")] = 0.7
    face = FaceAnimation(face, 30.0)
    images = []
    scene_a = make_scene([prepare_slot(avatar, posed(avatar, RELAXED, 2), face)], avatar)
    for av in (avatar, back):
        scene = make_scene([prepare_slot(av, posed(av, RELAXED, 2), face)], av)
        scene.camera = scene_a.camera
        target = OffscreenTarget(renderer.ctx, (320, 360))
        renderer.draw_trial(scene, 0.0, target.fbo)
        images.append(target.read_rgb())
        target.release()
    diff = np.abs(images[0].astype(int) - images[1].astype(int))
    assert diff.max() <= 1 and (diff > 0).mean() < 0.001


@pytest.mark.parametrize("version", ["0", "1"])
def test_vrm_perfect_sync_expressions_supply_arkit_shapes(tmp_path, version):
    # the bar's target 1 ("wiggle", 0.01 on every vertex) is not ARKit; a VRM expression named as an ARKit
    # shape binds it. An expression for a shape a target is already named after (jawOpen) changes nothing.
    gltf, data = bar_gltf(vrm=version)
    if version == "1":
        gltf["extensions"]["VRMC_vrm"]["expressions"] = {"custom": {
            "mouthSmileLeft": {"morphTargetBinds": [{"node": 3, "index": 1, "weight": 0.5}]},
            "jawOpen": {"morphTargetBinds": [{"node": 3, "index": 1, "weight": 1.0}]},
            "happy": {"morphTargetBinds": [{"node": 3, "index": 1, "weight": 1.0}]}}}
    else:
        gltf["extensions"]["VRM"]["blendShapeMaster"] = {"blendShapeGroups": [
            {"name": "MouthSmileLeft", "presetName": "unknown", "binds": [{"mesh": 0, "index": 1, "weight": 50}]},
            {"name": "JawOpen", "presetName": "unknown", "binds": [{"mesh": 0, "index": 1, "weight": 100}]},
            {"name": "Joy", "presetName": "joy", "binds": [{"mesh": 0, "index": 1, "weight": 100}]}]}
    av = load_gltf(write_gltf(tmp_path, gltf, data, "bar.vrm", "glb"))
    smile = av.morph_deltas[av.morph_index("mouthSmileLeft")]
    assert np.allclose(smile, 0.005)
    jaw = av.morph_deltas[av.morph_index("jawOpen")]
    assert np.allclose(jaw[10], [0, 0.05, 0]) and np.allclose(np.delete(jaw, 10, 0), 0)
    assert not av.morph_deltas[av.morph_index("mouthSmileRight")].any()
