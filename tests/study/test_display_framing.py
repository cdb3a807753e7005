"""The design's ``[display] framing`` key: default, accepted values, a clear problem for anything else,
and the value reaching the trial media the renderer reads."""
from __future__ import annotations

import pytest

from studyapp.study.design import Display, load_design, validate_design
from fixtures.synthetic import write_synthetic_study


@pytest.fixture
def design_path(tmp_path):
    return write_synthetic_study(tmp_path / "s", n_stimuli=1, seconds=1.0, practice=False)


def test_upper_body_is_the_default(design_path):
    design = load_design(design_path)
    assert design.display == Display() and design.display.framing == "upper-body"


def test_full_body_reaches_the_trial_media(design_path):
    from studyapp.study.schedule import participant_schedule
    from studyapp.study.stimuli import load_trial_media

    design_path.write_text(design_path.read_text() + '\n[display]\nframing = "full-body"\n')
    design = load_design(design_path)
    assert design.display.framing == "full-body"
    plan = participant_schedule(design, "P1", 0)[0]
    assert load_trial_media(design, plan).framing == "full-body"


@pytest.mark.parametrize("text,key,words", [
    ('framing = "upper_body"', "display.framing", ("unknown framing", "upper-body")),
    ('framing = 3', "display.framing", ("must be a string",)),
    ('zoom = 2', "display.zoom", ("unknown key",)),
])
def test_bad_values_are_reported_with_line_and_fix(design_path, text, key, words):
    design_path.write_text(design_path.read_text() + f"\n[display]\n{text}\n")
    problems = validate_design(design_path)
    assert [p.key for p in problems] == [key]
    p = problems[0]
    assert all(w in f"{p.message} {p.fix}" for w in words), p
    assert p.line == design_path.read_text().splitlines().index(text) + 1
