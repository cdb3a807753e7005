"""Remote studies: one zip a participant runs on their own PC, one results file they send back, and merging.

What ``make_bundle`` writes (``STUDY.zip``)::

    manifest.json   format, study name, sha256 of every file, the remote roster (participant id -> row)
    study.toml      the shipped (blinded) design, pointing at the bundled files
    schedule.json   each roster participant's trials, from the real schedule
    media/m_<hex>.* every motion (converted to BVH where needed), audio, face and avatar file, renamed

Blinding: what ``study.toml``, ``schedule.json`` and the media names say is built by
:mod:`studyapp.study.shipped` (read its notes): one opaque stimulus per participant and trial, neutral
condition tokens whose meaning is shuffled per trial, the same keys for every condition, and media names
that never link two clips of one model. The choice made for media: a motion file is named by a salted hash
of (model, clip, sample, bytes) and is shared by every participant's trial that shows it, rather than copied
per participant (which would multiply the zip's size by the roster); audio, face and avatar files are
named by a salted hash of their bytes. Zip entries carry one fixed time stamp. The salt is random per bundle
unless given, and everything is a function of the salt, the design and the roster, so a bundle made again
with the same salt and roster is the same bundle (same ids, same hash). Only roster ids can run a bundle:
another id's trials could not be computed on the participant's PC without telling the models apart.

The mapping back (the *key*) stays with the experimenter, in the experimenter's results database (table
``bundles``) only, so ``studyapp merge`` maps results back to the real condition and stimulus ids and to the
original design hash without extra arguments. No key file is written beside the zip, where it would be easy
to send along by accident; ``bundle --export-key FILE`` or ``studyapp key`` writes one on request (for
``merge --key`` on another machine). A killed ``bundle`` leaves either nothing or the zip with its key
(:func:`_publish`, :func:`settle_pending_keys`): never a ``.part`` file, a key without its zip or a zip
without its key.

On the participant's PC ``studyapp run STUDY.zip`` extracts the bundle to a per-user cache (verifying every
checksum; the bundle is confined to itself, see :func:`open_bundle`, and read within
:data:`~studyapp.safe_io.BUNDLE_ZIP`), stores results in the per-user data folder and, when the participant
finishes, writes ``results-<study>-<participant>-<hash>.zip`` (``results.json`` with that participant's rows + ``manifest.json``
with its sha256) into ``~/studyapp-results`` (a visible folder in the participant's home) and says where.

``merge_results`` imports such files into the experimenter's database, refusing -- with one clear message
per file -- damaged files (checksum), results of another design, and participants already present with other
answers (a file merged before is reported as already merged). The sha256 proves only that a file arrived
intact, since anyone can recompute it: before anything is imported, every answer is checked against the
roster, the schedule recomputed from the design, the ranking rules, plausible timings and the answers of
every other participant (:mod:`studyapp.study.returned`), and a file with any problem imports nothing.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import secrets
import shutil
import sqlite3
import string
import tempfile
import zipfile

import platformdirs
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO, Callable, Iterable

from studyapp import __version__
from studyapp import tomlfile
from studyapp.errors import InputError, StudyappError
from studyapp.safe_io import BUNDLE_ZIP, RESULTS_ZIP, SafeZip, safe_member_name
from studyapp.study.design.schema import BUILTIN_REFERENCE

BUNDLE_FORMAT = "studyapp-bundle"
#: The participants' trials inside a bundle (see :mod:`studyapp.study.shipped`).
SCHEDULE_FILE = "schedule.json"
#: Version 2 keys map each shipped stimulus (a participant's trial) and its tokens back; version 1 keys (the
#: bundles made before) had one opaque id per condition and per stimulus.
KEY_VERSION = 2
RESULTS_FORMAT = "studyapp-results"
FORMAT_VERSION = 1


# ------------------------------------------------------------------------------------------ places
def user_data_dir() -> Path:
    """Per-user data folder (``%APPDATA%\\studyapp``, ``~/Library/Application Support/studyapp``,
    ``$XDG_DATA_HOME/studyapp``), as platformdirs knows it for each system."""
    return Path(platformdirs.user_data_dir("studyapp", appauthor=False, roaming=True))


def user_cache_dir() -> Path:
    """Per-user cache folder (``%LOCALAPPDATA%\\studyapp\\Cache``, ``~/Library/Caches/studyapp``,
    ``$XDG_CACHE_HOME/studyapp``)."""
    return Path(platformdirs.user_cache_dir("studyapp", appauthor=False))


def results_folder() -> Path:
    """Where a remote participant's results file goes: a visible folder in their home."""
    return Path(os.environ.get("STUDYAPP_RESULTS_DIR") or Path.home() / "studyapp-results")


def _sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "-", text).strip("-.") or "study"


# ------------------------------------------------------------------------------------------ making bundles
@dataclass
class BundleInfo:
    """What :func:`make_bundle` wrote."""

    path: Path
    #: where the key was exported (``export_key``), else None: the key is kept in the results database only
    key_path: Path | None
    bundle_hash: str
    #: entries in the zip, manifest.json, schedule.json and study.toml included (what a participant sees when
    #: unzipping)
    n_files: int
    size_bytes: int
    roster: dict[str, int] = field(default_factory=dict)
    #: media files in the zip (``n_files`` less manifest.json, schedule.json and study.toml)
    n_media: int = 0
    #: the key (opaque ids -> real ones), as stored in the results database
    key: dict[str, Any] = field(default_factory=dict)
    #: the design's seed is small enough to be found by trying them all (see :mod:`studyapp.study.shipped`)
    small_seed: bool = False


def make_bundle(
    design_path: str | Path,
    output: str | Path,
    *,
    participants: int = 0,
    results: str | Path | None = None,
    salt: str | None = None,
    export_key: str | Path | None = None,
    upload_url: str | None = None,
) -> BundleInfo:
    """Write ``output`` (a zip) with everything a remote participant needs; see the module docstring.

    ``participants`` (at least 1) pre-assigns Latin-square rows to ids ``R01..RN``, continuing the balance
    of the experimenter's database ``results`` (which also keeps the key); the bundle carries each of those
    participants' trials (:mod:`studyapp.study.shipped`). ``upload_url``: the study server the participants'
    answers are uploaded to as they are committed (:mod:`studyapp.study.upload`); the bundle then carries that
    address and a secret of its own, which the key (in ``results``) keeps too.
    """
    from studyapp.study.design import conditions_named_in, load_design
    from studyapp.study.upload import check_upload_url
    from studyapp.study.schedule import n_rows
    from studyapp.study.shipped import SAFE_SEED, converter, seed_matters, ship_design
    from studyapp.study.storage import ResultsDB

    design_path = Path(design_path)
    output = Path(output)
    if participants < 1:
        raise InputError(None, "--participants", "a bundle carries the trials of each remote participant it is "
                         "made for: give --participants N (the ids R01..RN are handed out)")
    design = load_design(design_path)
    named = conditions_named_in(design, output.name)
    if named:
        raise InputError(output, None, f"the bundle's file name names condition {named[0]!r}, and participants see "
                         "it: that unblinds the study; choose a neutral name (e.g. the study's title)")
    raw = tomlfile.loads(design_path.read_text(encoding="utf-8"))
    salt = salt or secrets.token_hex(16)
    upload = {"url": check_upload_url(upload_url), "secret": secrets.token_hex(32)} if upload_url else None
    results = Path(results) if results is not None else design_path.with_name(f"{design_path.stem}.results.sqlite")
    output.parent.mkdir(parents=True, exist_ok=True)
    db = ResultsDB(results, design)
    try:
        settle_pending_keys(db)
        rows = n_rows(design)
        counts = db.row_counts(rows)
        # ids continue after those already used, so a merge never meets a participant twice
        taken = {r.id for r in db.participants()} | db.issued_remote_ids()
        width = max(2, len(str(participants + len(taken))))
        roster: dict[str, int] = {}
        k = 0
        while len(roster) < participants:
            k += 1
            pid = f"R{k:0{width}d}"
            if pid in taken or any(t.upper() == pid for t in taken):
                continue
            row = counts.index(min(counts))
            counts[row] += 1
            roster[pid] = row

        shipped = ship_design(design, raw, roster, salt, converter(design))
        design_text = tomlfile.dumps(shipped.design)
        schedule_text = json.dumps({"format": "studyapp-bundle-schedule", "rows": rows,
                                    "participants": shipped.schedules}, indent=1, sort_keys=True)
        # The hash the participant's copy will compute: load the shipped design from a scratch folder.
        with tempfile.TemporaryDirectory(prefix="studyapp-bundle-") as tmp:
            tmp_path = Path(tmp)
            for name, data in shipped.media.items():
                (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
                (tmp_path / name).write_bytes(data)
            (tmp_path / "study.toml").write_text(design_text, encoding="utf-8")
            bundle_hash = load_design(tmp_path / "study.toml").design_hash

        # The participant sees this name (cache and results file names): the design's title, which
        # validation already keeps free of condition names, never the experimenter's file name.
        study = _slug(design.title)[:40].strip("-.") or "study"
        key = {
            "format": "studyapp-bundle-key", "version": KEY_VERSION, "study": study, "bundle": output.name,
            "design_hash": design.design_hash, "bundle_hash": bundle_hash, "trials": shipped.trials,
            "files": shipped.origin, "roster": roster, "app_version": __version__,
            **({"upload_secret": upload["secret"]} if upload else {}),
        }
        earlier = db.bundle_key(bundle_hash) or {}

        files = {"study.toml": design_text.encode("utf-8"), SCHEDULE_FILE: schedule_text.encode("utf-8"),
                 **shipped.media}
        manifest = {
            "format": BUNDLE_FORMAT, "version": FORMAT_VERSION, "study": study, "title": design.title,
            "design": "study.toml", "design_hash": bundle_hash, "app_version": __version__,
            "roster": roster, "files": {name: _sha256_bytes(data) for name, data in sorted(files.items())},
            **({"upload": upload} if upload else {}),
        }

        def write_zip(fh: BinaryIO) -> None:
            with zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_DEFLATED) as zf:
                zf.writestr(_entry("manifest.json"), json.dumps(manifest, indent=2, sort_keys=True))
                for name, data in sorted(files.items()):
                    zf.writestr(_entry(name), data)

        def record_pending(digest: str) -> None:
            if earlier and not isinstance(earlier.get("pending"), dict):
                # this very bundle was completed before (and may have been sent): its key stays complete
                db.add_bundle_key(bundle_hash, key)
            else:
                db.add_bundle_key(bundle_hash, {**key, "pending": {"path": str(output.resolve()), "sha256": digest}})

        _publish(output, write_zip, record_pending)
        db.add_bundle_key(bundle_hash, key)  # the zip is in place: the key is complete
    finally:
        db.close()
    key_path = None
    if export_key is not None:
        key_path = write_key_file(key, export_key)
    # Counted from the zip as written, so the number reported can never drift from what is inside again.
    with zipfile.ZipFile(output) as zf:
        entries = zf.namelist()
    return BundleInfo(path=output, key_path=key_path, bundle_hash=bundle_hash, n_files=len(entries),
                      size_bytes=output.stat().st_size, roster=roster,
                      n_media=sum(n.startswith("media/") for n in entries), key=key,
                      small_seed=seed_matters(design) and design.seed < SAFE_SEED)


def _entry(name: str) -> zipfile.ZipInfo:
    """A zip entry that tells nothing but its name: a fixed time stamp and the same attributes for all."""
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.compress_type = zipfile.ZIP_DEFLATED
    info.external_attr = 0o644 << 16
    return info


# ------------------------------------------------------------------------------------------ the key, atomically
def _write_synced(fh: BinaryIO, write: Callable[[BinaryIO], None]) -> str:
    """Write the zip into ``fh``, make it durable, and return its sha256 (read back from the disk's copy)."""
    write(fh)
    fh.flush()
    os.fsync(fh.fileno())
    fh.seek(0)
    return _sha256_stream(fh)


def _publish(output: Path, write: Callable[[BinaryIO], None], record_pending: Callable[[str], None]) -> None:
    """Write ``output`` so that a kill at any moment leaves either the old state or the finished zip with
    its key (see :func:`settle_pending_keys`), and never a half-written file beside it.

    The zip is written into an anonymous file in the output's folder (Linux ``O_TMPFILE``: it has no name,
    so a killed process leaves nothing), fsynced, its key recorded as *pending* (naming the zip's path and
    sha256), and only then linked into place: the link is the moment the bundle exists. Where anonymous
    files are not available (macOS, Windows, some file systems) the zip goes to ``<output>.part`` and is
    renamed into place; a ``.part`` left by a killed run is removed by the next ``bundle`` of that output.
    """
    folder = output.parent
    fd = -1
    if hasattr(os, "O_TMPFILE") and Path("/proc/self/fd").is_dir():
        try:
            fd = os.open(folder, os.O_TMPFILE | os.O_RDWR, 0o644)
        except OSError:
            fd = -1  # the file system has no anonymous files: fall back to a named .part
    if fd >= 0:
        with os.fdopen(fd, "w+b") as fh:
            record_pending(_write_synced(fh, write))
            # A link cannot replace: an older bundle of the same name goes first. A kill in between leaves
            # no zip and a pending key without its zip, which counts as never made.
            output.unlink(missing_ok=True)
            # a directory fd makes Python call linkat(AT_SYMLINK_FOLLOW), which links the file behind the
            # /proc entry (plain link() would try to link the /proc symlink itself)
            dir_fd = os.open(folder, os.O_RDONLY)
            try:
                os.link(f"/proc/self/fd/{fh.fileno()}", output, src_dir_fd=dir_fd, follow_symlinks=True)
            finally:
                os.close(dir_fd)
    else:
        part = output.with_name(output.name + ".part")
        with open(part, "w+b") as fh:
            digest = _write_synced(fh, write)
        record_pending(digest)
        os.replace(part, output)
    _fsync_dir(folder)


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return  # Windows cannot open folders; its renames are durable enough for this
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _sha256_stream(fh: BinaryIO) -> str:
    h = hashlib.sha256()
    for chunk in iter(lambda: fh.read(1 << 20), b""):
        h.update(chunk)
    return h.hexdigest()


def settle_pending_keys(db: Any) -> list[str]:
    """Finish or forget keys that a killed ``bundle`` left *pending*; returns the hashes forgotten.

    A pending key whose zip is at its path with its sha256 belongs to a bundle that was completed (the
    run was killed after linking the zip): it is kept, and marked complete. Any other pending key belongs to
    a bundle that never came to exist and is removed, so its roster ids are free again. A ``.part`` file a
    killed run left (only where anonymous files are not available) is removed too.
    """
    forgotten = []
    for h, key in db.bundle_keys().items():
        pending = key.get("pending")
        if not isinstance(pending, dict):
            continue
        path = Path(str(pending.get("path", "")))
        Path(f"{path}.part").unlink(missing_ok=True)
        try:
            done = path.is_file() and _sha256_file(path) == pending.get("sha256")
        except OSError:
            done = False
        if done:
            db.add_bundle_key(h, {k: v for k, v in key.items() if k != "pending"})
        else:
            db.remove_bundle_key(h)
            forgotten.append(h)
    return forgotten


def write_key_file(key: dict[str, Any], path: str | Path) -> Path:
    """Write a bundle key (JSON) for ``merge --key`` on another machine; created private (mode 0600)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = json.dumps({k: v for k, v in key.items() if k != "pending"}, indent=2, sort_keys=True).encode("utf-8")
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


def export_key(results: str | Path, bundle: str | Path, path: str | Path) -> Path:
    """Write the key of ``bundle`` (a bundle zip, or its hash or a prefix of it) kept in the experimenter's
    database ``results`` to ``path``."""
    from studyapp.study.storage import ResultsDB

    db = ResultsDB(results, create=False)
    try:
        keys = {h: k for h, k in db.bundle_keys().items() if not isinstance(k.get("pending"), dict)}
    finally:
        db.close()
    wanted = str(bundle)
    if Path(wanted).suffix.lower() == ".zip":
        try:
            with zipfile.ZipFile(wanted) as zf:
                wanted = str(json.loads(zf.read("manifest.json"))["design_hash"])
        except (OSError, zipfile.BadZipFile, KeyError, ValueError, TypeError) as exc:
            raise InputError(bundle, "manifest.json", f"not a readable study bundle ({exc})") from None
    found = [h for h in keys if h.startswith(wanted)] if wanted else []
    if len(found) != 1:
        known = ", ".join(f"{h[:12]} ({keys[h].get('bundle', '?')})" for h in sorted(keys)) or "none"
        raise InputError(results, "bundles", f"{'no' if not found else 'more than one'} bundle key matches "
                         f"{str(bundle)!r}; the keys kept here are: {known}")
    return write_key_file(keys[found[0]], path)


# ------------------------------------------------------------------------------------------ opening bundles
@dataclass
class OpenedBundle:
    """A verified, extracted bundle on the participant's PC."""

    zip_path: Path
    folder: Path
    design_path: Path
    study: str
    bundle_hash: str
    roster: dict[str, int]
    default_results: Path
    results_dir: Path
    #: the study server's address and this bundle's upload secret (``bundle --upload-url``), else None
    upload: dict[str, str] | None = None


#: the largest manifest.json read (a bundle's lists a sha256 per file: 20,000 files are about 2 MB)
_MANIFEST_MAX_BYTES = 16 << 20


def open_bundle(zip_path: str | Path, cache: str | Path | None = None) -> OpenedBundle:
    """Verify ``zip_path`` against its manifest and extract it to the per-user cache (reused when intact).

    Everything is checked before any member is extracted and before any path in the bundle's design is
    followed: the zip passes :data:`~studyapp.safe_io.BUNDLE_ZIP` (member count, sizes, compression ratio), its
    members are exactly ``manifest.json`` and the files the manifest lists (a file in the zip that the
    manifest does not list is refused, as is one it lists that is missing), the manifest's ``design`` entry is
    one of them, and every file the design names resolves to a file of the manifest (:func:`_confine`), so a
    bundle cannot make the participant's app open a file anywhere else on their disk. Members are extracted in
    chunks, each checked against its sha256.
    """
    zip_path = Path(zip_path)
    if not zip_path.is_file():
        raise InputError(zip_path, None, "study bundle not found; check the path")
    try:
        return _open_bundle(zip_path, cache)
    except InputError as exc:
        if "damaged" not in exc.problem:
            raise
        raise InputError(exc.path, exc.where, f"{exc.problem}; ask the experimenter for the file again") from None


def _open_bundle(zip_path: Path, cache: str | Path | None) -> OpenedBundle:
    with SafeZip(zip_path, BUNDLE_ZIP) as zf:
        manifest = _bundle_manifest(zip_path, zf)
        files: dict[str, str] = manifest["files"]
        design_name = manifest["design"]
        design_bytes = zf.read(design_name)
        if _sha256_bytes(design_bytes) != files[design_name]:
            raise InputError(zip_path, design_name, "checksum mismatch: the bundle is damaged")
        _confine(zip_path, design_name, design_bytes, files)
        zip_digest = _sha256_file(zip_path)[:16]
        folder = Path(cache) if cache is not None else user_cache_dir() / "bundles" / f"{_slug(manifest['study'])}-{zip_digest}"
        if not _verify_folder(folder, files):
            tmp = Path(tempfile.mkdtemp(prefix=".extract-", dir=_mkdir(folder.parent)))
            try:
                for name, digest in files.items():
                    target = tmp / name
                    target.parent.mkdir(parents=True, exist_ok=True)
                    h = hashlib.sha256()
                    with open(target, "wb") as out:
                        for chunk in zf.chunks(name):
                            h.update(chunk)
                            out.write(chunk)
                    if h.hexdigest() != digest:
                        raise InputError(zip_path, name, "checksum mismatch: the bundle is damaged")
                if folder.exists() or folder.is_symlink():
                    if folder.is_symlink() or not folder.is_dir():
                        folder.unlink()
                    else:
                        shutil.rmtree(folder)
                os.replace(tmp, folder)
            finally:
                if tmp.exists():
                    shutil.rmtree(tmp, ignore_errors=True)
    study = _slug(manifest["study"])
    return OpenedBundle(
        zip_path=zip_path, folder=folder, design_path=folder / design_name, study=study,
        bundle_hash=manifest["design_hash"], roster=manifest["roster"],
        default_results=user_data_dir() / "studies" / f"{study}-{manifest['design_hash'][:12]}.results.sqlite",
        results_dir=results_folder(), upload=manifest.get("upload"),
    )


def _read_manifest(path: Path, zf: SafeZip) -> Any:
    """``manifest.json`` of a zip, parsed (size checked before it is read)."""
    if "manifest.json" not in zf.names:
        raise InputError(path, "manifest.json", "missing: this is not a studyapp file")
    if zf.info("manifest.json").file_size > _MANIFEST_MAX_BYTES:
        raise InputError(path, "manifest.json", f"larger than {_MANIFEST_MAX_BYTES >> 20} MB: not a studyapp manifest")
    try:
        return json.loads(zf.read("manifest.json"))
    except (ValueError, RecursionError):
        raise InputError(path, "manifest.json", "unreadable (not JSON): the file is damaged") from None


def _bundle_manifest(path: Path, zf: SafeZip) -> dict[str, Any]:
    """The bundle's manifest, every field checked, and the zip's members checked against its file list."""
    try:
        manifest = _read_manifest(path, zf)
    except InputError as exc:
        raise InputError(path, exc.where, f"{exc.problem}; this is not a studyapp study bundle") from None
    if not isinstance(manifest, dict) or manifest.get("format") != BUNDLE_FORMAT:
        raise InputError(path, "manifest.json", "not a studyapp study bundle")
    files, design, roster = manifest.get("files"), manifest.get("design", "study.toml"), manifest.get("roster", {})
    if not isinstance(files, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in files.items()):
        raise InputError(path, "manifest.json", "its `files` is not a table of file names and checksums: damaged")
    bad = [n for n in files if not safe_member_name(n)]
    if bad:
        raise InputError(path, "manifest.json", f"unsafe file names in the bundle: {bad[:3]}")
    in_zip = set(zf.names) - {"manifest.json"}
    unlisted = sorted(in_zip - set(files))
    if unlisted:
        raise InputError(path, unlisted[0], "in the zip but not in its manifest, so nothing vouches for it: refused")
    missing = sorted(set(files) - in_zip)
    if missing:
        raise InputError(path, missing[0], "listed in the manifest but missing from the zip: the bundle is damaged")
    if not isinstance(design, str) or design not in files or not design.endswith(".toml"):
        raise InputError(path, "manifest.json", f"its design entry {str(design)[:80]!r} is not one of the bundle's "
                         ".toml files: refused")
    if not isinstance(manifest.get("study"), str) or not isinstance(manifest.get("design_hash"), str):
        raise InputError(path, "manifest.json", "no study name or design hash: damaged")
    if not isinstance(roster, dict) or not all(isinstance(k, str) and type(v) is int and v >= 0
                                               for k, v in roster.items()):
        raise InputError(path, "manifest.json", "its roster is not participant ids with their rows: damaged")
    upload = manifest.get("upload")
    if upload is not None and not (isinstance(upload, dict) and isinstance(upload.get("url"), str)
                                   and isinstance(upload.get("secret"), str) and len(upload["secret"]) >= 32):
        raise InputError(path, "manifest.json", "its `upload` entry is not a server address with a secret: damaged")
    return {**manifest, "design": design, "roster": roster}


def _confine(path: Path, design_name: str, design_bytes: bytes, files: dict[str, str]) -> None:
    """Refuse a bundled design that names any file other than one its manifest lists (read nothing else).

    Paths are compared as written: ``media/x.bvh`` is in the bundle only when the manifest lists exactly
    that name, so absolute paths, ``..``, ``~``, drive letters, backslashes and links out of the folder
    never match; a motion pattern is filled in for every stimulus and sample first (refusing format
    specifications and attribute or index lookups, which ``str.format`` would run).
    """
    try:
        raw = tomlfile.loads(design_bytes.decode("utf-8"))
    except (UnicodeDecodeError, tomlfile.TOMLDecodeError, RecursionError, ValueError) as exc:
        raise InputError(path, design_name, f"not a readable design ({exc}): the bundle is damaged") from None
    try:
        named = bundle_design_paths(raw, len(files))
    except InputError as exc:
        raise InputError(path, f"{design_name}, {exc.where}", exc.problem) from None
    for key, value in named:
        if value in files:
            continue
        outside = (value.startswith(("/", "\\", "~")) or "\\" in value or ":" in value
                   or ".." in value.replace("\\", "/").split("/"))
        raise InputError(path, f"{design_name}, {key}", f"{value[:120]!r} " + (
            "points outside the bundle: refused (a bundle may only use its own files)" if outside else
            "is not a file of the bundle's manifest: refused (a bundle may only use the files it lists)"))


def bundle_design_paths(raw: dict[str, Any], max_samples: int) -> list[tuple[str, str]]:
    """``(key, path as written)`` for every file a (raw, parsed TOML) design names, keyed as
    :func:`~studyapp.study.design.referenced_files` keys them; motion patterns filled in for every stimulus and
    sample that sets the pattern's tags. A shipped trial tags only the tokens it plays (see
    :mod:`studyapp.study.shipped`), so a stimulus without a tag names no file of that condition; should the
    design still need one, it has no path to follow (the design check reports the missing tag). This is a
    superset of what the design package resolves, which is what confinement needs. Raises
    :class:`InputError` for a pattern that cannot be filled safely."""
    from studyapp.study.design.files import fill_sample, motion_key

    def strs(table: Any) -> dict[str, Any]:
        return table if isinstance(table, dict) else {}

    def rows(key: str) -> list[dict[str, Any]]:
        v = raw.get(key)
        return [e for e in v if isinstance(e, dict)] if isinstance(v, list) else []

    out: list[tuple[str, str]] = []
    stimuli = rows("stimuli")
    for i, s in enumerate(stimuli):
        for k in ("audio", "face", "head"):
            if isinstance(s.get(k), str):
                out.append((f"stimuli[{i}].{k}", s[k]))
    for i, c in enumerate(rows("conditions")):
        if isinstance(c.get("model"), str) and c["model"] != BUILTIN_REFERENCE:
            out.append((f"conditions[{i}].model", c["model"]))
        for k in ("template", "body_model"):
            if isinstance(c.get(k), str):
                out.append((f"conditions[{i}].{k}", c[k]))
        pattern = c.get("motion")
        if not isinstance(pattern, str):
            continue
        samples = c.get("samples", 1)
        samples = samples if type(samples) is int and samples >= 1 else 1
        if samples > max(max_samples, 1):
            raise InputError(None, f"conditions[{i}].samples", f"{samples} samples, more than the bundle has files")
        for s in stimuli:
            sid = s.get("id")
            fields = {k: v for k, v in strs(s.get("tags")).items() if isinstance(v, str)}
            fields["stimulus"] = sid if isinstance(sid, str) else ""
            for k in range(1, samples + 1):
                filled = _fill_pattern(fill_sample(pattern, k), fields, f"conditions[{i}].motion")
                if filled is not None:
                    out.append((motion_key(i, fields["stimulus"], k, samples), filled))
    avatar = strs(raw.get("avatar"))
    if isinstance(avatar.get("model"), str) and avatar["model"] != "builtin":
        out.append(("avatar.model", avatar["model"]))
    for k, v in strs(avatar.get("by_speaker")).items():
        if isinstance(v, str) and v != "builtin":
            out.append((f"avatar.by_speaker.{k}", v))
    return out


def _fill_pattern(pattern: str, fields: dict[str, str], key: str) -> str | None:
    """``pattern`` with each ``{name}`` replaced by ``fields[name]``; nothing else of ``str.format`` is run.
    None when a bare ``{name}`` is not one of ``fields`` (the stimulus names no such file).

    >>> _fill_pattern("media/m_{c_ab}.bvh", {"c_ab": "12", "stimulus": "s"}, "k")
    'media/m_12.bvh'
    >>> _fill_pattern("media/m_{x3}.bvh", {"stimulus": "s"}, "k") is None
    True
    >>> _fill_pattern("{stimulus:>99999999}", {"stimulus": "s"}, "k")
    Traceback (most recent call last):
    ...
    studyapp.errors.InputError: k: the pattern's placeholder {stimulus:>99999999} is not a plain {name}: refused
    """
    out = []
    try:
        parsed = list(string.Formatter().parse(pattern))
    except ValueError as exc:
        raise InputError(None, key, f"the pattern {pattern[:80]!r} cannot be read ({exc})") from None
    for literal, name, spec, conv in parsed:
        out.append(literal)
        if name is None:
            continue
        if spec or conv:
            shown = "{" + name + (f"!{conv}" if conv else "") + (f":{spec}" if spec else "") + "}"
            raise InputError(None, key, f"the pattern's placeholder {shown[:80]} is not a plain {{name}}: refused")
        if name not in fields:
            if name.isidentifier():
                return None
            raise InputError(None, key, f"the pattern uses {{{name[:80]}}}, which a stimulus does not set: refused")
        out.append(fields[name])
    return "".join(out)


def _mkdir(p: Path) -> Path:
    p.mkdir(parents=True, exist_ok=True)
    return p


def _verify_folder(folder: Path, files: dict[str, str]) -> bool:
    """Whether an earlier extraction in ``folder`` is intact: every file there, none a link, every checksum right."""
    if not folder.is_dir() or folder.is_symlink():
        return False
    try:
        for name, digest in files.items():
            p = folder
            for part in name.split("/"):
                p = p / part
                if p.is_symlink():
                    return False
            if not p.is_file() or _sha256_file(p) != digest:
                return False
        return True
    except OSError:
        return False


def remote_row(design: Any, opened: OpenedBundle, participant_id: str) -> int:
    """Latin-square row of a remote participant: from the bundle's roster, else derived from the id."""
    if participant_id in opened.roster:
        return opened.roster[participant_id]
    from studyapp.study.schedule import default_row

    return int(default_row(design, participant_id))


@dataclass(frozen=True)
class RemotePlan:
    """A roster participant's trials as the bundle carries them (see :mod:`studyapp.study.shipped`)."""

    row: int
    #: the design's row count, for registering the participant on their row
    n_rows: int
    plans: list[Any]


def remote_plan(opened: OpenedBundle, participant_id: str) -> RemotePlan | None:
    """The trials the bundle carries for ``participant_id``; None for a bundle made before bundles carried
    them (its design computes the schedule). An id the bundle was not made for is refused: its trials
    cannot be computed on the participant's PC without telling the models apart."""
    from studyapp.study.schedule import TrialPlan

    path = opened.folder / SCHEDULE_FILE
    if not path.is_file():
        return None
    where = f"{opened.zip_path.name}:{SCHEDULE_FILE}"
    def unreadable(exc: Exception) -> InputError:
        return InputError(where, None, f"the participants' trials cannot be read ({exc}); ask the experimenter "
                          "for the file again")

    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        people = data["participants"]
        known = participant_id in people
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise unreadable(exc) from None
    if not known:  # outside the try: InputError is a ValueError, and this one is the participant's, not the file's
        raise InputError(None, "--participant", f"{participant_id!r} is not one of the participant ids this "
                         f"study file was made for; use the id your experimenter gave you (this file has "
                         f"{', '.join(sorted(map(str, people))) or 'none'})")
    try:
        mine = people[participant_id]
        row, rows = int(mine["row"]), int(data["rows"])
        # a trial is [stimulus, slots, practice, check] and, since the response paradigms, {block, paradigm}
        plans = [TrialPlan(i, str(t[0]), tuple(str(c) for c in t[1]), bool(t[2]), bool(t[3]), row,
                           (1,) * len(t[1]), *((str(t[4]["block"]), str(t[4]["paradigm"])) if len(t) > 4
                                               else ("main", "rank")))
                 for i, t in enumerate(mine["trials"])]
        if any(len(p.slots) not in (2, 3, 4) for p in plans):
            raise ValueError("a trial with a number of slots no paradigm shows")
    except (ValueError, KeyError, TypeError, IndexError) as exc:
        raise unreadable(exc) from None
    return RemotePlan(row=row, n_rows=rows, plans=plans)


# ------------------------------------------------------------------------------------------ results files
def _participant_rows(db: Any, pid: str) -> dict[str, list[dict[str, Any]]]:
    con = db.connection
    rows = {}
    for table in ("participants", "sessions", "trials", "trial_slots", "responses", "judgements", "plays",
                  "questionnaire"):
        col = "id" if table == "participants" else "participant"
        rows[table] = [dict(r) for r in con.execute(f"SELECT * FROM {table} WHERE {col} = ?", (pid,))]
    return rows


def _answer_key(trial: dict[str, Any]) -> tuple[Any, ...]:
    """What identifies one answered trial across two exports of the same participant."""
    return trial.get("trial_index"), trial.get("stimulus"), trial.get("answered_at")


def _has_criteria(db: Any) -> bool:
    """Whether the database records its criteria (schema 7; a file read as it is may be older)."""
    return db.connection.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'criteria'"
                                 ).fetchone() is not None


def results_payload(db: Any, participant_id: str, study: str) -> dict[str, Any]:
    """What ``results.json`` holds for one participant (also what an upload carries, :mod:`studyapp.study.upload`);
    ``db``: anything with the results ``connection`` and its ``design_hash``."""
    return {
        "format": RESULTS_FORMAT, "version": FORMAT_VERSION, "study": study, "design_hash": db.design_hash,
        "app_version": __version__, "participant": participant_id,
        "stimuli": [dict(r) for r in db.connection.execute("SELECT * FROM stimuli")],
        # the criteria's labels (schema 7), checked against the design when merged (studyapp.study.returned)
        **({"criteria": [{k: r[k] for k in ("id", "position", "label", "question")}
                         for r in db.connection.execute("SELECT * FROM criteria ORDER BY position")]}
           if _has_criteria(db) else {}),
        **_participant_rows(db, participant_id),
    }


def write_results_file(db: Any, participant_id: str, out_dir: str | Path, opened: OpenedBundle | None = None) -> Path:
    """Pack one participant's rows as ``results-<study>-<participant>-<hash>.zip`` (``results.json`` + manifest).

    ``<participant>`` is the id made file-name safe and ``<hash>`` the first 8 hex digits of the sha256 of
    the exact id, so ids that sanitize alike (``p/1`` and ``p-1``) or differ only in case (``A`` and ``a``,
    one file on Windows and macOS) get different files. An existing file is replaced only when it is this
    participant's own results file of this design and every answer in it is in the new one (a resumed
    session); any other file there is kept and the new one gets ``-2``, ``-3``, ... added to its name.
    """
    study = opened.study if opened is not None else _slug(db.title)
    payload = results_payload(db, participant_id, study)
    data = json.dumps(payload, indent=1, sort_keys=True, default=str).encode("utf-8")
    manifest = {"format": RESULTS_FORMAT, "version": FORMAT_VERSION, "participant": participant_id, "study": study,
                "design_hash": db.design_hash, "files": {"results.json": _sha256_bytes(data)}}
    out_dir = _mkdir(Path(out_dir))
    stem = f"results-{study}-{_slug(participant_id)}-{_sha256_bytes(participant_id.encode('utf-8'))[:8]}"
    path, k = out_dir / f"{stem}.zip", 1
    answered = {_answer_key(t) for t in payload["trials"]}
    while path.exists():
        try:
            with SafeZip(path, RESULTS_ZIP) as zf:
                old = _read_manifest(path, zf)
                if (old.get("format"), old.get("participant"), old.get("design_hash")) == (
                        RESULTS_FORMAT, participant_id, db.design_hash):
                    before = {_answer_key(t) for t in json.loads(zf.read("results.json")).get("trials", [])}
                    if before <= answered:
                        break  # this participant's own earlier file (ended early, then resumed): update it
                    # else a run from a reset local database: the earlier answers may not have been sent yet
        except (InputError, ValueError, RecursionError, AttributeError, TypeError):
            pass  # not a results file we wrote: keep it
        k += 1
        path = out_dir / f"{stem}-{k}.zip"
    tmp = path.with_name(path.name + ".part")
    with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("results.json", data)
        zf.writestr("manifest.json", json.dumps(manifest, indent=2, sort_keys=True))
    os.replace(tmp, path)
    return path


# ------------------------------------------------------------------------------------------ merging
@dataclass
class MergeReport:
    """What merging one file did: imported (``ok``), merged before (``ok`` and ``already``), or refused."""

    file: Path
    ok: bool
    message: str
    participant: str | None = None
    #: a refused file's problems, one line each (``where: what``); nothing of the file was imported
    problems: list[str] = field(default_factory=list)
    #: the file's answers are in the database already (merged before): nothing to do, not an error
    already: bool = False


class _Refused(StudyappError):
    """A returned file failed the checks of :mod:`studyapp.study.returned`."""

    def __init__(self, problems: list[str]) -> None:
        self.problems = problems
        n = len(problems)
        super().__init__(f"{n} problem{'s' if n != 1 else ''} in the answers; nothing of this file was imported")


def _read_results_file(path: Path) -> dict[str, Any]:
    """The payload of a returned results file, its zip within :data:`~studyapp.safe_io.RESULTS_ZIP` and its
    checksum right (which proves only that it arrived as written: the answers are checked afterwards)."""
    if not path.is_file():
        raise InputError(path, None, "file not found")
    try:
        with SafeZip(path, RESULTS_ZIP) as zf:
            manifest = _read_manifest(path, zf)
            if isinstance(manifest, dict) and manifest.get("format") == BUNDLE_FORMAT:
                raise InputError(path, None, _BUNDLE_GIVEN)
            data = zf.read("results.json")
    except InputError as exc:
        if exc.problem != _BUNDLE_GIVEN and _is_bundle(path):  # too big for a results file: say what it is
            raise InputError(path, None, _BUNDLE_GIVEN) from None
        # the member named in the problem: the merge report shows only the problem
        where = f"{exc.where}: " if exc.where else ""
        damaged = "damaged" in exc.problem or "not a readable" in exc.problem
        raise InputError(path, None, f"{where}{exc.problem}" + ("; ask the participant to send it again"
                                                                 if damaged else "")) from None
    if not isinstance(manifest, dict) or manifest.get("format") != RESULTS_FORMAT:
        raise InputError(path, "manifest.json", "not a studyapp results file")
    files = manifest.get("files")
    if not isinstance(files, dict) or _sha256_bytes(data) != files.get("results.json"):
        raise InputError(path, "results.json", "checksum mismatch: the file was damaged or edited; ask the "
                         "participant to send the original again")
    try:
        payload = json.loads(data)
    except (ValueError, RecursionError) as exc:
        raise InputError(path, "results.json", f"not valid JSON ({str(exc)[:120]})") from None
    if not isinstance(payload, dict) or payload.get("design_hash") != manifest.get("design_hash"):
        raise InputError(path, "results.json", "the manifest and the results disagree on the design")
    return payload


_BUNDLE_GIVEN = ("this is a study bundle (the file participants run), not a results file; merge the "
                 "results-*.zip files that participants send back")


def _is_bundle(path: Path) -> bool:
    """Whether ``path`` is a study bundle (read only as far as its manifest)."""
    try:
        with SafeZip(path, BUNDLE_ZIP) as zf:
            manifest = _read_manifest(path, zf)
    except InputError:
        return False
    return isinstance(manifest, dict) and manifest.get("format") == BUNDLE_FORMAT


def _merge_design(db: Any, db_path: Path | str, design_path: str | Path | None) -> Any:
    """The study design the database was made for, to recompute every returned participant's schedule:
    ``design_path``, else ``<name>.toml`` next to ``<name>.results.sqlite`` (where ``run`` and ``bundle`` put it)."""
    from studyapp.study.design import load_design_of

    if design_path is None:
        name = db_path.name if isinstance(db_path, Path) else ""  # a server database (URL) has no design beside it
        guess = db_path.with_name(name[: -len(".results.sqlite")] + ".toml") \
            if isinstance(db_path, Path) and name.endswith(".results.sqlite") else None
        if guess is None or not guess.is_file():
            raise InputError(db_path, None, "merge checks every returned answer against the study's schedule and "
                             "needs the design: give it with --design STUDY.toml" +
                             (f" (it is not at {guess})" if guess is not None else ""))
        design_path = guess
    return load_design_of(design_path, db.design_hash)


@dataclass
class _Returned:
    """A readable results file with the real ids in it, ready for the checks."""

    payload: dict[str, Any]
    pid: Any
    roster: dict[str, int] | None  # None: the lab's own design, no roster
    id_findings: list[Any]
    remote: bool


def merge_results(db_path: str | Path, files: Iterable[str | Path], *, key_file: str | Path | None = None,
                  design: str | Path | None = None, allow_unlisted: bool = False) -> list[MergeReport]:
    """Import results files into the experimenter's database; one :class:`MergeReport` per file.

    Every file is checked first (:mod:`studyapp.study.returned`: roster, schedule, rankings, timings,
    copies of another participant's answers, here or in another file of ``files``); a file with any problem
    imports nothing. ``design``: the study's design (default: next to the database, see :func:`_merge_design`).
    """
    from studyapp.study.storage import ResultsDB

    extra_keys: dict[str, dict] = {}
    if key_file is not None:
        try:
            k = json.loads(Path(key_file).read_text(encoding="utf-8"))
            extra_keys[k["bundle_hash"]] = k
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(key_file, None, f"not a bundle key file ({exc})") from None
    db = ResultsDB(db_path, create=False)
    reports = []
    try:
        lab = _merge_design(db, db.path, design)
        db.store_design_metadata(lab)  # an upgraded database gains the design's labels (e.g. of its criteria)
        read: list[tuple[Path, _Returned | MergeReport]] = []
        for f in map(Path, files):
            read.append((f, _guarded(f, lambda: _prepare(db, f, extra_keys))))
        batch: dict[str, list[dict[str, Any]]] = {}
        for _, got in read:
            if isinstance(got, _Returned) and isinstance(got.pid, str):
                batch.setdefault(got.pid, got.payload["trials"])
        for f, got in read:
            if isinstance(got, MergeReport):
                reports.append(got)
                continue
            reports.append(_guarded(f, lambda: _merge_one(db, lab, f, got, batch, allow_unlisted)))
    finally:
        db.close()
    return reports


def _guarded(f: Path, step: Callable[[], Any]) -> Any:
    """``step()``, or a refusal report for the errors a malformed file raises (nothing of it is kept)."""
    try:
        return step()
    except _Refused as exc:
        return MergeReport(f, False, str(exc), problems=exc.problems)
    except StudyappError as exc:
        return MergeReport(f, False, getattr(exc, "problem", str(exc)))
    except (KeyError, TypeError, ValueError, AttributeError, IndexError, sqlite3.Error) as exc:
        # A file whose checksum matches but whose tables lack fields was not written by studyapp
        # (or by an incompatible version); the transaction rolled back, so nothing of it was kept.
        return MergeReport(f, False, f"results.json is not in the studyapp results layout "
                           f"({type(exc).__name__}: {exc}); it was not imported")


def _prepare(db: Any, path: Path, extra_keys: dict[str, dict]) -> _Returned:
    from studyapp.study.returned import map_ids

    payload = _read_results_file(path)
    h = payload["design_hash"]
    if h == db.design_hash:
        key: dict[str, Any] = {"conditions": {}, "stimuli": {}, "bundle_hash": h}
    else:
        key = db.bundle_key(h) or extra_keys.get(h)
        if key is None or key.get("design_hash") != db.design_hash:
            raise StudyappError(f"results of another design (hash {h[:12]}…): this database is for {db.title!r} "
                                f"(hash {db.design_hash[:12]}…) and knows no bundle with that hash. Merge it into the "
                                "database of its own study, or pass that bundle's --key file")
    remote = key.get("bundle_hash") != db.design_hash
    mapped, findings = map_ids(payload, key.get("conditions", {}), key.get("stimuli", {}), strict=remote,
                               trials=key.get("trials"))
    parts = payload["participants"]
    if len(parts) != 1:
        raise StudyappError(f"expected one participant in the file, found {len(parts)}")
    roster = {str(k): int(v) for k, v in key.get("roster", {}).items()} if remote else None
    return _Returned(mapped, parts[0]["id"], roster, findings, remote)


def _same_as_stored(db: Any, pid: str, payload: dict[str, Any]) -> bool:
    """The file's answers are exactly those stored for ``pid`` (the file was merged before)."""
    def trials(rows: Iterable[dict[str, Any]]) -> set[tuple[Any, ...]]:
        return {(t["trial_index"], t["stimulus"], t["answered_at"]) for t in rows}

    def ranks(rows: Iterable[dict[str, Any]]) -> set[tuple[Any, ...]]:
        return {(r["trial_index"], r["criterion"], r["slot"], r["condition"], float(r["rank"])) for r in rows}

    def judged(rows: Iterable[dict[str, Any]]) -> set[tuple[Any, ...]]:
        return {(r["trial_index"], r["criterion"], r["slot"], r["condition"], float(r["value"]), r["reasons"])
                for r in rows}

    return (trials(db.trials(pid)) == trials(payload["trials"])
            and ranks(db.responses(pid)) == ranks(payload["responses"])
            and judged(db.judgements(pid)) == judged(payload.get("judgements", [])))


def _merge_one(db: Any, design: Any, path: Path, got: _Returned, batch: dict[str, list[dict[str, Any]]],
               allow_unlisted: bool) -> MergeReport:
    from studyapp.study.returned import check_returned
    from studyapp.study.session import trial_duration_s

    payload, pid = got.payload, got.pid
    if isinstance(pid, str) and db.participant(pid) is not None:
        if _same_as_stored(db, pid, payload):
            return MergeReport(path, True, f"participant {pid}: already merged, nothing to do", pid, already=True)
        raise StudyappError(f"participant {pid!r} is already in the database with other answers (two participants "
                            "used the same id, or the file changed since it was merged); it was not imported")
    others: dict[str, list[dict[str, Any]]] = {}
    for t in db.trials():
        others.setdefault(t["participant"], []).append(t)
    for other, rows in batch.items():
        others.setdefault(other, rows)
    durations: dict[str, float | None] = {}

    def duration_of(plan: Any) -> float | None:
        if plan.stimulus_id not in durations:
            durations[plan.stimulus_id] = trial_duration_s(design, plan)
        return durations[plan.stimulus_id]

    findings = got.id_findings + check_returned(payload, design, roster=got.roster, allow_unlisted=allow_unlisted,
                                                others=others, duration_of=duration_of)
    if findings:
        raise _Refused([str(f) for f in findings])
    p = payload["participants"][0]
    groups = json.loads(p["groups"])
    if got.remote:
        groups.setdefault("remote", "yes")
        groups["bundle"] = payload["design_hash"][:12]
    from studyapp.study.storage import DuplicateAnswerError

    try:
        db.import_participant({**p, "groups": json.dumps(groups, sort_keys=True)}, payload["sessions"],
                              payload["trials"], payload["responses"], payload["plays"], payload["questionnaire"],
                              payload.get("trial_slots", []), payload.get("judgements", []))
    except DuplicateAnswerError as exc:  # two processes merging at once
        raise StudyappError(str(exc)) from None
    return MergeReport(path, True, f"participant {pid}", pid)
