"""glTF 2.0 / GLB / VRM avatars: load skinned meshes with ARKit morph targets, and export GLB.

What is read
------------
* ``.gltf`` (JSON with external or ``data:`` URI buffers), ``.glb`` and ``.vrm`` (GLB with a VRM extension).
* All triangle primitives of all mesh nodes, merged into one mesh. Skinned primitives use the first skin's
  joints (``JOINTS_0``/``WEIGHTS_0``: unsigned byte/short, float or normalized integer weights); meshes
  without a skin follow their nearest joint ancestor rigidly. A file with no skin at all (VRM 1.0 props
  hanging from bones) gets its skeleton from the node hierarchy: the VRM humanoid bones, else every node
  that is an ancestor of a mesh.
* The joints become a :class:`~studyapp.motion.skeleton.Skeleton` (depth-first, metres) whose rest
  pose is the node TRS rest pose: rotations in ``rest_rotations``, scale (e.g. a centimetre armature)
  folded into the offsets. Geometry is brought into that rest pose in world space, so the renderer's
  inverse bind matrices are plain inverses of the rest transforms.
* Facing is measured on the rest pose (left-right axis of the hips or shoulders, see
  :mod:`studyapp.render.avatar_rig`) and the whole figure (geometry, skeleton, binds) is turned about +Y to
  face +Z, the camera. VRM 0.x files (facing -Z) and three.js's Soldier are turned this way, by measurement.
* ``bone_map`` (the design's ``[avatar.bone_map]``) names humanoid bones for joints with other names.
* Morph targets named in ``mesh.extras.targetNames`` (or the primitive's extras) and matched to ARKit names
  with :func:`studyapp.face.arkit.match_arkit_name`; VRM 1.0 expressions and VRM 0.x blend shape groups
  named as ARKit shapes ("perfect sync") supply the shapes no target is named after, as the weighted sum of
  their bound targets; other targets are ignored with a note.
* ``baseColorFactor``, ``COLOR_0`` and one ``baseColorTexture`` (PNG/JPEG, via Pillow, with
  ``KHR_texture_transform``); ``doubleSided`` on any material turns back-face culling off for the avatar.
  Several different textures are baked into vertex colours (noted).
* Sparse accessors. VRM 0.x (``extensions.VRM``) and 1.0 (``extensions.VRMC_vrm``) humanoid bones are
  renamed to Unity humanoid names (``leftUpperArm`` -> ``LeftUpperArm``).
* gltfpack's compression: ``EXT_meshopt_compression`` and ``KHR_meshopt_compression`` buffer views
  (decoded by :mod:`studyapp.render.meshopt`) and ``KHR_mesh_quantization`` (integer and normalized integer positions,
  normals, UVs and morph deltas, dequantized by the node or bind transforms as the file states).

Other compression (Draco), KTX2/WebP textures and any other *required*
extension raise :class:`InputError` naming the extension; so does a web page saved as ``.glb``.

Nothing a file claims is trusted before it is checked: the document's types and indices, the node hierarchy
and external URIs by :mod:`studyapp.render.gltf_schema`; byte ranges here, where bytes are read (GLB chunks
within the file, buffers at least ``byteLength`` long, buffer views within their buffer, accessors with
their ``byteStride`` within their view, sparse parts within theirs, decoded meshopt sizes); then what the
loader relies on: attribute types and counts equal to the vertex count, unsigned indices below it, joint
indices below the skin's joint count, one invertible inverse bind matrix per joint, finite float data and
node transforms. Each problem is one :class:`InputError` naming the file and the JSON place.

>>> import tempfile, pathlib
>>> from studyapp.render.avatar import build_default_avatar
>>> path = pathlib.Path(tempfile.mkdtemp()) / "avatar.glb"
>>> _ = export_glb(build_default_avatar(), path)
>>> load_gltf(path).skeleton.names[:2]
('Hips', 'Spine')
"""
from __future__ import annotations

import base64
import io
import json
import struct
from pathlib import Path

import numpy as np

from studyapp.errors import InputError
from studyapp.face.arkit import ARKIT_NAMES, match_arkit_name
from studyapp.motion.fk import rest_global_transforms
from studyapp.motion.rotations import matrix_to_quat, quat_to_matrix
from studyapp.motion.skeleton import Skeleton
from studyapp.render.avatar import Avatar, vertex_normals
from studyapp.render.gltf_schema import COMPONENT_TYPES as _COMPONENT_NAMES
from studyapp.render.gltf_schema import DAMAGED as _DAMAGED
from studyapp.render.gltf_schema import (MAX_DECODED_VIEW, MAX_FILE_BYTES, MAX_TEXTURE_PIXELS, MAX_TEXTURE_PIXELS_TOTAL,
                                         MAX_VERTICES, check_document, confined_file, node_parents, parse_json)

GLB_MAGIC = 0x46546C67  # "glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942

_COMPONENT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_UNSUPPORTED = {
    "KHR_draco_mesh_compression": "Draco-compressed meshes",
    "KHR_texture_basisu": "Basis Universal / KTX2 textures",
}
# Required extensions that can be read (decoded here, or only changing looks the renderer does not show).
_READABLE = {"EXT_meshopt_compression", "KHR_meshopt_compression", "KHR_mesh_quantization", "KHR_texture_transform",
             "KHR_materials_unlit", "KHR_materials_emissive_strength", "KHR_materials_specular", "KHR_materials_ior",
             "KHR_materials_clearcoat", "KHR_materials_sheen", "KHR_lights_punctual", "VRM", "VRMC_vrm",
             "VRMC_materials_mtoon", "VRMC_springBone", "VRMC_node_constraint"}
_FIX = ("re-export the avatar without it (Blender's glTF exporter with Draco off; gltfpack without -tc: "
        "its meshopt compression is read)")
_MESHOPT = ("EXT_meshopt_compression", "KHR_meshopt_compression")


# ---------------------------------------------------------------------------------------------
# Container and accessors
# ---------------------------------------------------------------------------------------------

class _Doc:
    """A parsed glTF document with its binary buffers, decoding accessors on demand.

    The document passes :func:`~studyapp.render.gltf_schema.check_document` (types and indices) before
    anything else reads it; byte ranges are checked here, where the bytes are read.
    """

    def __init__(self, path: Path, check: bool = True) -> None:
        self.path = path
        try:
            if not path.is_file():  # a device or pipe (e.g. a link to /dev/zero) would be read forever
                raise InputError(path, None, "not a regular file" if path.exists() else "avatar file not found")
            size = path.stat().st_size
            if size > MAX_FILE_BYTES:
                raise InputError(path, None, f"avatar file has {size} bytes; at most {MAX_FILE_BYTES} are read")
            raw = path.read_bytes()
        except OSError as exc:
            raise InputError(path, None, f"cannot read avatar file: {exc.strerror or exc}") from None
        bin_chunk = None
        if raw[:4] == b"glTF":
            self.gltf, bin_chunk = self._parse_glb(raw)
        elif path.suffix.lower() in (".glb", ".vrm") or raw.lstrip()[:1] == b"<":
            # a web page saved under the model's name is the usual case: say what the file starts with
            head = raw.lstrip()[:9].decode("utf-8", "replace")
            kind = "glTF" if path.suffix.lower() == ".gltf" else "GLB"
            raise InputError(path, None, f"not a {kind} file (starts with {head!r}, not 'glTF'); "
                             "download the model file itself, not the web page showing it")
        else:
            try:
                raw.decode("utf-8-sig")
            except UnicodeDecodeError:
                raise InputError(path, None, "not a glTF file: neither GLB ('glTF' magic) nor UTF-8 JSON") from None
            self.gltf = parse_json(raw, path, None)
        if not isinstance(self.gltf, dict):
            raise InputError(path, None, "the glTF JSON must be an object")
        asset = self.gltf.get("asset", {})
        version = str(asset.get("version", "")) if isinstance(asset, dict) else ""
        if not version.startswith("2"):
            raise InputError(path, "key asset.version", f"only glTF 2.0 is supported, file says {version or 'nothing'!r}")
        self._cache: dict = {}
        if not check:  # the JSON only (for reports on files that cannot be loaded)
            self.buffers = []
            return
        check_document(self.gltf, path)
        required = set(self.gltf.get("extensionsRequired", []))
        used = required | set(self.gltf.get("extensionsUsed", []))
        for ext in sorted(used):
            if ext in _UNSUPPORTED:
                raise InputError(path, "key extensionsUsed", f"{ext} ({_UNSUPPORTED[ext]}) is not supported; {_FIX}")
        for ext in sorted(required - _READABLE):
            raise InputError(path, "key extensionsRequired", f"required extension {ext} is not supported; {_FIX}")
        for i, img in enumerate(self.gltf.get("images", [])):
            if img.get("mimeType") == "image/ktx2" or str(img.get("uri", "")).lower().endswith(".ktx2"):
                raise InputError(path, f"key images[{i}]", "KTX2 textures are not supported; "
                                 "re-export the avatar with PNG or JPEG textures (gltfpack without -tc)")
        self.buffers = [self._load_buffer(i, b, bin_chunk) for i, b in enumerate(self.gltf.get("buffers", []))]

    def _parse_glb(self, raw: bytes) -> tuple[object, bytes | None]:
        if len(raw) < 20:
            raise InputError(self.path, "header", "GLB file is truncated" + _DAMAGED)
        magic, version, length = struct.unpack_from("<III", raw, 0)
        if version != 2:
            raise InputError(self.path, "header", f"GLB version {version}; only 2 is supported")
        if length > len(raw):
            raise InputError(self.path, "header",
                             f"GLB says {length} bytes, file has {len(raw)} (truncated?)" + _DAMAGED)
        pos = 12
        doc = None
        binary = None
        while pos + 8 <= length:
            clen, ctype = struct.unpack_from("<II", raw, pos)
            if pos + 8 + clen > length:
                raise InputError(self.path, f"byte {pos}", f"GLB chunk of {clen} bytes runs past the end of the "
                                 f"file ({length} bytes)" + _DAMAGED)
            data = raw[pos + 8: pos + 8 + clen]
            if ctype == CHUNK_JSON and doc is None:
                doc = parse_json(data, self.path, "JSON chunk")
            elif ctype == CHUNK_BIN and binary is None:
                binary = bytes(data)
            pos += 8 + clen  # chunk lengths are 4-byte aligned by the spec
        if doc is None:
            raise InputError(self.path, "header", "GLB has no JSON chunk" + _DAMAGED)
        return doc, binary

    def _load_buffer(self, i: int, spec: dict, bin_chunk: bytes | None) -> memoryview:
        uri = spec.get("uri")
        where = f"key buffers[{i}]"
        if uri is None and (i > 0 or bin_chunk is None) and set(_MESHOPT) & set(spec.get("extensions", {})):
            return memoryview(b"")  # placeholder for meshopt-compressed views: never read, they are decoded
        if uri is None:
            if bin_chunk is None:
                raise InputError(self.path, where, "buffer has no uri and the file has no GLB binary chunk" + _DAMAGED)
            data = bin_chunk
        elif uri.startswith("data:"):
            data = _data_uri(uri, self.path, f"{where}.uri")
        else:
            data = confined_file(self.path, uri, f"{where}.uri").read_bytes()
        need = spec.get("byteLength", len(data))
        if len(data) < need:
            raise InputError(self.path, f"{where}.byteLength",
                             f"buffer has {len(data)} bytes, byteLength says {need}" + _DAMAGED)
        return memoryview(data)[:need]

    def view_bytes(self, index: int) -> tuple[memoryview, int | None]:
        """The bytes of buffer view ``index`` (decoded when meshopt-compressed) and its ``byteStride``."""
        v = self.gltf["bufferViews"][index]
        if set(_MESHOPT) & set(v.get("extensions", {})):
            return self._meshopt_view(index), v.get("byteStride")
        buf = self.buffers[v["buffer"]]
        off, length = v.get("byteOffset", 0), v["byteLength"]
        if off + length > len(buf):
            raise InputError(self.path, f"key bufferViews[{index}].byteLength",
                             f"bytes {off} to {off + length} of buffer {v['buffer']}, which has {len(buf)}" + _DAMAGED)
        return buf[off: off + length], v.get("byteStride")

    def _meshopt_view(self, index: int) -> memoryview:
        """The uncompressed bytes of a meshopt-compressed buffer view (EXT or KHR; decoded once)."""
        if ("view", index) in self._cache:
            return self._cache[("view", index)]
        from studyapp.render.meshopt import MeshoptError, decode_view

        exts = self.gltf["bufferViews"][index]["extensions"]
        name = next(n for n in _MESHOPT if n in exts)
        ext = exts[name]
        where = f"key bufferViews[{index}].extensions.{name}"
        buf = self.buffers[ext["buffer"]]
        off, length, count, stride = ext.get("byteOffset", 0), ext["byteLength"], ext["count"], ext["byteStride"]
        if off + length > len(buf):
            raise InputError(self.path, f"{where}.byteLength",
                             "compressed data runs past the end of its buffer" + _DAMAGED)
        if count * stride > MAX_DECODED_VIEW:
            raise InputError(self.path, f"{where}.count", f"{count} elements of {stride} bytes would decode to "
                             f"{count * stride} bytes; at most {MAX_DECODED_VIEW} are decoded per buffer view"
                             + _DAMAGED)
        try:
            data = decode_view(bytes(buf[off: off + length]), count, stride, ext["mode"], ext.get("filter", "NONE"))
        except MeshoptError as exc:
            raise InputError(self.path, where, f"cannot decode: {exc}" + _DAMAGED) from None
        self._cache[("view", index)] = memoryview(data)
        return self._cache[("view", index)]

    def accessor(self, index: int) -> np.ndarray:
        """Decode accessor ``index`` to an ``(count, width)`` array (floats when ``normalized``).

        Every byte range is checked against the bytes really there before it is read, and float data must
        be finite.
        """
        if index in self._cache:
            return self._cache[index]
        a = self.gltf["accessors"][index]
        where = f"key accessors[{index}]"
        dtype = np.dtype(_COMPONENT[a["componentType"]])
        width = _WIDTH[a["type"]]
        count = a["count"]
        elem = dtype.itemsize * width
        if "bufferView" in a:
            buf, stride = self.view_bytes(a["bufferView"])
            off = a.get("byteOffset", 0)
            stride = stride or elem
            if stride < elem:
                raise InputError(self.path, f"key bufferViews[{a['bufferView']}].byteStride",
                                 f"stride {stride} is shorter than one element of accessor {index} ({elem} bytes)"
                                 + _DAMAGED)
            end = off + stride * (count - 1) + elem if count else off
            if end > len(buf):
                raise InputError(self.path, f"{where}.count",
                                 f"{count} elements of {elem} bytes (stride {stride}) from byte {off} need {end} "
                                 f"bytes; bufferView {a['bufferView']} has {len(buf)}" + _DAMAGED)
            if stride == elem:
                out = np.frombuffer(buf, dtype, count * width, off).reshape(count, width)
            else:
                rows = np.frombuffer(buf, np.uint8, stride * (count - 1) + elem, off)
                idx = (np.arange(count)[:, None] * stride + np.arange(elem)[None]).reshape(-1)
                out = rows[idx].view(dtype).reshape(count, width)
            out = out.copy()
        else:
            if count > MAX_VERTICES:
                raise InputError(self.path, f"{where}.count", f"{count} elements without a bufferView; "
                                 f"at most {MAX_VERTICES} are read" + _DAMAGED)
            out = np.zeros((count, width), dtype)
        sparse = a.get("sparse")
        if sparse:
            n = sparse["count"]
            if n > count:
                raise InputError(self.path, f"{where}.sparse.count",
                                 f"{n} sparse values for an accessor of {count} elements" + _DAMAGED)
            si, sv = sparse["indices"], sparse["values"]
            ind = self._sparse_part(si, np.dtype(_COMPONENT[si["componentType"]]), n, 1, f"{where}.sparse.indices")
            vals = self._sparse_part(sv, dtype, n, width, f"{where}.sparse.values")
            ind = ind.reshape(-1).astype(np.int64)
            if n and int(ind.max()) >= count:
                raise InputError(self.path, f"{where}.sparse", "sparse index beyond the accessor count" + _DAMAGED)
            out = out.copy()
            out[ind] = vals
        if dtype.kind == "f" and not np.isfinite(out).all():
            bad = int(np.flatnonzero(~np.isfinite(out).all(axis=1))[0])
            raise InputError(self.path, where, f"element {bad} is not a finite number (NaN or infinity)" + _DAMAGED)
        if a.get("normalized") and dtype.kind in "iu":
            info = np.iinfo(dtype)
            out = out.astype(np.float32) / info.max
            if dtype.kind == "i":
                out = np.maximum(out, -1.0)
        self._cache[index] = out
        return out

    def _sparse_part(self, spec: dict, dtype: np.dtype, n: int, width: int, where: str) -> np.ndarray:
        """``n`` elements of a sparse accessor's indices or values, inside their buffer view."""
        buf, _ = self.view_bytes(spec["bufferView"])
        off = spec.get("byteOffset", 0)
        if off + n * width * dtype.itemsize > len(buf):
            raise InputError(self.path, where, f"{n} elements from byte {off} run past the end of bufferView "
                             f"{spec['bufferView']} ({len(buf)} bytes)" + _DAMAGED)
        return np.frombuffer(buf, dtype, n * width, off).reshape(n, width)

    def checked(self, index: int, where: str, types: tuple[str, ...], count: int | None = None,
                integer: bool = False) -> np.ndarray:
        """Accessor ``index`` used as ``where`` (a primitive's attribute, indices, a skin's matrices): its
        element type must be one of ``types``, its count ``count`` when given, and (``integer``) its
        components unsigned integers."""
        a = self.gltf["accessors"][index]
        if a["type"] not in types:
            raise InputError(self.path, f"key {where}", f"accessor {index} holds {a['type']}, not "
                             + " or ".join(types) + _DAMAGED)
        if integer and a["componentType"] not in (5121, 5123, 5125):
            raise InputError(self.path, f"key {where}", f"accessor {index} holds "
                             f"{_COMPONENT_NAMES[a['componentType']]} values, not unsigned integers" + _DAMAGED)
        if count is not None and a["count"] != count:
            raise InputError(self.path, f"key {where}",
                             f"accessor {index} has {a['count']} elements, the primitive has {count} vertices"
                             + _DAMAGED)
        return self.accessor(index)

    def image(self, index: int) -> np.ndarray | None:
        """An image as ``(H, W, 4) uint8`` (top row first), or None when it cannot be decoded."""
        imgs = self.gltf.get("images", [])
        if not 0 <= index < len(imgs):
            return None
        img = imgs[index]
        where = f"key images[{index}]"
        if "bufferView" in img:
            data = bytes(self.view_bytes(img["bufferView"])[0])
        elif "uri" in img:
            uri = img["uri"]
            if uri.startswith("data:"):
                data = _data_uri(uri, self.path, f"{where}.uri")
            else:
                data = confined_file(self.path, uri, f"{where}.uri").read_bytes()
        else:
            return None
        return decode_image(data, self.path, f"images[{index}]")


def _data_uri(uri: str, path: Path, where: str) -> bytes:
    """The bytes of a base64 ``data:`` URI."""
    head, _, payload = uri.partition(",")
    if ";base64" not in head:
        raise InputError(path, where, "only base64 data URIs are supported")
    try:
        return base64.b64decode(payload, validate=False)
    except ValueError as exc:
        raise InputError(path, where, f"bad base64 data: {exc}" + _DAMAGED) from None


def decode_image(data: bytes, path: Path | None = None, where: str | None = None) -> np.ndarray:
    """PNG or JPEG bytes -> ``(H, W, 4) uint8`` via Pillow (any PNG: 8 or 16 bits, grey, palette, RGB(A),
    interlaced; 16-bit channels keep their high byte)."""
    try:
        from PIL import Image

        with Image.open(io.BytesIO(data)) as probe:  # reads the header only
            w, h = probe.size
    except Exception as exc:
        raise InputError(path, where, f"cannot decode texture image: {exc}") from None
    if w * h > MAX_TEXTURE_PIXELS:
        raise InputError(path, where, f"texture of {w} x {h} pixels; at most {MAX_TEXTURE_PIXELS} pixels "
                         "(e.g. 8192 x 4096) are read: scale it down")
    try:
        with Image.open(io.BytesIO(data)) as im:
            if im.mode.startswith("I"):  # 16-bit grey ("I;16", "I;16B", "I"): Pillow's RGBA would clip it
                arr = (np.asarray(im).astype(np.uint32) >> 8).clip(0, 255).astype(np.uint8)
            else:
                arr = np.asarray(im.convert("RGBA"))
    except Exception as exc:
        raise InputError(path, where, f"cannot decode texture image: {exc}") from None
    if arr.ndim == 2:
        arr = np.stack([arr] * 3, -1)
    if arr.shape[2] == 3:
        arr = np.concatenate([arr, np.full(arr.shape[:2] + (1,), 255, np.uint8)], -1)
    return np.ascontiguousarray(arr[..., :4])


# ---------------------------------------------------------------------------------------------
# Scene graph
# ---------------------------------------------------------------------------------------------

def _node_matrix(node: dict) -> np.ndarray:
    if "matrix" in node:
        return np.array(node["matrix"], np.float64).reshape(4, 4).T  # glTF is column-major
    m = np.eye(4)
    s = np.array(node.get("scale", [1, 1, 1]), np.float64)
    r = np.array(node.get("rotation", [0, 0, 0, 1]), np.float64)
    m[:3, :3] = quat_to_matrix(r / max(np.linalg.norm(r), 1e-12)) * s[None, :]
    m[:3, 3] = node.get("translation", [0, 0, 0])
    return m


def _world_matrices(nodes: list[dict], path: Path) -> tuple[np.ndarray, np.ndarray]:
    """World matrix and parent index of every node (scenes' roots have parent -1); every matrix finite."""
    n = len(nodes)
    parent = node_parents(nodes, path)
    world = np.zeros((n, 4, 4))
    done = np.zeros(n, bool)

    def solve(i: int) -> np.ndarray:
        chain = []
        while i >= 0 and not done[i]:
            chain.append(i)
            i = parent[i]
        base = world[i] if i >= 0 else np.eye(4)
        for k in reversed(chain):
            with np.errstate(over="ignore", invalid="ignore"):
                base = base @ _node_matrix(nodes[k])
            if not np.isfinite(base).all():
                raise InputError(path, f"key nodes[{k}]", "the node's transform (with its parents') overflows "
                                 "to infinity: its scale or translation is far too large" + _DAMAGED)
            world[k] = base
            done[k] = True
        return base

    for i in range(n):
        if not done[i]:
            solve(i)
    return world, parent


def _pascal(bone: str) -> str:
    return bone[:1].upper() + bone[1:]


_VRM1_RENAME = {"ThumbMetacarpal": "ThumbProximal", "ThumbProximal": "ThumbIntermediate"}


def _vrm_bone_names(gltf: dict) -> dict[int, str]:
    """Node index -> Unity humanoid name, from a VRM 0.x or 1.0 extension (empty when not VRM)."""
    ext = gltf.get("extensions", {})
    out: dict[int, str] = {}
    if "VRMC_vrm" in ext:
        for bone, spec in ext["VRMC_vrm"].get("humanoid", {}).get("humanBones", {}).items():
            name = _pascal(bone)
            for old, new in _VRM1_RENAME.items():
                if name.endswith(old):
                    name = name[: -len(old)] + new
                    break
            out[int(spec["node"])] = name
    elif "VRM" in ext:
        for spec in ext["VRM"].get("humanoid", {}).get("humanBones", []):
            if "node" in spec and "bone" in spec:
                out[int(spec["node"])] = _pascal(spec["bone"])
    return out


def _direction_name(v: np.ndarray) -> str:
    """'+Z', '-X', ... for the axis nearest to an XZ direction (for notes and reports)."""
    k = 0 if abs(v[0]) > abs(v[2]) else 2
    return ("+" if v[k] > 0 else "-") + "XYZ"[k]


def _arkit_target_names(gltf: dict) -> set[str]:
    """ARKit shapes some morph target of the file is named after (those win over VRM expressions)."""
    found = set()
    for mesh in gltf.get("meshes", []):
        for prim in mesh.get("primitives", []):
            names = prim.get("extras", {}).get("targetNames", mesh.get("extras", {}).get("targetNames", []))
            found |= {match_arkit_name(n) for n in names} - {None}
    return found


def _vrm_arkit_expressions(gltf: dict, nodes: list[dict]) -> dict[tuple[int, int], list[tuple[str, float]]]:
    """``(mesh, target index) -> [(ARKit name, weight)]`` from VRM expressions named as ARKit shapes.

    "Perfect sync" VRM avatars expose the 52 ARKit shapes as VRM 1.0 custom expressions
    (``expressions.custom.jawOpen.morphTargetBinds``) or VRM 0.x blend shape groups (weights 0..100)
    over morph targets with other names.
    """
    out: dict[tuple[int, int], list[tuple[str, float]]] = {}
    ext = gltf.get("extensions", {})
    if "VRMC_vrm" in ext:
        expressions = ext["VRMC_vrm"].get("expressions", {})
        for group in ("preset", "custom"):
            for name, spec in expressions.get(group, {}).items():
                arkit = match_arkit_name(name)
                for bind in (spec.get("morphTargetBinds", []) if arkit else []):
                    node = bind.get("node")
                    if isinstance(node, int) and 0 <= node < len(nodes) and "mesh" in nodes[node]:
                        key = (nodes[node]["mesh"], int(bind.get("index", -1)))
                        out.setdefault(key, []).append((arkit, float(bind.get("weight", 1.0))))
    elif "VRM" in ext:
        for group in ext["VRM"].get("blendShapeMaster", {}).get("blendShapeGroups", []):
            arkit = match_arkit_name(group.get("name", ""))
            for bind in (group.get("binds", []) if arkit else []):
                key = (int(bind.get("mesh", -1)), int(bind.get("index", -1)))
                out.setdefault(key, []).append((arkit, float(bind.get("weight", 100.0)) / 100.0))
    return out


def _rigid(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (scale removed, via SVD) and translation of a 4x4 matrix."""
    u, _, vt = np.linalg.svd(m[:3, :3])
    r = u @ vt
    if np.linalg.det(r) < 0:
        u[:, -1] *= -1
        r = u @ vt
    return r, m[:3, 3].copy()


# ---------------------------------------------------------------------------------------------
# Loader
# ---------------------------------------------------------------------------------------------

def _hierarchy_joints(node_parent: np.ndarray, mesh_nodes: list[int], vrm: dict[int, str]) -> list[int]:
    """Joint nodes of a file without a skin: its VRM humanoid bones, else every ancestor of a mesh.

    Meshes then hang from their nearest joint ancestor and move rigidly with it.
    """
    if vrm:
        return sorted(vrm)
    out: set[int] = set()
    for m in mesh_nodes:
        p = int(node_parent[m])
        while p >= 0 and p not in out:
            out.add(p)
            p = int(node_parent[p])
    return sorted(out) or [mesh_nodes[0]]


def _joint_order(joint_nodes: list[int], node_parent: np.ndarray) -> tuple[list[int], dict[int, int]]:
    """Joints depth-first (parents before children) and each joint node's nearest joint ancestor (-1: none)."""
    jset = set(joint_nodes)
    up: dict[int, int] = {}
    for n in joint_nodes:
        p = int(node_parent[n])
        while p >= 0 and p not in jset:
            p = int(node_parent[p])
        up[n] = p
    children: dict[int, list[int]] = {}
    roots = []
    for n in joint_nodes:
        (children.setdefault(up[n], []) if up[n] >= 0 else roots).append(n)
    order: list[int] = []
    stack = list(reversed(roots))
    while stack:
        n = stack.pop()
        order.append(n)
        stack.extend(reversed(children.get(n, [])))
    return order, up


def _skeleton(order: list[int], up: dict[int, int], names: list[str], world: np.ndarray) -> Skeleton:
    """The joints' rest pose from node world matrices: rotations kept, scale folded into the offsets."""
    node_to_joint = {n: j for j, n in enumerate(order)}
    rots = np.zeros((len(order), 3, 3))
    pos = np.zeros((len(order), 3))
    for j, n in enumerate(order):
        rots[j], pos[j] = _rigid(world[n])
    parents = np.array([node_to_joint.get(up[n], -1) for n in order])
    offsets = np.zeros((len(order), 3))
    local_q = np.zeros((len(order), 4))
    for j in range(len(order)):
        p = parents[j]
        if p < 0:
            offsets[j] = pos[j]
            local_q[j] = matrix_to_quat(rots[j])
        else:
            offsets[j] = rots[p].T @ (pos[j] - pos[p])
            local_q[j] = matrix_to_quat(rots[p].T @ rots[j])
    return Skeleton(names=tuple(names), parents=parents, offsets=offsets, unit_scale=1.0, rest_rotations=local_q)


def _inverse_binds(doc: _Doc, skin: int, n_joints: int) -> np.ndarray:
    """A skin's inverse bind matrices as ``(n, 4, 4)`` row-major float64: one invertible matrix per joint."""
    index = doc.gltf["skins"][skin]["inverseBindMatrices"]
    where = f"skins[{skin}].inverseBindMatrices"
    m = doc.checked(index, where, ("MAT4",)).astype(np.float64)
    if len(m) < n_joints:
        raise InputError(doc.path, f"key {where}", f"accessor {index} has {len(m)} matrices for {n_joints} joints"
                         + _DAMAGED)
    m = m.reshape(-1, 4, 4).transpose(0, 2, 1)
    _check_invertible(m[:n_joints, :3, :3], doc.path, where, "matrix")
    return m


def _singular(m: np.ndarray) -> np.ndarray:
    """Which of the ``(..., 3, 3)`` transforms cannot be inverted (relative to their own scale)."""
    with np.errstate(over="ignore", invalid="ignore"):
        det = np.linalg.det(m)
        scale = np.abs(m).max(axis=(-2, -1)) ** 3
    return ~(np.isfinite(det) & (np.abs(det) > 1e-12 * scale))


def _check_invertible(m: np.ndarray, path: Path, where: str, item: str = "vertex") -> None:
    """Refuse 3x3 transforms that cannot be inverted (skinning inverts them to carry normals)."""
    bad = _singular(m)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputError(path, f"key {where}", f"{item} {k}: singular transform (a zero scale or a degenerate "
                         "inverse bind matrix), so its normals cannot be computed" + _DAMAGED)


def load_gltf(path: str | Path, bone_map: dict[str, str] | None = None) -> Avatar:
    """Load a glTF/GLB/VRM avatar (see the module docstring for what is supported).

    ``bone_map`` (``{joint name: humanoid bone}``, the design's ``[avatar.bone_map]``) names the humanoid
    bones of joints whose names are not recognised; joint names may be a VRM node's own name too. It is
    kept on the avatar (``Avatar.bone_map``) for retargeting and is used to measure the facing.
    """
    path = Path(path)
    doc = _Doc(path)
    g = doc.gltf
    nodes = g.get("nodes", [])
    world, node_parent = _world_matrices(nodes, path)
    notes: list[str] = []
    skins = g.get("skins", [])
    mesh_nodes = [i for i, n in enumerate(nodes) if "mesh" in n]
    if not mesh_nodes:
        raise InputError(path, "key nodes", "no node has a mesh; export the character with its mesh, "
                         "not only its armature or animation")
    skin_index = next((nodes[i]["skin"] for i in mesh_nodes if "skin" in nodes[i]), 0 if skins else None)
    joint_nodes = list(skins[skin_index]["joints"]) if skin_index is not None else []
    if len(set(joint_nodes)) < len(joint_nodes):
        twice = next(n for n in joint_nodes if joint_nodes.count(n) > 1)
        raise InputError(path, f"key skins[{skin_index}].joints", f"node {twice} is listed twice" + _DAMAGED)
    if skin_index is not None and len(skins) > 1:
        notes.append(f"{len(skins)} skins; using skin {skin_index} for every skinned mesh")
    vrm = _vrm_bone_names(g)
    if not joint_nodes:
        joint_nodes = _hierarchy_joints(node_parent, mesh_nodes, vrm)
        notes.append("no skin: skeleton from the node hierarchy; meshes move rigidly with their bones")

    # skeleton: joints in depth-first order (parents before children)
    order, up = _joint_order(joint_nodes, node_parent)
    from studyapp.render.gpu import MAX_BONES

    if len(order) > MAX_BONES:
        raise InputError(path, f"key skins[{skin_index}].joints",
                         f"{len(order)} joints; the renderer supports at most {MAX_BONES} (remove unused bones)")
    node_to_joint = {n: j for j, n in enumerate(order)}
    names: list[str] = []
    aliases: dict[str, str] = {}  # a VRM node's own name -> its humanoid joint name
    for n in order:
        name = vrm.get(n) or nodes[n].get("name") or f"joint{n}"
        while name in names:  # a duplicate, and even "Arm_7" for the second "Arm" (node 7) may be taken
            name = f"{name}_{n}"
        names.append(name)
        if nodes[n].get("name") and nodes[n]["name"] != name:
            aliases[nodes[n]["name"]] = name
    skeleton = _skeleton(order, up, names, world)

    # facing: measured on the rest pose, then the whole file is turned to face +Z (the camera)
    from studyapp.render.avatar_rig import (bone_map_problems, humanoid_map, resolve_bone_map, rest_facing, yaw_matrix,
                                            yaw_to_face_z)

    given = resolve_bone_map(skeleton.names, bone_map, aliases)
    notes += [f"[avatar.bone_map] {j}: {problem} (entry ignored)"
              for j, problem in bone_map_problems(skeleton.names, bone_map or {}, aliases)]
    bones = {b: skeleton.index(j) for j, b in humanoid_map(skeleton, given).items()}
    forward = rest_facing(rest_global_transforms(skeleton)[:, :3, 3], bones)
    if forward is None:
        notes.append("facing not measured (no left/right pair of humanoid bones); assumed +Z")
    else:
        angle = yaw_to_face_z(forward)
        if abs(angle) > np.radians(1.0):
            world = yaw_matrix(angle)[None] @ world
            skeleton = _skeleton(order, up, names, world)
            notes.append(f"faced {_direction_name(forward)} at rest: turned {np.degrees(angle):.0f} degrees to face +Z")
    rest = rest_global_transforms(skeleton)
    if "Head" in bones and "Hips" in bones and rest[bones["Head"], 1, 3] <= rest[bones["Hips"], 1, 3]:
        notes.append("the figure is not upright in +Y (its head is not above its hips): re-export it Y up")

    # geometry
    skin_ibm = None
    if skin_index is not None and "inverseBindMatrices" in skins[skin_index]:
        skin_ibm = _inverse_binds(doc, skin_index, len(joint_nodes))
    parts = []
    total_vertices = 0
    textures: dict[int, np.ndarray | None] = {}
    morph_names_found: set[str] = set()
    ignored: set[str] = set()
    named_arkit = _arkit_target_names(g)
    expression_binds = _vrm_arkit_expressions(g, nodes)
    for ni in mesh_nodes:
        node = nodes[ni]
        mesh = g["meshes"][node["mesh"]]
        target_names = list(mesh.get("extras", {}).get("targetNames", []))
        skinned = "skin" in node and skin_index is not None
        if skinned and node["skin"] != skin_index:
            notes.append(f"mesh node {ni} uses skin {node['skin']}; bound to skin {skin_index} by joint name")
        for pi, prim in enumerate(mesh.get("primitives", [])):
            where = f"meshes[{node['mesh']}].primitives[{pi}]"
            if prim.get("mode", 4) != 4:
                notes.append(f"{where}: not triangles (mode {prim.get('mode')}), skipped")
                continue
            attrs = prim.get("attributes", {})
            for ext in prim.get("extensions", {}):
                if ext in _UNSUPPORTED:
                    raise InputError(path, f"key {where}.extensions", f"{ext} ({_UNSUPPORTED[ext]}) is not supported")
            if "POSITION" not in attrs:
                raise InputError(path, f"key {where}.attributes", "primitive has no POSITION" + _DAMAGED)
            v = doc.checked(attrs["POSITION"], f"{where}.attributes.POSITION", ("VEC3",)).astype(np.float64)
            nv = len(v)
            total_vertices += nv
            if total_vertices > MAX_VERTICES:
                raise InputError(path, f"key {where}.attributes.POSITION", f"the avatar has more than {MAX_VERTICES} "
                                 "vertices, more than the renderer is made for: decimate the mesh")

            def attribute(name: str, types: tuple[str, ...], integer: bool = False, of: dict = attrs,
                          at: str = f"{where}.attributes") -> np.ndarray:
                return doc.checked(of[name], f"{at}.{name}", types, nv, integer)

            idx = (doc.checked(prim["indices"], f"{where}.indices", ("SCALAR",), integer=True).reshape(-1)
                   .astype(np.int64) if "indices" in prim else np.arange(nv))
            if len(idx) % 3:
                raise InputError(path, f"key {where}.indices", f"{len(idx)} indices is not a multiple of 3" + _DAMAGED)
            if len(idx) and idx.max() >= nv:
                raise InputError(path, f"key {where}.indices", "index beyond the vertex count" + _DAMAGED)
            tri = idx.reshape(-1, 3)
            nrm = (attribute("NORMAL", ("VEC3",)).astype(np.float64) if "NORMAL" in attrs
                   else vertex_normals(v, tri).astype(np.float64))
            if skinned and "JOINTS_0" in attrs and "WEIGHTS_0" in attrs:
                jj = attribute("JOINTS_0", ("VEC4",), integer=True).astype(np.int64)
                ww = attribute("WEIGHTS_0", ("VEC4",)).astype(np.float64)
                if jj.max(initial=0) >= len(joint_nodes):
                    raise InputError(path, f"key {where}.attributes.JOINTS_0",
                                     "joint index beyond the skin's joints" + _DAMAGED)
                jj = np.vectorize(lambda k: node_to_joint[joint_nodes[k]])(jj) if jj.size else jj
                jj = np.asarray(jj, np.int64).reshape(nv, 4)
                ibm = skin_ibm if skin_ibm is not None else np.broadcast_to(np.eye(4), (len(joint_nodes), 4, 4))
                # bind matrix per skin joint: world rest x inverse bind (identity for a clean export)
                bind_by_joint = np.zeros((len(order), 4, 4))
                for k, n in enumerate(joint_nodes):
                    bind_by_joint[node_to_joint[n]] = world[n] @ ibm[k]
                s = ww.sum(1, keepdims=True)
                if np.abs(s - 1).max(initial=0) > 1e-5:
                    ww = np.where(s > 0, ww / np.where(s > 0, s, 1), [[1.0, 0, 0, 0]])
                blend = np.einsum("vk,vkij->vij", ww, bind_by_joint[jj])
            else:
                if _singular(world[ni, :3, :3]):  # a part hidden by a zero scale stays hidden
                    notes.append(f"{where}: its node {ni} has a zero scale, not drawn")
                    continue
                p = ni
                while p >= 0 and p not in node_to_joint:
                    p = node_parent[p]
                j = node_to_joint.get(p, 0)
                jj = np.zeros((nv, 4), np.int64)
                jj[:, 0] = j
                ww = np.zeros((nv, 4))
                ww[:, 0] = 1
                blend = np.broadcast_to(world[ni], (nv, 4, 4))
            if np.abs(blend - np.eye(4)).max() > 1e-5:
                _check_invertible(blend[:, :3, :3], path, where)
                v = np.einsum("vij,vj->vi", blend[:, :3, :3], v) + blend[:, :3, 3]
                nrm = np.einsum("vij,vj->vi", np.linalg.inv(blend[:, :3, :3]).transpose(0, 2, 1), nrm)
            else:
                blend = None
            ln = np.linalg.norm(nrm, axis=1, keepdims=True)
            if np.abs(ln - 1).max(initial=0) > 1e-5:  # leave unit normals bit-exact
                nrm = np.where(ln > 1e-12, nrm / np.maximum(ln, 1e-12), [[0, 1.0, 0]])
            # material
            mat = g.get("materials", [])[prim["material"]] if "material" in prim else {}
            pbr = mat.get("pbrMetallicRoughness", {})
            factor = np.array(pbr.get("baseColorFactor", [1, 1, 1, 1]), np.float64)
            col = np.tile(factor[:3], (nv, 1))
            if "COLOR_0" in attrs:
                c0 = attribute("COLOR_0", ("VEC3", "VEC4")).astype(np.float64)
                if c0.dtype.kind != "f" or c0.max() > 1.0 + 1e-6:
                    c0 = c0 / max(c0.max(), 1.0)
                col = col * c0[:, :3]
            material_ids = (attribute("_MATERIAL", ("SCALAR",)).reshape(-1).astype(np.uint8)
                            if "_MATERIAL" in attrs else np.zeros(nv, np.uint8))
            tex_index = None
            if "baseColorTexture" in pbr:
                ti = pbr["baseColorTexture"].get("index")
                tex = g.get("textures", [])[ti] if ti is not None and ti < len(g.get("textures", [])) else {}
                if "source" in tex:
                    tex_index = tex["source"]
                    if tex_index not in textures:
                        textures[tex_index] = doc.image(tex_index)
                        pixels = sum(t.shape[0] * t.shape[1] for t in textures.values() if t is not None)
                        if pixels > MAX_TEXTURE_PIXELS_TOTAL:
                            raise InputError(path, f"key images[{tex_index}]", f"the textures used so far have "
                                             f"{pixels} pixels; at most {MAX_TEXTURE_PIXELS_TOTAL} are read: "
                                             "scale them down")
                else:
                    notes.append(f"{where}: texture without a PNG/JPEG source ignored")
            uv = attribute("TEXCOORD_0", ("VEC2",)).astype(np.float64) if "TEXCOORD_0" in attrs else None
            if uv is not None and "baseColorTexture" in pbr:
                uv = _texture_transform(uv, pbr["baseColorTexture"].get("extensions", {}).get("KHR_texture_transform"))
            # morph targets
            targets = prim.get("targets", [])
            names_here = list(prim.get("extras", {}).get("targetNames", target_names))
            deltas = {}
            for ti, t in enumerate(targets):
                raw = names_here[ti] if ti < len(names_here) else f"target{ti}"
                arkit = match_arkit_name(raw)
                # a target named as ARKit counts fully; VRM expressions named as ARKit add their weighted binds
                uses = [(arkit, 1.0)] if arkit is not None else []
                uses += [(a, w) for a, w in expression_binds.get((node["mesh"], ti), []) if a not in named_arkit]
                if not uses:
                    ignored.add(raw)
                    continue
                at = f"{where}.targets[{ti}]"
                d, dn = (attribute(a, ("VEC3",), of=t, at=at).astype(np.float64) if a in t else np.zeros((nv, 3))
                         for a in ("POSITION", "NORMAL"))
                if blend is not None:
                    d = np.einsum("vij,vj->vi", blend[:, :3, :3], d)
                    dn = np.einsum("vij,vj->vi", blend[:, :3, :3], dn)
                for name, w in uses:
                    prev = deltas.get(name)
                    deltas[name] = (w * d, w * dn) if prev is None else (prev[0] + w * d, prev[1] + w * dn)
                    morph_names_found.add(name)
            parts.append(dict(v=v, n=nrm, tri=tri, col=col, j=jj, w=ww, uv=uv, tex=tex_index, deltas=deltas,
                              mat=material_ids, alpha=factor[3], double=bool(mat.get("doubleSided", False))))
    if not parts:
        raise InputError(path, "key meshes", "no triangle primitives to draw")
    if ignored:
        notes.append(f"ignored {len(ignored)} non-ARKit morph targets: {', '.join(sorted(ignored)[:8])}"
                     + (" ..." if len(ignored) > 8 else ""))

    # one texture can stay a texture; several are baked into vertex colours
    used = sorted({p["tex"] for p in parts if p["tex"] is not None and textures.get(p["tex"]) is not None})
    texture = None
    if len(used) == 1:
        texture = textures[used[0]]
    elif len(used) > 1:
        notes.append(f"{len(used)} base-colour textures baked into vertex colours")
        for p in parts:
            img = textures.get(p["tex"]) if p["tex"] is not None else None
            if img is not None and p["uv"] is not None:
                p["col"] = p["col"] * _sample(img, p["uv"])[:, :3]
                p["tex"] = None
    offset = 0
    tris, cols_uv = [], []
    for p in parts:
        tris.append(p["tri"] + offset)
        offset += len(p["v"])
        if texture is not None:
            # untextured parts get uv = -1, which the fragment shader reads as 'no texture'
            cols_uv.append(p["uv"] if (p["tex"] is not None and p["uv"] is not None) else np.full((len(p["v"]), 2), -1.0))
    V = offset
    deltas = np.zeros((len(ARKIT_NAMES), V, 3), np.float32)
    ndeltas = np.zeros((len(ARKIT_NAMES), V, 3), np.float32)
    start = 0
    for p in parts:
        n = len(p["v"])
        for name, (d, dn) in p["deltas"].items():
            k = ARKIT_NAMES.index(name)
            deltas[k, start:start + n] = d
            ndeltas[k, start:start + n] = dn
        start += n
    missing = [n for n in ARKIT_NAMES if n not in morph_names_found]
    if missing and morph_names_found:
        notes.append(f"{len(missing)} ARKit shapes missing (they stay neutral)")
    elif not morph_names_found:
        notes.append("no ARKit morph targets: the face will not animate")
    return Avatar(
        skeleton=skeleton,
        vertices=np.concatenate([p["v"] for p in parts]),
        normals=np.concatenate([p["n"] for p in parts]),
        indices=np.concatenate(tris),
        colors=np.concatenate([p["col"] for p in parts]),
        joints=np.concatenate([p["j"] for p in parts]),
        weights=np.concatenate([p["w"] for p in parts]),
        inverse_bind=np.linalg.inv(rest),
        morph_names=ARKIT_NAMES,
        morph_deltas=deltas,
        morph_normal_deltas=ndeltas,
        material=np.concatenate([p["mat"] for p in parts]),
        uv=np.concatenate(cols_uv) if texture is not None else None,
        texture=texture,
        double_sided=any(p["double"] for p in parts),
        name=path.stem,
        notes=tuple(notes),
        bone_map=given,
        source=str(path),
        joint_aliases=aliases,
    )


def _texture_transform(uv: np.ndarray, spec: dict | None) -> np.ndarray:
    """``KHR_texture_transform`` (offset, rotation, scale) applied to UVs; gltfpack uses it to dequantize them.

    >>> _texture_transform(np.array([[1.0, 1.0]]), {"offset": [0.5, 0.0], "scale": [0.25, 0.5]}).tolist()
    [[0.75, 0.5]]
    """
    if not spec:
        return uv
    sx, sy = spec.get("scale", [1.0, 1.0])
    ox, oy = spec.get("offset", [0.0, 0.0])
    r = float(spec.get("rotation", 0.0))
    c, s = np.cos(r), np.sin(r)
    u, v = uv[:, 0] * sx, uv[:, 1] * sy
    return np.c_[c * u + s * v + ox, -s * u + c * v + oy]


def _sample(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    x = np.clip((np.mod(uv[:, 0], 1.0) * w).astype(int), 0, w - 1)
    y = np.clip((np.mod(uv[:, 1], 1.0) * h).astype(int), 0, h - 1)  # glTF uv origin is the image's top left
    return img[y, x].astype(np.float64) / 255.0


# ---------------------------------------------------------------------------------------------
# Export
# ---------------------------------------------------------------------------------------------

class _BinWriter:
    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, raw: bytes, target: int | None = None) -> int:
        while len(self.data) % 4:
            self.data.append(0)
        v = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)}
        if target:
            v["target"] = target
        self.data.extend(raw)
        self.views.append(v)
        return len(self.views) - 1

    def accessor(self, arr: np.ndarray, kind: str, component: int, target: int | None = None,
                 minmax: bool = False, normalized: bool = False) -> int:
        arr = np.ascontiguousarray(arr)
        view = self.view(arr.tobytes(), target)
        acc = {"bufferView": view, "componentType": component, "count": int(arr.shape[0]), "type": kind}
        if normalized:
            acc["normalized"] = True
        if minmax:
            flat = arr.reshape(arr.shape[0], -1)
            acc["min"] = [float(x) for x in flat.min(0)]
            acc["max"] = [float(x) for x in flat.max(0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def export_glb(avatar: Avatar, path: str | Path) -> Path:
    """Write ``avatar`` as a GLB: joint nodes, one skinned mesh with ARKit morph targets (``targetNames``),
    vertex colours, the material id as the custom ``_MATERIAL`` attribute and the base-colour texture."""
    path = Path(path)
    sk = avatar.skeleton
    w = _BinWriter()
    ARRAY, ELEMENT = 34962, 34963
    nodes = []
    for j in range(sk.n_joints):
        node = {"name": sk.names[j], "translation": [float(x) for x in sk.offsets[j]]}
        q = sk.rest_rotations[j]
        if not np.allclose(q, [0, 0, 0, 1]):
            node["rotation"] = [float(x) for x in q]
        kids = sk.children(j)
        if kids:
            node["children"] = kids
        nodes.append(node)
    attrs = {
        "POSITION": w.accessor(avatar.vertices.astype(np.float32), "VEC3", 5126, ARRAY, minmax=True),
        "NORMAL": w.accessor(avatar.normals.astype(np.float32), "VEC3", 5126, ARRAY),
        "COLOR_0": w.accessor(avatar.colors.astype(np.float32), "VEC3", 5126, ARRAY),
        "JOINTS_0": w.accessor(avatar.joints.astype(np.uint16), "VEC4", 5123, ARRAY),
        "WEIGHTS_0": w.accessor(avatar.weights.astype(np.float32), "VEC4", 5126, ARRAY),
        "_MATERIAL": w.accessor(avatar.material.astype(np.uint8).reshape(-1, 1), "SCALAR", 5121, ARRAY),
    }
    if avatar.uv is not None:
        attrs["TEXCOORD_0"] = w.accessor(avatar.uv.astype(np.float32), "VEC2", 5126, ARRAY)
    indices = w.accessor(avatar.indices.astype(np.uint32).reshape(-1, 1), "SCALAR", 5125, ELEMENT)
    targets = []
    for m in range(len(avatar.morph_names)):
        t = {"POSITION": w.accessor(avatar.morph_deltas[m].astype(np.float32), "VEC3", 5126, ARRAY, minmax=True)}
        if avatar.morph_normal_deltas is not None:
            t["NORMAL"] = w.accessor(avatar.morph_normal_deltas[m].astype(np.float32), "VEC3", 5126, ARRAY)
        targets.append(t)
    ibm = np.ascontiguousarray(avatar.inverse_bind.astype(np.float32).transpose(0, 2, 1)).reshape(-1, 16)
    ibm_acc = w.accessor(ibm, "MAT4", 5126)
    material = {"name": "base", "doubleSided": bool(avatar.double_sided), "pbrMetallicRoughness": {
        "baseColorFactor": [float(x) for x in avatar.base_color_factor], "metallicFactor": 0.0, "roughnessFactor": 0.8}}
    gltf: dict = {
        "asset": {"version": "2.0", "generator": "studyapp"},
        "scene": 0,
        "materials": [material],
    }
    if avatar.texture is not None:
        from PIL import Image

        png = io.BytesIO()
        Image.fromarray(np.ascontiguousarray(avatar.texture, np.uint8)).save(png, format="png")
        iv = w.view(png.getvalue())
        gltf["images"] = [{"bufferView": iv, "mimeType": "image/png"}]
        gltf["samplers"] = [{"magFilter": 9729, "minFilter": 9987}]
        gltf["textures"] = [{"source": 0, "sampler": 0}]
        material["pbrMetallicRoughness"]["baseColorTexture"] = {"index": 0}
    mesh_node = len(nodes)
    nodes.append({"name": avatar.name or "avatar", "mesh": 0, "skin": 0})
    roots = [j for j in range(sk.n_joints) if sk.parents[j] < 0]
    gltf["scenes"] = [{"nodes": roots + [mesh_node]}]
    gltf["nodes"] = nodes
    gltf["meshes"] = [{"name": avatar.name or "avatar", "primitives": [
        {"attributes": attrs, "indices": indices, "material": 0, "mode": 4, "targets": targets}],
        "weights": [0.0] * len(avatar.morph_names),
        "extras": {"targetNames": list(avatar.morph_names)}}]
    gltf["skins"] = [{"joints": list(range(sk.n_joints)), "inverseBindMatrices": ibm_acc, "skeleton": roots[0]}]
    gltf["accessors"] = w.accessors
    gltf["bufferViews"] = w.views
    while len(w.data) % 4:
        w.data.append(0)
    gltf["buffers"] = [{"byteLength": len(w.data)}]
    js = json.dumps(gltf, separators=(",", ":")).encode("utf-8")
    js += b" " * (-len(js) % 4)
    total = 12 + 8 + len(js) + 8 + len(w.data)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        f.write(struct.pack("<III", GLB_MAGIC, 2, total))
        f.write(struct.pack("<II", len(js), CHUNK_JSON))
        f.write(js)
        f.write(struct.pack("<II", len(w.data), CHUNK_BIN))
        f.write(bytes(w.data))
    return path
