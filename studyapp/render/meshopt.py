"""Decoder for glTF ``EXT_meshopt_compression`` and ``KHR_meshopt_compression`` buffer views (numpy; written
from the extensions' specs).

gltfpack compresses each buffer view on its own with one of three bitstreams and, for vertex data, an
optional filter applied after decoding:

* ``ATTRIBUTES`` (header ``0xa0``, or ``0xa1`` for KHR's version 1): elements split into blocks; per block
  and per byte of the element, zigzag byte deltas from the previous element, in groups of 16 coded as
  all-zero, 2-bit or 4-bit values with an escape to a full byte, or 16 raw bytes. The first element's
  baseline sits at the stream's end. Version 1 adds 1-bit groups, literal and all-zero bytes, and 16-bit
  or rotated 32-bit XOR deltas per 4-byte channel.
* ``TRIANGLES`` (header ``0xe1``): one code byte per triangle that reuses recent edges and vertices
  (16-entry FIFOs), with LEB128 zigzag index deltas for the rest and a 16-byte lookup table at the end.
* ``INDICES`` (header ``0xd1``): LEB128 zigzag deltas against one of two running baselines.
* Filters ``OCTAHEDRAL`` (unit vectors), ``QUATERNION`` (unit quaternions), ``EXPONENTIAL`` (floats as
  a signed exponent byte and a 24-bit mantissa) and KHR's ``COLOR`` (YCoCg).

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
FILTERS = ("NONE", "OCTAHEDRAL", "QUATERNION", "EXPONENTIAL", "COLOR")


class MeshoptError(ValueError):
    """The compressed stream is malformed (the caller adds the file and buffer view to the message)."""


def _unzigzag8(v: np.ndarray) -> np.ndarray:
    v = v.astype(np.uint8)
    return np.where(v & 1, ~(v >> 1), v >> 1).astype(np.uint8)


def _decode_group(data: bytes, pos: int, mode: int) -> tuple[np.ndarray, int]:
    """16 zigzag-coded byte deltas of one version-0 group starting at ``data[pos]``; returns them and the
    bytes used (mode 0: all zero, 1: 2-bit, 2: 4-bit, 3: 16 raw bytes)."""
    return _decode_bits(data, pos, (0, 2, 4, 8)[mode])


def _decode_bits(data: bytes, pos: int, bits: int) -> tuple[np.ndarray, int]:
    """16 deltas packed ``bits`` wide (0: all zero, 8: raw bytes), escapes to full bytes after the packed ones."""
    if bits == 0:
        return np.zeros(16, np.uint8), 0
    packed = 16 * bits // 8
    if pos + packed > len(data):
        raise MeshoptError("attribute group runs past the end of the stream")
    raw = np.frombuffer(data, np.uint8, packed, pos)
    if bits == 8:
        return raw.copy(), 16
    per = 8 // bits
    # 2 and 4 bits: most significant first inside each byte; 1 bit: least significant first
    shifts = np.arange(per) * bits if bits == 1 else np.arange(per - 1, -1, -1) * bits
    vals = ((raw[:, None] >> shifts[None, :]) & ((1 << bits) - 1)).reshape(-1).astype(np.uint8)
    sentinel = (1 << bits) - 1
    escaped = np.flatnonzero(vals == sentinel)
    end = pos + packed + len(escaped)
    if end > len(data):
        raise MeshoptError("attribute group escapes run past the end of the stream")
    vals[escaped] = np.frombuffer(data, np.uint8, len(escaped), pos + packed)
    return vals, packed + len(escaped)


# bit widths of the four group modes: version 0, and version 1 under byte control modes 0 and 1
_GROUP_BITS = {0: (0, 2, 4, 8), (1, 0): (0, 1, 2, 4), (1, 1): (1, 2, 4, 8)}


def decode_attributes(data: bytes, count: int, stride: int) -> bytes:
    """Mode 0: ``count`` elements of ``stride`` bytes; version 0 (``0xa0``, EXT) or 1 (``0xa1``, KHR).

    Version 1 adds a control mode per byte and block (group widths {0,1,2,4} or {1,2,4,8} bits, all zero,
    or literal bytes) and a channel mode per 4 bytes in the tail (byte deltas, 16-bit deltas, or 32-bit
    XOR deltas rotated right by the mode's high nibble).
    """
    if stride <= 0 or stride > 256 or stride % 4:
        raise MeshoptError(f"byteStride {stride} is not a multiple of 4 up to 256")
    if len(data) < 1 or data[0] not in (0xA0, 0xA1):
        raise MeshoptError("not an ATTRIBUTES stream (header byte must be 0xa0 or 0xa1)")
    version = data[0] & 0x0F
    tail_size = stride + (stride // 4 if version else 0)
    tail = max(tail_size, 24 if version else 32)
    if len(data) < 1 + tail:
        raise MeshoptError("ATTRIBUTES stream shorter than its tail")
    base = len(data) - tail_size
    baseline = np.frombuffer(data, np.uint8, stride, base).astype(np.int64)
    channels = (np.frombuffer(data, np.uint8, stride // 4, base + stride) if version
                else np.zeros(stride // 4, np.uint8))
    for c in channels:
        if (c & 0x0F) > 2 or ((c & 0x0F) < 2 and c >> 4):
            raise MeshoptError(f"invalid channel mode {c:#04x}")
    out = np.zeros((count, stride), np.uint8)
    block_max = min((8192 // stride) & ~15, 256)
    pos = 1
    start = 0
    limit = len(data) - tail
    while start < count:
        n = min(block_max, count - start)
        groups = (n + 15) // 16
        header_size = (groups + 3) // 4
        control = b""
        if version:
            control = data[pos: pos + stride // 4]
            pos += stride // 4
        deltas = np.zeros((stride, n), np.uint8)
        for k in range(stride):
            ctrl = (control[k // 4] >> ((k % 4) * 2)) & 3 if version else 0
            if ctrl == 2:
                continue  # all deltas zero
            if ctrl == 3:  # literal bytes, no header
                if pos + n > limit:
                    raise MeshoptError("attribute block runs into the stream's tail")
                deltas[k] = np.frombuffer(data, np.uint8, n, pos)
                pos += n
                continue
            if pos + header_size > limit:
                raise MeshoptError("attribute block runs into the stream's tail")
            header = data[pos: pos + header_size]
            pos += header_size
            widths = _GROUP_BITS[(1, ctrl)] if version else _GROUP_BITS[0]
            col = np.empty(groups * 16, np.uint8)
            for g in range(groups):
                mode = (header[g // 4] >> ((g % 4) * 2)) & 3
                col[g * 16: g * 16 + 16], used = _decode_bits(data, pos, widths[mode])
                pos += used
            deltas[k] = col[:n]
        for c, cm in enumerate(channels):
            b = slice(4 * c, 4 * c + 4)
            mode, rot = int(cm & 0x0F), int(cm >> 4)
            if mode == 0:  # byte deltas: a running sum modulo 256 from the previous element
                vals = (baseline[b, None] + np.cumsum(_unzigzag8(deltas[b]).astype(np.int64), 1)) & 0xFF
                out[start: start + n, b] = vals.T
            elif mode == 1:  # 16-bit deltas, little-endian
                for h in (4 * c, 4 * c + 2):
                    d = deltas[h].astype(np.int64) | (deltas[h + 1].astype(np.int64) << 8)
                    d = np.where(d & 1, ~(d >> 1), d >> 1)
                    prev = int(baseline[h]) | (int(baseline[h + 1]) << 8)
                    vals = (prev + np.cumsum(d)) & 0xFFFF
                    out[start: start + n, h] = vals & 0xFF
                    out[start: start + n, h + 1] = vals >> 8
            else:  # 32-bit XOR deltas, rotated right by rot
                d = sum(deltas[4 * c + i].astype(np.uint64) << np.uint64(8 * i) for i in range(4))
                d = ((d >> np.uint64(rot)) | (d << np.uint64((32 - rot) % 32))) & np.uint64(0xFFFFFFFF)
                prev = np.uint64(sum(int(baseline[4 * c + i]) << (8 * i) for i in range(4)))
                vals = np.bitwise_xor.accumulate(np.r_[prev, d])[1:]
                for i in range(4):
                    out[start: start + n, 4 * c + i] = (vals >> np.uint64(8 * i)) & np.uint64(0xFF)
            baseline[b] = out[start + n - 1, b]
        start += n
    if pos != limit:
        raise MeshoptError(f"ATTRIBUTES stream has {limit - pos} bytes more than it decodes")
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


def _filter_color(raw: bytes, stride: int) -> bytes:
    """KHR's COLOR filter: YCoCg with the bit depth K marked by the alpha's top bit, to normalized RGBA."""
    udt, sdt, top = (np.uint8, np.int8, 255) if stride == 4 else (np.uint16, np.int16, 65535)
    u = np.frombuffer(raw, udt).reshape(-1, 4).astype(np.int64)
    sgn = np.frombuffer(raw, sdt).reshape(-1, 4).astype(np.int64)
    y, co, cg, a_in = u[:, 0], sgn[:, 1], sgn[:, 2], u[:, 3]
    msb = np.floor(np.log2(np.maximum(a_in, 1))).astype(np.int64)
    scale = (1 << (msb + 1)) - 1
    a = a_in & (scale >> 1)
    a = (a << 1) | (a & 1)
    ss = top / scale
    rgba = np.stack([y + co - cg, y + cg, y - co - cg, a], 1) * ss[:, None]
    return np.clip(np.round(rgba), 0, top).astype(udt).tobytes()


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
        elif filter_ == "COLOR":
            if stride not in (4, 8):
                raise MeshoptError(f"COLOR filter needs byteStride 4 or 8, not {stride}")
            raw = _filter_color(raw, stride)
        return raw
    if stride not in (2, 4):
        raise MeshoptError(f"{mode} needs byteStride 2 or 4, not {stride}")
    idx = decode_triangles(data, count) if mode == "TRIANGLES" else decode_indices(data, count)
    return idx.astype(np.uint16 if stride == 2 else np.uint32).tobytes()
