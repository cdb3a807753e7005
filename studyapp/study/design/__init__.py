"""Study designs: TOML files that say what a study shows, in which order, and what it asks.

A design is read in two passes. The first pass (:func:`validate_design`) collects *every* problem in the
file -- syntax, unknown keys, wrong types, missing or mismatched stimulus files, skeletons that cannot be
retargeted -- so an experimenter fixes them all in one go instead of one per run. Only a design without
problems becomes a :class:`Design` (:func:`load_design`).

The format is documented by example in ``study_designs/example_beat.toml``. Paths in a design are relative
to the design file. A condition's ``motion`` is a pattern: ``{stimulus}`` is replaced by the stimulus id and
``{<tag>}`` by the stimulus's tag of that name (e.g. ``{speaker}``). A condition with ``samples = N`` gives N
files per stimulus, told apart by ``{sample}`` (1..N); the schedule picks one per participant and trial.

The package, one job a module: :mod:`.schema` declares every key once (a dataclass field with the types it
accepts and its default), :mod:`.model` holds the validated classes, :mod:`.parse` reads a file into them,
:mod:`.files` knows the files a design names and its hash, :mod:`.played` which (condition, stimulus) motion
some trial plays (only those need files), :mod:`.blinding` keeps condition names out of
participants' sight.

Example
-------
>>> from studyapp.resources import demo_design
>>> d = load_design(demo_design())
>>> [c.id for c in d.conditions]
['synced', 'lagged', 'static']
>>> motion_path(d, d.conditions[0], d.stimuli[0]).name
'clip01.bvh'
"""
from __future__ import annotations

import json
from pathlib import Path

from studyapp.errors import InputError
from studyapp.study.design import validated
from studyapp.study.design.blinding import conditions_named_in, visible_text_leaks
from studyapp.study.design.files import (SAMPLE_FIELD, design_hash, fill_sample, has_sample_field, model_path, motion_key, motion_path,
                                         pattern_fields, referenced_files, resolve)
from studyapp.study.design.model import (DEFAULT_CRITERIA, AttentionCheck, Block, Condition, Criterion, Design,
                                         DesignError, DesignWarning, Display, Playback, Problem, QuestionItem,
                                         Stimulus, criterion_aspect)
from studyapp.study.design.played import mismatch_sources, played_pairs
from studyapp.study.design.parse import REPRESENTATIONS, TABLES, condition_from_settings, parse_design
from studyapp.study.design.schema import (ATTENTION_KINDS, AVATAR_SUFFIXES, BUILTIN_REFERENCE, FROZEN_PREFIX,
                                          MOTION_SUFFIXES, ORDERINGS, PARADIGMS, PREFERENCE_LEVELS, QUESTION_KINDS,
                                          SLOT_ASSIGNMENTS, SLOT_LABELS)

__all__ = [
    "SAMPLE_FIELD", "fill_sample", "has_sample_field", "motion_key", "ATTENTION_KINDS", "AVATAR_SUFFIXES", "BUILTIN_REFERENCE", "DEFAULT_CRITERIA", "FROZEN_PREFIX",
    "MOTION_SUFFIXES", "ORDERINGS", "QUESTION_KINDS", "REPRESENTATIONS", "SLOT_ASSIGNMENTS", "SLOT_LABELS", "TABLES",
    "PARADIGMS", "PREFERENCE_LEVELS", "Block", "DesignWarning", "criterion_aspect",
    "AttentionCheck", "Condition", "Criterion", "Design", "DesignError", "Display", "Playback", "Problem", "QuestionItem",
    "Stimulus", "condition_from_settings", "conditions_named_in", "design_hash", "load_design", "load_design_of", "model_path", "motion_path",
    "mismatch_sources", "played_pairs", "pattern_fields", "problems_to_json", "referenced_files", "resolve", "validate_design", "visible_text_leaks",
]


def validate_design(path: str | Path, *, check_files: bool = True) -> list[Problem]:
    """Every problem of a design file; an empty list means the design can run.

    ``check_files=False`` skips reading stimulus files (durations, skeletons) but still reports missing ones.
    A full check that finds nothing is recorded (:mod:`.validated`) for sessions loaded with ``reuse_check``.

    >>> from studyapp.resources import demo_design
    >>> validate_design(demo_design())
    []
    """
    design, problems = parse_design(Path(path), check_files)
    if check_files and not problems and design is not None:
        validated.record(design.design_hash)
    return problems


def load_design(path: str | Path, *, check_files: bool = True, reuse_check: bool = False) -> Design:
    """Read and validate a design; raises :class:`DesignError` listing all problems.

    ``reuse_check=True`` (a session start) skips reading the stimulus files when a full check of exactly
    these files already passed (:mod:`.validated`: keyed by the design hash); otherwise checks them in full.
    """
    if check_files and reuse_check:
        design, problems = parse_design(Path(path), False)  # syntax, files present, the hash
        if not problems and design is not None and validated.is_recorded(design.design_hash):
            return design
    design, problems = parse_design(Path(path), check_files)
    if problems or design is None:
        raise DesignError(path, problems)
    if check_files:
        validated.record(design.design_hash)
    return design


def load_design_of(path: str | Path, recorded_hash: str) -> Design:
    """The design at ``path``, which must be the one a results database was made for: its hash (which covers
    the bytes of every stimulus file) equal to the database's ``recorded_hash``. The stimulus files are hashed,
    not checked again (the database's first session checked them). Raises :class:`DesignError` for a design
    with problems, and an :class:`~studyapp.errors.InputError` naming ``path`` when it is another design."""
    design = load_design(path, check_files=False)
    if design.design_hash != recorded_hash:
        raise InputError(path, None, f"not the design this results database was made for (design hash "
                         f"{design.design_hash[:12]}…, the database's {recorded_hash[:12]}…); give the study's "
                         "own design with --design")
    return design


def problems_to_json(problems: list[Problem]) -> str:
    return json.dumps([p.to_json() for p in problems], indent=2)
