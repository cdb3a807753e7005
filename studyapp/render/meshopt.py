"""Decoder for glTF ``EXT_meshopt_compression`` buffer views (numpy; written from the extension's spec).

gltfpack compresses each buffer view on its own with one of three bitstreams and, for vertex data, an
optional filter applied after decoding:

* ``ATTRIBUTES`` (header ``0xa0``): elements split into blocks; per block and per byte of the element,
  zigzag byte deltas from the previous element, in groups of 16 coded as all-zero, 2-bit or 4-bit values
  with an escape to a full byte, or 16 raw bytes. The first element's baseline sits at the stream's end.
* ``TRIANGLES`` (header ``0xe1``): one code byte per triangle that reuses recent edges and vertices
  (16-entry FIFOs), with LEB128 zigzag index deltas for the rest and a 16-byte lookup table at the end.
* ``INDICES`` (header ``0xd1``): LEB128 zigzag deltas against one of two running baselines.
* Filters ``OCTAHEDRAL`` (unit vectors), ``QUATERNION`` (unit quaternions) and ``EXPONENTIAL`` (floats as
  a signed exponent byte and a 24-bit mantissa).

:func:`decode_view` returns the raw bytes the parent buffer view would hold uncompressed, so accessors
read them as if the file had never been compressed.

The spec's own worked example of a 4-bit group (16 deltas, two of them escaped to full bytes):

>>> group = bytes([0x17, 0x5f, 0xf0, 0xbc, 0x77, 0xa9, 0x21, 0x00, 0x34, 0xb5])
>>> deltas, used = _decode_group(group, 0, 2)
>>> _unzigzag8(deltas).astype(np.int8).tolist(), used
([-1, -4, -3, 26, -91, 0, -6, 6, -4, -4, 5, -5, 1, -1, 0, 0], 10)
"""
from __future__ import annotations

import numpy as np

MODES = ("ATTRIBUTES", "TRIANGLES", "INDICES")
FILTERS = ("NONE", "OCTAHEDRAL", "QUATERNION", "EXPONENTIAL")


class MeshoptError(ValueError):
    """The compressed stream is malformed (the caller adds the file and buffer view to the message)."""


def _unzigzag8(v: np.ndarray) -> np.ndarray:
    v = v.astype(np.uint8)
    return np.where(v & 1, ~(v >> 1), v >> 1).astype(np.uint8)


def _decode_group(data: bytes, pos: int, mode: int) -> tuple[np.ndarray, int]:
    """16 zigzag-coded byte deltas of one group starting at ``data[pos]``; returns them and the bytes used."""
    if mode == 0:
        return np.zeros(16, np.uint8), 0
    if mode == 3:
        if pos + 16 > len(data):
            raise MeshoptError("attribute group runs past the end of the stream")
        return np.frombuffer(data, np.uint8, 16, pos).copy(), 16
    bits = 2 if mode == 1 else 4
    packed = 16 * bits // 8
    if pos + packed > len(data):
        raise MeshoptError("attribute group runs past the end of the stream")
    raw = np.frombuffer(data, np.uint8, packed, pos)
    per = 8 // bits
    # most significant bits first inside each byte
    shifts = np.arange(per - 1, -1, -1) * bits
    vals = ((raw[:, None] >> shifts[None, :]) & ((1 << bits) - 1)).reshape(-1).astype(np.uint8)
    sentinel = (1 << bits) - 1
    escaped = np.flatnonzero(vals == sentinel)
    end = pos + packed + len(escaped)
    if end > len(data):
        raise MeshoptError("attribute group escapes run past the end of the stream")
    vals[escaped] = np.frombuffer(data, np.uint8, len(escaped), pos + packed)
    return vals, packed + len(escaped)


def decode_attributes(data: bytes, count: int, stride: int) -> bytes:
    """Mode 0: ``count`` elements of ``stride`` bytes."""
    if stride <= 0 or stride > 256 or stride % 4:
        raise MeshoptError(f"byteStride {stride} is not a multiple of 4 up to 256")
    if len(data) < 1 + stride or data[0] != 0xA0:
        raise MeshoptError("not an ATTRIBUTES stream (header byte must be 0xa0)")
    tail = max(stride, 32)
    baseline = np.frombuffer(data, np.uint8, stride, len(data) - stride).astype(np.int64)
    out = np.zeros((count, stride), np.uint8)
    block_max = min((8192 // stride) & ~15, 256)
    pos = 1
    start = 0
    while start < count:
        n = min(block_max, count - start)
        groups = (n + 15) // 16
        header_size = (groups + 3) // 4
        for k in range(stride):
            if pos + header_size > len(data) - tail:
                raise MeshoptError("attribute block runs into the stream's tail")
            header = data[pos: pos + header_size]
            pos += header_size
            deltas = np.empty(groups * 16, np.uint8)
            for g in range(groups):
                mode = (header[g // 4] >> ((g % 4) * 2)) & 3
                deltas[g * 16: g * 16 + 16], used = _decode_group(data, pos, mode)
                pos += used
            # byte values wrap around: a running sum modulo 256 from the previous element
            vals = (baseline[k] + np.cumsum(_unzigzag8(deltas[:n]).astype(np.int64))) & 0xFF
            out[start: start + n, k] = vals
            baseline[k] = vals[-1]
        start += n
    if len(data) - pos != tail:
        raise MeshoptError(f"ATTRIBUTES stream has {len(data) - pos - tail} bytes more than it decodes")
    return out.tobytes()


def _leb128(data: bytes, pos: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if pos >= len(data):
            raise MeshoptError("index varint runs past the end of the stream")
        b = data[pos]
        pos += 1
        value |= (b & 0x7F) << shift
        if not b & 0x80:
            return value, pos
        shift += 7
        if shift > 35:
            raise MeshoptError("index varint longer than 5 bytes")


def _zigzag32(v: int) -> int:
    return -((v >> 1) + 1) if v & 1 else v >> 1


def decode_triangles(data: bytes, count: int) -> np.ndarray:
    """Mode 1: ``count`` indices (a multiple of 3) of a triangle list, as ``uint32``."""
    if count % 3:
        raise MeshoptError(f"TRIANGLES count {count} is not a multiple of 3")
    if len(data) < 1 + count // 3 + 16 or data[0] != 0xE1:
        raise MeshoptError("not a TRIANGLES stream (header byte must be 0xe1)")
    n_tri = count // 3
    codes = data[1: 1 + n_tri]
    pos = 1 + n_tri
    data_end = len(data) - 16
    aux = data[data_end:]
    edges = [(0, 0)] * 16
    verts = [0] * 16
    e_head = v_head = 0  # index of the next slot to write; entry 0 is the most recent
    nxt = last = 0
    out = np.empty(count, np.int64)

    def push_edge(a: int, b: int) -> None:
        nonlocal e_head
        edges[e_head] = (a, b)
        e_head = (e_head + 1) & 15

    def push_vert(v: int) -> None:
        nonlocal v_head
        verts[v_head] = v
        v_head = (v_head + 1) & 15

    def index() -> int:
        nonlocal pos, last
        v, pos = _leb128(data, pos)
        last = (last + _zigzag32(v)) & 0xFFFFFFFF
        return last

    for t, code in enumerate(codes):
        hi, lo = code >> 4, code & 15
        if hi < 15:
            a, b = edges[(e_head - 1 - hi) & 15]
            if lo == 0:
                c = nxt
                nxt += 1
                push_vert(c)
            elif lo < 13:
                c = verts[(v_head - 1 - lo) & 15]
            elif lo < 15:
                c = last = (last + (1 if lo == 14 else -1)) & 0xFFFFFFFF
                push_vert(c)
            else:
                c = index()
                push_vert(c)
            push_edge(c, b)
            push_edge(a, c)
        else:
            if lo < 14:
                zw = aux[lo]
                explicit_a = False
            else:
                if pos >= data_end:
                    raise MeshoptError("triangle data runs past the end of the stream")
                zw = data[pos]
                pos += 1
                if zw == 0:
                    nxt = 0
                explicit_a = lo == 15
            z, w = zw >> 4, zw & 15
            if explicit_a:
                a = index()
            else:
                a = nxt
                nxt += 1
            if z == 0:
                b = nxt
                nxt += 1
            elif z < 15:
                b = verts[(v_head - z) & 15]
            else:
                b = index()
            if w == 0:
                c = nxt
                nxt += 1
            elif w < 15:
                c = verts[(v_head - w) & 15]
            else:
                c = index()
            push_vert(a)
            if z == 0 or z == 15:
                push_vert(b)
            if w == 0 or w == 15:
                push_vert(c)
            push_edge(b, a)
            push_edge(c, b)
            push_edge(a, c)
        out[3 * t: 3 * t + 3] = (a, b, c)
    if pos != data_end:
        raise MeshoptError(f"TRIANGLES stream has {data_end - pos} unread bytes")
    return out.astype(np.uint32)


def decode_indices(data: bytes, count: int) -> np.ndarray:
    """Mode 2: ``count`` indices against two running baselines, as ``uint32``."""
    if len(data) < 1 + 4 or data[0] != 0xD1:
        raise MeshoptError("not an INDICES stream (header byte must be 0xd1)")
    last = [0, 0]
    pos = 1
    end = len(data) - 4
    out = np.empty(count, np.int64)
    for i in range(count):
        v, pos = _leb128(data, pos)
        base = v & 1
        d = v >> 1
        delta = -((d >> 1) + 1) if d & 1 else d >> 1
        last[base] = (last[base] + delta) & 0xFFFFFFFF
        out[i] = last[base]
    if pos != end:
        raise MeshoptError(f"INDICES stream has {end - pos} unread bytes")
    return out.astype(np.uint32)


def _filter_octahedral(raw: bytes, stride: int) -> bytes:
    dtype, top = (np.int8, 127.0) if stride == 4 else (np.int16, 32767.0)
    v = np.frombuffer(raw, dtype).reshape(-1, 4).astype(np.float64)
    one = np.where(v[:, 2] == 0, 1.0, v[:, 2])
    x, y = v[:, 0] / one, v[:, 1] / one
    z = 1.0 - np.abs(x) - np.abs(y)
    t = np.minimum(z, 0.0)
    x = x - np.copysign(t, x)
    y = y - np.copysign(t, y)
    ln = np.sqrt(x * x + y * y + z * z)
    ln = np.where(ln > 0, ln, 1.0)
    out = np.empty_like(v)
    out[:, 0], out[:, 1], out[:, 2] = np.round(x / ln * top), np.round(y / ln * top), np.round(z / ln * top)
    out[:, 3] = v[:, 3]
    return out.astype(dtype).tobytes()


def _filter_quaternion(raw: bytes) -> bytes:
    v = np.frombuffer(raw, np.int16).reshape(-1, 4).astype(np.int64)
    one = (v[:, 3] | 3).astype(np.float64)
    xyz = v[:, :3] / one[:, None] * (1.0 / np.sqrt(2.0))
    w = np.sqrt(np.maximum(0.0, 1.0 - (xyz ** 2).sum(1)))
    maxcomp = (v[:, 3] & 3).astype(np.int64)
    out = np.empty((len(v), 4), np.int16)
    rows = np.arange(len(v))
    for k in range(3):
        out[rows, (maxcomp + 1 + k) % 4] = np.round(xyz[:, k] * 32767.0)
    out[rows, maxcomp] = np.round(w * 32767.0)
    return out.tobytes()


def _filter_exponential(raw: bytes) -> bytes:
    v = np.frombuffer(raw, "<i4")
    e = v >> 24
    m = (v << 8) >> 8
    return (np.ldexp(m.astype(np.float64), e)).astype("<f4").tobytes()


def decode_view(data: bytes, count: int, stride: int, mode: str, filter_: str = "NONE") -> bytes:
    """The uncompressed bytes (``count * stride``) of one buffer view's ``EXT_meshopt_compression`` stream.

    >>> decode_view(bytes([0xd1, 0x00, 0x04, 0xcd, 0x01, 0x04, 0x07, 0x98, 0x1f, 0, 0, 0, 0]), 6, 4, "INDICES")[:8]
    b'\\x00\\x00\\x00\\x00\\x01\\x00\\x00\\x00'
    """
    if mode not in MODES:
        raise MeshoptError(f"unknown mode {mode!r} (known: {', '.join(MODES)})")
    if filter_ not in FILTERS:
        raise MeshoptError(f"unknown filter {filter_!r} (known: {', '.join(FILTERS)})")
    if mode == "ATTRIBUTES":
        raw = decode_attributes(data, count, stride)
        if filter_ == "OCTAHEDRAL":
            if stride not in (4, 8):
                raise MeshoptError(f"OCTAHEDRAL filter needs byteStride 4 or 8, not {stride}")
            raw = _filter_octahedral(raw, stride)
        elif filter_ == "QUATERNION":
            if stride != 8:
                raise MeshoptError(f"QUATERNION filter needs byteStride 8, not {stride}")
            raw = _filter_quaternion(raw)
        elif filter_ == "EXPONENTIAL":
            raw = _filter_exponential(raw)
        return raw
    if stride not in (2, 4):
        raise MeshoptError(f"{mode} needs byteStride 2 or 4, not {stride}")
    idx = decode_triangles(data, count) if mode == "TRIANGLES" else decode_indices(data, count)
    return idx.astype(np.uint16 if stride == 2 else np.uint32).tobytes()
