"""Design validation: broken designs written to temp folders, each problem reported once with file and key."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.io import wavfile

from studyapp.face.animation import FaceAnimation
from studyapp.face.io import save_face_csv
from studyapp.motion.beat import beat_skeleton
from studyapp.motion.bvh import write_bvh
from studyapp.motion.skeleton import Motion, Skeleton
from studyapp.study.design import DesignError, Problem, load_design, validate_design

FPS = 30.0
SECONDS = 2.0

GOOD = '''title = "Tiny"
instructions = "Rank them."
practice = ["s1"]

[[conditions]]
id = "a"
motion = "motion/a/{stimulus}.bvh"

[[conditions]]
id = "b"
motion = "motion/b/{stimulus}.bvh"

[[conditions]]
id = "c"
motion = "motion/c/{stimulus}.bvh"

[[stimuli]]
id = "s1"
audio = "audio/s1.wav"
face = "face/s1.csv"
tags = { speaker = "x" }

[[stimuli]]
id = "s2"
audio = "audio/s2.wav"
face = "face/s2.csv"
tags = { speaker = "y" }

[[attention_checks]]
stimulus = "s2"
kind = "frozen"

[ordering]
method = "balanced-latin-square"
seed = 5

[slots]
labels = "ABC"
'''


def write_motion(path: Path, seconds: float = SECONDS, skeleton: Skeleton | None = None) -> None:
    sk = skeleton or beat_skeleton()
    m = Motion.rest(sk, int(round(seconds * FPS)), FPS)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_bvh(m, path)


def write_audio(path: Path, seconds: float = SECONDS) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    t = np.arange(int(16000 * seconds)) / 16000
    wavfile.write(path, 16000, (0.3 * np.sin(2 * np.pi * 150 * t) * 32767).astype(np.int16))


@pytest.fixture(scope="module")
def study_files(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("study")
    for sid in ("s1", "s2"):
        write_audio(root / "audio" / f"{sid}.wav")
        (root / "face").mkdir(exist_ok=True)
        save_face_csv(FaceAnimation.neutral(int(SECONDS * FPS), FPS), root / "face" / f"{sid}.csv")
        for c in "abc":
            write_motion(root / "motion" / c / f"{sid}.bvh")
    return root


@pytest.fixture()
def study(study_files: Path, tmp_path: Path) -> Path:
    """A fresh, valid copy of the tiny study (tests break it in their own copy)."""
    import shutil

    dst = tmp_path / "study"
    shutil.copytree(study_files, dst)
    (dst / "design.toml").write_text(GOOD)
    return dst


def problems_for(study: Path, text: str) -> list[Problem]:
    (study / "design.toml").write_text(text)
    return validate_design(study / "design.toml")


def only(problems: list[Problem], key: str) -> Problem:
    hits = [p for p in problems if p.key == key]
    assert len(hits) == 1, (key, [str(p) for p in problems])
    return hits[0]


def test_valid_design_loads(study: Path) -> None:
    assert validate_design(study / "design.toml") == []
    d = load_design(study / "design.toml")
    assert d.condition_ids == ["a", "b", "c"] and [s.id for s in d.stimuli] == ["s1", "s2"]
    assert d.stimuli[0].audio == (study / "audio" / "s1.wav").resolve()
    assert d.criterion_ids == ["realism", "synchronization", "diversity"]
    assert d.slot_labels == ("A", "B", "C") and d.seed == 5 and d.practice == ["s1"]
    assert d.playback.allow_replay and not d.playback.allow_ties
    assert d.attention_checks[0].expected == {"criterion": "realism", "rank": 3}
    assert len(d.design_hash) == 64


def test_hash_changes_with_any_referenced_file(study: Path) -> None:
    h0 = load_design(study / "design.toml").design_hash
    assert load_design(study / "design.toml").design_hash == h0
    write_motion(study / "motion" / "b" / "s2.bvh", SECONDS + 0.05)  # same length within tolerance, new bytes
    h1 = load_design(study / "design.toml").design_hash
    assert h1 != h0
    (study / "design.toml").write_text(GOOD + "\n# a comment\n")
    assert load_design(study / "design.toml").design_hash not in (h0, h1)


def test_toml_syntax_error_has_line_and_column(study: Path) -> None:
    probs = problems_for(study, GOOD.replace('id = "b"', 'id = b"'))
    assert len(probs) == 1
    assert probs[0].line == 10 and "line 10, column" in probs[0].key and "syntax" in probs[0].message
    assert probs[0].path.endswith("design.toml")


def test_unknown_keys_suggest_the_right_one(study: Path) -> None:
    text = GOOD.replace('title = "Tiny"', 'titel = "Tiny"').replace('audio = "audio/s2.wav"', 'audoi = "audio/s2.wav"')
    probs = problems_for(study, text)
    p = only(probs, "titel")
    assert "did you mean 'title'" in p.fix and p.line == 1
    p = only(probs, "stimuli[1].audoi")
    assert "did you mean 'audio'" in p.fix and p.line == 25
    only(probs, "title")            # and title is now missing
    only(probs, "stimuli[1].audio")  # and so is the audio


def test_wrong_types(study: Path) -> None:
    text = GOOD.replace('motion = "motion/a/{stimulus}.bvh"', 'motion = "motion/a/{stimulus}.bvh"\nfps = "thirty"')
    text += "\n[playback]\nallow_ties = \"yes\"\n"
    probs = problems_for(study, text)
    assert "number" in only(probs, "conditions[0].fps").message
    assert "true or false" in only(probs, "playback.allow_ties").message
    assert len(probs) == 2


def test_each_missing_file_is_listed(study: Path) -> None:
    (study / "motion" / "b" / "s2.bvh").unlink()
    (study / "motion" / "c" / "s1.bvh").unlink()
    (study / "face" / "s1.csv").unlink()
    probs = validate_design(study / "design.toml")
    motion = [p for p in probs if p.key.endswith(".motion")]
    assert sorted(p.key for p in motion) == ["conditions[1].motion", "conditions[2].motion"]
    assert any("'b'" in p.message and "'s2'" in p.message for p in motion)
    assert any("'c'" in p.message and "'s1'" in p.message for p in motion)
    assert "not found" in only(probs, "stimuli[0].face").message
    assert len(probs) == 3
    with pytest.raises(DesignError) as err:
        load_design(study / "design.toml")
    assert len(err.value.problems) == 3 and "design.toml" in str(err.value) and "3 problems" in str(err.value)


def test_duration_mismatch_names_every_file(study: Path) -> None:
    write_motion(study / "motion" / "c" / "s2.bvh", SECONDS - 0.5)
    # A motion shorter than the trial (here: the audio's length) is the condition's problem: it names the
    # condition, the stimulus, the file, both durations and the fixes.
    p = only(validate_design(study / "design.toml"), "conditions[2]")
    assert "'c'" in p.message and "'s2'" in p.message and str(study / "motion" / "c" / "s2.bvh") in p.message
    assert f"{SECONDS - 0.5:.3f} s" in p.message and f"{SECONDS:.3f} s" in p.message
    assert 'motion_end = "hold" or "loop"' in p.fix and f"at most {SECONDS - 0.5:.3f}" in p.fix
    # A declared duration_s only needs every file to be long enough.
    text = GOOD.replace('face = "face/s2.csv"', 'face = "face/s2.csv"\nduration_s = 1.4')
    assert problems_for(study, text) == []
    text = GOOD.replace('face = "face/s2.csv"', 'face = "face/s2.csv"\nduration_s = 1.9')
    p = only(problems_for(study, text), "conditions[2]")
    assert "1.900 s" in p.message and "its duration_s" in p.message and "lower duration_s" in p.fix
    # ... unless the condition says what its motion does when it ends first.
    for end in ("hold", "loop"):
        held = text.replace('motion = "motion/c/{stimulus}.bvh"', f'motion = "motion/c/{{stimulus}}.bvh"\nmotion_end = "{end}"')
        assert problems_for(study, held) == []
    bad = text.replace('motion = "motion/c/{stimulus}.bvh"', 'motion = "motion/c/{stimulus}.bvh"\nmotion_end = "freeze"')
    assert "hold" in only(problems_for(study, bad), "conditions[2].motion_end").fix
    # A face too short stays the stimulus's problem: motion_end is about motion only.
    write_motion(study / "motion" / "c" / "s2.bvh", SECONDS)
    save_face_csv(FaceAnimation.neutral(int((SECONDS - 0.5) * FPS), FPS), study / "face" / "s2.csv")
    p = only(problems_for(study, GOOD), "stimuli[1]")
    assert "face" in p.message and "s2.csv" in p.message and f"{SECONDS - 0.5:.3f} s" in p.message


def test_condition_counts(study: Path) -> None:
    two = GOOD.replace('[[conditions]]\nid = "c"\nmotion = "motion/c/{stimulus}.bvh"\n', "")
    assert "exactly 3" in only(problems_for(study, two), "conditions").message
    one = two.replace('[[conditions]]\nid = "b"\nmotion = "motion/b/{stimulus}.bvh"\n', "")
    p = only(problems_for(study, one), "conditions")
    assert "at least 2" in p.message and "exactly 3" in p.message
    four = GOOD.replace("[[stimuli]]", '[[conditions]]\nid = "d"\nmotion = "motion/a/{stimulus}.bvh"\n\n[[stimuli]]', 1)
    assert "exactly 3" in only(problems_for(study, four), "conditions").message


def test_duplicates_and_unknown_references(study: Path) -> None:
    text = GOOD.replace('id = "c"', 'id = "a"').replace('stimulus = "s2"', 'stimulus = "s3"')
    text = text.replace('practice = ["s1"]', 'practice = ["s9"]')
    probs = problems_for(study, text)
    assert "duplicate" in only(probs, "conditions[2].id").message
    p = only(probs, "attention_checks[0].stimulus")
    assert "'s3'" in p.message and "s2" in p.fix
    assert "'s9'" in only(probs, "practice[0]").message


def test_bad_values(study: Path) -> None:
    text = GOOD.replace('method = "balanced-latin-square"', 'method = "balanced-latin"')
    text = text.replace('labels = "ABC"', 'labels = "XYZ"\nassignment = "even"')
    text = text.replace('kind = "frozen"', 'kind = "known-worst"')
    text = text.replace('motion = "motion/b/{stimulus}.bvh"', 'motion = "motion/b/clip.bvh"')
    probs = problems_for(study, text)
    assert "balanced-latin-square" in only(probs, "ordering.method").fix
    only(probs, "slots.labels")
    only(probs, "slots.assignment")
    assert "condition" in only(probs, "attention_checks[0].condition").message
    assert "{stimulus}" in only(probs, "conditions[1].motion").message


def test_top_level_key_after_a_table_and_tag_patterns(study: Path) -> None:
    text = GOOD.replace('practice = ["s1"]\n', "") + 'practice = ["s1"]\n'
    p = only(problems_for(study, text), "slots.practice")
    assert "top-level" in p.fix and p.line == text.splitlines().index('practice = ["s1"]') + 1
    # {speaker} is a tag placeholder: every stimulus needs the tag.
    tagged = GOOD.replace('motion = "motion/c/{stimulus}.bvh"', 'motion = "motion/c/{stimulus}{suffix}.bvh"')
    tagged = tagged.replace('tags = { speaker = "x" }', 'tags = { speaker = "x", suffix = "" }')
    p = only(problems_for(study, tagged), "conditions[2].motion")
    assert "'suffix'" in p.message and "'s2'" in p.message
    assert problems_for(study, tagged.replace('tags = { speaker = "y" }', 'tags = { speaker = "y", suffix = "" }')) == []


def test_motion_and_model_are_exclusive(study: Path) -> None:
    text = GOOD.replace('motion = "motion/c/{stimulus}.bvh"', 'motion = "motion/c/{stimulus}.bvh"\nmodel = "m.onnx"')
    assert "not both" in only(problems_for(study, text), "conditions[2]").message
    text = GOOD.replace('motion = "motion/c/{stimulus}.bvh"', "fps = 15")
    assert "exactly one" in only(problems_for(study, text), "conditions[2]").message


def test_unreadable_motion_is_reported(study: Path) -> None:
    (study / "motion" / "a" / "s1.bvh").write_text("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0\n")
    p = only(validate_design(study / "design.toml"), "conditions[0].motion")
    assert "s1" in p.message and "cannot read" in p.message


def test_unretargetable_skeleton_and_name_map_fix(study: Path) -> None:
    # joint names no rule reads (a fuzzy match would take "armL" for the left upper arm)
    odd = Skeleton(("root", "torso", "head", "limbA", "limbB"), np.array([-1, 0, 1, 1, 1]),
                   np.array([[0, 90, 0], [0, 20, 0], [0, 30, 0], [10, 25, 0], [-10, 25, 0]], float))
    for sid in ("s1", "s2"):
        write_motion(study / "motion" / "c" / f"{sid}.bvh", skeleton=odd)
    p = only(validate_design(study / "design.toml"), "conditions[2]")
    assert "retarget" in p.message and "Hips" in p.message and "LeftUpperLeg" in p.message and "name_map" in p.fix
    # Mapping some joints by hand leaves only the bones still missing; bad entries are reported one by one.
    text = GOOD.replace('motion = "motion/c/{stimulus}.bvh"', 'motion = "motion/c/{stimulus}.bvh"\n'
                        '[conditions.name_map]\nroot = "Hips"\ntorso = "Spine"\nhead = "Head"\nnose = "Head"\n'
                        'limbA = "LeftElbowBone"')
    probs = problems_for(study, text)
    p = only(probs, "conditions[2]")
    assert "Hips" not in p.message.split("bones")[1] and "LeftUpperArm" in p.message
    assert "nose" in only(probs, "conditions[2].name_map.nose").message
    assert "LeftElbowBone" in only(probs, "conditions[2].name_map.limbA").message


def test_many_problems_in_one_run(study: Path) -> None:
    text = GOOD.replace('title = "Tiny"', 'titl = "Tiny"').replace('id = "c"', 'id = "b"')
    text = text.replace('stimulus = "s2"', 'stimulus = "nope"') + "\n[playback]\nreplay = true\n"
    (study / "audio" / "s2.wav").unlink()
    write_motion(study / "motion" / "a" / "s1.bvh", SECONDS + 1.0)
    probs = problems_for(study, text)
    keys = {p.key for p in probs}
    assert {"titl", "title", "conditions[2].id", "attention_checks[0].stimulus", "playback.replay",
            "stimuli[1].audio", "stimuli[0]"} <= keys  # stimuli[0]: the duration mismatch, found all the same
    assert all(p.path.endswith("design.toml") and p.message for p in probs)


def run_cli(capsys, *args: str) -> tuple[int, str, str]:
    """Run this area's sub-commands in-process, through argparse exactly as ``studyapp`` registers them."""
    import argparse

    from studyapp.cli import design as design_cli

    parser = argparse.ArgumentParser(prog="studyapp")
    design_cli.register(parser.add_subparsers())
    ns = parser.parse_args(list(args))
    capsys.readouterr()
    code = ns.func(ns)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_cli_validate_text_and_json(study: Path, capsys) -> None:
    code, out, _ = run_cli(capsys, "validate", str(study / "design.toml"))
    assert code == 0 and "OK" in out
    (study / "motion" / "b" / "s2.bvh").unlink()
    (study / "design.toml").write_text(GOOD.replace("seed = 5", "seed = 5\nshuffle = true"))
    code, out, err = run_cli(capsys, "validate", str(study / "design.toml"))
    assert code == 1 and "2 problems" in err
    lines = out.strip().splitlines()
    assert len(lines) == 2 and all("design.toml" in ln for ln in lines)
    assert any("ordering.shuffle" in ln and "unknown key" in ln for ln in lines)
    code, out, _ = run_cli(capsys, "validate", "--json", str(study / "design.toml"))
    items = json.loads(out)
    assert code == 1 and {i["key"] for i in items} == {"ordering.shuffle", "conditions[1].motion"}
    assert all(set(i) >= {"file", "key", "message", "fix"} for i in items)


def test_cli_schedule_writes_plan_and_balance(study: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "plan.csv"
    code, stdout, _ = run_cli(capsys, "schedule", str(study / "design.toml"), "--participants", "6", "--csv", str(out))
    assert code == 0
    df = pd.read_csv(out)
    assert list(df.columns) == ["participant", "row", "trial_index", "stimulus", "is_practice",
                                "is_attention_check", "slot_left", "slot_middle", "slot_right", "sample_left",
                                "sample_middle", "sample_right"]
    assert (df[["sample_left", "sample_middle", "sample_right"]] == 1).all().all()  # one motion per stimulus
    assert "Samples shown" not in stdout
    assert len(df) == 6 * 4 and df.participant.nunique() == 6  # practice + 2 rated + 1 check each
    assert "Conditions (rows) x slots" in stdout and "left" in stdout
    from studyapp.study.schedule import balance_counts

    counts = balance_counts(df)
    # Two rated clips, six participants: each clip 3 times at each position; 4 rated trials per condition-slot.
    assert (counts["position_x_stimulus"].to_numpy() == 3).all()
    assert (counts["slot_x_condition"].to_numpy() == 4).all()
    assert counts["slot_x_condition"].to_string() in stdout


def test_empty_file_names_each_required_key_once(study: Path) -> None:
    probs = problems_for(study, "# nothing here\n")
    assert sorted(p.key for p in probs) == ["conditions", "stimuli", "title"]
    assert all("required" in p.message for p in probs)


def test_problem_text_is_one_line_with_file_line_key_and_fix(study: Path) -> None:
    p = only(problems_for(study, GOOD.replace("seed = 5", "seed = 5.5")), "ordering.seed")
    text = str(p)
    assert "\n" not in text and text.startswith(f"{study / 'design.toml'}:{p.line}: ordering.seed: ")
    assert "integer" in text and "-- fix: " in text


def test_any_mangled_design_gives_problems_not_crashes(study: Path) -> None:
    """Drop lines, retype values: validation must always answer with problems (or none), never a traceback."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    lines = GOOD.splitlines()
    values = st.sampled_from(['"x"', "1", "-3", "true", "[1, 2]", "{ a = 1 }", '"{bogus}.bvh"', "1.5", '""'])

    @settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
    @given(drop=st.sets(st.integers(0, len(lines) - 1), max_size=6),
           retype=st.dictionaries(st.integers(0, len(lines) - 1), values, max_size=3))
    def check(drop, retype):
        out = []
        for i, ln in enumerate(lines):
            if i in drop:
                continue
            if i in retype and " = " in ln:
                ln = ln.split(" = ")[0] + " = " + retype[i]
            out.append(ln)
        probs = problems_for(study, "\n".join(out) + "\n")
        assert all(isinstance(p, Problem) and p.message for p in probs)
        if not drop and not retype:
            assert probs == []

    check()


def test_participant_visible_text_naming_a_condition_is_a_problem() -> None:
    """Blinding: instructions, criteria and questionnaire texts must never name a condition."""
    from studyapp.resources import demo_design
    from studyapp.study.design import load_design, visible_text_leaks

    design = load_design(demo_design(), check_files=False)
    assert visible_text_leaks(design) == []
    design.title = "Synced or not?"
    design.criteria[2].explanation += " Some figures stay static."
    assert visible_text_leaks(design) == [("title", "synced"), ("criteria[2]", "static")]


def test_designs_do_not_share_the_default_criteria_objects() -> None:
    """Editing one loaded design's criteria (as an editor or a test may) must not change another design."""
    from studyapp.resources import demo_design
    from studyapp.study.design import DEFAULT_CRITERIA, load_design

    a = load_design(demo_design(), check_files=False)
    b = load_design(demo_design(), check_files=False)
    before = DEFAULT_CRITERIA[0].explanation
    a.criteria[0].explanation += " edited"
    assert b.criteria[0].explanation == before
    assert DEFAULT_CRITERIA[0].explanation == before


def test_one_problem_is_reported_once_and_points_at_its_line(study: Path) -> None:
    """A stimulus lacking audio is one problem, not also 'unknown stimulus' wherever it is referenced."""
    text = GOOD.replace('id = "s1"\naudio = "audio/s1.wav"\n', 'id = "s1"\n')
    text = text.replace('[[conditions]]\nid = "b"\nmotion = "motion/b/{stimulus}.bvh"\n', "")
    text = text.replace('[[conditions]]\nid = "c"\nmotion = "motion/c/{stimulus}.bvh"\n', "")
    probs = problems_for(study, text)
    lines = text.splitlines()
    assert only(probs, "stimuli[0].audio").line == lines.index('id = "s1"')
    assert not [p for p in probs if p.key.startswith("practice")], [str(p) for p in probs]
    p = only(probs, "conditions")  # a problem with the whole list points at its first block
    assert p.line == lines.index("[[conditions]]") + 1
    bad_practice = only(problems_for(study, GOOD.replace('practice = ["s1"]', 'practice = ["s9"]')), "practice[0]")
    assert bad_practice.line == GOOD.splitlines().index('practice = ["s1"]') + 1
    missing = only(problems_for(study, 'title = "x"\n[[stimuli]]\nid = "s1"\naudio = "audio/s1.wav"\n'), "conditions")
    assert "[[conditions]]" in missing.fix
    # a criterion lacking its question is one problem; the attention check that names it is fine
    crit = GOOD.replace("[ordering]", '[[criteria]]\nid = "realism"\n\n[[criteria]]\nid = "sync"\nquestion = "?"\n\n'
                                      "[ordering]")
    assert [p.key for p in problems_for(study, crit)] == ["criteria[0].question"]


def test_cli_validate_json_keeps_reader_notes_on_stderr(study: Path, capsys) -> None:
    bvh = study / "motion" / "a" / "s1.bvh"
    text = bvh.read_text()
    frames = int(re.search(r"Frames:\s*(\d+)", text).group(1))
    bvh.write_text(re.sub(r"Frames:\s*\d+", f"Frames: {frames + 1}", text))
    code, out, err = run_cli(capsys, "validate", "--json", str(study / "design.toml"))
    assert code == 0 and json.loads(out) == []
    assert "note:" in err and "Frames" in err and "s1.bvh" in err


def test_a_lying_frame_time_is_one_problem_with_the_fps_fix(study: Path) -> None:
    """DiffSHEG writes 120 fps headers over 15 fps data: the fix is `fps` on the condition, said once, not
    a "durations differ" line per clip that suggests cutting the clips."""
    for sid in ("s1", "s2"):
        path = study / "motion" / "b" / f"{sid}.bvh"
        path.write_text(re.sub(r"Frame Time:\s*\S+", "Frame Time: 0.008333", path.read_text()))
    probs = validate_design(study / "design.toml")
    p = only(probs, "conditions[1].fps")
    assert "4 times shorter" in p.message and "s1, s2" in p.message and p.fix.startswith("add fps = 30")
    # the line of the condition's [[conditions]] header, just above its id
    assert p.line == GOOD.splitlines().index('id = "b"') and len(probs) == 1, [str(x) for x in probs]
    fixed = GOOD.replace('motion = "motion/b/{stimulus}.bvh"', 'motion = "motion/b/{stimulus}.bvh"\nfps = 30')
    assert problems_for(study, fixed) == []


def _write_arrays(study: Path, joints: int) -> None:
    for sid in ("s1", "s2"):
        np.save(study / "motion" / "a" / f"{sid}.npy", np.zeros((int(SECONDS * FPS), joints, 3)))
    write_motion(study / "template.bvh")


def test_array_settings_are_asked_for_once_per_condition(study: Path) -> None:
    _write_arrays(study, 75)
    text = GOOD.replace('motion = "motion/a/{stimulus}.bvh"', 'motion = "motion/a/{stimulus}.npy"\ntemplate = "template.bvh"')
    probs = problems_for(study, text)
    assert "representation" in only(probs, "conditions[0].representation").fix
    assert "fps = 15" in only(probs, "conditions[0].fps").fix
    assert len(probs) == 2, [str(p) for p in probs]  # nothing per clip
    ok = text.replace('template = "template.bvh"', 'template = "template.bvh"\nrepresentation = "axis_angle"\nfps = 30')
    assert problems_for(study, ok) == []


def test_arrays_that_do_not_fit_the_template_are_one_problem_and_joints_fix_it(study: Path) -> None:
    _write_arrays(study, 3)
    text = GOOD.replace('motion = "motion/a/{stimulus}.bvh"', 'motion = "motion/a/{stimulus}.npy"\n'
                        'template = "template.bvh"\nrepresentation = "axis_angle"\nfps = 30')
    p = only(problems_for(study, text), "conditions[0].motion")
    assert "2 stimuli (s1, s2)" in p.message and "3 joints" in p.message and "joints" in p.fix
    ok = text.replace("fps = 30", 'fps = 30\njoints = ["Spine", "Neck", "Head"]')
    assert problems_for(study, ok) == []
    assert load_design(study / "design.toml").conditions[0].joints == ("Spine", "Neck", "Head")
    bad = text.replace("fps = 30", 'fps = 30\njoints = ["Spine", 3]')
    assert "joint names" in only(problems_for(study, bad), "conditions[0].joints").message


def test_a_pattern_tag_no_stimulus_has_is_reported_once_without_an_internal_error(study: Path) -> None:
    text = GOOD.replace('motion = "motion/c/{stimulus}.bvh"', 'motion = "motion/c/{clip}.bvh"')
    probs = problems_for(study, text)
    assert all("KeyError" not in str(p) for p in probs), [str(p) for p in probs]
    assert probs and all(p.key == "conditions[2].motion" and "no such tag" in p.message for p in probs), \
        [str(p) for p in probs]


def test_representations_match_the_motion_layer_and_6d_must_name_its_layout(study: Path) -> None:
    from studyapp.motion.rotations import REPRESENTATIONS
    from studyapp.study import design

    assert set(design.REPRESENTATIONS) == set(REPRESENTATIONS)
    _write_arrays(study, 75)
    text = GOOD.replace('motion = "motion/a/{stimulus}.bvh"', 'motion = "motion/a/{stimulus}.npy"\n'
                        'template = "template.bvh"\nrepresentation = "6d"\nfps = 30')
    p = only(problems_for(study, text), "conditions[0].representation")
    assert "ambiguous" in p.message and "sixd_rows" in p.fix


def test_array_settings_on_a_live_model_are_refused_not_ignored(tmp_path: Path) -> None:
    from studyapp.resources import designs_dir

    text = (designs_dir() / "live_model_example.toml").read_text()
    text = text.replace('model = "models/reference_gesture.onnx"', 'model = "models/reference_gesture.onnx"\ndegrees = false')
    (tmp_path / "live.toml").write_text(text.replace('"demo/', f'"{designs_dir()}/demo/').replace(
        '"models/', f'"{designs_dir()}/models/'))
    probs = validate_design(tmp_path / "live.toml", check_files=False)
    assert [p.key for p in probs] == ["conditions[1].degrees"], [str(p) for p in probs]


def test_a_head_track_shorter_than_the_clip_is_a_duration_problem(study: Path) -> None:
    """Head rotation rows come at the face's frame rate; a track a second short would freeze the live
    model's head input, so it is checked like the audio, face and motion."""
    np.save(study / "head_s1.npy", np.zeros((int(SECONDS * FPS), 3)))
    np.save(study / "head_s2.npy", np.zeros((int((SECONDS - 1.0) * FPS), 3)))
    text = GOOD.replace('face = "face/s1.csv"', 'face = "face/s1.csv"\nhead = "head_s1.npy"')
    assert problems_for(study, text) == []
    text = text.replace('face = "face/s2.csv"', 'face = "face/s2.csv"\nhead = "head_s2.npy"')
    p = only(problems_for(study, text), "stimuli[1]")
    assert "head 1.000 s" in p.message and "head_s2.npy" in p.message


_ROBOT_MAP = '''"Abdomen" = "Spine"
"Torso" = "Chest"
"Shoulder.L" = "LeftShoulder"
"UpperArm.L" = "LeftUpperArm"
"LowerArm.L" = "LeftLowerArm"
"Palm2.L" = "LeftHand"
"Shoulder.R" = "RightShoulder"
"UpperArm.R" = "RightUpperArm"
"LowerArm.R" = "RightLowerArm"
"Palm2.R" = "RightHand"
"UpperLeg.L" = "LeftUpperLeg"
"LowerLeg.L" = "LeftLowerLeg"
"Foot.L" = "LeftFoot"
"UpperLeg.R" = "RightUpperLeg"
"LowerLeg.R" = "RightLowerLeg"
"Foot.R" = "RightFoot"
'''


def test_avatar_bone_map_is_checked_against_the_avatar_file(study: Path) -> None:
    import shutil

    from studyapp.study.stimuli import load_trial_media
    from studyapp.study.schedule import participant_schedule

    samples = Path(__file__).resolve().parents[1] / "data" / "samples" / "avatars"
    (study / "avatar").mkdir()
    shutil.copy(samples / "RobotExpressive.glb", study / "avatar" / "robot.glb")
    shutil.copy(samples / "Fox.glb", study / "avatar" / "fox.glb")
    good = GOOD + '\n[avatar]\nmodel = "avatar/robot.glb"\n\n[avatar.bone_map]\n' + _ROBOT_MAP
    assert problems_for(study, good) == []
    design = load_design(study / "design.toml")
    assert design.avatar_bone_map["UpperArm.L"] == "LeftUpperArm"
    plan = participant_schedule(design, "P01")[0]
    assert load_trial_media(design, plan).avatar_bone_map == design.avatar_bone_map
    # one problem per bad entry: a joint the file lacks, a bone that does not exist, a value that is no name
    bad = good.replace('"Abdomen" = "Spine"', '"Abdomen" = 5').replace('"Torso" = "Chest"', '"Torso" = "Chestt"')
    bad = bad.replace('"Palm2.L" = "LeftHand"\n', '')  # a hand no name rule finds
    probs = problems_for(study, bad + '"Tail" = "UpperChest"\n')
    assert "humanoid bone name (a string)" in only(probs, "avatar.bone_map.Abdomen").message
    assert "'Chestt' is not a Unity humanoid bone" in only(probs, "avatar.bone_map.Torso").message
    p = only(probs, "avatar.bone_map.Tail")
    assert "joint 'Tail' is not in the avatar (robot.glb)" in p.message and "studyapp inspect" in p.fix
    # the left hand lost its entry: the avatar is no longer humanoid, said once with the file's joints (the
    # spine without its entry is still found: Abdomen sits between the hips and the neck)
    p = only(probs, "avatar.model")
    assert "robot.glb: not a humanoid avatar: no bones for LeftHand" in p.message and "Abdomen" in p.message
    # a fox is refused for what it is
    p = only(problems_for(study, GOOD + '\n[avatar]\nmodel = "avatar/fox.glb"\n'), "avatar.model")
    assert "fox.glb: not a humanoid avatar: its rest pose does not stand upright" in p.message


def _write_smpl(study: Path) -> None:
    """SMPL-X (BEAT2 keys) for condition a, AMASS-style SMPL-H for condition b: no template, layout or fps."""
    f = int(SECONDS * FPS)
    for sid in ("s1", "s2"):
        np.savez(study / "motion" / "a" / f"{sid}.npz", poses=np.zeros((f, 165)), trans=np.zeros((f, 3)),
                 betas=np.zeros(300), expressions=np.zeros((f, 100)), mocap_frame_rate=np.int32(30))
        np.savez(study / "motion" / "b" / f"{sid}.npz", poses=np.zeros((2 * f, 156)), trans=np.zeros((2 * f, 3)),
                 betas=np.zeros(16), mocap_framerate=np.float64(60))


def test_smpl_family_conditions_need_no_template_representation_or_fps(study: Path) -> None:
    _write_smpl(study)
    text = (GOOD.replace('motion = "motion/a/{stimulus}.bvh"', 'motion = "motion/a/{stimulus}.npz"')
            .replace('motion = "motion/b/{stimulus}.bvh"', 'motion = "motion/b/{stimulus}.npz"'))
    assert problems_for(study, text) == []
    # a body model is a referenced file like any other: missing, it is reported by key
    with_model = text.replace('motion = "motion/a/{stimulus}.npz"',
                              'motion = "motion/a/{stimulus}.npz"\nbody_model = "models/SMPLX_NEUTRAL.npz"')
    p = only(problems_for(study, with_model), "conditions[0].body_model")
    assert "SMPLX_NEUTRAL.npz" in str(p)
    # on a BVH condition a body model would be silently ignored: refused instead
    on_bvh = GOOD.replace('motion = "motion/c/{stimulus}.bvh"', 'motion = "motion/c/{stimulus}.bvh"\nbody_model = "m.npz"')
    assert any("not one" in p.message for p in problems_for(study, on_bvh) if p.key == "conditions[2].body_model")
    # a raw array in the same place still needs its settings, asked for once for the condition
    _write_arrays(study, 75)
    raw = GOOD.replace('motion = "motion/a/{stimulus}.bvh"', 'motion = "motion/a/{stimulus}.npy"')
    probs = problems_for(study, raw)
    assert {p.key for p in probs} == {"conditions[0].template", "conditions[0].representation", "conditions[0].fps"}


def _with_labels(*labels: str | None) -> str:
    """GOOD with ``label = ...`` added to conditions a, b, c (None: no label)."""
    text = GOOD
    for cid, label in zip("abc", labels):
        if label is not None:
            text = text.replace(f'id = "{cid}"\nmotion', f'id = "{cid}"\nlabel = {json.dumps(label)}\nmotion')
    return text


def test_condition_labels_load_and_default_to_the_id(study: Path) -> None:
    (study / "design.toml").write_text(_with_labels("Ours (diffusion)", None, "  Ground truth "))
    d = load_design(study / "design.toml")
    assert [c.label for c in d.conditions] == ["Ours (diffusion)", None, "Ground truth"]
    assert [c.shown_as for c in d.conditions] == ["Ours (diffusion)", "b", "Ground truth"]


def test_condition_labels_must_be_one_nonempty_line_and_unique(study: Path) -> None:
    p = only(problems_for(study, _with_labels("Ours", "  ", None)), "conditions[1].label")
    assert "empty" in p.message
    p = only(problems_for(study, _with_labels("Ours", "two\nlines", None)), "conditions[1].label")
    assert "line break" in p.message
    # the same label twice, ignoring case, and a label that reads as another condition's id
    p = only(problems_for(study, _with_labels("Ours", "ours", None)), "conditions[1].label")
    assert "conditions[0]" in p.message
    p = only(problems_for(study, _with_labels("c", None, None)), "conditions[2].id")
    assert "'c' names conditions[0]" in p.message
    assert problems_for(study, _with_labels("Ours", "Baseline", "GT")) == []


def test_participant_visible_text_naming_a_condition_label_is_a_problem(study: Path) -> None:
    """A label is the experimenter's name for a model: a text participants read must not hold it either."""
    text = _with_labels("DiffuGesture", None, None).replace('instructions = "Rank them."',
                                                            'instructions = "Rank them (diffugesture study)."')
    p = only(problems_for(study, text), "instructions")
    assert "'DiffuGesture'" in p.message and "unblinds" in p.message
