"""Files a design names: paths relative to the design, motion patterns, the design's hash.

A design's hash covers the design file and every file it references, so any changed stimulus changes it.
"""
from __future__ import annotations

import hashlib
import os
import re
import string
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from studyapp.study.design.schema import BUILTIN_REFERENCE

if TYPE_CHECKING:
    from studyapp.study.design.model import Condition, Design, Stimulus


class ProblemSink(Protocol):
    """Where a check reports a problem (the parser's collector)."""

    def add(self, key: str, message: str, fix: str = "") -> None: ...


def resolve(design: Design | Path | str, relpath: str | Path) -> Path:
    """Absolute path of a file named in a design (relative paths are relative to the design file).

    >>> resolve(Path("/studies/a.toml"), "clips/c1.wav").as_posix()
    '/studies/clips/c1.wav'
    """
    base = Path(getattr(design, "path", design)).resolve().parent
    p = Path(os.path.expanduser(str(relpath)))
    return p if p.is_absolute() else (base / p).resolve()


#: The placeholder of a condition's sample number (``samples = N``: 1..N).
SAMPLE_FIELD = "{sample}"


def fill_sample(pattern: str, sample: int) -> str:
    """``pattern`` with ``{sample}`` replaced by the sample number, before any other placeholder is filled.

    Filling it first lets ``{sample}`` also be part of a tag's name: a bundle names each sample's file by
    its own opaque tag, ``{c_1f2e3d_s{sample}}`` (see :mod:`studyapp.study.bundle`).

    >>> fill_sample("gen/{stimulus}/sample_{sample}.npz", 3)
    'gen/{stimulus}/sample_3.npz'
    >>> fill_sample("media/m_{c_ab_s{sample}}.bvh", 2)
    'media/m_{c_ab_s2}.bvh'
    >>> fill_sample("odd/{{sample}}/{stimulus}.bvh", 2)   # escaped braces: a folder literally named {sample}
    'odd/{{sample}}/{stimulus}.bvh'
    """
    return _SAMPLE_RE.sub(lambda m: m.group(1) + str(int(sample)), pattern)


# ``{sample}`` not inside escaped braces: preceded by an even number of ``{`` (``{{`` is a literal brace).
_SAMPLE_RE = re.compile(r"(?<!\{)((?:\{\{)*)\{sample\}")


def has_sample_field(pattern: str) -> bool:
    """Whether a pattern uses ``{sample}`` (escaped ``{{sample}}`` is a literal name, not the placeholder).

    >>> has_sample_field("a/{stimulus}_{sample}.bvh"), has_sample_field("a/{{sample}}/{stimulus}.bvh")
    (True, False)
    """
    return _SAMPLE_RE.search(pattern) is not None


def pattern_fields(pattern: str) -> list[str]:
    """Placeholder names used in a motion pattern (``{stimulus}``, ``{speaker}``, ...), ``{sample}`` aside.

    >>> pattern_fields("gen/{speaker}/{stimulus}_{sample}.bvh")
    ['speaker', 'stimulus']
    """
    try:
        return [f for _, f, _, _ in string.Formatter().parse(fill_sample(pattern, 1)) if f is not None]
    except ValueError:
        return ["<unbalanced braces>"]


def pattern_problem(pattern: str) -> str | None:
    """What makes a motion pattern unusable, or ``None``: placeholders are bare names (``{stimulus}``, a tag,
    ``{sample}``), never a format specification, conversion, attribute, index or position, which would let a
    design file run code paths of ``str.format`` (``{stimulus:>99999999}`` builds a 100 MB file name).

    >>> pattern_problem("gen/{speaker}/{stimulus}_{sample}.bvh") is None
    True
    >>> pattern_problem("m/{stimulus:>99999999}.bvh")
    "placeholder {stimulus:>99999999} has a format specification ':>99999999'; only bare names are allowed"
    >>> pattern_problem("m/{stimulus.__class__}.bvh")
    'placeholder {stimulus.__class__} is not a bare name; only bare names are allowed'
    """
    try:
        parts = list(string.Formatter().parse(fill_sample(pattern, 1)))
    except ValueError as exc:
        return f"unbalanced braces ({exc}); write {{{{ and }}}} for a literal brace"
    for _, name, spec, conversion in parts:
        if name is None:
            continue
        shown = "{" + name + (f"!{conversion}" if conversion else "") + (f":{spec}" if spec else "") + "}"
        if conversion:
            return f"placeholder {shown[:60]} has a conversion '!{conversion}'; only bare names are allowed"
        if spec:
            return f"placeholder {shown[:60]} has a format specification {':' + spec[:40]!r}; only bare names are allowed"
        if not name.isidentifier():
            return f"placeholder {shown[:60]} is not a bare name; only bare names are allowed"
    return None


def motion_path(design: Design, condition: Condition | str, stimulus: Stimulus | str, sample: int = 1) -> Path:
    """The motion file of one condition for one stimulus and sample (the condition's pattern filled in).

    ``sample`` is 1-based (``1..condition.samples``); a condition with one sample ignores it.
    """
    cond = design.condition(condition) if isinstance(condition, str) else condition
    stim = design.stimulus(stimulus) if isinstance(stimulus, str) else stimulus
    if cond.motion is None:
        raise ValueError(f"condition {cond.id!r} is a live model ({cond.model}); it has no motion files")
    if not 1 <= sample <= max(1, cond.samples):
        raise ValueError(f"condition {cond.id!r} has samples 1..{cond.samples}, not {sample}")
    problem = pattern_problem(cond.motion)
    if problem is not None:
        raise ValueError(f"condition {cond.id!r}: motion pattern {cond.motion!r}: {problem}")
    return resolve(design, fill_sample(cond.motion, sample).format(**{**stim.tags, "stimulus": stim.id}))


def motion_key(ci: int, stimulus_id: str, sample: int, samples: int) -> str:
    """Key of a motion file in :func:`referenced_files`: ``conditions[i].motion[<stimulus>]``, with
    ``:<sample>`` after the stimulus id when the condition has several samples.

    >>> motion_key(0, "clip01", 1, 1), motion_key(2, "clip01", 3, 5)
    ('conditions[0].motion[clip01]', 'conditions[2].motion[clip01:3]')
    """
    return f"conditions[{ci}].motion[{stimulus_id}{f':{sample}' if samples > 1 else ''}]"


def model_path(design: Design, condition: Condition) -> Path:
    """The ONNX file of a live condition (``builtin:reference``: the reference model shipped with studyapp)."""
    if condition.model is None:
        raise ValueError(f"condition {condition.id!r} has motion files, not a live model")
    if condition.model == BUILTIN_REFERENCE:
        from studyapp.models.reference import shipped_reference_model

        return shipped_reference_model()
    return resolve(design, condition.model)


_HASH_CACHE: dict[tuple[str, int, int], str] = {}


def _file_digest(path: Path) -> str:
    try:
        st = path.stat()
    except OSError:
        return "missing"
    if not path.is_file():
        return "not a file"
    key = (str(path), st.st_mtime_ns, st.st_size)
    if key not in _HASH_CACHE:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
        _HASH_CACHE[key] = h.hexdigest()
    return _HASH_CACHE[key]


def design_hash(design_bytes: bytes, files: dict[str, Path]) -> str:
    """sha256 over the design file and every file it references, so any changed stimulus changes it."""
    h = hashlib.sha256(design_bytes)
    for name in sorted(files):
        h.update(f"\0{name}\0{_file_digest(files[name])}".encode())
    return h.hexdigest()


def referenced_files(design: Design, col: ProblemSink | None = None) -> dict[str, Path]:
    """Every file a design refers to, keyed by the design key it comes from (``stimuli[0].audio``, ...).

    Motion files are keyed by :func:`motion_key` (every sample of a condition with ``samples > 1``), for the
    (condition, stimulus) pairs some trial plays (:func:`~studyapp.study.design.played.played_pairs`) in a
    design with ``[[blocks]]``; a design without blocks names every condition's motion for every stimulus,
    as it always did, so its hash never changes. With ``col`` given, missing files are reported there, one
    problem per file, played pairs' motion only (a file no trial plays is not needed).
    """
    from studyapp.study.design.played import played_pairs

    files: dict[str, Path] = {}
    played = played_pairs(design)
    unplayed: set[str] = set()  # keys hashed for a design without blocks that no trial plays
    for i, s in enumerate(design.stimuli):
        files[f"stimuli[{i}].audio"] = s.audio
        if s.face is not None:
            files[f"stimuli[{i}].face"] = s.face
        if s.head is not None:
            files[f"stimuli[{i}].head"] = s.head
    for i, c in enumerate(design.conditions):
        if c.model is not None:
            files[f"conditions[{i}].model"] = model_path(design, c)
        if c.template is not None:
            files[f"conditions[{i}].template"] = resolve(design, c.template)
        if c.body_model is not None:
            files[f"conditions[{i}].body_model"] = resolve(design, c.body_model)
        # a pattern with a problem (parse.py reports it) is never filled in: its files are unknown
        if c.motion is not None and pattern_problem(c.motion) is None and pattern_fields(c.motion):
            for s in design.stimuli:
                plays = s.id in played[c.id]
                if not plays and design.blocks:
                    continue
                try:
                    for k in range(1, max(1, c.samples) + 1):
                        files[motion_key(i, s.id, k, c.samples)] = motion_path(design, c, s, k)
                        if not plays:
                            unplayed.add(motion_key(i, s.id, k, c.samples))
                except (KeyError, IndexError, ValueError) as exc:
                    if col is not None and plays:
                        col.add(f"conditions[{i}].motion", f"pattern {c.motion!r} uses {exc} but stimulus "
                                f"{s.id!r} has no such tag", "add the tag to that stimulus or use only {stimulus}")
    if design.avatar != "builtin":
        files["avatar.model"] = resolve(design, design.avatar)
    for k, v in design.avatar_by_speaker.items():
        if v != "builtin":
            files[f"avatar.by_speaker.{k}"] = resolve(design, v)
    if col is not None:
        for key, p in files.items():
            if key not in unplayed and not p.is_file():
                what = key.split(".")[-1].split("[")[0]
                if ".motion[" in key:
                    ckey, stim = key[:-1].split(".motion[")
                    stim, _, sample = stim.partition(":")
                    cond = design.conditions[int(ckey.split("[")[1].rstrip("]"))].id
                    which = f", sample {sample}," if sample else ""
                    col.add(f"{ckey}.motion", f"motion file of condition {cond!r} for stimulus {stim!r}{which} not "
                            f"found: {p}", "generate or copy it there, or fix the pattern")
                else:
                    col.add(key, f"{what} file not found: {p}", "fix the path (relative to the design file)")
    return files
