"""Seeded mutations of real glTF/GLB/VRM files, and a forked, capped run of the avatar reader on each.

A uniquely named helper module (not conftest.py), used by ``test_gltf_fuzz.py``. Each case is one
mutation of one real avatar: byte-level damage (bit flips, truncation, GLB chunk lengths) or an edit of
one JSON field (negative or huge counts and offsets, wrong types, missing keys, NaN, node cycles, deep
chains, URIs outside the folder, zeroed inverse bind matrices). :func:`run_case` reads the file with
the real reader (``load_gltf`` and ``inspect``'s ``summarize_avatar``) in a forked child under an address-space
cap and a time limit, and classifies the outcome.
"""
from __future__ import annotations

import json
import os
import pickle
import random
import resource
import select
import signal
import struct
import time
from collections.abc import Callable
from pathlib import Path

OK, INPUT_ERROR, TRACEBACK, HANG, MEMORY = "loaded", "InputError", "traceback", "hang", "memory blow-up"
MEMORY_CAP = 1536 * 2**20  # address space the reader may add to what the forked child already maps
TIME_CAP = 20.0            # seconds per case (a real avatar loads in well under one)


# ---------------------------------------------------------------------------------------------
# GLB container
# ---------------------------------------------------------------------------------------------

def split_glb(raw: bytes) -> tuple[dict, bytes]:
    """The JSON document and the BIN chunk of a well-formed GLB."""
    jlen = struct.unpack_from("<I", raw, 12)[0]
    doc = json.loads(raw[20:20 + jlen])
    binary = b""
    pos = 20 + jlen
    if pos + 8 <= len(raw):
        blen = struct.unpack_from("<I", raw, pos)[0]
        binary = raw[pos + 8: pos + 8 + blen]
    return doc, binary


def pack_glb(doc: dict, binary: bytes) -> bytes:
    js = dump_json(doc)
    js += b" " * (-len(js) % 4)
    binary = binary + b"\0" * (-len(binary) % 4)
    out = struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(js) + (8 + len(binary) if binary else 0))
    out += struct.pack("<II", len(js), 0x4E4F534A) + js
    if binary:
        out += struct.pack("<II", len(binary), 0x004E4942) + binary
    return out


# ---------------------------------------------------------------------------------------------
# Mutations
# ---------------------------------------------------------------------------------------------

_BAD_VALUES: tuple = (-1, 0, 1, 3, 7, 2**31, 2**32 + 5, 2**62, 10**30, -(2**40), 1.5, 1e308, float("nan"),
                      float("inf"), "abc", "", None, True, [], {}, [1, 2], {"a": 1})


def _paths(node, prefix=()) -> list[tuple]:
    """Every (container, key) path in a JSON value, as tuples of keys."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append(prefix + (k,))
            out += _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node[:40]):  # long arrays (joints, targetNames) are sampled at their start
            out.append(prefix + (i,))
            out += _paths(v, prefix + (i,))
    return out


def _get(doc, path):
    for k in path:
        doc = doc[k]
    return doc


def _field_edit(doc: dict, rng: random.Random) -> str:
    paths = [p for p in _paths(doc) if p[0] in (
        "accessors", "bufferViews", "buffers", "nodes", "skins", "meshes", "scenes", "images", "textures",
        "materials", "extensions", "extensionsUsed", "extensionsRequired", "asset")] or _paths(doc)
    path = rng.choice(paths)
    parent = _get(doc, path[:-1])
    action = rng.random()
    if action < 0.15 and isinstance(parent, dict):
        del parent[path[-1]]
        return f"delete {path}"
    if action < 0.25 and isinstance(_get(doc, path), (int, float)) and not isinstance(_get(doc, path), bool):
        parent[path[-1]] = _get(doc, path) + rng.choice((-1, 1, 4, -4, 1000, 2**20))
        return f"nudge {path}"
    value = rng.choice(_BAD_VALUES)
    parent[path[-1]] = value
    return f"set {path} = {value!r}"


def _node_cycle(doc: dict, rng: random.Random) -> str:
    nodes = doc.get("nodes", [])
    parents = [i for i, n in enumerate(nodes) if n.get("children")]
    if not parents:
        return _field_edit(doc, rng)
    p = rng.choice(parents)
    kind = rng.random()
    if kind < 0.4:  # the node becomes its own child, or a child of its descendant
        child = p
        for _ in range(rng.randrange(4)):
            kids = nodes[child].get("children") or [child]
            child = rng.choice(kids)
        nodes[child].setdefault("children", []).append(p)
        return f"cycle: nodes[{child}] -> nodes[{p}]"
    if kind < 0.7:  # a node with two parents
        other = rng.randrange(len(nodes))
        nodes[other].setdefault("children", []).append(rng.choice(nodes[p]["children"]))
        return f"two parents via nodes[{other}]"
    # a chain 2,000 nodes deep hung under a joint
    start = len(nodes)
    for k in range(2000):
        nodes.append({"name": f"deep{k}", "children": [start + k + 1] if k < 1999 else []})
    nodes[p]["children"].append(start)
    return "2000-deep node chain"


def _uri_escape(doc: dict, rng: random.Random) -> str:
    target = rng.choice(("../../../../etc/hostname", "/etc/hostname", "file:///etc/hostname",
                         "http://example.invalid/x.bin", "%2e%2e/%2e%2e/etc/hostname", "data:;base64,@@@@",
                         "data:application/octet-stream;base64," + "A" * 7))
    if doc.get("images") and rng.random() < 0.4:
        img = rng.choice(doc["images"])
        img.pop("bufferView", None)
        img["uri"] = target
        return f"image uri {target}"
    if not doc.get("buffers"):
        return _field_edit(doc, rng)
    rng.choice(doc["buffers"])["uri"] = target
    return f"buffer uri {target}"


def _zero_matrix(doc: dict, binary: bytearray, rng: random.Random) -> str:
    """Zero an inverse bind matrix (singular) or write NaN into positions."""
    accs = doc.get("accessors", [])
    skins = [s for s in doc.get("skins", []) if "inverseBindMatrices" in s]
    if skins and rng.random() < 0.6:
        a = accs[skins[0]["inverseBindMatrices"]]
        fill = b"\0" * 4
        what = "zero inverse bind matrix"
    else:
        pos = [m["attributes"]["POSITION"] for mesh in doc.get("meshes", []) for m in mesh.get("primitives", [])
               if "POSITION" in m.get("attributes", {})]
        if not pos:
            return _field_edit(doc, rng)
        a = accs[rng.choice(pos)]
        fill = struct.pack("<f", rng.choice((float("nan"), float("inf"))))
        what = "NaN/Inf position"
    view = doc.get("bufferViews", [])[a.get("bufferView", 0)] if "bufferView" in a else None
    if view is None or "extensions" in view:
        return _field_edit(doc, rng)
    start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    k = rng.randrange(max(1, min(a["count"], 64)))
    width = 64 if what.startswith("zero") else 12
    for b in range(start + k * width, min(start + (k + 1) * width, len(binary)), 4):
        binary[b: b + 4] = fill
    return f"{what} (element {k})"


def _deep_json(doc: dict, rng: random.Random) -> str:
    depth = rng.choice((200, 5000, 100_000))
    doc["extras"] = json.loads("[" * depth + "]" * depth) if depth < 900 else "@DEEP@"
    doc["extras_depth"] = depth
    return f"JSON nested {depth} deep"


def mutate(raw: bytes, rng: random.Random) -> tuple[bytes, str]:
    """One seeded mutation of a GLB file: (new bytes, what was done)."""
    kind = rng.random()
    if kind < 0.12:  # bit flips anywhere
        out = bytearray(raw)
        n = rng.choice((1, 1, 2, 8))
        for _ in range(n):
            out[rng.randrange(len(out))] ^= 1 << rng.randrange(8)
        return bytes(out), f"{n} bit flip(s)"
    if kind < 0.2:  # truncation
        cut = rng.randrange(len(raw))
        return raw[:cut], f"truncated at {cut}"
    if kind < 0.26:  # a chunk or header length field lies
        out = bytearray(raw)
        at = rng.choice((8, 12, 20 + struct.unpack_from("<I", raw, 12)[0]))
        out[at: at + 4] = struct.pack("<I", rng.choice((0, 1, 3, 2**31, 2**32 - 1, len(raw), len(raw) * 4)))
        return bytes(out), f"length field at byte {at} edited"
    doc, binary = split_glb(raw)
    binary = bytearray(binary)
    what = mutate_doc(doc, binary, rng)
    return pack_glb(doc, bytes(binary)), what


def mutate_doc(doc: dict, binary: bytearray, rng: random.Random) -> str:
    """One seeded edit of a glTF document (and its binary buffer, in place); returns what was done."""
    kind = rng.random()
    if kind < 0.6:
        what = _field_edit(doc, rng)
        if rng.random() < 0.3:
            what += "; " + _field_edit(doc, rng)
        return what
    if kind < 0.72:
        return _node_cycle(doc, rng)
    if kind < 0.82:
        return _uri_escape(doc, rng)
    if kind < 0.93:
        return _zero_matrix(doc, binary, rng)
    return _deep_json(doc, rng)


def dump_json(doc: dict) -> bytes:
    """The document as JSON text; a ``"@DEEP@"`` placeholder becomes brackets nested too deep for ``json``."""
    js = json.dumps(doc, separators=(",", ":")).encode("utf-8")  # NaN/Infinity as Python writes them
    if b'"@DEEP@"' in js:
        depth = int(doc["extras_depth"])
        js = js.replace(b'"@DEEP@"', b"[" * depth + b"]" * depth)
    return js


# ---------------------------------------------------------------------------------------------
# Forked, capped run
# ---------------------------------------------------------------------------------------------

def _vsize() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[0]) * resource.getpagesize()


def run_case(path: Path, reader: Callable[[Path], object], time_cap: float = TIME_CAP) -> tuple[str, str]:
    """Run ``reader(path)`` in a forked child with an address-space cap and a time limit.

    Returns ``(outcome, detail)``: ``OK``, ``INPUT_ERROR`` (detail: the message), ``TRACEBACK`` (the
    exception's type and message), ``HANG`` or ``MEMORY``.
    """
    rfd, wfd = os.pipe()
    pid = os.fork()
    if pid == 0:  # child: never returns into pytest
        os.close(rfd)
        code = 0
        try:
            cap = _vsize() + MEMORY_CAP
            resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
            from studyapp.errors import InputError

            try:
                reader(path)
                result = (OK, "")
            except InputError as exc:
                result = (INPUT_ERROR, str(exc))
            except MemoryError as exc:
                result = (MEMORY, f"MemoryError {exc}")
            except BaseException as exc:  # noqa: BLE001 - exactly what the fuzz test counts
                import traceback

                tb = traceback.extract_tb(exc.__traceback__)
                at = f"{Path(tb[-1].filename).name}:{tb[-1].lineno}" if tb else "?"
                result = (TRACEBACK, f"{type(exc).__name__} at {at}: {str(exc)[:200]}")
            os.write(wfd, pickle.dumps(result))
        except BaseException:  # noqa: BLE001
            code = 3
        finally:
            os._exit(code)
    os.close(wfd)
    deadline = time.monotonic() + time_cap
    chunks = []
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            os.close(rfd)
            return HANG, f"no answer in {time_cap:.0f} s"
        ready, _, _ = select.select([rfd], [], [], left)
        if ready:
            data = os.read(rfd, 1 << 16)
            if not data:
                break
            chunks.append(data)
    os.close(rfd)
    _, status = os.waitpid(pid, 0)
    if not chunks:
        sig = os.WTERMSIG(status) if os.WIFSIGNALED(status) else None
        return MEMORY, f"child died (signal {sig}, status {status})"
    return pickle.loads(b"".join(chunks))
