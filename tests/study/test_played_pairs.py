"""Which (condition, stimulus) motion a design plays (``played_pairs``), and that a design with ``[[blocks]]``
needs motion files for those pairs only: it validates, runs to the end, bundles and pre-renders without the
files no trial plays.

The rules of :mod:`studyapp.study.design.played` are held here to the schedule itself: every trial of every
design row of every shipped design and of block designs built for the test, counted with plain loops.
"""
from __future__ import annotations

import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from fixtures.synthetic import FPS, write_synthetic_study
from studyapp.resources import designs_dir
from studyapp.study.design import FROZEN_PREFIX, load_design, motion_key, played_pairs, referenced_files, validate_design
from studyapp.study.design.parse import parse_design
from studyapp.study.schedule import n_rows, participant_schedule

#: Two blocks on different conditions and clips: a rank block (with the practice clip p1 and the known-worst
#: attention check on att1, which belong to it) and a pairwise block that brings in a fourth condition.
TWO_BLOCKS = '''
[[blocks]]
id = "ranked"
paradigm = "rank"
criteria = ["realism"]
conditions = ["synced", "lagged", "static"]
stimuli = ["s1", "s2"]

[[blocks]]
id = "pairs"
paradigm = "pairwise"
criteria = ["realism"]
conditions = ["synced", "extra"]
stimuli = ["s3", "s4"]
'''
#: What TWO_BLOCKS plays, by hand: the rank block's three conditions on its clips, the practice clip and the
#: check's clip; the pairwise block's two on its clips.
TWO_BLOCKS_PLAYS = {"synced": ("s1", "s2", "s3", "s4", "p1", "att1"), "lagged": ("s1", "s2", "p1", "att1"),
                    "static": ("s1", "s2", "p1", "att1"), "extra": ("s3", "s4")}

#: A mismatch block first (so the practice clip is a mismatch trial), a rating block with a hidden reference,
#: and a rank block last (which the attention check joins).
MISMATCH_RATING_RANK = '''
[[blocks]]
id = "fit"
paradigm = "mismatch"
criteria = ["synchronization"]
conditions = ["lagged", "extra"]
stimuli = ["s1", "s2", "s3", "s4"]

[[blocks]]
id = "rated"
paradigm = "rating"
criteria = ["realism"]
conditions = ["synced", "static"]
reference = "extra"
stimuli = ["s3"]

[[blocks]]
id = "ranked"
paradigm = "rank"
criteria = ["realism"]
conditions = ["synced", "lagged", "static"]
stimuli = ["s4"]
'''

#: A pairwise block first (its practice), then a rating block without a reference; no attention check.
PAIRWISE_RATING = '''
[[blocks]]
id = "pairs"
paradigm = "pairwise"
criteria = ["realism"]
conditions = ["synced", "lagged", "extra"]
stimuli = ["s1", "s2"]

[[blocks]]
id = "rated"
paradigm = "rating"
criteria = ["realism"]
conditions = ["lagged", "static"]
stimuli = ["s3", "s4"]
'''


def blocked_study(folder: Path, blocks: str, *, seconds: float = 0.5, check: bool = True, slots: str = "balanced",
                  only_played: bool = False) -> Path:
    """The synthetic study (clips s1..s4, practice p1, a known-worst check on att1) with a fourth condition
    ``extra`` and ``blocks``; ``only_played``: every motion file no trial plays removed (by the hand list
    :data:`TWO_BLOCKS_PLAYS` for :data:`TWO_BLOCKS`, else by ``played_pairs``)."""
    path = write_synthetic_study(folder, n_stimuli=4, seconds=seconds, attention_check=check)
    (folder / "motion" / "extra").mkdir()
    for f in (folder / "motion" / "static").iterdir():
        shutil.copy(f, folder / "motion" / "extra" / f.name)
    text = path.read_text()
    text += f'\n[[conditions]]\nid = "extra"\nmotion = "motion/extra/{{stimulus}}.bvh"\nfps = {FPS}\n'
    text += f'\n[slots]\nassignment = "{slots}"\n' + blocks
    path.write_text(text)
    if only_played:
        plays = TWO_BLOCKS_PLAYS if blocks == TWO_BLOCKS else played_pairs(load_design(path, check_files=False))
        for cond in ("synced", "lagged", "static", "extra"):
            for f in (folder / "motion" / cond).iterdir():
                if f.stem not in plays[cond]:
                    f.unlink()
    return path


def schedule_pairs(design) -> dict[str, set[str]]:
    """Condition -> stimuli whose motion some trial of some row shows, from the schedule's trials."""
    out: dict[str, set[str]] = {c.id: set() for c in design.conditions}
    for row in range(n_rows(design)):
        for plan in participant_schedule(design, f"P{row:03d}", row):
            for i, slot in enumerate(plan.slots):
                out[slot.removeprefix(FROZEN_PREFIX)].add(plan.motion_stimulus(i))
    return out


SHIPPED = sorted(designs_dir().glob("*.toml"))
BUILT = {"two-blocks": (TWO_BLOCKS, "balanced"), "mismatch-rating-rank": (MISMATCH_RATING_RANK, "balanced"),
         "pairwise-rating": (PAIRWISE_RATING, "balanced"), "pairwise-rating-random": (PAIRWISE_RATING, "random"),
         "mismatch-rating-rank-random": (MISMATCH_RATING_RANK, "random")}


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_played_pairs_of_every_shipped_design_are_what_its_schedule_plays(path: Path) -> None:
    design, _ = parse_design(path, False)  # the schedule needs no file contents
    assert design is not None
    assert {c: set(s) for c, s in played_pairs(design).items()} == schedule_pairs(design)


@pytest.mark.parametrize("name", list(BUILT))
def test_played_pairs_of_block_designs_are_what_their_schedule_plays(name: str, tmp_path: Path) -> None:
    blocks, slots = BUILT[name]
    # attention checks belong to a rank block: the design without one has none
    design = load_design(blocked_study(tmp_path / "s", blocks, slots=slots, check=blocks != PAIRWISE_RATING),
                         check_files=False)
    got = played_pairs(design)
    assert {c: set(s) for c, s in got.items()} == schedule_pairs(design)
    assert all(got[c] for c in got)  # every condition is played somewhere in these designs
    if blocks == TWO_BLOCKS:
        assert got == TWO_BLOCKS_PLAYS


def _full_motion_keys(design) -> set[str]:
    """The motion keys a design's hash covered before played pairs: every condition x stimulus x sample."""
    return {motion_key(i, s.id, k, c.samples) for i, c in enumerate(design.conditions) if c.motion is not None
            for s in design.stimuli for k in range(1, max(1, c.samples) + 1)}


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_a_design_without_blocks_hashes_every_condition_for_every_stimulus(path: Path) -> None:
    design, _ = parse_design(path, False)
    assert design is not None
    motion = {k for k in referenced_files(design) if ".motion[" in k}
    if design.blocks:  # a design with blocks: the played pairs' files
        want = {motion_key(i, s, k, c.samples) for i, c in enumerate(design.conditions) if c.motion is not None
                for s in played_pairs(design)[c.id] for k in range(1, max(1, c.samples) + 1)}
        assert motion == want
    else:  # the hash a design without blocks always had
        assert motion == _full_motion_keys(design)


def test_an_unplayed_clip_of_a_design_without_blocks_keeps_its_hash_and_needs_no_file(tmp_path: Path) -> None:
    """att1 without its attention check is a clip no trial shows: its missing files are no problem, and the
    hash still covers the keys it always covered (so the design's hash is what it was)."""
    path = write_synthetic_study(tmp_path / "s", n_stimuli=4, seconds=0.5, attention_check=True)
    path.write_text(path.read_text().split("[[attention_checks]]")[0] + "[ordering]" +
                    path.read_text().split("[ordering]")[1])
    for cond in ("synced", "lagged", "static"):
        (tmp_path / "s" / "motion" / cond / "att1.bvh").unlink()
    assert validate_design(path) == []
    design = load_design(path)
    assert played_pairs(design)["synced"] == ("s1", "s2", "s3", "s4", "p1")
    assert {k for k in referenced_files(design) if ".motion[" in k} == _full_motion_keys(design)


def test_a_missing_file_of_a_played_pair_is_one_line_naming_it(tmp_path: Path) -> None:
    path = blocked_study(tmp_path / "s", TWO_BLOCKS, only_played=True)
    gone = tmp_path / "s" / "motion" / "extra" / "s4.bvh"
    gone.unlink()
    problems = validate_design(path)
    assert len(problems) == 1, problems
    assert problems[0].key == "conditions[3].motion" and str(gone) in problems[0].message
    assert "'extra'" in problems[0].message and "'s4'" in problems[0].message


def test_a_block_design_with_only_its_played_files_validates_runs_bundles_and_prerenders(tmp_path: Path) -> None:
    from fixtures.bundles import remote_run
    from studyapp import tomlfile
    from studyapp.study import prerender as pr
    from studyapp.study.bundle import bundle_design_paths, make_bundle, merge_results, open_bundle
    from studyapp.study.export import export_dataframe

    seconds = 0.4
    path = blocked_study(tmp_path / "s", TWO_BLOCKS, seconds=seconds, only_played=True)
    assert sum(1 for _ in (tmp_path / "s" / "motion").rglob("*.bvh")) == 6 + 4 + 4 + 2
    assert validate_design(path) == []
    design = load_design(path)

    # a scripted participant runs the real app offscreen to the end
    db = tmp_path / "s" / "tiny.results.sqlite"  # where merge finds the design beside it
    ran = subprocess.run([sys.executable, "-m", "studyapp.cli", "run", str(path), "--participant", "P01",
                          "--offscreen", "--bot", "careful", "--results", str(db)],
                         capture_output=True, text=True, timeout=600)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    assert "completed the study" in ran.stdout
    with sqlite3.connect(db) as con:
        blocks = {b for (b,) in con.execute("SELECT DISTINCT block FROM trials WHERE participant = 'P01'")}
        status = con.execute("SELECT status FROM participants WHERE id = 'P01'").fetchone()[0]
    assert status == "done" and blocks == {"ranked", "pairs"}

    # the bundle ships the played motion only, its design's files are exactly what the confinement walk sees,
    # and a remote participant's results merge back
    info = make_bundle(path, tmp_path / "study.zip", participants=2, results=db, salt="played")
    for entry in info.key["trials"].values():
        for tok, real in entry["conditions"].items():
            assert entry["motions"][tok] in TWO_BLOCKS_PLAYS[real], (real, entry)
    opened = open_bundle(info.path, cache=tmp_path / "cache")
    shipped, problems = parse_design(opened.design_path, False)
    assert shipped is not None and problems == []
    walked = dict(bundle_design_paths(tomlfile.loads(opened.design_path.read_text(encoding="utf-8")), 100))
    assert set(walked) == set(referenced_files(shipped))
    results_zip = remote_run(info.path, tmp_path / "remote", "R01", pace_s=seconds)
    reports = merge_results(db, [results_zip])
    assert [r.ok for r in reports] == [True], reports[0].message
    merged = export_dataframe(db)
    remote = merged[merged["participant"] == "R01"]
    assert set(zip(remote["condition"], remote["stimulus"])) <= {
        (c, s) for c, clips in TWO_BLOCKS_PLAYS.items() for s in clips}
    assert set(remote["block"]) == {"ranked", "pairs"}

    # pre-rendering renders every trial, and with them exactly the played pairs
    cache = tmp_path / "videos"
    report = pr.prerender(design, cache, settings=pr.RenderSettings(size=(96, 54), fps=15))
    trials = pr.distinct_trials(design)
    assert report.total == report.rendered == len(trials) == len(list(cache.glob("*.mp4")))
    rendered: dict[str, set[str]] = {}
    for plan in trials:
        for i, slot in enumerate(plan.slots):
            rendered.setdefault(slot.removeprefix(FROZEN_PREFIX), set()).add(plan.motion_stimulus(i))
    assert rendered == {c: set(s) for c, s in TWO_BLOCKS_PLAYS.items()}


def test_a_mismatch_rating_rank_design_with_only_its_played_files_validates_and_bundles(tmp_path: Path) -> None:
    """The mismatch block's sources, the rating block's reference, the practice clip opening the mismatch
    block and the check joining the last block: all played, nothing else on disk; the shipped design's own
    played pairs are exactly the files it ships."""
    from studyapp import tomlfile
    from studyapp.study.bundle import bundle_design_paths, make_bundle, open_bundle

    path = blocked_study(tmp_path / "s", MISMATCH_RATING_RANK, only_played=True)
    assert not (tmp_path / "s" / "motion" / "synced" / "s1.bvh").exists()  # synced is in no block with s1
    assert validate_design(path) == []
    info = make_bundle(path, tmp_path / "study.zip", participants=3, results=tmp_path / "s" / "tiny.results.sqlite",
                       salt="mm")
    plays = played_pairs(load_design(path))
    for entry in info.key["trials"].values():
        for tok, real in entry["conditions"].items():
            assert entry["motions"][tok] in plays[real], (real, entry)
    opened = open_bundle(info.path, cache=tmp_path / "cache")
    shipped, problems = parse_design(opened.design_path, True)
    assert shipped is not None and problems == []
    walked = dict(bundle_design_paths(tomlfile.loads(opened.design_path.read_text(encoding="utf-8")), 100))
    assert set(walked) == set(referenced_files(shipped))
