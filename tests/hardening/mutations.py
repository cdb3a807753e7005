"""Seeded mutations of input files, for the fuzz harness (:mod:`tests.hardening.fuzz`).

Every mutator is a pure function ``(rng, data) -> data`` of a :class:`random.Random` and the file's bytes,
so the same seed always gives the same mutated file. :func:`mutators_for` lists the ones that make sense
for a reader: byte-level damage for every format (bit flips, inserted / deleted bytes, truncation,
duplicated chunks, magic integers written over headers), text damage for the text formats (duplicated
or deleted lines, a very long line, NUL, numbers replaced by huge values, ``Infinity`` and ``NaN``) and
the attacks each format invites (a 1,000-deep BVH joint chain, a CSV with 100k columns, JSON nested 100k
deep, a format specification in a design's path pattern, a WAV or NPY header claiming more data than the
file holds, an NPZ member that expands past the memory cap, glTF accessors counting 10^12 elements,
wrong types in an NPZ or a results database).

Nothing here imports studyapp: the harness only feeds files to the command line.
"""
from __future__ import annotations

import base64
import io
import json
import random
import re
import sqlite3
import struct
import tempfile
import warnings
import zipfile
import zlib
from collections.abc import Callable
from pathlib import Path

Mutator = Callable[[random.Random, bytes], bytes]

#: The largest file a mutation may produce (the 10 MB one-line BVH of issue 16 fits under it).
MAX_SIZE = 12 * 1024 * 1024

#: Values written in place of a number in a text file.
TEXT_NUMBERS = ("1e308", "-1e308", "1e400", "99999999999999999999999", "-1", "0", "-0", "1e-320", "Infinity",
                "-Infinity", "inf", "NaN", "nan", "abc", "", "0x7fffffff", "1_000", "4294967296", "2.5")
#: Integers written over binary headers (32-bit and 64-bit, both signs, the 10^12 of issue 16).
MAGIC_INTS = (0, 1, 0x7FFFFFFF, 0x80000000, 0xFFFFFFFF, 10**12, 2**63 - 1, 2**64 - 1)
#: Values put in place of a JSON / database value.
WRONG_VALUES = (1e308, -1, 2**64, float("nan"), float("inf"), "abc", None, [], {}, True, "", 0, [[[]]])

_NUMBER = re.compile(rb"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")
_DEEP = "\u0001DEEP\u0001"


def _pos(rng: random.Random, data: bytes) -> int:
    return rng.randrange(len(data) + 1)


def _cap(data: bytes) -> bytes:
    return data[:MAX_SIZE]


# --- bytes -----------------------------------------------------------------------------------------


def bit_flip(rng: random.Random, data: bytes) -> bytes:
    if not data:
        return b"\x01"
    b = bytearray(data)
    for _ in range(rng.choice((1, 1, 2, 4, 8))):
        i = rng.randrange(len(b))
        b[i] ^= 1 << rng.randrange(8)
    return bytes(b)


def byte_insert(rng: random.Random, data: bytes) -> bytes:
    i = _pos(rng, data)
    return data[:i] + bytes(rng.randrange(256) for _ in range(rng.randint(1, 16))) + data[i:]


def byte_delete(rng: random.Random, data: bytes) -> bytes:
    i = _pos(rng, data)
    return data[:i] + data[i + rng.randint(1, 64):]


def truncate(rng: random.Random, data: bytes) -> bytes:
    return data[:_pos(rng, data)]


def dup_chunk(rng: random.Random, data: bytes) -> bytes:
    if not data:
        return data
    i = rng.randrange(len(data))
    chunk = data[i:i + rng.randint(1, 4096)]
    j = _pos(rng, data)
    reps = min(rng.choice((1, 2, 10, 100)), max(1, (MAX_SIZE - len(data)) // len(chunk)))
    return _cap(data[:j] + chunk * reps + data[j:])


def magic_int(rng: random.Random, data: bytes) -> bytes:
    """A 32- or 64-bit magic integer written over the file, most often in its first 64 bytes (headers)."""
    if len(data) < 8:
        return data + struct.pack("<I", 0xFFFFFFFF)
    limit = min(len(data) - 8, 64) if rng.random() < 0.7 else len(data) - 8
    i = rng.randrange(0, limit + 1)
    v = rng.choice(MAGIC_INTS)
    raw = struct.pack("<Q", v) if rng.random() < 0.3 else struct.pack("<I", v & 0xFFFFFFFF)
    return data[:i] + raw + data[i + len(raw):]


BYTE_MUTATORS: tuple[Mutator, ...] = (bit_flip, byte_insert, byte_delete, truncate, dup_chunk, magic_int)


# --- text ------------------------------------------------------------------------------------------


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True) or [b""]


def dup_lines(rng: random.Random, data: bytes) -> bytes:
    lines = _lines(data)
    i = rng.randrange(len(lines))
    block = b"".join(lines[i:i + rng.randint(1, 5)])
    # a few copies only of a long block (after long_line, say): the file stays under MAX_SIZE
    reps = min(rng.choice((1, 2, 100, 10_000)), max(1, (MAX_SIZE - len(data)) // max(1, len(block))))
    return _cap(b"".join(lines[:i]) + block * reps + b"".join(lines[i:]))


def delete_lines(rng: random.Random, data: bytes) -> bytes:
    lines = _lines(data)
    i = rng.randrange(len(lines))
    return b"".join(lines[:i] + lines[i + rng.randint(1, 5):])


def long_line(rng: random.Random, data: bytes) -> bytes:
    n = rng.choice((10_000, 1_000_000, 10_000_000))
    filler = rng.choice((b"1.0 ", b"x", b",", b"0,", b"[", b" "))
    lines = _lines(data)
    i = rng.randrange(len(lines))
    return _cap(b"".join(lines[:i]) + (filler * (n // len(filler))) + b"\n" + b"".join(lines[i:]))


def nul(rng: random.Random, data: bytes) -> bytes:
    i = _pos(rng, data)
    return data[:i] + b"\x00" * rng.choice((1, 1, 100)) + data[i:]


def number(rng: random.Random, data: bytes) -> bytes:
    """One (or every) number in the text replaced by a huge, infinite, NaN, negative or non-numeric value."""
    hits = list(_NUMBER.finditer(data))
    if not hits:
        return nul(rng, data)
    new = rng.choice(TEXT_NUMBERS).encode()
    if rng.random() < 0.1:
        return _NUMBER.sub(new, data)
    m = rng.choice(hits)
    return data[:m.start()] + new + data[m.end():]


def one_line(rng: random.Random, data: bytes) -> bytes:
    """The file grown to up to ~10 MB by repeating its second half, then every newline removed."""
    target = rng.choice((len(data), 1_000_000, 10_000_000))
    half = data[len(data) // 2:] or b"0 "
    grown = data + half * max(0, (target - len(data)) // len(half))
    return _cap(grown.replace(b"\r", b"").replace(b"\n", b" "))


TEXT_MUTATORS: tuple[Mutator, ...] = (dup_lines, delete_lines, long_line, nul, number, number, one_line)


# --- BVH -------------------------------------------------------------------------------------------


def bvh_deep_chain(rng: random.Random, data: bytes) -> bytes:
    """A chain of 100 to 5,000 nested joints inserted under the root (issue 16: 1,000 deep crashed)."""
    depth = rng.choice((100, 1000, 5000))
    m = re.search(rb"CHANNELS[^\n]*\n", data)
    if not m:
        return data
    chain = b"".join(b"JOINT d%d\n{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n" % k for k in range(depth))
    chain += b"End Site\n{\nOFFSET 0 1 0\n}\n" + b"}\n" * depth
    return data[:m.end()] + chain + data[m.end():]


def bvh_channels(rng: random.Random, data: bytes) -> bytes:
    hits = list(re.finditer(rb"CHANNELS\s+(\S+)", data))
    if not hits:
        return data
    m = rng.choice(hits)
    new = rng.choice((b"Infinity", b"NaN", b"1e9", b"-3", b"3.5", b"99999999999999999999", b"0", b"7"))
    return data[:m.start(1)] + new + data[m.end(1):]


def bvh_header(rng: random.Random, data: bytes) -> bytes:
    """``Frames:`` or ``Frame Time:`` replaced (10^12 frames against a file of a few kB)."""
    key = rng.choice((rb"Frames:\s*(\S+)", rb"Frame Time:\s*(\S+)"))
    m = re.search(key, data)
    if not m:
        return data
    new = rng.choice((b"1000000000000", b"9223372036854775807", b"-5", b"0", b"1e400", b"nan", b"1e-300", b"3.7"))
    return data[:m.start(1)] + new + data[m.end(1):]


# --- CSV / JSON ------------------------------------------------------------------------------------


def csv_wide(rng: random.Random, data: bytes) -> bytes:
    """The header (and maybe each row) widened by 1,000 to 100,000 columns (1.2 MB with 100k hung)."""
    n = rng.choice((1000, 100_000))
    lines = _lines(data)
    head = lines[0][:MAX_SIZE // 4].rstrip(b"\r\n") + b"".join(b",c%d" % k for k in range(n)) + b"\n"
    rows = lines[1:]
    if rng.random() < 0.5 and rows:
        rows = [r[:MAX_SIZE // 40].rstrip(b"\r\n") + b",0" * n + b"\n" for r in rows[:20]]
    return _cap(head + b"".join(rows))


def _json_paths(node, path=()):
    yield path
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _json_paths(v, (*path, k))
    elif isinstance(node, list):
        for k, v in enumerate(node):
            yield from _json_paths(v, (*path, k))


def _json_set(doc, path, value):
    if not path:
        return value
    parent = doc
    for k in path[:-1]:
        parent = parent[k]
    parent[path[-1]] = value
    return doc


#: glTF keys whose values are sizes, offsets or references: mutated more often than others.
GLTF_KEYS = frozenset({"count", "byteLength", "byteOffset", "byteStride", "children", "joints", "inverseBindMatrices",
                       "bufferView", "componentType", "type", "buffer", "mesh", "skin", "indices", "POSITION",
                       "JOINTS_0", "WEIGHTS_0", "skeleton", "node", "nodes", "scene", "min", "max", "uri"})


def json_edit(rng: random.Random, data: bytes, prefer: frozenset[str] = frozenset()) -> bytes:
    """A value of the JSON document replaced by a wrong type, a huge or non-finite number, a 100k-long list,
    a 1,000- or 100,000-deep nesting, or deleted; or a reference made a cycle (glTF node children)."""
    try:
        doc = json.loads(data)
    except (ValueError, RecursionError):
        return number(rng, data)
    paths = [p for p in _json_paths(doc) if p]
    if not paths:
        return number(rng, data)
    preferred = [p for p in paths if any(isinstance(k, str) and k in prefer for k in p[-2:])]
    path = rng.choice(preferred if preferred and rng.random() < 0.7 else paths)
    roll = rng.random()
    if roll < 0.1 and isinstance(path[-1], str):
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        del parent[path[-1]]
    elif roll < 0.2:
        doc = _json_set(doc, path, _DEEP)
    elif roll < 0.25:
        doc = _json_set(doc, path, [0] * 100_000)
    elif roll < 0.3 and "nodes" in doc if isinstance(doc, dict) else False:
        nodes = doc["nodes"]
        if isinstance(nodes, list) and nodes and isinstance(nodes[0], dict):
            nodes[0]["children"] = [0]  # a node that is its own child
    elif roll < 0.55 and prefer:
        doc = _json_set(doc, path, rng.choice((10**12, 2**31, 2**32 + 4, -1, 0, 3.5, 1e308)))
    else:
        doc = _json_set(doc, path, rng.choice(WRONG_VALUES))
    text = json.dumps(doc, allow_nan=True)
    depth = rng.choice((1000, 100_000))
    return _cap(text.replace(json.dumps(_DEEP), "[" * depth + "]" * depth).encode())


def json_deep(rng: random.Random, data: bytes) -> bytes:
    """The document nested 1,000 or 100,000 deep (issue 16: 100k crashed the face reader)."""
    depth = rng.choice((1000, 100_000))
    return _cap(b"[" * depth + data + b"]" * depth) if rng.random() < 0.5 else \
        _cap(b'{"a":' * depth + data + b"}" * depth)


# --- TOML designs ----------------------------------------------------------------------------------


def toml_pattern(rng: random.Random, data: bytes) -> bytes:
    """A format specification, conversion or attribute inside a motion/audio/face path pattern."""
    spec = rng.choice((b"{stimulus:>99999999}", b"{stimulus:>9999}", b"{stimulus!r}", b"{stimulus.__class__}",
                       b"{stimulus[0]}", b"{0}", b"{}", b"{stimulus:%Y}", b"{condition:x<100000000}",
                       b"{stimulus", b"stimulus}", b"{{stimulus}}"))
    if b"{stimulus}" in data:
        hits = [m.start() for m in re.finditer(rb"\{stimulus\}", data)]
        i = rng.choice(hits)
        return data[:i] + spec + data[i + len(b"{stimulus}"):]
    m = re.search(rb'(motion|audio|face)\s*=\s*"', data)
    return data if not m else data[:m.end()] + spec + data[m.end():]


def toml_deep(rng: random.Random, data: bytes) -> bytes:
    depth = rng.choice((100, 1000, 100_000))
    value = (b"[" * depth + b"]" * depth) if rng.random() < 0.6 else (b"{a=" * depth + b"1" + b"}" * depth)
    key = rng.choice((b"deep", b"practice", b"title"))
    return _cap(key + b" = " + value + b"\n" + data)


def toml_nul_path(rng: random.Random, data: bytes) -> bytes:
    """A NUL (escaped ``\\u0000`` or a raw byte) inside a quoted path."""
    hits = list(re.finditer(rb'(?:motion|audio|face|avatar)\s*=\s*"([^"]*)"', data))
    if not hits:
        return nul(rng, data)
    m = rng.choice(hits)
    i = rng.randint(m.start(1), m.end(1))
    return data[:i] + rng.choice((b"\\u0000", b"\x00", b"\\u0000/../../etc/passwd")) + data[i:]


def toml_value(rng: random.Random, data: bytes) -> bytes:
    """The value of one ``key = value`` line replaced by a wrong type or an absurd number."""
    hits = list(re.finditer(rb"(?m)^(\s*[A-Za-z_][\w.-]*\s*=\s*)(.*)$", data))
    if not hits:
        return number(rng, data)
    m = rng.choice(hits)
    new = rng.choice((b'"abc"', b"1e308", b"-1", b"inf", b"nan", b"[]", b"{}", b'[1, "a"]', b"true", b"99999999999",
                      b"1979-05-27T07:32:00Z", b'""', b'"' + b"x" * 100_000 + b'"'))
    return data[:m.start(2)] + new + data[m.end(2):]


# --- WAV -------------------------------------------------------------------------------------------


def wav_header(rng: random.Random, data: bytes) -> bytes:
    """One RIFF / fmt / data field (sizes, channels, rate, bit depth, block align) set to a magic value."""
    if len(data) < 44:
        return magic_int(rng, data)
    fields = {4: 4, 16: 4, 20: 2, 22: 2, 24: 4, 28: 4, 32: 2, 34: 2}
    data_at = data.find(b"data")
    if data_at >= 0:
        fields[data_at + 4] = 4
    off, width = rng.choice(sorted(fields.items()))
    v = rng.choice(MAGIC_INTS) & (0xFFFFFFFF if width == 4 else 0xFFFF)
    return data[:off] + v.to_bytes(width, "little") + data[off + width:]


# --- NPY / NPZ -------------------------------------------------------------------------------------


def npy_header(rng: random.Random, data: bytes) -> bytes:
    """The NPY header's shape, dtype or order rewritten (10^12 frames against a file of a few kB)."""
    m = re.search(rb"\{.*?\}", data[:4096], re.S)
    if not data.startswith(b"\x93NUMPY") or not m:
        return magic_int(rng, data)
    head = m.group(0)
    roll = rng.random()
    if roll < 0.5:
        head = re.sub(rb"'shape': \([^)]*\)", rng.choice((b"'shape': (1000000000000, 52)", b"'shape': (-1, 52)",
                      b"'shape': (2305843009213693952,)", b"'shape': ()", b"'shape': (0, 52)",
                      b"'shape': (3, 3, 3, 3, 3, 3, 3, 3)", b"'shape': (1e3, 52)")), head)
    elif roll < 0.85:
        head = re.sub(rb"'descr': '[^']*'", rng.choice((b"'descr': '|O'", b"'descr': '<U10'", b"'descr': '>c16'",
                      b"'descr': '|b1'", b"'descr': '<i8'", b"'descr': '|V16'", b"'descr': '<f2'", b"'descr': 'xx'")), head)
    else:
        head = head.replace(b"False", b"True") if rng.random() < 0.5 else head.replace(b"'fortran_order'", b"'x'")
    return data[:m.start()] + head + data[m.end():]


def _npz_members(data: bytes) -> list[tuple[str, bytes]] | None:
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as z:
            if sum(i.file_size for i in z.infolist()) > MAX_SIZE * 4:
                return None  # a bomb from an earlier mutation: never expanded here
            return [(i.filename, z.read(i)) for i in z.infolist()]
    except Exception:  # noqa: BLE001 - a seed already damaged by an earlier mutation
        return None


def _npy_bytes(array_header: bytes, body: bytes) -> bytes:
    pad = 64 - (10 + len(array_header) + 1) % 64
    head = array_header + b" " * pad + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(head)) + head + body


def _wrong_npy(rng: random.Random) -> bytes:
    kind = rng.choice(("str", "object", "scalar", "int", "4d", "empty", "bool", "complex"))
    header = {
        "str": b"{'descr': '<U3', 'fortran_order': False, 'shape': (2,), }",
        "object": b"{'descr': '|O', 'fortran_order': False, 'shape': (1,), }",
        "scalar": b"{'descr': '<f8', 'fortran_order': False, 'shape': (), }",
        "int": b"{'descr': '<i8', 'fortran_order': False, 'shape': (2, 3), }",
        "4d": b"{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 1, 2), }",
        "empty": b"{'descr': '<f4', 'fortran_order': False, 'shape': (0, 165), }",
        "bool": b"{'descr': '|b1', 'fortran_order': False, 'shape': (3,), }",
        "complex": b"{'descr': '<c16', 'fortran_order': False, 'shape': (1, 3), }",
    }[kind]
    body = {
        "str": "abcdef".encode("utf-32-le"),
        "object": b"\x80\x04N.",  # a pickle: a reader must refuse it (allow_pickle=False), never load it
        "scalar": struct.pack("<d", 1e308),
        "int": struct.pack("<6q", *(2**62, -1, 0, 5, 7, 9)),
        "4d": struct.pack("<4f", 1, 2, 3, float("nan")),
        "empty": b"",
        "bool": b"\x01\x00\x01",
        "complex": struct.pack("<6d", 1, 2, 3, 4, 5, 6),
    }[kind]
    return _npy_bytes(header, body)


_BOMB_CACHE: dict[tuple[bytes, int], tuple[bytes, int]] = {}


def _bomb(npy_header: bytes, n_zeros: int) -> tuple[bytes, int]:
    """A raw deflate stream of an NPY header followed by ``n_zeros`` zero bytes, and its CRC-32.

    Computed once per process (it takes a few seconds): a stored block with the header, then the zeros
    compressed about 1000:1, so a 1.6 MB member expands to 1.6 GB.
    """
    key = (npy_header, n_zeros)
    if key not in _BOMB_CACHE:
        body = _npy_bytes(npy_header, b"")
        c = zlib.compressobj(9, zlib.DEFLATED, -15)
        block = bytes(1 << 20)
        parts = [struct.pack("<BHH", 0, len(body), len(body) ^ 0xFFFF), body]
        crc = zlib.crc32(body)
        for _ in range(n_zeros >> 20):
            parts.append(c.compress(block))
            crc = zlib.crc32(block, crc)
        tail = bytes(n_zeros & ((1 << 20) - 1))
        parts += [c.compress(tail), c.flush()]
        crc = zlib.crc32(tail, crc)
        _BOMB_CACHE[key] = (b"".join(parts), crc)
    return _BOMB_CACHE[key]


def _zip_with_bomb(members: list[tuple[str, bytes]], name: str, npy_header: bytes, n_zeros: int) -> bytes:
    """The NPZ with member ``name`` replaced by an NPY of ``n_zeros`` zeros, deflated (a zip bomb)."""
    payload, crc = _bomb(npy_header, n_zeros)
    size = len(_npy_bytes(npy_header, b"")) + n_zeros
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for n, raw in members:
            if n != name:
                z.writestr(n, raw)
        # written by hand: zipfile would compress 1.6 GB again for every case
        info = zipfile.ZipInfo(name, date_time=(2020, 1, 1, 0, 0, 0))
        info.compress_type = zipfile.ZIP_DEFLATED
        info.CRC, info.compress_size, info.file_size = crc, len(payload), size
        info.header_offset = z.fp.tell()
        z.fp.write(info.FileHeader(zip64=False))
        z.fp.write(payload)
        z.start_dir = z.fp.tell()
        z.filelist.append(info)
        z.NameToInfo[name] = info
    return buf.getvalue()


def npz_member(rng: random.Random, data: bytes) -> bytes:
    """One NPZ member replaced by a wrong type, given a damaged NPY header, renamed, or made a zip bomb."""
    members = _npz_members(data)
    if not members:
        return bit_flip(rng, data)
    i = rng.randrange(len(members))
    name, raw = members[i]
    roll = rng.random()
    if roll < 0.1:
        rows = 1_250_000 if rng.random() < 0.5 else 1_200  # 1.65 GB (past the memory cap) or 1.6 MB of float64
        header = b"{'descr': '<f8', 'fortran_order': False, 'shape': (%d, 165), }" % rows
        return _zip_with_bomb(members, name, header, rows * 165 * 8)
    if roll < 0.5:
        members[i] = (name, _wrong_npy(rng))
    elif roll < 0.8:
        members[i] = (name, npy_header(rng, raw))
    elif roll < 0.9:
        members[i] = (rng.choice(("../x.npy", "a" * 300 + ".npy", "x.npy", name.upper(), "")) or name, raw)
    else:
        members.append(members[i])  # a duplicate member name
    out = io.BytesIO()
    with warnings.catch_warnings(), zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        warnings.simplefilter("ignore")  # "Duplicate name": that is the point of this mutation
        for n, r in members:
            z.writestr(n, r)
    return out.getvalue()


# --- glTF / GLB / VRM ------------------------------------------------------------------------------


def _glb_split(data: bytes) -> tuple[bytes, bytes] | None:
    if len(data) < 20 or data[:4] != b"glTF":
        return None
    n = struct.unpack_from("<I", data, 12)[0]
    if data[16:20] != b"JSON" or 20 + n > len(data):
        return None
    return data[20:20 + n], data[20 + n:]


def glb_json(rng: random.Random, data: bytes) -> bytes:
    """The GLB's JSON chunk edited like a .gltf (sizes, offsets, references, types), the container rebuilt."""
    parts = _glb_split(data)
    if parts is None:
        return magic_int(rng, data)
    text, rest = parts
    new = json_edit(rng, text, GLTF_KEYS)
    new += b" " * (-len(new) % 4)
    body = struct.pack("<I", len(new)) + b"JSON" + new + rest
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body


def gltf_json(rng: random.Random, data: bytes) -> bytes:
    return json_edit(rng, data, GLTF_KEYS)


def glb_to_gltf(glb: bytes) -> bytes:
    """A .gltf (JSON, the binary chunk as a base64 data URI) holding the same asset as a GLB."""
    parts = _glb_split(glb)
    if parts is None:
        raise ValueError("not a GLB")
    text, rest = parts
    doc = json.loads(text)
    n = struct.unpack_from("<I", rest, 0)[0]
    blob = rest[8:8 + n]
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
    return json.dumps(doc).encode()


# --- results databases -----------------------------------------------------------------------------


def sqlite_value(rng: random.Random, data: bytes) -> bytes:
    """One cell of one table set to a wrong type or absurd value (or rows deleted / duplicated), through
    SQLite itself so the file stays a valid database: what a reader sees when someone edits the file."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "db.sqlite"
        path.write_bytes(data)
        try:
            con = sqlite3.connect(path)
            tables = [r[0] for r in con.execute("SELECT name FROM sqlite_master WHERE type='table'")]
            tables = [t for t in tables if con.execute(f'SELECT count(*) FROM "{t}"').fetchone()[0]]
            if not tables:
                con.close()
                return bit_flip(rng, data)
            table = rng.choice(sorted(tables))
            cols = [r[1] for r in con.execute(f'PRAGMA table_info("{table}")')]
            rowids = [r[0] for r in con.execute(f'SELECT rowid FROM "{table}"')]
            rowid = rng.choice(rowids)
            roll = rng.random()
            if roll < 0.7:
                col = rng.choice(cols)
                value = rng.choice((None, "abc", -5, 99, 2**63 - 1, 1e308, float("nan"), b"\x00\xff", "",
                                    "x" * 100_000, '{"a": [', "clkp04", 0.5))
                try:
                    con.execute(f'UPDATE "{table}" SET "{col}" = ? WHERE rowid = ?', (value, rowid))
                except sqlite3.Error:
                    pass
            elif roll < 0.85:
                con.execute(f'DELETE FROM "{table}" WHERE rowid = ?', (rowid,))
            else:
                try:
                    con.execute(f'INSERT INTO "{table}" SELECT * FROM "{table}" WHERE rowid = ?', (rowid,))
                except sqlite3.Error:
                    pass
            con.commit()
            con.close()
        except sqlite3.Error:
            return bit_flip(rng, data)
        return path.read_bytes()


def sqlite_page(rng: random.Random, data: bytes) -> bytes:
    """Bits flipped inside one database page (not the 100-byte file header)."""
    if len(data) <= 4096:
        return bit_flip(rng, data)
    b = bytearray(data)
    page = rng.randrange(len(data) // 4096)
    for _ in range(rng.choice((1, 1, 2, 8))):
        i = page * 4096 + rng.randrange(100 if page == 0 else 0, 4096)
        b[i] ^= 1 << rng.randrange(8)
    return bytes(b)


# --- per reader ------------------------------------------------------------------------------------

_MUTATORS: dict[str, tuple[Mutator, ...]] = {
    "bvh": BYTE_MUTATORS + TEXT_MUTATORS + (bvh_deep_chain, bvh_channels, bvh_header, bvh_header),
    "face_csv": BYTE_MUTATORS + TEXT_MUTATORS + (csv_wide, csv_wide),
    "face_json": BYTE_MUTATORS + TEXT_MUTATORS + (json_edit, json_edit, json_deep),
    "wav": BYTE_MUTATORS + (wav_header, wav_header, wav_header),
    "npy": BYTE_MUTATORS + (npy_header, npy_header, npy_header),
    "npz": BYTE_MUTATORS + (npz_member, npz_member, npz_member, npz_member),
    "gltf": BYTE_MUTATORS + TEXT_MUTATORS + (gltf_json,) * 6 + (json_deep,),
    "glb": BYTE_MUTATORS + (glb_json,) * 6,
    "vrm": BYTE_MUTATORS + (glb_json,) * 6,
    "toml": BYTE_MUTATORS + TEXT_MUTATORS + (toml_pattern, toml_pattern, toml_deep, toml_nul_path, toml_value,
                                             toml_value, toml_value),
    "sqlite": BYTE_MUTATORS + (sqlite_value, sqlite_value, sqlite_value, sqlite_page, sqlite_page),
}

READERS: tuple[str, ...] = tuple(_MUTATORS)


def mutators_for(reader: str) -> tuple[Mutator, ...]:
    return _MUTATORS[reader]


def mutate(rng: random.Random, reader: str, data: bytes) -> tuple[bytes, list[str]]:
    """``data`` after one to three mutations chosen by ``rng``, and their names."""
    names = []
    for _ in range(rng.choice((1, 1, 1, 2, 3))):
        m = rng.choice(_MUTATORS[reader])
        data = m(rng, data)
        names.append(m.__name__)
    return data, names
