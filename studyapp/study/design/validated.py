"""A record of designs whose files passed the full check, so a participant session need not redo it.

The choice (issue 20, "the first trial frame within 1.5 s"): a **validation record keyed by the design
hash**, not a per-trial check. The full check (:func:`~studyapp.study.stimuli.check_stimulus_files`: every
file read, every trial scene built in a dry run through the session's own code) costs seconds, and a session
used to redo it at start even when the experimenter had just run ``studyapp validate``. Now:

* every full check that finds no problem (``studyapp validate``, :func:`~studyapp.study.design.load_design`)
  records the design's key here;
* a session start (``studyapp demo``, ``studyapp run`` on a new results database) loads the design with
  ``reuse_check=True``: the cheap parse (design syntax, every referenced file present, the design hash)
  always runs, and the full check is skipped only when the key is recorded;
* anything else runs the full check, so a session never starts on files that were not checked, and a
  broken file is refused before the first trial with the same one-line problem ``validate`` prints.

The key is the design hash (sha256 over the design file and the bytes of every file it references:
:func:`~studyapp.study.design.design_hash`), so changing, replacing or breaking any stimulus, motion, avatar
or model file invalidates the record; plus the identity of the checking code (every ``.py`` file of the
installed ``studyapp``: path, size, modification time), so an upgraded checker checks again. A per-trial
check was not chosen: a file that breaks at trial 3 would stop a participant halfway, where this refuses
the design before anyone starts.

Records are empty files named by the key in ``$STUDYAPP_CACHE_DIR/validated`` (else the platform's user
cache, as for :mod:`studyapp.models.live`). Deleting them is always safe: the next session checks again.
"""
from __future__ import annotations

import hashlib
import os
from functools import lru_cache
from pathlib import Path

import studyapp


def records_dir() -> Path:
    """The folder validation records live in."""
    env = os.environ.get("STUDYAPP_CACHE_DIR")
    if env:
        return Path(env) / "validated"
    import platformdirs  # only when no folder is given (it is cheap, but not needed by most commands)

    return Path(platformdirs.user_cache_dir("studyapp", appauthor=False)) / "validated"


@lru_cache(maxsize=1)
def code_identity() -> str:
    """A digest of the checking code: every ``.py`` file of the studyapp package by path, size and mtime."""
    root = Path(studyapp.__file__).resolve().parent
    h = hashlib.sha256(studyapp.__version__.encode())
    for folder, dirs, files in sorted(os.walk(root)):
        dirs.sort()
        for name in sorted(files):
            if name.endswith(".py"):
                st = os.stat(os.path.join(folder, name))
                h.update(f"\0{os.path.relpath(os.path.join(folder, name), root)}\0{st.st_size}\0{st.st_mtime_ns}".encode())
    return h.hexdigest()


def record_key(design_hash: str) -> str:
    return hashlib.sha256(f"{design_hash}\0{code_identity()}".encode()).hexdigest()


def is_recorded(design_hash: str) -> bool:
    """Whether a full check of exactly these files, by this code, found no problem."""
    return bool(design_hash) and (records_dir() / record_key(design_hash)).is_file()


def record(design_hash: str) -> None:
    """Remember that a full check of this design found no problem (best effort: a read-only cache only
    means the next session checks again)."""
    if not design_hash:
        return
    try:
        folder = records_dir()
        folder.mkdir(parents=True, exist_ok=True)
        (folder / record_key(design_hash)).touch()
    except OSError:
        pass
