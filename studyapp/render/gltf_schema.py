"""What a glTF document must satisfy before :mod:`studyapp.render.gltf` trusts its types, indices and sizes.

A glTF file is a JSON document that points into binary buffers by index and byte offset. The loader reads
it by plain indexing, so everything it reads is checked here first, and each problem is one
:class:`~studyapp.errors.InputError` naming the file, the JSON place (``key accessors[3].count``) and
what is wrong:

* :func:`parse_json`: UTF-8 JSON, nested at most :data:`MAX_JSON_DEPTH` deep and of at most
  :data:`MAX_JSON_VALUES` values (both measured before parsing, so a 100,000-deep ``[[[[...`` is refused
  without recursion), numbers of at most 4,300 digits.
* :func:`check_document`: every field the loader reads has the right JSON type (integers are integers,
  not floats or booleans), every index points at an existing item (``accessors[3].bufferView`` <
  ``len(bufferViews)``), every number is finite, and enumerations (``componentType``, ``type``, ``mode``)
  hold known values; at most :data:`MAX_NODES` nodes. Unknown keys and extensions the loader does not
  read are left alone (glTF is extensible). VRM 0.x and 1.0 humanoid and expression fields are checked the same way.
* :func:`node_parents`: each node has at most one parent, no node is its own ancestor and the hierarchy
  is at most :data:`MAX_NODE_DEPTH` levels deep.
* :func:`confined_file`: an external ``uri`` (buffer or image) names a regular file inside the glTF's own
  folder: absolute paths, ``..`` that leaves the folder (also through symbolic links), URL schemes other
  than ``data:`` and NUL bytes are refused before anything is opened.

The byte-level limits (GLB chunks, buffers, buffer views, accessors) are checked where the bytes are
read, in :mod:`studyapp.render.gltf`, with the limits defined here.

>>> check_document({"asset": {"version": "2.0"}, "nodes": [{"children": [1]}, {"mesh": 0}]}, "a.gltf")
Traceback (most recent call last):
    ...
studyapp.errors.InputError: a.gltf, key nodes[1].mesh: index 0, but the file has 0 meshes; the file is damaged or breaks the glTF 2.0 rules: download or export it again (the Khronos glTF Validator shows what is wrong)
>>> node_parents([{"children": [1]}, {"children": [0]}], "a.gltf")
Traceback (most recent call last):
    ...
studyapp.errors.InputError: a.gltf, key nodes[1].children: node 0 is its own ancestor (the node hierarchy has a cycle); the file is damaged or breaks the glTF 2.0 rules: download or export it again (the Khronos glTF Validator shows what is wrong)
"""
from __future__ import annotations

import json
import math
import re
from collections.abc import Callable
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from studyapp.errors import InputError

#: JSON nesting accepted (a glTF document is ~6 deep; VRM extensions and extras a few more).
MAX_JSON_DEPTH = 64
#: Bytes of the JSON text (a .gltf may embed its buffers as base64 ``data:`` URIs; a .glb's JSON is small).
MAX_JSON_BYTES = 128 * 2**20
#: Values (array items and object members) in the JSON: a large avatar has ~100,000; each costs Python
#: ~100 bytes once parsed, so this bounds the parsed document to a few hundred MB.
MAX_JSON_VALUES = 2_000_000
#: Nodes: real avatars have a few hundred to a few thousand; each costs the loader ~0.1 ms.
MAX_NODES = 16_384
#: Levels of nodes below a scene root (real rigs, hair chains included, stay under 40).
MAX_NODE_DEPTH = 256
#: Bytes of an avatar file or external buffer or image: far above any real-time avatar, and safely below
#: the memory the loader then needs.
MAX_FILE_BYTES = 512 * 2**20
#: Bytes one meshopt-compressed buffer view may decode to: the stream can compress 64 to 1 and this
#: decoder writes about a megabyte a second, so the bound keeps a crafted file from running for minutes
#: (gltfpack's largest real view, 52 quantized morph targets of 300,000 vertices, fits).
MAX_DECODED_VIEW = 64 * 2**20
#: Vertices of the whole avatar: each costs ~1.3 kB of morph-target arrays (52 ARKit shapes, positions
#: and normals), so this keeps a loaded avatar under ~700 MB; real-time avatars have under 100,000.
MAX_VERTICES = 500_000
#: Pixels of one texture (8192 x 4096): decoding goes through 16-byte float pixels.
MAX_TEXTURE_PIXELS = 8192 * 4096
#: Pixels of all textures an avatar uses (each kept as 4 bytes a pixel while loading; real avatars have
#: a dozen textures of 2048 x 2048 or fewer).
MAX_TEXTURE_PIXELS_TOTAL = 4 * MAX_TEXTURE_PIXELS

# what to do about a file that breaks the glTF rules (truncated download, buggy exporter)
DAMAGED = ("; the file is damaged or breaks the glTF 2.0 rules: download or export it again "
           "(the Khronos glTF Validator shows what is wrong)")

COMPONENT_TYPES = {5120: "byte", 5121: "unsigned byte", 5122: "short", 5123: "unsigned short",
                   5125: "unsigned int", 5126: "float"}
ELEMENT_TYPES = ("SCALAR", "VEC2", "VEC3", "VEC4", "MAT2", "MAT3", "MAT4")



def json_shape(text: bytes, chunk: int = 1 << 22) -> tuple[int, int]:
    """Deepest nesting of ``[``/``{`` in JSON text and roughly how many values it holds (separators and
    brackets), outside strings: linear time, no recursion, nothing parsed, read ``chunk`` bytes at a time
    so the scan itself needs little memory.

    >>> json_shape(b'{"a": [1, {"b": "[[[[,,,"}]}')
    (3, 9)
    """
    depth = deepest = values = 0
    inside = False  # within a string at the chunk's start
    run = 0  # backslashes just before the chunk's start
    for start in range(0, len(text), chunk):
        b = np.frombuffer(text, np.uint8, min(chunk, len(text) - start), start)
        n = len(b)
        # a quote ends or starts a string unless an odd run of backslashes escapes it
        is_bs = b == ord("\\")
        last = np.where(is_bs, -1, np.arange(n, dtype=np.int64))
        last = np.maximum.accumulate(last)  # last non-backslash at or before each byte (-1: none)
        quotes = np.flatnonzero(b == ord('"'))
        before = np.where(quotes > 0, last[np.maximum(quotes - 1, 0)], -1)
        runs = quotes - 1 - before + np.where(before < 0, run, 0)
        toggles = np.zeros(n, np.uint8)
        toggles[quotes[runs % 2 == 0]] = 1
        parity = np.bitwise_xor.accumulate(toggles) ^ np.uint8(inside)
        outside = parity == 0  # brackets and separators are never quotes themselves
        step = (outside & ((b == ord("[")) | (b == ord("{")))).astype(np.int64)
        closes = outside & ((b == ord("]")) | (b == ord("}")))
        level = depth + np.cumsum(step - closes)
        deepest = max(deepest, int(level.max(initial=depth)))
        depth = int(level[-1]) if n else depth
        values += int(step.sum() + closes.sum() + (outside & ((b == ord(",")) | (b == ord(":")))).sum())
        inside = bool(parity[-1]) if n else inside
        run = n - 1 - int(last[-1]) + (run if last[-1] < 0 else 0) if n else run
    return deepest, values


def parse_json(text: bytes, path: str | Path, where: str | None) -> object:
    """JSON text (UTF-8, an optional BOM) -> Python value, or an InputError naming ``where``."""
    if text.startswith(b"\xef\xbb\xbf"):
        text = text[3:]
    try:
        decoded = text.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(path, where, f"the JSON is not UTF-8 text (byte {exc.start})" + DAMAGED) from None
    if len(text) > MAX_JSON_BYTES:
        raise InputError(path, where, f"{len(text)} bytes of JSON; at most {MAX_JSON_BYTES} are read (a .gltf "
                         "with large embedded data: URIs converts to a .glb, e.g. with gltfpack or Blender)")
    depth, values = json_shape(text)
    if depth > MAX_JSON_DEPTH:
        raise InputError(path, where, f"JSON nested {depth} levels deep; at most {MAX_JSON_DEPTH} are read" + DAMAGED)
    if values > MAX_JSON_VALUES:
        raise InputError(path, where, f"JSON of about {values} values; at most {MAX_JSON_VALUES} are read" + DAMAGED)
    try:
        return json.loads(decoded)
    except json.JSONDecodeError as exc:
        place = f"line {exc.lineno}, column {exc.colno}"
        raise InputError(path, f"{where}, {place}" if where else place, f"invalid JSON: {exc.msg}") from None
    except (ValueError, RecursionError) as exc:  # e.g. an integer of more than 4,300 digits
        raise InputError(path, where, f"invalid JSON: {exc}" + DAMAGED) from None


# ---------------------------------------------------------------------------------------------
# Document structure: a small combinator schema of exactly what the loader reads
# ---------------------------------------------------------------------------------------------

Check = Callable[[object, str, "_Context"], None]


class _Context:
    def __init__(self, doc: dict, path: str | Path) -> None:
        self.doc = doc
        self.path = path

    def fail(self, where: str, problem: str) -> None:
        raise InputError(self.path, f"key {where}", problem + DAMAGED)

    def length(self, kind: str) -> int:
        items = self.doc.get(kind)
        return len(items) if isinstance(items, list) else 0


def _kind(value: object) -> str:
    if isinstance(value, bool):
        return "a boolean"
    if value is None:
        return "null"
    return {int: "an integer", float: "a number", str: "a string", list: "an array", dict: "an object"}.get(
        type(value), type(value).__name__)


def _is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def integer(lo: int = 0, hi: int = 2**53) -> Check:
    def check(value: object, where: str, ctx: _Context) -> None:
        if not _is_int(value):
            ctx.fail(where, f"must be an integer, not {_kind(value)} ({value!r:.40})")
        if not lo <= value <= hi:  # type: ignore[operator]
            ctx.fail(where, f"{value} is out of range ({lo} to {hi})")
    return check


def index(kind: str) -> Check:
    def check(value: object, where: str, ctx: _Context) -> None:
        if not _is_int(value):
            ctx.fail(where, f"must be an index into {kind}, not {_kind(value)} ({value!r:.40})")
        n = ctx.length(kind)
        if not 0 <= value < n:  # type: ignore[operator]
            ctx.fail(where, f"index {value}, but the file has {n} {kind}")
    return check


def number(value: object, where: str, ctx: _Context) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        ctx.fail(where, f"must be a number, not {_kind(value)} ({value!r:.40})")
    try:
        finite = math.isfinite(value)  # type: ignore[arg-type]
    except OverflowError:  # an integer too large for a float
        finite = False
    if not finite:
        ctx.fail(where, f"must be a finite number, not {value!r:.40}")


def numbers(n: int) -> Check:
    def check(value: object, where: str, ctx: _Context) -> None:
        if not isinstance(value, list) or len(value) != n:
            ctx.fail(where, f"must be an array of {n} numbers, not {_kind(value)} ({value!r:.60})")
        for i, x in enumerate(value):  # type: ignore[arg-type]
            number(x, f"{where}[{i}]", ctx)
    return check


def string(value: object, where: str, ctx: _Context) -> None:
    if not isinstance(value, str):
        ctx.fail(where, f"must be a string, not {_kind(value)} ({value!r:.40})")


def boolean(value: object, where: str, ctx: _Context) -> None:
    if not isinstance(value, bool):
        ctx.fail(where, f"must be true or false, not {_kind(value)} ({value!r:.40})")


def one_of(*allowed: object) -> Check:
    def check(value: object, where: str, ctx: _Context) -> None:
        if isinstance(value, bool) or value not in allowed:
            ctx.fail(where, f"{value!r:.40} is not one of {', '.join(map(repr, allowed))}")
    return check


def array(item: Check) -> Check:
    def check(value: object, where: str, ctx: _Context) -> None:
        if not isinstance(value, list):
            ctx.fail(where, f"must be an array, not {_kind(value)} ({value!r:.40})")
        for i, x in enumerate(value):  # type: ignore[arg-type]
            item(x, f"{where}[{i}]", ctx)
    return check


def mapping(item: Check) -> Check:
    """An object whose every value satisfies ``item`` (attributes, VRM bone and expression tables)."""
    def check(value: object, where: str, ctx: _Context) -> None:
        if not isinstance(value, dict):
            ctx.fail(where, f"must be an object, not {_kind(value)} ({value!r:.40})")
        for k, x in value.items():  # type: ignore[union-attr]
            item(x, f"{where}.{k}", ctx)
    return check


def obj(fields: dict[str, Check] | None = None, required: tuple[str, ...] = ()) -> Check:
    """An object; the listed fields are checked when present, ``required`` ones must be present."""
    fields = fields or {}

    def check(value: object, where: str, ctx: _Context) -> None:
        if not isinstance(value, dict):
            ctx.fail(where, f"must be an object, not {_kind(value)} ({value!r:.40})")
        for key in required:
            if key not in value:  # type: ignore[operator]
                ctx.fail(f"{where}.{key}" if where else key, "is missing")
        for key, sub in fields.items():
            if key in value:  # type: ignore[operator]
                sub(value[key], f"{where}.{key}" if where else key, ctx)  # type: ignore[index]
    return check


_UINT = integer(0, 2**53)
_EXTENSIONS = obj()  # any extension objects: only those read are checked further
_NAMES = obj({"targetNames": array(string)})  # mesh and primitive extras
_MESHOPT = obj({"buffer": index("buffers"), "byteOffset": _UINT, "byteLength": _UINT, "byteStride": integer(1, 256),
                "count": _UINT, "mode": string, "filter": string},
               required=("buffer", "byteLength", "byteStride", "count", "mode"))
_SPARSE = obj({
    "count": integer(1),
    "indices": obj({"bufferView": index("bufferViews"), "byteOffset": _UINT, "componentType": one_of(5121, 5123, 5125)},
                   required=("bufferView", "componentType")),
    "values": obj({"bufferView": index("bufferViews"), "byteOffset": _UINT}, required=("bufferView",)),
}, required=("count", "indices", "values"))
_PRIMITIVE = obj({
    "attributes": mapping(index("accessors")), "indices": index("accessors"), "material": index("materials"),
    "mode": integer(0, 6), "targets": array(mapping(index("accessors"))), "extras": _NAMES, "extensions": _EXTENSIONS,
}, required=("attributes",))
_TEXTURE_INFO = obj({"index": index("textures"), "extensions": obj({
    "KHR_texture_transform": obj({"offset": numbers(2), "scale": numbers(2), "rotation": number})})},
    required=("index",))
_VRM1_EXPRESSION = obj({"morphTargetBinds": array(obj({"node": index("nodes"), "index": _UINT, "weight": number}))})
_VRM = obj({
    "VRMC_vrm": obj({
        "humanoid": obj({"humanBones": mapping(obj({"node": index("nodes")}, required=("node",)))}),
        "expressions": obj({"preset": mapping(_VRM1_EXPRESSION), "custom": mapping(_VRM1_EXPRESSION)}),
    }),
    "VRM": obj({
        "humanoid": obj({"humanBones": array(obj({"node": index("nodes"), "bone": string}))}),
        "blendShapeMaster": obj({"blendShapeGroups": array(obj({
            "name": string,
            "binds": array(obj({"mesh": index("meshes"), "index": _UINT, "weight": number}))}))}),
    }),
})

_DOCUMENT = obj({
    "asset": obj(),
    "extensionsUsed": array(string),
    "extensionsRequired": array(string),
    "extensions": _VRM,
    "buffers": array(obj({"byteLength": _UINT, "uri": string, "extensions": _EXTENSIONS})),
    "bufferViews": array(obj({"buffer": index("buffers"), "byteOffset": _UINT, "byteLength": _UINT,
                              "byteStride": integer(4, 252),
                              "extensions": obj({"EXT_meshopt_compression": _MESHOPT,
                                                 "KHR_meshopt_compression": _MESHOPT})},
                             required=("buffer", "byteLength"))),
    "accessors": array(obj({"bufferView": index("bufferViews"), "byteOffset": _UINT,
                            "componentType": one_of(*COMPONENT_TYPES), "count": integer(1),
                            "type": one_of(*ELEMENT_TYPES), "normalized": boolean, "sparse": _SPARSE},
                           required=("componentType", "count", "type"))),
    "nodes": array(obj({"children": array(index("nodes")), "mesh": index("meshes"), "skin": index("skins"),
                        "matrix": numbers(16), "translation": numbers(3), "rotation": numbers(4),
                        "scale": numbers(3), "name": string})),
    "meshes": array(obj({"primitives": array(_PRIMITIVE), "extras": _NAMES}, required=("primitives",))),
    "skins": array(obj({"joints": array(index("nodes")), "inverseBindMatrices": index("accessors"),
                        "skeleton": index("nodes")}, required=("joints",))),
    "images": array(obj({"bufferView": index("bufferViews"), "uri": string, "mimeType": string})),
    "textures": array(obj({"source": index("images")})),
    "materials": array(obj({"pbrMetallicRoughness": obj({"baseColorFactor": numbers(4),
                                                         "baseColorTexture": _TEXTURE_INFO}),
                            "doubleSided": boolean})),
    "scenes": array(obj({"nodes": array(index("nodes"))})),
})


def check_document(doc: object, path: str | Path) -> None:
    """Raise :class:`InputError` for the first field the loader reads that has a wrong type, index or value."""
    if not isinstance(doc, dict):
        raise InputError(path, None, f"the glTF JSON must be an object, not {_kind(doc)}" + DAMAGED)
    nodes = doc.get("nodes")
    if isinstance(nodes, list) and len(nodes) > MAX_NODES:
        raise InputError(path, "key nodes", f"{len(nodes)} nodes; at most {MAX_NODES} are read" + DAMAGED)
    _DOCUMENT(doc, "", _Context(doc, path))


# ---------------------------------------------------------------------------------------------
# Node hierarchy
# ---------------------------------------------------------------------------------------------

def node_parents(nodes: list[dict], path: str | Path) -> np.ndarray:
    """Parent index of every node (-1 for roots), after refusing nodes with two parents, cycles and
    hierarchies deeper than :data:`MAX_NODE_DEPTH` (``nodes`` already passed :func:`check_document`)."""
    n = len(nodes)
    parent = np.full(n, -1)
    for i, node in enumerate(nodes):
        for c in node.get("children", []):
            if parent[c] >= 0 or c == i:
                what = (f"node {c} is its own child" if c == i else
                        f"node {c} is listed twice" if parent[c] == i else
                        f"node {c} is a child of both node {parent[c]} and node {i}")
                raise InputError(path, f"key nodes[{i}].children", what + DAMAGED)
            parent[c] = i
    depth = np.full(n, -1)  # -1: not reached yet, -2: on the current walk up
    for i in range(n):
        chain = []
        j = i
        while j >= 0 and depth[j] == -1:
            depth[j] = -2
            chain.append(j)
            j = int(parent[j])
        if j >= 0 and depth[j] == -2:
            raise InputError(path, f"key nodes[{parent[j]}].children",
                             f"node {j} is its own ancestor (the node hierarchy has a cycle)" + DAMAGED)
        base = depth[j] if j >= 0 else -1
        for k in reversed(chain):
            base += 1
            depth[k] = base
            if base > MAX_NODE_DEPTH:
                raise InputError(path, f"key nodes[{k}]", f"node {k} is {base} levels below its root; "
                                 f"at most {MAX_NODE_DEPTH} are read" + DAMAGED)
    return parent


# ---------------------------------------------------------------------------------------------
# External files
# ---------------------------------------------------------------------------------------------

_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


def confined_file(gltf_path: Path, uri: str, where: str) -> Path:
    """The file an external ``uri`` names, which must be a regular file inside the glTF's own folder.

    >>> confined_file(Path("/tmp/a/avatar.gltf"), "../secret.bin", "key buffers[0].uri")
    Traceback (most recent call last):
        ...
    studyapp.errors.InputError: /tmp/a/avatar.gltf, key buffers[0].uri: '../secret.bin' leads outside the glTF's folder; only files in /tmp/a (or its subfolders) and data: URIs are read
    """
    folder = gltf_path.parent
    rel = unquote(uri)
    outside = (f"{uri!r:.80} leads outside the glTF's folder; only files in {folder} (or its subfolders) "
               "and data: URIs are read")
    if "\0" in rel:
        raise InputError(gltf_path, where, f"{uri!r:.80} contains a NUL byte" + DAMAGED)
    if _SCHEME.match(rel) or rel.startswith(("/", "\\")) or Path(rel).is_absolute():
        raise InputError(gltf_path, where, outside)
    file = folder / rel
    try:
        inside = file.resolve().is_relative_to(folder.resolve())
    except (OSError, RuntimeError, ValueError):  # a symbolic link loop, a name the system refuses
        inside = False
    if not inside:
        raise InputError(gltf_path, where, outside)
    if not file.is_file():
        raise InputError(gltf_path, where, f"file {uri!r:.80} not found next to the glTF ({file})")
    size = file.stat().st_size
    if size > MAX_FILE_BYTES:
        raise InputError(gltf_path, where, f"file {uri!r:.80} has {size} bytes; at most {MAX_FILE_BYTES} are read")
    return file
