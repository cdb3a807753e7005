"""Zip members, ``.npy`` and ``.npz`` files read without trusting a size they claim.

Every reader of a container the app did not just write itself goes through here: results zips
(``merge``), study bundles (``run STUDY.zip``), NumPy motion, face, head and body-model files, the live
model cache. A file states sizes in several places (a zip's end record and central directory, each
member's header, an ``.npy`` header's shape and dtype); each one is checked against a limit and against the
bytes really there *before* anything of that size is allocated or decompressed:

* a zip's member count is read from its end record before :mod:`zipfile` builds its directory;
* each member's uncompressed size, the total and the compression ratio are checked against
  :class:`ZipLimits` (a ratio above ``max_ratio`` on a large member is a zip bomb), members are read in
  chunks and reading stops at the stated size, so a member whose header understates what it expands to
  is refused rather than trusted; encrypted members, compression methods other than stored/deflate and
  symbolic links are refused;
* an ``.npy`` header (its own length first) is parsed as a literal, its dtype must be plain data (numbers,
  booleans or text: an object dtype is a pickle, which can run code, and is never loaded) and shape x
  itemsize must equal the bytes that follow the header, so a header claiming 10^12 frames is refused
  before one byte of data is read.

Every failure is one :class:`~studyapp.errors.InputError` naming the file, the member or key, and what is
wrong. :func:`require` checks a loaded field's kind and shape, for readers whose files have a layout (a
studyapp motion ``.npz`` with ``joints`` saved as numbers is refused by name, not by a traceback).

>>> import numpy as np, tempfile, os
>>> path = os.path.join(tempfile.mkdtemp(), "a.npz")
>>> np.savez_compressed(path, poses=np.zeros((4, 6)), names=np.array(["a", "b"]))
>>> with open_npz(path) as z:
...     z.files, z.header("poses").shape, z["names"].tolist()
(['poses', 'names'], (4, 6), ['a', 'b'])
"""
from __future__ import annotations

import ast
import io
import os
import stat
import struct
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Iterator

import numpy as np

from studyapp.errors import InputError

__all__ = [
    "ZipLimits", "RESULTS_ZIP", "BUNDLE_ZIP", "NPZ_ZIP", "NPY_MAX_BYTES", "SafeZip", "NpyHeader", "Npz",
    "read_npy_header", "npy_header", "load_npy", "open_npz", "numpy_kind", "load_numpy", "require", "human_bytes",
    "safe_member_name",
]

_CHUNK = 1 << 20
_NPY_MAGIC = b"\x93NUMPY"
#: numpy itself refuses headers longer than this unless the file is fully trusted
_NPY_MAX_HEADER = 10_000
#: dtype kinds a data file may hold: booleans, integers, floats, bytes and unicode text
_PLAIN_KINDS = "biufSU"
_PICKLED = ("holds pickled Python objects, which studyapp never loads (loading them can run code); save the data "
            "as numbers")


@dataclass(frozen=True)
class ZipLimits:
    """What a zip of one kind may hold: members, bytes per member and in all, and compression ratio.

    The ratio (uncompressed / compressed) is checked only on members larger than ``ratio_from_bytes``:
    small files of repeated lines (a still figure's BVH) compress far better than any data worth a bomb.
    """

    what: str
    max_members: int
    max_member_bytes: int
    max_total_bytes: int
    max_ratio: float = 100.0
    ratio_from_bytes: int = 64 << 20
    #: names that differ only in case are refused (members extracted to disk: one file on Windows and macOS)
    distinct_ignoring_case: bool = False


#: a returned results file: ``results.json`` (one participant's rows) and ``manifest.json``
RESULTS_ZIP = ZipLimits("results file", max_members=16, max_member_bytes=64 << 20, max_total_bytes=64 << 20)
#: a study bundle: every stimulus, motion, template and avatar of a study, extracted to disk in chunks
BUNDLE_ZIP = ZipLimits("study bundle", max_members=20_000, max_member_bytes=1 << 30, max_total_bytes=4 << 30,
                       distinct_ignoring_case=True)
#: an ``.npz``: motion and face arrays are a few MB, an SMPL-X body model a few hundred
NPZ_ZIP = ZipLimits(".npz file", max_members=1_000, max_member_bytes=1 << 30, max_total_bytes=1 << 30)
#: the largest array read from an ``.npy`` file
NPY_MAX_BYTES = 1 << 30


def human_bytes(n: int) -> str:
    """``n`` bytes for a message.

    >>> human_bytes(2 << 30), human_bytes(64 << 20), human_bytes(512)
    ('2.0 GB', '64 MB', '512 bytes')
    """
    for unit, size in (("GB", 1 << 30), ("MB", 1 << 20), ("KB", 1 << 10)):
        if n >= size:
            return f"{n / size:.1f} {unit}" if n < 10 * size else f"{n // size} {unit}"
    return f"{n} bytes"


# ------------------------------------------------------------------------------------------------ zips
def _declared_entries(fp: BinaryIO, size: int) -> tuple[int, int] | None:
    """``(entries, central directory bytes)`` from a zip's end record (zip64 when present), or ``None``.

    Read before :class:`zipfile.ZipFile`, which builds an object per directory entry: a small file can
    claim millions of entries.
    """
    tail_len = min(size, 22 + 0xFFFF + 20)
    fp.seek(size - tail_len)
    tail = fp.read(tail_len)
    at = tail.rfind(b"PK\x05\x06")
    if at < 0 or len(tail) - at < 22:
        return None
    entries, cd_size = _eocd(tail[at:at + 22])
    loc = at - 20
    if (entries == 0xFFFF or cd_size == 0xFFFFFFFF) and loc >= 0 and tail[loc:loc + 4] == b"PK\x06\x07":
        (z64_at,) = struct.unpack("<Q", tail[loc + 8:loc + 16])
        if z64_at + 56 <= size:
            fp.seek(z64_at)
            rec = fp.read(56)
            if rec[:4] == b"PK\x06\x06":
                entries, cd_size = struct.unpack("<Q Q", rec[32:48])
    return entries, cd_size


def _eocd(rec: bytes) -> tuple[int, int]:
    # signature, disk, cd disk, entries on disk, total entries, cd size, cd offset, comment length
    _sig, _d, _cd, _n_disk, n_total, cd_size, _off, _clen = struct.unpack("<4s4H2LH", rec)
    return n_total, cd_size


class SafeZip:
    """A zip whose directory and every member passed :class:`ZipLimits` (see the module docstring).

    Use as a context manager; :meth:`read` returns a member's bytes, :meth:`copy` streams one into a file.
    Zip-slip names (absolute, ``..``, drive letters, backslashes) are refused for every kind of zip: no
    studyapp zip has a reason to hold one.
    """

    def __init__(self, path: str | Path, limits: ZipLimits) -> None:
        self.path = Path(path)
        self.limits = limits
        self._fp = _open_file(self.path)
        try:
            self._zf = self._open()
            self.infos = self._check(self._zf.infolist())
        except BaseException:
            self.close()
            raise

    def _fail(self, where: str | None, problem: str) -> InputError:
        return InputError(self.path, where, problem)

    def _open(self) -> zipfile.ZipFile:
        lim = self.limits
        size = os.fstat(self._fp.fileno()).st_size
        declared = _declared_entries(self._fp, size)
        if declared is not None:
            entries, cd_size = declared
            # a directory entry is 46 bytes plus its name and extra fields
            if entries > lim.max_members or cd_size > lim.max_members * 1024:
                raise self._fail(None, f"the zip directory claims {entries} members ({human_bytes(cd_size)}); a "
                                 f"{lim.what} holds at most {lim.max_members}: refused")
        self._fp.seek(0)
        try:
            return zipfile.ZipFile(self._fp)
        except (zipfile.BadZipFile, zlib.error, EOFError, ValueError, OverflowError, struct.error, OSError,
                NotImplementedError, RuntimeError) as exc:
            raise self._fail(None, f"not a readable {lim.what} (a damaged zip: {exc})") from None

    def _check(self, infos: list[zipfile.ZipInfo]) -> list[zipfile.ZipInfo]:
        lim = self.limits
        if len(infos) > lim.max_members:
            raise self._fail(None, f"{len(infos)} members; a {lim.what} holds at most {lim.max_members}")
        seen: set[str] = set()
        total = 0
        for info in infos:
            name = info.filename
            if not safe_member_name(name):
                raise self._fail(name, "unsafe member name (absolute, '..', a drive letter or a backslash): refused")
            folded = name.lower() if lim.distinct_ignoring_case else name
            if folded in seen:
                raise self._fail(name, "the zip holds this name twice" + (
                    " (or twice in different case)" if lim.distinct_ignoring_case else "") + ": refused")
            seen.add(folded)
            if info.flag_bits & 0x1:
                raise self._fail(name, "the member is encrypted; studyapp never encrypts its files")
            if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
                raise self._fail(name, f"compression method {info.compress_type} is not one studyapp or numpy "
                                 "writes (stored or deflate)")
            if stat.S_ISLNK(info.external_attr >> 16):
                raise self._fail(name, "the member is a symbolic link: refused")
            if info.file_size > lim.max_member_bytes:
                raise self._fail(name, f"expands to {human_bytes(info.file_size)}; a member of a {lim.what} may "
                                 f"hold at most {human_bytes(lim.max_member_bytes)}: refused")
            if info.compress_type == zipfile.ZIP_STORED and info.compress_size != info.file_size:
                raise self._fail(name, "the member is stored uncompressed but its two sizes differ: damaged")
            ratio = info.file_size / max(info.compress_size, 1)
            if info.file_size > lim.ratio_from_bytes and ratio > lim.max_ratio:
                raise self._fail(name, f"{human_bytes(info.compress_size)} expand to {human_bytes(info.file_size)} "
                                 f"(ratio {ratio:.0f}:1, a zip bomb?): refused")
            total += info.file_size
            if total > lim.max_total_bytes:
                raise self._fail(None, f"the members expand to more than {human_bytes(lim.max_total_bytes)} in "
                                 f"all; a {lim.what} holds less: refused")
        return infos

    @property
    def names(self) -> list[str]:
        return [i.filename for i in self.infos]

    def info(self, name: str) -> zipfile.ZipInfo:
        try:
            return self._zf.getinfo(name)
        except KeyError:
            raise self._fail(name, f"missing from the {self.limits.what}") from None

    def chunks(self, name: str) -> Iterator[bytes]:
        """A member's bytes in chunks, never more than its (checked) stated size; any damage is an InputError."""
        info = self.info(name)
        left = info.file_size
        try:
            with self._zf.open(info) as member:
                while True:
                    # one byte past the stated size: a member that expands further is refused, not cut
                    chunk = member.read(min(_CHUNK, left + 1))
                    if not chunk:
                        break
                    left -= len(chunk)
                    if left < 0:
                        raise self._fail(name, "expands beyond the size its header states: refused")
                    yield chunk
        except (zipfile.BadZipFile, zlib.error, EOFError, RuntimeError, NotImplementedError, ValueError,
                OverflowError, struct.error, OSError) as exc:
            if isinstance(exc, InputError):
                raise
            raise self._fail(name, f"cannot be read ({exc}): the file is damaged") from None
        if left:
            raise self._fail(name, "ends before the size its header states: the file is damaged")

    def read(self, name: str) -> bytes:
        return bytes(self.read_into_buffer(name))

    def read_into_buffer(self, name: str) -> bytearray:
        """A member's bytes in one writable buffer of its (checked) stated size."""
        buf = bytearray(self.info(name).file_size)
        pos = 0
        for chunk in self.chunks(name):
            buf[pos:pos + len(chunk)] = chunk
            pos += len(chunk)
        return buf

    def copy(self, name: str, out: BinaryIO) -> int:
        """Write a member into ``out`` chunk by chunk; the number of bytes written."""
        n = 0
        for chunk in self.chunks(name):
            out.write(chunk)
            n += len(chunk)
        return n

    def close(self) -> None:
        zf = getattr(self, "_zf", None)
        if zf is not None:
            zf.close()
        self._fp.close()

    def __enter__(self) -> SafeZip:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def safe_member_name(name: str) -> bool:
    """Whether a zip member name stays inside the folder it is extracted to, on every system.

    >>> [safe_member_name(n) for n in ("media/m_1.bvh", "../x", "/etc/passwd", "C:x", "a\\\\b", "a//b", "a/./b")]
    [True, False, False, False, False, False, False]
    """
    if not name or "\\" in name or ":" in name or "\0" in name or name.startswith("/"):
        return False
    parts = name.rstrip("/").split("/")
    return all(p not in ("", ".", "..") for p in parts)


# ------------------------------------------------------------------------------------------------ npy
@dataclass(frozen=True)
class NpyHeader:
    """What an ``.npy`` header says, checked: ``offset`` is where the data starts, ``nbytes`` its length."""

    shape: tuple[int, ...]
    dtype: np.dtype
    fortran_order: bool
    offset: int
    nbytes: int


def read_npy_header(fp: BinaryIO, size: int, path: str | Path, where: str | None = None,
                    max_bytes: int = NPY_MAX_BYTES, objects: bool = False) -> NpyHeader:
    """Parse the header at the start of ``fp`` (``size`` bytes in all) and check it against ``size``.

    An object dtype (a pickle) is refused, or with ``objects`` returned unchecked (its data is never read:
    :meth:`Npz.is_plain` only needs to tell it apart).
    """

    def fail(problem: str) -> InputError:
        return InputError(path, where, problem)

    head = fp.read(8)
    if len(head) < 8 or not head.startswith(_NPY_MAGIC):
        raise fail(f"not a NumPy .npy array (it starts with {head[:8]!r})")
    major = head[6]
    if major not in (1, 2, 3):
        raise fail(f".npy format version {major}.{head[7]} is not one numpy writes (1, 2 or 3)")
    fmt = "<H" if major == 1 else "<I"
    raw_len = fp.read(struct.calcsize(fmt))
    if len(raw_len) < struct.calcsize(fmt):
        raise fail("the .npy header is cut off: the file is damaged")
    (hlen,) = struct.unpack(fmt, raw_len)
    if hlen > _NPY_MAX_HEADER:
        raise fail(f"the .npy header claims {hlen} bytes; numpy writes well under {_NPY_MAX_HEADER}: refused")
    text = fp.read(hlen)
    if len(text) < hlen:
        raise fail("the .npy header is cut off: the file is damaged")
    try:
        d = ast.literal_eval(text.decode("utf-8" if major == 3 else "latin1"))
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError, UnicodeDecodeError):
        raise fail("the .npy header is not readable: the file is damaged") from None
    if not isinstance(d, dict) or set(d) != {"descr", "fortran_order", "shape"}:
        raise fail("the .npy header does not hold descr, fortran_order and shape: the file is damaged")
    shape, fortran = d["shape"], d["fortran_order"]
    if (not isinstance(shape, tuple) or len(shape) > 32
            or not all(type(n) is int and n >= 0 for n in shape) or type(fortran) is not bool):
        raise fail(f"the .npy header's shape {str(shape)[:60]} is not a tuple of sizes: the file is damaged")
    try:
        dtype = np.lib.format.descr_to_dtype(d["descr"])
    except (TypeError, ValueError, KeyError, IndexError, RecursionError, MemoryError):
        raise fail(f"the .npy header's dtype {str(d['descr'])[:60]} is not a NumPy dtype: the file is damaged") from None
    offset = 8 + struct.calcsize(fmt) + hlen
    if dtype.hasobject:
        if objects:
            return NpyHeader(tuple(shape), dtype, fortran, offset, 0)
        raise fail(_PICKLED)
    if dtype.kind not in _PLAIN_KINDS or dtype.names is not None or dtype.subdtype is not None or not dtype.itemsize:
        raise fail(f"dtype {dtype} is not numbers or text")
    count = 1
    for n in shape:
        count *= n
    nbytes = count * dtype.itemsize
    if nbytes > max_bytes:
        raise fail(f"the header claims a {'x'.join(map(str, shape))} {dtype} array ({human_bytes(nbytes)}); "
                   f"at most {human_bytes(max_bytes)} is read: refused")
    if offset + nbytes != size:
        raise fail(f"the header claims a {'x'.join(map(str, shape))} {dtype} array ({nbytes} bytes) but "
                   f"{max(size - offset, 0)} bytes follow it: the file is damaged or cut off")
    return NpyHeader(tuple(shape), dtype, fortran, offset, nbytes)


def _array_from(buf: bytearray | memoryview, h: NpyHeader) -> np.ndarray:
    a = np.frombuffer(buf, dtype=h.dtype, count=h.nbytes // h.dtype.itemsize if h.dtype.itemsize else 0)
    return a.reshape(h.shape, order="F" if h.fortran_order else "C")


def _read_exact(chunks: Iterator[bytes], n: int) -> bytearray:
    buf = bytearray()
    for c in chunks:
        buf += c
        if len(buf) >= n:
            break
    return buf


def npy_header(path: str | Path, max_bytes: int = NPY_MAX_BYTES) -> NpyHeader:
    """The checked header of an ``.npy`` file (nothing else of it is read)."""
    with _open_file(path) as fp:
        return read_npy_header(fp, os.fstat(fp.fileno()).st_size, path, None, max_bytes)


def load_npy(path: str | Path, max_bytes: int = NPY_MAX_BYTES) -> np.ndarray:
    """The array of an ``.npy`` file, its header checked first (see the module docstring)."""
    with _open_file(path) as fp:
        h = read_npy_header(fp, os.fstat(fp.fileno()).st_size, path, None, max_bytes)
        buf = bytearray(h.nbytes)
        view = memoryview(buf)
        got = 0
        while got < h.nbytes:
            n = fp.readinto(view[got:got + _CHUNK])
            if not n:
                raise InputError(path, None, "the file ended early (it shrank while being read)")
            got += n
    return _array_from(buf, h)


def _open_file(path: str | Path) -> BinaryIO:
    """``path`` opened for reading; only a regular file (a FIFO or device would block or never end)."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            raise InputError(path, None, "not a regular file (a folder, pipe or device)")
        return open(path, "rb")
    except FileNotFoundError:
        raise InputError(path, None, "file not found") from None
    except OSError as exc:
        raise InputError(path, None, f"cannot read the file: {exc.strerror or exc}") from None


# ------------------------------------------------------------------------------------------------ npz
class Npz:
    """The arrays of an ``.npz`` (keys without ``.npy``), each header checked before its data is read.

    Members that are not ``.npy`` are not arrays and are left out of :attr:`files`.
    """

    def __init__(self, path: str | Path, limits: ZipLimits = NPZ_ZIP) -> None:
        self.path = Path(path)
        self._zip = SafeZip(path, limits)
        self._members = {n[:-4]: n for n in self._zip.names if n.endswith(".npy")}
        self._headers: dict[str, NpyHeader] = {}

    @property
    def files(self) -> list[str]:
        return list(self._members)

    def __contains__(self, key: object) -> bool:
        return key in self._members

    def keys(self) -> list[str]:
        return self.files

    def _member(self, key: str) -> str:
        if key not in self._members:
            raise InputError(self.path, f"key {key}", f"no such array; the file has: {', '.join(self.files) or 'nothing'}")
        return self._members[key]

    def header(self, key: str) -> NpyHeader:
        """The checked header of one array (only the member's first bytes are decompressed)."""
        if key not in self._headers:
            name = self._member(key)
            size = self._zip.info(name).file_size
            head = _read_exact(self._zip.chunks(name), min(size, 8 + 4 + _NPY_MAX_HEADER))
            self._headers[key] = read_npy_header(io.BytesIO(bytes(head)), size, self.path, f"key {key}",
                                                 self._zip.limits.max_member_bytes, objects=True)
        return self._headers[key]

    def is_plain(self, key: str) -> bool:
        """Whether ``key`` holds plain data; ``False`` for a pickled object array (which is never read)."""
        return not self.header(key).dtype.hasobject

    def __getitem__(self, key: str) -> np.ndarray:
        h = self.header(key)
        if h.dtype.hasobject:
            raise InputError(self.path, f"key {key}", _PICKLED)
        buf = self._zip.read_into_buffer(self._member(key))
        return _array_from(memoryview(buf)[h.offset:], h)

    def arrays(self, skip_objects: bool = False) -> dict[str, np.ndarray]:
        """Every array; with ``skip_objects``, pickled object members (settings dicts some pipelines add)
        are left out instead of refused."""
        return {k: self[k] for k in self.files if not skip_objects or self.is_plain(k)}

    def close(self) -> None:
        self._zip.close()

    def __enter__(self) -> Npz:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_npz(path: str | Path, limits: ZipLimits = NPZ_ZIP) -> Npz:
    """An ``.npz`` whose zip passed ``limits``; arrays are read (and their headers checked) on access."""
    return Npz(path, limits)


def numpy_kind(path: str | Path) -> str:
    """``"npy"`` or ``"npz"``, from the file's first bytes (not its name); anything else is an InputError."""
    with _open_file(path) as fp:
        head = fp.read(8)
    if not head:
        raise InputError(path, None, "file is empty; expected a NumPy .npy or .npz file")
    if head.startswith(_NPY_MAGIC):
        return "npy"
    if head.startswith((b"PK\x03\x04", b"PK\x05\x06")):
        return "npz"
    raise InputError(path, "header", f"not a NumPy .npy/.npz file (it starts with {head[:8]!r})")


def load_numpy(path: str | Path) -> np.ndarray | Npz:
    """What ``np.load(path, allow_pickle=False)`` returns, read safely: an array for ``.npy``, an :class:`Npz`
    (close it, or use ``with``) for ``.npz``; told apart by :func:`numpy_kind`."""
    return load_npy(path) if numpy_kind(path) == "npy" else open_npz(path)


# ------------------------------------------------------------------------------------------------ fields
_KINDS = {"number": ("biuf", "numbers"), "integer": ("iu", "integers"), "text": ("US", "text")}


def require(arr: np.ndarray, path: str | Path, where: str, kind: str = "number",
            shape: tuple[int | None, ...] | None = None) -> np.ndarray:
    """``arr`` if its dtype is of ``kind`` (``"number"``, ``"integer"`` or ``"text"``) and its shape matches
    ``shape`` (``None`` for any size on that axis; no ``shape``: any), else one :class:`InputError`.

    >>> require(np.zeros((3, 4)), "m.npz", "key rotations", shape=(None, 4)).shape
    (3, 4)
    >>> require(np.array(["a"]), "m.npz", "key parents", "integer")
    Traceback (most recent call last):
    ...
    studyapp.errors.InputError: m.npz, key parents: holds text (dtype <U1, shape (1,)); expected integers
    """
    kinds, what = _KINDS[kind]
    found = "text" if arr.dtype.kind in "US" else "numbers" if arr.dtype.kind in "biuf" else f"dtype {arr.dtype}"
    if arr.dtype.kind not in kinds:
        raise InputError(path, where, f"holds {found} (dtype {arr.dtype}, shape {arr.shape}); expected {what}")
    if shape is not None and (arr.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, arr.shape))):
        want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise InputError(path, where, f"has shape {arr.shape}; expected {want}")
    return arr
